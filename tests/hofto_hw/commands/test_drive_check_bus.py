"""``hofto-hw drive check PROFILE --interface I --channel C`` / ``--iface IF`` the way an
integrator runs it on a bench: the drives are already on the bus (here an emulator the test
starts itself, as its own bus: CANopen nodes on python-can's virtual bus, or ``hofto-hw
sim-ethercat`` on a veth pair in its own process as root), the check is told how many
drives of PROFILE to bring up (``--axes N`` < 6) and moves them with ``--move``."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml
from support.canopen import unique_channel

from drivers.cia402.state_machine import State
from hofto_hw.cli import main
from hofto_hw.config.drive_profile import load_profile
from hofto_hw.config.loader import dump_yaml

ROOT = Path(__file__).resolve().parents[3]
DRIVES = ROOT / "configs" / "drives"
STEP = 0.05  # [rad]


def bench_config(
    folder: Path, base: Path, profile: Path, n: int, bus: dict[str, Any], options: dict[str, Any]
) -> Path:
    """``base`` with its first ``n`` drives running ``profile`` (identity from it), ``bus``
    keys set in ``bus:`` and ``options`` in its transport's section: the config an integrator
    hands ``drive check --config`` (and here, the emulator too)."""
    data = yaml.safe_load(base.read_text())
    prof = load_profile(profile)
    for d in data["bus"]["drives"][:n]:
        d["profile"] = str(profile)
        d["identity"] = {
            "vendor_id": prof.identity.vendor_id,
            "product_code": prof.identity.product_code,
        }
    data["bus"].update(bus)
    data["bus"][prof.bus] = {**(data["bus"].get(prof.bus) or {}), **options}
    data["robot"]["urdf"] = str((base.parent / data["robot"]["urdf"]).resolve())
    path = folder / "bench.yaml"
    path.write_text(dump_yaml(data, sort_keys=False))
    return path


def _check(capsys: pytest.CaptureFixture, *argv: str) -> tuple[int, dict]:
    code = main(["drive", "check", *argv, "--move", str(STEP), "--json"])
    captured = capsys.readouterr()
    assert captured.out, captured.err
    return code, json.loads(captured.out)


def _assert_moved(code: int, report: dict, n: int) -> None:
    assert report["faults"] == [], report["faults"]
    assert report["operational"] is True and report["enabled"] is True
    assert report["emulated"] is False and report["axes"] == n
    assert len(report["moved_rad"]) == n
    assert all(abs(m - STEP) <= 0.1 * STEP for m in report["moved_rad"]), report["moved_rad"]
    assert report["passed"] is True and code == 0


# ------------------------------------------------------------------------ CANopen


@pytest.fixture()
def can_bench(tmp_path: Path) -> Iterator[Any]:
    """Start CANopen nodes built from a bench config on a virtual channel of their own;
    yields a function (profile, n) -> (config path, channel, the nodes)."""
    import can

    from drivers.sim.canopen_node import CanopenDrives
    from hofto_hw.config.loader import load_config
    from hofto_hw.runtime.build import build_emulated_drives

    running: list[tuple[Any, Any]] = []

    def start(
        profile: Path, n: int, edit: Any = None, node_ids: list[int] | None = None
    ) -> tuple[Path, str, Any]:
        channel = unique_channel("bench")
        # generous deadlines: the nodes run in a thread of this process on a loaded machine
        opts = {"can_interface": "virtual", "tpdo_deadline": 0.05, "sdo_timeout": 2.0}
        if node_ids is not None:
            opts["node_ids"] = node_ids
        path = bench_config(tmp_path, ROOT / "configs" / "er3a_canopen.yaml", profile, n,
                            {"interface": channel}, opts)  # fmt: skip
        cfg = load_config(path)
        bus = can.Bus(interface="virtual", channel=channel)
        ids = cfg.bus.canopen.node_ids
        nodes = CanopenDrives(build_emulated_drives(cfg, external=False), bus, ids)
        if edit is not None:
            edit(nodes)
        running.append((nodes.start(), bus))
        return path, channel, nodes

    try:
        yield start
    finally:
        for nodes, bus in running:
            nodes.stop()
            bus.shutdown()


@pytest.mark.parametrize("name", ["zeroerr_erob", "technosoft_ipos"])
def test_canopen_check_of_one_drive_on_a_live_bus(can_bench, capsys, name: str) -> None:
    """``--interface virtual --channel C --axes 1 --move 0.05`` against six live nodes: the
    check brings node 1 up alone (the others stay pre-operational as far as it cares),
    enables and moves it, with the scaling of ``--config``."""
    profile = DRIVES / f"{name}.yaml"
    config, channel, _nodes = can_bench(profile, 1)
    code, report = _check(capsys, str(profile), "--interface", "virtual", "--channel", channel,
                          "--axes", "1", "--config", str(config))  # fmt: skip
    _assert_moved(code, report, 1)
    assert report["bus"] == "canopen"
    assert report["devices"] == [{"device": 0, "axis": 0}]
    prof = yaml.safe_load(profile.read_text())
    assert report["pdos"][0]["rx"] == [f"0x{p['index']:04X}" for p in prof["rx_pdos"]]


def test_canopen_check_of_two_drives_with_the_default_base_config(can_bench, capsys) -> None:
    """No ``--config``: the base config is configs/er3a_canopen.yaml (its scaling), the bus
    the one named on the command line; two nodes of the profile checked."""
    profile = DRIVES / "zeroerr_erob.yaml"
    _config, channel, _nodes = can_bench(profile, 2)
    code, report = _check(capsys, str(profile), "--interface", "virtual", "--channel", channel,
                          "--axes", "2")  # fmt: skip
    _assert_moved(code, report, 2)


def test_the_node_ids_of_the_config_are_those_of_the_drives_checked(can_bench, capsys) -> None:
    """A config naming the node ids of its six drives (11..16): ``--axes 2`` checks the
    drives on nodes 11 and 12 (the id list is cut with the drive list)."""
    profile = DRIVES / "zeroerr_erob.yaml"
    config, channel, _nodes = can_bench(profile, 2, node_ids=[11, 12, 13, 14, 15, 16])
    code, report = _check(capsys, str(profile), "--interface", "virtual", "--channel", channel,
                          "--axes", "2", "--config", str(config))  # fmt: skip
    _assert_moved(code, report, 2)


def test_a_bench_config_with_only_bus_and_loop_sections(can_bench, capsys, tmp_path) -> None:
    """An integrator's ``--config`` for a bench: one drive, no robot section at all."""
    profile = DRIVES / "zeroerr_erob.yaml"
    config, channel, _nodes = can_bench(profile, 1)
    data = yaml.safe_load(config.read_text())
    data["bus"]["drives"] = data["bus"]["drives"][:1]
    bench = tmp_path / "one_drive.yaml"
    bench.write_text(dump_yaml({"loop": data["loop"], "bus": data["bus"]}, sort_keys=False))
    code, report = _check(capsys, str(profile), "--interface", "virtual", "--channel", channel,
                          "--axes", "1", "--config", str(bench))  # fmt: skip
    _assert_moved(code, report, 1)


