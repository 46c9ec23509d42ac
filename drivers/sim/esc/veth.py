"""Create and delete veth pairs for the emulated EtherCAT network (root or CAP_NET_ADMIN)."""

from __future__ import annotations

import os
import subprocess
import time

from hofto_hw.errors import UserError


def exists(name: str) -> bool:
    """Whether network interface ``name`` exists."""
    return os.path.exists(f"/sys/class/net/{name}")


def _ip(*args: str) -> None:
    try:
        res = subprocess.run(["ip", *args], capture_output=True, text=True, check=False)
    except FileNotFoundError:
        raise UserError("the `ip` command (iproute2) is needed to create veth pairs") from None
    if res.returncode != 0:
        msg = res.stderr.strip() or res.stdout.strip()
        if "Operation not permitted" in msg:
            raise UserError(
                f"cannot run `ip {' '.join(args)}`: needs root or CAP_NET_ADMIN ({msg})"
            )
        raise UserError(f"`ip {' '.join(args)}` failed: {msg}")


def create_pair(master: str, slave: str) -> None:
    """Create veth pair ``master``/``slave`` (both up, no IPv6 chatter); replaces an old one."""
    if os.geteuid() != 0:
        raise UserError(
            f"creating veth pair {master}/{slave} needs root (or CAP_NET_ADMIN); "
            "run as root or create it beforehand"
        )
    if exists(master):
        _ip("link", "del", master)
    _ip("link", "add", master, "type", "veth", "peer", "name", slave)
    for name in (master, slave):
        try:
            with open(f"/proc/sys/net/ipv6/conf/{name}/disable_ipv6", "w") as f:
                f.write("1")
        except OSError:
            pass  # IPv6 disabled system-wide or not permitted: only costs stray frames
        _ip("link", "set", name, "up")
    wait_up(master, slave)


def wait_up(*names: str, timeout: float = 10.0) -> None:
    """Wait until every interface reports carrier and operstate up.

    The kernel activates a new link's queueing discipline asynchronously (link watch); a
    frame sent before that is dropped, and SOEM would report no slave. Waits for the state,
    not for a time; raises UserError naming the interface after ``timeout`` [s].
    """
    deadline = time.monotonic() + timeout
    for name in names:
        while _read(name, "operstate") != "up" or _read(name, "carrier") != "1":
            if time.monotonic() > deadline:
                raise UserError(
                    f"network interface {name!r} is not up {timeout:g} s after `ip link set up` "
                    f"(operstate {_read(name, 'operstate') or 'unknown'})"
                )
            time.sleep(0.01)


def _read(name: str, attr: str) -> str:
    try:
        with open(f"/sys/class/net/{name}/{attr}") as f:
            return f.read().strip()
    except OSError:
        return ""


def delete_pair(master: str) -> None:
    """Delete the veth pair that ``master`` belongs to (no error when it is gone)."""
    if exists(master):
        _ip("link", "del", master)
