"""``hofto-hw drive ACTION``: drive profiles (docs/drives.md).

- ``drive import FILE [--device SELECTOR] [--loop MODE] [-o PROFILE] [--json]``: build a drive
  profile from a vendor ESI (EtherCAT XML) or EDS/DCF (CANopen) file and say what was chosen
  and why.

Sub-commands are one row of :data:`ACTIONS` each: ``(configure, run, help)``.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from hofto_hw.commands.args import HelpFormatter, output_file, refuse_overwrite
from hofto_hw.errors import UserError

if TYPE_CHECKING:
    from drivers.profiles.description import DeviceDescription


def _configure_import(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", type=Path, metavar="FILE", help="vendor ESI (.xml) or EDS/DCF file")
    p.add_argument(
        "--device",
        metavar="SELECTOR",
        help="which device of a file that describes several: its number in the list, its "
        "name, or PRODUCT[:REVISION] (e.g. 0x30924:0x10420)",
    )
    p.add_argument(
        "--loop",
        choices=("csp", "csv", "cst", "ip", "pv"),
        help="mode the loop runs the drive in (default: csp, else csv, else cst; a drive "
        "without them: ip, else pv)",
    )
    p.add_argument(
        "-o",
        "--output",
        type=output_file,
        metavar="PROFILE",
        help="write the profile (YAML) here; its name is the file's stem",
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON")


def _run_import(args: argparse.Namespace) -> int:
    from drivers.profiles import read_vendor_description
    from drivers.profiles.choose import choose
    from hofto_hw.config.drive_profile import profile_yaml, write_profile

    out: Path | None = args.output
    refuse_overwrite(out, [args.file], "-o")
    if out is not None and out.suffix not in (".yaml", ".yml"):
        raise UserError(f"-o {out}: a drive profile is a .yaml file")
    descs = read_vendor_description(args.file)
    desc = select_device(args.file, descs, args.device)
    choice = choose(desc, loop=args.loop, name=out.stem if out is not None else None)
    profile = choice.profile
    header = (
        f"drive profile written by `hofto-hw drive import {args.file.name}`"
        + (f" --device {args.device!r}" if args.device else "")
        + f"\nfrom {desc.path.name} (sha256 {desc.sha256[:16]}...), device {desc.device!r}"
        + "\nwhy this layout:\n"
        + "\n".join(f"  {r}" for r in choice.reasons)
        + "\nsee docs/drives.md"
    )
    if out is not None:
        write_profile(profile, out, header)
    if args.json:
        print(
            json.dumps(
                {
                    "file": str(args.file),
                    "device": desc.device,
                    "profile": profile.model_dump(mode="json"),
                    "reasons": choice.reasons,
                    "written": str(out) if out is not None else None,
                },
                indent=2,
            )
        )
        return 0
    print(f"{args.file}: {desc.device} -> profile {profile.name} ({profile.bus})")
    for line in choice.reasons:
        print(f"  {line}")
    for side, pdos in (("rx", profile.rx_pdos), ("tx", profile.tx_pdos)):
        for pdo in pdos:
            entries = ", ".join(
                e.field or (f"pad{e.bits}" if e.index == 0 else f"0x{e.index:04X}:{e.subindex:02X}")
                for e in pdo.entries
            )
            kind = "fixed" if pdo.fixed else "written"
            print(f"  {side} 0x{pdo.index:04X} ({kind}, {pdo.bits // 8} bytes): {entries}")
    if out is not None:
        print(f"wrote {out}")
    else:
        sys.stdout.write(profile_yaml(profile))
    return 0


def select_device(
    path: Path, descs: list[DeviceDescription], selector: str | None
) -> DeviceDescription:
    """The device ``selector`` names (``--device``), or the file's only drive.

    Raises:
        UserError: no drive in the file (an I/O module), several and no selector (lists
            them), or a selector that matches none or several.
    """
    from drivers.profiles.choose import is_drive

    def label(k: int, d: DeviceDescription) -> str:
        rev = f":0x{d.revision:X}" if d.revision is not None else ""
        return f"[{k}] {d.device} (0x{d.product_code:X}{rev})"

    drives = [d for d in descs if is_drive(d)]
    if not drives:
        names = ", ".join(sorted({d.device for d in descs}))
        raise UserError(
            f"{path}: no CiA-402 drive described: {len(descs)} device(s) ({names}) without "
            "controlword 0x6040, statusword 0x6041 and position actual value 0x6064"
        )
    listing = "; ".join(label(k, d) for k, d in enumerate(drives, 1))
    if selector is None:
        if len(drives) == 1:
            return drives[0]
        raise UserError(
            f"{path}: describes {len(drives)} drives; choose one with --device: {listing}"
        )
    s = selector.strip()
    if s.isdigit() and 1 <= int(s) <= len(drives):
        return drives[int(s) - 1]
    found = [d for d in drives if d.device.lower() == s.lower()]
    if not found:
        found = [d for d in drives if _matches_code(d, s)]
    if not found:
        found = [d for d in drives if s.lower() in d.device.lower()]
    if len(found) == 1:
        return found[0]
    what = "matches none" if not found else f"matches {len(found)}"
    raise UserError(f"{path}: --device {selector!r} {what} of: {listing}")


def _matches_code(d: DeviceDescription, s: str) -> bool:
    from drivers.profiles.description import parse_number

    parts = s.split(":")
    try:
        codes = [parse_number(p) for p in parts]
    except ValueError:
        return False
    if not codes or codes[0] is None or len(codes) > 2:
        return False
    if codes[0] != d.product_code:
        return False
    return len(codes) == 1 or codes[1] == d.revision


#: sub-command -> (configure, run, one-line help)
ACTIONS: dict[
    str,
    tuple[Callable[[argparse.ArgumentParser], None], Callable[[argparse.Namespace], int], str],
] = {
    "import": (
        _configure_import,
        _run_import,
        "build a drive profile from a vendor ESI (EtherCAT) or EDS (CANopen) file",
    ),
    "check": (
        lambda p: _check_module().configure(p),
        lambda a: _check_module().run(a),
        "commissioning check: bring drives of a profile to OP, enable, move, read back",
    ),
}


def _check_module():  # type: ignore[no-untyped-def]
    """``drive check`` lives in its own module (hofto_hw/commands/drive_check.py)."""
    from hofto_hw.commands import drive_check

    return drive_check


def configure(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    for name, (conf, _, help_text) in ACTIONS.items():
        conf(sub.add_parser(name, help=help_text, description=help_text,
                            formatter_class=HelpFormatter))  # fmt: skip


def run(args: argparse.Namespace) -> int:
    return ACTIONS[args.action][1](args)
