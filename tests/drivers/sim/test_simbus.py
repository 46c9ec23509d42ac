"""SimBus: the in-process transport over the emulated drives and the plant."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.sim.simbus import SimBus
from drivers.transport import (
    STATUS_NO_RESPONSE,
    STATUS_NOT_OPEN,
    STATUS_OK,
    SdoAbortError,
    TransportError,
)
from hofto_hw.config.models import SystemConfig
from hofto_hw.runtime.build import build_sim_bus


def test_exchange_needs_open_and_advances_one_tick(bus: SimBus) -> None:
    t0 = bus.plant.t
    assert bus.exchange() == STATUS_NOT_OPEN
    assert bus.plant.t == t0
    with bus:
        assert bus.exchange() == STATUS_OK
        assert bus.plant.t == pytest.approx(t0 + bus.cycle_time)
        assert bus.cycle_time == 0.001
    assert bus.exchange() == STATUS_NOT_OPEN  # closed by the context manager


def test_tx_is_a_copy_of_the_drives_image(bus: SimBus) -> None:
    with bus:
        bus.exchange()
        assert bus.tx.tobytes() == bus.drives.tx.tobytes()
        assert bus.tx is not bus.drives.tx  # the master's image is its own


def test_dropped_frames_keep_tx_and_report_no_response(bus: SimBus) -> None:
    with bus:
        bus.rx["controlword"] = 0x0006
        bus.exchange()  # not ready -> switch on disabled (automatic)
        bus.exchange()  # shutdown -> ready to switch on
        before = bus.tx.copy()
        bus.rx["controlword"] = 0x0007  # would change the state if delivered
        bus.drop_cycles(2)
        t0 = bus.plant.t
        assert [bus.exchange(), bus.exchange()] == [STATUS_NO_RESPONSE] * 2
        assert bus.plant.t == pytest.approx(t0 + 2 * bus.cycle_time)  # time goes on
        assert bus.tx.tobytes() == before.tobytes()
        assert bus.exchange() == STATUS_OK
        assert bus.tx["statusword"][0] & 0x6F == 0x23  # switched on once delivered


def test_sdo_errors_name_axis_object_and_decoded_abort(bus: SimBus) -> None:
    assert bus.read_value(0, 0x1018, 1, "u32") == 0xDEC
    with pytest.raises(SdoAbortError) as e:
        bus.sdo_write(4, 0x6041, 0, b"\x00\x00")
    msg = str(e.value)
    assert msg == (
        "axis 4 (joint_5): SDO write 0x6041:00 aborted: "
        "0x06010002 attempt to write a read-only object"
    )
    assert e.value.code == 0x06010002 and e.value.axis == 4
    with pytest.raises(SdoAbortError, match=r"SDO read 0x2345:00 .*does not exist"):
        bus.sdo_read(1, 0x2345, 0)
    with pytest.raises(TransportError, match="axis 6 does not exist"):
        bus.sdo_read(6, 0x1000, 0)


def test_typed_sdo_helpers(bus: SimBus) -> None:
    bus.write_value(2, 0x6072, 0, "u16", 1234)
    assert bus.read_value(2, 0x6072, 0, "u16") == 1234
    bus.write_value(2, 0x605A, 0, "i16", 6)
    assert bus.read_value(2, 0x605A, 0, "i16") == 6
    with pytest.raises(TransportError, match=r"value 70000 does not fit object 0x6072:00 \(u16\)"):
        bus.write_value(2, 0x6072, 0, "u16", 70000)


def test_inject_fault_reaches_the_drive(bus: SimBus) -> None:
    with bus:
        bus.inject_fault(1, "encoder")
        for _ in range(3):
            bus.exchange()
        assert bus.tx["error_code"][1] == 0x7305
        assert np.count_nonzero(bus.tx["error_code"]) == 1
    with pytest.raises(ValueError, match="unknown fault 'bogus'"):
        bus.inject_fault(0, "bogus")


def test_the_bus_cycles_at_the_loop_rate(cfg: SystemConfig) -> None:
    # loop.rate_hz is the only cycle time in a config (bus.cycle_time could disagree with it)
    slow = cfg.model_copy(update={"loop": cfg.loop.model_copy(update={"rate_hz": 500.0})})
    bus = build_sim_bus(slow, external=False)
    assert bus.cycle_time == bus.plant.dt == pytest.approx(0.002)
    with bus:
        t0 = bus.plant.t
        bus.exchange()
        assert bus.plant.t == pytest.approx(t0 + 0.002)


def test_wait_next_cycle_does_not_sleep(bus: SimBus) -> None:
    import time

    t0 = time.perf_counter()
    for _ in range(1000):
        bus.wait_next_cycle()
    assert time.perf_counter() - t0 < 0.5  # 1000 real cycles would take 1 s
