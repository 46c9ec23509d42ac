"""Contact episodes: maximal runs of detected collision, with the joints and peaks involved."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray


@dataclass
class Episode:
    """One contact: ``start``/``end`` [s] (recording time), ``rows`` (first, last) in the
    source, ``joints`` (1-based) that tripped, ``peak`` (n,) largest |tau_ext_hat| [N·m] per
    joint inside the episode, ``peak_ratio`` largest |tau_ext_hat| / threshold."""

    start: float
    end: float
    rows: tuple[int, int]
    joints: list[int]
    peak: list[float]
    peak_ratio: float

    def as_dict(self) -> dict[str, Any]:
        """Plain types for JSON."""
        return {
            "start": self.start,
            "end": self.end,
            "duration": self.end - self.start,
            "rows": list(self.rows),
            "joints": self.joints,
            "peak": self.peak,
            "peak_ratio": self.peak_ratio,
        }


def find_episodes(
    t: NDArray[np.float64],
    joints: NDArray[np.bool_],
    tau_ext: NDArray[np.float64],
    threshold: NDArray[np.float64],
    rows: NDArray[np.int64] | None = None,
    merge_gap: float = 0.5,
) -> list[Episode]:
    """Episodes from per-sample tripped joints ``joints`` (N, n).

    Runs separated by less than ``merge_gap`` [s] are one episode (a contact whose estimate
    dips under the release level for a moment is still one contact).
    """
    detected = joints.any(axis=1)
    if not detected.any():
        return []
    rows = np.arange(1, t.size + 1) if rows is None else rows
    edges = np.diff(np.concatenate([[0], detected.astype(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1) - 1
    spans: list[list[int]] = []
    for s, e in zip(starts, ends, strict=True):
        if spans and t[s] - t[spans[-1][1]] < merge_gap:
            spans[-1][1] = int(e)
        else:
            spans.append([int(s), int(e)])
    out = []
    ratio = np.abs(tau_ext) / threshold
    for s, e in spans:
        sl = slice(s, e + 1)
        out.append(
            Episode(
                start=float(t[s]),
                end=float(t[e]),
                rows=(int(rows[s]), int(rows[e])),
                joints=[int(j) + 1 for j in np.flatnonzero(joints[sl].any(axis=0))],
                peak=[float(v) for v in np.max(np.abs(tau_ext[sl]), axis=0)],
                peak_ratio=float(np.max(ratio[sl])),
            )
        )
    return out