def test_a_bench_config_with_a_bad_bus_field_is_one_line(capsys, tmp_path) -> None:
    profile = DRIVES / "zeroerr_erob.yaml"
    data = yaml.safe_load((ROOT / "configs" / "er3a_canopen.yaml").read_text())
    data["bus"]["drives"][0]["gear_ratio"] = -1
    bad = tmp_path / "bad.yaml"
    bad.write_text(dump_yaml({"loop": data["loop"], "bus": data["bus"]}, sort_keys=False))
    code = main(["drive", "check", str(profile), "--interface", "virtual", "--channel", "x",
                 "--axes", "1", "--config", str(bad)])  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and "Traceback" not in err
    assert err.startswith(f"hofto-hw drive: error: {bad}: bus.drives[0].gear_ratio")


# ----------------------------------------------------------------------- EtherCAT


@pytest.mark.root
def test_ethercat_check_of_two_drives_on_a_bench(tmp_path: Path, capsys) -> None:
    """``hofto-hw sim-ethercat --drives 2`` (its own process, a bench of the first two drives
    of the config) on a veth pair; ``drive check --iface IF --axes 2 --move 0.05``."""
    from support.rootnet import emulator, require_root, sim_ethercat_args, veth_pair

    require_root()
    profile = DRIVES / "elmo_gold.yaml"
    config = bench_config(tmp_path, ROOT / "configs" / "er3a.yaml", profile, 2,
                          {"transport": "ethercat", "interface": "unused"},
                          {"pdo_watchdog": 2.0, "receive_timeout": 0.02})  # fmt: skip
    with (
        veth_pair("bm", "bs") as (master, slave),
        emulator([*sim_ethercat_args(slave, config), "--drives", "2"], tmp_path, timeout=30.0),
    ):
        code, report = _check(capsys, str(profile), "--iface", master, "--axes", "2",
                              "--config", str(config))  # fmt: skip
    _assert_moved(code, report, 2)
    assert report["bus"] == "ethercat"
    assert [d["device"] for d in report["devices"]] == [0, 1]
    assert report["line"] == {
        "slaves": 2,
        "checked": [1, 2],
        "positions": [1, 2],
        "left_in_preop": [],
    }


