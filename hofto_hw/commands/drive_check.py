"""``hofto-hw drive check PROFILE (--emulated | --iface IF | --interface I --channel C)``:
a commissioning check of one drive profile with the real master.

Brings N drives to OP / operational with the stack's own EtherCAT or CANopen master (the
drive configured as the profile says, its layout read back), enables them bumplessly in the
profile's loop mode, moves each joint by a small CSP step and back (``--emulated``: 0.05 rad
by default; on a real bus only when ``--move RAD`` is given), reads everything back and
prints what it saw (``--json``: ``bus``, ``axes``, ``operational``, ``enabled``,
``moved_rad``, ``devices`` (slave/node and its axis per joint), ``process_image_bytes`` (of
the joint's device), ``pdos``, ``startup_sdos``, ``settings`` (the setting objects the drive
lacks, which configure leaves out), ``warnings``, ``faults``, ...). A multi-axis
profile (``axes: k``) serves k joints per device: N joints run on ceil(N / k) devices.

``--emulated`` runs the emulator itself: EtherCAT on a veth pair with ``hofto-hw
sim-ethercat`` in its own process (root), CANopen on python-can's virtual bus in a thread
(``--can-interface udp_multicast``: over UDP multicast instead, on a group and port of this
run's own, no root needed).
The emulated arm is the six-joint arm of the base config (``--config``; default
configs/er3a.yaml for EtherCAT, configs/er3a_canopen.yaml for CANopen): the first N joints
get drives of PROFILE, the others the built-in emulated drive. The base config also gives
the scaling (counts per revolution, gear ratio, rated torque) of the real drives.

On a real bus (``--iface`` / ``--interface``) the check reads only the base config's
``bus:`` and ``loop:`` sections, its first N drives (and the names of their joints, from
``robot.joints`` when it has them): checking 1..N drives on a bench needs no arm model, and
a ``--config`` of a bench may hold nothing but those two sections.

Part of a longer EtherCAT line (``--iface``): an integrator commissions one drive of an
installed line without unplugging the others. ``--axes N`` checks the first N slaves;
``--slaves 1,3`` the slaves at those line positions (1-based, as the master's messages and
SOEM number them; the drive of position p is ``bus.drives[p - 1]`` of ``--config``, the
config listing the line's drives in line order). The other slaves are brought to PRE-OP
with the line (SOEM reads every slave's PDO assignment by CoE there) and left in PRE-OP:
below SAFE-OP a slave exchanges no process data, so nothing the check writes reaches it and
its drive cannot be enabled from the bus, while its mailbox still answers (emergencies,
diagnosis), as IgH's master leaves slaves it has no configuration for. The report says
which (``line``). A position beyond the line is refused in one line (exit 2).

Exit codes: 0 the check passed, 1 it ran and something failed (listed), 2 bad input.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import secrets
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hofto_hw.errors import UserError

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_EMULATED_MOVE = 0.05  # [rad]


def configure(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "profile", metavar="PROFILE", help="drive profile: a YAML file or a name in configs/drives/"
    )
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--emulated", action="store_true", help="run the emulator itself")
    where.add_argument("--iface", metavar="IF", help="EtherCAT network interface")
    where.add_argument("--interface", metavar="I", help="python-can interface (CANopen)")
    p.add_argument("--channel", metavar="C", help="python-can channel (with --interface)")
    p.add_argument(
        "--axes",
        type=int,
        default=None,
        metavar="N",
        help="drives of this profile to check (default 6); on a longer EtherCAT line "
        "the first N slaves, the others left in PRE-OP",
    )
    p.add_argument(
        "--slaves",
        default=None,
        metavar="P,P",
        help="--iface only: line positions (1-based) of the drives to check on a longer "
        "line; the others stay in PRE-OP (default: the first N)",
    )
    p.add_argument(
        "--move",
        type=float,
        default=None,
        metavar="RAD",
        help=f"CSP step per joint [rad] (emulated default {DEFAULT_EMULATED_MOVE}; "
        "a real bus moves only when given)",
    )
    p.add_argument(
        "--config",
        type=Path,
        default=None,
        metavar="CONFIG",
        help="base config: the arm (emulated), the scaling and the loop rate",
    )
    p.add_argument(
        "--can-interface",
        choices=("virtual", "udp_multicast"),
        default=None,
        help="--emulated CANopen only: python-can interface the emulated bus runs on "
        "(default virtual; udp_multicast: a group and free port of this run)",
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON")


# ------------------------------------------------------------------ input


def _load_profile(spec: str) -> Any:
    from hofto_hw.config.drive_profile import find_profile, load_profile

    return load_profile(find_profile(spec))


def _base_config(args: argparse.Namespace, bus: str) -> Path:
    if args.config is not None:
        if not args.config.is_file():
            raise UserError(f"--config {args.config}: no such file")
        return args.config
    return ROOT / "configs" / ("er3a.yaml" if bus == "ethercat" else "er3a_canopen.yaml")


def _check_args(args: argparse.Namespace, profile: Any) -> int:
    """The number of profile axes N; UserError for what does not fit."""
    if args.interface is not None and not args.channel:
        raise UserError("--interface needs --channel (the python-can channel)")
    if args.channel and args.interface is None:
        raise UserError("--channel goes with --interface (CANopen)")
    if args.iface is not None and profile.bus != "ethercat":
        raise UserError(f"{args.profile}: a {profile.bus} profile; --iface is for EtherCAT")
    if args.interface is not None and profile.bus != "canopen":
        raise UserError(f"{args.profile}: a {profile.bus} profile; --interface is for CANopen")
    if args.can_interface is not None and not (args.emulated and profile.bus == "canopen"):
        raise UserError("--can-interface goes with --emulated and a CANopen profile")
    if args.move is not None and not (np.isfinite(args.move) and 0 < abs(args.move) <= 0.5):
        raise UserError(f"--move {args.move}: a step of at most 0.5 rad, not 0")
    if args.slaves is not None:
        if args.iface is None:
            raise UserError("--slaves goes with --iface (positions on an EtherCAT line)")
        k = profile.axes
        fits = args.axes is None or -(-args.axes // k) == len(_positions(args.slaves))
        if not fits:
            raise UserError(
                f"--axes {args.axes} does not fit --slaves {args.slaves} "
                f"({len(_positions(args.slaves))} slaves of {k} axes)"
            )
        if args.axes is None:
            args.axes = len(_positions(args.slaves)) * k
    n = 6 if args.axes is None else args.axes
    if not 1 <= n <= 6:
        raise UserError(f"--axes {args.axes}: 1 to 6 drives")
    return n


def _positions(text: str) -> list[int]:
    """``--slaves 1,3`` as [1, 3]; UserError for what is not distinct positions from 1."""
    try:
        got = [int(x) for x in text.split(",")]
    except ValueError:
        raise UserError(f"--slaves {text}: line positions from 1, comma-separated") from None
    if not got or min(got) < 1 or len(set(got)) != len(got):
        raise UserError(f"--slaves {text}: distinct line positions from 1, comma-separated")
    return got


def _check_config(
    base: Path,
    profile: Any,
    n: int,
    folder: Path,
    emulated: bool,
    interface: str | None,
    options: dict[str, Any],
    picks: list[int] | None = None,
) -> Path:
    """A config for the check: the base config with the drives ``picks`` (indices into its
    ``bus.drives``; default its first ``n``) running ``profile`` (identity from the
    profile), the bus on ``interface``, ``options`` merged into ``bus.ethercat`` /
    ``bus.canopen``. On a real bus the config keeps only the drives checked."""
    from hofto_hw.config.loader import dump_yaml, read_yaml

    picks = list(range(n)) if picks is None else picks
    data = read_yaml(base, "config")
    bus = data.get("bus") or {}
    drives = bus.get("drives") or []
    if len(drives) < n:
        raise UserError(f"{base}: bus.drives has {len(drives)} drives, --axes asks for {n}")
    if max(picks) >= len(drives):
        raise UserError(
            f"--slaves: {base} has {len(drives)} drives (bus.drives, in line order); "
            f"slave {max(picks) // profile.axes + 1} has none"
        )
    prof_file = folder / f"{profile.name}.yaml"
    prof_file.write_text(dump_yaml(profile.model_dump(mode="json"), sort_keys=False))
    for i, d in enumerate(drives[j] for j in picks):
        d["profile"] = str(prof_file)
        d["identity"] = {
            "vendor_id": profile.identity.vendor_id,
            "product_code": profile.identity.product_code,
        }
        if profile.axes > 1:  # a multi-axis drive serves `axes` joints: fill each device
            d["device"], d["device_axis"] = divmod(i, profile.axes)
    section = bus.get(profile.bus) or {}
    if not emulated:  # the check runs the drives picked: their node ids too
        bus["drives"] = [drives[j] for j in picks]
        if isinstance(section.get("node_ids"), list):
            ids = section["node_ids"]
            section["node_ids"] = [ids[j] for j in picks if j < len(ids)]
    bus["transport"] = profile.bus
    if interface is not None:
        bus["interface"] = interface
    section.update(options)
    bus[profile.bus] = section
    robot = data.get("robot") or {}
    for key in ("urdf", "parameters"):
        if isinstance(robot.get(key), str) and not Path(robot[key]).is_absolute():
            robot[key] = str((base.parent / robot[key]).resolve())
    out = folder / "check.yaml"
    out.write_text(dump_yaml(data, sort_keys=False))
    return out


@dataclass(frozen=True)
class CheckBus:
    """What the check runs on: the ``bus:`` section (a validated BusConfig), the joint name
    of each of its drives and the loop period [s]."""

    bus: Any
    joints: list[str]
    cycle_time: float


def _bus_only(path: Path, n: int, source: Path, picks: list[int] | None = None) -> CheckBus:
    """The check config's ``bus:`` and ``loop:`` sections, validated without the robot
    (a real bus: the check runs n drives, not the arm); ConfigError names the field and
    ``source``, the base config they come from (the check config is a temporary file)."""
    from pydantic import ValidationError

    from hofto_hw.config.base import FileModel
    from hofto_hw.config.drives import BusConfig
    from hofto_hw.config.loader import format_validation_error, read_yaml
    from hofto_hw.config.models import LoopConfig
    from hofto_hw.errors import ConfigError

    class _BusAndLoop(FileModel):
        bus: BusConfig
        loop: LoopConfig

    data = read_yaml(path, "config")
    try:
        got = _BusAndLoop.model_validate({"bus": data.get("bus"), "loop": data.get("loop") or {}})
    except ValidationError as err:
        raise ConfigError(format_validation_error(str(source), err)) from None
    picks = list(range(n)) if picks is None else picks
    joints = (data.get("robot") or {}).get("joints")
    if not isinstance(joints, list) or len(joints) <= max(picks):
        joints = [f"joint_{i + 1}" for i in range(max(picks) + 1)]
    return CheckBus(got.bus, [str(joints[j]) for j in picks], 1.0 / got.loop.rate_hz)


# ---------------------------------------------------------------- emulators


@contextlib.contextmanager
def _emulated_ethercat(config: Path, folder: Path, master: str) -> Iterator[None]:
    """veth pair ``master``/``dcs...`` + ``hofto-hw sim-ethercat`` serving ``config``."""
    from drivers.sim.esc import veth

    if os.geteuid() != 0:
        raise UserError(
            "drive check --emulated (EtherCAT) needs root: a veth pair and raw "
            "sockets (run it with sudo)"
        )
    slave = "dcs" + master[3:]
    veth.create_pair(master, slave)
    proc = None
    try:
        veth.wait_up(master, slave)
        from hofto_hw.commands.sim_ethercat import start_emulator

        proc = start_emulator(slave, config, folder / "ready", timeout=60.0)
        yield
    finally:
        if proc is not None and proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        veth.delete_pair(master)


def _udp_multicast_where() -> tuple[str, dict[str, Any]]:
    """A multicast group and a free UDP port of this run (``--can-interface
    udp_multicast``): python-can binds every such bus to the port on any address, so a port
    of its own keeps another run's frames out."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("", 0))
        port = probe.getsockname()[1]
    pid = os.getpid()
    return f"239.74.{(pid >> 8) & 0xFF}.{pid & 0xFF}", {"port": port}


