"""What a flight log carries besides messages, so that `hofto-hw replay` can rebuild the run:
the config file, its URDF, the identified-parameters file and the thresholds file as MCAP
attachments, and a few strings as metadata.

Attachment names are fixed (replay looks them up by name): ``config.yaml``, ``robot.urdf``,
``parameters.yaml``, ``thresholds.yaml``. Metadata keys (record ``hofto_hw.flight``):
``robot``, ``rate_hz``, ``config_file`` (the original path, for people), ``detector`` (the
observer whose estimate the collision monitor watched).
"""

from __future__ import annotations

from pathlib import Path

from hofto_hw.config.models import SystemConfig
from hofto_hw.errors import UserError

CONFIG = "config.yaml"
URDF = "robot.urdf"
PARAMETERS = "parameters.yaml"
THRESHOLDS = "thresholds.yaml"
YAML = "application/yaml"


def _read(path: Path, what: str) -> bytes:
    try:
        return Path(path).read_bytes()
    except OSError as exc:
        raise UserError(f"{path}: cannot read {what} for the log: {exc.strerror}") from None


def run_attachments(
    config_path: Path,
    cfg: SystemConfig,
    *,
    parameters_path: Path | None = None,
    thresholds_path: Path | None = None,
) -> list[tuple[str, str, bytes]]:
    """(name, media type, bytes) of the files that define a run. ``cfg`` is ``config_path``
    loaded (its URDF path resolved); ``parameters_path`` defaults to ``cfg.robot.parameters``."""
    out = [(CONFIG, YAML, _read(config_path, "the config"))]
    out.append((URDF, "application/xml", _read(cfg.robot.urdf, "the URDF")))
    params = parameters_path or cfg.robot.parameters
    if params is not None:
        out.append((PARAMETERS, YAML, _read(params, "the parameters file")))
    if thresholds_path is not None:
        out.append((THRESHOLDS, YAML, _read(thresholds_path, "the thresholds file")))
    return out


def run_metadata(config_path: Path, cfg: SystemConfig, detector: str) -> dict[str, str]:
    """Metadata strings of a run (see the module docstring)."""
    return {
        "robot": cfg.robot.name,
        "rate_hz": repr(float(cfg.loop.rate_hz)),
        "config_file": str(config_path),
        "detector": detector,
    }