_PREOP = 0x02
_OP = 0x08


@pytest.mark.root
@pytest.mark.parametrize("name", ["elmo_gold", "nanotec_c5_e_2_21"])
def test_ethercat_check_of_part_of_a_longer_line(tmp_path: Path, capsys, name: str) -> None:
    """An installed line of three drives (``sim-ethercat --drives 3``): ``--axes 1`` checks
    slave 1 and ``--slaves 1,3`` slaves 1 and 3, each moved 0.05 rad; the slaves not
    checked are brought to PRE-OP with the line and never go higher (the emulator records
    each slave's highest AL state), so no process data reaches them and their drives are
    never enabled. A position beyond the line is one line, exit 2, and brings nothing up.
    The Nanotec (AssignActivate 0x0330) gets 0x30 in ESC 0x0980 at the slaves checked only,
    found by their line position with a slave in PRE-OP between them."""
    from support.rootnet import emulator, require_root, sim_ethercat_args, veth_pair

    require_root()
    profile = DRIVES / f"{name}.yaml"
    unit = 0x30 if name.startswith("nanotec") else 0x00
    config = bench_config(tmp_path, ROOT / "configs" / "er3a.yaml", profile, 3,
                          {"transport": "ethercat", "interface": "unused"},
                          {"pdo_watchdog": 2.0, "receive_timeout": 0.02})  # fmt: skip
    with (
        veth_pair("lm", "ls") as (master, slave),
        emulator(
            [*sim_ethercat_args(slave, config), "--drives", "3"], tmp_path, timeout=30.0
        ) as emu,  # fmt: skip
    ):
        code1, one = _check(capsys, str(profile), "--iface", master, "--axes", "1",
                            "--config", str(config))  # fmt: skip
        after_one = emu.call(op="status")
        code2, two = _check(capsys, str(profile), "--iface", master, "--slaves", "1,3",
                            "--config", str(config))  # fmt: skip
        after_two = emu.call(op="status")
        beyond = main(["drive", "check", str(profile), "--iface", master, "--slaves", "4",
                       "--config", str(config), "--move", str(STEP), "--json"])  # fmt: skip
        captured = capsys.readouterr()
        after_beyond = emu.call(op="status")
    _assert_moved(code1, one, 1)
    assert one["line"] == {"slaves": 3, "checked": [1], "positions": [1], "left_in_preop": [2, 3]}
    assert one["devices"] == [{"device": 0, "axis": 0}]
    assert after_one["highest_al_state"] == [_OP, _PREOP, _PREOP]
    assert after_one["al_state"][1:] == [_PREOP, _PREOP]  # left where the check put them
    assert after_one["cyclic_unit_control"] == [unit, 0, 0]

    _assert_moved(code2, two, 2)
    assert two["line"] == {
        "slaves": 3,
        "checked": [1, 3],
        "positions": [1, 3],
        "left_in_preop": [2],
    }
    assert after_two["highest_al_state"] == [_OP, _PREOP, _OP]
    assert after_two["cyclic_unit_control"] == [unit, 0, unit]
    # the drives left alone were never enabled (CiA-402 state of the emulated drive)
    assert after_one["drive_state"][1] != State.OPERATION_ENABLED
    assert after_one["drive_state"][2] != State.OPERATION_ENABLED
    assert after_two["drive_state"][1] != State.OPERATION_ENABLED

    assert beyond == 2 and captured.out == ""
    err = captured.err.strip()
    assert "\n" not in err and "Traceback" not in err
    assert err == (
        f"hofto-hw drive: error: {master}: slave position 4 is beyond the EtherCAT line "
        "(found 3 slaves: positions 1 to 3)"
    )
    assert after_beyond["highest_al_state"][1] == _PREOP


# ---------------------------------------------------------------------- units (0x608F)


