"""The enabling input of hand guiding as a small state machine (IEC 60204-1 / ISO 10218-1:
motion only while an enabling device is held).

States: READY (mode on, waiting for a press), ACTIVE (dragging), STOPPING (released or
refused motion: waiting for standstill). A press is a rising edge of the input; it enters
ACTIVE only from standstill and only with no latched fault, otherwise it is refused (and
must be released and pressed again). A release while ACTIVE is a stop request of category 2
(hold): the machine reports it, the caller's stop controller acts. Allocation-free.

Input sources (``drag.enable_input.source``): a bit of a drive's digital inputs 0x60FD
(:meth:`EnableInput.from_word`), a simulation script or the control socket
(:meth:`EnableInput.set`, one writer).
"""

from __future__ import annotations

from enum import IntEnum


class EnableState(IntEnum):
    READY = 0
    ACTIVE = 1
    STOPPING = 2


class EnableEvent(IntEnum):
    """What :meth:`Enabling.update` reports for this tick."""

    NONE = 0
    ENTERED = 1  # press accepted: dragging
    RELEASED = 2  # released while dragging: category 2 stop request
    REFUSED_MOTION = 3  # press while the arm moves
    REFUSED_FAULT = 4  # press with a latched fault
    FAULT = 5  # a fault latched while dragging (the stop controller acts already)
    STANDSTILL = 6  # stopping finished


_READY, _ACTIVE, _STOPPING = 0, 1, 2


class EnableInput:
    """The enabling input: ``pressed`` (bool). ``bit`` for 0x60FD words."""

    def __init__(self, source: str = "scripted", bit: int = 17, axis: int = 0) -> None:
        self.source = source
        self.mask = 1 << bit
        self.axis = axis
        self.pressed = False

    @classmethod
    def from_config(cls, cfg: object) -> EnableInput:
        """From a :class:`hofto_hw.config.drag.EnableInputConfig`."""
        return cls(cfg.source, cfg.bit, cfg.axis)  # type: ignore[attr-defined]

    def set(self, pressed: bool) -> None:
        """Scripted / control-socket source: the operator holds (True) or releases."""
        self.pressed = bool(pressed)

    def from_word(self, digital_inputs: int) -> bool:
        """Digital-input source: take the configured bit of drive ``axis``'s 0x60FD word."""
        self.pressed = (int(digital_inputs) & self.mask) != 0
        return self.pressed


class Enabling:
    """The state machine of the module docstring; ``state`` and the last ``event``."""

    def __init__(self) -> None:
        self.state = _READY
        self.event = 0
        self._was_pressed = False

    def reset(self) -> None:
        self.state = _READY
        self.event = 0
        self._was_pressed = False

    def update(self, pressed: bool, standstill: bool, fault_latched: bool) -> int:
        """One tick: the input, whether every joint is at rest, whether a fault is latched.
        Returns the :class:`EnableEvent` code of this tick."""
        edge = pressed and not self._was_pressed
        self._was_pressed = pressed
        ev = 0
        s = self.state
        if s == _READY:
            if edge:
                if fault_latched:
                    ev = 4
                elif not standstill:
                    ev = 3
                else:
                    self.state = _ACTIVE
                    ev = 1
        elif s == _ACTIVE:
            if fault_latched:
                self.state = _STOPPING
                ev = 5
            elif not pressed:
                self.state = _STOPPING
                ev = 2
        elif standstill and not pressed:
            self.state = _READY
            ev = 6
        self.event = ev
        return ev

    @property
    def active(self) -> bool:
        return self.state == _ACTIVE
