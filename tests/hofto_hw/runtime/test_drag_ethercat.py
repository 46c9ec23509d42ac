"""Issue 9's drag test over the EtherCAT emulator on a veth pair: ``hofto-hw run`` (1 kHz,
configs/er3a.yaml with the bus on the veth pair) holds the arm; a hand (the emulator's
``push`` request, a force on its own true arm) hits the tool hard enough for a collision
stop; after a reset, drag mode and the enabling input (the run's control socket), a 20 N
push along x drags the tool at F/B_a within 10 % and the arm comes to rest within 100 ms of
the hand's release; releasing the enabling input stops the arm (enabling_released,
category 2). The speeds are the true arm's (the emulator's state, as the simulated drag
script's figures). The run records a flight log (tmp folder) for a failure's post-mortem.

Off-axis drift, the issue's 5 %: before the knock the arm runs the demo path (``mode move``,
4 s of plant time, at 0.4 of the config's amplitude: see PATH_SCALE) and moves back home, so
that the drag learns the friction model's error (control/friction_residual.py: ~4.7 s of
motion). At the drag's joint speeds, 0.27/-0.41/0.15 rad/s on joints 2/3/5, far above the
emulated arm's Stribeck velocities (0.05-0.08 rad/s), the (1, tanh, qd) features fit it: the
learned correction 0.22/0.24/-0.07 N·m against the true error 0.28/0.24/-0.05 N·m. The arm
then rests 1.2 s in drag mode before the press, as a person would: the tare (drag.tare_time,
1 s) averages the estimate's standstill wander (+-0.3 N·m on joints 2-3). Measured before:
no learning (the test's config had no ``run.path``, so ``mode move`` moved nothing) and a
0.2 s tare left -1.9 N along z at the tool (friction -1.0 N, tare -1.0 N): 7.8-9.3 mm/s
off-axis; learning (full-amplitude path) with the 0.2 s tare 4.7-5.0 mm/s; learning and the
1 s tare 0.3-0.6 mm/s (full amplitude), 0.1-0.2 mm/s (0.4 amplitude).
Over CANopen (issue 25: multi-axis nodes) the same test runs on configs/er3a_canopen.yaml
(200 Hz, ``hofto-hw sim-canopen`` over udp_multicast in a private network namespace) and on
three two-axis CANopen nodes (tests/support/profiles.py CAN_TWO_AXIS). At 200 Hz a CAN
sample is a SYNC old and a command acts at the next SYNC (10 ms against 1 ms), and the
admittance needs twice the mass for its explicit Euler step (a 30 ms time constant against
15 ms), so the rest after the release is bounded by 350 ms (issue 9's 100 ms is not met at
200 Hz) and the off-axis drift by 10 % there; the steady speed keeps the 10 % of F/B_a.
Measured (loaded 2-core machine, load 8-15, 4-5 runs each): er3a_canopen 96.7-100.0 mm/s,
off-axis 0.8-8.0 mm/s, rest <= 175-260 ms; three two-axis nodes 95.2-98.7 mm/s, 2.2-6.6
mm/s, <= 155-215 ms (EtherCAT er3a.yaml in the same session: 100.1 mm/s, 0.16 mm/s, 1 ms).
Needs root (veth, raw sockets, network namespaces): skipped when unprivileged, a failure
under CI.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from support.control_service import LeaseHolder
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

CONFIG = ROOT / "configs" / "er3a.yaml"
PUSH = 20.0  # N along x, world frame
PUSH_TIME = 1.8  # s
SETTLE = 0.5  # s from the push's start to the steady window (drag_figures' settle)
RAMP = 0.2  # s: the hand builds its push up (not a 20 ms step)
REST_WITHIN = 0.1  # s after the hand lets go (issue 9)
#: over CANopen at 200 Hz (see the module docstring): rest time and off-axis bound
CAN_REST_WITHIN = 0.35
CAN_OFF_AXIS = 0.1
RESOLUTION = 0.05  # s: the rest time is judged only when the samples around it are this dense
# the demo path at 0.4 of its amplitude: joint speeds up to 0.5-1.4 rad/s (full: up to 3.4),
# the drag's 0.15-0.45 inside; off-axis 0.1-0.4 mm/s after it against 0.3-0.6 at full amplitude
PATH_SCALE = 0.4
MOVE_TIME = 4.0  # s of the demo path before the knock (contact-free motion)
TARE_WAIT = 1.2  # s at rest in drag mode before the press (drag.tare_time, 1 s, and margin)


def _config(folder: Path, master: str, base: Path = CONFIG) -> tuple[Path, dict]:
    run = er3a_run("model_error", "path")
    # the demo path stays, scaled: the arm moves contact-free before the drag
    run["path"]["amplitude"] = [PATH_SCALE * a for a in run["path"]["amplitude"]]
    return ethercat_run_config(
        folder,
        master,
        "er3a-ethercat-drag.yaml",
        overrun_streak=100_000,  # host stalls are not under test here
        # the emulator is a user-space process: on a loaded 2-core machine it was starved of
        # 20+ cycles (a bus loss, category 0) once in 6 runs; bus loss is not under test here
        lost_cycles=200,
        # DC: the observers integrate over the drives' sample interval (the reference clock's
        # time), not over the master's late wake-ups on this loaded machine
        ethercat={"dc_sync": True},
        run=run,
        # the test holds the button
        edit=lambda data: data["drag"].update(enable_input={"source": "socket"}),
        base=base,
    )


def _can_options(base: Path) -> dict:
    import yaml

    return dict(yaml.safe_load(base.read_text())["bus"]["canopen"])


def _can_config(folder: Path, base: Path) -> tuple[Path, dict]:
    run = er3a_run("model_error", "path")
    run["path"]["amplitude"] = [PATH_SCALE * a for a in run["path"]["amplitude"]]
    return run_config(
        folder,
        "er3a-canopen-drag.yaml",
        base=base,
        overrun_streak=100_000,  # host stalls are not under test here
        # late TPDOs and heartbeats of a loaded machine are not under test either: 100 cycles
        # (0.5 s at 200 Hz), the TPDO resync and heartbeat timeout above it (1 s)
        lost_cycles=100,
        bus={"canopen": {**_can_options(base), "heartbeat_timeout": 1.0, "tpdo_resync": 1.0}},
        run=run,
        # er3a_canopen.yaml has no drag section: the schema's, as er3a.yaml's, but M_a 6 kg and
        # 0.3 kg·m² (at 200 Hz the release damping's explicit Euler step needs twice); the steady
        # speed F/B_a does not depend on it
        edit=lambda data: data.update(
            drag={
                "observer": "hofto",
                "mass": 6.0,
                "rotational_mass": 0.3,
                "enable_input": {"source": "socket"},
            }
        ),
    )


@dataclass
class DragRig:
    data: dict
    emu: Emulator
    service: ServiceRun
    bus: str = "ethercat"

    def push(
        self,
        force: tuple[float, float, float],
        duration: float,
        ramp: float = 0.02,
        trace: float = 0.0,
    ) -> float:
        """Start a push on the emulated arm (with ``trace`` > 0 also a trace of the true arm's
        state at every plant step for that long [s]); returns the emulator's plant time then."""
        extra = {"trace": trace} if trace > 0.0 else {}
        reply = self.emu.call(op="push", force=list(force), duration=duration, ramp=ramp, **extra)
        assert reply["ok"], reply
        return float(reply["t"])

    def plant_time(self) -> float:
        return float(self.emu.call(op="status")["t"])

    def ask(self, line: str) -> dict[str, Any]:
        return self.service.request(line)


