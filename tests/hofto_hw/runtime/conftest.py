"""Shared helpers for the runtime tests: the ER3A config and a system on the simulated arm."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from hofto_hw.config.loader import load_config
from hofto_hw.config.models import SystemConfig

CONFIG = Path(__file__).resolve().parents[3] / "configs" / "er3a.yaml"


@pytest.fixture(scope="session")
def cfg() -> SystemConfig:
    return load_config(CONFIG)


def with_updates(cfg: SystemConfig, section: str, **values: Any) -> SystemConfig:
    """A copy of ``cfg`` with fields of one section replaced."""
    sec = getattr(cfg, section).model_copy(update=values)
    return cfg.model_copy(update={section: sec})


def run_until(system: Any, cond: Any, limit: int) -> int:
    """Run the loop until ``cond()`` holds after a tick; returns the ticks taken."""
    before = system.loop.ticks
    system.loop.run(max_ticks=limit, should_stop=cond)
    if not cond():
        raise AssertionError(f"condition not reached within {limit} ticks")
    return system.loop.ticks - before
