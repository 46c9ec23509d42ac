"""Acceptance of issue 11 at rest, on runs left out of the calibration: the shipped thresholds'
settings (re-calibrated without these runs, as ``hofto-hw tune`` chose them) find at least as
many contacts at rest on joints 4-6 as the thresholds shipped before issue 11 (fa8d200, with
their own parameters file; none of these runs was in their calibration either).

Contacts: half-sine pulses (0.4 s) of 5, 7 and 10 N·m subtracted from the measured torque
(hofto_hw.replay.pulses), the observer re-run; only pulses during which no joint moved count.
Joints 1-3 find none of these sizes at rest, before or after (docs/sensitivity.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[3]
DATA = ROOT.parent / "shared" / "data" / "ur10e"
CONFIGS = ROOT / "configs"
BEFORE = ROOT / "tests" / "data" / "ur10e" / "fa8d200"
# three static holds and three free-motion runs, in neither calibration set
LEFT_OUT = [
    "validation/ur-20_01_17-p4.csv",
    "validation/ur-20_01_17-p5.csv",
    "validation/ur-20_01_17-p6.csv",
    "identification/ur-20_01_31-unload.csv",
    "identification/ur-20_02_19_15harm50sec.csv",
    "identification/ur-20_02_10-20sec_7harm.csv",
]
AMPLITUDES = [5.0, 7.0, 10.0]
ROUNDS = 6

pytestmark = [
    pytest.mark.data,
    pytest.mark.slow,
    pytest.mark.skipif(not DATA.is_dir(), reason="../shared/data/ur10e (UR10e recordings) absent"),
]


def _path(name: str) -> Path:
    for sub in ("identification", "validation"):
        if (DATA / sub / name).is_file():
            return DATA / sub / name
    raise FileNotFoundError(name)


def _rest_hits(setup, observer_cfg, monitor, name: str, recs) -> tuple[np.ndarray, np.ndarray]:
    """(A, n) pulses found and tried at rest on ``recs`` with one observer and monitor."""
    from hofto_hw.replay.pulses import PulseStats
    from hofto_hw.replay.runner import run_monitor
    from hofto_hw.replay.session import observer_for
    from hofto_hw.replay.tuning import judge, pulsed_runs
    from safety.collision import CollisionMonitor

    runs = pulsed_runs(
        recs,
        lambda r: observer_for(name, observer_cfg, setup, r, "auto"),
        AMPLITUDES,
        0.4,
        ROUNDS,
        seed=11,
    )
    stats = PulseStats.empty(AMPLITUDES, setup.model.n)
    for run in runs:
        thr, _, _ = run_monitor(run.rec, run.est, CollisionMonitor(monitor))
        false = judge(run, thr, monitor.debounce_time, stats)
        assert not false.any(), (name, run.rec.source, np.flatnonzero(false) + 1)
    return stats.hits[:, 1], stats.tries[:, 1]


@pytest.fixture(scope="module")
def after():
    """The shipped settings re-calibrated on every run they were tuned on but LEFT_OUT."""
    from support.ur10e import refit_shipped

    from hofto_hw.replay.session import load_for_replay
    from hofto_hw.replay.setup import load_setup
    from hofto_hw.replay.thresholds import read_thresholds

    setup = load_setup(CONFIGS / "ur10e" / "parameters.yaml")
    th = read_thresholds(CONFIGS / "ur10e" / "thresholds.yaml")
    left = {Path(p).name for p in LEFT_OUT}
    fit = [f for f in th.provenance["files"] if f not in left]
    recs = [load_for_replay(setup, _path(f), None) for f in fit]
    monitors = refit_shipped(setup, th, recs)
    out = {obs: (th.observers[obs].observer, monitors[obs]) for obs in monitors}
    return setup, out


@pytest.mark.parametrize("obs", ["momentum", "hofto"])
def test_rest_contacts_found_at_least_as_often_as_before(after, obs: str) -> None:
    from hofto_hw.replay.session import load_for_replay
    from hofto_hw.replay.setup import load_setup
    from hofto_hw.replay.thresholds import read_thresholds

    setup, monitors = after
    recs = [load_for_replay(setup, DATA / p, None) for p in LEFT_OUT]
    hits, tries = _rest_hits(setup, *monitors[obs], obs, recs)
    old_setup = load_setup(BEFORE / "parameters.yaml", CONFIGS / "ur10e.yaml")
    old = read_thresholds(BEFORE / "thresholds.yaml").observers[obs]
    old_recs = [load_for_replay(old_setup, DATA / p, None) for p in LEFT_OUT]
    old_hits, old_tries = _rest_hits(old_setup, old.observer, old.monitor, obs, old_recs)
    assert np.array_equal(tries, old_tries)  # the same pulses
    assert tries[:, 3:].min() >= 14, tries  # enough rest pulses on joints 4-6 to compare
    per_joint, old_per_joint = hits.sum(axis=0), old_hits.sum(axis=0)
    assert np.all(per_joint[3:] >= old_per_joint[3:]), (per_joint, old_per_joint, tries)
