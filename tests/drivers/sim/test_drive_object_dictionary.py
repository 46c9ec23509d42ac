"""Object dictionary of the emulated drives: SDO read/write, abort codes, PDO mapping."""

from __future__ import annotations

import struct
from collections.abc import Callable

import pytest

from drivers.cia402.pdo import RXPDO_MAPPING, TXPDO_MAPPING, PdoEntry, mapping_value
from drivers.sim.object_dictionary import ObjectDictionary, SdoAbort
from drivers.sim.simbus import SimBus
from hofto_hw.config.models import SystemConfig


@pytest.fixture
def od(bus: SimBus) -> ObjectDictionary:
    return bus.drives.ods[2]


def _abort(fn: Callable[..., object], *args: object) -> int:
    with pytest.raises(SdoAbort) as info:
        fn(*args)
    return info.value.code


def test_identity_and_device_type(od: ObjectDictionary, cfg: SystemConfig) -> None:
    ident = cfg.bus.drives[2].identity
    assert struct.unpack("<I", od.read(0x1018, 1))[0] == ident.vendor_id
    assert struct.unpack("<I", od.read(0x1018, 2))[0] == ident.product_code
    assert od.read(0x1018, 0) == b"\x04"
    assert struct.unpack("<I", od.read(0x1000, 0))[0] & 0xFFFF == 402
    assert b"joint_3" in od.read(0x1008, 0)


def test_every_contract_object_is_present(od: ObjectDictionary) -> None:
    wanted = [
        0x1000,
        0x1018,
        0x1600,
        0x1A00,
        0x1C12,
        0x1C13,
        0x603F,
        0x6040,
        0x6041,
        0x6060,
        0x6061,
        0x6064,
        0x606C,
        0x6071,
        0x6072,
        0x6075,
        0x6076,
        0x6077,
        0x6078,
        0x607A,
        0x6085,
        0x608F,
        0x6091,
        0x60B2,
        0x60FD,
        0x60FF,
    ]
    assert set(wanted) <= set(od.indices())


def test_abort_codes(od: ObjectDictionary) -> None:
    assert _abort(od.read, 0x2FFF, 0) == 0x06020000  # no such object
    assert _abort(od.read, 0x1018, 9) == 0x06090011  # no such sub-index
    assert _abort(od.write, 0x6041, 0, b"\x00\x00") == 0x06010002  # read-only
    assert _abort(od.write, 0x1018, 1, b"\x00" * 4) == 0x06010002
    assert _abort(od.write, 0x6072, 0, b"\x01\x02\x03\x04") == 0x06070010  # u16 given 4 B
    assert _abort(od.write, 0x6072, 0, b"\x01") == 0x06070010
    assert _abort(od.write, 0x605A, 0, struct.pack("<h", 9)) == 0x06090031  # too high
    assert _abort(od.write, 0x605A, 0, struct.pack("<h", -1)) == 0x06090032  # too low
    assert _abort(od.write, 0x6085, 0, struct.pack("<I", 0)) == 0x06090032


def test_bound_objects_read_and_write_the_live_drive(bus: SimBus, od: ObjectDictionary) -> None:
    bus.drives.tx["position"][2] = -4242
    assert struct.unpack("<i", od.read(0x6064, 0))[0] == -4242
    od.write(0x6072, 0, struct.pack("<H", 777))
    assert bus.drives.max_torque[2] == 777
    assert bus.drives.max_torque[1] != 777  # other drives untouched
    od.write(0x6060, 0, struct.pack("<b", 9))
    assert bus.drives.rx["mode"][2] == 9


def test_scaling_objects_describe_the_config(od: ObjectDictionary, cfg: SystemConfig) -> None:
    d = cfg.bus.drives[2]
    assert od.get(0x608F, 1) == d.counts_per_rev
    assert od.get(0x6091, 1) / od.get(0x6091, 2) == pytest.approx(d.gear_ratio)
    assert od.get(0x6076) == round(d.rated_torque)
    assert od.get(0x6075) == round(d.rated_current)


def test_default_mapping_is_the_shared_layout(od: ObjectDictionary) -> None:
    assert od.mapping(0x1600) == list(RXPDO_MAPPING)
    assert od.mapping(0x1A00) == list(TXPDO_MAPPING)
    assert od.get(0x1C12, 1) == 0x1600 and od.get(0x1C13, 1) == 0x1A00


def test_remap_in_pre_operational_follows_the_cia301_sequence(od: ObjectDictionary) -> None:
    sw = mapping_value(TXPDO_MAPPING[0])
    pos = mapping_value(TXPDO_MAPPING[2])
    # Entries can only change while sub 0 is 0.
    assert _abort(od.write, 0x1A00, 1, struct.pack("<I", pos)) == 0x06010003
    od.write(0x1A00, 0, b"\x00")
    od.write(0x1A00, 1, struct.pack("<I", pos))
    od.write(0x1A00, 2, struct.pack("<I", sw))
    od.write(0x1A00, 0, b"\x02")
    assert od.mapping(0x1A00) == [TXPDO_MAPPING[2], TXPDO_MAPPING[0]]


def test_bad_mappings_abort(od: ObjectDictionary) -> None:
    od.write(0x1600, 0, b"\x00")
    bad = [
        (PdoEntry(0x1018, 1, 32, ""), 0x06040041),  # not mappable
        (PdoEntry(0x6041, 0, 16, ""), 0x06040041),  # read-only object in an RxPDO
        (PdoEntry(0x2ABC, 0, 16, ""), 0x06020000),  # no such object
        (PdoEntry(0x6040, 0, 32, ""), 0x06040042),  # wrong length
    ]
    for entry, code in bad:
        assert _abort(od.write, 0x1600, 1, struct.pack("<I", mapping_value(entry))) == code


def test_mapping_is_locked_while_pdos_run(bus: SimBus) -> None:
    od = bus.drives.ods[0]
    bus.open()
    assert _abort(od.write, 0x1600, 0, b"\x00") == 0x08000022
    assert _abort(od.write, 0x1C12, 0, b"\x00") == 0x08000022
    bus.close()
    od.write(0x1600, 0, b"\x00")  # pre-operational again: allowed


def test_complete_access_read(od: ObjectDictionary) -> None:
    data = od.read_complete(0x1018)
    assert data[0] == 4 and data[1] == 0  # sub 0 padded to 16 bits
    assert len(data) == 2 + 4 * 4
    assert struct.unpack_from("<I", data, 2)[0] == od.get(0x1018, 1)
