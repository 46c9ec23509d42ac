"""``hofto-hw bus ACTION``: the live bus.

- ``bus scan (--iface IF | --interface I --channel C) [-o DIR] [--json]``: read every
  drive on the bus (EtherCAT: SII identity and DC op mode, CoE 0x1018, 0x1C12/0x1C13 and the
  assigned mappings, 0x6502, which CiA-402 objects exist; CANopen: boot-up after NMT reset
  communication, 0x1018, the PDO communication and mapping parameters) and write a draft
  drive profile per distinct drive (``DIR/<name>.yaml``) plus the matching ``bus:`` section
  (``DIR/bus.yaml``); without ``-o`` they are printed. Two drives claiming one station alias
  or node id: refused in one line (exit 2). Files that exist are not overwritten.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from hofto_hw.commands.args import HelpFormatter
from hofto_hw.errors import UserError


def _configure_scan(p: argparse.ArgumentParser) -> None:
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--iface", metavar="IF", help="EtherCAT network interface")
    where.add_argument("--interface", metavar="I", help="python-can interface (CANopen)")
    p.add_argument("--channel", metavar="C", help="python-can channel (with --interface)")
    p.add_argument("--bitrate", type=int, default=1_000_000, help="CAN bitrate [bit/s]")
    p.add_argument("-o", "--output", type=Path, metavar="DIR", help="write the files here")
    p.add_argument("--json", action="store_true", help="print the result as JSON")


def scan_bus(args: argparse.Namespace) -> list[Any]:
    """The scanned drives (``drivers.cia402.scan.ScannedDrive``) of the bus ``args`` name."""
    if args.iface is not None:
        from drivers.ethercat.scan import scan

        return scan(args.iface)
    if not args.channel:
        raise UserError("--interface needs --channel (the python-can channel)")
    from drivers.canopen.scan import scan as can_scan

    return can_scan(args.interface, args.channel, args.bitrate)


def drafts(drives: list[Any]) -> tuple[list[Any], list[str]]:
    """(one draft profile per distinct drive, the profile name of each drive)."""
    from drivers.cia402.scan import draft_profile

    profiles: dict[tuple[Any, ...], Any] = {}
    names: list[str] = []
    used: set[str] = set()
    for d in drives:
        key = d.key()
        if key not in profiles:
            prof = draft_profile(d)
            name, k = prof.name, 2
            while name in used:  # the same model running another layout
                name, k = f"{prof.name}_{k}", k + 1
            used.add(name)
            profiles[key] = prof.model_copy(update={"name": name})
        names.append(profiles[key].name)
    return list(profiles.values()), names


def bus_section(
    args: argparse.Namespace, drives: list[Any], names: list[str], axes: list[int] | None = None
) -> str:
    """The ``bus:`` section of a config for the scanned bus (YAML text, with the values the
    bus does not tell left for the user). ``axes``: CiA-402 axes per drive (default 1); a
    multi-axis drive gets one joint per axis (``device``, ``device_axis``)."""
    axes = axes if axes is not None else [1] * len(drives)
    transport = "ethercat" if args.iface is not None else "canopen"
    lines = [
        "# written by `hofto-hw bus scan`: review it; values marked TODO are not on the bus",
        "bus:",
        f"  transport: {transport}",
        f"  interface: {args.iface if args.iface is not None else args.channel}",
    ]
    if transport == "canopen":
        ids = [int(d.address.split()[1]) for d in drives]
        lines += [
            "  canopen:",
            f"    can_interface: {args.interface}",
            f"    bitrate: {args.bitrate}",
            f"    node_ids: {ids}",
        ]
    lines.append("  drives:")
    joints = [(dev, k) for dev, n in enumerate(axes) for k in range(n)]
    for dev, k in joints:
        d, name = drives[dev], names[dev]
        cpr = d.units.get(0x608F, (None, None))[0]
        gear = d.units.get(0x6091)
        ratio = round(gear[0] / gear[1], 6) if gear and gear[1] else None
        on = [f"      device: {dev}", f"      device_axis: {k}"] if axes[dev] > 1 else []
        lines += [
            f"    - # {d.address}{f' axis {k}' if axes[dev] > 1 else ''}: {d.name}",
            f"      identity: {{vendor_id: 0x{d.vendor_id:08X}, product_code: "
            f"0x{d.product_code:08X}}}",
            *on,
            f"      profile: {name}",
            f"      counts_per_rev: {cpr if cpr else 'null  # TODO: encoder counts per motor rev'}",
            f"      gear_ratio: {ratio if ratio else 'null  # TODO: motor revs per joint rev'}",
            "      rated_torque: null          # TODO: 0x6076 [mN·m]",
            "      rated_current: null         # TODO: 0x6075 [mA]",
            "      torque_constant: null       # TODO: [N·m/A]",
            "      torque_limit: null          # TODO: joint side [N·m]",
            "      quick_stop_deceleration: null  # TODO: joint side [rad/s²]",
        ]
    return "\n".join(lines) + "\n"


def _run_scan(args: argparse.Namespace) -> int:
    from hofto_hw.config.drive_profile import profile_yaml

    if args.channel and args.interface is None:
        raise UserError("--channel goes with --interface (CANopen)")
    out: Path | None = args.output
    if out is not None and out.exists() and not out.is_dir():
        raise UserError(f"-o {out}: exists and is not a folder")
    drives = scan_bus(args)
    profiles, names = drafts(drives)
    by_name = {p.name: p for p in profiles}
    section = bus_section(args, drives, names, [by_name[n].axes for n in names])
    files = {
        f"{p.name}.yaml": profile_yaml(
            p, f"draft profile written by `hofto-hw bus scan` ({p.description})"
        )
        for p in profiles
    }
    files["bus.yaml"] = section
    written: list[str] = []
    if out is not None:
        clash = [n for n in files if (out / n).exists()]
        if clash:
            raise UserError(f"-o {out}: {clash[0]} exists; not overwritten (choose another folder)")
        out.mkdir(parents=True, exist_ok=True)
        for n, text in files.items():
            (out / n).write_text(text)
            written.append(str(out / n))
    if args.json:
        print(
            json.dumps(
                {
                    "drives": [
                        {
                            "address": d.address,
                            "name": d.name,
                            "vendor_id": d.vendor_id,
                            "product_code": d.product_code,
                            "revision": d.revision,
                            "profile": n,
                        }
                        for d, n in zip(drives, names, strict=True)
                    ],
                    "profiles": [p.model_dump(mode="json") for p in profiles],
                    "written": written,
                },
                indent=2,
            )
        )
    elif out is None:
        for n, text in files.items():
            print(f"--- {n}")
            print(text)
    else:
        for d, n in zip(drives, names, strict=True):
            print(f"{d.address}: {d.name} (0x{d.vendor_id:08X}:0x{d.product_code:08X}) -> {n}")
        print(f"wrote {len(written)} files to {out}")
    return 0


ACTIONS = {"scan": (_configure_scan, _run_scan, "read the live bus into draft drive profiles")}


def configure(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    for name, (conf, _, help_text) in ACTIONS.items():
        conf(
            sub.add_parser(
                name, help=help_text, description=help_text, formatter_class=HelpFormatter
            )
        )


def run(args: argparse.Namespace) -> int:
    return ACTIONS[args.action][1](args)
