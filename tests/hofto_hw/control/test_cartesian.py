"""A straight tool line as a joint path (hofto_hw/control/cartesian.py, runtime/teach.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hofto_hw.config.loader import load_config
from hofto_hw.control.cartesian import pose_of
from hofto_hw.errors import UserError
from hofto_hw.runtime import teach
from hofto_hw.runtime.compose import build_model

CONFIG = Path(__file__).resolve().parents[3] / "configs" / "er3a.yaml"


@pytest.fixture(scope="module")
def setup():
    cfg = load_config(CONFIG)
    model = build_model(cfg)
    return cfg, model, teach.motion_limits(cfg, model)


def test_the_tool_follows_the_line_and_ends_at_the_target(setup) -> None:
    cfg, model, limits = setup
    d = model.create_data()
    q0 = model.home.copy()
    p0 = pose_of(d, q0)
    target = p0 + np.array([0.05, 0.02, -0.03, 0.0, 0.0, 0.0])
    target[3:] = pose_of(d, q0 + np.array([0, 0, 0, 0.1, 0, 0.2]))[3:]  # and turn the tool
    pb = teach.plan_linear(target, q0, model, limits, 1e-3)
    assert np.abs(pose_of(d, pb.traj.q[-1]) - target).max() < 1e-6
    a, b = p0[:3], target[:3]
    u = (b - a) / np.linalg.norm(b - a)
    pts = np.array([d.tool_pose(q)[0] for q in pb.traj.q[::10]])
    off = np.linalg.norm((pts - a) - np.outer((pts - a) @ u, u), axis=1)
    assert off.max() < 1e-4  # on the line within 0.1 mm (the spline between samples)
    assert np.abs(pb.traj.qd[0]).max() == 0.0 and np.abs(pb.traj.qd[-1]).max() < 1e-9
    assert pb.mode == teach.MOVE_TO and pb.kind == "linear"


@pytest.mark.parametrize(
    ("delta", "needle"),
    [
        ((2.0, 0, 0), "leaves the arm's reach"),
        ((0, 0, -0.6), "outside"),  # through the base: a joint past its limit or no solution
    ],
)
def test_a_line_the_arm_cannot_follow_is_refused_before_moving(setup, delta, needle) -> None:
    cfg, model, limits = setup
    d = model.create_data()
    q0 = model.home.copy()
    target = pose_of(d, q0) + np.array([*delta, 0, 0, 0])
    with pytest.raises(UserError) as e:
        teach.plan_linear(target, q0, model, limits, 1e-3)
    assert "\n" not in str(e.value) and "move_linear" in str(e.value)
