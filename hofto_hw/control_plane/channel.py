"""The shared-memory segment between the loop and the control-plane process (created,
reserved, named and cleaned up by hofto_hw.recording.shared.Segment, as the recorder's).

Every word, ring counter and slot has exactly one writer, so neither side locks or waits:

- ``ctl`` (int64 words, :data:`CTL_WORDS`): the control plane writes ``STOP_SEQ`` (one more
  per operator stop), ``LEASE_NS`` (CLOCK_MONOTONIC deadline [ns] of the remote enabling
  input; 0: released), the plan words ``PLAN_ID``, ``PLAN_ROWS``, ``PLAN_HEAD``, ``CP_PID``,
  ``CP_BEAT``; the loop writes ``STOP_ACK``, ``TICKS``, ``EXIT``, ``LOOP_DONE``,
  ``PLAN_TAIL_ID``, ``PLAN_TAIL``, ``TEACH_STATE``, ``STATE_SEQ``.
- the stop server (:mod:`~hofto_hw.control_plane.stop_server`, a process of its own) writes
  ``STOP_FAST_SEQ`` (one more per stop on the stop socket) and ``STOP_PID``; the loop
  acknowledges it in ``STOP_FAST_ACK`` in the poll that sets its stop request. A word of its
  own, not ``STOP_SEQ``: two processes incrementing one word could lose a stop.
- ``fctl`` (float64 words): the control plane writes the timing percentiles the diagnostics
  records carry (``WAKE_P99``, ``COMP_P99``).
- ``requests`` (control plane -> loop) and ``replies`` (loop -> control plane): rings of
  fixed records (:data:`REQUEST_DTYPE`, :data:`REPLY_DTYPE`); ``events`` (loop -> control
  plane): the stop controller's events (``hofto_hw.recording.record.EVENT_DTYPE``);
  ``taught`` (loop -> control plane): (t, q) samples of a taught path being recorded.
- the plan: ``plan_q``, ``plan_qd``, ``plan_qdd`` (``PLAN_CAP`` rows of n) filled by the
  control plane ahead of the loop (row r in slot r mod PLAN_CAP, published by ``PLAN_HEAD``,
  released by ``PLAN_TAIL``), ``plan_start`` (n): the plan's first row, ``plan_accel`` (n):
  the acceleration limits [rad/s²] it was planned within (a starved plan ramps down at
  them).
- the state slot (a seqlock: ``STATE_SEQ`` odd while the loop writes it): the tick record of
  the last tick and ``extra`` (float64 words ``X_*``, then the per-axis words: from
  :data:`X_WORDS` safe torque off per axis (1.0 active), from ``X_WORDS + n`` the holding
  brake per axis (:data:`BRAKE_CLOSED`, :data:`BRAKE_OPEN`, :data:`BRAKE_UNKNOWN`)).
- ``wakeup_counts``, ``compute_counts``: the loop's timing histograms (1 µs bins,
  hofto_hw/runtime/timing.py), read by the control plane for ``status``.
"""

from __future__ import annotations

import numpy as np

from hofto_hw.recording.record import EVENT_DTYPE, tick_dtype
from hofto_hw.recording.ring import Ring, ring_nbytes
from hofto_hw.recording.shared import Segment, remove_stale
from hofto_hw.runtime.axes import BRAKE_CLOSED, BRAKE_OPEN, BRAKE_UNKNOWN

__all__ = ["BRAKE_CLOSED", "BRAKE_OPEN", "BRAKE_UNKNOWN", "Channel"]

CTL_WORDS = 64
(STOP_SEQ, STOP_ACK, LEASE_NS, PLAN_ID, PLAN_ROWS, PLAN_HEAD, PLAN_TAIL_ID, PLAN_TAIL,
 TICKS, EXIT, LOOP_DONE, TEACH_STATE, STATE_SEQ, CP_PID, CP_BEAT,
 EVENTS_LOST, LOG_FAILING, LOG_LOST, STOP_FAST_SEQ, STOP_FAST_ACK,
 STOP_PID) = range(21)  # fmt: skip
