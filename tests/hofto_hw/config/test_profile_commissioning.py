"""The drive profile's commissioning sections (issue 28): where STO is read, the brake delay
objects and brake fault codes; their defaults and the one-line refusals."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from drivers.cia402.profiles import BRAKE_FAULT_CODE, builtin_profile
from hofto_hw.config.drive_profile import ProfileBrake, SdoParameter, StoSource, load_profile
from tests.hofto_hw.config.test_drive_profile import SHIPPED


def test_sto_source_defaults_and_refusals() -> None:
    assert builtin_profile("ethercat").sto_source() == StoSource(source="input", bit=16)
    can = builtin_profile("canopen").sto_source()
    assert (can.source, can.index, can.bit) == ("object", 0x60FD, 16)  # not mapped: by SDO
    # a vendor profile that says nothing: bits 16-31 of 0x60FD are the vendor's
    elmo = load_profile(next(p for p in SHIPPED if p.stem == "elmo_gold"))
    assert elmo.sto is None and elmo.sto_source().source == "state"
    with pytest.raises(ValidationError, match="bit 9 does not fit a 8-bit object"):
        StoSource(source="object", index=0x2100, bits=8, bit=9)
    with pytest.raises(ValidationError, match="source 'input' is 0x60FD:00"):
        StoSource(source="input", index=0x2100)


def test_brake_objects_and_fault_codes() -> None:
    b = builtin_profile("canopen").brake
    assert b is not None and b.is_brake_fault(BRAKE_FAULT_CODE) and not b.is_brake_fault(0x2310)
    assert b.release_delay is not None and b.release_delay.raw(0.1) == 100
    assert SdoParameter(index=0x2000, bits=8, unit=0.001).raw(1.0) == 255  # clipped to u8
    with pytest.raises(ValidationError, match=r"range \[0x7200, 0x7100\] is reversed"):
        ProfileBrake(fault_codes=[(0x7200, 0x7100)])


@pytest.mark.parametrize(
    ("stem", "release", "engage"),
    [
        ("inovance_sv660n", (0x2002, 10), (0x2002, 11)),
        ("nanotec_c5_e_2_21", (0x2038, 4), (0x2038, 1)),
        ("synapticon_somanet_node", (0x2004, 3), (0x2004, 5)),
        ("elmo_gold", None, None),
    ],
)
def test_shipped_profiles_name_their_brake_delay_objects(stem, release, engage) -> None:
    prof = load_profile(next(p for p in SHIPPED if p.stem == stem))
    if release is None:
        assert prof.brake is None  # none known: the drive's own setting stays
        return
    assert prof.brake is not None
    got = prof.brake.release_delay, prof.brake.engage_delay
    assert [(o.index, o.subindex) for o in got] == [release, engage]
