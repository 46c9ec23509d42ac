"""SII EEPROM image: built from a description, read back as a master reads it."""

from __future__ import annotations

import struct

import pytest
from esc_helpers import PRODUCT, REVISION, VENDOR, make_desc, make_od

from drivers.sim.esc import registers as r
from drivers.sim.esc import sii
from drivers.sim.esc.description import COE_COMPLETE_ACCESS, SlaveDescription
from drivers.sim.esc.esc import Esc


def test_image_round_trip_carries_identity_mailbox_and_categories() -> None:
    desc = make_desc(serial=42, alias=0x1234, mbx_out_size=96, mbx_in_size=64)
    info = sii.parse_image(sii.build_image(desc))
    assert (info.vendor_id, info.product_code, info.revision, info.serial) == (
        VENDOR,
        PRODUCT,
        REVISION,
        42,
    )
    assert info.alias == 0x1234
    assert info.mbx_out == (0x1000, 96)
    assert info.mbx_in == (0x1080, 64)
    assert info.mailbox_protocols == 0x04  # CoE only
    assert info.strings[0] == desc.name
    assert info.coe_details & COE_COMPLETE_ACCESS
    assert info.fmmu_usage[:3] == (1, 2, 3)
    types = [sm[4] for sm in info.sync_managers]
    assert types == [1, 2, 3, 4]
    assert info.sync_managers[2][:2] == (desc.outputs_offset, 15)
    assert info.sync_managers[3][:2] == (desc.inputs_offset, 21)
    assert info.checksum_ok


def test_checksum_detects_a_changed_configuration_area() -> None:
    image = bytearray(sii.build_image(make_desc()))
    image[2] ^= 0x01
    assert not sii.parse_image(bytes(image)).checksum_ok


def test_crc8_changes_with_every_byte() -> None:
    base = bytes(14)
    seen = {sii.crc8(base)}
    for i in range(14):
        b = bytearray(base)
        b[i] = 1
        seen.add(sii.crc8(bytes(b)))
    assert len(seen) == 15


def test_no_complete_access_is_advertised_when_disabled() -> None:
    info = sii.parse_image(sii.build_image(make_desc(complete_access=False)))
    assert not info.coe_details & COE_COMPLETE_ACCESS


@pytest.mark.parametrize(
    ("field", "value"),
    [("vendor_id", -1), ("product_code", 1 << 32), ("alias", 1 << 16)],
)
def test_description_rejects_values_that_do_not_fit(field: str, value: int) -> None:
    kw = {"vendor_id": 1, "product_code": 2, "revision": 3, field: value}
    with pytest.raises(ValueError, match=field):
        SlaveDescription(**kw)


def test_description_rejects_overlapping_areas() -> None:
    with pytest.raises(ValueError, match="overlaps"):
        make_desc(mbx_out_size=256)


def _eeprom_read(esc: Esc, word: int) -> bytes:
    esc.write(r.EEPROM_CONTROL, struct.pack("<HI", r.EEPROM_CMD_READ, word))
    status = bytearray(2)
    esc.read(r.EEPROM_CONTROL, status, 0, 2)
    st = struct.unpack("<H", status)[0]
    assert not st & (r.EEPROM_BUSY | r.EEPROM_CMD_MASK), "command bits must clear"
    assert st & r.EEPROM_READ_8_BYTES
    data = bytearray(8)
    esc.read(r.EEPROM_DATA, data, 0, 8)
    return bytes(data)


def test_eeprom_interface_reads_the_image_8_bytes_at_a_time() -> None:
    esc = Esc(make_desc(), make_od())
    assert _eeprom_read(esc, 0x08) == struct.pack("<II", VENDOR, PRODUCT)
    assert _eeprom_read(esc, 0x0C)[:4] == struct.pack("<I", REVISION)
    image = sii.build_image(esc.desc)
    assert _eeprom_read(esc, 0x40) == image[0x80:0x88]


def test_eeprom_write_needs_write_enable() -> None:
    esc = Esc(make_desc(), make_od())
    esc.write(r.EEPROM_DATA, b"\x34\x12")
    esc.write(r.EEPROM_CONTROL, struct.pack("<HI", r.EEPROM_CMD_WRITE, 0x0E))
    st = bytearray(2)
    esc.read(r.EEPROM_CONTROL, st, 0, 2)
    assert struct.unpack("<H", st)[0] & r.EEPROM_ERROR_ACK
    esc.write(r.EEPROM_CONTROL, struct.pack("<HI", r.EEPROM_CMD_WRITE | 1, 0x0E))
    assert _eeprom_read(esc, 0x0E)[:2] == b"\x34\x12"
