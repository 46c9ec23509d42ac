"""Calibration with a standstill term and on residuals sustained over the debounce time."""

from __future__ import annotations

import numpy as np

from hofto_hw.config.collision import CollisionConfig
from hofto_hw.identify.data import Recording
from hofto_hw.replay.calibrate import calibrate, features, sustained


def _rec() -> tuple[Recording, np.ndarray]:
    """4 s of motion at 0.3 rad/s, then 4 s at rest; residual 1 N·m in motion, 6 at rest."""
    t = np.arange(0.0, 8.0, 0.01)
    qd = np.where(t < 4.0, 0.3, 0.0)[:, None] * np.ones((1, 1))
    q = np.cumsum(qd, axis=0) * 0.01
    rec = Recording(
        t=t, q=q, qd=qd, tau=np.zeros_like(q), source="synthetic", rows=np.arange(1, t.size + 1)
    )
    res = np.where(t < 4.0, 1.0, 6.0)[:, None].copy()
    return rec, res


def test_standstill_term_keeps_the_threshold_in_motion_low() -> None:
    rec, res = _rec()
    tmpl = CollisionConfig(base=[1.0], reversal_time=0.05, moving_time=0.05)
    plain = calibrate([rec], [res], tmpl, margin=0.0, min_base=0.5)
    still = calibrate(
        [rec], [res], tmpl, margin=0.0, min_base=0.5, terms=(True, True, True, True, True)
    )
    assert plain.config.base[0] > 5.5  # without it the base must cover the rest residual
    assert still.config.base[0] < 1.5  # with it the threshold in motion stays near 1 N·m
    assert still.config.standstill_margin[0] > 4.0
    assert plain.config.standstill_margin is None


def test_sustained_residual_ignores_single_sample_peaks() -> None:
    rec, res = _rec()
    res = res.copy()
    res[100, 0] = 40.0  # one-sample jolt in motion
    s = sustained(rec, res, 0.03)
    assert s[100, 0] == 1.0 and s[500, 0] == 6.0
    tmpl = CollisionConfig(base=[1.0], debounce_time=0.03)
    peak = calibrate([rec], [res], tmpl, margin=0.0, min_base=0.5)
    sus = calibrate([rec], [res], tmpl, margin=0.0, min_base=0.5, sustain=True)
    f = features(rec, tmpl)[100, 0]  # threshold features at the jolt
    assert f @ peak.envelope[0] >= 40.0 - 1e-6  # single samples: the jolt is covered
    assert f @ sus.envelope[0] < 10.0  # sustained: the monitor would never trip on it
