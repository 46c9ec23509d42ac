"""Master and emulated drives in two processes over udp_multicast, inside a private network
namespace with loopback only. Needs root: skipped when unprivileged, a failure under CI."""

from __future__ import annotations

import itertools
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from support.canopen import CONFIG, ROOT

_counter = itertools.count()
CHANNEL = "239.74.163.2"


def _require_root() -> None:
    if os.geteuid() == 0:
        return
    if os.environ.get("CI"):
        pytest.fail("CI is set but the tests do not run as root: network namespaces need root")
    pytest.skip("needs root for a private network namespace (set CI to make this a failure)")


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True)


@pytest.fixture()
def netns():
    _require_root()
    name = f"hcan{os.getpid() % 100000}x{next(_counter)}"
    _ip("netns", "add", name)
    try:
        _ip("netns", "exec", name, "ip", "link", "set", "lo", "up")
        _ip("netns", "exec", name, "ip", "route", "add", "224.0.0.0/4", "dev", "lo")
        yield name
    finally:
        subprocess.run(["ip", "netns", "del", name], capture_output=True)


def test_full_loop_across_two_processes_udp_multicast(netns, tmp_path) -> None:
    from drivers.sim.esc.network import ControlClient

    control, ready = str(tmp_path / "ctl.sock"), tmp_path / "ready"
    env = dict(os.environ, PYTHONPATH=f"{ROOT}:{ROOT / 'tests'}")
    inns = ["ip", "netns", "exec", netns, sys.executable]
    log = open(tmp_path / "emulator.log", "w")
    emu = subprocess.Popen(
        [
            *inns,
            "-m",
            "hofto_hw.cli",
            "sim-canopen",
            "--interface",
            "udp_multicast",
            "--channel",
            CHANNEL,
            "--config",
            str(CONFIG),
            "--control",
            control,
            "--quiet-arm",
            "--ready-file",
            str(ready),
        ],
        cwd=ROOT,
        env=env,
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    try:
        end = time.monotonic() + 30
        while not ready.exists():
            assert emu.poll() is None, (tmp_path / "emulator.log").read_text()
            assert time.monotonic() < end, "emulator did not start within 30 s"
            time.sleep(0.02)
        master = subprocess.run(
            [*inns, "-m", "support.canopen_remote", str(CONFIG), "udp_multicast", CHANNEL],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert master.returncode == 0, master.stderr[-3000:]
        out = json.loads(master.stdout.strip().splitlines()[-1])
        assert out["states"] == [4] * 6  # Operation enabled
        np.testing.assert_allclose(out["q"], out["q_target"], atol=5e-3)
        status = ControlClient(control).call(op="status")
        np.testing.assert_allclose(status["q"], out["q_target"], atol=5e-3)
        np.testing.assert_allclose(status["tau_applied"], out["tau_cmd"], atol=0.05)
    finally:
        emu.send_signal(signal.SIGTERM)
        try:
            emu.wait(timeout=5)
        except subprocess.TimeoutExpired:
            emu.kill()
            emu.wait()
        log.close()
