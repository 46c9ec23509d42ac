"""The emulated network's frame handling and control requests, in-process (no sockets)."""

from __future__ import annotations

import struct

import numpy as np
from esc_helpers import make_desc

from drivers.sim.esc import datagram as dg
from drivers.sim.esc import registers as r
from drivers.sim.esc.network import EmulatedNetwork


def _brd() -> bytearray:
    body = struct.pack("<BBHHHH", dg.BRD, 0, 0, r.TYPE, 2, 0) + bytes(4)
    eth = b"\xff" * 6 + b"\x01" * 6 + b"\x88\xa4"
    return bytearray(eth + struct.pack("<H", len(body) | 0x1000) + body)


def _wkc(frame: bytearray) -> int:
    return dg.describe_frame(bytes(frame))[0][4]


def test_drop_and_corrupt_requests_apply_to_the_next_frames() -> None:
    net = EmulatedNetwork([make_desc() for _ in range(3)], None)
    assert net.control({"op": "drop", "count": 1}) == {"ok": True}
    assert not net.handle(_brd(), len(_brd()))
    frame = _brd()
    assert net.handle(frame, len(frame))
    assert _wkc(frame) == 3
    assert frame[6] & 0x02, "the reply's source MAC is marked by port 0"
    net.control({"op": "corrupt", "count": 1, "slave": 1})
    frame = _brd()
    assert net.handle(frame, len(frame))
    assert _wkc(frame) == 1
    status = net.control({"op": "status"})
    assert (status["frames"], status["dropped"], status["corrupted"]) == (3, 1, 1)


def test_silence_restart_and_al_error_requests() -> None:
    net = EmulatedNetwork([make_desc() for _ in range(3)], None)
    net.control({"op": "silence", "slave": 2, "on": True})
    frame = _brd()
    net.handle(frame, len(frame))
    assert _wkc(frame) == 2
    net.slaves[0].write(r.STATION_ADDRESS, b"\x01\x10")
    net.control({"op": "restart", "slave": 0})
    assert net.slaves[0].station_address == 0
    net.control({"op": "al_error", "slave": 1, "code": 0x001A})
    assert net.control({"op": "status"})["al_status_code"] == [0, 0x001A, 0]


def test_bad_requests_are_answered_with_the_reason() -> None:
    net = EmulatedNetwork([make_desc()], None)
    reply = net.control({"op": "silence", "slave": 5})
    assert not reply["ok"] and "slave 5 does not exist" in reply["error"]
    assert "unknown op" in net.control({"op": "explode"})["error"]
    assert "no drives" in net.control({"op": "drive_fault", "slave": 0, "code": 0x2310})["error"]


def test_malformed_frames_are_counted_and_not_answered() -> None:
    net = EmulatedNetwork([make_desc()], None)
    frame = bytearray(_brd()[:20])
    assert not net.handle(frame, len(frame))
    assert net.malformed == 1


def test_a_trace_records_the_true_arm_at_every_plant_step(er3a_config) -> None:
    """``trace`` (and ``push`` with ``trace``) record t, q, qd at every plant step for the
    asked time, whatever the client's polling; ``trace_read`` returns them."""
    from hofto_hw.runtime.build import build_emulated_network

    net = build_emulated_network(er3a_config)
    dt = net.drives.dt
    reply = net.control(
        {"op": "push", "force": [5.0, 0, 0], "duration": 0.01, "ramp": 0.002, "trace": 0.02}
    )
    assert reply["ok"]
    t0 = reply["t"]
    for _ in range(10):
        net.step()
    partial = net.control({"op": "trace_read"})
    assert partial["ok"] and not partial["done"] and len(partial["t"]) == 10
    for _ in range(30):
        net.step()
    tr = net.control({"op": "trace_read"})
    assert tr["done"]
    t = np.array(tr["t"])
    np.testing.assert_allclose(np.diff(t), dt, rtol=1e-9)  # every step, none twice
    assert t[0] > t0 and t[-1] <= t0 + 0.02 + 1e-12 and t[-1] > t0 + 0.02 - dt
    assert np.array(tr["q"]).shape == (len(t), net.n) == np.array(tr["qd"]).shape
    assert net.drives.plant.t > t[-1] + 5 * dt  # the plant went on, the trace did not
    for bad in (0.0, -1.0, float("nan"), 61.0):
        assert "trace seconds" in net.control({"op": "trace", "seconds": bad})["error"]
    assert (
        "no drives" in EmulatedNetwork([make_desc()], None).control({"op": "trace_read"})["error"]
    )


def test_restart_takes_the_drives_start_up_values_and_pdo_configuration_with_the_power(
    er3a_config,
) -> None:
    from hofto_hw.runtime.build import build_emulated_network

    net = build_emulated_network(er3a_config)
    od = net.slaves[1].od
    mode, count = od.get(0x6060), od.get(0x1600, 0)
    od.write(0x6060, 0, bytes([10]))  # a start-up SDO: CST
    od.write(0x1600, 0, b"\x00")  # a PDO being remapped
    other = net.slaves[2].od
    other.write(0x6060, 0, bytes([10]))
    net.control({"op": "restart", "slave": 1})
    assert net.slaves[1].od is od  # the same drive, powered on again
    assert (od.get(0x6060), od.get(0x1600, 0)) == (mode, count) != (10, 0)
    assert other.get(0x6060) == 10  # the others keep theirs
