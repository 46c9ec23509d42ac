"""`hofto-hw sim-canopen`: bad input gets one clear line; a control path never deletes a file."""

from __future__ import annotations

import threading

from support.canopen import CONFIG, unique_channel, wait_for

from hofto_hw.cli import main


def test_duration_must_be_positive_and_finite(capsys) -> None:
    for bad in ("-1", "nan", "inf"):
        args = ["sim-canopen", "--interface", "virtual", "--channel", unique_channel()]
        assert main([*args, "--config", str(CONFIG), "--duration", bad]) == 2
        assert "--duration: must be a finite number of seconds > 0" in capsys.readouterr().err


def test_control_path_that_is_a_file_is_refused_and_kept(tmp_path, capsys) -> None:
    keep = tmp_path / "notes.txt"
    keep.write_text("mine")
    args = ["sim-canopen", "--interface", "virtual", "--channel", unique_channel()]
    assert main([*args, "--config", str(CONFIG), "--control", str(keep), "--duration", "1"]) == 2
    assert "exists and is not a socket" in capsys.readouterr().err
    assert keep.read_text() == "mine"


def test_serves_a_master_until_the_duration(tmp_path) -> None:
    from support.canopen import load_cfg

    from drivers.canopen.master import CANopenTransport
    from drivers.sim.esc.network import ControlClient

    cfg = load_cfg()
    channel, ready, ctl = unique_channel(), tmp_path / "ready", str(tmp_path / "c.sock")
    args = ["sim-canopen", "--interface", "virtual", "--channel", channel, "--quiet-arm"]
    args += ["--config", str(CONFIG), "--control", ctl, "--ready-file", str(ready)]
    result: list[int] = []
    th = threading.Thread(target=lambda: result.append(main([*args, "--duration", "8"])))
    th.start()
    wait_for(ready.exists, 10.0, "emulator ready")
    t = CANopenTransport(channel, cfg.bus.drives, 1 / 200, can_interface="virtual", sdo_timeout=2.0)
    with t:
        assert ControlClient(ctl).call(op="status")["nmt"] == [5] * 6
    assert ControlClient(ctl).call(op="stop")["ok"]
    th.join(10.0)
    assert result == [0]
