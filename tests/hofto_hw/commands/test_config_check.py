"""``hofto-hw config check``: what the schema cannot check (registered transports), and the
one-line errors of an old or non-finite config, as a user meets them."""

from __future__ import annotations

from pathlib import Path

import pytest

from drivers.transport import BACKENDS
from hofto_hw.cli import main

ROOT = Path(__file__).resolve().parents[3]
ER3A = ROOT / "configs" / "er3a.yaml"


def _config(tmp_path: Path, *replacements: tuple[str, str]) -> Path:
    text = ER3A.read_text().replace("urdf: er3a/er3a.urdf", f"urdf: {ER3A.parent}/er3a/er3a.urdf")
    for old, new in replacements:
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / "cfg.yaml"
    path.write_text(text)
    return path


def _check(path: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = main(["config", "check", str(path)])
    return code, capsys.readouterr().err.strip()


def _refused(path: Path, capsys: pytest.CaptureFixture[str]) -> str:
    """config check's error for ``path``, asserting exit code 2 and one line."""
    code, err = _check(path, capsys)
    assert code == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


def test_an_unregistered_transport_fails_config_check(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _config(tmp_path, ("  transport: sim", "  transport: profinet\n  interface: eth1"))
    err = _refused(path, capsys)
    assert f"{path}: bus.transport: " in err and "(got 'profinet')" in err
    assert all(name in err for name in BACKENDS)


def test_every_registered_transport_passes_config_check(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for name in BACKENDS:
        if name == "canopen":  # a 1 kHz loop is more than a CAN bus carries: its own config
            path = ROOT / "configs" / "er3a_canopen.yaml"
        else:
            path = _config(tmp_path, ("  transport: sim", f"  transport: {name}\n  interface: x0"))
        assert _check(path, capsys)[0] == 0, name


def test_an_old_config_with_bus_cycle_time_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _config(tmp_path, ("  transport: sim", "  transport: sim\n  cycle_time: 0.001"))
    err = _refused(path, capsys)
    assert f"{path}: bus.cycle_time: removed; the bus cycles at loop.rate_hz" in err


def test_an_infinite_gain_is_one_line_naming_field_and_value(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # the top-level observers.momentum (4 spaces), not loop.observers.momentum (6)
    path = _config(tmp_path, ("\n    gain: [30.0,", "\n    gain: [.inf,"))
    err = _refused(path, capsys)
    assert f"{path}: observers.momentum.momentum.gain[0]: " in err and "(got inf)" in err


def test_the_registry_not_the_schema_decides_which_transports_exist(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    # as `transport: canopen` before a CANopen backend existed: the name is known to the
    # schema's authors but no backend serves it, so config check must refuse it
    monkeypatch.delitem(BACKENDS, "ethercat")
    path = _config(tmp_path, ("  transport: sim", "  transport: ethercat\n  interface: eth1"))
    err = _refused(path, capsys)
    assert err.endswith(
        f"{path}: bus.transport: no transport backend of that name; the backends are "
        f"{', '.join(sorted(BACKENDS))} (got 'ethercat')"
    )


def test_a_canopen_tpdo_resync_within_the_bus_loss_streak_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # 0.01 s is 2 cycles at 200 Hz: a late TPDO stream would be written off before the 3
    # lost cycles of safety.bus make it a bus loss
    can = ROOT / "configs" / "er3a_canopen.yaml"
    text = can.read_text().replace("urdf: er3a/er3a.urdf", f"urdf: {can.parent}/er3a/er3a.urdf")
    old = "    heartbeat_time: 0.05\n"
    assert old in text
    path = tmp_path / "can.yaml"
    path.write_text(text.replace(old, old + "    tpdo_resync: 0.01\n"))
    err = _refused(path, capsys)
    assert f"{path}: " in err and "bus.canopen.tpdo_resync = 0.01 s is 2 cycles at 200 Hz" in err
    assert "safety.bus.lost_cycles = 3" in err


def test_check_takes_robot_names_and_names_an_unknown_one(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)  # the shipped configs, not ./configs
    assert main(["config", "check", "er3a", "er3a_service"]) == 0
    out = capsys.readouterr().out
    assert "er3a.yaml: ok (er3a" in out and "er3a_service.yaml: ok (er3a" in out
    assert main(["config", "check", "nobot"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("hofto-hw config: error: config check: 'nobot' is neither a file")
    assert "er3a_service" in err and "\n" not in err
