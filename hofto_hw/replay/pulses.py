"""Synthetic contacts injected into free-motion recordings: detection rate and delay.

A half-sine pulse of amplitude A [N·m] and width W [s] on joint j at a random time t0 reaches
the momentum observer's estimate through the observer's own linear response (a first-order
lag with its gain K_j, on the real time stamps): est_pulsed = est + lag(pulse). The monitor's
thresholds depend only on the motion, so one replay per recording serves every pulse; the
trip rule (above the threshold for ``debounce_time``) is applied within [t0, t0 + W + 0.2 s].
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def lag_response(t: np.ndarray, pulse: np.ndarray, gain: float) -> np.ndarray:
    """Response r' = K·(p − r) of the momentum observer to an external torque p (N,) [N·m]."""
    r = np.zeros_like(pulse)
    for k in range(1, t.size):
        a = 1.0 - np.exp(-gain * (t[k] - t[k - 1]))
        r[k] = r[k - 1] + a * (pulse[k] - r[k - 1])
    return r


def first_trip(excess: np.ndarray, t: np.ndarray, debounce: float) -> float | None:
    """Time [s] after t[0] at which ``excess`` (N,) bool has held for ``debounce``; None."""
    start = None
    for k in range(excess.size):
        if excess[k]:
            if start is None:
                start = k
            if t[k] - t[start] >= debounce - 1e-9:
                return float(t[k] - t[0])
        else:
            start = None
    return None


@dataclass
class PulseStats:
    """Per amplitude (rows) and joint (columns): hits, tries; delays [s] of the hits."""

    amplitudes: list[float]
    hits: np.ndarray
    tries: np.ndarray
    delays: list[list[list[float]]] = field(default_factory=list)

    @property
    def rate(self) -> np.ndarray:
        return self.hits / np.maximum(self.tries, 1)

    def median_delay(self) -> np.ndarray:
        return np.array(
            [[float(np.median(d)) if d else np.nan for d in row] for row in self.delays]
        )


def inject_pulses(
    t: np.ndarray,
    est: np.ndarray,
    thr: np.ndarray,
    gain: np.ndarray,
    debounce: float,
    amplitudes: list[float],
    pulses: int,
    rng: np.random.Generator,
    width: float = 0.4,
    stats: PulseStats | None = None,
) -> PulseStats:
    """Add ``pulses`` random half-sine pulses per joint and amplitude to one recording's
    estimate ``est`` (N, n) with thresholds ``thr`` (N, n); accumulate into ``stats``."""
    n = est.shape[1]
    if stats is None:
        stats = PulseStats(
            list(amplitudes),
            np.zeros((len(amplitudes), n)),
            np.zeros((len(amplitudes), n)),
            [[[] for _ in range(n)] for _ in amplitudes],
        )
    if t[-1] - t[0] < width + 2.5:
        return stats
    for ai, amp in enumerate(amplitudes):
        for j in range(n):
            for _ in range(pulses):
                t0 = rng.uniform(t[0] + 1.0, t[-1] - width - 1.0)
                sel = (t >= t0) & (t <= t0 + width + 0.2)
                tt = t[sel]
                phase = np.clip((tt - t0) / width, 0.0, 1.0)
                p = rng.choice([-1.0, 1.0]) * amp * np.sin(np.pi * phase)
                r = lag_response(tt, p, float(gain[j]))
                d = first_trip(np.abs(est[sel, j] + r) > thr[sel, j], tt, debounce)
                stats.tries[ai, j] += 1
                if d is not None:
                    stats.hits[ai, j] += 1
                    stats.delays[ai][j].append(d)
    return stats
