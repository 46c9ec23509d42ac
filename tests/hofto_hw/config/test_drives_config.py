"""Bus and drive config models: defaults, validation errors naming the field."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import ValidationError

from hofto_hw.config.drives import BusConfig
from hofto_hw.config.loader import load_config, parse_config
from hofto_hw.errors import ConfigError

ROOT = Path(__file__).resolve().parents[3]
DRIVE = {
    "counts_per_rev": 131072,
    "gear_ratio": 100.0,
    "rated_torque": 640,
    "rated_current": 2800,
    "torque_constant": 0.23,
    "torque_limit": 120.0,
    "quick_stop_deceleration": 10.0,
}


def test_shipped_configs_have_six_drives() -> None:
    for name in ("er3a.yaml", "ur10e.yaml"):
        cfg = load_config(ROOT / "configs" / name)
        assert cfg.bus is not None and len(cfg.bus.drives) == 6
        assert cfg.cycle_time == pytest.approx(1.0 / cfg.loop.rate_hz)


def test_defaults() -> None:
    bus = BusConfig(transport="sim", drives=[DRIVE])
    d = bus.drives[0]
    assert d.direction == 1 and d.zero_offset == 0 and not hasattr(bus, "cycle_time")
    assert d.following_error_window == 0.05 and d.identity.revision is None


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"gear_ratio": 0.0}, "gear_ratio"),
        ({"direction": 2}, "direction"),
        ({"counts_per_rev": -5}, "counts_per_rev"),
        ({"torque_limit": -1.0}, "torque_limit"),
        ({"bogus": 1}, "bogus"),
    ],
)
def test_bad_drive_values_name_the_field(change: dict, field: str) -> None:
    with pytest.raises(ValidationError, match=field):
        BusConfig(transport="sim", drives=[{**DRIVE, **change}])


def test_real_transports_need_an_interface() -> None:
    with pytest.raises(ValidationError, match="interface is required for transport 'ethercat'"):
        BusConfig(transport="ethercat", drives=[DRIVE])
    assert BusConfig(transport="ethercat", interface="eth1", drives=[DRIVE]).interface == "eth1"


def test_one_drive_per_joint_is_checked_with_the_file_named(er3a_config) -> None:
    data = er3a_config.model_dump(mode="json")
    data["bus"]["drives"] = data["bus"]["drives"][:5]
    with pytest.raises(ConfigError, match=r"my\.yaml: .*bus\.drives has 5 entries, expected 6"):
        parse_config(data, source="my.yaml")


def test_the_cycle_time_is_one_over_the_loop_rate(er3a_config) -> None:
    loop = er3a_config.loop.model_copy(update={"rate_hz": 250.0})
    slow = er3a_config.model_copy(update={"loop": loop})
    assert er3a_config.cycle_time == pytest.approx(0.001)
    assert slow.cycle_time == pytest.approx(0.004)


def test_an_old_bus_cycle_time_is_one_line_naming_its_replacement(er3a_config) -> None:
    data = er3a_config.model_dump(mode="json")
    data["loop"]["rate_hz"] = 1000.0
    data["bus"]["cycle_time"] = 0.002  # disagrees with the loop: once silently accepted
    with pytest.raises(ConfigError) as err:
        parse_config(data, source="old.yaml")
    assert str(err.value) == (
        "old.yaml: bus.cycle_time: removed; the bus cycles at loop.rate_hz "
        "(here 1000.0 Hz, a 0.001 s cycle): delete the line (got 0.002)"
    )


def test_any_transport_name_passes_the_schema() -> None:
    # which names exist is drivers.transport.BACKENDS' business (checked by `config check`)
    assert BusConfig(transport="profinet", interface="eth1", drives=[DRIVE]).transport == "profinet"
    with pytest.raises(ValidationError, match="transport"):
        BusConfig(transport="", drives=[DRIVE])
