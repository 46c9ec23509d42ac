"""The holding torque of the arm with a payload (hofto_hw.model.holding): equal to the gravity
of a model carrying the payload, its worst case within the joint limits no smaller than any
pose sampled apart from it, and the one-line refusal naming the joint, the torque and the
limit at the current pose or at the worst pose."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hofto_hw.config.loader import load_config
from hofto_hw.model.holding import HoldingTorque
from hofto_hw.model.payload import Payload
from hofto_hw.runtime.compose import build_model

CONFIG = Path(__file__).resolve().parents[3] / "configs" / "er3a.yaml"
LOAD = Payload(3.0, (0.0, 0.0, 0.05))


@pytest.fixture(scope="module")
def arm():
    cfg = load_config(CONFIG)
    model = build_model(cfg)
    return cfg, model, HoldingTorque(model)


def test_the_holding_torque_is_the_gravity_of_the_arm_carrying_the_payload(arm) -> None:
    cfg, model, hold = arm
    rng = np.random.default_rng(7)
    lim = model.limits
    for _ in range(5):
        q = lim.position_lower + rng.random(model.n) * (lim.position_upper - lim.position_lower)
        np.testing.assert_allclose(hold.at(q, LOAD), _gravity_with(cfg, q, LOAD), atol=1e-9)
        assert np.abs(hold.at(q, LOAD) - _gravity_with(cfg, q, Payload(0.0, (0, 0, 0)))).max() > 0.1


def _gravity_with(cfg, q: np.ndarray, payload: Payload) -> np.ndarray:
    """g(q) of a model whose only payload is ``payload`` (built without safety.payload)."""
    from hofto_hw.model.payload import LinkSwap, bare_link, link_numbers

    model = build_model(cfg)
    swap = LinkSwap(model)
    np.copyto(swap.values, link_numbers(model, bare_link(model), payload))
    swap.apply(payload)
    return model.create_data().gravity(q)


def test_the_worst_case_is_no_smaller_than_any_pose_within_the_limits(arm) -> None:
    cfg, model, hold = arm
    h = hold.check(np.zeros(model.n), LOAD)
    rng = np.random.default_rng(11)
    lo, hi = hold.lower, hold.upper
    seen = np.zeros(model.n)
    for q in lo + rng.random((3000, model.n)) * (hi - lo):
        seen = np.maximum(seen, np.abs(hold.at(q, LOAD)))
    assert (h.worst >= seen - 1e-9).all(), (h.worst, seen)
    for j in range(model.n):  # reached at the pose it names, inside the limits
        q = h.worst_q[j]
        assert (q >= lo).all() and (q <= hi).all()
        assert abs(hold.at(q, LOAD)[j]) == pytest.approx(h.worst[j], rel=1e-9)
    assert h.worst[1] > 40.0  # the shoulder, arm stretched out with 3 kg (er3a: 48 N·m)


def test_a_payload_that_does_not_fit_is_refused_naming_the_joint_torque_and_limit(arm) -> None:
    cfg, model, hold = arm
    keep = model.limits.torque.copy()
    try:
        model.limits.torque[1] = 45.0  # the shoulder's limit below the worst case with 3 kg
        home = np.array(cfg.robot.home)
        assert hold.refusal(home, Payload(0.5, (0.0, 0.0, 0.05))) == ""
        why = hold.refusal(home, LOAD)  # fits where it is, not stretched out
        assert why.startswith("joint_2 would hold 48.")
        assert "at a pose within the joint limits (q = [" in why
        assert why.endswith("rad), more than its torque limit 45 N·m"), why
        worst_q = hold.check(home, LOAD).worst_q[1]
        why = hold.refusal(worst_q, LOAD)  # where the arm is now
        assert why.startswith("joint_2 would hold 48.") and "at the current pose" in why, why
        assert why.endswith("more than its torque limit 45 N·m")
        why = hold.refusal(home, Payload(0.5, (0.0, 0.0, 0.05)), fraction=0.5)
        assert (
            why.startswith("joint_2 would hold ") and "more than 0.5 x its torque limit 45" in why
        )
        assert "\n" not in why
    finally:
        model.limits.torque[:] = keep
