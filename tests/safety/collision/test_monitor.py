"""The one collision monitor (safety/collision/): both config forms map onto it, the mean
fusion, the full threshold formula in the loop's levels, and the tool-force limit."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from pydantic import ValidationError

from hofto_hw.config.collision import CollisionConfig
from hofto_hw.config.safety import CollisionLevelsConfig, StopCategories
from hofto_hw.control.wrench import ToolJacobian
from safety.collision import COLLIDED, CollisionLevels, CollisionMonitor, from_thresholds
from safety.stop import Fault, StopController

DT = 1e-3


def _levels(**kw) -> CollisionLevelsConfig:
    base = {
        "observer": "both",
        "contact": {"nominal": [2.0, 2.0], "acceleration": [3.0, 3.0]},
        "collision": {"nominal": [5.0, 5.0], "acceleration": [8.0, 8.0]},
        "release_time": 0.01,
    }
    base.update(kw)
    return CollisionLevelsConfig.model_validate(base)


def _tick(mon: CollisionLevels, stop: StopController, est, n: int = 2, q=None) -> bool:
    stop.begin_tick(stop.tick + 1)
    z = np.zeros(n)
    flags = mon.update(stop, np.asarray(est, float), z if q is None else q, z, z, DT)
    return bool(flags & COLLIDED)


@pytest.mark.parametrize(
    ("rows", "any_", "all_", "mean"),
    [
        ([6.5, 4.5], True, False, True),  # ratios 1.3, 0.9: mean 1.1
        ([6.5, 2.5], True, False, False),  # 1.3, 0.5: mean 0.9, one row alone trips any
        ([5.5, 5.5], True, True, True),
        ([4.5, 4.5], False, False, False),
    ],
)
def test_mean_fusion_decides_on_the_mean_ratio(rows, any_, all_, mean) -> None:
    for logic, expected in (("any", any_), ("all", all_), ("mean", mean)):
        mon = CollisionLevels(_levels(logic=logic), ["hofto", "momentum"])
        stop = StopController.from_config(StopCategories())
        assert _tick(mon, stop, [[rows[0], 0.0], [rows[1], 0.0]]) is expected, logic
        assert stop.is_latched(Fault.COLLISION) is expected
        if logic == "mean":
            assert mon.ratios[1, 2, 0] == pytest.approx((rows[0] + rows[1]) / 2 / 5.0)
            assert list(mon.collision_joints) == [expected, False]


def test_mean_fusion_ignores_non_deciding_rows_and_holds_on_a_non_finite_row() -> None:
    cfg = _levels(logic="mean", debounce_time=0.002)
    mon = CollisionLevels(cfg, ["hofto", "eso", "momentum"])  # eso does not decide
    stop = StopController.from_config(StopCategories())
    _tick(mon, stop, [[6.0, 0.0], [100.0, 0.0], [6.0, 0.0]])
    assert mon.ratios[1, 3, 0] == pytest.approx(1.2)  # eso's 20 is not in the mean
    _tick(mon, stop, [[np.nan, 0.0], [0.0, 0.0], [6.0, 0.0]])  # held, neither trips nor resets
    assert not mon.collision and stop.is_latched(Fault.NON_FINITE)
    _tick(mon, stop, [[6.0, 0.0], [0.0, 0.0], [6.0, 0.0]])  # 2 ms above now: trips
    assert mon.collision


def test_levels_config_takes_the_full_threshold_formula_of_a_thresholds_file() -> None:
    """The loop's levels and a thresholds file's monitor are one formula: the same terms give
    the same thresholds, tick by tick, on the same motion."""
    terms = {
        "velocity_gain": [1.0, 0.5],
        "acceleration_gain": [0.2, 0.1],
        "reversal_margin": [3.0, 2.0],
        "standstill_margin": [2.0, 1.0],
        "standstill_time": 0.05,
    }
    levels = CollisionLevels(
        _levels(
            observer="hofto",
            collision={"nominal": [5.0, 4.0], "acceleration": [5.0, 4.0]},
            **terms,
        ),
        ["hofto"],
    )
    single = CollisionMonitor(CollisionConfig(base=[5.0, 4.0], **terms))
    stop = StopController.from_config(StopCategories())
    t = np.arange(600) * DT
    qd = np.stack([0.5 * np.cos(2 * np.pi * 2 * t), 0.02 * np.sin(2 * np.pi * 5 * t)], axis=1)
    qd[300:] = 0.0
    z = np.zeros(2)
    for i in range(600):
        stop.begin_tick(i + 1)
        levels.update(stop, np.zeros((1, 2)), z, qd[i], z, DT)
        single.update(z, qd[i], DT)
        np.testing.assert_array_equal(levels.threshold[1, 0], single.threshold)
    assert levels.threshold[1, 0, 0] > 5.5  # the terms were active, not only the base


def test_thresholds_file_rows_keep_their_own_thresholds_and_must_share_filters() -> None:
    a = CollisionConfig(base=[2.0, 2.0], debounce_time=0.0)
    b = CollisionConfig(base=[4.0, 4.0], debounce_time=0.0)
    mon = CollisionLevels.from_params(from_thresholds({"hofto": a, "momentum": b}, logic="mean"))
    assert mon.levels == ("collision",) and not mon.contact
    assert mon.step(np.array([[3.0, 0.0], [3.0, 0.0]]), np.zeros(2), None, DT, 1)  # 1.5, .75
    assert list(mon.first_tick) == [1, -1]  # per row: hofto crossed, momentum did not
    with pytest.raises(ValueError, match="moving_time"):
        from_thresholds({"a": a, "b": b.model_copy(update={"moving_time": 1.0})})
    with pytest.raises(ValueError, match="deciding rows"):
        from_thresholds({"a": a}, deciding=["b"])


def test_reports_only_when_something_happens() -> None:
    mon = CollisionLevels(_levels(), ["hofto", "momentum"])
    stop = StopController.from_config(StopCategories())
    for _ in range(50):
        _tick(mon, stop, [[1.0, 0.0], [1.0, 0.0]])
    assert stop.events.count == 0
    _tick(mon, stop, [[2.5, 0.0], [0.0, 0.0]])
    assert stop.events.count == 1  # the contact, once


# ------------------------------------------------------------------ tool force


def _tool_setup(model, limit: float):
    cfg = _levels(
        observer="hofto",
        contact={"nominal": [200.0] * 6, "acceleration": [200.0] * 6},
        collision={"nominal": [400.0] * 6, "acceleration": [400.0] * 6},
        tool_force=limit,
    )
    mon = CollisionLevels(cfg, ["hofto", "momentum"], model)
    q = model.home + np.array([0.2, -0.3, 0.4, 0.1, 0.5, 0.2])
    jac = ToolJacobian(model)
    jac.update(q)
    return mon, q, jac.J


def _push(J: np.ndarray, force_n: float) -> np.ndarray:
    """Joint torques (2, 6) of a push of force_n [N] at the tool along (1, 1, -1)/√3 (hofto
    row), the momentum row zero."""
    w = np.zeros(6)
    w[:3] = force_n * np.array([1.0, 1.0, -1.0]) / np.sqrt(3.0)
    est = np.zeros((2, 6))
    est[0] = J.T @ w
    return est


def test_tool_force_above_the_limit_trips_the_same_push_below_does_not(er3a_model) -> None:
    mon, q, J = _tool_setup(er3a_model, limit=50.0)
    stop = StopController.from_config(StopCategories())
    _tick(mon, stop, _push(J, 40.0), n=6, q=q)
    assert mon.tool_force_value == pytest.approx(40.0, rel=1e-6)
    assert not stop.is_latched(Fault.COLLISION) and not mon.collision
    _tick(mon, stop, _push(J, 60.0), n=6, q=q)
    assert mon.tool_force_value == pytest.approx(60.0, rel=1e-6)
    assert stop.is_latched(Fault.COLLISION) and not mon.collision  # the tool limit, not a joint
    assert stop.events.joint[stop.events.count - 1] == -1


def test_tool_force_needs_the_model() -> None:
    with pytest.raises(ValueError, match="needs the robot model"):
        CollisionLevels(_levels(tool_force=50.0), ["hofto", "momentum"])


def test_tool_force_check_allocates_nothing(er3a_model) -> None:
    mon, q, J = _tool_setup(er3a_model, limit=500.0)
    stop = StopController.from_config(StopCategories())
    est = _push(J, 40.0)
    z = np.zeros(6)
    for _ in range(10):
        _tick(mon, stop, est, n=6, q=q)
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    for k in range(3000):
        q[4] = 0.6 + 1e-4 * k
        stop.begin_tick(stop.tick + 1)
        mon.update(stop, est, q, z, z, DT)
    grown = tracemalloc.get_traced_memory()[1] - before
    tracemalloc.stop()
    assert grown < 4000  # bytes: transient pinocchio/LAPACK temporaries, no array per tick


def test_levels_config_checks_the_new_terms_and_logics() -> None:
    with pytest.raises(ValidationError, match=r"reversal_margin has 1 entries, collision\.nominal"):
        _levels(reversal_margin=[1.0])
    with pytest.raises(ValidationError, match="logic"):
        _levels(logic="median")
    assert _levels(logic="mean", standstill_margin=[1.0, 2.0]).logic == "mean"
