"""Drive torque-scale calibration with a known load (identify/drive_gains.py)."""

from __future__ import annotations

import numpy as np
import pytest

from hofto_hw.errors import UserError
from hofto_hw.identify.drive_gains import (
    KnownLoad,
    estimate_drive_gains,
    parse_known_load,
)
from hofto_hw.identify.pipeline import Samples, nominal_theta
from hofto_hw.identify.regressor import N_RIGID, Regressor
from tests.hofto_hw.identify.conftest import smooth_motion

TRUE_SCALE = np.array([1.12, 0.9, 1.06, 1.0, 0.93, 1.08])  # true gain / configured gain
CONFIGURED = np.array([10.0, 11.0, 8.0, 9.0, 9.5, 10.0])


def _runs(model, mass: float, com_first_moment: np.ndarray, quasi_static: bool = False):
    """An unloaded and a loaded run of the ER3A; torque as read on the configured gains
    (true torque / TRUE_SCALE) with 0.05 N·m noise. ``quasi_static``: the loaded run only
    holds poses (qd = qdd = 0), so the load's weight is all it adds."""
    reg = Regressor(model.pin_model, model.friction.smooth_velocity)
    theta = nominal_theta(model)
    link = model.pin_model.frames[model.tool_frame_id].parentJoint - 1
    rng = np.random.default_rng(3)
    out = []
    for seed, m in ((1, 0.0), (2, mass)):
        _, q, qd, qdd = smooth_motion(model.n, 20.0, 50.0, seed=seed)
        if quasi_static and m > 0:
            qd[:] = qdd[:] = 0.0
        H = reg.stack(q, qd, qdd)
        tau = (H[:, : theta.size] @ theta).reshape(q.shape[0], model.n)
        if m > 0:
            cols = H[:, N_RIGID * link : N_RIGID * link + 4]
            tau += (cols @ np.r_[m, com_first_moment]).reshape(q.shape[0], model.n)
        tau0 = tau / TRUE_SCALE + rng.normal(0.0, 0.05, tau.shape)
        out.append(Samples(q, qd, qdd, tau0, f"run{seed}"))
    return out


def test_gains_recovered_with_std_and_every_joint_calibrated(er3a_model) -> None:
    unloaded, loaded = _runs(er3a_model, 3.0, np.array([0.06, -0.03, 0.24]))
    est = estimate_drive_gains(
        er3a_model,
        [unloaded],
        [KnownLoad(loaded, 3.0)],
        CONFIGURED,
        smooth_velocity=er3a_model.friction.smooth_velocity,
    )
    assert est.calibrated.all()
    assert np.allclose(est.scale, TRUE_SCALE, rtol=0.015), est.scale
    # the std dev is an honest spread: positive, small, and the error within a few of them
    assert np.all(est.std > 0) and np.all(est.std < 0.01 * est.gains)
    assert np.all(np.abs(est.gains - CONFIGURED * TRUE_SCALE) < 4 * est.std), est.gains
    # the load's com comes back in the tool frame too (first moments / mass)
    assert est.load_com[0].shape == (3,)


def test_a_joint_the_load_does_not_excite_keeps_its_configured_gain(er3a_model) -> None:
    # the weight of a load held still puts no torque on the vertical first axis
    unloaded, loaded = _runs(er3a_model, 3.0, np.array([0.06, -0.03, 0.24]), quasi_static=True)
    est = estimate_drive_gains(
        er3a_model,
        [unloaded],
        [KnownLoad(loaded, 3.0)],
        CONFIGURED,
        smooth_velocity=er3a_model.friction.smooth_velocity,
    )
    names = er3a_model.joint_names
    assert est.weak_joints(names) == [names[0]]
    assert est.gains[0] == CONFIGURED[0]  # kept
    assert est.load_snr[0] < 1e-6 < est.load_snr[1]
    assert np.allclose(est.scale[1:], TRUE_SCALE[1:], rtol=0.02)


def test_a_load_too_light_to_excite_anything_is_refused(er3a_model) -> None:
    unloaded, loaded = _runs(er3a_model, 1e-4, np.zeros(3))
    with pytest.raises(UserError, match=r"run2: the known load does not excite any joint"):
        estimate_drive_gains(
            er3a_model,
            [unloaded],
            [KnownLoad(loaded, 1e-4)],
            CONFIGURED,
            smooth_velocity=er3a_model.friction.smooth_velocity,
        )


@pytest.mark.parametrize(
    ("spec", "needle"),
    [
        ("run.csv", "expected FILE:KG"),
        ("run.csv:", "expected FILE:KG"),
        (":2.8", "expected FILE:KG"),
        ("run.csv:heavy", "'heavy' is not a number"),
        ("run.csv:nan", "finite number > 0"),
        ("run.csv:inf", "finite number > 0"),
        ("run.csv:0", "finite number > 0"),
        ("run.csv:-2.8", "finite number > 0"),
    ],
)
def test_malformed_known_load_is_one_line(spec: str, needle: str) -> None:
    with pytest.raises(UserError, match=needle) as info:
        parse_known_load(spec)
    assert "\n" not in str(info.value)


def test_known_load_with_rows_keeps_the_row_range() -> None:
    assert parse_known_load("a/run.csv@10:500:2.805") == ("a/run.csv@10:500", 2.805)
