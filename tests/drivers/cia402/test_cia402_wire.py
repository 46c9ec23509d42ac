"""Per-axis wire layouts: canonical records <-> each drive's own bytes, vectorised."""

from __future__ import annotations

import struct
import tracemalloc

import numpy as np
import pytest

from drivers.cia402.pdo import new_rx, new_tx
from drivers.cia402.wire import BUILTIN_LAYOUT, AxisLayout, LayoutError, WireEntry, WireImage

E = WireEntry
PAD8 = E(0, 0, 8)

#: Elmo-like: controlword last, the 8-bit mode padded to 16 bits, no torque offset
ELMO = AxisLayout(
    rx=(
        E(0x607A, 0, 32),
        E(0x60FF, 0, 32),
        E(0x6071, 0, 16),
        E(0x6060, 0, 8),
        PAD8,
        E(0x6040, 0, 16),
    ),
    tx=(
        E(0x6064, 0, 32),
        E(0x60FD, 0, 32),
        E(0x606C, 0, 32),
        E(0x6077, 0, 16),
        E(0x6041, 0, 16),
        E(0x6061, 0, 8),
        PAD8,
    ),
)
#: Faulhaber-like: no 0x6071/0x6077/0x603F/0x60B2, mode by SDO, a vendor object mapped
SPARSE = AxisLayout(
    rx=(E(0x6040, 0, 16), E(0x607A, 0, 32), E(0x60B8, 0, 16)),
    tx=(E(0x6041, 0, 16), E(0x6064, 0, 32), E(0x60B9, 0, 16), E(0x606C, 0, 32)),
)


