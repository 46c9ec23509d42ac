"""Commissioning over every bus (issue 28, done-when): the simulated bus, the CANopen emulator
(python-can's virtual bus, the emulator in a thread) and the EtherCAT emulator (a veth pair,
``hofto-hw sim-ethercat`` in a child process; needs root: skipped unprivileged, a failure
under CI). The same drive-layer code the service runs (``runtime/compose.build_bus``,
``enable_drives``, the preload, the brake release check, the homing sequence, the brake
test command, the start-up position check, ``zero set``) against the emulated drives, which
are told through their control requests (STO input, brake, switches, index pulses).

The config: configs/er3a.yaml (CANopen: er3a_canopen.yaml, 200 Hz) with a master-controlled
brake (0x60FE) on the gravity-loaded shoulder joint_2 and a drive-controlled one on joint_3.
Every wait is for a state, counted in bus cycles.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from drivers.cia402.brake import ReleaseCheck
from drivers.cia402.drive_group import DriveGroup
from drivers.cia402.homing import home_axes, homing_plan
from drivers.cia402.state_machine import State
from hofto_hw.config.drives import HomingConfig
from hofto_hw.config.loader import dump_yaml, load_config
from hofto_hw.errors import UserError
from hofto_hw.runtime import compose
from safety.bus_health import BusHealth
from safety.stop import Fault, StopController
from tests.support.reference_safety import bus_check

ROOT = Path(__file__).resolve().parents[3]
SHOULDER, ELBOW, WRIST = 1, 2, 3  # joint_2 (brake by 0x60FE output), joint_3 (by the drive)
BRAKE_OUTPUT = {"control": "output", "release_delay": 0.05, "engage_delay": 0.05,
                "holding_torque": 60.0}  # fmt: skip
BRAKE_DRIVE = {"control": "drive", "release_delay": 0.1, "engage_delay": 0.05,
               "holding_torque": 40.0}  # fmt: skip
OE = int(State.OPERATION_ENABLED)
SOD = int(State.SWITCH_ON_DISABLED)


def _config(folder: Path, kind: str, interface: str | None) -> Path:
    base = ROOT / "configs" / ("er3a_canopen.yaml" if kind == "canopen" else "er3a.yaml")
    data = yaml.safe_load(base.read_text())
    data["robot"]["urdf"] = str((base.parent / data["robot"]["urdf"]).resolve())
    bus = data["bus"]
    bus["drives"][SHOULDER]["brake"] = dict(BRAKE_OUTPUT)
    bus["drives"][ELBOW]["brake"] = dict(BRAKE_DRIVE)
    if kind == "ethercat":
        bus.update(transport="ethercat", interface=interface)
        bus["ethercat"] = {**(bus.get("ethercat") or {}), "pdo_watchdog": 2.0}
    elif kind == "canopen":
        bus["interface"] = interface
        bus["canopen"].update(
            can_interface="virtual", tpdo_deadline=0.05, heartbeat_timeout=0.5, sdo_timeout=2.0
        )
    (data.get("run") or {}).pop("collision", None)
    path = folder / f"er3a-{kind}-commissioning.yaml"
    path.write_text(dump_yaml(data))
    return path


@dataclass
class Rig:
    """One bus with emulated drives: the config, a way to open the master, the emulator's
    control requests (``axis`` is the drive's position) and status."""

    kind: str
    path: Path
    control: Callable[[dict[str, Any]], dict[str, Any]] | None
    opened: list[Any] = field(default_factory=list)

    @property
    def cfg(self) -> Any:
        return load_config(self.path)

    def open(self) -> tuple[Any, Any]:
        """The transport and drive group the service would build (configured, CSP)."""
        bus, group = compose.build_bus(self.cfg, "sim" if self.kind == "sim" else "real")
        self.opened.append(bus)
        return bus, group

    def ctl(self, op: str, axis: int, **fields: Any) -> dict[str, Any]:
        request = {"op": op, "slave": axis, "node": axis, **fields}
        if self.control is None:  # the simulated bus: its drives in this process
            self.opened[-1].drives.commissioning(axis, request)
            return {"ok": True}
        reply = self.control(request)
        assert reply.get("ok"), reply
        return reply

    def status(self) -> dict[str, Any]:
        if self.control is None:
            d = self.opened[-1].drives
            return {"q": d.plant.q.tolist(), "drive_state": [int(x) for x in d.state],
                    **d.commissioning_status()}  # fmt: skip
        return self.ctl("status", 0)

    def close(self) -> None:
        for bus in self.opened:
            bus.close()
        self.opened.clear()


@pytest.fixture(params=["sim", "canopen", "ethercat"])
def rig(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Rig]:
    kind = request.param
    if kind == "sim":
        r = Rig(kind, _config(tmp_path, kind, None), None)
        try:
            yield r
        finally:
            r.close()
    elif kind == "canopen":
        import can
        from support.canopen import unique_channel

        from drivers.sim.canopen_node import CanopenDrives
        from hofto_hw.runtime.build import build_emulated_drives

        channel = unique_channel("comm")
        path = _config(tmp_path, kind, channel)
        can_bus = can.Bus(interface="virtual", channel=channel)
        drives = build_emulated_drives(load_config(path), external=False, load=True)
        emu = CanopenDrives(drives, can_bus)
        emu.start()
        r = Rig(kind, path, emu.control)
        try:
            yield r
        finally:
            r.close()
            emu.stop()
            can_bus.shutdown()
    else:
        from support.rootnet import emulator, sim_ethercat_args, veth_pair

        with veth_pair("hc", "hd") as (master, slave):
            path = _config(tmp_path, kind, master)
            with emulator(sim_ethercat_args(slave, path), tmp_path, timeout=60.0) as emu:
                r = Rig(kind, path, lambda req: emu.call(**req))
                try:
                    yield r
                finally:
                    r.close()


def _cycles(bus: Any, group: Any, n: int, until: Callable[[], bool] | None = None) -> int:
    """Hold and exchange up to ``n`` cycles (until ``until()``); the cycles taken."""
    for k in range(1, n + 1):
        group.hold()
        bus.wait_next_cycle()
        group.cycle()
        if until is not None and until():
            return k
    return n


def _enabled(rig: Rig, preload: bool = True) -> tuple[Any, Any, float, float]:
    """Open, preload gravity on the braked axes (or not), enable, open the shoulder's brake
    (0x60FE) and hold for the release check: the transport, the group and the shoulder's
    largest motion [rad] from the enable, and from the cycle its brake opened on."""
    bus, group = rig.open()
    cfg = rig.cfg
    model = compose.build_model(cfg)
    if preload:
        compose.preload_braked_axes(cfg, model, group)
    compose.enable_drives(bus, group)
    check = ReleaseCheck.from_drives(list(cfg.bus.drives), bus.cycle_time)
    assert check is not None
    check.start(group.q)
    bus.write_value(SHOULDER, 0x60FE, 1, "u32", 1)  # the master opens the shoulder's brake
    q0, total, after, q_open = float(group.q[SHOULDER]), 0.0, 0.0, None
    result = check.RUNNING
    while result == check.RUNNING or q_open is None:
        _cycles(bus, group, 1)
        q = float(group.q[SHOULDER])
        total = max(total, abs(q - q0))
        if q_open is None and not rig.status()["brake_engaged"][SHOULDER]:
            q_open = q
        if q_open is not None:
            after = max(after, abs(q - q_open))
        result = check.step(group.q)
    return bus, group, total, after


# --------------------------------------------------------------------------- brakes


def test_brake_delays_are_written_to_the_drive_by_sdo(rig: Rig) -> None:
    _, group = rig.open()
    rig.ctl("brake", ELBOW, release_delay=0.3, engage_delay=0.3, holding_torque=40.0)
    assert rig.status()["brake_delay_ms"][0][ELBOW] == 300
    group.configure(rig.cfg.bus.drives)  # writes the config's delays to 0x2110:1/2
    status = rig.status()
    assert [row[ELBOW] for row in status["brake_delay_ms"]] == [100, 50]
    assert group.brake_setup[0].startswith("axis 2 (joint_3): brake release_delay 0.1 s -> "
                                           "0x2110:01 = 100")  # fmt: skip
    assert len(group.brake_setup) == 1  # joint_2's brake is the master's (output): no delays


def test_enable_with_preload_holds_the_shoulder_and_without_it_sags(rig: Rig) -> None:
    """The shoulder moves less than 0.5 mrad while its brake opens with the gravity preload,
    more without. From the enable on, the emulated brake's own compliance adds the spring's
    unloading while it is still closed: its stiffness follows the drive loop's bandwidth
    (drivers/sim/drive.LoopTuning), ~0.8 mrad at CANopen's 200 Hz, < 0.2 mrad at 1 kHz."""
    _, _, total, held = _enabled(rig, preload=True)
    rig.close()
    _, _, total_without, sagged = _enabled(rig, preload=False)
    print(
        f"{rig.kind}: shoulder motion while its brake opened: {held * 1e3:.3f} mrad with the "
        f"preload, {sagged * 1e3:.3f} mrad without; from the enable {total * 1e3:.3f} / "
        f"{total_without * 1e3:.3f} mrad"
    )
    assert held < 0.5e-3
    assert sagged > 0.5e-3 and sagged > 3.0 * held
    if rig.kind != "canopen":  # 1 kHz: the brake's compliance is below the bound as well
        assert total < 0.5e-3


@pytest.mark.parametrize("category", [0, 1, 2])
def test_stop_categories_end_with_their_brake_states(rig: Rig, category: int) -> None:
    bus, group, _, _ = _enabled(rig)
    assert rig.status()["brake_engaged"][ELBOW] is False
    engage = int(np.ceil(BRAKE_DRIVE["engage_delay"] / bus.cycle_time))
    if category == 0:
        group.command_disable_voltage()
    elif category == 1:
        group.command_quick_stop()
    for k in range(int(3.0 / bus.cycle_time)):  # the ramp, the engage delay, margin
        bus.wait_next_cycle()
        group.cycle()
        if category != 2:  # both brakes: the drive's and the master's (0x60FE)
            st = rig.status()
            done = (group.states == SOD).all() and st["brake_engaged"][ELBOW]
            if done and st["brake_engaged"][SHOULDER]:
                break
        elif k >= 4 * engage:
            break
    status = rig.status()
    bit = bus.read_value(SHOULDER, 0x60FE, 1, "u32") & 1
    if category == 2:  # power kept, brake open
        assert (group.states == OE).all() and status["brake_engaged"][ELBOW] is False
        assert status["brake_engaged"][SHOULDER] is False and bit == 1
    else:  # power removed, brakes engaged, the master's brake bit cleared by the drive
        assert (group.states == SOD).all() and status["brake_engaged"][ELBOW] is True
        assert status["brake_engaged"][SHOULDER] is True and bit == 0


def _brake_test(rig: Rig, fraction: float, holding: float) -> int:
    """``hofto-hw brake test --joint joint_2 --torque fraction`` with the emulated shoulder
    brake rated ``holding`` [N·m] (the config says 60 N·m)."""
    from hofto_hw.commands import brake

    args = argparse.Namespace(config=str(rig.path), joint="joint_2", torque=str(fraction))
    if rig.kind != "sim":
        rig.ctl("brake", SHOULDER, release_delay=0.05, engage_delay=0.05,
                holding_torque=holding, by_output=True)  # fmt: skip
        return brake.run(args)
    real = compose.build_bus  # its own SimBus: give its drives that brake there

    def build_bus(cfg: Any, clock: str) -> Any:
        bus, group = real(cfg, clock)
        bus.drives.configure_brake(SHOULDER, 0.05, 0.05, holding, by_output=True)
        return bus, group

    compose.build_bus = build_bus  # type: ignore[assignment]
    try:
        return brake.run(args)
    finally:
        compose.build_bus = real  # type: ignore[assignment]


def test_a_slipping_brake_fails_the_brake_test(rig: Rig, capsys: pytest.CaptureFixture) -> None:
    """A good brake holds 80 % of its rating, one worn to 30 % slips (the issue's figures).
    CANopen at 200 Hz: 10 % against a brake worn to 5 %, since the emulated brake's stiffness
    follows the drive loop's bandwidth (drivers/sim/drive.LoopTuning: ~3.6 kN·m/rad on the
    shoulder at 200 Hz, so 18 N·m already bend it by the test's 5 mrad bound)."""
    fraction, worn = (0.1, 3.0) if rig.kind == "canopen" else (0.8, 18.0)
    assert _brake_test(rig, fraction, 60.0) == 0
    assert f"joint_2 held {fraction:.0%} of 60 N·m" in capsys.readouterr().out
    with pytest.raises(UserError, match=r"^brake test: joint_2: the brake slipped"):
        _brake_test(rig, fraction, worn)


def test_a_brake_that_does_not_open_is_a_latched_brake_fault(rig: Rig) -> None:
    bus, group = rig.open()
    rig.ctl("brake", ELBOW, stuck=True)
    compose.enable_drives(bus, group)
    stop = StopController.from_config(rig.cfg.safety.categories)
    health = BusHealth(group.n, 3, OE, (int(State.FAULT_REACTION_ACTIVE), int(State.FAULT),
                                        int(State.UNKNOWN)))  # fmt: skip
    health.sto_of, health.brake_code = group.sto_of, group.is_brake_fault
    codes = bus.tx["error_code"]
    for k in range(int(2.0 / bus.cycle_time)):
        stop.begin_tick(k)
        status = bus.exchange()
        group.read()
        if group.states[ELBOW] == int(State.FAULT) and codes[ELBOW]:
            bus_check(health, stop, status, group.fresh, group.states, codes, True)
            break
        bus.wait_next_cycle()
    assert stop.is_latched(Fault.BRAKE), (stop.latched_names(), group.states, codes)
    assert stop.is_latched(Fault.DRIVE_FAULT)
    ev = stop.events
    brake = [i for i in range(ev.count) if ev.kind[i] == Fault.BRAKE]
    assert len(brake) == 1 and ev.joint[brake[0]] == ELBOW
    assert ev.category[brake[0]] == rig.cfg.safety.categories.brake
    assert int(ev.value[brake[0]]) == 0xFF21


# ------------------------------------------------------------------------------ STO


def test_sto_at_boot_is_a_clear_state_then_release_enables(rig: Rig) -> None:
    from drivers.errors import DriveError

    bus, group = rig.open()
    rig.ctl("sto", WRIST, active=True)
    _cycles(bus, group, 500, lambda: WRIST in group.sto_axes())  # the emulator's next frame
    with pytest.raises(DriveError, match=r"^axis 3 \(joint_4\): safe torque off is active "
                                         r"\(0x60FD:00 bit 16\)"):  # fmt: skip
        group.enable()
    assert not group.any_fault()
    rig.ctl("sto", WRIST, active=False)
    _cycles(bus, group, 500, lambda: WRIST not in group.sto_axes())
    compose.enable_drives(bus, group)
    assert (group.states == OE).all()


def test_sto_while_enabled_is_category_0_naming_the_axis(rig: Rig) -> None:
    bus, group, _, _ = _enabled(rig)
    stop = StopController.from_config(rig.cfg.safety.categories)
    health = BusHealth(group.n, 3, OE, (int(State.FAULT_REACTION_ACTIVE), int(State.FAULT),
                                        int(State.UNKNOWN)))  # fmt: skip
    health.sto_of = group.sto_of
    rig.ctl("sto", WRIST, active=True)
    for k in range(int(2.0 / bus.cycle_time)):
        stop.begin_tick(k)
        status = bus.exchange()
        group.read()
        bus_check(health, stop, status, group.fresh, group.states, bus.tx["error_code"], True)
        if stop.latched:
            break
        bus.wait_next_cycle()
    assert stop.latched_names() == ["sto"] and stop.category == 0
    assert stop.events.joint[0] == WRIST
    # released: enabling again works (the loop's explicit reset is tests/hofto_hw/runtime)
    rig.ctl("sto", WRIST, active=False)
    _cycles(bus, group, 500, lambda: WRIST not in group.sto_axes())
    compose.enable_drives(bus, group)
    assert (group.states == OE).all()


def test_sto_toggling_while_enabling_stops_enabling_naming_the_axis(rig: Rig) -> None:
    from drivers.errors import DriveError

    bus, group = rig.open()
    real_cycle, calls = group.cycle, [0]

    def cycle() -> int:
        calls[0] += 1
        if calls[0] == 3:
            rig.ctl("sto", WRIST, active=True)
        return real_cycle()

    group.cycle = cycle  # type: ignore[method-assign]
    # STO in the TxPDO (sim, EtherCAT): enabling stops at once; read by SDO (the built-in
    # CANopen layout does not map 0x60FD): named when the transition times out
    with pytest.raises(DriveError, match=r"^axis 3 \(joint_4\): (safe torque off became "
                       r"active while enabling|no transition .*; safe torque off active "
                       r"\(0x60FD:00 bit 16\)$)"):  # fmt: skip
        group.enable()
    group.cycle = real_cycle  # type: ignore[method-assign]
    _cycles(bus, group, 50, lambda: not (group.states == OE).any())
    assert not (group.states == OE).any()  # nothing left half enabled


# --------------------------------------------------------------------------- homing


def _home(rig: Rig, bus: Any, group: Any, axis: int, **homing: Any) -> str:
    cfg = HomingConfig(**{"speeds": (0.2, 0.05), "acceleration": 2.0, "timeout": 10.0,
                          "tolerance": 0.01, **homing})  # fmt: skip
    plan = homing_plan(cfg, group.scaling, axis, bus.cycle_time, name=f"joint_{axis + 1}")
    return home_axes(group, [plan])


@pytest.mark.parametrize("method", [35, 33, 1])
def test_homing_methods(rig: Rig, method: int) -> None:
    axis = 4  # joint_5: no brake, little gravity
    bus, group, _, _ = _enabled(rig)
    _cycles(bus, group, int(1.0 / bus.cycle_time))  # settled after the enable
    q0 = float(np.array(rig.status()["q"])[axis])
    pitch = 2.0 * np.pi / rig.cfg.bus.drives[axis].gear_ratio  # one motor turn
    index = q0 - 0.3 * pitch  # the next index pulse below the start
    rig.ctl("index_phase", axis, phase=index)
    if method == 1:  # the negative limit switch 20 mrad below, then on up to the index
        rig.ctl("home_switch", axis, position=q0 - 0.02)
        index = q0 - 0.02 + pitch - ((q0 - 0.02 - index) % pitch)  # first pulse above it
    result = _home(rig, bus, group, axis, method=method, offset=0.1)
    true_q = float(np.array(rig.status()["q"])[axis])
    assert result == ""
    if method == 35:  # home = where the axis was at the start edge (it may creep in mode 6)
        assert float(group.q[axis]) == pytest.approx(0.1, abs=5e-3)
    else:  # the drive latched the pulse: reported - offset = true - the pulse's position
        assert float(group.q[axis]) - 0.1 == pytest.approx(true_q - index, abs=2e-4)


def test_homing_timeout(rig: Rig) -> None:
    axis = 4
    bus, group, _, _ = _enabled(rig)
    rig.ctl("index_phase", axis, phase=float(np.array(rig.status()["q"])[axis]) + 0.001)
    msg = _home(rig, bus, group, axis, method=33, speeds=(0.2, 1e-4), timeout=0.1)
    assert msg.startswith("joint_5: homing (method 33) did not end within the configured "
                          "timeout")  # fmt: skip


# ---------------------------------------------------- the absolute zero across restarts


def test_a_lost_turn_is_refused_at_start_up_and_zero_set_round_trips(
    rig: Rig, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    from hofto_hw.commands import zero
    from hofto_hw.runtime.positions import LastPositions, save_positions

    cfg = rig.cfg
    bus, group = rig.open()
    group.cycle()
    q = group.q.copy()
    joints = list(cfg.robot.joints)
    offsets = [d.zero_offset for d in cfg.bus.drives]
    state = tmp_path / "last_positions.yaml"
    lost = q.copy()
    lost[3] += 2.0 * np.pi / cfg.bus.drives[3].gear_ratio  # a whole motor turn at joint_4
    save_positions(state, LastPositions(joints, lost, offsets))
    with pytest.raises(UserError, match=r"^joint_4: position [-+]?\d+\.\d+ rad read at start-up"):
        compose.check_start_positions(cfg, bus, group, state)
    rig.opened.remove(bus)  # check_start_positions closed it

    # zero set: joint_4 is at a reference of 0.25 rad; the drive keeps its counts
    bus, group = rig.open()
    save_positions(state, LastPositions(joints, q.copy(), offsets))
    args = argparse.Namespace(
        config=str(rig.path), joint="joint_4", at="0.25", positions=state, socket=None
    )
    assert zero.run(args) == 0
    assert "joint_4 zero_offset" in capsys.readouterr().out
    cfg2 = load_config(rig.path)
    assert cfg2.bus.drives[3].zero_offset != offsets[3]
    group2 = DriveGroup.from_config(bus, cfg2.bus)  # the new config on the same drives
    group2.cycle()
    group.read()  # the same sample through the old config
    assert float(group2.q[3] - group.q[3]) == pytest.approx(0.25 - q[3], abs=1e-6)
    assert np.array_equal(np.delete(group2.q, 3), np.delete(group.q, 3))
    compose.check_start_positions(cfg2, bus, group2, state)  # the stored position follows
