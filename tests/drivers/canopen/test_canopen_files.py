"""The shipped EDS matches the emulated drive; the control socket never deletes a file."""

from __future__ import annotations

import os
import socket
import stat
import threading

import pytest
from support.canopen import ROOT

from drivers.sim.control_socket import open_control_socket, serve_control
from hofto_hw.errors import UserError


def test_shipped_eds_is_what_the_generator_writes() -> None:
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "make_eds", ROOT / "tools" / "make_canopen_eds.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    shipped = (ROOT / "configs" / "canopen" / "emulated_drive.eds").read_text()
    assert shipped == mod.build(), "regenerate with python tools/make_canopen_eds.py"


def test_eds_parses_with_canopen_and_has_the_drive_objects() -> None:
    canopen = pytest.importorskip("canopen")
    od = canopen.import_od(str(ROOT / "configs" / "canopen" / "emulated_drive.eds"), 7)
    assert od[0x1800][1].default == 0x187  # $NODEID+0x180
    assert od[0x1401][1].default == 0x307
    assert od[0x1018][1].default == 0xDEC
    assert od[0x6041].pdo_mappable and not od[0x6041].writable
    assert od[0x1A01][2].default == 0x60780010


def test_control_socket_refuses_a_regular_file(tmp_path) -> None:
    path = tmp_path / "precious.txt"
    path.write_text("keep me")
    with pytest.raises(UserError, match="exists and is not a socket"):
        open_control_socket(str(path))
    assert path.read_text() == "keep me"


def test_control_socket_missing_folder_and_live_socket(tmp_path) -> None:
    with pytest.raises(UserError, match="does not exist"):
        open_control_socket(str(tmp_path / "nope" / "ctl.sock"))
    path = str(tmp_path / "ctl.sock")
    srv = open_control_socket(path)
    try:
        assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
        with pytest.raises(UserError, match="in use by another process"):
            open_control_socket(path)
    finally:
        srv.close()
    # A stale socket (nobody listening) is replaced.
    open_control_socket(path).close()


def test_serve_control_answers_and_removes_its_socket(tmp_path) -> None:
    path = str(tmp_path / "ctl.sock")
    stop = threading.Event()
    t = serve_control(path, lambda req: {"ok": True, "echo": req.get("op")}, stop)
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.connect(path)
        s.sendall(b'{"op": "status"}\n')
        assert b'"echo": "status"' in s.recv(4096)
    stop.set()
    t.join(2.0)
    assert not os.path.exists(path)
