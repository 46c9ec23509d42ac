"""The CSP adapter: controlword bit 4 for interpolated-position axes, the position loop over
streamed profile velocity, applied to a copy at the wire encode (the loop's record stays CSP)."""

from __future__ import annotations

import tracemalloc

import numpy as np

from drivers.cia402.csp_adapter import CW_ENABLE_IP, CspAdapter
from drivers.cia402.pdo import new_rx, new_tx
from drivers.cia402.state_machine import CW_ENABLE_OPERATION, CW_QUICK_STOP, Mode
from drivers.cia402.wire import BUILTIN_LAYOUT, AxisLayout, WireEntry, WireImage

OE = 0x0027  # statusword: Operation enabled
SO = 0x0023  # Switched on
DT = 0.005


def _images(n: int = 3):
    rx, tx = new_rx(n), new_tx(n)
    rx["controlword"] = CW_ENABLE_OPERATION
    tx["statusword"] = OE
    return rx, tx


def test_modes_the_loop_gets_for_csp():
    a = CspAdapter(["csp", "ip", "pv"], [None, None, 10.0], DT)
    assert a.csp_modes.tolist() == [Mode.CSP, Mode.INTERPOLATED_POSITION, Mode.PROFILE_VELOCITY]
    assert a.active and a.ip.tolist() == [False, True, False]
    assert not CspAdapter(["csp", "csv"], [None, None], DT).active


def test_ip_bit_only_while_enable_operation_in_operation_enabled():
    a = CspAdapter(["csp", "ip", "ip"], [None, None, None], DT)
    rx, tx = _images()
    tx["statusword"] = [OE, OE, SO]  # axis 2 is still switching on: no bit 4 yet
    a.apply(rx, tx)
    assert rx["controlword"].tolist() == [0x0F, 0x0F | CW_ENABLE_IP, 0x0F]
    rx["controlword"] = CW_QUICK_STOP  # any other command: the bit falls
    tx["statusword"] = OE
    a.apply(rx, tx)
    assert rx["controlword"].tolist() == [CW_QUICK_STOP] * 3


def test_pv_velocity_is_feed_forward_plus_gain_times_error_in_counts():
    gain = 10.0
    a = CspAdapter(["pv", "pv", "csp"], [gain, gain, None], DT)
    rx, tx = _images()
    tx["position"] = [1000, -500, 0]
    rx["target_position"] = [1000, -400, 7]
    a.apply(rx, tx)  # first enabled cycle: no feed-forward yet, the error only
    assert rx["target_velocity"].tolist() == [0, round(gain * 100), 0]
    rx["target_velocity"] = 0
    rx["target_position"] = [1050, -400, 7]  # +50 counts in one 5 ms cycle
    a.apply(rx, tx)
    assert rx["target_velocity"].tolist() == [round(50 / DT + gain * 50), round(gain * 100), 0]


def test_pv_velocity_zero_unless_enabled_and_restarts_without_a_jump():
    a = CspAdapter(["pv"], [10.0], DT)
    rx, tx = _images(1)
    tx["statusword"] = SO
    rx["target_position"] = 5000  # the target moved while the drive was off
    tx["position"] = 0
    a.apply(rx, tx)
    assert rx["target_velocity"][0] == 0
    tx["statusword"] = OE
    rx["target_position"] = 0
    a.apply(rx, tx)  # the 5000-count step of the disabled spell is no feed-forward
    assert rx["target_velocity"][0] == 0


