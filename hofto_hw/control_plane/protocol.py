"""The control socket's wire format, both directions: one JSON object per line.

Requests (client -> service) are objects with ``"cmd"`` and that command's fields, checked
here (:func:`parse_request`) before anything acts on them; a line longer than
:data:`MAX_LINE` bytes, not UTF-8, not JSON, nested deeper than :data:`MAX_DEPTH`, or with
an unknown command, an unknown or mistyped field is refused with one line naming it. An
optional ``"id"`` (int or str) is echoed in the reply.

Replies (service -> client) are objects with ``"ok"`` (bool) and ``"message"`` (str) or
the command's fields; :func:`parse_reply` is the clients' check (the same limits, finite
numbers only, ``ok`` a bool).
"""

from __future__ import annotations

import json
import math
from typing import Any

MAX_LINE = 65536  # bytes of one request line (the longest real one, a path, is ~4 KiB)
MAX_REPLY = 4 << 20  # bytes of one reply line a client accepts
MAX_DEPTH = 32  # nesting of arrays and objects

MODES = ("hold", "move", "drag")

#: the stop socket beside the control socket ``S``: ``S.stop`` (control_plane/stop_server.py)
STOP_SUFFIX = ".stop"


def stop_path(control: Any) -> Any:
    """The stop socket's path (a ``pathlib.Path``) beside the control socket ``control``."""
    import os
    from pathlib import Path

    p = Path(os.path.abspath(control))
    return p.with_name(p.name + STOP_SUFFIX)


#: command -> {field: (types, required)}; types are Python types a JSON value may have
_FLOAT = (int, float)
COMMANDS: dict[str, dict[str, tuple[tuple[type, ...], bool]]] = {
    "hello": {"name": ((str,), False)},
    "status": {},
    "state": {},
    "stop": {},
    "reset": {},
    "mode": {"mode": ((str,), True), "record": ((str,), False), "force": ((bool,), False)},
    "replay": {"file": ((str,), True)},
    "move_joints": {
        "q": ((list,), True),
        "speed": (_FLOAT, False),
        "acceleration": (_FLOAT, False),
    },
    "move_linear": {
        "pose": ((list,), True),
        "speed": (_FLOAT, False),
        "acceleration": (_FLOAT, False),
    },
    "cancel": {},
    "enable": {"on": ((bool,), True)},
    "release": {},
    "events": {"since": ((int,), False)},
    "stream_info": {},
    "set_safety_profile": {"name": ((str,), True)},
    "set_payload": {"mass": (_FLOAT, True), "com": ((list,), True)},
    "home": {"joints": ((list,), False)},
    "zero_set": {"joint": ((str, int), True), "at": (_FLOAT, True)},
}
#: commands that move the arm or hold the enabling input: one client at a time
MOTION = frozenset(
    {
        "mode",
        "replay",
        "move_joints",
        "move_linear",
        "cancel",
        "enable",
        "set_safety_profile",
        "set_payload",
        "home",
        "zero_set",
    }
)


class ProtocolError(ValueError):
    """A request or reply that is not what the protocol allows (one line)."""


def _depth_ok(text: str, limit: int) -> bool:
    """True when no array/object nests deeper than ``limit`` (brackets inside strings are
    counted too: a string of brackets is refused rather than parsed; cheap and safe)."""
    depth = 0
    for c in text:
        if c == "[" or c == "{":
            depth += 1
            if depth > limit:
                return False
        elif c == "]" or c == "}":
            depth -= 1
    return True


def _no_constant(name: str) -> Any:
    raise ProtocolError(f"{name} is not a number JSON allows")


