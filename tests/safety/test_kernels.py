"""The bus and limit checks (safety.kernels, compiled and as their Python source, through
tests/support/reference_safety.py) give the numpy reference's reports
(tests/safety/reference.py).

Every ``stop.report`` call (fault, joint, value, tick) is compared, not only the latched
events, over thousands of random ticks with limits crossed, non-finite samples, stale data
and drives in and out of Operation enabled.
"""

from __future__ import annotations

import numpy as np
import pytest
from support.compiled import require_compiled_kernels

from hofto_hw.config.safety import StopCategories
from safety.bus_health import BusHealth
from safety.limits import LimitMonitor
from safety.stop import StopController
from tests.safety.reference import ReferenceBus, ReferenceLimits
from tests.support.reference_safety import bus_check, limits_check

require_compiled_kernels()

N = 6
TICKS = 4000
OP_ENABLED, FAULT_STATES = 6, (7, 8, 9)  # any codes: safety takes them from the caller


class Recorder(StopController):
    """A stop controller that also keeps every report call."""

    def __init__(self) -> None:
        c = StopCategories()
        super().__init__([getattr(c, n) for n in _names()])
        self.calls: list[tuple[int, int, int, float]] = []

    def report(self, fault: int, joint: int = -1, value: float = 0.0) -> None:
        self.calls.append((self.tick, int(fault), int(joint), float(value)))
        super().report(fault, joint, value)


def _names() -> list[str]:
    from safety.stop import FAULT_NAMES, Fault

    return [FAULT_NAMES[int(f)] for f in Fault]


def _same(a: list[tuple[int, int, int, float]], b: list[tuple[int, int, int, float]]) -> bool:
    if len(a) != len(b):
        return False
    for x, y in zip(a, b, strict=True):
        if x[:3] != y[:3]:
            return False
        if not (x[3] == y[3] or (np.isnan(x[3]) and np.isnan(y[3]))):
            return False
    return True


_LIMITS = (
    np.full(N, -1.0),
    np.linspace(0.8, 1.2, N),
    np.linspace(1.5, 2.5, N),
    np.linspace(8.0, 12.0, N),
    0.05,
    0.02,
)


def _limit_monitor(backend: str) -> LimitMonitor:
    return LimitMonitor(*_LIMITS, backend=backend)  # type: ignore[arg-type]


@pytest.mark.parametrize("backend", ["numba", "python"])
@pytest.mark.parametrize("packed", [False, True], ids=["separate arrays", "rows of one block"])
def test_limit_monitor_reports_the_references(packed: bool, backend: str) -> None:
    """``packed``: q, qd, tau reach the monitor as consecutive rows of one 2-D array (as the
    drive group's are: the scan then reads that block in place), else as separate arrays
    (the scan reads the monitor's copy). ``numpy``: the kernels' Python source."""
    rng = np.random.default_rng(7)
    ref, fast = ReferenceLimits(*_LIMITS), _limit_monitor(backend)
    assert fast.backend == backend and fast._use_kernel == (backend == "numba")
    s_ref, s_fast = Recorder(), Recorder()
    q = np.zeros(N)
    start = q.copy()
    ref.reset(start)
    fast.reset(start)
    reported = 0
    block = np.zeros((5, N))  # the sample in rows 1..3, as a caller's workspace holds it
    rows = block[1], block[2], block[3]
    for k in range(TICKS):
        if k % 500 == 0:  # a reset, as the tick does after a fault reset
            s_ref, s_fast = Recorder(), Recorder()
        s_ref.begin_tick(k)
        s_fast.begin_tick(k)
        # mostly quiet ticks, sometimes one limit crossed, sometimes a non-finite entry
        q = q + rng.normal(0.0, 0.004, N)
        q = np.clip(q, -0.9, 0.9)
        qd = rng.normal(0.0, 0.5, N)
        tau = rng.normal(0.0, 3.0, N)
        q_cmd = q + rng.normal(0.0, 0.01, N)
        event = rng.integers(0, 12)
        j = int(rng.integers(0, N))
        x = (q, qd, tau, q_cmd)[int(rng.integers(0, 4))]
        if event == 0:
            x[j] = rng.choice([np.nan, np.inf, -np.inf])
        elif event == 1:
            x[j] = rng.choice([-1.0, 1.0]) * rng.uniform(1.0, 20.0)
        elif event == 2:
            q_sample = q.copy()
            q_sample[j] += rng.choice([-1.0, 1.0]) * rng.uniform(0.0, 0.1)
            q = q_sample
        fresh = bool(rng.random() < 0.9)
        tracking = bool(rng.random() < 0.8)
        gap = float(rng.choice([0.0, 0.0, rng.uniform(0.0, 0.05)]))  # a stall's allowance
        ref.check(s_ref, q, qd, tau, q_cmd, fresh, tracking, gap)
        if packed:
            block[1:4] = q, qd, tau
            read = limits_check(fast, s_fast, *rows, q_cmd.copy(), fresh, tracking, gap)
            assert read.base is block  # the scan read the caller's rows in place
        else:
            args = q.copy(), qd.copy(), tau.copy(), q_cmd.copy()
            limits_check(fast, s_fast, *args, fresh, tracking, gap)
        assert _same(s_ref.calls, s_fast.calls), k
        assert s_ref.latched == s_fast.latched and s_ref.category == s_fast.category
        np.testing.assert_array_equal(ref.q_prev, fast.q_prev)
        assert ref.have_prev == fast._have_prev
        reported += len(s_ref.calls)
        if not np.all(np.isfinite(q)):
            q = np.zeros(N)
    assert reported > 100  # the run did cross limits


