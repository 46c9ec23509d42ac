"""The limit and bus checks (safety.kernels on the LimitMonitor's and BusHealth's
workspaces, through tests/support/reference_safety.py) report the first offending joint to
the StopController."""

from __future__ import annotations

import numpy as np
import pytest

from hofto_hw.config.safety import StopCategories
from safety.bus_health import BusHealth
from safety.limits import LimitMonitor
from safety.stop import Fault, StopController
from tests.support.reference_safety import bus_check, finite, limits_check

N = 3


def _mon() -> LimitMonitor:
    return LimitMonitor(
        np.full(N, -1.0), np.full(N, 1.0), np.full(N, 2.0), np.full(N, 10.0), 0.05, 0.02
    )


def _check(mon: LimitMonitor, q, qd=None, tau=None, q_cmd=None, tracking=True) -> StopController:
    s = StopController.from_config(StopCategories())
    s.begin_tick(1)
    z = np.zeros(N)
    q = np.asarray(q, float)
    limits_check(
        mon,
        s,
        q,
        z if qd is None else np.asarray(qd, float),
        z if tau is None else np.asarray(tau, float),
        q if q_cmd is None else np.asarray(q_cmd, float),
        True,
        tracking,
    )
    return s


def test_each_limit_names_its_joint() -> None:
    mon = _mon()
    mon.reset(np.zeros(N))
    assert _check(mon, [0.0, 0.0, 0.0]).latched == 0
    s = _check(_mon(), [0.0, 1.2, 0.0])
    assert s.is_latched(Fault.POSITION_LIMIT) and s.events.joint[0] == 1
    s = _check(_mon(), [0.0] * N, qd=[0.0, 0.0, -2.5])
    assert s.is_latched(Fault.VELOCITY_LIMIT) and s.events.joint[0] == 2
    s = _check(_mon(), [0.0] * N, tau=[11.0, 0.0, 0.0])
    assert s.is_latched(Fault.TORQUE_LIMIT)
    s = _check(_mon(), [0.0] * N, tau=[11.0, 0.0, 0.0], tracking=False)
    assert s.latched == 0  # brakes, not the motor, when unpowered
    s = _check(_mon(), [0.0] * N, q_cmd=[0.0, 0.1, 0.0])
    assert s.is_latched(Fault.FOLLOWING_ERROR) and s.events.value[0] > 0.05


@pytest.mark.parametrize("backend", ["python", "auto"])
def test_following_error_is_judged_on_fresh_samples_only(backend) -> None:
    """The CI case: joint 2 moves 0.017 rad per cycle and lags 2 cycles (0.034 rad); a late
    TPDO repeats the last sample, whose lag then reads 3 cycles (0.051 rad > 0.05) against
    the next command: not the drive's lag, not reported. The same lag on the next fresh
    sample is the drive's: reported with the joint and value, latched with the configured
    category (2 here, not the default 1), on that tick."""
    cats = StopCategories(following_error=2)
    mon = LimitMonitor(
        np.full(N, -1.0), np.full(N, 1.0), np.full(N, 4.0), np.full(N, 10.0), 0.05, 0.02,
        backend=backend,
    )  # fmt: skip
    step, stop = 0.017, StopController.from_config(cats)
    q = np.zeros(N)
    mon.reset(q)
    z = np.zeros(N)
    for k in range(1, 6):  # fresh samples at a 2-cycle lag: quiet
        stop.begin_tick(k)
        q = np.array([0.0, (k - 2) * step, 0.0])
        limits_check(mon, stop, q, z, z, q + 2 * step * np.array([0, 1, 0]), True, True)
    assert stop.latched == 0
    stale = q.copy()  # tick 6: the TPDO is late, the sample repeats, the command moved on
    stop.begin_tick(6)
    q_cmd = stale + 3 * step * np.array([0, 1, 0])
    assert abs(q_cmd[1] - stale[1]) > 0.05
    limits_check(mon, stop, stale, z, z, q_cmd, False, True)
    assert stop.latched == 0 and stop.active == 0 and stop.events.count == 0
    # tick 7: a fresh sample with that lag: the drive does lag 3 cycles now
    stop.begin_tick(7)
    q = stale + step * np.array([0, 1, 0])
    limits_check(mon, stop, q, z, z, q + 0.051 * np.array([0, 1, 0]), True, True)
    assert stop.latched == 1 << Fault.FOLLOWING_ERROR
    assert stop.category == 2 and stop.first_tick == 7
    e = stop.events
    assert (e.count, e.kind[0], e.joint[0], e.category[0]) == (1, Fault.FOLLOWING_ERROR, 1, 2)
    assert e.value[0] == pytest.approx(0.051)


@pytest.mark.parametrize("backend", ["python", "auto"])
def test_a_stale_sample_is_still_judged_on_torque_position_and_velocity(backend) -> None:
    """A repeated sample is still the last the drive measured: its torque (while tracking),
    position and velocity are judged; not its lag, nor a jump."""
    mon = LimitMonitor(
        np.full(N, -1.0), np.full(N, 1.0), np.full(N, 2.0), np.full(N, 10.0), 0.05, 0.02,
        backend=backend,
    )  # fmt: skip
    mon.reset(np.zeros(N))
    stop = StopController.from_config(StopCategories())
    stop.begin_tick(1)
    q = np.array([1.2, 0.5, 0.0])  # joint 0 past its soft limit, joint 1 jumped 0.5 rad
    qd, tau, q_cmd = np.array([0.0, 0.0, -2.5]), np.array([0.0, 11.0, 0.0]), np.zeros(N)
    limits_check(mon, stop, q, qd, tau, q_cmd, False, True)
    want = (Fault.POSITION_LIMIT, Fault.VELOCITY_LIMIT, Fault.TORQUE_LIMIT)
    assert stop.latched == sum(1 << f for f in want)
    assert list(stop.events.kind[:3]) == list(want) and list(stop.events.joint[:3]) == [0, 2, 1]
    np.testing.assert_array_equal(mon.q_prev, np.zeros(N))  # a stale q is no previous sample


