"""Causal replay: an observer (and optionally a collision monitor) run over a recording
sample by sample, with the recorded time stamps, exactly as the loop would run them."""

from __future__ import annotations

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


def run_observer(rec: Recording, observer: Observer, out: FloatArray | None = None) -> FloatArray:
    """tau_ext_hat (N, n) [N·m] of ``observer`` over ``rec``; dt = t[k] - t[k-1]."""
    n_samples, n = rec.q.shape
    est = np.zeros((n_samples, n)) if out is None else out
    q, qd, tau, t = rec.q, rec.qd, rec.tau, rec.t
    observer.reset(q[0], qd[0])
    est[0] = 0.0
    update = observer.update
    for k in range(1, n_samples):
        est[k] = update(q[k], qd[k], tau[k], t[k] - t[k - 1])
    return est


def run_monitor(
    rec: Recording, tau_ext: FloatArray, monitor: CollisionMonitor
) -> tuple[FloatArray, NDArray[np.bool_], NDArray[np.bool_]]:
    """Thresholds (N, n) [N·m], tripped joints (N, n) and detection (N,) over ``rec``."""
    n_samples, n = tau_ext.shape
    thr = np.zeros((n_samples, n))
    joints = np.zeros((n_samples, n), dtype=bool)
    detected = np.zeros(n_samples, dtype=bool)
    qd, t = rec.qd, rec.t
    monitor.reset(qd[0])
    thr[0] = monitor.threshold
    for k in range(1, n_samples):
        detected[k] = monitor.update(tau_ext[k], qd[k], t[k] - t[k - 1])
        thr[k] = monitor.threshold
        joints[k] = monitor.joints
    return thr, joints, detected


def replay(
    rec: Recording, observer: Observer, monitor: CollisionMonitor | None = None
) -> ReplayResult:
    """Run ``observer`` (and ``monitor`` on its estimate) causally over ``rec``."""
    if rec.n_joints != observer.n:
        raise ValueError(
            f"{rec.source}: {rec.n_joints} joints, the observer's model has {observer.n}"
        )
    tau_ext = run_observer(rec, observer)
    result = ReplayResult(rec, getattr(observer, "name", type(observer).__name__), tau_ext)
    if monitor is not None:
        result.threshold, result.joints, result.detected = run_monitor(rec, tau_ext, monitor)
    return result
