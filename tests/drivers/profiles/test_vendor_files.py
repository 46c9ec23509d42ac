"""Every real vendor file of ../shared/data/drives imports with the expected layout facts (or
is refused in one line: the I/O module); the two CANopen drives without a cyclic synchronous
mode run interpolated position (Technosoft) and streamed profile velocity (Faulhaber)."""

from __future__ import annotations

from pathlib import Path

import pytest

from drivers.profiles import ProfileImportError, read_vendor_description
from drivers.profiles.choose import choose, is_drive
from hofto_hw.config.drive_profile import check_profile_against_loop, load_profile
from hofto_hw.errors import ConfigError

ROOT = Path(__file__).resolve().parents[3]
DATA = ROOT.parent / "shared" / "data" / "drives"
SHIPPED = ROOT / "configs" / "drives"

pytestmark = [
    pytest.mark.data,
    pytest.mark.skipif(not DATA.is_dir(), reason="../shared/data/drives (vendor files) absent"),
]


def _import(name: str, device: int = 0, loop: str | None = None):
    descs = [d for d in read_vendor_description(DATA / name) if is_drive(d)]
    return choose(descs[device], loop=loop)


def _layout(pdos) -> list[list[str | None]]:
    return [[e.field for e in p.entries] for p in pdos]


def test_elmo_fixed_pdos_controlword_after_targets_padding():
    descs = read_vendor_description(DATA / "elmo_GoldDrive.xml")
    assert len(descs) == 4  # two products, two revisions
    new = next(d for d in descs if d.product_code == 0x30924 and d.revision == 0x10420)
    p = choose(new).profile
    assert all(pdo.fixed for pdo in p.rx_pdos + p.tx_pdos)  # only assigned, never written
    assert [pdo.index for pdo in p.rx_pdos] == [0x1605, 0x1618]
    rx = _layout(p.rx_pdos)[0]
    assert rx.index("controlword") > rx.index("target_torque")  # Elmo maps it after targets
    assert p.rx_pdos[0].entries[-1].index == 0 and p.rx_pdos[0].entries[-1].bits == 8  # pad
    assert {0x1A13, 0x1A1F, 0x1A26} <= {pdo.index for pdo in p.tx_pdos}  # single-object PDOs
    assert p.mapped_fields() >= {"statusword", "position", "velocity", "torque", "error_code"}
    assert p.dc is not None and p.dc.assign_activate == 0x300 and p.dc.sync0_cycle_ns is None
    assert p.startup_value(0x60C2, 1) == "loop_period"  # the file's 0x60C2:1 = 2 follows the loop
    assert p.identity.revision_min == 0x10420
    old = next(d for d in descs if d.product_code == 0x30924 and d.revision == 1)
    p_old = choose(old).profile  # one fixed layout, mode set at start-up
    assert [pdo.index for pdo in p_old.rx_pdos] == [0x1600]
    assert _layout(p_old.rx_pdos)[0][-1] == "controlword"  # controlword last
    assert p_old.modes.set_by == "startup" and p_old.startup_value(0x6060) == 8


def test_inovance_configurable_layout_over_fixed_defaults():
    c = _import("inovance_SV660N.xml")
    p = c.profile
    # the fixed 0x1701/0x1B01 defaults miss objects the loop wants; 0x1600/0x1A00 (writable
    # in PREOP, excluding them) map them all: chosen, and the reason says so
    assert [pdo.index for pdo in p.rx_pdos] == [0x1600] and not p.rx_pdos[0].fixed
    assert [pdo.index for pdo in p.tx_pdos] == [0x1A00]
    assert any("best fixed set" in r for r in c.reasons)
    assert p.mapped_fields() >= {"controlword", "mode", "target_position", "torque_offset"}
    assert p.fallbacks == {"current": "unavailable"}  # 0x6078 is not in the dictionary
    assert p.dc is not None and p.dc.assign_activate == 0x300


