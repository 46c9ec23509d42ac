"""Shared memory of the flight recorder: a full /dev/shm is one line at creation (never a
SIGBUS), and the segment a killed run leaves behind is found and removed by the next run.

Before: ``hofto-hw run`` with a full /dev/shm died of SIGBUS (exit 135, no message) when it
first touched the ring; killing the main process together with its writer left a 1.7 MB
segment that nothing removed. The full-/dev/shm cases run in a private mount namespace with
a small tmpfs over /dev/shm (root: CI runs them; elsewhere they skip and say why); the real
/dev/shm is never filled.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from support.cli import one_line_error
from support.small_shm import in_small_shm as _in_small_shm
from support.small_shm import need_root as _need_root

from hofto_hw.recording import shared as sh
from hofto_hw.recording.flight_file import LogSpec
from hofto_hw.recording.recorder import FlightRecorder

SHM = Path("/dev/shm")


def test_run_with_a_full_dev_shm_is_one_line_not_a_bus_error(tmp_path: Path) -> None:
    _need_root()
    argv = ["run", "--clock", "sim", "--duration", "0.2", "--log-dir", str(tmp_path)]
    p = _in_small_shm(f"import sys; from hofto_hw.cli import main; sys.exit(main({argv!r}))")
    assert p.returncode != -7 and p.returncode != 135, "died of SIGBUS"
    line = one_line_error(p.returncode, p.stderr, "/dev/shm:", "MB free", "shared memory needs")
    assert "bytes)" in line and p.stdout == ""
    assert list(tmp_path.iterdir()) == []  # no log was started


def test_reserving_the_segment_fails_at_creation_not_on_first_touch() -> None:
    # statvfs made to say there is room: posix_fallocate must still refuse (ENOSPC) before
    # any page is touched (the old creation touched every page: SIGBUS)
    _need_root()
    code = (
        "import os, sys\n"
        "from hofto_hw.errors import UserError\n"
        "from hofto_hw.recording import shared as sh\n"
        "from hofto_hw.recording.record import tick_dtype\n"
        "real = os.statvfs\n"
        "class Roomy:\n"
        "    f_bavail, f_frsize = 1 << 40, 1\n"
        "os.statvfs = lambda p: Roomy()\n"
        "try:\n"
        "    sh.SharedBlock(tick_dtype(6, 2), sh.Capacities(), create=True)\n"
        "except UserError as e:\n"
        "    print(e, file=sys.stderr); sys.exit(2)\n"
        "print('created')\n"
    )
    p = _in_small_shm(code)
    assert p.returncode == 2, (p.returncode, p.stderr[-500:])
    one_line_error(p.returncode, p.stderr, "/dev/shm: cannot reserve", "No space left on device")


def test_the_segment_a_killed_run_left_is_removed_by_the_next(child_factory, tmp_path) -> None:
    child = child_factory(tmp_path / "killed.mcap", 0)
    name = child.expect("ready").split()[2].lstrip("/")
    assert name.startswith(f"hofto-hw-{child.proc.pid}-")  # the owner's pid in the name
    child.kill_group()  # the loop and its writer (and a resource tracker) killed together
    assert (SHM / name).exists()  # left behind
    rec = FlightRecorder(LogSpec(tmp_path / "next.mcap", ["j1", "j2"], ["hofto"])).start()
    try:
        assert not (SHM / name).exists()
        assert [r[0] for r in rec.removed_stale if r[0] == name] == [name]
        assert rec.health().writer_alive
    finally:
        rec.close()


def test_a_live_owners_segment_is_kept_and_a_reused_pid_is_not_an_owner() -> None:
    # pid 1 is alive and started at boot: its segment made now is kept; one "made" in 1970,
    # before pid 1 started, belongs to an earlier process of that pid and is stale
    token = os.urandom(4).hex()
    live = SHM / f"hofto-hw-1-{token}a"
    old = SHM / f"hofto-hw-1-{token}b"
    for p in (live, old):
        p.write_bytes(b"\0" * 4096)
    os.utime(old, (0.0, 0.0))
    time.sleep(0.01)
    try:
        removed = [r[0] for r in sh.remove_stale()]
        assert old.name in removed and not old.exists()
        assert live.name not in removed and live.exists()
    finally:
        live.unlink(missing_ok=True)
        old.unlink(missing_ok=True)
