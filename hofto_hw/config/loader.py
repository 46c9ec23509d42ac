"""Read a YAML config file into :class:`SystemConfig`, with errors that name file and field."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ValidationError

from hofto_hw.config.models import SystemConfig
from hofto_hw.errors import ConfigError, UserError

M = TypeVar("M", bound=BaseModel)


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
    _refuse_removed_fields(data, source)
    try:
        cfg = SystemConfig.model_validate(data)
    except ValidationError as err:
        raise ConfigError(format_validation_error(source, err)) from None
    if base_dir is not None:
        _resolve_paths(cfg, base_dir)
    return cfg


def _refuse_removed_fields(data: dict, source: str) -> None:
    """Fields an older schema had, refused with what replaces them (not "extra input")."""
    bus = data.get("bus")
    if isinstance(bus, dict) and "cycle_time" in bus:
        loop = data.get("loop")
        rate = loop.get("rate_hz", 1000.0) if isinstance(loop, dict) else 1000.0
        raise ConfigError(
            f"{source}: bus.cycle_time: removed; the bus cycles at loop.rate_hz "
            f"(here {rate!r} Hz, a {_period(rate)} cycle): delete the line "
            f"(got {bus['cycle_time']!r})"
        )


def _period(rate: Any) -> str:
    try:
        return f"{1.0 / float(rate):g} s"
    except (TypeError, ValueError, ZeroDivisionError):
        return "1 / rate_hz"


def _resolve_paths(cfg: SystemConfig, base_dir: Path) -> None:
    robot = cfg.robot
    if not robot.urdf.is_absolute():
        robot.urdf = (base_dir / robot.urdf).resolve()
    if robot.parameters is not None and not robot.parameters.is_absolute():
        robot.parameters = (base_dir / robot.parameters).resolve()
    # a drive profile given as a path relative to the config (not a name in configs/drives/):
    # made absolute here, so that the masters and emulators find it from any working folder
    for drive in cfg.bus.drives if cfg.bus is not None else []:
        spec = drive.profile
        if spec and ("/" in spec or spec.endswith((".yaml", ".yml"))):
            if not Path(spec).is_absolute() and (base_dir / spec).is_file():
                drive.profile = str((base_dir / spec).resolve())


def read_yaml(path: str | Path, what: str, error: type[UserError] = ConfigError) -> dict:
    """Parse the YAML file ``path`` whose top level must be a mapping; ``what`` names the kind
    of file in messages ("config file", "column map", ...).

    Raises ``error`` with one line naming the file: not found, a folder, unreadable, empty,
    binary, not UTF-8 at byte N, not valid YAML at line L column C (a truncated file says it
    ends early), or not a mapping.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise error(f"{path}: {what} not found") from None
    except IsADirectoryError:
        raise error(f"{path}: is a folder, not a {what}") from None
    except OSError as exc:
        raise error(f"{path}: cannot read {what}: {exc.strerror}") from None
    text = _decode(raw, path, what, error)
    try:
        data = yaml.safe_load(text)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        problem = " ".join(str(exc.problem or exc.context or "invalid").split())
        if mark is None:
            raise error(f"{path}: not valid YAML: {problem}") from None
        at_end = mark.index >= len(text.rstrip())
        ends_early = at_end or "<stream end>" in problem or "end of stream" in problem
        hint = " (the file ends early: truncated?)" if ends_early else ""
        raise error(
            f"{path}: line {mark.line + 1} column {mark.column + 1}: not valid YAML{hint}: "
            f"{problem}"
        ) from None
    except yaml.reader.ReaderError as exc:
        at = exc.position
        line, column = text.count("\n", 0, at) + 1, at - text.rfind("\n", 0, at)
        raise error(
            f"{path}: line {line} column {column}: not valid YAML: control character "
            f"U+{_code_point(exc.character):04X} is not allowed in a {what}"
        ) from None
    except (yaml.YAMLError, RecursionError) as exc:
        reason = "nested too deeply" if isinstance(exc, RecursionError) else str(exc)
        raise error(f"{path}: not valid YAML: {reason.splitlines()[0]}") from None
    if data is None:
        raise error(f"{path}: {what} is empty")
    if not isinstance(data, dict):
        raise error(
            f"{path}: expected a mapping (key: value lines) at the top level of a {what}, "
            f"got {_kind(data)}"
        )
    return data


def _decode(raw: bytes, path: Path, what: str, error: type[UserError]) -> str:
    """UTF-8 text of ``raw`` (a BOM is dropped), or ``error`` for a binary/non-UTF-8 file."""
    if not raw.strip():
        raise error(f"{path}: {what} is empty")
    head = raw[:4096]
    controls = sum(b < 32 and b not in b"\t\n\r\f" for b in head)
    if b"\0" in head or (controls > 1 and 20 * controls > len(head)):  # > 5 % control bytes
        raise error(f"{path}: is a binary file, not a {what} (YAML text)")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        if exc.end >= len(raw) and "unexpected end" in exc.reason:
            raise error(
                f"{path}: the {what} ends inside a UTF-8 character at byte {exc.start} "
                f"(line {line}): truncated?"
            ) from None
        raise error(
            f"{path}: not UTF-8 text at byte {exc.start} (line {line}, byte "
            f"0x{raw[exc.start]:02x}): save the {what} as UTF-8"
        ) from None


def _code_point(character: str | int) -> int:
    return character if isinstance(character, int) else ord(character)


def _kind(data: Any) -> str:
    if isinstance(data, list):
        return "a list"
    return f"a single value {data!r:.40}"


def read_model(path: str | Path, what: str, model: type[M]) -> M:
    """Read the YAML file ``path`` (see :func:`read_yaml`) and validate it as ``model``.

    Raises :class:`ConfigError`, one line per problem: ``FILE: field.path: message (got VALUE)``.
    """
    data = read_yaml(path, what)
    try:
        return model.model_validate(data)
    except ValidationError as err:
        raise ConfigError(format_validation_error(str(path), err)) from None


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
