"""Read a YAML config file into :class:`SystemConfig`, with errors that name file and field."""

from __future__ import annotations

import json
import os
import reprlib
import stat
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
        shown = excerpt(got, 80)
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
            f"(here {excerpt(rate, 40)} Hz, a {_period(rate)} cycle): delete the line "
            f"(got {excerpt(bus['cycle_time'], 40)})"
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


#: largest YAML file any reader accepts [bytes]: the biggest shipped file (a parameters file)
#: is ~20 kB; 4 MiB leaves room for long hand-written files and bounds the parser's memory.
MAX_YAML_BYTES = 4 << 20


def read_bounded(
    path: str | Path, what: str, max_bytes: int, error: type[UserError] = ConfigError
) -> bytes:
    """The bytes of the regular file ``path``, at most ``max_bytes`` of them.

    A FIFO, a device (``/dev/zero``), a socket or a folder is refused by stat before it is
    opened (opening a device can have effects of its own), and again by fstat on the file
    opened non-blocking (a swap between the two never blocks); a file larger than
    ``max_bytes`` is refused before it is read (the read itself is bounded too, for a file
    that grows meanwhile). Raises ``error``, one line naming the file.
    """
    path = Path(path)
    require_regular(path, what, error)
    flags = os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise error(f"{path}: {what} not found") from None
    except IsADirectoryError:
        raise error(f"{path}: is a folder, not a {what}") from None
    except OSError as exc:
        raise error(f"{path}: cannot read {what}: {exc.strerror}") from None
    try:
        st = os.fstat(fd)
        if stat.S_ISDIR(st.st_mode):
            raise error(f"{path}: is a folder, not a {what}")
        if not stat.S_ISREG(st.st_mode):
            raise error(f"{path}: is {_file_kind(st.st_mode)}, not a {what} (a regular file)")
        if st.st_size > max_bytes:
            raise error(
                f"{path}: {st.st_size} bytes; a {what} is at most {max_bytes} bytes "
                f"({max_bytes / 1e6:g} MB)"
            )
        chunks, left = [], max_bytes + 1
        while left > 0:
            chunk = os.read(fd, min(left, 1 << 20))
            if not chunk:
                break
            chunks.append(chunk)
            left -= len(chunk)
        if left <= 0:
            raise error(f"{path}: grew past {max_bytes} bytes while read; not a {what}")
        return b"".join(chunks)
    except OSError as exc:
        raise error(f"{path}: cannot read {what}: {exc.strerror}") from None
    finally:
        os.close(fd)


def require_regular(path: str | Path, what: str, error: type[UserError] = ConfigError) -> None:
    """Refuse (``error``, one line) a ``path`` that is not a regular file, before a reader
    that streams a large file (CSV recordings, MCAP logs) opens it: a FIFO would block the
    open, a device (/dev/zero) never end. A missing path is left to the reader's message."""
    try:
        st = os.stat(path)
    except OSError:
        return
    if stat.S_ISDIR(st.st_mode):
        raise error(f"{path}: is a folder, not a {what}")
    if not stat.S_ISREG(st.st_mode):
        raise error(f"{path}: is {_file_kind(st.st_mode)}, not a {what} (a regular file)")


