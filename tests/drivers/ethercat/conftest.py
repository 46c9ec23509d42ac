"""Emulated EtherCAT network on a veth pair, served by `hofto-hw sim-ethercat` in a child
process, for the master tests. Needs root: skipped when unprivileged, a failure under CI."""

from __future__ import annotations

import itertools
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
CONFIG = ROOT / "configs" / "er3a.yaml"
_counter = itertools.count()


def require_root() -> None:
    """Skip (or fail under CI) when veth pairs and raw sockets are not available."""
    if os.geteuid() == 0:
        return
    if os.environ.get("CI"):
        pytest.fail("CI is set but the tests do not run as root: veth pairs need root")
    pytest.skip("needs root for veth pairs and raw sockets (set CI to make this a failure)")


@dataclass
class EmulatedBus:
    """A running emulator: the master's interface, the control socket, the config."""

    master_iface: str
    slave_iface: str
    control: str
    proc: subprocess.Popen
    cfg: object

    def call(self, **request: object) -> dict:
        from drivers.sim.esc.network import ControlClient

        return ControlClient(self.control).call(**request)


@pytest.fixture()
def emulated_bus(tmp_path: Path) -> Iterator[EmulatedBus]:
    require_root()
    from drivers.sim.esc import veth
    from hofto_hw.config.loader import load_config

    k = next(_counter)
    tag = f"{os.getpid() % 100000}{k}"
    master, slave = f"hm{tag}"[:15], f"hs{tag}"[:15]
    control = str(tmp_path / "ctl.sock")
    ready = tmp_path / "ready"
    veth.create_pair(master, slave)
    cmd = [
        sys.executable,
        "-m",
        "hofto_hw.cli",
        "sim-ethercat",
        "--iface",
        slave,
        "--config",
        str(CONFIG),
        "--control",
        control,
        "--quiet-arm",
        "--ready-file",
        str(ready),
    ]
    log = open(tmp_path / "emulator.log", "w")
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 30
        while not ready.exists():
            if proc.poll() is not None:
                raise RuntimeError(
                    f"emulator exited with {proc.returncode}: "
                    + (tmp_path / "emulator.log").read_text()
                )
            if time.monotonic() > deadline:
                raise RuntimeError("emulator did not start within 30 s")
            time.sleep(0.02)
        yield EmulatedBus(master, slave, control, proc, load_config(CONFIG))
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        log.close()
        veth.delete_pair(master)