def loads_line(raw: bytes, limit: int, what: str) -> dict[str, Any]:
    """One line (without its newline) -> a JSON object; ProtocolError naming what is wrong."""
    if len(raw) > limit:
        raise ProtocolError(f"{what} longer than {limit} bytes")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ProtocolError(f"{what} is not UTF-8 (byte {exc.start})") from None
    if not text.strip():
        raise ProtocolError(f"empty {what}")
    if "[" in text or "{" in text:
        if not _depth_ok(text, MAX_DEPTH):
            raise ProtocolError(f"{what} nested deeper than {MAX_DEPTH} levels")
    try:
        obj = json.loads(text, parse_constant=_no_constant)
    except ProtocolError as exc:
        raise ProtocolError(f"{what}: {exc}") from None
    except (ValueError, RecursionError) as exc:
        raise ProtocolError(f"{what} is not JSON: {exc}") from None
    if not isinstance(obj, dict):
        raise ProtocolError(f"{what} is not a JSON object (got {type(obj).__name__})")
    return obj


def parse_request(raw: bytes) -> dict[str, Any]:
    """A request line -> a checked request dict (``cmd`` and its fields)."""
    req = loads_line(raw, MAX_LINE, "request")
    cmd = req.get("cmd")
    if not isinstance(cmd, str) or cmd not in COMMANDS:
        known = ", ".join(COMMANDS)
        raise ProtocolError(f"request: unknown cmd {_short(cmd)} (known: {known})")
    fields = COMMANDS[cmd]
    for key, value in req.items():
        if key in ("cmd", "id"):
            continue
        if key not in fields:
            raise ProtocolError(f"{cmd}: unknown field {_short(key)}")
        types, _ = fields[key]
        if isinstance(value, bool) and bool not in types:
            raise ProtocolError(f"{cmd}.{key}: expected {types[0].__name__}, got {value!r}")
        if not isinstance(value, types):
            raise ProtocolError(
                f"{cmd}.{key}: expected {types[0].__name__}, got {type(value).__name__}"
            )
    for key, (_, required) in fields.items():
        if required and key not in req:
            raise ProtocolError(f"{cmd}: missing field {key!r}")
    rid = req.get("id")
    if rid is not None and not (isinstance(rid, (int, str)) and not isinstance(rid, bool)):
        raise ProtocolError("request.id: expected an int or a string")
    if cmd == "mode" and req["mode"] not in MODES:
        raise ProtocolError(f"mode: unknown mode {_short(req['mode'])} (known: {', '.join(MODES)})")
    return req


def numbers(values: list[Any], what: str, n: int | None = None) -> list[float]:
    """A list of finite numbers (``n`` of them when given); ProtocolError otherwise."""
    if n is not None and len(values) != n:
        raise ProtocolError(f"{what}: {len(values)} values, expected {n}")
    out = []
    for i, v in enumerate(values):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ProtocolError(f"{what}[{i}]: {_short(v)} is not a finite number")
        out.append(float(v))
    return out


def _check_finite(obj: Any, path: str) -> None:
    if isinstance(obj, float) and not math.isfinite(obj):
        raise ProtocolError(f"reply: {path} is {obj}")
    if isinstance(obj, dict):
        for k, v in obj.items():
            _check_finite(v, f"{path}.{k}")
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            _check_finite(v, f"{path}[{i}]")


def parse_reply(raw: bytes) -> dict[str, Any]:
    """A reply line -> its dict: a JSON object with a bool ``ok``, every number finite."""
    rep = loads_line(raw, MAX_REPLY, "reply")
    if not isinstance(rep.get("ok"), bool):
        raise ProtocolError(f"reply: 'ok' is {_short(rep.get('ok', 'missing'))}, not a bool")
    msg = rep.get("message", "")
    if msg is not None and not isinstance(msg, str):
        raise ProtocolError("reply: 'message' is not a string")
    _check_finite(rep, "reply")
    return rep


def dumps(obj: dict[str, Any]) -> bytes:
    """One line (no NaN/inf: refused by the reader; callers send finite numbers)."""
    return json.dumps(obj, allow_nan=False, separators=(",", ":")).encode() + b"\n"


def _short(v: Any) -> str:
    text = repr(v)
    return text if len(text) <= 60 else text[:57] + "..."
