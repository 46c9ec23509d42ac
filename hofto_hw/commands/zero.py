"""``hofto-hw zero set --joint J --at RAD``: re-zero a joint a person has put at a reference.

Offline, against the config and the positions the service stored at its last clean shutdown
(``hofto_hw.runtime.positions``; the service must be stopped: the command does not talk to
it). The drive's ``zero_offset`` [counts] in the config is rewritten so that the stored
position of J reads RAD:

    zero_new = zero_old + direction · (q_stored − RAD) · counts_per_rev · gear_ratio / 2π

Refused (one line, nothing written) when no positions are stored, the arm was moving or a
fault was latched at that shutdown, the config's offset is not the one the position was read
with, or the config's text has no ``bus.drives[J]`` to edit. The edit touches only that value
(comments and layout kept), is checked by loading the new config before it replaces the old
one (atomically), the old file is kept as ``<config>.bak-<time>``, the change is appended to
``zero_changes.log`` beside the positions file and the stored position is updated.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import math
import shutil
from pathlib import Path

import yaml

from hofto_hw.commands.args import HelpFormatter, add_config
from hofto_hw.errors import UserError


def configure(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    st = sub.add_parser(
        "set",
        help="rewrite a joint's zero offset so its position reads RAD",
        formatter_class=HelpFormatter,
    )
    add_config(st, default="er3a")
    st.add_argument("--joint", required=True, help="joint name or number (1-based)")
    st.add_argument("--at", required=True, metavar="RAD", help="the joint's true angle [rad]")
    st.add_argument(
        "--positions",
        type=Path,
        help="positions file (default: last_positions.yaml in run.log_dir)",
    )


def run(args: argparse.Namespace) -> int:
    from hofto_hw.commands.run import _log_dir
    from hofto_hw.config import load_config
    from hofto_hw.config.locate import find_config
    from hofto_hw.runtime.positions import load_positions, save_positions, state_path

    config_path = find_config(args.config)
    cfg = load_config(config_path)
    if cfg.bus is None:
        raise UserError(f"{config_path}: bus: section missing: no drive zero offset to set")
    joints = list(cfg.robot.joints)
    j = joint_index(args.joint, joints)
    try:
        at = float(args.at)
    except ValueError:
        raise UserError(f"zero set: --at {args.at!r} is not a number [rad]") from None
    if not math.isfinite(at):
        raise UserError(f"zero set: --at must be a finite angle [rad], got {args.at}")
    positions = args.positions or state_path(_log_dir(cfg, config_path))
    last = load_positions(positions)
    if last is None:
        raise UserError(
            f"{positions}: no positions stored; run the service and stop it cleanly first"
        )
    name = joints[j]
    if name not in last.joints:
        raise UserError(f"{positions}: no stored position for joint {name}")
    if last.latched:
        raise UserError(
            f"{positions}: a fault was latched at the last shutdown ({', '.join(last.latched)}): "
            "reset it and stop the service cleanly first"
        )
    if not last.at_rest:
        raise UserError(f"{positions}: the arm was moving at the last shutdown; stop it first")
    k = last.joints.index(name)
    drive = cfg.bus.drives[j]
    if last.zero_offsets[k] != drive.zero_offset:
        raise UserError(
            f"{positions}: {name} was read with zero_offset {last.zero_offsets[k]}, the config "
            f"has {drive.zero_offset}: the config changed since; restart the service first"
        )
    counts_per_rad = drive.counts_per_rev * drive.gear_ratio / (2.0 * math.pi)
    stored = float(last.positions[k])
    new = int(round(drive.zero_offset + drive.direction * (stored - at) * counts_per_rad))
    text = config_path.read_text()
    new_text = _with_zero_offset(text, j, new, config_path)
    _check_edit(new_text, config_path, cfg, j, new)
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    backup = config_path.with_name(f"{config_path.name}.bak-{stamp}")
    shutil.copy2(config_path, backup)
    from hofto_hw.runtime.positions import write_atomic

    write_atomic(config_path, new_text)
    last.positions[k] = at
    last.zero_offsets[k] = new
    save_positions(positions, last)
    line = (
        f"{stamp} {config_path}: {name} zero_offset {drive.zero_offset} -> {new} counts "
        f"(stored position {stored:.6f} rad set to {at:.6f} rad); backup {backup.name}\n"
    )
    with open(positions.parent / "zero_changes.log", "a") as log:
        log.write(line)
    print(f"zero set: {line.strip()}")
    return 0


def joint_index(text: str, joints: list[str]) -> int:
    if text in joints:
        return joints.index(text)
    if text.isdigit() and 1 <= int(text) <= len(joints):
        return int(text) - 1
    raise UserError(
        f"zero set: --joint {text!r}: not one of {', '.join(joints)} or 1-{len(joints)}"
    )


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


def _check_edit(new_text: str, source: Path, old, j: int, value: int) -> None:
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
