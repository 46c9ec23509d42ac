"""Causal replay: an observer (and optionally a collision monitor) run over a recording
sample by sample, with the recorded time stamps, exactly as the loop would run them."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hofto_hw.identify.data import Recording
from hofto_hw.observers.base import Observer
from safety.collision import CollisionMonitor

FloatArray = NDArray[np.float64]


@dataclass
class ReplayResult:
    """What a replay produced, sample for sample with the recording.

    ``tau_ext`` (N, n) estimated external torque [N·m] (0 at the first sample, where the
    observer is reset); with a monitor also ``threshold`` (N, n) [N·m], ``joints`` (N, n)
    tripped joints and ``detected`` (N,).
    """

    recording: Recording
    observer: str
    tau_ext: FloatArray
    threshold: FloatArray | None = None
    joints: NDArray[np.bool_] | None = None
    detected: NDArray[np.bool_] | None = None


#: samples between two progress calls (a check of the clock costs little against this)
PROGRESS_EVERY = 20_000

Progress = Callable[[int, int], None]


def run_observer(
    rec: Recording,
    observer: Observer,
    out: FloatArray | None = None,
    progress: Progress | None = None,
) -> FloatArray:
    """tau_ext_hat (N, n) [N·m] of ``observer`` over ``rec``, reset at the first sample and
    updated from the second on with the recorded dt = t[k] - t[k-1]; ``progress(k, N)`` is
    called every PROGRESS_EVERY samples."""
    n_samples, n = rec.q.shape
    est = np.zeros((n_samples, n)) if out is None else out
    q, qd, tau, t = rec.q, rec.qd, rec.tau, rec.t
    observer.reset(q[0], qd[0])
    est[0] = 0.0
    update = observer.update
    for start in range(1, n_samples, PROGRESS_EVERY):
        for k in range(start, min(start + PROGRESS_EVERY, n_samples)):
            est[k] = update(q[k], qd[k], tau[k], t[k] - t[k - 1])
        if progress is not None:
            progress(min(start + PROGRESS_EVERY, n_samples), n_samples)
    return est


def run_monitor(
    rec: Recording,
    tau_ext: FloatArray,
    monitor: CollisionMonitor,
    progress: Progress | None = None,
) -> tuple[FloatArray, NDArray[np.bool_], NDArray[np.bool_]]:
    """Thresholds (N, n) [N·m], tripped joints (N, n) and detection (N,) over ``rec``."""
    n_samples, n = tau_ext.shape
    thr = np.zeros((n_samples, n))
    joints = np.zeros((n_samples, n), dtype=bool)
    detected = np.zeros(n_samples, dtype=bool)
    qd, t = rec.qd, rec.t
    monitor.reset(qd[0])
    thr[0] = monitor.threshold
    for start in range(1, n_samples, PROGRESS_EVERY):
        for k in range(start, min(start + PROGRESS_EVERY, n_samples)):
            detected[k] = monitor.update(tau_ext[k], qd[k], t[k] - t[k - 1])
            thr[k] = monitor.threshold
            joints[k] = monitor.joints
        if progress is not None:
            progress(min(start + PROGRESS_EVERY, n_samples), n_samples)
    return thr, joints, detected


def replay(
    rec: Recording,
    observer: Observer,
    monitor: CollisionMonitor | None = None,
    progress: Callable[[str], Progress | None] | None = None,
) -> ReplayResult:
    """Run ``observer`` (and ``monitor`` on its estimate) causally over ``rec``;
    ``progress(stage)`` gives the progress callback of each stage (or None)."""
    stage = progress if progress is not None else (lambda _name: None)
    if rec.n_joints != observer.n:
        raise ValueError(
            f"{rec.source}: {rec.n_joints} joints, the observer's model has {observer.n}"
        )
    tau_ext = run_observer(rec, observer, progress=stage("observer"))
    result = ReplayResult(rec, getattr(observer, "name", type(observer).__name__), tau_ext)
    if monitor is not None:
        result.threshold, result.joints, result.detected = run_monitor(
            rec, tau_ext, monitor, stage("monitor")
        )
    return result
