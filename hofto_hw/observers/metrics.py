"""Table II's performance indices, per joint (see the note under the paper's Table II).

- Offset: |mean(error)|
- MA: max |error|
- RMS: sqrt(mean(error²))
with error = estimate - truth, arrays of shape (samples, joints), N·m.
"""

from __future__ import annotations

import numpy as np


def error_indices(estimate: np.ndarray, truth: np.ndarray) -> dict[str, np.ndarray]:
    """{'offset', 'ma', 'rms'} -> arrays of shape (joints,)."""
    estimate = np.asarray(estimate, dtype=float)
    truth = np.asarray(truth, dtype=float)
    if estimate.shape != truth.shape or estimate.ndim != 2:
        raise ValueError(f"shapes differ or are not 2-D: {estimate.shape} vs {truth.shape}")
    err = estimate - truth
    return {
        "offset": np.abs(err.mean(axis=0)),
        "ma": np.abs(err).max(axis=0),
        "rms": np.sqrt((err**2).mean(axis=0)),
    }
