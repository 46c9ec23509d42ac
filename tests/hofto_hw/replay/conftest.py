"""Shared fixtures of the replay tests: the UR10e config, parameters and samples in the repo."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
CONFIGS = ROOT / "configs"
PARAMS = CONFIGS / "ur10e" / "parameters.yaml"
THRESHOLDS = CONFIGS / "ur10e" / "thresholds.yaml"
SAMPLES = ROOT / "tests" / "data" / "ur10e"
PUSH = SAMPLES / "push_pose_1_rows100-600.csv"
EXCITATION = SAMPLES / "excitation_30sec_12harm_rows601-840.csv"
SHARED = ROOT.parent / "shared" / "data" / "ur10e"


@pytest.fixture(scope="session")
def setup():
    # parameters.yaml ships with the project: its absence fails (no skip)
    from hofto_hw.replay.setup import load_setup

    return load_setup(PARAMS)
