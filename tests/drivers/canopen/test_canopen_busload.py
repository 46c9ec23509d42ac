"""Worst-case CAN bus load and its refusal (config check and the master)."""

from __future__ import annotations

import pytest

from drivers.canopen.busload import (
    bus_load,
    check_bus_load,
    classic_frame_bits,
    configured_load,
    fd_frame_bits,
)
from drivers.canopen.layout import RPDOS, TPDOS, frame_payloads
from hofto_hw.errors import ConfigError


def test_classic_frame_bits_worst_case_stuffing() -> None:
    assert classic_frame_bits(8) == 135
    assert classic_frame_bits(0) == 55  # SYNC
    assert classic_frame_bits(7) == 125  # 34 + 56 + 13 + floor(89 / 4)
    with pytest.raises(ValueError):
        classic_frame_bits(9)


def test_six_drives_one_rpdo_two_tpdos_matches_the_hand_count() -> None:
    load = bus_load([0] + [8, 8, 8] * 6, 1000.0, 1_000_000)
    assert load.bits_per_cycle == 2485
    assert load.load == pytest.approx(2.485)
    assert 400 < load.highest_rate(1.0) < 405
    assert 280 < load.highest_rate() < 283  # at the default 70 % limit


def test_can_fd_is_cheaper_per_byte_than_classic() -> None:
    nom, dat = fd_frame_bits(16)
    assert nom < 40 and dat > 8 * 16
    fd = bus_load([0] + [8, 16] * 6, 1000.0, 1_000_000, 5_000_000)
    assert 0.75 < fd.load < 0.9


def test_our_layout_two_rpdos_two_tpdos_per_drive() -> None:
    assert [p.size for p in RPDOS + TPDOS] == [8, 7, 8, 7]
    payloads = frame_payloads(6)
    assert payloads[0] == 0 and len(payloads) == 25
    load = bus_load(payloads, 200.0, 1_000_000)
    assert load.bits_per_cycle == 55 + 6 * (135 + 125 + 135 + 125)


def test_refusal_names_load_limit_and_highest_rate() -> None:
    load = bus_load(frame_payloads(6), 1000.0, 1_000_000)
    with pytest.raises(ConfigError) as e:
        check_bus_load(load, "bus.canopen")
    msg = str(e.value)
    assert "bus load 318 % at 1000 Hz" in msg
    assert "limit 70 %" in msg
    assert "highest feasible rate is 220 Hz" in msg
    check_bus_load(bus_load(frame_payloads(6), 200.0, 1_000_000))  # 64 %: accepted


def test_configured_load_follows_the_options() -> None:
    from support.canopen import load_cfg

    cfg = load_cfg()
    assert configured_load(cfg.bus, cfg.loop.rate_hz).load == pytest.approx(0.635, abs=0.01)
    slow = cfg.bus.model_copy(
        update={"canopen": cfg.bus.canopen.model_copy(update={"bitrate": 500_000})}
    )
    assert configured_load(slow, 200.0).load > 1.2


def test_config_check_refuses_a_rate_the_bus_cannot_carry(tmp_path, capsys) -> None:
    from support.canopen import CONFIG

    from hofto_hw.cli import main

    text = CONFIG.read_text().replace("rate_hz: 200.0", "rate_hz: 400.0")
    text = text.replace("urdf: er3a/er3a.urdf", f"urdf: {CONFIG.parent / 'er3a' / 'er3a.urdf'}")
    path = tmp_path / "fast.yaml"
    path.write_text(text)
    assert main(["config", "check", str(path)]) == 2
    err = capsys.readouterr().err
    assert "bus load 127 % at 400 Hz" in err and "limit 70 %" in err and "220 Hz" in err
    assert main(["config", "check", str(CONFIG)]) == 0
    assert "CANopen bus load 64 % at 200 Hz" in capsys.readouterr().out


def test_canopen_options_are_validated_naming_the_field() -> None:
    import yaml
    from support.canopen import CONFIG

    from hofto_hw.config.loader import parse_config

    data = yaml.safe_load(CONFIG.read_text())
    data["bus"]["canopen"]["node_ids"] = [1, 2, 3]
    with pytest.raises(ConfigError, match="node_ids has 3 ids for 6 drives"):
        parse_config(data, "x.yaml", CONFIG.parent)
    data["bus"]["canopen"]["node_ids"] = [1, 2, 3, 4, 5, 5]
    with pytest.raises(ConfigError, match="node_ids must be unique"):
        parse_config(data, "x.yaml", CONFIG.parent)
    data["bus"]["canopen"]["node_ids"] = None
    data["bus"]["canopen"]["load_limit"] = 1.5
    with pytest.raises(ConfigError, match="load_limit"):
        parse_config(data, "x.yaml", CONFIG.parent)