def test_position_jump_between_fresh_samples() -> None:
    mon = _mon()
    mon.reset(np.zeros(N))
    assert _check(mon, [0.01, 0.0, 0.0]).latched == 0
    s = _check(mon, [0.01, 0.0, 0.05], q_cmd=[0.01, 0.0, 0.05])
    assert s.is_latched(Fault.POSITION_JUMP) and s.events.joint[0] == 2


def test_position_jump_allowance_grows_with_the_gap_since_the_last_fresh_sample() -> None:
    """A gap of 10 ms beyond one cycle allows the velocity limit (2 rad/s) x 0.01 s more."""

    def jumped(step: float, gap: float) -> bool:
        mon = _mon()
        mon.reset(np.zeros(N))
        s = StopController.from_config(StopCategories())
        s.begin_tick(1)
        q = np.array([0.0, step, 0.0])
        limits_check(mon, s, q, np.zeros(N), np.zeros(N), q, True, True, gap)
        return s.is_latched(Fault.POSITION_JUMP)

    assert jumped(0.03, 0.0)  # consecutive samples: the bound is position_jump (0.02)
    assert not jumped(0.03, 0.01)  # 0.02 + 2 rad/s x 0.01 s = 0.04
    assert jumped(0.05, 0.01)


def test_non_finite_is_reported_and_does_not_poison() -> None:
    s = StopController.from_config(StopCategories())
    s.begin_tick(1)
    assert not finite(s, np.array([0.0, np.nan, 0.0]))
    assert s.is_latched(Fault.NON_FINITE) and s.events.joint[0] == 1
    assert finite(s, np.zeros(N))


def test_bus_loss_after_a_streak_and_drive_states() -> None:
    s = StopController.from_config(StopCategories())
    bh = BusHealth(N, 3, 4, (6, 7, 8))
    states = np.full(N, 4, dtype=np.uint8)
    codes = np.zeros(N, dtype=np.uint16)
    for k in range(2):
        s.begin_tick(k)
        assert not bus_check(bh, s, 2, False, states, codes, True)
    assert s.latched == 0  # two lost cycles: tolerated
    s.begin_tick(3)
    assert bus_check(bh, s, 0, True, states, codes, True)  # a good one resets the streak
    for k in range(3):
        s.begin_tick(4 + k)
        bus_check(bh, s, 0, False, states, codes, True)  # stale data counts as lost
    assert s.is_latched(Fault.BUS_LOSS)
    s2 = StopController.from_config(StopCategories())
    states[1] = 7
    codes[1] = 0x2310
    bus_check(bh, s2, 0, True, states, codes, True)
    assert s2.is_latched(Fault.DRIVE_FAULT) and s2.events.value[0] == 0x2310
    s3 = StopController.from_config(StopCategories())
    states[1] = 1
    bus_check(bh, s3, 0, True, states, codes, True)
    assert s3.is_latched(Fault.DRIVE_DISABLED) and s3.events.joint[0] == 1


@pytest.mark.parametrize("backend", ["python", "auto"])
def test_sto_and_brake_fault_codes_are_their_own_classes(backend) -> None:
    """The drive layer names STO (``sto_of``) and brake fault codes (``brake_code``): an axis
    that left Operation enabled with STO active is STO, not drive_disabled; a brake fault
    code latches BRAKE beside drive_fault; each with its category and the axis named."""
    cats = [1] * len(Fault)
    cats[Fault.STO], cats[Fault.BRAKE], cats[Fault.DRIVE_DISABLED] = 0, 1, 2
    oe, fault = 5, 7
    for sto in (True, False):
        stop = StopController(cats)
        h = BusHealth(3, 3, oe, (6, 7, 8), backend=backend)
        h.sto_of = lambda j, sto=sto: sto and j == 1
        stop.begin_tick(1)
        bus_check(h, stop, 0, True, np.array([oe, 3, oe], dtype=np.uint8), np.zeros(3), True)
        want = Fault.STO if sto else Fault.DRIVE_DISABLED
        assert stop.latched == 1 << want and stop.events.joint[0] == 1
        assert stop.category == (0 if sto else 2)
    stop = StopController(cats)
    h = BusHealth(3, 3, oe, (6, 7, 8), backend=backend)
    h.brake_code = lambda j, code: code == 0xFF21
    stop.begin_tick(1)
    bus_check(
        h, stop, 0, True, np.array([oe, oe, fault], dtype=np.uint8), np.array([0, 0, 0xFF21]), True
    )
    assert stop.latched == (1 << Fault.DRIVE_FAULT) | (1 << Fault.BRAKE)
    assert list(stop.events.joint[:2]) == [2, 2] and stop.events.value[1] == 0xFF21
