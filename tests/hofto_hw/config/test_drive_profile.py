"""Drive profile schema (hofto_hw/config/drive_profile.py): a hand-written profile loads, and
each kind of mistake is refused in one line naming the field."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
import yaml

from hofto_hw.config.drive_profile import (
    CIA402_OBJECTS,
    DriveProfile,
    check_profile_against_loop,
    cia402_object,
    find_profile,
    load_profile,
    modes_from_bits,
)
from hofto_hw.errors import ConfigError

#: an Elmo-like drive: fixed single-object PDOs, controlword last, mode by start-up SDO
PROFILE: dict = {
    "profile": 1,
    "name": "test_fixed",
    "description": "hand-written test profile",
    "identity": {"vendor_id": 0x9A, "product_code": 0x30924, "revision_min": 0x10420},
    "bus": "ethercat",
    "modes": {"supported": ["pp", "csp", "csv", "cst", "hm"], "loop": "csp", "set_by": "startup"},
    "rx_pdos": [
        {"index": 0x160A, "fixed": True, "entries": [{"index": 0x607A, "bits": 32}]},
        {"index": 0x160C, "fixed": True, "entries": [{"index": 0x6071, "bits": 16}]},
        {"index": 0x1600, "fixed": True, "entries": [{"index": 0x6040, "bits": 16}]},
    ],
    "tx_pdos": [
        {
            "index": 0x1A00,
            "fixed": False,
            "entries": [
                {"index": 0x6041, "bits": 16},
                {"index": 0x6064, "bits": 32},
                {"index": 0x606C, "bits": 32},
                {"index": 0x6077, "bits": 16},
                {"index": 0x6061, "bits": 8},
                {"index": 0, "bits": 8},
            ],
        }
    ],
    "fallbacks": {
        "mode": "startup",
        "target_velocity": "unavailable",
        "torque_offset": "target_torque_in_cst",
        "current": "unavailable",
        "error_code": "sdo",
        "digital_inputs": "none",
    },
    "startup": [
        {"index": 0x6060, "value": 8, "bits": 8, "transition": "PS", "comment": "CSP"},
        {"index": 0x60C2, "subindex": 1, "value": 1, "bits": 8, "transition": "PS"},
        {"index": 0x60C2, "subindex": 2, "value": -3, "bits": 8, "transition": "PS"},
    ],
    "dc": {"assign_activate": 0x300, "sync0_shift_ns": 0},
}


def _profile(**changes) -> dict:
    data = copy.deepcopy(PROFILE)
    data.update(changes)
    return data


def _write(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_handwritten_profile_loads(tmp_path):
    p = load_profile(_write(tmp_path, PROFILE))
    assert p.rx_pdos[-1].entries[0].field == "controlword"
    assert [e.field for e in p.tx_pdos[0].entries][:2] == ["statusword", "position"]
    assert p.tx_pdos[0].entries[-1].field is None  # padding
    assert p.tx_pdos[0].bits == 112
    assert p.mapped_fields() >= {"controlword", "target_position", "statusword", "position"}
    assert p.startup_value(0x6060) == 8
    assert p.identity.matches(0x9A, 0x30924, 0x10420)
    assert not p.identity.matches(0x9A, 0x30924, 0x10000)
    # what is written is read back unchanged
    again = DriveProfile.model_validate(yaml.safe_load(yaml.safe_dump(p.model_dump())))
    assert again == p


def test_field_names_agree_with_pdo_layout():
    from drivers.cia402.pdo import OBJECT_FIELDS
    from hofto_hw.config.drive_profile import SUB_OBJECTS

    for (index, sub), name in OBJECT_FIELDS.items():
        if sub == 0:
            assert CIA402_OBJECTS[index][0] == name
        else:  # 0x60C1:01, the ip target
            assert SUB_OBJECTS[(index, sub)][0] == name


def test_helpers():
    assert cia402_object(0x6840) == (0x6040, 1)
    assert cia402_object(0x6064) == (0x6064, 0)
    assert cia402_object(0x2000) is None
    assert modes_from_bits(0x3A5) == ["pp", "pv", "hm", "csp", "csv", "cst"]


def _refused(tmp_path: Path, data: dict) -> str:
    path = _write(tmp_path, data)
    with pytest.raises(ConfigError) as err:
        load_profile(path)
    msg = str(err.value)
    assert msg.startswith(str(path))
    return msg


def test_duplicate_entry_refused(tmp_path):
    data = _profile()
    data["rx_pdos"][1]["entries"] = [{"index": 0x607A, "bits": 32}]
    msg = _refused(tmp_path, data)
    assert "0x607A:00 mapped twice" in msg and "0x160A" in msg


def test_odd_bit_layout_refused(tmp_path):
    data = _profile()
    data["tx_pdos"][0]["entries"].pop()  # drop the 8-bit padding: 104 bits is fine...
    data["tx_pdos"][0]["entries"].append({"index": 0, "bits": 4})  # ...108 is not
    assert "108 bits, not a whole number of bytes" in _refused(tmp_path, data)


def test_wrong_object_size_refused(tmp_path):
    data = _profile()
    data["rx_pdos"][2]["entries"] = [{"index": 0x6040, "bits": 32}]
    assert "(controlword) is 16 bits, not 32" in _refused(tmp_path, data)


def test_loop_mode_not_supported(tmp_path):
    data = _profile(modes={"supported": ["pp", "csv"], "loop": "csp", "set_by": "startup"})
    assert "modes.loop: csp is not among" in _refused(tmp_path, data)


def test_needed_object_without_fallback(tmp_path):
    data = _profile()
    del data["fallbacks"]["error_code"]
    msg = _refused(tmp_path, data)
    assert "error_code (0x603F)" in msg and "fallbacks.error_code is not set" in msg


def test_target_of_loop_mode_must_be_mapped(tmp_path):
    data = _profile()
    data["rx_pdos"].pop(0)
    data["fallbacks"]["target_position"] = "unavailable"
    assert "target_position (0x607A) of axis 0 is not mapped" in _refused(tmp_path, data)


def test_bad_fallback_refused(tmp_path):
    data = _profile()
    data["fallbacks"]["error_code"] = "guess"
    assert "fallbacks.error_code: 'guess'" in _refused(tmp_path, data)


def test_mode_by_startup_needs_the_write(tmp_path):
    data = _profile()
    data["startup"].pop(0)
    assert "0x6060 = 8 (csp)" in _refused(tmp_path, data)


def test_sync_manager_size(tmp_path):
    data = _profile(process_data={"rx_bytes": 6})
    assert "8 bytes exceed the sync manager's 6" in _refused(tmp_path, data)


def test_canopen_max_entries(tmp_path):
    data = _profile(
        bus="canopen",
        dc=None,
        canopen={
            "bitrates": [1_000_000],
            "max_entries": 4,
            "rpdo": [{"cob_id_base": 0x200 + 0x100 * i} for i in range(3)],
            "tpdo": [{"cob_id_base": 0x180}],
        },
    )
    for s in data["startup"]:
        s["transition"] = "PO"
    msg = _refused(tmp_path, data)
    assert "6 entries, the drive takes at most 4" in msg


def test_dc_cycle_against_loop(tmp_path):
    data = _profile()
    data["dc"]["sync0_cycle_ns"] = 1_000_000
    p = load_profile(_write(tmp_path, data))
    check_profile_against_loop(p, 0.001, "cfg.yaml: bus.drives[0].profile")
    with pytest.raises(ConfigError) as err:
        check_profile_against_loop(p, 0.0005, "cfg.yaml: bus.drives[0].profile")
    msg = str(err.value)
    assert "\n" not in msg and "dc.sync0_cycle_ns" in msg and "500000 ns" in msg


def test_interpolation_period_against_loop(tmp_path):
    p = load_profile(_write(tmp_path, PROFILE))  # 0x60C2 = 1e-3 s
    with pytest.raises(ConfigError, match="0x60C2 interpolation period"):
        check_profile_against_loop(p, 0.002, "x")


def test_find_profile(tmp_path, monkeypatch):
    path = _write(tmp_path, PROFILE)
    assert find_profile(path) == path
    assert find_profile("p.yaml", base_dir=tmp_path) == tmp_path / "p.yaml"
    monkeypatch.chdir(tmp_path)
    (tmp_path / "configs" / "drives").mkdir(parents=True)
    (tmp_path / "configs" / "drives" / "mine.yaml").write_text("x: 1\n")
    assert find_profile("mine").name == "mine.yaml"
    with pytest.raises(ConfigError, match="neither a file nor a profile"):
        find_profile("nosuch")


def test_config_names_a_profile(tmp_path, er3a_config):
    from hofto_hw.config.drive_profile import resolve_profiles
    from hofto_hw.config.drives import DriveConfig

    _write(tmp_path, PROFILE)
    bus = er3a_config.bus.model_copy(
        update={
            "transport": "ethercat",
            "interface": "eth0",
            "drives": [
                DriveConfig.model_validate(
                    d.model_dump(exclude={"identity"}) | {"profile": "p.yaml"}
                )
                if i == 0
                else d
                for i, d in enumerate(er3a_config.bus.drives)
            ],
        }
    )
    got = resolve_profiles(bus, 0.001, "cfg.yaml", tmp_path)
    assert got[0] is not None and got[0].name == "test_fixed" and got[1] is None
    with pytest.raises(ConfigError, match=r"cfg.yaml: bus.drives\[0\].profile '[a-z.]*': .*0x60C2"):
        resolve_profiles(bus, 0.002, "cfg.yaml", tmp_path)
    canbus = bus.model_copy(update={"transport": "canopen"})
    with pytest.raises(ConfigError, match="is an ethercat drive, the bus is canopen"):
        resolve_profiles(canbus, 0.001, "cfg.yaml", tmp_path)
    missing = bus.model_copy(
        update={"drives": [d.model_copy(update={"profile": "nosuch"}) for d in bus.drives]}
    )
    with pytest.raises(
        ConfigError, match=r"bus.drives\[0\].profile '[a-z.]*': drive profile 'nosuch'"
    ):
        resolve_profiles(missing, 0.001, "cfg.yaml", tmp_path)
    other = bus.drives[0].model_copy(update={"identity": bus.drives[1].identity})
    other.model_fields_set.add("identity")
    wrong = bus.model_copy(update={"drives": [other, *bus.drives[1:]]})
    with pytest.raises(ConfigError, match=r"identity \(vendor 0x00000DEC.*is not the profile's"):
        resolve_profiles(wrong, 0.001, "cfg.yaml", tmp_path)


def test_interpolation_period_follows_the_loop(tmp_path):
    data = _profile()
    data["startup"][1]["value"] = "loop_period"
    p = load_profile(_write(tmp_path, data))
    for cycle in (0.001, 0.002, 0.004):
        check_profile_against_loop(p, cycle, "x")
    with pytest.raises(ConfigError, match="cannot hold the loop's period"):
        check_profile_against_loop(p, 0.00025, "x")
    data["startup"][0]["value"] = "loop_period"
    assert "only for 0x60C2:01" in _refused(tmp_path, data)


def test_written_profile_reads_back_equal(tmp_path):
    from hofto_hw.config.drive_profile import profile_yaml, write_profile

    p = load_profile(_write(tmp_path, PROFILE))
    text = profile_yaml(p, header="test header\nsecond line")
    assert text.startswith("# test header\n# second line\n")
    assert "index: 0x6040" in text and "vendor_id: 0x0000009A" in text
    out = tmp_path / "out.yaml"
    write_profile(p, out, header="x")
    assert load_profile(out) == p
    assert [f.name for f in tmp_path.iterdir() if f.name.startswith(".")] == []
    with pytest.raises(ConfigError, match="cannot write drive profile"):
        write_profile(p, tmp_path / "nosuch" / "p.yaml")


def test_field_offsets(tmp_path):
    p = load_profile(_write(tmp_path, PROFILE))
    rx = p.field_offsets("rx")
    assert rx == {"target_position": (0, 32), "target_torque": (32, 16), "controlword": (48, 16)}
    tx = p.field_offsets("tx")
    assert tx["mode_display"] == (96, 8) and p.image_bits("tx") == 112


def test_profile_errors_are_short(tmp_path):
    data = _profile()
    data["rx_pdos"][1]["entries"] = [{"index": 0x607A, "bits": 32}]
    msg = _refused(tmp_path, data)
    assert "Value error" not in msg and "{" not in msg and "\n" not in msg


SHIPPED = sorted((Path(__file__).resolve().parents[3] / "configs" / "drives").glob("*.yaml"))


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_shipped_profiles_load(path):
    p = load_profile(path)
    assert p.name == path.stem and find_profile(path.stem).resolve() == path.resolve()
    check_profile_against_loop(p, 0.001, str(path))  # every shipped drive runs a 1 kHz loop


def test_nine_profiles_are_shipped():
    # the eight vendor drives (Technosoft in ip, Faulhaber in pv), and the Elmo ESI's second
    # product (elmo_gold_30925: the sixth EtherCAT model of configs/er3a_mixed.yaml)
    assert len(SHIPPED) == 9
    loops = {p.stem: load_profile(p).modes.loop for p in SHIPPED}
    assert loops["technosoft_ipos"] == "ip" and loops["faulhaber_mcbl300x"] == "pv"


def _shipped(name: str) -> dict:
    path = next(p for p in SHIPPED if p.stem == name)
    return yaml.safe_load(path.read_text())


def _invalid(data: dict, expect: str) -> None:
    from pydantic import ValidationError

    with pytest.raises(ValidationError) as err:
        DriveProfile.model_validate(data)
    assert expect in str(err.value)


def test_ip_and_pv_profiles_are_checked():
    ip, pv = _shipped("technosoft_ipos"), _shipped("faulhaber_mcbl300x")
    assert DriveProfile.model_validate(ip).modes.loop == "ip"
    # pv needs its position-loop gain, and only pv takes one
    bad = copy.deepcopy(pv)
    del bad["modes"]["position_gain"]
    _invalid(bad, "loop pv needs position_gain")
    bad = copy.deepcopy(ip)
    bad["modes"]["position_gain"] = 10.0
    _invalid(bad, "position_gain is for loop pv only (loop is ip)")
    # ip's target is 0x60C1:01, not pp's 0x607A
    bad = copy.deepcopy(ip)
    entry = next(e for e in bad["rx_pdos"][0]["entries"] if e["index"] == 0x60C1)
    entry.update(index=0x607A, subindex=0)
    _invalid(bad, "modes.loop ip: its target target_position goes through 0x60C1:01")
    # one object carries a field: 0x607A next to 0x60C1:01 maps the position target twice
    bad = copy.deepcopy(ip)
    bad["rx_pdos"].append(
        {"index": 0x1601, "fixed": False, "entries": [{"index": 0x607A, "bits": 32}]}
    )
    bad["canopen"]["rpdo"].append(copy.deepcopy(bad["canopen"]["rpdo"][0]))
    bad["canopen"]["rpdo"][-1]["cob_id_base"] = 0x300
    _invalid(bad, "target_position is mapped twice (0x60C1:01, 0x607A:00)")
    # ip needs the interpolation period written at start-up
    bad = copy.deepcopy(ip)
    bad["startup"] = [s for s in bad["startup"] if s["index"] != 0x60C2]
    _invalid(bad, "modes.loop ip needs a start-up write of 0x60C2:01")


def test_absent_settings_are_named_and_checked():
    """The shipped ip/pv profiles say which start-up setting objects their drives lack (the
    vendor files have no 0x6072, 0x6075, 0x6076; the Faulhaber no 0x6065/0x6066 either); an
    unknown or repeated name is refused."""
    ip, pv = _shipped("technosoft_ipos"), _shipped("faulhaber_mcbl300x")
    lacks = DriveProfile.model_validate(ip).objects.absent_settings
    assert lacks == ["max_torque", "rated_current", "rated_torque"]
    lacks = DriveProfile.model_validate(pv).objects.absent_settings
    assert set(lacks) == {
        "max_torque",
        "rated_current",
        "rated_torque",
        "following_error_window",
        "following_error_timeout",
    }
    assert DriveProfile.model_validate(_profile()).objects.absent_settings == []  # as today
    bad = copy.deepcopy(pv)
    bad["objects"]["absent_settings"] = ["max_torque", "max_current"]
    _invalid(bad, "unknown setting object 'max_current'")
    bad["objects"]["absent_settings"] = ["max_torque", "max_torque"]
    _invalid(bad, "listed twice")


def test_velocity_units_default_to_counts_and_are_checked(tmp_path):
    """units.velocity / units.acceleration: counts/s by default (the built-in layout and every
    profile written before them), rpm or unknown when stated; anything else one line."""
    data = _shipped("zeroerr_erob")
    assert "velocity" not in data["units"]  # written before units.velocity existed
    units = DriveProfile.model_validate(data).units
    assert (units.velocity, units.acceleration) == ("counts/s", "counts/s^2")
    assert units.counts_per_drive_unit(131072) == (1.0, 1.0)
    data["units"].update(velocity="rpm", acceleration="rpm/s")
    units = DriveProfile.model_validate(data).units
    assert units.counts_per_drive_unit(3000) == (50.0, 50.0)  # counts/s per min^-1
    data["units"]["acceleration"] = "rev/s^2"  # Faulhaber's 1/s^2: 60 rpm/s
    assert DriveProfile.model_validate(data).units.counts_per_drive_unit(3000) == (50.0, 3000.0)
    data["units"]["velocity"] = "rad/s"
    msg = _refused(tmp_path, data)
    assert "units.velocity" in msg and "\n" not in msg