@pytest.fixture(
    params=["er3a.yaml", "er3a_mixed.yaml", "two_axis", "canopen:er3a_canopen.yaml",
            "canopen:two_axis"]
)  # fmt: skip
def rig(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[DragRig]:
    """configs/er3a.yaml, configs/er3a_mixed.yaml (six drive models of six vendor profiles
    on the bus, issue 25) and the arm on three two-axis slaves (a synthetic multi-axis
    profile, tests/support/profiles.py TWO_AXIS), with the same figures; over CANopen
    configs/er3a_canopen.yaml and the arm on three two-axis nodes (CAN_TWO_AXIS)."""
    if request.param.startswith("canopen:"):
        yield from _can_rig(tmp_path, request.param.split(":", 1)[1])
        return
    with veth_pair("dm", "ds") as (master, slave):
        if request.param == "two_axis":
            from support.profiles import write_two_axis_config

            (tmp_path / "two_axis").mkdir()
            base = write_two_axis_config(tmp_path / "two_axis", master)
        else:
            base = ROOT / "configs" / request.param
        config, data = _config(tmp_path, master, base)
        with emulator(sim_ethercat_args(slave, config), tmp_path) as emu:
            service = ServiceRun(tmp_path, config)
            try:
                yield DragRig(data, emu, service)
            finally:
                service.close()


def _can_rig(tmp_path: Path, which: str) -> Iterator[DragRig]:
    if which == "two_axis":
        from support.profiles import write_can_two_axis_config

        (tmp_path / "two_axis").mkdir()
        base = write_can_two_axis_config(tmp_path / "two_axis")
    else:
        base = ROOT / "configs" / which
    with private_netns("hcd") as ns:
        config, data = _can_config(tmp_path, base)
        channel = data["bus"]["interface"]  # a group inside the test's own namespace
        with emulator(
            sim_canopen_args("udp_multicast", channel, config), tmp_path, netns=ns
        ) as emu:
            service = ServiceRun(tmp_path, config, netns=ns)
            try:
                yield DragRig(data, emu, service, "canopen")
            finally:
                service.close()


def _until_ok(r: DragRig, line: str, timeout: float = 30.0) -> dict[str, Any]:
    """Repeat a control request until it is accepted (e.g. drag mode once at standstill)."""
    last: dict[str, Any] = {}

    def accepted() -> bool:
        last.clear()
        last.update(r.ask(line))
        return bool(last.get("ok"))

    try:
        wait_for(accepted, timeout, f"{line!r} accepted", r.service.proc)
    except AssertionError as exc:
        raise AssertionError(f"{exc}: last answer {last}") from None
    return dict(last)


def _at_rest(r: DragRig, speed: float) -> bool:
    """Every joint of the true arm slower than ``speed`` [rad/s]."""
    return float(np.abs(r.emu.call(op="status")["qd"]).max()) < speed


def _rest_time(
    t: np.ndarray, tool_speed: np.ndarray, joint_moving: np.ndarray, t_release: float, fast: float
) -> tuple[float, float]:
    """(upper bound of the rest time [s] after ``t_release``, the sampling gap it hides):
    the first sample after the last one where the tool is faster than ``fast`` [m/s] or a
    joint moves (faster than the standstill speed; both criteria of drag_figures)."""
    after = np.flatnonzero(t >= t_release)
    moving = after[(tool_speed[after] > fast) | joint_moving[after]]
    last = int(moving[-1]) if moving.size else int(after[0]) - 1
    if last + 1 >= t.shape[0]:
        return np.inf, np.inf
    return float(t[last + 1] - t_release), float(t[last + 1] - t[max(last, 0)])


def _free_motion(r: DragRig, attempts: int = 3) -> int:
    """The demo path for MOVE_TIME of plant time, then hold until the arm is at rest (the
    deceleration from the path is part of the free motion); returns the number of collision
    stops it met. When this 2-core machine starves the loop (50 ms stalls, thousands of
    overruns: not under test here, as bus loss and overrun faults above) the monitor has
    stopped the free motion (full amplitude 2 of 5 runs, 0.4 amplitude 4 of 12; the two
    inspected: compute median 1.2-1.6 ms, above the 1 ms cycle), also while it came to rest
    ('mode move-to' then refused: a fault is latched): reset and move on; the friction
    learning skips stopped ticks."""
    s = r.service
    # classes the config only reports (log_failure: the flight recorder's writer starved on a
    # loaded machine) stop nothing: they are no stop of the free motion
    report_only = {k for k, v in r.data["safety"]["categories"].items() if v is None}
    for attempt in range(attempts):
        _until_ok(r, "mode move")
        t_moved = r.plant_time() + MOVE_TIME
        wait_for(
            lambda t=t_moved: r.plant_time() > t or s.status()["category"] >= 0,
            60,
            "the demo path moved",
            s.proc,
        )
        if s.status()["category"] < 0:
            _until_ok(r, "mode hold")
            wait_for(
                lambda: _at_rest(r, 0.002) or s.status()["category"] >= 0,
                30,
                "the arm at rest after the move",
                s.proc,
            )
        st = s.status()
        if st["category"] < 0:
            return attempt
        st["faults"] = [f for f in st["faults"] if f not in report_only]
        # a starved 200 Hz CANopen loop (a 136 ms stall) also tripped the following-error
        # monitor once in the free motion; neither is under test here
        tolerated = (["collision"], ["following_error"]) if r.bus == "canopen" else (["collision"],)
        assert st["faults"] in tolerated, f"the free motion was stopped: {st}"
        wait_for(lambda: s.status()["state"] == "stopped", 30, "stopped", s.proc)
        _until_ok(r, "reset")
        s.wait_state("running")
    raise AssertionError(f"the free motion was stopped {attempts} times")


def test_drag_after_collision_and_reset(rig: DragRig) -> None:
    from hofto_hw.config.loader import load_config
    from hofto_hw.experiments.drag_sim import tool_motion
    from hofto_hw.model import RobotModel

    r = rig.service
    r.start("--hold", log=True)
    r.wait_state("running")
    wait_for(lambda: r.status()["ticks"] > 500, 60, "500 ticks", r.proc)
    # contact-free motion first (the demo path, as the main job): the drag learns the
    # friction model's error from it (drag.friction_learning) and takes it off the estimate
    false_stops = _free_motion(rig)
    # back to the hold pose: the drag runs where --hold started (not where the path stopped)
    home = ",".join(repr(float(x)) for x in rig.data["robot"]["home"])
    _until_ok(rig, f"mode move-to {home}")
    wait_for(lambda: r.status()["mode"] == "hold", 60, "the move home done", r.proc)
    wait_for(lambda: _at_rest(rig, 0.002), 30, "the arm at rest at home", r.proc)
    # a hard knock at the tool: the monitor stops the arm (category 1)
    rig.push((0.0, 0.0, -80.0), 0.3)
    r.wait_latched("collision")
    assert r.status()["category"] == rig.data["safety"]["categories"]["collision"]
    wait_for(lambda: r.status()["state"] == "stopped", 30, "stopped", r.proc)
    t_knock_end = rig.plant_time() + 0.35
    wait_for(lambda: rig.plant_time() > t_knock_end, 30, "the knock over", r.proc)
    answer = _until_ok(rig, "reset")
    assert answer["message"].startswith("reset"), answer
    r.wait_state("running")
    _until_ok(rig, "mode drag")
    # the press enters dragging only from standstill (else it is refused, and the push would
    # meet an arm that holds): the re-enabled arm settles first
    wait_for(lambda: _at_rest(rig, 0.002), 30, "the arm at rest before the press", r.proc)
    t_tared = rig.plant_time() + TARE_WAIT
    wait_for(lambda: rig.plant_time() > t_tared, 30, "the tare's wait", r.proc)
    # the enabling input: a lease renewed while held, by a process of its own (a thread of
    # this test process was starved of CPU long enough for the lease to lapse mid-push)
    lease = LeaseHolder(r.socket)
    try:
        # the true arm's state at every plant step from the push on, traced by the emulator
        # (a test process starved of CPU would sample it too rarely to judge the window)
        t0 = rig.push((PUSH, 0.0, 0.0), PUSH_TIME, ramp=RAMP, trace=PUSH_TIME + 0.3)
        t_end = t0 + PUSH_TIME
        # for a failure's message: whether the press had entered dragging as the push began
        # (on the loaded machine the arm was seen not to follow the hand, cause not found)
        enabling = r.request("state").get("enabling")
        wait_for(lambda: rig.plant_time() > t_end + 0.3, 60, "the push over", r.proc)
        trace = rig.emu.call(op="trace_read")
        assert trace["done"], "the trace is not over"
        samples = list(zip(trace["t"], trace["q"], trace["qd"], strict=True))
        st = r.status()
        if st["mode"] != "drag":
            held = lease.release()
            _, s = r.terminate()
            raise AssertionError(
                f"left drag mode during the push: {st}; events {s['events']}; lease {held};"
                f" enabling as the push began {enabling}"
            )
        released = lease.release()
    finally:
        lease.close()
    assert released["ok"], released
    try:
        r.wait_latched("enabling_released")
    except AssertionError as exc:
        raise AssertionError(f"{exc}; enabling as the push began {enabling}") from None
    status = r.status()
    # the file leaves this class at the schema's default
    assert status["category"] == 2 == load_config(CONFIG).safety.categories.enabling_released

    wait_for(lambda: _at_rest(rig, 0.01), 30, "the arm at rest after the release", r.proc)
    code, s = r.terminate()
    assert code == 0
    kinds = [e["kind"] for e in s["events"] if e["category"] >= 0 or e["kind"] == "reset"]
    k = 2 * false_stops  # each false stop of the free motion: collision, reset
    assert kinds[k : k + 4] == ["collision", "reset", "enabling_released", "stop_request"], s[
        "events"
    ]
    assert first_event(s, "enabling_released")["category"] == 2

    cfg = load_config(CONFIG)
    t = np.array([x[0] for x in samples])
    q = np.array([x[1] for x in samples])
    qd = np.array([x[2] for x in samples])
    _, tool_v = tool_motion(RobotModel.from_config(cfg.robot), q, qd)
    window = (t >= t0 + SETTLE) & (t <= t_end - 0.1)
    assert window.sum() >= 10, int(window.sum())
    steady = float(tool_v[window, 0].mean())
    off_axis = float(np.linalg.norm(tool_v[window, 1:].mean(axis=0)))
    expected = PUSH / cfg.drag.damping
    tool_speed = np.linalg.norm(tool_v, axis=1)
    joint_moving = np.abs(qd).max(axis=1) > cfg.drag.standstill_speed
    fast = max(0.05 * steady, 1e-3)
    rest, gap = _rest_time(t, tool_speed, joint_moving, t_end, fast)
    print(
        f"FIGURE drag over {rig.bus} steady={steady * 1e3:.1f} mm/s expected="
        f"{expected * 1e3:.1f} mm/s off_axis={off_axis * 1e3:.2f} mm/s rest<={rest * 1e3:.0f} ms"
        f" (sampling gap {gap * 1e3:.0f} ms) samples={int(window.sum())}"
        f" overruns={s['overruns']} false_stops={false_stops}"
        f" lease_renew_late_max={released['renew_late_max_s'] * 1e3:.0f} ms"
    )
    assert abs(steady - expected) < 0.1 * expected, (steady, expected)
    can = rig.bus == "canopen"
    assert off_axis < (CAN_OFF_AXIS if can else 0.05) * expected, (off_axis, expected)
    if gap <= RESOLUTION:  # measurable: the samples bracket the rest instant closely enough
        assert rest <= (CAN_REST_WITHIN if can else REST_WITHIN), (rest, gap)