def _bus(backend: str) -> BusHealth:
    return BusHealth(N, 3, OP_ENABLED, FAULT_STATES, backend=backend)  # type: ignore[arg-type]


@pytest.mark.parametrize("backend", ["numba", "python"])
def test_bus_health_reports_the_references(backend: str) -> None:
    rng = np.random.default_rng(11)
    ref, fast = ReferenceBus(N, 3, OP_ENABLED, FAULT_STATES), _bus(backend)
    assert fast.backend == backend
    s_ref, s_fast = Recorder(), Recorder()
    codes = np.array([0, 1, 2, 3, 4, 5, 6, 6, 6, 6, 7, 8, 9], dtype=np.uint8)
    for k in range(TICKS):
        s_ref.begin_tick(k)
        s_fast.begin_tick(k)
        states = np.full(N, OP_ENABLED, dtype=np.uint8)
        if rng.random() < 0.3:
            states[rng.integers(0, N, size=rng.integers(1, 3))] = rng.choice(codes)
        errors = rng.integers(0, 0xFFFF, N).astype(np.uint16)
        status = int(rng.random() < 0.1)
        fresh = bool(rng.random() < 0.95)
        expect = bool(rng.random() < 0.7)
        a = ref.check(s_ref, status, fresh, states, errors, expect)
        b = bus_check(fast, s_fast, status, fresh, states.copy(), errors.copy(), expect)
        assert a == b
        assert s_ref.calls == s_fast.calls, k
        assert (ref.streak, ref.lost_total) == (fast.streak, fast.lost_total)
    assert len({c[1] for c in s_ref.calls}) == 3  # bus loss, drive fault, drive disabled


def test_python_backend_runs_the_kernels_source() -> None:
    """backend python: the monitors compile nothing and their checks run the kernels' own
    source as Python (hofto_hw.jit.compiled_or_python: the kernels they call run as Python
    too), not a compiled dispatcher; numba: the compiled kernels."""
    from hofto_hw import jit
    from safety import kernels

    bus, lim = _bus("python"), _limit_monitor("python")
    assert bus.backend == "python" and bus._use_kernel is False
    assert lim.backend == "python" and lim._use_kernel is False
    for kernel in (kernels.drive_scan, kernels.limits_scan, kernels.limits_commit):
        py = jit.compiled_or_python(kernel, "python")
        assert py.__code__ is kernel.py_func.__code__ and not hasattr(py, "py_func")
        assert jit.compiled_or_python(kernel, "numba") is kernel
