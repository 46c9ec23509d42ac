"""The control channel's shared memory is made as the flight recorder's is (one
implementation, hofto_hw.recording.shared.Segment): a full /dev/shm is one line naming the
control plane, never a SIGBUS; nothing is left behind (socket, segment, log).

Before: the channel made its segment with a bare SharedMemory(create=True) and touched every
page, so a /dev/shm without room killed ``hofto-hw run --socket`` with SIGBUS. The
full-/dev/shm cases run in a private mount namespace with a small tmpfs (root; CI runs them).
"""

from __future__ import annotations

from pathlib import Path

from support.cli import one_line_error
from support.small_shm import in_small_shm, need_root

from hofto_hw.control_plane import channel as ch
from hofto_hw.recording import shared as sh


def test_the_channel_is_a_named_reserved_segment_removed_at_close() -> None:
    chan = ch.Channel(6, 2, create=True)
    path = sh.SHM_DIR / chan.name.lstrip("/")
    try:
        assert chan.name.startswith(sh.PREFIX)  # the owner's pid in it: remove_stale knows it
        assert path.exists() and path.stat().st_blocks * 512 >= path.stat().st_size
        other = ch.Channel(6, 2, name=chan.name)  # the control plane's side
        other.ctl[ch.STOP_SEQ] = 3
        assert int(chan.ctl[ch.STOP_SEQ]) == 3
        other.close()
        assert path.exists()  # the attached side never unlinks
    finally:
        chan.close()
    assert not path.exists()


def test_run_with_a_socket_and_a_full_dev_shm_is_one_line(tmp_path: Path) -> None:
    need_root()
    sock = tmp_path / "c.sock"
    argv = ["run", "--clock", "real", "--duration", "1", "--no-log", "--socket", str(sock)]
    p = in_small_shm(f"import sys; from hofto_hw.cli import main; sys.exit(main({argv!r}))")
    assert p.returncode != -7 and p.returncode != 135, "died of SIGBUS"
    line = one_line_error(
        p.returncode, p.stderr, "/dev/shm:", "MB free", "the control plane's shared memory needs"
    )
    assert "bytes)" in line
    assert list(tmp_path.iterdir()) == []  # no socket left


def test_reserving_the_channel_fails_at_creation_not_on_first_touch() -> None:
    need_root()
    code = (
        "import os, sys\n"
        "from hofto_hw.errors import UserError\n"
        "from hofto_hw.control_plane.channel import Channel\n"
        "class Roomy:\n"
        "    f_bavail, f_frsize = 1 << 40, 1\n"
        "os.statvfs = lambda p: Roomy()\n"
        "try:\n"
        "    Channel(6, 2, create=True)\n"
        "except UserError as e:\n"
        "    print(e, file=sys.stderr); sys.exit(2)\n"
        "print('created')\n"
    )
    p = in_small_shm(code)
    assert p.returncode == 2, (p.returncode, p.stderr[-500:])
    one_line_error(
        p.returncode, p.stderr, "/dev/shm: cannot reserve", "control plane", "No space left"
    )
