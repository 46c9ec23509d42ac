"""``hofto-hw zero set --joint J --at RAD``: re-zero a joint a person has put at a reference.

The drive's ``zero_offset`` [counts] in the config is rewritten so that the joint's position
reads RAD (hofto_hw/runtime/zero_offset.py: the formula, the edit, the backup and the log).

- **A service runs** (``--socket``, or the config's ``service.socket`` / the default socket
  answers): through it (``Robot.zero_set``). The joint's live position is used; refused while
  the arm moves or a fault is latched; the service's own process rewrites its config and logs
  the change, and the loop reads the joint with the new offset from the next tick.
- **No service runs**: offline, against the positions the service stored at its last clean
  shutdown (``hofto_hw.runtime.positions``). Refused (one line, nothing written) when no
  positions are stored, the arm was moving or a fault was latched at that shutdown, or the
  config's offset is not the one the position was read with; the stored position is updated.

Either way the edit touches only that value (comments and layout kept), is checked by loading
the new config before it replaces the old one (atomically), the old file is kept as
``<config>.bak-<time>`` and the change is appended to ``zero_changes.log`` beside the
positions file (in ``run.log_dir``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from hofto_hw.commands.args import HelpFormatter, add_config
from hofto_hw.errors import UserError
from hofto_hw.runtime.control_client import add_service_socket_argument
from hofto_hw.runtime.zero_offset import (
    commit_edit,
    joint_index,
    new_zero_offset,
    parse_angle,
    prepare_edit,
)


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
        help="offline only: positions file (default: last_positions.yaml in run.log_dir)",
    )
    add_service_socket_argument(st)


def run(args: argparse.Namespace) -> int:
    from hofto_hw.config import load_config
    from hofto_hw.config.locate import find_config
    from hofto_hw.runtime.control_client import running_service

    config_path = find_config(args.config)
    cfg = load_config(config_path)
    if cfg.bus is None:
        raise UserError(f"{config_path}: bus: section missing: no drive zero offset to set")
    joints = list(cfg.robot.joints)
    j = joint_index(args.joint, joints)
    at = parse_angle(args.at)
    sock = running_service(args.socket, cfg)
    if sock is not None:
        if args.positions is not None:
            raise UserError("--positions: only offline; the running service reads the joint")
        from hofto_hw.client import Refused, Robot, ServiceError

        try:
            with Robot.connect(socket=sock) as robot:
                line = robot.zero_set(joints[j], at)
        except (Refused, ServiceError) as exc:
            raise UserError(f"zero set: {exc}") from None
        print(f"zero set: {line}")
        return 0
    return _offline(args, config_path, cfg, j, at)


def _offline(args: argparse.Namespace, config_path: Path, cfg, j: int, at: float) -> int:
    """No service runs: against the positions stored at its last clean shutdown."""
    from hofto_hw.commands.run import _log_dir
    from hofto_hw.runtime.positions import load_positions, save_positions, state_path

    joints = list(cfg.robot.joints)
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
    stored = float(last.positions[k])
    new = new_zero_offset(drive, drive.zero_offset, stored, at)
    new_text = prepare_edit(config_path, cfg, j, new)
    what = (
        f"{name} zero_offset {drive.zero_offset} -> {new} counts "
        f"(stored position {stored:.6f} rad set to {at:.6f} rad)"
    )
    try:
        line = commit_edit(config_path, new_text, positions.parent, what)
    except OSError as exc:
        raise UserError(f"zero set: {config_path}: not written ({exc.strerror})") from None
    last.positions[k] = at
    last.zero_offsets[k] = new
    save_positions(positions, last)
    print(f"zero set: {line}")
    return 0
