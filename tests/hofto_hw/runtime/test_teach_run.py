"""Teach and play through the whole loop (simulated clock, deterministic): 10 s of drag
recorded by the tick, the file written off the tick, replayed as REPLAY mode (move to the
start + the time-scaled path), a collision during the replay, a jerk-limited move to a joint
target, and the allocation-free REPLAY tick."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from support.alloc import tick_memory

from hofto_hw.config.loader import load_config
from hofto_hw.config.models import ExternalTorqueConfig, SystemConfig
from hofto_hw.config.runtime import ScriptedDragConfig
from hofto_hw.control.joint_motion import DRAG, HOLD, MOVE_TO, REPLAY
from hofto_hw.control.taught_path import load_taught_path
from hofto_hw.experiments.drag_sim import ToolPush, tool_motion
from hofto_hw.runtime import teach
from hofto_hw.runtime.compose import build
from hofto_hw.runtime.drag_script import DragScript
from hofto_hw.runtime.summary import build_summary, format_summary
from safety.stop import Fault
from tests.hofto_hw.runtime.conftest import CONFIG, run_until

# 15 N pushes with 0.3 s ramps: x, then y, then back up-left (the tool moves ~0.2 m in x, y)
TEACH = ScriptedDragConfig(
    reset=0.01,
    mode=0.05,
    press=0.1,
    push_start=0.5,
    push_end=3.5,
    release=10.2,
    force=(15.0, 0.0, 0.0),
    ramp=0.3,
)
MORE_PUSHES = [(3.5, 6.5, (0.0, 15.0, 0.0)), (6.5, 9.5, (-12.0, -7.5, 7.5))]


def _events(system, kind: int) -> list[tuple[int, int, int]]:
    ev = system.tick.stop.events
    return [
        (int(ev.tick[i]), int(ev.joint[i]), int(ev.category[i]))
        for i in range(ev.count)
        if ev.kind[i] == kind
    ]


@pytest.fixture(scope="module")
def taught(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    """10 s of scripted drag through the loop with a Recording handed over with the drag
    request, as ``mode drag --record FILE`` does; the file is saved off the tick once the
    drag ended."""
    cfg = load_config(CONFIG)
    system = build(cfg, clock="sim", contact=False)
    plant, tick = system.bus.plant, system.tick
    script = DragScript(TEACH, plant, system.rate_hz)
    for a, b, f in MORE_PUSHES:
        script.hand.pushes.append(ToolPush(f, plant.t + a, plant.t + b, TEACH.ramp))
    tick.script = script
    file = teach.check_output(tmp_path_factory.mktemp("teach") / "taught.csv", force=False)
    rec = teach.Recording(file, False, system.model, capacity=12000)
    script.recording = rec  # handed to the tick as record_request with the drag request
    run_until(system, lambda: tick.motion.mode == DRAG, 200)
    assert tick.recording is rec and tick.record_request is None
    states = set()
    run_until(system, lambda: states.add(rec.state) or rec.state == teach.FINISHED, 11000)
    assert teach.save_finished(tick) == rec.message
    info = {
        "states": states,
        "count": rec.recorder.count,
        "state": rec.state,
        "message": rec.message,
        "released": _events(system, Fault.ENABLING_RELEASED),
        "collisions": _events(system, Fault.COLLISION),
        "model": system.model,
    }
    system.close()
    return file, info


def _holding(cfg: SystemConfig):
    """A fresh arm holding at home, settled."""
    system = build(cfg, clock="sim", contact=False)
    tick = system.tick
    system.loop.run(max_ticks=300)
    assert tick.motion.mode == HOLD and tick.stop.latched == 0
    return system


def _play(system, pb: teach.Playback) -> None:
    tick = system.tick
    tick.mode_result = ""
    tick.play_request = pb
    tick.mode_request = pb.mode
    run_until(system, lambda: tick.mode_result != "", 5)
    assert tick.mode_result == "playing", tick.mode_result
    assert tick.motion.mode == pb.mode and tick.play_request is None


def test_drag_record_writes_the_taught_path(taught) -> None:
    file, info = taught
    assert info["collisions"] == []
    assert len(info["released"]) == 1  # the drag ended by letting go of the enabling input
    assert {teach.ARMED, teach.RECORDING, teach.FINISHED} <= info["states"]
    assert info["state"] == teach.SAVED, info["message"]
    assert str(file) in info["message"]
    path = load_taught_path(file, info["model"])
    # recorded while the hand held the enabling input: 0.1 s .. 10.2 s
    assert path.t.shape[0] == info["count"]
    assert abs(path.t[-1] - (TEACH.release - TEACH.press)) < 0.01
    tool, _ = tool_motion(info["model"], path.q, np.zeros_like(path.q))
    assert np.ptp(tool[:, 0]) > 0.1 and np.ptp(tool[:, 1]) > 0.1  # a real path was taught


def test_replay_through_the_loop_follows_the_taught_path(cfg: SystemConfig, taught) -> None:
    file, _ = taught
    system = _holding(cfg)
    tick, model = system.tick, system.model
    limits = teach.motion_limits(cfg, model)
    pb = teach.plan_replay(file, tick.motion.q.copy(), model, limits, 1.0 / system.rate_hz)
    _play(system, pb)
    run_until(system, lambda: tick.motion.mode == HOLD, pb.traj.q.shape[0] + 10)
    system.loop.run(max_ticks=300)
    assert pb.completed and tick.stop.latched == 0
    fig = pb.figures(model)
    print("replay figures", fig)
    assert fig["max_path_error_mm"] <= 2.0, fig
    assert fig["max_jerk_ratio"] <= 1.01, fig  # peaks found on a 1 ms grid
    assert np.all(np.abs(pb.traj.qd) <= limits.velocity * 1.001)
    taught_path = load_taught_path(file, model)
    end = np.abs(system.group.q - taught_path.q[-1]).max()
    assert end < 2e-3, end
    s = build_summary(system, None, "test")
    assert s["replay"]["max_path_error_mm"] == fig["max_path_error_mm"]
    assert s["replay"]["completed"] is True
    assert "replay of the taught path: max tool path error" in format_summary(s)
    system.close()


def test_collision_during_replay_is_stopped_by_the_monitor(cfg: SystemConfig, taught) -> None:
    file, _ = taught
    system = _holding(cfg)
    tick, model, plant = system.tick, system.model, system.bus.plant
    limits = teach.motion_limits(cfg, model)
    pb = teach.plan_replay(file, tick.motion.q.copy(), model, limits, 1.0 / system.rate_hz)
    start = pb.traj.segments[1]  # the contact hits while following the path
    t_hit = plant.t + (start + 1500) / system.rate_hz
    onset = tick.tick + start + 1500  # the tick whose exchange first carries the contact
    amp = [0.0, 25.0, 0.0, 0.0, 0.0, 0.0]
    plant.external.components.append(
        ExternalTorqueConfig(kind="constant", start=t_hit, duration=0.3, amplitude=amp)
    )
    _play(system, pb)
    run_until(system, lambda: tick.stop.latched != 0, start + 2500)
    col = _events(system, Fault.COLLISION)
    assert col and col[0][2] == cfg.safety.categories.collision
    assert col[0][1] == 1  # the link the contact is on
    assert 0 <= col[0][0] - onset < 50, (col, onset)  # detected within 50 ms
    system.loop.run(max_ticks=1000)
    assert tick.motion.mode != REPLAY and not pb.completed
    assert np.abs(plant.qd).max() < 0.01
    s = build_summary(system, None, "test")
    assert s["replay"]["completed"] is False
    assert [e["kind"] for e in s["events"] if e["category"] >= 0] == ["collision"]
    system.close()


def test_move_to_joint_target_reaches_it_within_jerk_limits(cfg: SystemConfig) -> None:
    system = _holding(cfg)
    tick, model = system.tick, system.model
    target = model.home + np.array([0.3, -0.2, 0.25, 0.4, -0.3, 0.5])
    limits = teach.motion_limits(cfg, model)
    dt = 1.0 / system.rate_hz
    pb = teach.plan_move(target, tick.motion.q.copy(), model, limits, dt)
    _play(system, pb)
    assert tick.motion.mode == MOVE_TO
    run_until(system, lambda: tick.motion.mode == HOLD, pb.traj.q.shape[0] + 10)
    system.loop.run(max_ticks=500)
    assert pb.completed and tick.stop.latched == 0
    assert np.abs(system.group.q - target).max() < 2e-3
    assert np.abs(system.bus.plant.q - target).max() < 2e-3
    # ruckig: time-optimal within the limits (sampled jerk of the command)
    assert pb.max_jerk_ratio <= 1.001, pb.max_jerk_ratio
    assert np.all(np.abs(pb.traj.qd) <= limits.velocity * 1.0001)
    assert np.all(np.abs(pb.traj.qdd) <= limits.acceleration * 1.0001)
    s = build_summary(system, None, "test")
    assert s["move"]["completed"] is True and s["move"]["final_error_rad"] < 2e-3
    system.close()


def test_play_refused_when_the_hold_moved_or_not_holding(cfg: SystemConfig) -> None:
    system = _holding(cfg)
    tick, model = system.tick, system.model
    limits = teach.motion_limits(cfg, model)
    q0 = tick.motion.q.copy()
    pb = teach.plan_move(q0 + 0.1, q0 + 0.01, model, limits, 1.0 / system.rate_hz)
    tick.play_request = pb
    tick.mode_request = pb.mode
    system.loop.run(max_ticks=2)
    assert tick.mode_result.startswith("refused: the hold moved")
    assert tick.motion.mode == HOLD and tick.playback is None
    tick.stop_requested = True
    system.loop.run(max_ticks=50)
    pb = teach.plan_move(q0 + 0.1, tick.motion.q.copy(), model, limits, 1.0 / system.rate_hz)
    tick.play_request = pb
    tick.mode_request = pb.mode
    system.loop.run(max_ticks=2)
    assert tick.mode_result == "refused: a fault is latched, reset first"
    assert tick.mode_request == -1 and tick.play_request is None  # not kept for the reset
    assert tick.motion.mode == HOLD and tick.playback is None
    system.close()


def test_replay_tick_allocates_nothing(cfg: SystemConfig, taught) -> None:
    file, _ = taught
    system = _holding(cfg)
    tick, model = system.tick, system.model
    limits = teach.motion_limits(cfg, model)
    pb = teach.plan_replay(file, tick.motion.q.copy(), model, limits, 1.0 / system.rate_hz)
    _play(system, pb)
    system.loop.run(max_ticks=pb.traj.segments[1] + 200)  # on the path
    assert tick.motion.mode == REPLAY
    grown, peak = tick_memory(system)
    assert tick.motion.mode == REPLAY and tick.stop.latched == 0
    assert pb.executed.count > 3000
    assert grown < 4000
    assert peak < 16000
    system.close()
