"""Shared fixtures: the project's configs and models, built once per session."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"
SHARED_DATA = ROOT.parent / "shared" / "data"


SHM = Path("/dev/shm")
_shm_before: set[str] = set()


def _shm_names() -> set[str]:
    return {p.name for p in SHM.iterdir()} if SHM.is_dir() else set()


def _mapped_shm() -> set[str]:
    """Names of /dev/shm segments some live process maps (another session's are alive)."""
    names: set[str] = set()
    for maps in Path("/proc").glob("[0-9]*/maps"):
        try:
            text = maps.read_text()
        except OSError:
            continue
        names.update(
            line.rsplit("/dev/shm/", 1)[1].split()[0]
            for line in text.splitlines()
            if "/dev/shm/" in line
        )
    return names


def pytest_sessionstart(session: pytest.Session) -> None:
    """Load the native dynamics (hofto_hw/model/native, built by ``pip install``) before the
    first test; unavailable: the tests run the pinocchio Python path, test_native skips (fails
    under CI). Note the shared-memory segments that exist now."""
    from hofto_hw.model import native

    native.ready()
    _shm_before.update(_shm_names())


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """Shared-memory segments left behind (created since the session's start, mapped by no
    live process: a recorder ring nobody unlinked) fail the session under CI, which runs
    alone; elsewhere other sessions on the machine may have left them: a warning line."""
    left = sorted(_shm_names() - _shm_before - _mapped_shm())
    if left:
        print(f"\nshared-memory segments left behind in {SHM}: {', '.join(left)}")
        if os.environ.get("CI"):
            session.exitstatus = pytest.ExitCode.TESTS_FAILED


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
