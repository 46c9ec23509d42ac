"""Shared fixtures: the UR10e and ER3A models, their regressors and base sets, built once
(the ER3A config comes from tests/conftest.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hofto_hw.config.loader import load_config
from hofto_hw.identify.base_params import find_base_parameters
from hofto_hw.identify.regressor import Regressor
from hofto_hw.model import RobotModel

ROOT = Path(__file__).resolve().parents[3]
CONFIGS = ROOT / "configs"
UR10E_DATA = Path("/work/shared/data/ur10e")


@pytest.fixture(scope="session")
def ur10e_model() -> RobotModel:
    return RobotModel.from_config(load_config(CONFIGS / "ur10e.yaml").robot)


@pytest.fixture(scope="session")
def er3a_model(er3a_config) -> RobotModel:
    """One ER3A model for the identification tests (they do not modify it): the regressor
    and base-parameter fixtures below are built once from it."""
    return RobotModel.from_config(er3a_config.robot)


@pytest.fixture(scope="session")
def er3a_base(er3a_model):
    reg = Regressor(er3a_model.pin_model, er3a_model.friction.smooth_velocity)
    return reg, find_base_parameters(reg, er3a_model.joint_names)


def smooth_motion(n: int, duration: float, rate: float, seed: int = 0):
    """A random multi-sine motion: t (N,), q, qd, qdd (N, n) consistent with each other."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 1.0 / rate)
    q = np.zeros((t.size, n))
    qd = np.zeros_like(q)
    qdd = np.zeros_like(q)
    w = 2 * np.pi / duration
    for l in range(1, 6):
        a = rng.normal(0.0, 0.6, n) / l
        ph = rng.uniform(0, 2 * np.pi, n)
        arg = w * l * t[:, None] + ph
        q += a / (w * l) * np.sin(arg)
        qd += a * np.cos(arg)
        qdd += -a * w * l * np.sin(arg)
    return t, q, qd, qdd
