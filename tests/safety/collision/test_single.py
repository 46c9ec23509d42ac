"""Tests of safety.collision.CollisionMonitor."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from pydantic import ValidationError

from hofto_hw.config.collision import CollisionConfig
from safety.collision import CollisionMonitor

DT = 0.01


def _monitor(**kw: object) -> CollisionMonitor:
    args: dict[str, object] = {"base": [10.0, 5.0], "debounce_time": 0.02, "release_time": 0.05}
    args.update(kw)
    return CollisionMonitor(CollisionConfig.model_validate(args))


def _run(mon: CollisionMonitor, tau: np.ndarray, qd: np.ndarray | None = None) -> np.ndarray:
    """Detected flag per sample for tau (N, n) and qd (N, n)."""
    qd = np.zeros_like(tau) if qd is None else qd
    return np.array([mon.update(tau[k], qd[k], DT) for k in range(tau.shape[0])])


def test_below_threshold_never_trips() -> None:
    mon = _monitor()
    tau = np.tile([9.9, -4.9], (200, 1))
    assert not _run(mon, tau).any()
    np.testing.assert_allclose(mon.ratio, [0.99, 0.98])


def test_trips_after_debounce_on_the_right_joint() -> None:
    mon = _monitor()
    tau = np.zeros((50, 2))
    tau[10:, 1] = -6.0
    det = _run(mon, tau)
    # above from sample 10; 0.02 s of debounce at 0.01 s per tick -> flagged at sample 11
    assert not det[:11].any() and det[11:].all()
    assert list(mon.joints) == [False, True]


def test_single_spike_is_debounced_but_not_without_debounce() -> None:
    tau = np.zeros((20, 2))
    tau[5, 0] = 50.0
    assert not _run(_monitor(), tau).any()
    det = _run(_monitor(debounce_time=0.0), tau)
    assert det[5] and not det[:5].any()


def test_hysteresis_holds_then_releases() -> None:
    mon = _monitor(release_ratio=0.8)
    tau = np.zeros((60, 2))
    tau[0:10, 0] = 12.0  # trip
    tau[10:30, 0] = 9.0  # 0.9 threshold: still in contact (above release ratio)
    tau[30:, 0] = 4.0  # released after release_time = 0.05 s
    det = _run(mon, tau)
    assert det[10:30].all()
    assert det[30:34].all() and not det[35:].any()


def test_velocity_and_acceleration_raise_the_threshold() -> None:
    mon = _monitor(velocity_gain=[20.0, 0.0], acceleration_gain=[0.0, 2.0], debounce_time=0.0)
    n = 100
    qd = np.zeros((n, 2))
    qd[:, 0] = 0.5  # 10 N·m more on joint 1
    t = np.arange(n) * DT
    qd[:, 1] = 0.3 * np.sin(2 * np.pi * 2.0 * t)  # |a| up to ~3.8 rad/s² on joint 2
    tau = np.tile([15.0, 0.0], (n, 1))
    assert not _run(mon, tau, qd).any()
    assert mon.threshold[0] == pytest.approx(20.0)
    still = _monitor(debounce_time=0.0)
    assert _run(still, tau).all()
    assert mon.accel.shape == (2,) and np.max(np.abs(mon.accel)) > 1.0


def test_reversal_margin_only_for_a_joint_that_was_moving() -> None:
    cfg = {"reversal_margin": [30.0, 30.0], "reversal_velocity": 0.05, "debounce_time": 0.0}
    n = 400
    t = np.arange(n) * DT
    qd = np.zeros((n, 2))
    qd[:, 0] = 0.8 * np.cos(2 * np.pi * 0.5 * t)  # reverses at t = 0.5, 1.5, ...
    qd[:, 1] = 0.01 * np.sin(2 * np.pi * 3.0 * t)  # a holding joint, small motion
    # friction-like spike at each reversal of joint 1, a 12 N·m push on joint 2
    tau = np.zeros((n, 2))
    rev = np.abs(qd[:, 0]) < 0.04
    tau[rev, 0] = 25.0
    tau[200:260, 1] = 12.0
    mon = _monitor(**cfg)
    flags = np.zeros((n, 2), dtype=bool)
    for k in range(n):
        mon.update(tau[k], qd[k], DT)
        flags[k] = mon.joints
    assert not flags[:, 0].any()  # reversals survived
    assert flags[200:260, 1].all()  # the push on the still joint is seen at base level
    plain = _monitor(debounce_time=0.0)
    assert _run(plain, tau, qd)[rev].all()  # without the margin every reversal trips


def test_reset_clears_state() -> None:
    mon = _monitor(debounce_time=0.0)
    mon.update(np.array([20.0, 0.0]), np.zeros(2), DT)
    assert mon.detected
    mon.reset(np.zeros(2))
    assert not mon.detected and not mon.joints.any()


def test_update_allocates_nothing() -> None:
    mon = _monitor(
        velocity_gain=[1.0, 1.0], acceleration_gain=[0.1, 0.1], reversal_margin=[5.0, 5.0]
    )
    tau = np.array([3.0, -2.0])
    qd = np.array([0.2, -0.1])
    for _ in range(10):
        mon.update(tau, qd, DT)
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    for _ in range(2000):
        mon.update(tau, qd, DT)
    grown = tracemalloc.get_traced_memory()[1] - before
    tracemalloc.stop()
    assert grown < 2000  # bytes: no array per tick (one (2,) array alone is ~100 bytes)


def test_config_lengths_are_checked() -> None:
    with pytest.raises(ValidationError, match="velocity_gain has 1 entries, base has 2"):
        CollisionConfig.model_validate({"base": [1.0, 2.0], "velocity_gain": [1.0]})
    with pytest.raises(ValidationError, match="base"):
        CollisionConfig.model_validate({"base": [0.0]})


# ---------------------------------------------------------------- non-finite inputs (issue 7)


def test_nan_velocity_reports_fault_and_detection_keeps_working() -> None:
    mon = CollisionMonitor(
        CollisionConfig.model_validate(
            {
                "base": [1.0, 1.0],
                "velocity_gain": [0.5, 0.5],
                "acceleration_gain": [0.1, 0.1],
                "reversal_margin": [2.0, 2.0],
                "debounce_time": 0.02,
            }
        )
    )
    zero = np.zeros(2)
    for _ in range(5):
        mon.update(zero, zero, DT)
    mon.update(zero, np.array([np.nan, 0.0]), DT)
    assert mon.fault_nonfinite
    assert list(mon.nonfinite) == [True, False]
    mon.update(zero, zero, DT)
    assert not mon.fault_nonfinite and not mon.nonfinite.any()
    assert np.all(np.isfinite(mon.threshold)) and np.all(np.isfinite(mon.accel))
    tau = np.array([100.0, 0.0])
    det = [mon.update(tau, zero, DT) for _ in range(5)]
    assert det[-1] and mon.joints[0]


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nonfinite_torque_is_a_fault_and_hides_no_collision_elsewhere(bad: float) -> None:
    mon = _monitor(debounce_time=0.0)
    qd = np.zeros(2)
    tau = np.array([bad, 50.0])
    assert mon.update(tau, qd, DT)
    assert mon.fault_nonfinite and list(mon.nonfinite) == [True, False]
    assert list(mon.joints) == [False, True]
    assert np.all(np.isfinite(mon.ratio))


def test_nonfinite_handling_allocates_nothing() -> None:
    mon = _monitor()
    tau = np.array([np.nan, 1.0])
    qd = np.array([0.1, np.inf])
    mon.update(tau, qd, DT)
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    for _ in range(2000):
        mon.update(tau, qd, DT)
    grown = tracemalloc.get_traced_memory()[1] - before
    tracemalloc.stop()
    assert grown < 2000
