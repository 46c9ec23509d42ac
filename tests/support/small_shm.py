"""A small tmpfs over /dev/shm in a private mount namespace (root: CI runs these tests;
elsewhere they skip and say why): a full /dev/shm without filling the real one."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from support.cli import read_only_reason

ROOT = Path(__file__).resolve().parents[2]


def need_root() -> None:
    """Skip (fail under CI) where a private /dev/shm cannot be mounted."""
    reason = read_only_reason()  # the same needs: root and unshare(1)
    if reason is not None:
        reason = reason.replace("a read-only mount", "a private /dev/shm")
        if os.environ.get("CI"):
            pytest.fail(reason)
        pytest.skip(reason)


def in_small_shm(code: str, size: str = "256k", timeout: float = 300.0, cwd: Path = ROOT):
    """Run ``python -c CODE`` with a ``size`` tmpfs over /dev/shm (private mount namespace)."""
    script = f'mount -t tmpfs -o size={size} tmpfs /dev/shm && exec "$@"'
    cmd = ["unshare", "--mount", "--propagation", "private", "sh", "-c", script, "sh"]
    env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    return subprocess.run(
        [*cmd, sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=cwd,
        env=env,
    )
