"""The drag: section: what a user can get wrong is refused with the field named."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from hofto_hw.config import SystemConfig
from hofto_hw.config.drag import DragConfig


def _system(er3a_config, **drag: object) -> SystemConfig:
    data = er3a_config.model_dump()
    data["drag"] = drag
    return SystemConfig.model_validate(data)


def test_defaults_validate_at_1khz(er3a_config) -> None:
    cfg = _system(er3a_config)
    assert cfg.drag is not None and cfg.drag.max_tool_speed == 0.25


def test_unstable_admittance_at_the_loop_rate_is_refused(er3a_config) -> None:
    # B·k·dt/M = 200·3·0.001/0.5 = 1.2 >= 1 at 1 kHz
    with pytest.raises(ValidationError, match=r"drag\.mass/damping: k·B_a·dt/M_a .* 1\.2"):
        _system(er3a_config, mass=0.5)
    data = er3a_config.model_dump()
    data["loop"] = {"rate_hz": 100.0}
    data["drag"] = {}
    with pytest.raises(ValidationError, match=r"at 100 Hz"):
        SystemConfig.model_validate(data)


def test_bad_values_are_named() -> None:
    with pytest.raises(ValidationError, match="mass"):
        DragConfig(mass=0.0)
    with pytest.raises(ValidationError, match="damping"):
        DragConfig(damping=-1.0)
    with pytest.raises(ValidationError, match="ISO 10218"):
        DragConfig(max_tool_speed=0.3)
    with pytest.raises(ValidationError, match="every axis is locked"):
        DragConfig(unlock={"x": False, "y": False, "z": False})
    with pytest.raises(ValidationError, match="finite"):
        DragConfig(damping=float("nan"))
    with pytest.raises(ValidationError, match=r"workspace\.lower\.x"):
        DragConfig(workspace={"lower": [1, 0, 0], "upper": [0, 1, 1]})


def test_unknown_observer_and_joint_gain_lengths(er3a_config) -> None:
    with pytest.raises(ValidationError, match=r"drag\.observer: 'kalman' is not in observers"):
        _system(er3a_config, observer="kalman")
    with pytest.raises(ValidationError, match="joint_mass/joint_damping have 2/2 entries"):
        _system(er3a_config, space="joint", joint_mass=[1, 1], joint_damping=[5, 5])
