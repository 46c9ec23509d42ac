"""``hofto-hw sim-ethercat``: serve emulated EtherCAT CiA-402 drives on a network interface.

Example (root): ``hofto-hw sim-ethercat --iface ecs0 --config configs/er3a.yaml
--create-veth`` makes the veth pair ecm0/ecs0, serves the six drives of the config on ecs0
and leaves ecm0 to the master (``bus.interface: ecm0``). Fault injection and status go
through the Unix socket given with ``--control`` (one JSON object per line, see
:meth:`drivers.sim.esc.network.EmulatedNetwork.control`); the socket is created with mode
0600, and only a stale socket at that path is replaced (anything else is refused).
"""

from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import FrameType

from hofto_hw.commands.args import add_config, run_seconds


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the command's arguments."""
    parser.add_argument("--iface", default="ecs0", help="interface to serve on (default ecs0)")
    add_config(parser, default="er3a")
    parser.add_argument(
        "--create-veth",
        action="store_true",
        help="create the veth pair MASTER/IFACE first and delete it on exit (root)",
    )
    parser.add_argument(
        "--master-iface",
        default=None,
        help="master end of the veth pair (default: IFACE with 's' -> 'm', e.g. ecm0)",
    )
    parser.add_argument("--control", default=None, help="Unix socket path for control/faults")
    parser.add_argument(
        "--duration", type=run_seconds, default=None, help="stop after N seconds (default: run)"
    )
    parser.add_argument(
        "--quiet-arm", action="store_true", help="leave out the config's scripted external torques"
    )
    parser.add_argument("--ready-file", default=None, help="file created once serving")
    parser.add_argument(
        "--drives",
        type=int,
        default=None,
        metavar="K",
        help="serve only the first K drives of the config (a bench of K drives, e.g. for "
        "`drive check --iface IF --axes K`); the arm's other joints have no drive",
    )


def _master_name(iface: str) -> str:
    if "s" in iface:
        i = iface.rindex("s")
        return iface[:i] + "m" + iface[i + 1 :]
    return iface + "m"


def run(args: argparse.Namespace) -> int:
    """Build the network from the config and serve until SIGTERM/SIGINT or ``--duration``."""
    from drivers.sim.control_socket import check_control_path
    from drivers.sim.esc import veth
    from drivers.sim.esc.network import serve
    from hofto_hw.config.loader import load_config
    from hofto_hw.config.locate import find_config
    from hofto_hw.errors import UserError
    from hofto_hw.runtime.build import build_emulated_network

    if args.control:
        check_control_path(args.control)
    master = args.master_iface or _master_name(args.iface)
    if not args.create_veth and not veth.exists(args.iface):
        raise UserError(f"network interface {args.iface!r} does not exist (see `ip link`)")
    cfg = load_config(find_config(args.config))
    n = len(cfg.bus.drives) if cfg.bus is not None else 0
    if args.drives is not None and not 1 <= args.drives <= n:
        raise UserError(f"--drives {args.drives}: the config has {n} drives (1 to {n})")
    net = build_emulated_network(cfg, external=not args.quiet_arm, load=True, first=args.drives)
    if args.create_veth:
        veth.create_pair(master, args.iface)

    def _stop(_signum: int, _frame: FrameType | None) -> None:
        net.stopping = True

    signal.signal(signal.SIGTERM, _stop)
    signal.signal(signal.SIGINT, _stop)
    print(
        f"serving {net.n} emulated EtherCAT drives on {args.iface}"
        + (f" (master side: {master})" if args.create_veth else ""),
        flush=True,
    )
    try:
        serve(net, args.iface, args.control, args.duration, args.ready_file)
    finally:
        if args.create_veth:
            veth.delete_pair(master)
    return 0


def start_emulator(iface: str, config: Path, ready: Path, timeout: float = 60.0):
    """``hofto-hw sim-ethercat`` on ``iface`` for ``config`` in its own process (quiet arm),
    returned (a ``subprocess.Popen``) once it has written the file ``ready``.

    Raises:
        UserError: it exited first (naming its last line on stderr) or did not get ready
            within ``timeout`` seconds (then it is killed).
    """
    from hofto_hw.errors import UserError

    proc = subprocess.Popen(
        [sys.executable, "-m", "hofto_hw.cli", "sim-ethercat", "--iface", iface,
         "--config", str(config), "--quiet-arm", "--ready-file", str(ready)],
        cwd=Path(__file__).resolve().parents[2],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )  # fmt: skip
    deadline = time.monotonic() + timeout
    while not ready.exists():
        if proc.poll() is not None:
            err = (proc.stderr.read() if proc.stderr else "").strip().splitlines()
            raise UserError(f"emulator did not start: {err[-1] if err else 'no message'}")
        if time.monotonic() > deadline:
            proc.kill()
            proc.wait()
            raise UserError(f"emulator did not start within {timeout:g} s")
        time.sleep(0.02)
    return proc
