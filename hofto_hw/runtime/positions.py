"""The last known joint positions across a power cycle (the absolute zero, issue 28).

A multi-turn absolute encoder that loses its turn count (battery change, a glitch) comes back
a whole motor turn away, which through a 100:1 gearbox is 3.6° at the joint: nothing else
notices. At a clean shutdown the service writes the measured joint positions to a small state
file beside the logs (``last_positions.yaml``, written atomically: temporary file, fsync,
rename); at start-up, before any drive is enabled, every joint whose read position differs
from the stored one by more than its bound (default half a motor turn at the joint,
π / gear_ratio) is refused in one line naming the joint, the stored and the read position.

``hofto-hw zero set --joint J --at RAD`` (commands/zero.py) re-zeroes a joint that a person
has put at a reference: it rewrites the drive's ``zero_offset`` in the config, so that the
joint position stored at the last clean shutdown reads RAD.

File I/O only: nothing here runs in the tick.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from hofto_hw.config.loader import dump_yaml
from hofto_hw.errors import UserError

STATE_FILE = "last_positions.yaml"
FORMAT = "hofto-hw/last-positions"


@dataclass
class LastPositions:
    """What a clean shutdown left: joint names, positions [rad], the drives' zero offsets
    [counts] the positions were read with, whether the arm was at rest and nothing latched."""

    joints: list[str]
    positions: np.ndarray
    zero_offsets: list[int]
    at_rest: bool = True
    latched: list[str] | None = None
    written: str = ""


def state_path(log_dir: Path) -> Path:
    """The state file in the service's log folder."""
    return Path(log_dir) / STATE_FILE


def write_atomic(path: Path, text: str) -> None:
    """Replace ``path`` by ``text``: a temporary file in the same folder, fsync, rename; a
    reader sees the old file or the new one, never half of one."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    dirfd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dirfd)
    finally:
        os.close(dirfd)


def save_positions(path: Path, last: LastPositions) -> None:
    """Write ``last`` atomically to ``path``."""
    doc: dict[str, Any] = {
        "format": FORMAT,
        "written": last.written or _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "at_rest": bool(last.at_rest),
        "latched": list(last.latched or []),
        "joints": {
            name: {"position": float(q), "zero_offset": int(z)}
            for name, q, z in zip(last.joints, last.positions, last.zero_offsets, strict=True)
        },
    }
    write_atomic(
        path,
        "# hofto-hw: joint positions at the last clean shutdown\n"
        + dump_yaml(doc, sort_keys=False),
    )


def load_positions(path: Path) -> LastPositions | None:
    """The state file's content; None when there is none (first start). UserError in one
    line for a file that is not one."""
    path = Path(path)
    if not path.is_file():
        return None
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise UserError(f"{path}: not a readable positions file ({type(exc).__name__})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise UserError(f"{path}: not a hofto-hw positions file (format: {FORMAT} missing)")
    joints = doc.get("joints")
    if not isinstance(joints, dict) or not joints:
        raise UserError(f"{path}: joints: expected a mapping joint -> position, zero_offset")
    names, q, z = [], [], []
    for name, entry in joints.items():
        try:
            pos = float(entry["position"])
            off = int(entry["zero_offset"])
        except (TypeError, KeyError, ValueError):
            raise UserError(
                f"{path}: joints.{name}: needs position [rad] and zero_offset"
            ) from None
        if not math.isfinite(pos):
            raise UserError(f"{path}: joints.{name}.position: not finite ({pos})")
        names.append(str(name))
        q.append(pos)
        z.append(off)
    return LastPositions(
        names,
        np.array(q),
        z,
        at_rest=bool(doc.get("at_rest", False)),
        latched=[str(x) for x in doc.get("latched") or []],
        written=str(doc.get("written", "")),
    )


def turn_bounds(gear_ratios: np.ndarray | list[float]) -> np.ndarray:
    """Default bound per joint [rad]: half a motor turn at the joint side, π / gear_ratio."""
    return math.pi / np.asarray(gear_ratios, dtype=float)


def check_positions(
    last: LastPositions | None, joints: list[str], q: np.ndarray, bounds: np.ndarray, source: Path
) -> None:
    """Refuse (UserError, one line) the first joint whose read position ``q`` [rad] is more
    than ``bounds`` [rad] away from the stored one; nothing stored = nothing to check."""
    if last is None:
        return
    if list(last.joints) != list(joints):
        raise UserError(
            f"{source}: stored for joints {', '.join(last.joints)}, the robot has "
            f"{', '.join(joints)}: remove the file if the robot changed"
        )
    diff = np.asarray(q, dtype=float) - last.positions
    for j, name in enumerate(joints):
        if not abs(diff[j]) <= bounds[j]:
            raise UserError(
                f"{name}: position {q[j]:.5f} rad read at start-up, {last.positions[j]:.5f} rad "
                f"stored at the last shutdown ({source}): {diff[j]:+.5f} rad, more than "
                f"{bounds[j]:.5f} rad (a lost encoder turn?); check the joint, then "
                f"'hofto-hw zero set --joint {name} --at RAD' at a reference"
            )