def _faulhaber_rpm(folder: Path) -> Path:
    """The shipped Faulhaber profile with its units stated (rpm, rpm/s), as an integrator
    sets them from the manual: a real bus runs it."""
    prof = yaml.safe_load((DRIVES / "faulhaber_mcbl300x.yaml").read_text())
    prof["units"].update(velocity="rpm", acceleration="rpm/s")
    path = folder / "faulhaber_mcbl300x.yaml"
    path.write_text(yaml.safe_dump(prof, sort_keys=False))
    return path


def test_a_drive_in_rpm_is_checked_on_a_live_bus(can_bench, capsys, tmp_path) -> None:
    """0x608F agrees with counts_per_rev (the emulated drive serves the encoder it has):
    configure passes the units check and the pv stream in rpm moves the joint."""
    profile = _faulhaber_rpm(tmp_path)
    config, channel, nodes = can_bench(profile, 1)
    assert (
        nodes.ods[0].get(0x608F, 1)
        == yaml.safe_load(config.read_text())["bus"]["drives"][0]["counts_per_rev"]
    )
    code, report = _check(capsys, str(profile), "--interface", "virtual", "--channel", channel,
                          "--axes", "1", "--config", str(config))  # fmt: skip
    _assert_moved(code, report, 1)


def test_a_drive_reporting_another_encoder_resolution_is_refused(can_bench, capsys, tmp_path):
    """The drive's 0x608F says 3000 increments per revolution (the Faulhaber's default), the
    config 13107200: the check refuses at configure, in one line naming the axis, the
    object, what the config expects and what the drive says; nothing is enabled."""
    profile = _faulhaber_rpm(tmp_path)

    def encoder_of_3000(nodes: Any) -> None:
        nodes.ods[0].entry(0x608F, 1).value = 3000

    config, channel, _nodes = can_bench(profile, 1, encoder_of_3000)
    cpr = yaml.safe_load(config.read_text())["bus"]["drives"][0]["counts_per_rev"]
    code, report = _check(capsys, str(profile), "--interface", "virtual", "--channel", channel,
                          "--axes", "1", "--config", str(config))  # fmt: skip
    assert code == 1 and report["passed"] is False
    assert report["operational"] is True and report["enabled"] is False
    assert report["faults"] == [
        "bus.drives[0].counts_per_rev: axis 0 (joint_1) object 0x608F (position encoder "
        f"resolution) says 3000 increments per 1 motor revolutions, config expects {cpr} per 1"
    ]


@pytest.mark.root
def test_canopen_check_against_the_emulator_in_its_own_process(tmp_path: Path) -> None:
    """Two processes as on a bench: ``hofto-hw sim-canopen`` serving six nodes over UDP
    multicast, and ``hofto-hw drive check --interface udp_multicast --channel GROUP --axes 1
    --move 0.05 --json`` (both in a private network namespace with loopback only)."""
    import subprocess

    from support.rootnet import (
        child_env,
        emulator,
        private_netns,
        python_argv,
        require_root,
        sim_canopen_args,
    )

    require_root("a network namespace")
    group = "239.74.163.25"
    profile = DRIVES / "zeroerr_erob.yaml"
    opts = {"tpdo_deadline": 0.05, "sdo_timeout": 2.0, "heartbeat_timeout": 0.5}
    config = bench_config(tmp_path, ROOT / "configs" / "er3a_canopen.yaml", profile, 1,
                          {"interface": group}, opts)  # fmt: skip
    with (
        private_netns("hdc") as netns,
        emulator(sim_canopen_args("udp_multicast", group, config), tmp_path, netns=netns),
    ):
        check = ["drive", "check", str(profile), "--interface", "udp_multicast",
                 "--channel", group, "--axes", "1", "--config", str(config),
                 "--move", str(STEP), "--json"]  # fmt: skip
        run = subprocess.run(
            [*python_argv(netns), "-m", "hofto_hw.cli", *check],
            cwd=ROOT,
            env=child_env(),
            capture_output=True,
            text=True,
            timeout=120,
        )
    assert run.stdout, run.stderr[-3000:]
    _assert_moved(run.returncode, json.loads(run.stdout), 1)


@pytest.mark.parametrize("k", ["0", "7"])
def test_sim_ethercat_drives_out_of_range_is_one_line(capsys, k: str) -> None:
    code = main(["sim-ethercat", "--iface", "lo", "--drives", k])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and "Traceback" not in err
    assert err.endswith(f"--drives {k}: the config has 6 drives (1 to 6)")
