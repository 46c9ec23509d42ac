"""Section 4's fault array (hofto_hw/runtime/fused.py): the stop state it keeps as its
findings come in is the stop controller's after the same reports (what later checks of the
tick read), and the array holds the findings in order (Tick._report_faults reports them so)
— over random sequences of faults and configured categories, from random
latched/active/category states."""

from __future__ import annotations

import numpy as np

from hofto_hw.runtime import fused
from hofto_hw.runtime.fused import fault_cap, tick_state_dtype
from safety.stop import N_FAULTS, NO_CATEGORY, StopController

_report = getattr(fused._report, "py_func", fused._report)  # the kernel's own source


def test_section4_keeps_the_stop_state_the_stop_controller_reaches() -> None:
    rng = np.random.default_rng(27)
    k = 2
    for _ in range(500):
        cats = [None if c < 0 else int(c) for c in rng.integers(-1, 3, N_FAULTS)]
        stop = StopController(cats)
        stop.begin_tick(1)
        for f in rng.choice(N_FAULTS, rng.integers(0, 4), replace=False):  # earlier ticks
            stop.report(int(f), 0, 1.0)
        stop.begin_tick(2)
        if rng.random() < 0.3:
            stop.report(int(rng.integers(N_FAULTS)), 1, 2.0)  # what a pre-safety step did
        st = np.zeros(1, tick_state_dtype(6, k))[0]
        st["cats"] = stop.categories
        st["s_latched"], st["s_active"], st["s_cat"] = stop.latched, stop.active, stop.category
        found = [(int(f), int(rng.integers(-1, 6)), float(rng.normal())) for f in
                 rng.integers(0, N_FAULTS, rng.integers(1, fault_cap(k) + 1))]  # fmt: skip
        for f, j, v in found:
            _report(st, f, j, v)
            stop.report(f, j, v)
            # what later checks of the tick read: the same as the controller's, at every step
            assert (st["s_latched"], st["s_active"]) == (stop.latched, stop.active)
            assert st["s_cat"] == (stop.category if stop.category != NO_CATEGORY else -1)
        assert st["nf"] == len(found)
        n = len(found)
        entries = zip(st["fk"][:n], st["fj"][:n], st["fv"][:n], strict=True)
        assert [(int(a), int(b), float(c)) for a, b, c in entries] == found
