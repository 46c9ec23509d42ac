"""Shared fixtures: the project's configs and models, built once per session."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"
SHARED_DATA = ROOT.parent / "shared" / "data"


@pytest.fixture(scope="session")
def er3a_config():
    """configs/er3a.yaml, loaded once for the whole run: the one fixture every test that needs
    the ER3A config uses (do not modify it; ``model_copy(update=...)`` for a variant)."""
    from hofto_hw.config import load_config

    return load_config(CONFIGS / "er3a.yaml")


@pytest.fixture(scope="session")
def er3a_model(er3a_config):
    """The ER3A RobotModel built from :func:`er3a_config`, once for the whole run."""
    from hofto_hw.model import RobotModel

    return RobotModel.from_config(er3a_config.robot)