def _file_kind(mode: int) -> str:
    for test, name in (
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return name
    return "not a regular file"


class _Refused(Exception):
    """A YAML construct the safe loader refuses: ``line`` (1-based) and a message."""

    def __init__(self, line: int, message: str) -> None:
        super().__init__(message)
        self.line = line
        self.message = message


class _SafeLoader(yaml.SafeLoader):
    """yaml.SafeLoader that refuses aliases (``*name``: a few hundred bytes of nested aliases
    expand to billions of nodes in whatever walks the result) and duplicate keys (YAML says
    a key is unique; PyYAML lets the last one win silently)."""

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise _Refused(
                event.start_mark.line + 1,
                f"alias *{_clip(str(event.anchor), 40)} refused: aliases are not accepted "
                "in hofto-hw files (write the value out)",
            )
        return super().compose_node(parent, index)

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:
        if isinstance(node, yaml.MappingNode):
            seen: dict[Any, int] = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                line = key_node.start_mark.line + 1
                try:
                    first = seen.get(key)
                except TypeError:  # an unhashable key: the constructor refuses it below
                    continue
                if first is not None:
                    raise _Refused(
                        line,
                        f"duplicate key {excerpt(key, 60)} (first at line {first}): "
                        "remove one (YAML keeps only the last, silently)",
                    )
                seen[key] = line
        return super().construct_mapping(node, deep=deep)


def _clip(text: str, limit: int) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


def excerpt(value: Any, limit: int = 80) -> str:
    """A bounded repr of ``value`` (at most ``limit`` characters): never the repr of a whole
    input, which for a big or deeply shared structure costs as much as the input."""
    r = reprlib.Repr()
    r.maxstring = r.maxother = limit
    r.maxlist = r.maxtuple = r.maxdict = r.maxset = 6
    r.maxlevel = 3
    shown = r.repr(value)
    return shown if len(shown) <= limit else shown[: limit - 3] + "..."


class NoAliasDumper(yaml.SafeDumper):
    """YAML writer for every file the stack writes: values written out, never as aliases
    (:func:`read_yaml` refuses aliases, so a file we write must read back)."""

    def ignore_aliases(self, data: Any) -> bool:
        return True


def dump_yaml(data: Any, **kwargs: Any) -> str:
    """``yaml.safe_dump`` without anchors and aliases (see :class:`NoAliasDumper`)."""
    return yaml.dump(data, Dumper=NoAliasDumper, **kwargs)


def read_yaml(
    path: str | Path,
    what: str,
    error: type[UserError] = ConfigError,
    *,
    max_bytes: int = MAX_YAML_BYTES,
) -> dict:
    """Parse the YAML file ``path`` whose top level must be a mapping; ``what`` names the kind
    of file in messages ("config file", "column map", ...).

    The one YAML reader of the stack (config, parameters, thresholds, column maps, drive
    profiles): a regular file of at most ``max_bytes`` (checked before reading: a FIFO, a
    device or a huge file never blocks or fills memory), no aliases, no duplicate keys.

    Raises ``error`` with one line naming the file: not found, a folder, not a regular file,
    too large, unreadable, empty, binary, not UTF-8 at byte N, not valid YAML at line L
    column C (a truncated file says it ends early), an alias or a duplicate key at line L,
    or not a mapping.
    """
    raw = read_bounded(path, what, max_bytes, error)
    return parse_yaml_bytes(raw, str(path), what, error, max_bytes=max_bytes)


def parse_yaml_bytes(
    raw: bytes,
    source: str,
    what: str,
    error: type[UserError] = ConfigError,
    *,
    max_bytes: int = MAX_YAML_BYTES,
) -> dict:
    """Decode and parse YAML ``raw`` with the rules of :func:`read_yaml`; ``source`` names
    it in messages. For YAML that is not a file of its own (a config attached to a log)."""
    if len(raw) > max_bytes:
        raise error(f"{source}: {len(raw)} bytes; a {what} is at most {max_bytes} bytes")
    text = _decode(raw, source, what, error)
    try:
        data = yaml.load(text, Loader=_SafeLoader)  # a SafeLoader subclass
    except _Refused as exc:
        raise error(f"{source}: line {exc.line}: {exc.message}") from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        problem = _clip(" ".join(str(exc.problem or exc.context or "invalid").split()), 160)
        if mark is None:
            raise error(f"{source}: not valid YAML: {problem}") from None
        at_end = mark.index >= len(text.rstrip())
        ends_early = at_end or "<stream end>" in problem or "end of stream" in problem
        hint = " (the file ends early: truncated?)" if ends_early else ""
        raise error(
            f"{source}: line {mark.line + 1} column {mark.column + 1}: not valid YAML{hint}: "
            f"{problem}"
        ) from None
    except yaml.reader.ReaderError as exc:
        at = exc.position
        line, column = text.count("\n", 0, at) + 1, at - text.rfind("\n", 0, at)
        raise error(
            f"{source}: line {line} column {column}: not valid YAML: control character "
            f"U+{_code_point(exc.character):04X} is not allowed in a {what}"
        ) from None
    except (yaml.YAMLError, RecursionError, ValueError) as exc:
        # ValueError: an integer literal longer than Python's int() accepts (4300 digits)
        reason = "nested too deeply" if isinstance(exc, RecursionError) else str(exc)
        first = reason.splitlines()[0] if reason else type(exc).__name__
        raise error(f"{source}: not valid YAML: {_clip(first, 160)}") from None
    if data is None:
        raise error(f"{source}: {what} is empty")
    if not isinstance(data, dict):
        raise error(
            f"{source}: expected a mapping (key: value lines) at the top level of a {what}, "
            f"got {_kind(data)}"
        )
    return data


def _decode(raw: bytes, path: str | Path, what: str, error: type[UserError]) -> str:
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
    return f"a single value {excerpt(data, 40)}"


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
