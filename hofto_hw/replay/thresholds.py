"""The collision-thresholds file written by ``hofto-hw thresholds calibrate``.

Thresholds are only valid for the observer gains and the model they were calibrated with, so
the file carries both: each observer entry holds the observer config and the monitor config,
and the file names the parameters file (with its sha256) behind the model.

.. code-block:: yaml

    format: hofto-hw/collision-thresholds
    version: 1
    robot: ur10e
    parameters: {file: ur10e_parameters.yaml, sha256: 3f9a...}
    created: '2026-11-21T10:00:00+00:00'
    margin: 0.6                      # thresholds = (1 + margin) · envelope
    calibrated_on: [ur-20_02_05-20sec_8harm.csv, ...]
    observers:
      momentum:
        observer: {type: momentum, gain: [20.0, ...]}
        monitor: {base: [...], velocity_gain: [...], ...}   # see hofto_hw/config/collision.py
        peak: [...]                  # largest |tau_ext_hat| on the calibration data [N·m]
        samples: 41230
    fusion:                          # optional (hofto-hw tune): thresholds calibrated with the
      logic: mean                    # mean of the rows' ratios as the decision
      monitors: {hofto: {base: [...], ...}, momentum: {...}}   # rows: observers above
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import Field

from hofto_hw.config.base import FileModel
from hofto_hw.config.collision import CollisionConfig
from hofto_hw.config.loader import NoAliasDumper, read_model
from hofto_hw.config.models import ObserverConfig
from hofto_hw.errors import ConfigError
from hofto_hw.outputs import write_atomic

FORMAT = "hofto-hw/collision-thresholds"


class ParametersRef(FileModel):
    """Which identified-parameters file the thresholds were calibrated with."""

    file: str
    sha256: str = ""


class ObserverThresholds(FileModel):
    """Thresholds of one observer: its config, the monitor config, calibration figures."""

    observer: ObserverConfig
    monitor: CollisionConfig
    peak: list[float] = Field(default_factory=list, description="[N·m] per joint")
    samples: int = 0


class FusionThresholds(FileModel):
    """Thresholds calibrated for the fused decision (safety/collision ``logic: mean``: the
    mean of the rows' ratios |est| / thr must cross 1): one monitor per row, each row an
    observer of the file's ``observers`` (whose observer settings it uses)."""

    logic: Literal["mean"] = "mean"
    monitors: dict[str, CollisionConfig]


class ThresholdsFile(FileModel):
    """Content of a thresholds file (see the module docstring)."""

    format: Literal["hofto-hw/collision-thresholds"] = FORMAT
    version: Literal[1] = 1
    robot: str
    parameters: ParametersRef | None = None
    created: str = ""
    margin: float = 0.0
    calibrated_on: list[str] = Field(default_factory=list)
    observers: dict[str, ObserverThresholds]
    fusion: FusionThresholds | None = Field(
        None, description="thresholds for the fused ratio of two or more observers above"
    )
    provenance: dict[str, Any] | None = Field(
        None, description="how the file was made (hofto-hw tune: files, sha256, settings)"
    )


def read_thresholds(path: str | Path) -> ThresholdsFile:
    """Read and validate a thresholds file; errors name the file and the field."""
    th = read_model(path, "thresholds file", ThresholdsFile)
    if th.fusion is not None:
        missing = [r for r in th.fusion.monitors if r not in th.observers]
        if missing or len(th.fusion.monitors) < 2:
            raise ConfigError(
                f"{path}: fusion.monitors {sorted(th.fusion.monitors)}: needs two or more rows, "
                f"each one of observers {sorted(th.observers)}"
            )
    return th


def write_thresholds(path: str | Path, content: ThresholdsFile) -> None:
    """Write ``content`` as YAML (lists of numbers in flow style, one line each)."""

    class _Dumper(NoAliasDumper):
        pass

    def _list(dumper: yaml.SafeDumper, data: list) -> yaml.Node:
        flow = all(isinstance(v, (int, float)) for v in data)
        return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)

    _Dumper.add_representer(list, _list)
    data = content.model_dump(mode="json", exclude_none=True)
    write_atomic(  # UserError naming the file on failure
        path,
        "# Collision thresholds: written by `hofto-hw thresholds calibrate` or `hofto-hw tune`"
        " (see provenance).\n" + yaml.dump(data, Dumper=_Dumper, sort_keys=False, width=100),
        "thresholds file",
    )