def _canonical(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    rx, tx = new_rx(n), new_tx(n)
    rx.view(np.uint8)[:] = rng.integers(0, 256, rx.nbytes, dtype=np.uint8)
    tx.view(np.uint8)[:] = rng.integers(0, 256, tx.nbytes, dtype=np.uint8)
    return rx, tx


def test_builtin_layout_is_the_canonical_record():
    img = WireImage([BUILTIN_LAYOUT] * 3)
    rx, tx = _canonical(3)
    img.bind_master(rx, tx)
    img.encode_rx()
    assert img.builtin
    assert bytes(img.rx_out) == rx.tobytes()
    img.tx_in[:] = np.frombuffer(_canonical(3, 1)[1].tobytes(), np.uint8)
    img.decode_tx()
    assert tx.tobytes() == bytes(img.tx_in)


def test_mixed_layouts_encode_each_axis_in_its_own_order():
    layouts = [ELMO, BUILTIN_LAYOUT, SPARSE]
    img = WireImage(layouts)
    rx, tx = _canonical(3)
    img.bind_master(rx, tx)
    img.encode_rx()
    assert [img.rx_size(i) for i in range(3)] == [14, 15, 8]
    a0 = bytes(img.rx_slice(0))
    pos, vel, tau, mode, pad, cw = struct.unpack("<iihbbH", a0)
    assert (pos, vel, tau, mode, pad, cw) == (
        rx["target_position"][0],
        rx["target_velocity"][0],
        rx["target_torque"][0],
        rx["mode"][0],
        0,
        rx["controlword"][0],
    )
    assert bytes(img.rx_slice(1)) == rx[1:2].tobytes()
    cw, pos, probe = struct.unpack("<HiH", bytes(img.rx_slice(2)))
    assert (cw, pos, probe) == (rx["controlword"][2], rx["target_position"][2], 0)


def test_decode_fills_absent_fields_with_their_defaults_and_reports_presence():
    layouts = [ELMO, SPARSE]
    img = WireImage(layouts, ["j1", "j2"])
    rx, tx = _canonical(2)
    img.bind_master(rx, tx)
    img.set_default(1, "mode_display", 8)
    img.tx_slice(0)[:] = np.frombuffer(
        struct.pack("<iIihHbb", -5, 0x10000, 77, -12, 0x1237, 8, 0x55), np.uint8
    )
    img.tx_slice(1)[:] = np.frombuffer(struct.pack("<HiHi", 0x0637, 123, 0xFFFF, -9), np.uint8)
    img.decode_tx()
    assert tx["position"].tolist() == [-5, 123]
    assert tx["velocity"].tolist() == [77, -9]
    assert tx["statusword"].tolist() == [0x1237, 0x0637]
    assert tx["torque"].tolist() == [-12, 0]  # absent on axis 1: its default
    assert tx["error_code"].tolist() == [0, 0]
    assert tx["mode_display"].tolist() == [8, 8]
    assert tx["digital_inputs"].tolist() == [0x10000, 0]
    assert img.present["torque"].tolist() == [True, False]
    assert img.present["torque_offset"].tolist() == [False, False]
    assert img.present["mode"].tolist() == [True, False]
    assert img.present["statusword"].all()


def test_drive_side_round_trip_keeps_what_the_drive_does_not_map():
    layouts = [ELMO, SPARSE, BUILTIN_LAYOUT]
    img = WireImage(layouts)
    m_rx, m_tx = _canonical(3, 2)
    img.bind_master(m_rx, m_tx)
    d_rx, d_tx = _canonical(3, 3)
    d_rx["mode"][1] = 8  # axis 1 got its mode by SDO: the wire must not overwrite it
    img.encode_rx()
    img.drive_rx(d_rx)
    for f in ("controlword", "target_position"):
        assert d_rx[f].tolist() == m_rx[f].tolist()
    assert d_rx["mode"][1] == 8
    assert d_rx["torque_offset"][2] == m_rx["torque_offset"][2]
    img.drive_tx(d_tx)
    img.decode_tx()
    for f in ("statusword", "position", "velocity"):
        assert m_tx[f].tolist() == d_tx[f].tolist()
    assert m_tx["torque"][1] == 0 and m_tx["torque"][0] == d_tx["torque"][0]


@pytest.mark.parametrize(
    ("layout", "message"),
    [
        (
            AxisLayout(rx=(E(0x6040, 0, 16), E(0x607A, 0, 32), E(0, 0, 4)), tx=SPARSE.tx),
            "not a whole number of bytes",
        ),
        (AxisLayout(rx=(E(0x6040, 0, 16), E(0x607A, 0, 16)), tx=SPARSE.tx), "is 32 bits"),
        (
            AxisLayout(rx=(E(0x6040, 0, 16), E(0x607A, 0, 32), E(0x6040, 0, 16)), tx=SPARSE.tx),
            "mapped twice",
        ),
        (
            AxisLayout(rx=(E(0x6040, 0, 16), E(0x607A, 0, 32), E(0x6041, 0, 16)), tx=SPARSE.tx),
            "other direction",
        ),
        (AxisLayout(rx=(E(0x607A, 0, 32),), tx=SPARSE.tx), "do not map controlword"),
        (AxisLayout(rx=SPARSE.rx, tx=(E(0x6041, 0, 16),)), "do not map position"),
    ],
)
def test_layouts_the_stack_cannot_run_are_refused_in_one_line(layout, message):
    with pytest.raises(LayoutError, match=message) as err:
        WireImage([BUILTIN_LAYOUT, layout], ["j1", "j2"])
    assert str(err.value).startswith("axis 1 (j2): ")
    assert "\n" not in str(err.value)


def test_six_mixed_axes_encode_and_decode_without_allocating():
    layouts = [ELMO, SPARSE, BUILTIN_LAYOUT, ELMO, SPARSE, BUILTIN_LAYOUT]
    img = WireImage(layouts)
    rx, tx = _canonical(6)
    img.bind_master(rx, tx)

    def run(k: int) -> tuple[int, int]:
        tracemalloc.start()
        before, _ = tracemalloc.get_traced_memory()
        for _ in range(k):
            img.encode_rx()
            img.decode_tx()
        after, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        return after - before, peak - before

    run(10)
    short, long = run(100), run(5000)
    # tracemalloc's own bookkeeping aside (a few dozen bytes), 4900 more cycles keep nothing
    assert long[0] - short[0] < 256
    assert long[1] < 4096
