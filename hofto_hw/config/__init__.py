"""Configuration: pydantic models of configs/*.yaml and the loader that names bad fields."""

from hofto_hw.config.base import FileModel
from hofto_hw.config.loader import (
    format_validation_error,
    json_schema,
    load_config,
    parse_config,
    read_model,
    read_yaml,
)
from hofto_hw.config.models import (
    DirectConfig,
    DobConfig,
    EsoConfig,
    ExternalTorqueConfig,
    FrictionConfig,
    HoftoConfig,
    LimitsConfig,
    LoopConfig,
    MomentumConfig,
    ObserverConfig,
    RobotConfig,
    SimulationConfig,
    StaConfig,
    SystemConfig,
)

__all__ = [
    "DirectConfig",
    "DobConfig",
    "EsoConfig",
    "ExternalTorqueConfig",
    "FileModel",
    "FrictionConfig",
    "HoftoConfig",
    "LimitsConfig",
    "LoopConfig",
    "MomentumConfig",
    "ObserverConfig",
    "RobotConfig",
    "SimulationConfig",
    "StaConfig",
    "SystemConfig",
    "format_validation_error",
    "json_schema",
    "load_config",
    "parse_config",
    "read_model",
    "read_yaml",
]
