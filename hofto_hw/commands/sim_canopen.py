"""``hofto-hw sim-canopen``: serve emulated CANopen CiA-402 drives on a python-can bus.

Example: ``hofto-hw sim-canopen --interface udp_multicast --channel 239.74.163.2
--config configs/er3a_canopen.yaml --control /tmp/can.sock``. One node per drive of the
config, one per device with multi-axis drives (node ids from ``bus.canopen.node_ids``,
default 1..n); one plant tick of
``1 / loop.rate_hz`` per SYNC. Fault injection and status through the Unix socket given
with ``--control`` (one JSON object per line, see
:meth:`drivers.sim.canopen_node.CanopenDrives.control`).
"""

from __future__ import annotations

import argparse
import gc
import signal
import threading
from pathlib import Path
from types import FrameType
from typing import Any

from hofto_hw.commands.args import add_config, run_seconds


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the command's arguments."""
    parser.add_argument(
        "--interface",
        default="udp_multicast",
        choices=("udp_multicast", "virtual", "socketcan"),
        help="python-can interface (default udp_multicast)",
    )
    parser.add_argument(
        "--channel", default=None, help="channel (default: bus.interface of the config)"
    )
    add_config(parser, default="er3a_canopen")
    parser.add_argument("--control", default=None, help="Unix socket path for control/faults")
    parser.add_argument("--duration", type=run_seconds, default=None, help="stop after N seconds")
    parser.add_argument(
        "--quiet-arm", action="store_true", help="leave out the config's scripted external torques"
    )
    parser.add_argument("--ready-file", default=None, help="file created once serving")


def node_ids(cfg: Any) -> list[int]:
    """Node ids of the config's devices (``bus.canopen.node_ids`` or 1..n; one per
    multi-axis node)."""
    from hofto_hw.config.drives import device_map

    opts = cfg.bus.canopen
    if opts is not None and opts.node_ids is not None:
        return list(opts.node_ids)
    return list(range(1, len({d for d, _k in device_map(cfg.bus.drives)}) + 1))


def _collecting(handler: Any) -> Any:
    """``handler`` followed by a garbage collection: the frame path runs with the cyclic
    collector off (drivers.sim.pacing.answer_first), so collect between control requests."""

    def handle(request: dict[str, Any]) -> dict[str, Any]:
        try:
            return handler(request)
        finally:
            gc.collect()

    return handle


def run(args: argparse.Namespace) -> int:
    """Serve until SIGTERM/SIGINT, a ``stop`` request or ``--duration``."""
    import can

    from drivers.canopen.socket_buffer import widen_receive_buffer
    from drivers.sim.canopen_node import CanopenDrives
    from drivers.sim.control_socket import serve_control
    from drivers.sim.pacing import answer_first, control_beside_frames
    from hofto_hw.config.loader import load_config
    from hofto_hw.config.locate import find_config
    from hofto_hw.errors import UserError
    from hofto_hw.runtime.build import build_emulated_drives

    cfg = load_config(find_config(args.config))
    channel = args.channel or (cfg.bus.interface if cfg.bus is not None else None)
    if not channel:
        raise UserError(f"--channel: not given and {args.config} has no bus.interface")
    drives = build_emulated_drives(cfg, external=not args.quiet_arm, load=True)
    try:
        bus = can.Bus(interface=args.interface, channel=channel)
    except (can.CanError, OSError, ValueError) as exc:
        raise UserError(f"cannot open CAN channel {channel!r} ({args.interface}): {exc}") from None
    widen_receive_buffer(bus)  # udp_multicast: a SYNC lost to a full socket is an unanswered one
    net = CanopenDrives.for_bus(drives, bus, cfg.bus)
    stop_control = threading.Event()
    ctl = None
    if args.control:
        try:
            ctl = serve_control(
                args.control, _collecting(net.control), stop_control, control_beside_frames
            )
        except BaseException:
            bus.shutdown()
            raise

    def _stop(_signum: int, _frame: FrameType | None) -> None:
        net.stopping = True

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _stop)
        signal.signal(signal.SIGINT, _stop)
    print(
        f"serving {drives.n} emulated CANopen drives (nodes {net.node_ids}) on "
        f"{args.interface}:{channel}",
        flush=True,
    )
    answer_first()  # frames before other work, as the EtherCAT emulator
    if args.ready_file:
        Path(args.ready_file).write_text("ready\n")
    try:
        net.run(args.duration)
    finally:
        stop_control.set()
        if ctl is not None:
            ctl.join(2.0)
        bus.shutdown()
    return 0