F_WORDS = 8
WAKE_P99, COMP_P99 = range(2)

#: extra state words (float64) beside the tick record in the state slot
X_WORDS = 32
(X_CATEGORY, X_ACTIVE, X_STOPPING, X_ENABLING, X_EXIT, X_OVERRUNS, X_LOOP_TICKS, X_DRAG_ACTIVE,
 X_PRESSED, X_PLAN_ID, X_PLAN_K, X_PLAN_DONE, X_TEACH_STATE, X_TEACH_SAMPLES, X_WAKE_MAX,
 X_COMP_MAX, X_HAS_PATH, X_HAS_DRAG, X_ENABLE_SOURCE, X_PLAYING_KIND, X_STOP_REQUESTED,
 X_MOVING, X_PROFILE, X_ACCEL) = range(24)  # fmt: skip

#: X_ACCEL bits: what the tick runs (hofto_hw.runtime.acceleration.report), set once
ACCEL_COMPILED, ACCEL_NUMBA, ACCEL_NATIVE, ACCEL_HAS_FUSED, ACCEL_FUSED = 1, 2, 4, 8, 16

#: enabling-input source codes (X_ENABLE_SOURCE)
SOURCES = ("scripted", "digital_input", "socket")

#: request kinds (REQUEST_DTYPE.kind)
REQ_RESET, REQ_MODE, REQ_PLAY, REQ_PROFILE, REQ_PAYLOAD = 1, 2, 3, 4, 5
#: homing (arg: bit mask of the axes, homed in order) and a new zero offset (arg: the axis,
#: value[0]: its new zero offset [counts], value[1]: the one the request was computed with)
REQ_HOME, REQ_ZERO = 6, 7
#: REQ_PAYLOAD's ``value``: mass [kg], com (3) [m], then the tool link's new inertia (10
#: numbers, hofto_hw.model.payload.LINK_NUMBERS) the control plane computed;
#: REQ_PROFILE's: collision scale, drag mass, damping and speed scales
VALUE_WORDS = 16
REQUEST_DTYPE = np.dtype(
    [
        ("seq", "<u8"),
        ("kind", "<i4"),
        ("mode", "<i4"),
        ("arg", "<i8"),
        ("flag", "<i4"),
        ("value", "<f8", (VALUE_WORDS,)),
    ]
)
#: reply codes (REPLY_DTYPE.code): 1 ok, 0 refused
REPLY_DTYPE = np.dtype([("seq", "<u8"), ("code", "<i4"), ("text", "S200")])

PLAN_CAP = 4096  # rows (4 s at 1 kHz): the control plane keeps the ring ahead of the loop
RING_CAP = 64
EVENT_CAP = 256
TAUGHT_CAP = 8192
HIST_BINS = 20001  # hofto_hw.runtime.timing.Histogram's default max_us + 1


def taught_dtype(n: int) -> np.dtype:
    return np.dtype([("t", "<f8"), ("q", "<f8", (n,))])


