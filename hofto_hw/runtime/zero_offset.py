"""Rewriting a drive's ``zero_offset`` in the config (``hofto-hw zero set``), offline and
through the service (the control plane's process does the file work; the loop only takes the
new offset at a tick boundary, hofto_hw/control_plane/port.py).

The new offset makes the joint's position ``q`` [rad] (read with the current offset) read
``at`` [rad]:

    zero_new = zero_old + direction · (q − at) · counts_per_rev · gear_ratio / 2π

The edit touches only that value in the file's text (comments and layout kept), is checked by
loading the edited config (exactly that one value changed) before anything is written, the
old file is kept as ``<config>.bak-<time>``, the new one replaces it atomically, and the
change is appended to ``zero_changes.log`` in the given folder (beside the positions file).
"""

from __future__ import annotations

import datetime as _dt
import math
import shutil
from pathlib import Path
from typing import Any

import yaml

from hofto_hw.errors import UserError

LOG_FILE = "zero_changes.log"


def joint_index(text: str, joints: list[str], what: str = "zero set") -> int:
    """A joint given by name or 1-based number -> its index (UserError naming the choices)."""
    if text in joints:
        return joints.index(text)
    if text.isdigit() and 1 <= int(text) <= len(joints):
        return int(text) - 1
    raise UserError(f"{what}: --joint {text!r}: not one of {', '.join(joints)} or 1-{len(joints)}")


def parse_angle(text: Any) -> float:
    """``--at`` as a finite angle [rad] (UserError otherwise)."""
    try:
        at = float(text)
    except (TypeError, ValueError):
        raise UserError(f"zero set: --at {str(text)[:40]!r} is not a number [rad]") from None
    if not math.isfinite(at):
        raise UserError(f"zero set: --at must be a finite angle [rad], got {text}")
    return at


def _scaling(drive: Any) -> Any:
    from drivers.cia402.units import AxisScaling, Scaling

    return Scaling([AxisScaling.from_config(drive)])


def new_zero_offset(drive: Any, zero_old: float, q: float, at: float) -> int:
    """The offset [counts] under which position ``q`` [rad] (read with ``zero_old``) reads
    ``at`` [rad]; ``drive``: its DriveConfig (direction, counts_per_rev, gear_ratio)."""
    return int(round(zero_old + (q - at) * float(_scaling(drive).count_per_rad[0])))


def shift_of(drive: Any, zero_old: float, zero_new: float) -> float:
    """How far [rad] a position read with ``zero_old`` moves when read with ``zero_new``."""
    return float((zero_old - zero_new) * _scaling(drive).rad_per_count[0])


def prepare_edit(config_path: Path, cfg: Any, j: int, value: int) -> str:
    """The config's text with ``bus.drives[j].zero_offset = value``, checked by loading it
    (UserError, nothing written, when it cannot be edited or loads differently)."""
    text = config_path.read_text()
    new_text = _with_zero_offset(text, j, value, config_path)
    _check_edit(new_text, config_path, cfg, j, value)
    return new_text


def commit_edit(config_path: Path, new_text: str, log_folder: Path, what: str) -> str:
    """Keep a backup, replace the config atomically, append ``what`` to the change log;
    returns the log line (without its newline). OSError propagates (nothing replaced when
    the backup could not be made)."""
    from hofto_hw.runtime.positions import write_atomic

    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    backup = config_path.with_name(f"{config_path.name}.bak-{stamp}")
    k = 1
    while backup.exists():  # two changes within a second: never overwrite a backup
        backup = config_path.with_name(f"{config_path.name}.bak-{stamp}-{k}")
        k += 1
    shutil.copy2(config_path, backup)
    write_atomic(config_path, new_text)
    line = f"{stamp} {config_path}: {what}; backup {backup.name}"
    log_folder.mkdir(parents=True, exist_ok=True)
    with open(log_folder / LOG_FILE, "a") as log:
        log.write(line + "\n")
    return line


def _with_zero_offset(text: str, j: int, value: int, source: Path) -> str:
    """``text`` with ``bus.drives[j].zero_offset`` set to ``value`` (only that span edited)."""
    try:
        root = yaml.compose(text)
    except yaml.YAMLError:
        raise UserError(f"{source}: not valid YAML") from None

    def child(node, key):
        if not isinstance(node, yaml.MappingNode):
            return None
        for k, v in node.value:
            if isinstance(k, yaml.ScalarNode) and k.value == key:
                return k, v
        return None

    bus = child(root, "bus")
    drives = child(bus[1], "drives") if bus else None
    if drives is None or not isinstance(drives[1], yaml.SequenceNode) or j >= len(drives[1].value):
        raise UserError(f"{source}: no bus.drives[{j}] in this file to rewrite (an included file?)")
    item = drives[1].value[j]
    if not isinstance(item, yaml.MappingNode) or not item.value:
        raise UserError(f"{source}: bus.drives[{j}] is not a mapping")
    found = child(item, "zero_offset")
    if found is not None:
        v = found[1]
        return text[: v.start_mark.index] + str(value) + text[v.end_mark.index :]
    if item.flow_style:
        at = item.start_mark.index + 1
        return text[:at] + f"zero_offset: {value}, " + text[at:]
    first = item.value[0][0]
    at = first.start_mark.index
    return text[:at] + f"zero_offset: {value}\n" + " " * first.start_mark.column + text[at:]


def _check_edit(new_text: str, source: Path, old: Any, j: int, value: int) -> None:
    """Load the edited text as a config: the one offset changed, nothing else."""
    import tempfile

    from hofto_hw.config import load_config

    with tempfile.NamedTemporaryFile("w", suffix=".yaml", dir=source.parent, delete=True) as f:
        f.write(new_text)
        f.flush()
        try:
            cfg = load_config(Path(f.name))
        except Exception as exc:
            raise UserError(
                f"{source}: the edited config does not load ({exc}); unchanged"
            ) from None
    want = old.model_dump()
    want["bus"]["drives"][j]["zero_offset"] = value
    if cfg.model_dump() != want:
        raise UserError(f"{source}: editing zero_offset changed more than it; file unchanged")
