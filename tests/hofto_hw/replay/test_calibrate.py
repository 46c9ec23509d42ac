"""Threshold calibration: the smallest envelope of free-motion residuals, with a margin."""

from __future__ import annotations

import numpy as np
import pytest

from hofto_hw.config.collision import CollisionConfig
from hofto_hw.identify.data import Recording
from hofto_hw.replay.calibrate import calibrate, features
from hofto_hw.replay.runner import run_monitor
from safety.collision import CollisionMonitor


def _motion(seed: int) -> tuple[Recording, np.ndarray]:
    """A two-joint recording: joint 1 reverses (sine), joint 2 holds still; residuals with a
    friction-like spike at each reversal of joint 1 and noise on both."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.008, 0.012, 3000))
    qd = np.zeros((t.size, 2))
    qd[:, 0] = 0.8 * np.sin(2 * np.pi * 0.3 * t + 0.5 + seed)
    rec = Recording(
        t=t,
        q=np.zeros_like(qd),
        qd=qd,
        tau=np.zeros_like(qd),
        source=f"synthetic {seed}",
        rows=np.arange(1, t.size + 1),
    )
    res = rng.normal(0.0, 0.5, qd.shape)
    res[:, 0] += 8.0 * np.exp(-((qd[:, 0] / 0.04) ** 2))  # Coulomb switching
    return rec, res


def test_envelope_covers_all_and_prefers_the_reversal_term() -> None:
    tmpl = CollisionConfig(base=[1.0, 1.0], debounce_time=0.0)
    recs, res = zip(*[_motion(s) for s in range(3)], strict=True)
    cal = calibrate(list(recs), list(res), tmpl, margin=0.0)
    # joint 1: a resting threshold well under the spike, the spike carried by the reversal term
    assert cal.envelope[0, 0] < 4.0
    assert cal.envelope[0, 3] > 4.0
    # joint 2 never moves: base only, just above its noise peak
    assert cal.envelope[1, 1:].sum() == pytest.approx(0.0, abs=1e-9)
    assert cal.envelope[1, 0] == pytest.approx(np.max(np.abs(np.concatenate(res)[:, 1])))
    # every calibration sample is covered by its threshold
    for rec, r in zip(recs, res, strict=True):
        f = features(rec, tmpl)
        thr = np.einsum("knf,nf->kn", f, cal.envelope)
        assert np.all(np.abs(r) <= thr + 1e-6)


def test_margin_scales_and_monitor_stays_quiet_on_new_free_motion() -> None:
    tmpl = CollisionConfig(base=[1.0, 1.0], debounce_time=0.03)
    recs, res = zip(*[_motion(s) for s in range(3)], strict=True)
    cal = calibrate(list(recs), list(res), tmpl, margin=0.5)
    np.testing.assert_allclose(cal.config.base, 1.5 * cal.envelope[:, 0])
    rec, r = _motion(11)  # not calibrated on
    _, _, detected = run_monitor(rec, r, CollisionMonitor(cal.config))
    assert not detected.any()
    r = r.copy()
    r[1000:1100, 1] += 6.0  # a push on the still joint
    r[2000:2100, 0] += 12.0  # and on the moving one
    _, joints, _ = run_monitor(rec, r, CollisionMonitor(cal.config))
    assert joints[1000:1100, 1].any() and joints[2000:2100, 0].any()
    assert not joints[:1000].any()
