"""Master and emulated drives in two processes over udp_multicast, inside a private network
namespace with loopback only. Needs root: skipped when unprivileged, a failure under CI
(the plumbing is tests/support/rootnet.py, shared with the other root tests)."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest
from support.canopen import CONFIG, ROOT
from support.rootnet import child_env, emulator, private_netns, python_argv, sim_canopen_args

CHANNEL = "239.74.163.2"


@pytest.fixture()
def netns():
    with private_netns("hcan") as name:
        yield name


def test_full_loop_across_two_processes_udp_multicast(netns, tmp_path) -> None:
    args = sim_canopen_args("udp_multicast", CHANNEL, CONFIG)
    with emulator(args, tmp_path, netns=netns, timeout=30.0) as emu:
        master = subprocess.run(
            [*python_argv(netns), "-m", "support.canopen_remote", str(CONFIG)]
            + ["udp_multicast", CHANNEL],
            cwd=ROOT,
            env=child_env(),
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert master.returncode == 0, master.stderr[-3000:]
        out = json.loads(master.stdout.strip().splitlines()[-1])
        assert out["states"] == [4] * 6  # Operation enabled
        np.testing.assert_allclose(out["q"], out["q_target"], atol=5e-3)
        status = emu.call(op="status")
        np.testing.assert_allclose(status["q"], out["q_target"], atol=5e-3)
        np.testing.assert_allclose(status["tau_applied"], out["tau_cmd"], atol=0.05)
