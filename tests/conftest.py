"""Shared fixtures: the project's configs and models, built once per session."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"
SHARED_DATA = ROOT.parent / "shared" / "data"


def pytest_sessionstart(session: pytest.Session) -> None:
    """Build the native dynamics (hofto_hw/model/native) before the first test, once per
    machine (~40 s of CPU; then a cache look-up): no test, nor a ``hofto-hw run`` a test
    starts with a timeout, waits for the compiler. Unavailable (no numba, compiler or
    headers): the tests run the pinocchio Python path, test_native skips (fails under CI)."""
    from hofto_hw.model import native

    native.ready()


@pytest.fixture(scope="session")
def er3a_config():
    """configs/er3a.yaml, loaded once for the whole run: the one fixture every test that needs
    the ER3A config uses (do not modify it; ``model_copy(update=...)`` for a variant)."""
    from hofto_hw.config import load_config

    return load_config(CONFIGS / "er3a.yaml")


@pytest.fixture()
def er3a_model(er3a_config):
    """A fresh ER3A RobotModel per test (some tests change its friction or parameters)."""
    from hofto_hw.model import RobotModel

    return RobotModel.from_config(er3a_config.robot)
