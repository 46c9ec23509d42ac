"""StopController: latch in the detecting tick, most severe category wins, explicit reset."""

from __future__ import annotations

from hofto_hw.config.safety import StopCategories
from safety.stop import EventKind, Fault, StopController


def _stop() -> StopController:
    return StopController.from_config(StopCategories())


def test_first_report_latches_and_commands_in_the_same_tick() -> None:
    s = _stop()
    s.begin_tick(7)
    assert s.category == -1
    s.report(Fault.COLLISION, 1, 1.5)
    assert s.category == 1 and s.first_tick == 7 and s.is_latched(Fault.COLLISION)
    assert s.events.count == 1 and s.events.kind[0] == Fault.COLLISION
    assert s.events.tick[0] == 7 and s.events.joint[0] == 1 and s.events.category[0] == 1
    s.report(Fault.COLLISION, 1, 2.0)  # still present: no second event
    assert s.events.count == 1


def test_most_severe_category_wins_and_never_relaxes() -> None:
    s = _stop()
    s.begin_tick(1)
    s.report(Fault.COLLISION)  # 1
    s.report(Fault.BUS_LOSS)  # 0
    assert s.category == 0
    s.begin_tick(2)
    s.report(Fault.OVERRUN)  # 1: does not relax the stop
    assert s.category == 0


def test_report_only_class_latches_without_stopping() -> None:
    s = _stop()
    s.begin_tick(1)
    s.report(Fault.LOG_FAILURE)
    assert s.is_latched(Fault.LOG_FAILURE) and s.category == -1 and s.events.count == 1


def test_reset_refuses_while_the_cause_persists() -> None:
    s = _stop()
    s.begin_tick(1)
    s.report(Fault.DRIVE_FAULT, 2, 0x4310)
    s.begin_tick(2)
    s.report(Fault.DRIVE_FAULT, 2, 0x4310)
    done, msg = s.reset()
    assert not done and msg == "reset refused, cause still present: drive_fault"
    assert s.category == 0
    s.begin_tick(3)  # the cause was reported in tick 2: still refused
    assert not s.reset()[0]
    s.begin_tick(4)  # not reported in tick 3: gone
    done, msg = s.reset()
    assert done and msg == "reset: drive_fault"
    assert s.latched == 0 and s.category == -1
    assert s.events.kind[s.events.count - 1] == EventKind.RESET


def test_every_fault_class_has_a_config_field() -> None:
    cats = StopCategories()
    for f in Fault:
        assert hasattr(cats, f.name.lower())
