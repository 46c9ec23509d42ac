"""The motion: section's recording buffer and the scripted replay of run.drag: bad values are
refused with the field named."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from hofto_hw.config.motion import MotionConfig
from hofto_hw.config.runtime import ScriptedDragConfig


def test_record_seconds_bounds() -> None:
    assert MotionConfig().record_seconds == 300.0
    for bad in (0.0, -5.0, float("nan"), 7200.0):
        with pytest.raises(ValidationError, match="record_seconds"):
            MotionConfig(record_seconds=bad)


def test_scripted_replay_comes_after_the_drag_figures_window() -> None:
    ok = ScriptedDragConfig(release=5.9, replay=6.9)
    assert ok.replay == 6.9
    with pytest.raises(ValidationError, match=r"drag\.replay = 6\.3 s must come at least 1 s"):
        ScriptedDragConfig(release=5.9, replay=6.3)
    assert ScriptedDragConfig().replay is None  # no replay unless asked
