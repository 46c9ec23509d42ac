"""Enabling an axis with a holding brake (issue 28): the gravity torque is applied before the
brake opens, motion is accepted only after the release delay and a motion check."""

from __future__ import annotations

import numpy as np
import pytest

from hofto_hw.config.models import SystemConfig
from hofto_hw.errors import UserError
from hofto_hw.runtime import compose

BRAKE = {
    "control": "drive",
    "release_delay": 0.1,
    "engage_delay": 0.05,
    "holding_torque": 150.0,
}  # release_bound: the default 0.5 mrad; measured (run.model_error 10 %): 0.24 mrad with the
# preload, 1.01 mrad without


def _with_brake(cfg: SystemConfig) -> SystemConfig:
    from hofto_hw.config.drives import BrakeConfig

    drives = list(cfg.bus.drives)
    drives[1] = drives[1].model_copy(update={"brake": BrakeConfig(**BRAKE)})
    return cfg.model_copy(update={"bus": cfg.bus.model_copy(update={"drives": drives})})


def test_enable_with_the_preload_keeps_the_shoulder_still(cfg: SystemConfig) -> None:
    system = compose.build(_with_brake(cfg), clock="sim", contact=False)
    try:
        d = system.bus.drives
        assert d.real_brake[1] and not d.brake_engaged[1]  # opened after its delay
        assert not d.real_brake[0]
    finally:
        system.close()


def test_without_the_preload_the_motion_check_refuses(cfg: SystemConfig, monkeypatch) -> None:
    def no_preload(cfg, model, group):
        return np.array([i for i, d in enumerate(cfg.bus.drives) if d.brake is not None], int)

    monkeypatch.setattr(compose, "preload_braked_axes", no_preload)
    with pytest.raises(
        UserError, match=r"^joint_2: moved [-+]\d+\.\d+ mrad while its brake opened"
    ):
        compose.build(_with_brake(cfg), clock="sim", contact=False)


def test_brake_config_none_and_bad_values() -> None:
    from pydantic import ValidationError

    from hofto_hw.config.drives import BrakeConfig

    with pytest.raises(ValidationError, match="release_delay"):
        BrakeConfig(**{**BRAKE, "release_delay": -0.1})
    with pytest.raises(ValidationError, match="holding_torque"):
        BrakeConfig(**{**BRAKE, "holding_torque": 0.0})