@contextlib.contextmanager
def _emulated_canopen(cfg: Any, bus_kwargs: dict[str, Any]) -> Iterator[None]:
    """The config's drives as CANopen nodes on its python-can channel (a thread): the
    virtual bus, or udp_multicast with ``bus_kwargs`` (the port)."""
    import can

    from drivers.canopen.socket_buffer import widen_receive_buffer
    from drivers.sim.canopen_node import CanopenDrives
    from hofto_hw.runtime.build import build_emulated_drives

    channel = cfg.bus.interface
    bus = can.Bus(interface=cfg.bus.canopen.can_interface, channel=channel, **bus_kwargs)
    widen_receive_buffer(bus)
    emu = CanopenDrives.for_bus(build_emulated_drives(cfg, external=False), bus, cfg.bus).start()
    try:
        yield
    finally:
        emu.stop()
        bus.shutdown()


# ---------------------------------------------------------------- the check


def _transport(
    cfg: CheckBus, profile: Any, bus_kwargs: dict[str, Any], positions: list[int] | None
) -> Any:
    names = cfg.joints[: len(cfg.bus.drives)]
    if profile.bus == "ethercat":
        from drivers.ethercat.master import EtherCATTransport

        return EtherCATTransport.from_config(
            cfg.bus, names, cycle_time=cfg.cycle_time, positions=positions
        )
    from drivers.canopen.master import CANopenTransport

    t = CANopenTransport.from_config(cfg.bus, names, cycle_time=cfg.cycle_time)
    t.bus_kwargs.update(bus_kwargs)
    return t