def test_nanotec_dc_fixed_sync0_and_shift():
    p = _import("nanotec_C5-E-2-21.xml").profile
    assert p.dc is not None
    assert (p.dc.assign_activate, p.dc.sync0_cycle_ns, p.dc.sync0_shift_ns) == (
        0x330,
        1_000_000,
        250_000,
    )
    assert "csp" in p.modes.supported and "cst" in p.modes.supported
    check_profile_against_loop(p, 0.001, "x")
    with pytest.raises(ConfigError, match="SYNC0 every 1000000 ns"):
        check_profile_against_loop(p, 0.0005, "x")


def test_somanet_dictionary_in_module_and_bom():
    raw = (DATA / "synapticon_SOMANET-Node-fw5.6.6.xml").read_bytes()
    assert raw.startswith(b"\xef\xbb\xbf")
    descs = read_vendor_description(DATA / "synapticon_SOMANET-Node-fw5.6.6.xml")
    assert [d.device for d in descs] == [
        "SOMANET Node",
        "SOMANET Circulo",
        "SOMANET Circulo SMM",
        "SOMANET Integro",
    ]
    d = descs[0]
    assert d.has(0x6502) and d.default_of(0x6502) == 0x303AD  # from the CiA402 module
    p = choose(d).profile
    assert p.modes.loop == "csp" and p.modes.set_by == "pdo"
    assert p.process_data.rx_bytes == 300
    assert p.dc is not None and p.dc.sync0_cycle_ns is None  # Factor=1: the loop period


def test_maxon_sii_dump_recognised():
    descs = read_vendor_description(DATA / "maxon_EPOS4-Micro-24-5_IgH-SII-dump_NOT-VENDOR-ESI.xml")
    assert len(descs) == 1  # three identical live drives, listed once
    assert descs[0].kind == "igh-sii-dump" and descs[0].vendor_id == 251  # decimal id
    c = choose(descs[0])
    assert [pdo.index for pdo in c.profile.rx_pdos] == [0x1600]
    assert "SII dump" in c.profile.description
    assert c.profile.dc is None and any("SII dump" in r for r in c.reasons)


def test_zeroerr_one_megabit_and_disabled_pdos():
    descs = read_vendor_description(DATA / "zeroerr_eRob-eDriver.eds")
    assert descs[0].bitrates == [1_000_000]
    p = choose(descs[0]).profile
    assert p.bus == "canopen" and p.canopen is not None
    assert p.canopen.bitrates == [1_000_000]
    assert [c.cob_id_base for c in p.canopen.rpdo] == [0x200, 0x300]
    assert [c.enabled_by_default for c in p.canopen.rpdo] == [True, False]  # bit 31 in file
    assert all(c.transmission_type == 1 for c in p.canopen.rpdo + p.canopen.tpdo)
    assert all(pdo.bits <= 64 for pdo in p.rx_pdos + p.tx_pdos)
    assert p.fallbacks == {"error_code": "emcy", "digital_inputs": "none"}


def test_technosoft_runs_interpolated_position():
    """No csp/csv/cst (0x6502 = 0x001F0065: pp, pv, hm, ip): the loop runs ip, its target
    through 0x60C1:01, the interpolation period written at start-up."""
    d = read_vendor_description(DATA / "technosoft_iPOS.eds")[0]
    assert not d.has(0x60B2) and not d.has(0x603F)
    c = choose(d)
    p = c.profile
    assert p.modes.loop == "ip" and p.modes.supported == ["pp", "pv", "hm", "ip"]
    assert p.modes.position_gain is None
    rx = [(e.index, e.subindex, e.field) for pdo in p.rx_pdos for e in pdo.entries]
    assert (0x60C1, 1, "target_position") in rx
    assert not any(i == 0x607A for i, _, _ in rx)  # 0x607A is pp's target, not ip's
    assert not any(i == 0x60FF for i, _, _ in rx)  # no other target travels
    assert p.startup_value(0x60C2, 1) == "loop_period"
    assert p.startup_value(0x60C2, 2) == -3
    assert p.startup_value(0x60C0) == 0  # linear interpolation
    assert p.fallbacks["error_code"] == "emcy" and p.fallbacks["torque_offset"] == "unavailable"
    assert any(r.startswith("loop: ip") and "0x60C1:01" in r for r in c.reasons)
    check_profile_against_loop(p, 0.005, "test")  # 5 ms fits 0x60C2's UNSIGNED8 ms


