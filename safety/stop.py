"""Fault classes, stop categories and the StopController (safety decides, the loop acts).

Every fault class has one stop category from config (IEC 60204-1): 0 = remove power now,
1 = controlled stop (drive quick-stop ramp) then remove power, 2 = controlled stop with power
kept (ramp to standstill, hold). ``None`` in config makes a class report-only.

The StopController is told every tick which fault causes are present
(:meth:`StopController.report`). The first report of a class latches it and records an event
in the same tick; :attr:`StopController.category` is then the most severe category of all
latched classes (0 < 1 < 2), so the loop commands the stop in the tick that detected it.
Latches clear only by an explicit :meth:`StopController.reset`, which refuses while any
latched cause was still reported in the last tick. Allocation-free per tick.
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np


class Fault(IntEnum):
    """Fault classes; the value is the bit in the latched mask and the event kind code."""

    COLLISION = 0
    POSITION_LIMIT = 1
    VELOCITY_LIMIT = 2
    TORQUE_LIMIT = 3
    FOLLOWING_ERROR = 4
    POSITION_JUMP = 5
    NON_FINITE = 6
    BUS_LOSS = 7
    DRIVE_FAULT = 8
    DRIVE_DISABLED = 9
    OVERRUN = 10
    STOP_REQUEST = 11
    LOG_FAILURE = 12
    ENABLING_RELEASED = 13  # hand guiding: the enabling input let go while dragging
    STO = 14  # safe torque off became active on an axis that was enabled (or enabling)
    BRAKE = 15  # a holding brake: the drive's brake fault code, or a joint moved as it opened


class EventKind(IntEnum):
    """Event kinds that are not faults (codes above every Fault)."""

    CONTACT = 100  # a contact-level crossing (reported, clears itself)
    RESET = 101  # the latched faults were reset
    STANDSTILL = 102  # the arm came to rest after a stop
    PROFILE = 103  # a safety profile became active (joint: its index, value: collision scale)
    PAYLOAD = 104  # a payload became active: joint -1 its mass [kg]; 0, 1, 2 its com x, y, z [m]


#: Fault -> name used in config (``safety.categories``), events and messages
FAULT_NAMES: dict[int, str] = {int(f): f.name.lower() for f in Fault}
EVENT_NAMES: dict[int, str] = {**FAULT_NAMES, **{int(e): e.name.lower() for e in EventKind}}
N_FAULTS = len(Fault)
NO_CATEGORY = -1


def commanded(current: int, cat: int) -> int:
    """The stop category commanded once a fault of category ``cat`` latches while ``current``
    is commanded (NO_CATEGORY: none; ``cat`` NO_CATEGORY: report only): the stronger, i.e.
    the lower, of the two. The one place of this rule: StopController.report and the tick's
    compiled section 4 (hofto_hw/runtime/fused.py, its copy of the stop's state) call it."""
    if cat == NO_CATEGORY or (current != NO_CATEGORY and current <= cat):
        return current
    return cat


def kind_name(kind: int) -> str:
    """Name of an event kind code (fault class or other event)."""
    return EVENT_NAMES.get(int(kind), f"kind {int(kind)}")


class EventLog:
    """Fixed-size ring of safety events (tick, kind, joint, category, value); no allocation.

    ``count`` grows for ever; entry ``i`` (0 <= count - i <= capacity) is at ``i % capacity``.
    """

    def __init__(self, capacity: int = 1024) -> None:
        self.capacity = capacity
        self.tick = np.zeros(capacity, dtype=np.int64)
        self.kind = np.zeros(capacity, dtype=np.int32)
        self.joint = np.zeros(capacity, dtype=np.int32)
        self.category = np.zeros(capacity, dtype=np.int32)
        self.value = np.zeros(capacity)
        self.count = 0

    def add(self, tick: int, kind: int, joint: int, category: int, value: float) -> None:
        i = self.count % self.capacity
        self.tick[i] = tick
        self.kind[i] = kind
        self.joint[i] = joint
        self.category[i] = category
        self.value[i] = value
        self.count += 1

    def copy(self, i: int, rec: np.ndarray, t: float) -> None:
        """Entry ``i`` into the 0-d record ``rec`` (fields t, tick, kind, joint, category,
        value: the flight log's and the control plane's event record) at loop time ``t`` [s]."""
        j = i % self.capacity
        rec["t"] = t
        rec["tick"] = self.tick[j]
        rec["kind"] = self.kind[j]
        rec["joint"] = self.joint[j]
        rec["category"] = self.category[j]
        rec["value"] = self.value[j]


class StopController:
    """Latches faults and tells the loop which stop category to act (see module docstring).

    ``categories``: one entry per :class:`Fault` (0, 1, 2 or None = report only), in Fault
    order. Public state: ``latched`` / ``active`` (bit masks over Fault), ``category`` (int,
    -1 = run), ``first_tick`` (tick of the latch that started the current stop, -1 = none),
    ``events`` (:class:`EventLog`).
    """

    def __init__(self, categories: list[int | None]) -> None:
        if len(categories) != N_FAULTS:
            raise ValueError(f"need {N_FAULTS} categories, got {len(categories)}")
        self.categories = np.array(
            [NO_CATEGORY if c is None else int(c) for c in categories], dtype=np.int64
        )
        self._cat = [int(c) for c in self.categories]  # plain ints for the tick
        self.latched = 0
        self.active = 0
        self._active_next = 0
        self.category = NO_CATEGORY
        self.first_tick = -1
        self.tick = 0
        self.events = EventLog()

    @classmethod
    def from_config(cls, categories: object) -> StopController:
        """From a :class:`hofto_hw.config.safety.StopCategories`."""
        return cls([getattr(categories, FAULT_NAMES[int(f)]) for f in Fault])

    def begin_tick(self, tick: int) -> None:
        """Start tick ``tick``: the causes reported during the last tick become ``active``."""
        self.tick = tick
        self.active = self._active_next
        self._active_next = 0

    def report(self, fault: int, joint: int = -1, value: float = 0.0) -> None:
        """The cause of ``fault`` is present this tick (on ``joint``, with ``value``).

        Latches it (and records an event) the first time; the commanded category follows
        at once.
        """
        bit = 1 << fault
        self._active_next |= bit
        self.active |= bit
        if self.latched & bit:
            return
        self.latched |= bit
        cat = self._cat[fault]
        self.events.add(self.tick, fault, joint, cat, value)
        if cat != NO_CATEGORY and self.category == NO_CATEGORY:
            self.first_tick = self.tick
        self.category = commanded(self.category, cat)

    def note(self, kind: int, joint: int = -1, value: float = 0.0) -> None:
        """Record a non-fault event (contact, standstill) this tick."""
        self.events.add(self.tick, kind, joint, NO_CATEGORY, value)

    def is_latched(self, fault: int) -> bool:
        return bool(self.latched & (1 << fault))

    def stopping(self) -> bool:
        """True while a stop (category 0, 1 or 2) is latched."""
        return self.category != NO_CATEGORY

    def persisting(self) -> list[str]:
        """Names of latched faults whose cause was reported in the last tick (slow path)."""
        both = self.latched & self.active
        return [FAULT_NAMES[f] for f in range(N_FAULTS) if both & (1 << f)]

    def latched_names(self) -> list[str]:
        """Names of the latched fault classes (slow path)."""
        return [FAULT_NAMES[f] for f in range(N_FAULTS) if self.latched & (1 << f)]

    def reset(self) -> tuple[bool, str]:
        """Clear every latch unless a latched cause persists; returns (done, message)."""
        if not self.latched:
            return True, "nothing latched"
        still = self.persisting()
        if still:
            return False, "reset refused, cause still present: " + ", ".join(still)
        names = ", ".join(self.latched_names())
        self.latched = 0
        self.category = NO_CATEGORY
        self.first_tick = -1
        self.events.add(self.tick, EventKind.RESET, -1, NO_CATEGORY, 0.0)
        return True, f"reset: {names}"
