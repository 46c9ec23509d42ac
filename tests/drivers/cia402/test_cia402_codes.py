"""Decoded meanings of SDO abort codes and CiA 301/402 error codes."""

from __future__ import annotations

from drivers.cia402.codes import describe_error_code, describe_sdo_abort


def test_known_error_codes() -> None:
    assert describe_error_code(0x2310) == "0x2310 continuous over-current"
    assert describe_error_code(0x8611) == "0x8611 following error too large"
    assert "encoder" in describe_error_code(0x7305)
    assert "over-voltage" in describe_error_code(0x3210)
    assert "communication lost" in describe_error_code(0x8130)
    assert describe_error_code(0) == "0x0000 no error"


def test_unlisted_error_codes_fall_back_to_their_class() -> None:
    assert (
        describe_error_code(0x2399)
        == "0x2399 current error on the device output side (code not listed)"
    )
    assert describe_error_code(0x4F01).startswith("0x4F01 temperature error")
    assert describe_error_code(0xFF42).startswith("0xFF42 device-specific error")


def test_sdo_abort_codes() -> None:
    assert describe_sdo_abort(0x06020000) == (
        "0x06020000 object does not exist in the object dictionary"
    )
    assert "read-only" in describe_sdo_abort(0x06010002)
    assert "length" in describe_sdo_abort(0x06070010)
    assert "device state" in describe_sdo_abort(0x08000022)
    assert describe_sdo_abort(0x12345678).endswith("unknown SDO abort code")