def test_faulhaber_runs_streamed_profile_velocity():
    """pp, pv, hm only (0x6502 = 0x25; 0x6060 limited to 6: no ip): the loop runs pv, the
    target velocity 0x60FF every SYNC, the master's position loop gain in the profile."""
    d = read_vendor_description(DATA / "faulhaber_MCBL300x-CO.eds")[0]
    assert d.objects[(0x6060, 0)].high == 6
    c = choose(d)
    p = c.profile
    assert p.modes.loop == "pv" and p.modes.supported == ["pp", "pv", "hm"]
    assert p.modes.position_gain == 10.0
    rx = [e.field for pdo in p.rx_pdos for e in pdo.entries]
    assert rx == ["controlword", "target_velocity", "mode"]  # 56 bits, 3 of 4 entries
    assert p.fallbacks["torque"] == "current" and "target_position" in p.objects.sdo
    assert any(r.startswith("loop: pv") and "0x60FF" in r for r in c.reasons)
    # no velocity factor objects (0x6094-0x6097) in the EDS: the unit of 0x60FF/0x6083 is not
    # known (the limits suggest rpm); the import says so, once, and leaves it unknown
    assert not any(d.has(i, 1) or d.has(i) for i in range(0x6094, 0x6098))
    assert (p.units.velocity, p.units.acceleration) == ("unknown", "unknown")
    why = [r for r in c.reasons if r.startswith("units:")]
    assert len(why) == 1 and "0x6094-0x6097" in why[0] and "\n" not in why[0]


@pytest.mark.parametrize("name", ["technosoft_iPOS.eds", "nanotec_C5-E-2-21.xml"])
def test_position_loops_keep_velocities_in_counts(name):
    """ip and csp send positions: their velocity unit stays counts/s, nothing said."""
    c = _import(name)
    assert (c.profile.units.velocity, c.profile.units.acceleration) == ("counts/s", "counts/s^2")
    assert not any(r.startswith("units:") for r in c.reasons)


def test_drive_with_neither_ip_nor_pv_refused_naming_what_is_missing():
    """A drive whose 0x6502 offers only pp and hm (the Faulhaber file with pv taken out) is
    refused in one line saying which modes and objects the loop would need."""
    d = read_vendor_description(DATA / "faulhaber_MCBL300x-CO.eds")[0]
    d.objects[(0x6502, 0)].default = 0x21  # pp, hm
    with pytest.raises(ProfileImportError) as err:
        choose(d)
    msg = str(err.value)
    assert "\n" not in msg
    assert "no cyclic synchronous mode" in msg and "the drive supports pp, hm" in msg
    assert "nor ip with 0x60C1:01 mappable" in msg and "nor pv with 0x60FF mappable" in msg
    for index in ("0x60B2", "0x603F", "0x6071", "0x6077"):
        assert index in msg


def test_ip_drive_whose_interpolation_period_is_read_only_falls_back_to_pv():
    d = read_vendor_description(DATA / "technosoft_iPOS.eds")[0]
    d.objects[(0x60C2, 1)].access = "ro"  # the loop period could not be written
    p = choose(d).profile
    assert p.modes.loop == "pv"
    assert [e.index for pdo in p.rx_pdos for e in pdo.entries][:2] == [0x6040, 0x60FF]


