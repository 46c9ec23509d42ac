from __future__ import annotations

import numpy as np
import pytest

from hofto_hw.observers import error_indices


def test_offset_ma_rms_as_defined_under_table2():
    truth = np.zeros((4, 2))
    est = np.array([[1.0, -2.0], [3.0, 2.0], [-1.0, 0.0], [1.0, 0.0]])
    idx = error_indices(est, truth)
    assert idx["offset"] == pytest.approx([1.0, 0.0])
    assert idx["ma"] == pytest.approx([3.0, 2.0])
    assert idx["rms"] == pytest.approx([np.sqrt(12 / 4), np.sqrt(8 / 4)])
    with pytest.raises(ValueError):
        error_indices(est[:, 0], truth[:, 0])
