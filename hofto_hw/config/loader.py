"""Read a YAML config file into :class:`SystemConfig`, with errors that name file and field."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from hofto_hw.config.models import SystemConfig
from hofto_hw.errors import ConfigError, UserError


def _format_loc(loc: tuple[Any, ...]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out or "(top level)"


def format_validation_error(source: str, err: ValidationError) -> str:
    """One line per problem: ``FILE: field.path: message (got VALUE)``."""
    lines = []
    for e in err.errors(include_url=False):
        # Discriminated unions add the tag name ("hofto") to the location: keep it, it helps.
        loc = _format_loc(tuple(e.get("loc", ())))
        msg = e.get("msg", "invalid")
        got = e.get("input")
        shown = repr(got)
        if len(shown) > 80:
            shown = shown[:77] + "..."
        lines.append(f"{source}: {loc}: {msg} (got {shown})")
    return "\n".join(lines)


def parse_config(data: Any, source: str = "<config>", base_dir: Path | None = None) -> SystemConfig:
    """Validate an already-parsed mapping; relative paths are resolved against ``base_dir``."""
    if not isinstance(data, dict):
        raise ConfigError(
            f"{source}: expected a mapping at the top level, got {type(data).__name__}"
        )
    try:
        cfg = SystemConfig.model_validate(data)
    except ValidationError as err:
        raise ConfigError(format_validation_error(source, err)) from None
    if base_dir is not None:
        _resolve_paths(cfg, base_dir)
    return cfg


def _resolve_paths(cfg: SystemConfig, base_dir: Path) -> None:
    robot = cfg.robot
    if not robot.urdf.is_absolute():
        robot.urdf = (base_dir / robot.urdf).resolve()
    if robot.parameters is not None and not robot.parameters.is_absolute():
        robot.parameters = (base_dir / robot.parameters).resolve()


def read_yaml(path: str | Path, what: str, error: type[UserError] = ConfigError) -> Any:
    """Parse the YAML file ``path``; ``what`` names the kind of file in messages.

    Raises ``error`` naming the file: ``FILE: <what> not found``, ``FILE: cannot read <what>:
    reason`` or ``FILE: line L column C: not valid YAML: problem``.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise error(f"{path}: {what} not found") from None
    except OSError as exc:
        raise error(f"{path}: cannot read {what}: {exc.strerror}") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1} column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise error(f"{path}:{where}: not valid YAML: {problem}") from None


def load_config(path: str | Path) -> SystemConfig:
    """Load and validate ``path``; relative file names inside resolve against its folder.

    Raises :class:`ConfigError` naming the file, the field path and the bad value.
    """
    path = Path(path)
    data = read_yaml(path, "config file")
    cfg = parse_config(data, source=str(path), base_dir=path.parent)
    if not cfg.robot.urdf.is_file():
        raise ConfigError(f"{path}: robot.urdf: file not found (got '{cfg.robot.urdf}')")
    if cfg.robot.parameters is not None and not cfg.robot.parameters.is_file():
        raise ConfigError(
            f"{path}: robot.parameters: file not found (got '{cfg.robot.parameters}')"
        )
    return cfg


def json_schema() -> str:
    """The JSON schema of :class:`SystemConfig`, pretty-printed."""
    return json.dumps(SystemConfig.model_json_schema(), indent=2)
