"""An emulated drive's dictionary impersonating a profile refuses what the real drive
refuses: writing a fixed PDO (0x06010002), remapping in SAFE-OP/OP (0x08000022), assigning
a PDO it does not have (0x06090030), reading an object it does not have (0x06020000)."""

from __future__ import annotations

import struct

import pytest
from support.profiles import ELMO, ROOT, SOMANET, SPARSE, profile

from drivers.cia402 import codes
from drivers.sim.drive import EmulatedDrives
from drivers.sim.object_dictionary import SdoAbort
from drivers.sim.plant import Plant
from hofto_hw.config.loader import load_config
from hofto_hw.model.robot import RobotModel


@pytest.fixture(scope="module")
def drives() -> EmulatedDrives:
    cfg = load_config(ROOT / "configs" / "er3a.yaml")
    plant = Plant(RobotModel.from_config(cfg.robot), cfg.simulation, cfg.cycle_time)
    profiles = [profile(p) for p in (ELMO, SPARSE, SOMANET)] + [None] * 3
    return EmulatedDrives(plant, cfg.bus.drives, profiles=profiles)


def _abort(od, index: int, sub: int, data: bytes) -> int:
    with pytest.raises(SdoAbort) as err:
        od.write(index, sub, data)
    return err.value.code


def test_identity_and_pdos_are_the_profiles(drives) -> None:
    od = drives.ods[0]
    assert od.get(0x1018, 1) == ELMO["identity"]["vendor_id"]
    assert od.get(0x1018, 2) == ELMO["identity"]["product_code"]
    assert od.get(0x1C12, 1) == 0x1605 and od.get(0x1C13, 1) == 0x1A07
    assert [e[:3] for e in od.mapping(0x1605)][-1] == (0x6040, 0, 16)
    assert (0x1600, 0) not in od  # the built-in 0x1600 is not this drive's


def test_a_fixed_pdo_is_read_only(drives) -> None:
    od = drives.ods[0]
    assert _abort(od, 0x1605, 0, b"\x00") == codes.ABORT_READ_ONLY == 0x06010002


def test_a_configurable_pdo_is_writable_in_preop_only(drives) -> None:
    od = drives.ods[1]
    od.write(0x1600, 0, b"\x00")
    od.write(0x1600, 1, struct.pack("<I", 0x60400010))
    od.write(0x1600, 0, b"\x01")
    od.pdo_locked = True
    try:
        assert _abort(od, 0x1600, 0, b"\x00") == codes.ABORT_DEVICE_STATE
    finally:
        od.pdo_locked = False


def test_only_its_own_pdos_can_be_assigned(drives) -> None:
    od = drives.ods[2]
    od.write(0x1C12, 0, b"\x00")
    od.write(0x1C12, 3, struct.pack("<H", 0x1601))
    assert _abort(od, 0x1C12, 1, struct.pack("<H", 0x1A00)) == codes.ABORT_VALUE_RANGE


def test_absent_objects_are_absent(drives) -> None:
    od = drives.ods[1]
    for index in (0x6071, 0x6077, 0x60B2, 0x603F, 0x60FD):
        with pytest.raises(SdoAbort) as err:
            od.read(index, 0)
        assert err.value.code == codes.ABORT_NO_OBJECT
    assert drives.ods[3].get(0x1C12, 1) == 0x1600  # no profile: the built-in drive
