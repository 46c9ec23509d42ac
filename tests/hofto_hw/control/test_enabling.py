"""The enabling state machine: entered only on a press from standstill without a latched
fault; a release while dragging is a category 2 stop request."""

from __future__ import annotations

from hofto_hw.control.enabling import EnableEvent, EnableInput, EnableState, Enabling


def test_press_from_standstill_enters_release_stops() -> None:
    e = Enabling()
    assert e.update(False, True, False) == EnableEvent.NONE
    assert e.update(True, True, False) == EnableEvent.ENTERED
    assert e.state == EnableState.ACTIVE
    assert e.update(True, False, False) == EnableEvent.NONE
    assert e.update(False, False, False) == EnableEvent.RELEASED
    assert e.state == EnableState.STOPPING
    assert e.update(False, False, False) == EnableEvent.NONE  # still moving
    assert e.update(False, True, False) == EnableEvent.STANDSTILL
    assert e.state == EnableState.READY


def test_refused_while_moving_or_faulted_and_needs_a_new_press() -> None:
    e = Enabling()
    assert e.update(True, False, False) == EnableEvent.REFUSED_MOTION
    assert e.update(True, True, False) == EnableEvent.NONE  # held: no new edge
    assert e.state == EnableState.READY
    e.update(False, True, False)
    assert e.update(True, True, True) == EnableEvent.REFUSED_FAULT
    e.update(False, True, False)
    assert e.update(True, True, False) == EnableEvent.ENTERED


def test_fault_while_dragging_leaves_active() -> None:
    e = Enabling()
    e.update(True, True, False)
    assert e.update(True, False, True) == EnableEvent.FAULT
    assert e.state == EnableState.STOPPING
    # held through the fault: no way back to READY until released
    assert e.update(True, True, False) == EnableEvent.NONE
    assert e.state == EnableState.STOPPING


def test_digital_input_bit() -> None:
    src = EnableInput("digital_input", bit=17)
    assert not src.from_word(1 << 16)
    assert src.from_word((1 << 17) | (1 << 16))


def test_input_from_config() -> None:
    from hofto_hw.config.drag import EnableInputConfig

    src = EnableInput.from_config(EnableInputConfig(source="digital_input", axis=2, bit=20))
    assert src.axis == 2 and src.from_word(1 << 20) and not src.from_word(1 << 17)
