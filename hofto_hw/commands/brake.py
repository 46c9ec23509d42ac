"""``hofto-hw brake test [--joint J] [--torque FRACTION]``: does each holding brake hold?

Commissioning step run while the service is stopped (it opens the bus itself, like
``hofto-hw home``). Every axis with a master-controlled brake (``brake: {control: output}``)
is enabled with its brake kept closed; the tested axis switches to CST and carries the
identified gravity torque plus +T then −T (T = FRACTION of the brake's rated holding torque,
drivers/cia402/brake.py) while the other axes hold their position in CSP. One line per axis:
held, with the largest motion, or slipped (exit code 2). Brakes the drive controls open on
Operation enabled and cannot be tested this way (named, skipped). Refused while a drive is in
Fault.
"""

from __future__ import annotations

import argparse

import numpy as np

from hofto_hw.commands.args import HelpFormatter, add_config
from hofto_hw.errors import UserError

#: [s] held after enabling, before the first test: the joints settle on their closed brakes
SETTLE = 0.5


def configure(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    t = sub.add_parser(
        "test", help="apply a torque against each closed brake", formatter_class=HelpFormatter
    )
    add_config(t, default="er3a")
    t.add_argument("--joint", help="test only this joint (name or 1-based number)")
    t.add_argument(
        "--torque",
        default="0.8",
        metavar="FRACTION",
        help="test torque as a fraction of the rated holding torque, in (0, 1]",
    )


def run(args: argparse.Namespace) -> int:
    from drivers.cia402.brake import BrakeTest, brake_test_plan
    from drivers.cia402.state_machine import Mode, State
    from hofto_hw.config import load_config
    from hofto_hw.config.locate import find_config
    from hofto_hw.runtime.compose import (
        build_bus,
        build_model,
        enable_drives,
        preload_braked_axes,
    )
    from hofto_hw.runtime.zero_offset import joint_index

    try:
        fraction = float(args.torque)
    except ValueError:
        fraction = float("nan")
    if not (0.0 < fraction <= 1.0):
        raise UserError(f"brake test: --torque must be a fraction in (0, 1], got {args.torque}")
    config_path = find_config(args.config)
    cfg = load_config(config_path)
    if cfg.bus is None:
        raise UserError(f"{config_path}: bus: section missing: no brake to test")
    joints = list(cfg.robot.joints)
    drives = cfg.bus.drives
    axes = [i for i, d in enumerate(drives) if d.brake is not None]
    if args.joint is not None:
        j = joint_index(args.joint, joints, "brake test")
        if drives[j].brake is None:
            raise UserError(f"{config_path}: bus.drives[{j}].brake: none: {joints[j]} has no brake")
        axes = [j]
    if not axes:
        print("brake test: no axis has a brake (bus.drives[i].brake)")
        return 0
    for i in axes:
        if drives[i].brake.control != "output":  # type: ignore[union-attr]
            print(
                f"brake test: {joints[i]}: the drive controls its brake (control: drive): "
                "use the drive's own brake test; skipped"
            )
    axes = [i for i in axes if drives[i].brake.control == "output"]  # type: ignore[union-attr]
    if not axes:
        return 0
    model = build_model(cfg)
    clock = "sim" if str(cfg.bus.transport) == "sim" else "real"
    bus, group = build_bus(cfg, clock)
    lines, failure = [], ""
    try:
        group.cycle()
        faulted = [
            joints[i] for i in range(group.n) if group.states[i] >= State.FAULT_REACTION_ACTIVE
        ]
        if faulted:
            raise UserError(f"brake test: refused: {', '.join(faulted)} in Fault (latched)")
        gravity = model.create_data().gravity(group.q).copy()
        preload_braked_axes(cfg, model, group)  # 0x60B2 = gravity on the braked axes only
        enable_drives(bus, group)
        # the drives take the load from the closed brakes (the preload): let the joints
        # settle on them before any test measures from where they are
        for _ in range(int(np.ceil(SETTLE / bus.cycle_time))):
            group.hold()
            bus.wait_next_cycle()
            group.cycle()
        rx, sc = bus.rx, group.scaling
        raw = np.zeros(group.n, dtype=rx["target_torque"].dtype)
        for a in axes:
            b = drives[a].brake
            test = BrakeTest(
                brake_test_plan(a, joints[a], b.holding_torque, fraction, bus.cycle_time)  # type: ignore[union-attr]
            )
            # gravity stays in the torque offset 0x60B2 (it adds to the CST target too), so
            # no cycle of the mode change leaves it to the brake; only a drive without the
            # offset mapped gets it in the target torque
            with_offset = bool(group.present("torque_offset")[a])
            tau = gravity.copy()
            rx["mode"][a] = Mode.CST
            while not test.done:
                tau[a] = test.torque if with_offset else gravity[a] + test.torque
                sc.torque_to_raw(tau, raw)
                rx["target_torque"][a] = raw[a]
                group.hold()
                bus.wait_next_cycle()
                group.cycle()
                test.step(float(group.q[a]))
            rx["mode"][a] = Mode.CSP
            group.hold()
            if test.result:
                failure = test.result
                break
            lines.append(
                f"brake test: {joints[a]} held {fraction:.0%} of {b.holding_torque:g} N·m "  # type: ignore[union-attr]
                f"(largest motion {test.worst * 1e3:+.3f} mrad)"
            )
        group.disable()
    finally:
        bus.close()
    for line in lines:
        print(line)
    if failure:
        raise UserError(f"brake test: {failure}")
    return 0
