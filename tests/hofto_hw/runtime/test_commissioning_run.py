"""Safe torque off while ``hofto-hw run`` runs over the EtherCAT emulator (veth) and the
CANopen emulator (udp_multicast in a private network namespace) (issue 28): STO is its own
fault class, category 0, the axis named; a reset does not enable through an active STO;
after STO is released the explicit reset enables the arm again. Needs root: skipped when
unprivileged, a failure under CI. The runs keep the tolerances of test_run_ethercat.py /
test_run_canopen.py (host stalls and late frames of a loaded machine are not the fault under
test). Every wait is for a state.

On EtherCAT the emulated drives' STO is 0x60FD bit 16 in the TxPDO: a reset while it is
active is refused naming the axis. The built-in CANopen layout does not map 0x60FD (its STO
is read by SDO, which the loop does not do): the loop sees STO as a drive that dropped to
Switch on disabled, and a reset while it is active re-latches STO when the axis will not
enable.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from support.rootnet import (
    ROOT,
    Emulator,
    ServiceRun,
    emulator,
    er3a_run,
    ethercat_run_config,
    first_event,
    private_netns,
    run_config,
    sim_canopen_args,
    sim_ethercat_args,
    veth_pair,
    wait_for,
)

WRIST = 3  # joint_4
#: EtherCAT: 1 s of late frames at 1 kHz; host stalls of over 100 ms were seen while other
#: sessions loaded the machine, and a bus loss is not under test
LOST_CYCLES = 1000


@contextmanager
def _service(kind: str, folder: Path) -> Iterator[tuple[Emulator, ServiceRun, dict[str, Any]]]:
    if kind == "ethercat":
        with veth_pair("sm", "ss") as (master, slave):
            config, data = ethercat_run_config(
                folder,
                master,
                "er3a-sto.yaml",
                overrun_streak=100_000,
                lost_cycles=LOST_CYCLES,
                edit=lambda d: d["loop"].update(realtime="preferred"),
            )
            with emulator(sim_ethercat_args(slave, config), folder) as emu:
                run = ServiceRun(folder, config)
                try:
                    yield emu, run, data
                finally:
                    run.close()
        return
    with private_netns("hst") as ns:
        config, data = run_config(
            folder,
            "er3a-canopen-sto.yaml",
            base=ROOT / "configs" / "er3a_canopen.yaml",
            overrun_streak=100_000,
            lost_cycles=10,  # test_run_canopen.py's (tpdo_resync bounds it)
            run=er3a_run("model_error", "path"),
        )
        args = sim_canopen_args("udp_multicast", "239.74.163.3", config)
        with emulator(args, folder, netns=ns) as emu:
            run = ServiceRun(folder, config, netns=ns)
            try:
                yield emu, run, data
            finally:
                run.close()


@pytest.mark.parametrize("kind", ["ethercat", "canopen"])
def test_sto_while_running_then_release_and_reset(tmp_path: Path, kind: str) -> None:
    with _service(kind, tmp_path) as (emu, run, data):
        run.start("--hold")
        run.wait_state("running")
        assert emu.call(op="sto", slave=WRIST, node=WRIST, active=True)["ok"]
        run.wait_latched("sto")
        status = run.status()
        assert status["faults"] == ["sto"], status  # not drive_disabled
        reply = run.request("reset")
        if kind == "ethercat":  # STO in the process image: refused, naming the axis
            assert "safe torque off active: joint_4" in str(reply), reply
        else:  # not in the image: the axis will not enable, STO latches again
            wait_for(lambda: run.latched("sto"), 60, "sto latched again", run.proc)
        assert run.latched("sto")
        assert emu.call(op="sto", slave=WRIST, node=WRIST, active=False)["ok"]
        wait_for(lambda: not emu.call(op="status")["sto"][WRIST], 30, "STO released")
        assert run.latched("sto")  # released: nothing re-enables by itself
        run.request("reset")
        wait_for(lambda: not run.status()["faults"], 60, "reset", run.proc)
        run.wait_state("running")
        code, summary = run.terminate()
    assert code == 0
    events = [e for e in summary["events"] if e["kind"] == "sto"]
    assert events and all(e["joint"] == WRIST for e in events), summary["events"]
    e = first_event(summary, "sto")
    assert e["category"] == 0 == data["safety"]["categories"]["sto"]
    assert "safe torque off" in e["detail"]
