"""Synthetic contacts injected into free-motion recordings: detection rate and delay.

A contact torque p(t) on a joint, with the recorded motion kept, means the motors delivered
tau - p: :func:`pulse_train` lays half-sine pulses (amplitude A [N·m], width W [s], random
sign) one after another on the joints in turn, far enough apart for the observer to settle
(``gap``), and the observer is re-run on the recording with tau - p. This holds for any
observer, linear (momentum, DOB) or not (HOFTO, ESO). A pulse is *at rest* when no joint
moves faster than ``rest_velocity`` during it, else *in motion*.

Detection uses the collision monitor's own trip rule: a joint trips once |est| has stayed
above its threshold for ``debounce`` (time accumulated over the recorded sample intervals,
as :class:`safety.collision.CollisionMonitor` does), looked for within [t0, t0 + W + 0.2 s].
The thresholds depend only on the motion, so one monitor run per recording serves every
pulse.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: the trip is looked for until this long after the end of the pulse [s]
AFTER = 0.2
#: state names (index 0, 1 of PulseStats' middle axis)
STATES = ("motion", "rest")


@dataclass(frozen=True)
class Pulse:
    """One injected pulse: ``joint`` (0-based), ``t0`` [s], samples [start, stop) of its
    detection window, ``rest`` (True: no joint moved during it)."""

    joint: int
    t0: float
    start: int
    stop: int
    rest: bool


def pulse_train(
    t: FloatArray,
    qd: FloatArray,
    amplitude: float,
    width: float,
    rng: np.random.Generator,
    gap: float = 1.0,
    rest_velocity: float = 0.02,
    lead: float = 1.0,
) -> tuple[FloatArray, list[Pulse]]:
    """Contact torque (N, n) [N·m] of half-sine pulses on the joints in turn (first joint at
    random), each starting ``gap``..2·``gap`` s after the previous window, the first after
    ``lead`` s (the observer's start-up), the last ending before t[-1]; and the pulses."""
    n_samples, n = qd.shape
    p = np.zeros((n_samples, n))
    pulses: list[Pulse] = []
    joint = int(rng.integers(n))
    cursor = t[0] + lead
    moving = np.abs(qd).max(axis=1) > rest_velocity
    while True:
        t0 = cursor + rng.uniform(0.0, gap)
        end = t0 + width + AFTER
        if end > t[-1]:
            break
        start, stop = np.searchsorted(t, [t0, end], side="left")
        phase = (t[start:stop] - t0) / width
        shape = np.where(phase <= 1.0, np.sin(np.pi * np.clip(phase, 0.0, 1.0)), 0.0)
        p[start:stop, joint] = rng.choice([-1.0, 1.0]) * amplitude * shape
        pulses.append(Pulse(joint, float(t0), int(start), int(stop), not moving[start:stop].any()))
        joint = (joint + 1) % n
        cursor = end + gap
    return p, pulses


def time_above(above: NDArray[np.bool_], t: FloatArray) -> FloatArray:
    """(N, n) time [s] each column has been above its threshold at each sample, accumulated
    over t[k] - t[k-1] as the monitor's debounce does (0 at the first sample, which the
    monitor only uses to reset)."""
    dt = np.diff(t, prepend=t[0])[:, None]
    inc = np.where(above, dt, 0.0)
    inc[0] = 0.0
    total = np.cumsum(inc, axis=0)
    # where not above, the run restarts: subtract the running total at the last break
    breaks = np.where(above, 0.0, total)
    breaks[0] = 0.0
    return total - np.maximum.accumulate(breaks, axis=0)


def trips(est: FloatArray, thr: FloatArray, t: FloatArray, debounce: float) -> NDArray[np.bool_]:
    """(N, n) samples at which the monitor's debounce is met (|est| > thr for ``debounce``)."""
    return time_above(np.abs(est) > thr, t) >= max(debounce - 1e-9, 1e-12)


@dataclass
class PulseStats:
    """Per amplitude, state (motion, rest) and joint: hits, tries; delays [s] of the hits."""

    amplitudes: list[float]
    hits: FloatArray
    tries: FloatArray
    delays: list[list[list[list[float]]]] = field(default_factory=list)

    @classmethod
    def empty(cls, amplitudes: list[float], n: int) -> PulseStats:
        shape = (len(amplitudes), len(STATES), n)
        delays = [[[[] for _ in range(n)] for _ in STATES] for _ in amplitudes]
        return cls(list(amplitudes), np.zeros(shape), np.zeros(shape), delays)

    @property
    def rate(self) -> FloatArray:
        """(A, 2, n) hits / tries (NaN where nothing was tried)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.tries > 0, self.hits / np.maximum(self.tries, 1), np.nan)

    def median_delay(self) -> FloatArray:
        """(A, 2, n) median delay [s] after the pulse start (NaN without hits)."""
        return np.array(
            [
                [[float(np.median(d)) if d else np.nan for d in row] for row in state]
                for state in self.delays
            ]
        )

    def add(self, other: PulseStats) -> None:
        """Accumulate ``other`` (same amplitudes and joints) into this one."""
        self.hits += other.hits
        self.tries += other.tries
        for a, state in enumerate(other.delays):
            for s, row in enumerate(state):
                for j, d in enumerate(row):
                    self.delays[a][s][j].extend(d)

    def joint(self, j: int) -> PulseStats:
        """The figures of joint ``j`` alone (the other joints' tries zeroed)."""
        mask = np.zeros(self.hits.shape[2])
        mask[j] = 1.0
        delays = [
            [[list(d) if k == j else [] for k, d in enumerate(row)] for row in state]
            for state in self.delays
        ]
        return dataclasses.replace(
            self, hits=self.hits * mask, tries=self.tries * mask, delays=delays
        )


def score(
    pulses: list[Pulse], est: FloatArray, thr: FloatArray, t: FloatArray, debounce: float
) -> list[float | None]:
    """Delay [s] from each pulse's start to the trip of its joint in its window, or None."""
    tripped = trips(est, thr, t, debounce)
    out: list[float | None] = []
    for p in pulses:
        hit = np.flatnonzero(tripped[p.start : p.stop, p.joint])
        out.append(float(t[p.start + hit[0]] - p.t0) if hit.size else None)
    return out


def tally(
    stats: PulseStats, amplitude_index: int, pulses: list[Pulse], delays: list[float | None]
) -> None:
    """Add pulses of one amplitude and their delays (None = missed) to ``stats``."""
    for p, d in zip(pulses, delays, strict=True):
        s = int(p.rest)
        stats.tries[amplitude_index, s, p.joint] += 1
        if d is not None:
            stats.hits[amplitude_index, s, p.joint] += 1
            stats.delays[amplitude_index][s][p.joint].append(d)
