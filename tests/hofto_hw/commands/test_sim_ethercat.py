"""`hofto-hw sim-ethercat`: bad durations and control-socket paths are refused in one line,
and nothing but a stale socket is ever removed (defect 9)."""

from __future__ import annotations

import os
import socket
import stat
from pathlib import Path

import pytest

from drivers.sim.control_socket import check_control_path, open_control_socket
from hofto_hw.cli import main
from hofto_hw.errors import UserError

ROOT = Path(__file__).resolve().parents[3]
CONFIG = str(ROOT / "configs" / "er3a.yaml")


def _cli(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    code = main(["sim-ethercat", "--iface", "nosuchif0", "--config", CONFIG, *args])
    err = capsys.readouterr().err
    return code, err


@pytest.mark.parametrize("value", ["-1", "0", "nan", "inf", "-inf"])
def test_bad_duration_is_refused_in_one_line(value: str, capsys) -> None:
    code, err = _cli(capsys, f"--duration={value}")
    assert code == 2
    assert err.count("\n") == 1 and "--duration" in err and "positive finite" in err
    assert "Traceback" not in err


def test_regular_file_at_the_control_path_is_refused_and_kept(tmp_path, capsys) -> None:
    victim = tmp_path / "important.txt"
    victim.write_text("keep me")
    code, err = _cli(capsys, "--control", str(victim))
    assert code == 2 and err.count("\n") == 1
    assert "--control" in err and "not a socket" in err and str(victim) in err
    assert victim.read_text() == "keep me"


def test_folder_at_the_control_path_is_refused(tmp_path, capsys) -> None:
    folder = tmp_path / "sockdir"
    folder.mkdir()
    code, err = _cli(capsys, "--control", str(folder))
    assert code == 2 and err.count("\n") == 1 and "is a folder" in err
    assert folder.is_dir()


def test_control_path_in_a_missing_folder_is_refused(tmp_path, capsys) -> None:
    code, err = _cli(capsys, "--control", str(tmp_path / "nope" / "ctl.sock"))
    assert code == 2 and err.count("\n") == 1
    assert "does not exist" in err and "nope" in err


def test_symlink_to_a_file_is_refused_and_its_target_kept(tmp_path) -> None:
    target = tmp_path / "target.txt"
    target.write_text("x")
    link = tmp_path / "ctl.sock"
    link.symlink_to(target)
    with pytest.raises(UserError, match="not a socket"):
        check_control_path(str(link))
    assert link.is_symlink() and target.read_text() == "x"


def test_stale_socket_is_replaced_and_the_new_one_is_owner_only(tmp_path) -> None:
    path = str(tmp_path / "ctl.sock")
    stale = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    stale.bind(path)
    stale.close()  # the file stays, nobody listens: stale
    old_mask = os.umask(0)  # even with a permissive umask the socket is 0600
    try:
        srv = open_control_socket(path)
    finally:
        os.umask(old_mask)
    try:
        st = os.lstat(path)
        assert stat.S_ISSOCK(st.st_mode)
        assert stat.S_IMODE(st.st_mode) == 0o600
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as c:
            c.connect(path)  # the new socket listens
    finally:
        srv.close()


def test_live_socket_is_not_taken_over(tmp_path) -> None:
    path = str(tmp_path / "ctl.sock")
    live = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    live.bind(path)
    live.listen(1)
    try:
        with pytest.raises(UserError, match="in use by another process"):
            open_control_socket(path)
        assert stat.S_ISSOCK(os.lstat(path).st_mode)
    finally:
        live.close()
