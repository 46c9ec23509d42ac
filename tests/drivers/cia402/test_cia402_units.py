"""Raw <-> SI conversions: known values, round trips, saturation, no allocation."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.cia402.units import AxisScaling, Scaling

AXES = [
    AxisScaling(131072, 100.0, 1, 0, 640.0, 2800.0, 0.2286),
    AxisScaling(131072, 100.0, -1, 12345, 640.0, 2800.0, 0.2286),
    AxisScaling(1 << 20, 121.0, 1, -5000, 320.0, 1600.0, 0.2),
    AxisScaling(10000, 50.0, -1, 0, 80.0, 800.0, 0.1),
    AxisScaling(4096, 1.0, 1, 7, 80.0, 800.0, 0.1),
    AxisScaling(131072, 101.0, 1, 0, 64.0, 800.0, 0.08),
]


@pytest.fixture
def sc() -> Scaling:
    return Scaling(AXES)


def test_known_values(sc: Scaling) -> None:
    counts = np.array([131072 * 100, 12345 - 131072 * 25, -5000, 0, 7 + 1024, 0], np.int32)
    q = np.zeros(6)
    sc.position_to_si(counts, q)
    assert q[0] == pytest.approx(2 * np.pi)  # one joint turn = 100 motor turns
    assert q[1] == pytest.approx(np.pi / 2)  # direction -1, offset
    assert q[2] == pytest.approx(0.0)
    assert q[4] == pytest.approx(np.pi / 2)
    tau = np.zeros(6)
    sc.torque_to_si(np.array([1000, 1000, -500, 1000, 0, 0], np.int16), tau)
    # 1000 ‰ of 640 mN·m at the motor, times 100 at the joint = 64 N·m; sign by direction.
    assert tau[:4] == pytest.approx([64.0, -64.0, -0.5 * 0.32 * 121.0, -4.0])
    cur = np.zeros(6)
    sc.current_to_si(np.array([1000, 500, 0, 0, 0, 0], np.int16), cur)
    assert cur[:2] == pytest.approx([2.8, -1.4])
    t = np.zeros(6)
    sc.current_to_torque(np.array([2.8, 0, 0, 0, 0, 0]), t)
    assert t[0] == pytest.approx(2.8 * 0.2286 * 100.0)


def test_round_trips_within_one_raw_step(sc: Scaling) -> None:
    rng = np.random.default_rng(1)
    q = rng.uniform(-3, 3, 6)
    qd = rng.uniform(-2, 2, 6)
    tau = rng.uniform(-1, 1, 6) * 30000 * np.abs(sc.nm_per_permille)  # inside int16 range
    cur = rng.uniform(-1, 1, 6)
    raw32 = np.zeros(6, np.int32)
    raw16 = np.zeros(6, np.int16)
    back = np.zeros(6)
    sc.position_to_si(sc.position_to_raw(q, raw32), back)
    assert np.all(np.abs(back - q) <= 0.5 * np.abs(sc.rad_per_count) + 1e-12)
    sc.velocity_to_si(sc.velocity_to_raw(qd, raw32), back)
    assert np.all(np.abs(back - qd) <= 0.5 * np.abs(sc.rad_per_count) + 1e-12)
    sc.torque_to_si(sc.torque_to_raw(tau, raw16), back)
    assert np.all(np.abs(back - tau) <= 0.5 * np.abs(sc.nm_per_permille) + 1e-12)
    sc.current_to_si(sc.current_to_raw(cur, raw16), back)
    assert np.all(np.abs(back - cur) <= 0.5 * np.abs(sc.amp_per_permille) + 1e-12)
    # raw -> SI -> raw is exact
    counts = rng.integers(-(2**30), 2**30, 6).astype(np.int32)
    again = np.zeros(6, np.int32)
    sc.position_to_raw(sc.position_to_si(counts, back), again)
    assert np.array_equal(again, counts)


def test_to_raw_saturates_instead_of_wrapping(sc: Scaling) -> None:
    raw16 = np.zeros(6, np.int16)
    sc.torque_to_raw(np.full(6, 1e9), raw16)
    assert np.all(np.abs(raw16.astype(int)) >= 32767)
    raw32 = np.zeros(6, np.int32)
    sc.position_to_raw(np.full(6, -1e12), raw32)
    assert np.all(np.abs(raw32.astype(np.int64)) >= 2**31 - 1)


def test_writes_into_structured_field_views(sc: Scaling) -> None:
    from drivers.cia402.pdo import new_rx

    rx = new_rx(6)
    sc.position_to_raw(np.full(6, 0.1), rx["target_position"])
    assert rx["target_position"][0] == round(0.1 / (2 * np.pi) * 131072 * 100)


def test_limits_to_raw(sc: Scaling) -> None:
    assert sc.torque_limit_permille(0, 120.0) == 1875  # 120 N·m / (0.64 N·m · 100)
    assert sc.acceleration_to_raw(0, 2 * np.pi) == 131072 * 100
    assert sc.angle_to_counts(1, -2 * np.pi) == 131072 * 100


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"counts_per_rev": 0}, "counts_per_rev"),
        ({"gear_ratio": -1.0}, "gear_ratio"),
        ({"direction": 2}, "direction"),
        ({"rated_torque": 0.0}, "rated_torque"),
    ],
)
def test_bad_axis_scaling_names_the_field(kwargs: dict, field: str) -> None:
    base = {"counts_per_rev": 1000, "gear_ratio": 10.0}
    with pytest.raises(ValueError, match=field):
        AxisScaling(**{**base, **kwargs})
