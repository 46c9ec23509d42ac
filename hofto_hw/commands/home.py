"""``hofto-hw home [--joint J]``: CiA 402 homing of the incremental axes (``homing:`` per
drive in ``bus.drives``; ``homing: none`` = absolute encoder, never homed).

- **A service runs** (``--socket``, or the config's ``service.socket`` / the default socket
  answers): through it (``Robot.home``). The loop homes each axis in turn
  (hofto_hw/runtime/homing_run.py) and returns it to its mode; refused while anything is
  latched, while the arm moves, or while another client holds motion.
- **No service runs**: the command opens the bus itself, refuses when a drive is in Fault
  (faults latch: reset them first), enables the drives holding their positions, homes each
  axis in turn (drivers/cia402/homing.py: method, speeds, acceleration, offset, timeout),
  returns it to the loop's mode (CSP), disables the drives and closes the bus.

One line per homed axis; a failure (timeout, homing error, end position off the offset) is one
error line (exit code 2), the axes after it are not homed.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from hofto_hw.commands.args import add_config
from hofto_hw.errors import UserError
from hofto_hw.runtime.control_client import add_service_socket_argument


def configure(parser: argparse.ArgumentParser) -> None:
    add_config(parser, default="er3a")
    parser.add_argument("--joint", help="home only this joint (name or 1-based number)")
    add_service_socket_argument(parser)


def run(args: argparse.Namespace) -> int:
    from drivers.cia402.homing import home_axes, homing_plan
    from drivers.cia402.state_machine import State
    from hofto_hw.config import load_config
    from hofto_hw.config.locate import find_config
    from hofto_hw.runtime.compose import build_bus, enable_drives
    from hofto_hw.runtime.zero_offset import joint_index

    config_path = find_config(args.config)
    cfg = load_config(config_path)
    if cfg.bus is None:
        raise UserError(f"{config_path}: bus: section missing: no drive to home")
    joints = list(cfg.robot.joints)
    axes = [i for i, d in enumerate(cfg.bus.drives) if d.homing is not None]
    if args.joint is not None:
        j = joint_index(args.joint, joints, "home")
        if cfg.bus.drives[j].homing is None:
            raise UserError(
                f"{config_path}: bus.drives[{j}].homing: none: {joints[j]} has an absolute "
                "encoder, nothing to home"
            )
        axes = [j]
    from hofto_hw.runtime.control_client import running_service

    sock = running_service(args.socket, cfg)  # a --socket nobody answers: one line, first
    if not axes:
        print("home: every axis has homing: none (absolute encoders): nothing to home")
        return 0
    if sock is not None:
        return _through_service(sock, [(joints[i], cfg.bus.drives[i].homing) for i in axes])
    clock = "sim" if str(cfg.bus.transport) == "sim" else "real"
    bus, group = build_bus(cfg, clock)
    try:
        group.cycle()
        faulted = [
            joints[i] for i in range(group.n) if group.states[i] >= State.FAULT_REACTION_ACTIVE
        ]
        if faulted:
            raise UserError(
                f"home: refused: {', '.join(faulted)} in Fault (latched); reset the faults first"
            )
        enable_drives(bus, group)
        plans = [
            homing_plan(
                cfg.bus.drives[i].homing,  # type: ignore[arg-type]
                group.scaling,
                i,
                bus.cycle_time,
                joints[i],
                group.drive_units(i),
            )
            for i in axes
        ]
        failure = home_axes(group, plans)
        group.disable()
    finally:
        bus.close()
    for plan in plans:
        if failure.startswith(plan.name + ":"):
            raise UserError(f"home: {failure}")
        print(f"home: {plan.name} homed (method {plan.method}) at {plan.offset:.4f} rad")
    return 0


def _through_service(sock: Path, axes: list) -> int:
    """Home ``axes`` ((name, homing config) in axis order) through the service at ``sock``."""
    from hofto_hw.client import Refused, Robot, ServiceError

    try:
        with Robot.connect(socket=sock) as robot:
            robot.home([name for name, _ in axes])
    except (Refused, ServiceError) as exc:
        raise UserError(f"home: {exc}") from None
    for name, h in axes:
        print(f"home: {name} homed (method {h.method}) at {h.offset:.4f} rad, through {sock}")
    return 0