def _move(g: Any, t: Any, step: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """Ramp to q0 + step on ``joints`` and back; returns the step reached per joint [rad]."""
    q0 = g.q.copy()
    ramp = max(20, round(0.4 / t.cycle_time))
    target = q0.copy()
    for k in range(1, ramp + 1):
        target[joints] = q0[joints] + step[joints] * (k / ramp)
        g.command_position(target)
        g.cycle()
        t.wait_next_cycle()
    settle = round(2.0 / t.cycle_time)
    reached = g.q - q0
    for _ in range(settle):  # wait for the state: within 5 % of the step, or time out
        g.command_position(target)
        g.cycle()
        t.wait_next_cycle()
        reached = g.q - q0
        if np.all(np.abs(reached[joints] - step[joints]) <= 0.05 * np.abs(step[joints])):
            break
    for k in range(ramp - 1, -1, -1):
        target[joints] = q0[joints] + step[joints] * (k / ramp)
        g.command_position(target)
        g.cycle()
        t.wait_next_cycle()
    return reached


def check(
    cfg: CheckBus,
    profile: Any,
    n: int,
    move: float | None,
    emulated: bool,
    bus_kwargs: dict[str, Any] | None = None,
    positions: list[int] | None = None,
) -> dict[str, Any]:
    """Run the check on the bus ``cfg`` describes (EtherCAT ``positions``: the line
    positions of its devices, the other slaves left in PRE-OP); returns the report (see
    module). A position beyond the line is a UserError."""
    from drivers.cia402.drive_group import DriveGroup
    from drivers.cia402.state_machine import Mode, State
    from drivers.errors import DriverError
    from hofto_hw.config.drive_profile import MODE_NUMBERS
    from hofto_hw.errors import ConfigError

    report: dict[str, Any] = {
        "profile": profile.name,
        "bus": profile.bus,
        "loop": profile.modes.loop,
        "emulated": emulated,
        "axes": n,
        "operational": False,
        "enabled": False,
        "moved_rad": [0.0] * n,
        "devices": [],
        "process_image_bytes": [],
        "pdos": [],
        "startup_sdos": 0,
        "unavailable": [],
        "settings": [],
        "warnings": [],
        "faults": [],
    }
    from drivers.ethercat.errors import SlavePositionError

    t = _transport(cfg, profile, bus_kwargs or {}, positions)
    joints = np.arange(n)
    try:
        t.open()
        report["operational"] = True
        w = t.wire
        dev = [w.serve[i][0] for i in range(n)]  # the slave/node of each axis
        report["devices"] = [{"device": w.serve[i][0], "axis": w.serve[i][1]} for i in range(n)]
        if profile.bus == "ethercat":  # where on the line each joint's slave sits
            at = [t.positions[d] if t.positions is not None else d + 1 for d in dev]
            report["line"] = {
                "slaves": t.line_slaves,
                "checked": sorted(set(at)),
                "positions": at,
                "left_in_preop": t.left_alone,
            }
        report["process_image_bytes"] = [
            {"rx": w.rx_size(dev[i]), "tx": w.tx_size(dev[i])} for i in range(n)
        ]
        report["pdos"] = [
            {
                "rx": [f"0x{x:04X}" for x in w.layouts[dev[i]].rx_pdos],
                "tx": [f"0x{x:04X}" for x in w.layouts[dev[i]].tx_pdos],
            }
            for i in range(n)
        ]
        report["startup_sdos"] = t.startup_written
        report["warnings"] = list(getattr(t, "warnings", []))
        g = DriveGroup.from_config(t, cfg.bus)
        report["unavailable"] = [u for u in g.unavailable() if int(u.split()[1]) < n]
        g.configure(cfg.bus.drives)  # as `run` does: identity, ratings, limits by SDO
        report["settings"] = [u for u in g.settings_notes if int(u.split()[1]) < n]
        g.cycle()
        if g.any_fault():
            g.fault_reset()
        loop = profile.modes.loop
        g.set_mode(Mode.CSP if loop in ("ip", "pv") else Mode(MODE_NUMBERS[loop]))
        g.enable()
        report["enabled"] = bool(g.all_in(State.OPERATION_ENABLED))
        # ip and pv drives take the CSP step too: the driver layer turns it into the target
        # 0x60C1:01 (ip) or the streamed velocity (pv; drivers/cia402/csp_adapter.py)
        if move is not None and profile.modes.loop in ("csp", "ip", "pv"):
            step = np.zeros(t.n_axes)
            step[joints] = move
            reached = _move(g, t, step, joints)
            report["moved_rad"] = [round(float(x), 5) for x in reached[joints]]
        elif move is not None:
            report["faults"].append(
                f"no move: the profile's loop mode is {profile.modes.loop}, the step is CSP"
            )
        report["faults"] += g.fault_messages()
        g.disable()
    except SlavePositionError as exc:  # bad input: a position the line does not have
        raise UserError(str(exc)) from None
    except (DriverError, ConfigError) as exc:  # ConfigError: identity/ratings differ
        report["faults"].append(str(exc))
    finally:
        t.close()
    return report


def passed(report: dict[str, Any], move: float | None) -> bool:
    """Operational, enabled, every joint within 10 % of the step (when moved), no fault."""
    ok = report["operational"] and report["enabled"] and not report["faults"]
    if move is not None:
        ok = ok and all(abs(m - move) <= 0.1 * abs(move) for m in report["moved_rad"])
    return bool(ok)


def run(args: argparse.Namespace) -> int:
    from hofto_hw.config.drive_profile import check_profile_against_loop
    from hofto_hw.config.loader import load_config

    profile = _load_profile(args.profile)
    n = _check_args(args, profile)
    units_note = None
    if args.emulated:  # a real bus refuses unknown units (its master does, one line)
        from drivers.cia402.profiles import with_counts_units

        profile, units_note = with_counts_units(profile)
        if units_note is not None:
            print(f"note: {units_note}", file=sys.stderr)
    move = args.move
    if move is None and args.emulated:
        move = DEFAULT_EMULATED_MOVE
    base = _base_config(args, profile.bus)
    positions = picks = None
    if args.iface is not None:  # the devices checked on the line, and their config drives
        k = profile.axes
        positions = (
            _positions(args.slaves) if args.slaves is not None else list(range(1, -(-n // k) + 1))
        )
        picks = [(p - 1) * k + j for p in positions for j in range(k)][:n]
    # the check pauses between its steps (SDOs while cycling); a loop never does: generous
    # watchdogs and deadlines on the emulated bus, a shared machine's frame timeout
    if profile.bus == "ethercat":
        options: dict[str, Any] = (
            {"pdo_watchdog": 2.0, "receive_timeout": 0.02} if args.emulated else {}
        )
        iface = args.iface
    else:
        options = {"tpdo_deadline": 0.05, "sdo_timeout": 2.0} if args.emulated else {}
        bus_kwargs: dict[str, Any] = {}
        if args.emulated:
            options["can_interface"] = args.can_interface or "virtual"
            iface = f"hofto-drive-check-{os.getpid()}"
            if options["can_interface"] == "udp_multicast":
                iface, bus_kwargs = _udp_multicast_where()
        else:
            options["can_interface"] = args.interface
            iface = args.channel
    with tempfile.TemporaryDirectory(prefix="hofto-drive-check-") as tmp:
        folder = Path(tmp)
        if args.emulated and profile.bus == "ethercat":
            # random: the machine's network namespace is shared with other sessions, whose
            # pids (from another pid namespace) can equal ours
            iface = f"dcm{secrets.token_hex(4)}"
        path = _check_config(base, profile, n, folder, args.emulated, iface, options, picks)
        if args.emulated:  # the emulator runs the whole arm of the base config
            cfg = load_config(path)
            on = CheckBus(cfg.bus, list(cfg.robot.joints), cfg.cycle_time)
        else:
            on = _bus_only(path, n, base, picks)
        check_profile_against_loop(profile, on.cycle_time, f"{base}: loop.rate_hz")
        if args.emulated and profile.bus == "ethercat":
            with _emulated_ethercat(path, folder, iface):
                report = check(on, profile, n, move, True)
        elif args.emulated:
            with _emulated_canopen(cfg, bus_kwargs):
                report = check(on, profile, n, move, True, bus_kwargs)
            report["can_interface"] = cfg.bus.canopen.can_interface
        else:
            report = check(on, profile, n, move, False, positions=positions)
    if units_note is not None:
        report["warnings"].append(units_note)
    ok = passed(report, move)
    report["passed"] = ok
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        _print(report)
    return 0 if ok else 1


def _print(r: dict[str, Any]) -> None:
    where = "emulated" if r["emulated"] else "live"
    print(
        f"drive check: profile {r['profile']}, {r['bus']} ({where}), {r['axes']} axes, "
        f"loop {r['loop']}"
    )
    line = r.get("line")
    if line is not None:
        alone = ", ".join(str(p) for p in line["left_in_preop"]) or "none"
        checked = ", ".join(str(p) for p in line["checked"])
        print(f"  line: {line['slaves']} slaves, checked {checked}, left in PRE-OP: {alone}")
    print(f"  operational: {'yes' if r['operational'] else 'NO'}")
    print(f"  enabled:     {'yes' if r['enabled'] else 'NO'}")
    print(f"  start-up SDOs written: {r['startup_sdos']}")
    for i, (b, p) in enumerate(zip(r["process_image_bytes"], r["pdos"], strict=False)):
        print(f"  axis {i}: rx {b['rx']} B {' '.join(p['rx'])}, tx {b['tx']} B {' '.join(p['tx'])}")
    print("  moved [rad]: " + " ".join(f"{m:+.4f}" for m in r["moved_rad"]))
    for u in r["unavailable"]:
        print(f"  note: {u}")
    for u in r["settings"]:
        print(f"  note: {u}")
    for f in r["faults"]:
        print(f"  FAULT: {f}")
    print("  passed" if r["passed"] else "  FAILED")
