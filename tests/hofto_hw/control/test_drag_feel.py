"""How the drag feels with a fast collision observer (issue 9's figures not met before):
no buzz while dragging, at rest within 100 ms of the release, the speed limit held by the
arm itself after an 80 N release, no false off-tool contact, an averaged tare, and the
collision monitor's hand share taken per observer row.

Closed loop in simulated time (the harness of hofto_hw/experiments/drag_sim.py, the loop's
observer gains, 10 % model error, sensor noise), deterministic; no timing assertions.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from hofto_hw.config.loader import load_config
from hofto_hw.control.drag import DragController
from hofto_hw.experiments.drag_sim import (
    ER3A,
    MAIN_JOB_PATH,
    MAIN_JOB_POSE,
    DragSim,
    ToolPush,
    drag_figures,
)
from hofto_hw.model.robot import RobotModel

PRESS = 0.3


def _pressed(t: float) -> bool:
    return t > PRESS


def _faster_hofto(tmp_path: Path, pole: float = 400.0) -> Path:
    """A copy of the ER3A config whose loop HOFTO (eq. 17, four gains placing the
    linearisation's poles at -300 rad/s) has its poles at ``-pole`` (the collision tuning's
    direction: faster and noisier)."""
    text = ER3A.read_text()
    for i, c in enumerate((4, 6, 4, 1), start=1):
        row = "[" + ", ".join([f"{c * 300.0**i}"] * 6) + "]"
        assert row in text, row
        text = text.replace(row, "[" + ", ".join([f"{c * pole**i}"] * 6) + "]")
    shutil.copytree(ER3A.parent / "er3a", tmp_path / "er3a")
    out = tmp_path / "er3a_fast.yaml"
    out.write_text(text)
    return out


def _push(sim: DragSim, force: tuple[float, float, float], end: float = 2.0):
    push = ToolPush(force, 0.8, end)
    sim.world.pushes.append(push)
    wrench: list[np.ndarray] = []
    run = sim.run(
        end + 0.6, pressed=_pressed, on_tick=lambda s: wrench.append(s.drag.wrench[:3].copy())
    )
    return run, push, np.array(wrench)


@pytest.fixture(scope="module")
def hofto_push():
    sim = DragSim(observer="hofto")
    run, push, wrench = _push(sim, (20.0, 0.0, 0.0))
    return sim, run, push, wrench


def test_no_buzz_while_dragging(hofto_push) -> None:
    # before: the fast HOFTO's estimate rang with the admittance at ~25 Hz, +-7 N across the
    # push (joint 1's friction near zero speed), the tool shook +-10 mm/s sideways
    _, run, push, wrench = hofto_push
    w = (run.t > push.start + 0.5) & (run.t < push.end - 0.05)
    assert wrench[w, 1].std() < 1.5, wrench[w].std(axis=0)
    assert run.tool_v[w, 1].std() < 3e-3, run.tool_v[w].std(axis=0)


def test_hofto_drag_figures_with_the_loop_gains(hofto_push) -> None:
    sim, run, push, _ = hofto_push
    fig = drag_figures(run, push, sim.drag_cfg.damping, sim.drag_cfg.standstill_speed)
    assert run.stop_tick == -1
    assert abs(fig["steady_speed_mps"] - 0.1) <= 0.01, fig
    assert fig["off_axis_mps"] < 0.05 * fig["steady_speed_mps"], fig
    assert fig["rest_time_ms"] <= 100.0, fig  # tool < 5 % of steady and joints at standstill


def test_a_faster_noisier_hofto_drags_without_false_stops(tmp_path: Path) -> None:
    # before: a faster HOFTO (Levant L = 50000) chattered enough for the off-tool check to
    # stop the drag (link 6)
    sim = DragSim(config=_faster_hofto(tmp_path), observer="hofto")
    run, push, _ = _push(sim, (20.0, 0.0, 0.0))
    fig = drag_figures(run, push, sim.drag_cfg.damping, sim.drag_cfg.standstill_speed)
    assert run.stop_tick == -1, (run.reason.max(), run.contact_link)
    assert abs(fig["steady_speed_mps"] - 0.1) <= 0.01, fig
    assert fig["rest_time_ms"] <= 100.0, fig


@pytest.mark.parametrize("gains", ["loop", "paper"])
@pytest.mark.parametrize("observer", ["hofto", "momentum"])
def test_releasing_a_hard_push_keeps_the_arm_under_the_speed_limit(
    observer: str, gains: str
) -> None:
    # before (HOFTO): 0.298 m/s after the release (the drives took up their following error
    # while the command still ran at the limit) and a false off-tool stop naming link 5;
    # then with the paper's (slower) gains 0.263 (HOFTO) and 0.254 m/s (momentum): the
    # estimate's lag kept the hand feed-forward pulling the arm back, and the drives took
    # that following error up above the command. The limit holds on the true arm.
    sim = DragSim(observer=observer, gains=gains)
    run, push, _ = _push(sim, (0.0, 80.0, 0.0))
    assert run.stop_tick == -1, (run.reason.max(), run.contact_link)
    speed = np.linalg.norm(run.tool_v, axis=1)
    limit = sim.drag_cfg.max_tool_speed
    assert speed.max() <= limit, speed.max()
    w = (run.t > 1.3) & (run.t < push.end - 0.05)
    assert speed[w].mean() > 0.85 * limit  # still dragged near the limit


def test_drag_in_the_main_jobs_conditions_stays_on_axis() -> None:
    # before: 7.2 mm/s off-axis here (7.3 in the main job itself, 7.7 % of the steady
    # speed): joints 1-3's friction differs from the model's by +0.37, -0.28, -0.23 N·m
    # once they move, a term that switches with the direction of motion which the tare at
    # rest cannot remove; it reads as 1.4 N sideways at the tool. The drag learns it from
    # the contact-free motion before (the main job's path) and takes it off the estimate.
    sim = DragSim(observer="hofto", payload=True, q0=MAIN_JOB_POSE)
    sim.free_motion(*MAIN_JOB_PATH, duration=3.0)
    assert sim.drag.friction is not None and sim.drag.friction.seconds > 2.0
    t0 = sim.t
    push = ToolPush((20.0, 0.0, 0.0), t0 + 0.8, t0 + 2.0)
    sim.world.pushes.append(push)
    run = sim.run(2.6, pressed=lambda t: t > t0 + 0.3)
    fig = drag_figures(run, push, sim.drag_cfg.damping, sim.drag_cfg.standstill_speed)
    assert run.stop_tick == -1, (run.reason.max(), run.contact_link)
    assert abs(fig["steady_speed_mps"] - 0.1) <= 0.01, fig
    assert fig["off_axis_mps"] < 0.05 * fig["steady_speed_mps"], fig
    assert fig["rest_time_ms"] <= 100.0, fig


def test_tare_is_the_averaged_estimate_not_one_sample() -> None:
    cfg = load_config(ER3A)
    model = RobotModel.from_config(cfg.robot)
    drag = DragController(cfg.drag, model, cfg.robot.gravity)
    q = np.array(cfg.robot.home)
    qd = np.zeros(model.n)
    drag.start(q)
    bias = np.array([1.0, -2.0, 0.5, 0.1, 0.0, 0.2])
    rng = np.random.default_rng(3)
    for _ in range(1000):  # 1 s at standstill, input not pressed: noise of 1 N·m
        drag.update(q, qd, bias + rng.normal(0.0, 1.0, model.n), 1e-3, False, False)
    last = bias + np.array([1.5, -1.5, 1.5, -1.5, 1.5, -1.5])  # the press tick's sample
    drag.update(q, qd, last, 1e-3, True, False)
    assert drag.active
    # before: the bias was the press tick's sample (1.5 N·m off on every joint here)
    np.testing.assert_allclose(drag.tau_bias, bias, atol=0.3)


def test_monitor_input_takes_each_rows_own_hand_share() -> None:
    cfg = load_config(ER3A)
    model = RobotModel.from_config(cfg.robot)
    drag = DragController(cfg.drag, model, cfg.robot.gravity)
    q = np.array(cfg.robot.home)
    qd = np.zeros(model.n)
    drag.start(q)
    zero = np.zeros(model.n)
    for _ in range(50):
        drag.update(q, qd, zero, 1e-3, False, False)
    drag.update(q, qd, zero, 1e-3, True, False)
    drag.jac.update(drag.q_cmd)
    hand = drag.jac.J[:3].T @ np.array([20.0, 0.0, 0.0])  # a 20 N hand at the tool
    # the fast row sees the whole hand, the slow row a third of it, the drag's own
    # (filtered) estimate a different share again: each row's share is its own
    rows = np.vstack([hand, hand / 3.0])
    drag.update(q, qd, hand, 1e-3, True, False)
    out = np.zeros_like(rows)
    drag.monitor_input(rows, out)
    np.testing.assert_allclose(out, np.zeros_like(rows), atol=1e-6)


@pytest.mark.parametrize("observer", ["hofto", "momentum"])
def test_paper_gains_rest_within_100_ms_and_release_is_seen_only_at_the_release(
    observer: str,
) -> None:
    # before: with the paper's HOFTO gains the arm rested 121 ms after the release: the
    # estimate of a letting-go hand falls ~110 N/s at the tool, and both filters of the
    # estimate-based release detector see it that slowly. The arm's own motion shows it
    # within ~20 ms (the feed-forward pulls it behind a steady command)
    sim = DragSim(observer=observer, gains="paper")
    push = ToolPush((20.0, 0.0, 0.0), 0.8, 2.0)
    sim.world.pushes.append(push)
    released: list[bool] = []
    run = sim.run(2.6, pressed=_pressed, on_tick=lambda s: released.append(s.drag._released))
    fig = drag_figures(run, push, sim.drag_cfg.damping, sim.drag_cfg.standstill_speed)
    assert run.stop_tick == -1, (run.reason.max(), run.contact_link)
    assert abs(fig["steady_speed_mps"] - 0.1) <= 0.01, fig
    assert fig["off_axis_mps"] < 0.05 * fig["steady_speed_mps"], fig
    assert fig["rest_time_ms"] <= 100.0, fig
    seen = np.array(released)
    pushing = (run.t > push.start) & (run.t < push.end - push.ramp)
    assert not seen[pushing].any(), run.t[pushing][seen[pushing]][:5]  # no false release
    after = (run.t >= push.end - push.ramp) & (run.t < push.end + 0.05)
    assert seen[after].any()  # the release itself is seen