class Channel:
    """The segment seen from one side (``create=True``: the loop's owner makes and later
    unlinks it; else attach to ``name``). ``n`` joints, ``k`` observer rows."""

    def __init__(self, n: int, k: int, *, name: str | None = None, create: bool = False) -> None:
        self.n, self.k = int(n), int(k)
        self.rec_dtype = tick_dtype(n, k)
        sizes = [
            ("ctl", CTL_WORDS * 8),
            ("fctl", F_WORDS * 8),
            ("requests", ring_nbytes(REQUEST_DTYPE, RING_CAP)),
            ("replies", ring_nbytes(REPLY_DTYPE, RING_CAP)),
            ("events", ring_nbytes(EVENT_DTYPE, EVENT_CAP)),
            ("taught", ring_nbytes(taught_dtype(n), TAUGHT_CAP)),
            ("plan_q", PLAN_CAP * n * 8),
            ("plan_qd", PLAN_CAP * n * 8),
            ("plan_qdd", PLAN_CAP * n * 8),
            ("plan_start", n * 8),
            ("plan_accel", n * 8),
            ("state_rec", _round8(self.rec_dtype.itemsize)),
            ("extra", (X_WORDS + 2 * n) * 8),
            ("wakeup_counts", HIST_BINS * 8),
            ("compute_counts", HIST_BINS * 8),
        ]
        total = sum(s for _, s in sizes)
        if create:
            remove_stale()  # segments of killed runs (a run with --no-log starts no recorder)
        self.segment = Segment(
            total,
            name=name,
            create=create,
            what="the control plane's shared memory",
            hint="free space there",
        )
        self.shm = self.segment.shm
        self.owner = create
        buf = self.shm.buf
        off = {}
        o = 0
        for key, size in sizes:
            off[key] = o
            o += size
        self.ctl = np.ndarray((CTL_WORDS,), "<i8", buf, off["ctl"])
        self.fctl = np.ndarray((F_WORDS,), "<f8", buf, off["fctl"])
        self.requests = Ring(buf, off["requests"], REQUEST_DTYPE, RING_CAP, init=create)
        self.replies = Ring(buf, off["replies"], REPLY_DTYPE, RING_CAP, init=create)
        self.events = Ring(buf, off["events"], EVENT_DTYPE, EVENT_CAP, init=create)
        self.taught = Ring(buf, off["taught"], taught_dtype(n), TAUGHT_CAP, init=create)
        self.plan_q = np.ndarray((PLAN_CAP, n), "<f8", buf, off["plan_q"])
        self.plan_qd = np.ndarray((PLAN_CAP, n), "<f8", buf, off["plan_qd"])
        self.plan_qdd = np.ndarray((PLAN_CAP, n), "<f8", buf, off["plan_qdd"])
        self.plan_start = np.ndarray((n,), "<f8", buf, off["plan_start"])
        self.plan_accel = np.ndarray((n,), "<f8", buf, off["plan_accel"])
        if create:
            self.plan_accel[:] = np.inf  # until a plan says: the robot's limits
        self.state_rec = np.ndarray((), self.rec_dtype, buf, off["state_rec"])
        self.extra = np.ndarray((X_WORDS + 2 * n,), "<f8", buf, off["extra"])
        #: per axis: safe torque off (1.0 active) and the holding brake (BRAKE_*), views
        self.sto = self.extra[X_WORDS : X_WORDS + n]
        self.brake = self.extra[X_WORDS + n :]
        self.wakeup_counts = np.ndarray((HIST_BINS,), "<i8", buf, off["wakeup_counts"])
        self.compute_counts = np.ndarray((HIST_BINS,), "<i8", buf, off["compute_counts"])

    _last: tuple[np.ndarray, np.ndarray] | None = None
    stale_reads = 0

    @property
    def name(self) -> str:
        return self.shm.name

    def read_state(self, timeout: float = 0.2) -> tuple[np.ndarray, np.ndarray] | None:
        """A consistent copy of (tick record, extra words) (reader side of the seqlock);
        None before the loop's first tick. When no consistent copy can be taken within
        ``timeout`` [s] (the loop was preempted in the middle of a write), the last one
        taken (``stale_reads`` counts those)."""
        import time

        ctl = self.ctl
        end = 0.0
        spins = 0
        while True:
            s1 = int(ctl[STATE_SEQ])
            if s1 == 0:
                return None
            if not s1 & 1:
                rec = self.state_rec.copy()
                extra = self.extra.copy()
                if int(ctl[STATE_SEQ]) == s1:
                    self._last = (rec, extra)
                    return rec, extra
            spins += 1
            if spins > 100:  # the writer was preempted mid-write: let it finish
                now = time.monotonic()
                if end == 0.0:
                    end = now + timeout
                elif now > end:
                    self.stale_reads += 1
                    return self._last
                time.sleep(0.0002)

    def close(self) -> None:
        """Drop this side's views; the creator also unlinks the segment."""
        for attr in list(self.__dict__):
            if attr not in ("segment", "shm", "owner", "n", "k", "rec_dtype"):
                self.__dict__.pop(attr, None)
        self.segment.close()


def _round8(n: int) -> int:
    return (n + 7) // 8 * 8
