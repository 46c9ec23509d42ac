"""The shipped systemd unit verifies cleanly and keeps its hardening."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

UNIT = Path(__file__).resolve().parents[3] / "configs" / "systemd" / "hofto-hw.service"


def test_unit_verifies_with_nothing_on_stderr() -> None:
    if not shutil.which("systemd-analyze"):
        if os.environ.get("CI"):
            pytest.fail("CI installs systemd (.ci/run); systemd-analyze is missing")
        pytest.skip("systemd-analyze not installed (apt-get install systemd)")
    r = subprocess.run(
        ["systemd-analyze", "verify", str(UNIT)], capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 0 and r.stderr == "", r.stderr


def test_unit_keeps_the_service_contract() -> None:
    text = UNIT.read_text()
    for line in (
        "Type=notify",
        "AmbientCapabilities=CAP_NET_RAW CAP_SYS_NICE CAP_IPC_LOCK",
        "NoNewPrivileges=yes",
        "ProtectSystem=strict",
        "ProtectHome=yes",
        "PrivateTmp=yes",
        "LimitMEMLOCK=infinity",
        "RestrictAddressFamilies=AF_UNIX AF_PACKET AF_INET",
        "User=hofto-hw",
    ):
        assert line in text.splitlines(), line
    assert any(x.startswith("WatchdogSec=") for x in text.splitlines())
    assert any(x.startswith("ReadWritePaths=") for x in text.splitlines())