@pytest.mark.parametrize("loop", ["ip", "pv"])
def test_loop_option_picks_ip_or_pv(loop):
    p = _import("technosoft_iPOS.eds", loop=loop).profile
    assert p.modes.loop == loop


def test_loop_option_refuses_a_mode_the_drive_lacks():
    with pytest.raises(ProfileImportError, match="--loop ip: the drive supports pp, pv, hm"):
        _import("faulhaber_MCBL300x-CO.eds", loop="ip")


def test_faulhaber_four_entries_per_pdo():
    d = read_vendor_description(DATA / "faulhaber_MCBL300x-CO.eds")[0]
    assert {p.max_entries for p in d.pdos} == {4}
    assert d.vendor_id == 327 and d.product_code == 3150  # decimal in [DeviceInfo]


def test_io_module_has_no_drive():
    descs = read_vendor_description(DATA / "itegva_E7x-IO_NEGATIVE.xml")
    assert descs and not any(is_drive(d) for d in descs)


@pytest.mark.parametrize("path", sorted(SHIPPED.glob("*.yaml")), ids=lambda p: p.stem)
def test_shipped_profile_is_what_import_gives(path):
    """configs/drives/*.yaml are exactly what `drive import` makes of the vendor file today."""
    shipped = load_profile(path)
    descs = read_vendor_description(DATA / shipped.source.file)
    desc = next(
        d
        for d in descs
        if d.product_code == shipped.identity.product_code
        and d.revision == shipped.identity.revision_min
    )
    again = choose(desc, name=shipped.name).profile
    assert again == shipped
    check_profile_against_loop(shipped, 0.001, str(path))


def test_zeroerr_signed_limits_written_in_hex():
    d = read_vendor_description(DATA / "zeroerr_eRob-eDriver.eds")[0]
    home = d.objects[(0x607C, 0)]  # INTEGER32, LowLimit=0x80000000 HighLimit=0x7FFFFFFF
    assert (home.low, home.high) == (-(2**31), 2**31 - 1)
    assert d.objects[(0x6040, 0)].high == 0xFFFF  # unsigned stays unsigned


def test_interpolation_period_written_where_writable():
    nanotec = _import("nanotec_C5-E-2-21.xml").profile  # 0x60C2 ro, its sub-indices rw
    assert nanotec.startup_value(0x60C2, 1) == "loop_period"
    assert nanotec.startup_value(0x60C2, 2) == -3
    zeroerr = _import("zeroerr_eRob-eDriver.eds").profile
    assert [s.transition for s in zeroerr.startup] == ["PO", "PO"]
    inovance = _import("inovance_SV660N.xml").profile  # no writable 0x60C2
    assert inovance.startup == []


def test_ethercat_drive_with_ip_only_writes_the_ip_target_into_a_configurable_pdo():
    """None of the ESIs lacks csp; the Inovance file made into an ip-only drive shows the
    EtherCAT side of the choice: 0x60C1:01 written into the configurable RxPDO, no 0x607A."""
    from drivers.profiles.description import ObjectInfo

    d = read_vendor_description(DATA / "inovance_SV660N.xml")[0]
    d.objects[(0x6502, 0)].default = 1 << 6  # ip only
    d.objects[(0x60C1, 1)] = ObjectInfo(0x60C1, 1, 32, mappable="rx", access="rw")
    d.objects.setdefault((0x60C2, 1), ObjectInfo(0x60C2, 1, 8, access="rw"))
    d.objects[(0x60C2, 1)].access = "rw"
    c = choose(d)
    p = c.profile
    assert p.modes.loop == "ip"
    rx = [(e.index, e.subindex) for pdo in p.rx_pdos for e in pdo.entries]
    assert (0x60C1, 1) in rx and (0x607A, 0) not in rx
    assert all(not pdo.fixed for pdo in p.rx_pdos)
    assert p.startup_value(0x60C2, 1) == "loop_period"
