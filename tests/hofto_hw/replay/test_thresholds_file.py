"""The thresholds file: round trip and clear errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from hofto_hw.config.collision import CollisionConfig
from hofto_hw.config.models import MomentumConfig
from hofto_hw.errors import ConfigError
from hofto_hw.replay.thresholds import (
    ObserverThresholds,
    ThresholdsFile,
    read_thresholds,
    write_thresholds,
)


def test_round_trip(tmp_path: Path) -> None:
    content = ThresholdsFile(
        robot="arm",
        margin=0.5,
        observers={
            "momentum": ObserverThresholds(
                observer=MomentumConfig(gain=[20.0, 20.0]),
                monitor=CollisionConfig(base=[3.0, 4.0], reversal_margin=[1.0, 0.0]),
                peak=[2.0, 2.5],
                samples=10,
            )
        },
    )
    p = tmp_path / "th.yaml"
    write_thresholds(p, content)
    back = read_thresholds(p)
    assert back == content
    assert "base: [3.0, 4.0]" in p.read_text()


def test_errors_name_file_and_field(tmp_path: Path) -> None:
    p = tmp_path / "th.yaml"
    p.write_text(
        "robot: arm\nobservers:\n  momentum:\n    observer: {type: momentum, gain: [1]}\n"
        "    monitor: {base: [-1.0]}\n"
    )
    with pytest.raises(ConfigError, match=r"th\.yaml: observers\.momentum\.monitor\.base\[0\]"):
        read_thresholds(p)
    with pytest.raises(ConfigError, match="thresholds file not found"):
        read_thresholds(tmp_path / "none.yaml")


def test_fusion_rows_must_be_observers_of_the_file(tmp_path: Path) -> None:
    p = tmp_path / "th.yaml"
    head = (
        "robot: arm\nobservers:\n  momentum:\n    observer: {type: momentum, gain: [1]}\n"
        "    monitor: {base: [1.0]}\n"
    )
    p.write_text(
        head + "fusion:\n  monitors:\n    momentum: {base: [2.0]}\n    hofto: {base: [2.0]}\n"
    )
    with pytest.raises(ConfigError, match=r"th\.yaml: fusion\.monitors \['hofto', 'momentum'\]"):
        read_thresholds(p)
    p.write_text(head + "fusion:\n  logic: any\n  monitors: {momentum: {base: [2.0]}}\n")
    with pytest.raises(ConfigError, match=r"fusion\.logic"):
        read_thresholds(p)
