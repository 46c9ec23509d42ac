"""Shared driver fixtures: the ER3A config and its quiet simulated bus (one definition)."""

from __future__ import annotations

import pytest

from drivers.sim.simbus import SimBus
from hofto_hw.config.models import SystemConfig


@pytest.fixture(scope="module")
def cfg(er3a_config: SystemConfig) -> SystemConfig:
    """configs/er3a.yaml (loaded once per session, see tests/conftest.py)."""
    return er3a_config


@pytest.fixture
def bus(cfg: SystemConfig) -> SimBus:
    """A fresh, not yet opened SimBus of ER3A without the scripted external torques."""
    from hofto_hw.runtime.build import build_sim_bus

    return build_sim_bus(cfg, external=False)
