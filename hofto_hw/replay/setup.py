"""Everything a replay needs besides the recording: the robot config found from the
parameters file, the model with identified parameters, column map, thresholds, observer.

Defaults let ``hofto-hw replay PARAMS FILE`` run with nothing else to write: the config is
``<robot>.yaml`` in the parameters file's folder or its parent (configs/ur10e.yaml for
configs/ur10e/<params>.yaml), the column map ``<robot>/columns_<k>.yaml`` beside that config
for a CSV with k columns, the thresholds ``<robot>/thresholds.yaml``.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

from hofto_hw.config import load_config
from hofto_hw.config.locate import find_config
from hofto_hw.config.models import ObserverConfig, SystemConfig
from hofto_hw.errors import ConfigError, ModelError, UserError
from hofto_hw.identify.data import count_columns
from hofto_hw.model import RobotModel
from hofto_hw.model.parameters import ParametersFile, apply_parameters, read_parameters
from hofto_hw.replay.defaults import OBSERVER_NAMES, default_observer
from hofto_hw.replay.thresholds import ThresholdsFile, read_thresholds


@dataclass
class Setup:
    """A model ready for replay and where its pieces came from."""

    model: RobotModel
    config: SystemConfig
    config_path: Path
    parameters: ParametersFile
    parameters_path: Path

    @property
    def robot_dir(self) -> Path:
        """configs/<robot>/ beside the config file."""
        return self.config_path.parent / self.config.robot.name


def sha256_of(path: Path) -> str:
    """Hex sha256 of a file's bytes."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def load_setup(params: str | Path, config: str | Path | None = None) -> Setup:
    """Read the parameters file, find/load the config (``config``: a path, a robot name or
    None = by the file's robot, see :func:`hofto_hw.config.locate.find_config`), build the model
    and apply the parameters."""
    params_path = Path(params)
    if not params_path.is_file():
        raise UserError(f"{params_path}: parameters file not found")
    pf = read_parameters(params_path)
    config_path = find_config(config, pf.robot, params_path.parent)
    cfg = load_config(config_path)
    if cfg.robot.name != pf.robot:
        raise ModelError(
            f"{params_path}: parameters are for robot {pf.robot!r}, but {config_path} "
            f"describes robot {cfg.robot.name!r}"
        )
    model = RobotModel.from_config(cfg.robot, apply_parameters=False)
    apply_parameters(model, pf, str(params_path))
    return Setup(model, cfg, config_path, pf, params_path)


def default_columns(setup: Setup, recording: Path) -> Path | None:
    """The robot's column map for this CSV's column count (None for MCAP logs)."""
    if recording.suffix.lower() == ".mcap":
        return None
    k = count_columns(recording)
    candidate = setup.robot_dir / f"columns_{k}.yaml"
    if not candidate.is_file():
        known = sorted(p.name for p in setup.robot_dir.glob("columns_*.yaml"))
        raise UserError(
            f"{recording}: {k} columns and no column map {candidate} for that layout "
            f"(have: {', '.join(known) or 'none'}); pass --columns"
        )
    return candidate


def default_thresholds(setup: Setup) -> Path | None:
    """configs/<robot>/thresholds.yaml if it exists."""
    candidate = setup.robot_dir / "thresholds.yaml"
    return candidate if candidate.is_file() else None


def load_thresholds_for(setup: Setup, path: Path) -> ThresholdsFile:
    """Read a thresholds file and check it belongs to this robot."""
    th = read_thresholds(path)
    if th.robot != setup.config.robot.name:
        raise ConfigError(
            f"{path}: thresholds are for robot {th.robot!r}, the model is "
            f"{setup.config.robot.name!r}"
        )
    return th


def observer_config(
    name: str, setup: Setup, thresholds: ThresholdsFile | None = None
) -> ObserverConfig:
    """Observer ``name``: as calibrated in ``thresholds``, else from the config (by name,
    then by type), else the ~100 Hz default of :mod:`hofto_hw.replay.defaults`."""
    if thresholds is not None and name in thresholds.observers:
        return thresholds.observers[name].observer
    observers = setup.config.observers
    if name in observers:
        return observers[name]
    for obs in observers.values():
        if obs.type == name:
            return obs
    if name not in OBSERVER_NAMES:
        raise UserError(f"unknown observer {name!r}; choose one of {', '.join(OBSERVER_NAMES)}")
    return default_observer(name, setup.model.n)
