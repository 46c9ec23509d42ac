"""The shared PDO layout: sizes, offsets, byte order, mapping as data."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from drivers.cia402 import pdo


def test_rxpdo_layout_is_packed_15_bytes_in_contract_order() -> None:
    assert pdo.RXPDO_SIZE == 15
    names = [
        "controlword",
        "mode",
        "target_position",
        "target_velocity",
        "target_torque",
        "torque_offset",
    ]
    assert list(pdo.RXPDO_DTYPE.names) == names
    offsets = [pdo.RXPDO_DTYPE.fields[n][1] for n in names]
    assert offsets == [0, 2, 3, 7, 11, 13]


def test_txpdo_layout_is_packed_21_bytes_in_contract_order() -> None:
    assert pdo.TXPDO_SIZE == 21
    names = [
        "statusword",
        "mode_display",
        "position",
        "velocity",
        "torque",
        "current",
        "error_code",
        "digital_inputs",
    ]
    assert list(pdo.TXPDO_DTYPE.names) == names
    offsets = [pdo.TXPDO_DTYPE.fields[n][1] for n in names]
    assert offsets == [0, 2, 3, 7, 11, 13, 15, 17]


def test_bytes_are_little_endian_and_signed_where_cia402_says() -> None:
    rx = pdo.new_rx(2)
    rx[1] = (0x000F, 8, -123456, 7890, -300, 25)
    raw = rx.tobytes()[15:]
    assert raw == struct.pack("<Hbiihh", 0x000F, 8, -123456, 7890, -300, 25)
    tx = np.frombuffer(
        struct.pack("<HbiihhHI", 0x0237, 10, -5, 6, -7, 8, 0x8611, 3), dtype=pdo.TXPDO_DTYPE
    )
    assert tx["statusword"][0] == 0x0237 and tx["position"][0] == -5
    assert tx["error_code"][0] == 0x8611 and tx["mode_display"][0] == 10


def test_mapping_entries_match_the_dtypes() -> None:
    assert [e.field for e in pdo.RXPDO_MAPPING] == list(pdo.RXPDO_DTYPE.names)
    assert [e.field for e in pdo.TXPDO_MAPPING] == list(pdo.TXPDO_DTYPE.names)
    assert sum(e.bit_length for e in pdo.RXPDO_MAPPING) == 15 * 8
    assert sum(e.bit_length for e in pdo.TXPDO_MAPPING) == 21 * 8
    rx_index = {e.field: e.index for e in pdo.RXPDO_MAPPING}
    assert rx_index == {
        "controlword": 0x6040,
        "mode": 0x6060,
        "target_position": 0x607A,
        "target_velocity": 0x60FF,
        "target_torque": 0x6071,
        "torque_offset": 0x60B2,
    }
    tx_index = {e.field: e.index for e in pdo.TXPDO_MAPPING}
    assert tx_index == {
        "statusword": 0x6041,
        "mode_display": 0x6061,
        "position": 0x6064,
        "velocity": 0x606C,
        "torque": 0x6077,
        "current": 0x6078,
        "error_code": 0x603F,
        "digital_inputs": 0x60FD,
    }


def test_mapping_value_round_trip() -> None:
    e = pdo.RXPDO_MAPPING[2]
    assert pdo.mapping_value(e) == 0x607A0020
    assert pdo.parse_mapping_value(0x607A0020) == e
    assert pdo.parse_mapping_value(0x20000108).field == ""  # unknown object


def test_layout_dtype_of_a_reordered_mapping_and_bad_mappings() -> None:
    entries = [pdo.TXPDO_MAPPING[2], pdo.TXPDO_MAPPING[0]]
    dt = pdo.layout_dtype(entries)
    assert dt.itemsize == 6 and dt.names == ("position", "statusword")
    with pytest.raises(ValueError, match="0x1018:01 is not PDO-mappable"):
        pdo.layout_dtype([pdo.PdoEntry(0x1018, 1, 32, "x")])
    with pytest.raises(ValueError, match="0x6064:00 is 32 bits, mapping says 16"):
        pdo.layout_dtype([pdo.PdoEntry(0x6064, 0, 16, "position")])


def test_six_axes_are_vector_operations_on_field_views() -> None:
    tx = pdo.new_tx(6)
    pos = tx["position"]
    pos[:] = np.arange(6) * 1000
    assert np.frombuffer(tx.tobytes(), dtype=pdo.TXPDO_DTYPE)["position"][5] == 5000
    assert not pos.flags.owndata  # a view: writes land in the process image
