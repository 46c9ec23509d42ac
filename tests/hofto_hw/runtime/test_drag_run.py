"""Drag-teach through the whole loop (simulated clock, deterministic): exchange -> observers
-> drag controller -> safety -> command, with a scripted hand on the true simulated arm."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from support.alloc import tick_memory

from hofto_hw.config.models import SystemConfig
from hofto_hw.config.runtime import ScriptedDragConfig
from hofto_hw.control.joint_motion import DRAG, HOLD, MOVE
from hofto_hw.experiments.drag_sim import LinkPush, tool_motion
from hofto_hw.runtime.compose import build
from hofto_hw.runtime.drag_script import DragScript, drag_summary
from safety.stop import Fault
from tests.hofto_hw.runtime.conftest import CONFIG

ROOT = Path(__file__).resolve().parents[3]
SCRIPT = ScriptedDragConfig(
    reset=0.01, mode=0.05, press=0.1, push_start=0.3, push_end=1.5, release=1.7
)


def _drag_system(cfg: SystemConfig, enable: bool = True):
    """The arm holding at home (no demo path, no collision) with the scripted hand."""
    system = build(cfg, clock="sim", contact=False)
    script = DragScript(SCRIPT, system.bus.plant, system.rate_hz, enable=enable)
    system.tick.script = system.drag_script = script
    return system, script


def _events(system, kind: int) -> list[tuple[int, int, int]]:
    ev = system.tick.stop.events
    return [
        (int(ev.tick[i]), int(ev.joint[i]), int(ev.category[i]))
        for i in range(ev.count)
        if ev.kind[i] == kind
    ]


def test_push_with_enabling_drags_at_f_over_ba_and_release_holds(cfg: SystemConfig) -> None:
    system, script = _drag_system(cfg)
    system.loop.run(max_ticks=1000)
    assert system.tick.motion.mode == DRAG, system.tick.mode_result
    assert system.tick.drag.active
    w = system.tick.tick_rec["wrench"]  # the WrenchStamped record while dragging [N, N·m]
    assert abs(np.linalg.norm(w[:3]) - 20.0) < 2.0, w  # |F| (frame-independent)
    system.loop.run(max_ticks=1500)  # push ends at 1.5 s, release at 1.7 s, rest
    fig = drag_summary(script, cfg.drag.damping, cfg.drag.standstill_speed)
    expected = 20.0 / cfg.drag.damping
    assert fig["expected_speed_mps"] == expected
    assert abs(fig["steady_speed_mps"] - expected) < 0.1 * expected, fig
    released = _events(system, Fault.ENABLING_RELEASED)
    assert len(released) == 1 and released[0][2] == 2
    assert abs(released[0][0] - round(SCRIPT.release * system.rate_hz)) <= 1
    assert _events(system, Fault.COLLISION) == []
    assert system.tick.stop.category == 2
    assert np.abs(system.bus.plant.qd).max() < cfg.drag.standstill_speed
    assert system.tick.motion.mode == HOLD
    # the wrench topic carried the estimate while dragging (NaN outside drag mode)
    assert np.isnan(system.tick.tick_rec["wrench"]).all()


def test_nothing_moves_without_the_enabling_input(cfg: SystemConfig) -> None:
    system, script = _drag_system(cfg, enable=False)
    system.loop.run(max_ticks=250)
    assert system.tick.motion.mode == DRAG
    system.loop.run(max_ticks=750)
    # the collision monitor stays armed in drag mode: with no hand on the enabling input a
    # 20 N push is an external force like any other (here above joint 2's stop level)
    assert not system.tick.drag.active
    assert np.abs(system.tick.drag.qd_cmd).max() == 0.0
    k = script.k
    tool, _ = tool_motion(system.bus.plant.true_model, script.q[:k], script.qd[:k])
    moved = np.linalg.norm(tool - tool[0], axis=1).max()
    assert moved < 0.002, moved  # the hold deflects under 20 N, but does not follow it


def test_push_on_link_3_while_dragging_stops_and_names_the_link(cfg: SystemConfig) -> None:
    system, script = _drag_system(cfg)
    plant = system.bus.plant
    script.hand.pushes.append(
        LinkPush((0.0, 0.0, -40.0), plant.t + 0.8, plant.t + 1.2, link=3, ramp=0.02)
    )
    system.loop.run(max_ticks=1200)
    col = _events(system, Fault.COLLISION)
    assert col, "no stop for the push on link 3"
    tick_col, joint, category = col[0]
    assert joint == 2  # link 3 (the link after joint 3, 0-based joint index 2)
    assert category == cfg.safety.categories.collision
    assert 800 <= tick_col < 1000
    assert _events(system, Fault.ENABLING_RELEASED) == []
    system.loop.run(max_ticks=800)
    assert np.abs(plant.qd).max() < cfg.drag.standstill_speed


def test_drag_mode_refused_with_a_latched_fault(cfg: SystemConfig) -> None:
    system = build(cfg, clock="sim", contact=False)
    tick = system.tick
    tick.stop_requested = True
    system.loop.run(max_ticks=50)
    tick.mode_request = DRAG
    system.loop.run(max_ticks=5)
    assert tick.motion.mode != DRAG


def test_drag_tick_allocates_nothing_after_warm_up(cfg: SystemConfig) -> None:
    system = build(cfg, clock="sim", contact=False)
    tick = system.tick
    system.loop.run(max_ticks=200)
    tick.mode_request = DRAG
    tick.enable_input.pressed = True
    system.loop.run(max_ticks=1500)
    assert tick.motion.mode == DRAG and tick.drag.active
    grown, peak = tick_memory(system)
    assert tick.stop.latched == 0
    assert grown < 4000
    assert peak < 16000


def test_run_summary_has_the_drag_keys(tmp_path: Path) -> None:
    out = tmp_path / "summary.json"
    cmd = [sys.executable, "-m", "hofto_hw.cli", "run", "--config", str(CONFIG)]
    cmd += ["--clock", "sim", "--no-log", "--summary-json", str(out)]
    r = subprocess.run(
        cmd, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)}
    )
    assert r.returncode == 0, r.stderr
    s = json.loads(out.read_text())
    d = s["drag"]
    for key in ("steady_speed_mps", "expected_speed_mps", "rest_time_ms", "max_speed_mps"):
        assert isinstance(d[key], float), (key, d)
    assert d["expected_speed_mps"] == 0.1
    assert 0.0 <= d["drift_mps"] < 0.001
    assert d["steady_speed_mps"] > 0.5 * d["expected_speed_mps"]
    stops = [e["kind"] for e in s["events"] if e["category"] >= 0]
    assert stops == ["collision", "enabling_released"], stops  # the collision, then the drag
    assert s["observers"]["hofto"] is not None  # the scripted collision's delay survives
    assert "drag: steady tool speed" in r.stdout
    # run.drag.replay: the path taught from press to release, replayed through the loop
    rp = s["replay"]
    assert rp["completed"] is True, rp
    assert 0.0 < rp["max_path_error_mm"] <= 2.0, rp
    assert rp["max_jerk_ratio"] <= 1.01, rp
    assert "replay of the taught path: max tool path error" in r.stdout


def test_control_socket_mode_drag_and_enable(cfg: SystemConfig, tmp_path: Path) -> None:
    import threading

    from hofto_hw.client.connection import Connection
    from hofto_hw.control_plane.process import InProcessControl
    from hofto_hw.runtime.control_client import request

    drag = cfg.drag.model_copy(
        update={"enable_input": cfg.drag.enable_input.model_copy(update={"source": "socket"})}
    )
    system = build(cfg.model_copy(update={"drag": drag}), clock="sim", contact=False)
    tick = system.tick
    done = threading.Event()
    sock = tmp_path / "control.sock"
    server = InProcessControl(sock, system)
    server.start()
    runner = threading.Thread(target=lambda: system.loop.run(should_stop=done.is_set))
    runner.start()
    try:
        end = time.monotonic() + 30.0
        while system.loop.ticks < 600 and time.monotonic() < end:
            time.sleep(0.01)  # the arm settles in hold after the drives are enabled
        with Connection(sock) as conn:  # a client that holds the lease, then stops renewing
            r = conn.call({"cmd": "mode", "mode": "drag"})
            assert r["ok"], r
            assert request(sock, "status")["mode"] == "drag"
            end = time.monotonic() + 30.0
            while not tick.drag.active and time.monotonic() < end:
                assert conn.call({"cmd": "enable", "on": True})["ok"]  # renewed
                time.sleep(0.02)
            assert tick.drag.active
            # another client may read, not move nor take the enabling input
            other = request(sock, "enable on")
            assert not other["ok"] and "held by client" in other["message"], other
            # no renewal: the lease lapses (while the holder is still connected)
            end = time.monotonic() + 30.0
            while not tick.stop.latched and time.monotonic() < end:
                time.sleep(0.01)
            assert tick.stop.latched_names() == ["enabling_released"]
            assert tick.stop.category == 2
        r = request(sock, "mode drag")
        assert not r["ok"] and "reset" in r["message"]
    finally:
        done.set()
        runner.join()
        server.close()
        system.close()


def test_momentum_drags_while_the_monitor_decides_on_hofto(cfg: SystemConfig) -> None:
    # before: the hand's share came from the drag's (momentum) estimate and was taken off
    # the HOFTO row too; HOFTO sees the push first, so its onset read as a collision
    drag = cfg.drag.model_copy(update={"observer": "momentum"})
    assert cfg.safety.collision.observer == "hofto"
    system, script = _drag_system(cfg.model_copy(update={"drag": drag}))
    system.loop.run(max_ticks=1600)
    assert _events(system, Fault.COLLISION) == []
    fig = drag_summary(script, cfg.drag.damping, cfg.drag.standstill_speed)
    assert abs(fig["steady_speed_mps"] - 0.1) < 0.01, fig


def test_the_loop_learns_the_friction_error_in_contact_free_motion_only(cfg: SystemConfig) -> None:
    # the drag's friction-error estimate (control/friction_residual.py) learns from the tick
    # outside drag mode while the arm moves with no contact and no stop: not at rest, not
    # while a stop is active
    system = build(cfg, clock="sim", contact=False)
    tick = system.tick
    fr = tick.drag.friction
    assert fr is not None
    system.loop.run(max_ticks=300)  # holding at rest
    assert fr.seconds == 0.0
    tick.mode_request = MOVE  # the demo path
    system.loop.run(max_ticks=1500)
    assert fr.seconds > 0.3, fr.seconds
    tick.stop_requested = True  # category 1: the arm ramps down, nothing learned meanwhile
    system.loop.run(max_ticks=1)  # (the request's own tick is judged before it latches)
    learned = fr.seconds
    system.loop.run(max_ticks=300)
    assert tick.stop.category == 1
    assert fr.seconds == learned
    # what it learned is the true arm's: joint 1's Coulomb friction is 0.3 N·m above the
    # model's, which the estimate reads as -0.3 N·m times the direction of motion
    fr.solve()
    true = system.bus.plant.true_model.friction
    d_c = -(true.coulomb[0] - system.model.friction.coulomb[0])
    assert abs(fr.coef[0, 1] - d_c) < 0.2, (fr.coef[0], d_c)