def test_wire_encode_adapts_a_copy_not_the_loops_record():
    ip_layout = AxisLayout(
        rx=(WireEntry(0x6040, 0, 16), WireEntry(0x60C1, 1, 32), WireEntry(0x6060, 0, 8)),
        tx=(WireEntry(0x6041, 0, 16), WireEntry(0x6064, 0, 32)),
    )
    pv_layout = AxisLayout(
        rx=(WireEntry(0x6040, 0, 16), WireEntry(0x60FF, 0, 32), WireEntry(0x6060, 0, 8)),
        tx=(WireEntry(0x6041, 0, 16), WireEntry(0x6064, 0, 32)),
    )
    w = WireImage([ip_layout, pv_layout, BUILTIN_LAYOUT])
    rx, tx = _images()
    w.bind_master(rx, tx)
    w.set_adapter(CspAdapter(["ip", "pv", "csp"], [None, 10.0, None], DT))
    rx["target_position"] = [123456, 2000, 0]
    tx["position"] = [0, 1000, 0]
    w.encode_rx()
    ip = w.rx_slice(0)
    assert int.from_bytes(ip[0:2].tobytes(), "little") == 0x0F | CW_ENABLE_IP
    assert int.from_bytes(ip[2:6].tobytes(), "little", signed=True) == 123456  # 0x60C1:01
    pv = w.rx_slice(1)
    assert int.from_bytes(pv[2:6].tobytes(), "little", signed=True) == 10 * 1000  # 0x60FF
    assert rx["controlword"].tolist() == [0x0F] * 3  # the loop's own record: untouched
    assert rx["target_velocity"].tolist() == [0, 0, 0]
    np.testing.assert_array_equal(w.adapt_rx(), w._rx_head)  # in-process buses: same copy


def test_apply_allocates_nothing():
    a = CspAdapter(["ip", "pv", "csp"] * 2, [None, 10.0, None] * 2, DT)
    rx, tx = _images(6)
    for _ in range(3):
        a.apply(rx, tx)
    tracemalloc.start()
    before = tracemalloc.take_snapshot()
    for k in range(2000):
        rx["target_position"] = k
        a.apply(rx, tx)
    after = tracemalloc.take_snapshot()
    tracemalloc.stop()
    grown = sum(s.size_diff for s in after.compare_to(before, "filename") if s.size_diff > 0)
    assert grown < 4096, grown


def test_pv_velocity_in_rpm_scaled_before_rounding_and_read_back_in_counts():
    """A drive whose profile says rpm (3000 counts per motor revolution: 50 counts/s per rpm):
    the streamed 0x60FF is in rpm, the reported 0x606C is turned back into counts/s; a counts
    axis next to it is untouched."""
    a = CspAdapter(["pv", "pv"], [10.0, 10.0], DT, [(50.0, 50.0), (1.0, 1.0)])
    assert a.active and a.scaled.tolist() == [True, False]
    assert a.accel_unit.tolist() == [50.0, 1.0]
    rx, tx = _images(2)
    tx["position"] = [0, 0]
    rx["target_position"] = [0, 0]
    a.apply(rx, tx)
    rx["target_position"] = [60, 60]  # 60 counts in 5 ms: 12000 counts/s + 10/s x 60
    a.apply(rx, tx)
    assert rx["target_velocity"].tolist() == [round(12600 / 50.0), 12600]
    tx["velocity"] = [252, 12600]  # what the drives report: rpm, counts/s
    a.decode(tx)
    assert tx["velocity"].tolist() == [12600, 12600]


def test_csv_target_velocity_in_rpm():
    a = CspAdapter(["csv", "csv"], [None, None], DT, [(50.0, 1.0), (1.0, 1.0)])
    rx, tx = _images(2)
    rx["target_velocity"] = [5000, 5000]
    a.apply(rx, tx)
    assert rx["target_velocity"].tolist() == [100, 5000]


def test_wire_decode_turns_rpm_back_into_counts():
    lay = AxisLayout(rx=BUILTIN_LAYOUT.rx, tx=BUILTIN_LAYOUT.tx)
    w = WireImage([lay, lay], ["a", "b"])
    rx, tx = new_rx(2), new_tx(2)
    w.bind_master(rx, tx)
    w.set_adapter(CspAdapter(["csp", "csp"], [None, None], DT, [(50.0, 50.0), (1.0, 1.0)]))
    drive_tx = new_tx(2)
    drive_tx["velocity"] = [-30, -30]
    w.drive_tx(drive_tx)
    w.decode_tx()
    assert tx["velocity"].tolist() == [-1500, -30]
