"""The transport interface: one interface, many backends (in-process sim, EtherCAT, CANopen).

A transport moves a CiA-402 process image; :mod:`drivers.cia402` gives it meaning. It owns
two structured arrays of shape (n_axes,): ``rx`` (RxPDO, master -> drives, dtype
:data:`drivers.cia402.pdo.RXPDO_DTYPE`) and ``tx`` (TxPDO, drives -> master). Every cycle the
caller fills ``rx``, calls :meth:`Transport.exchange` and reads ``tx``.

``exchange`` never raises and never allocates: it returns a status code (0 = ok, see
:data:`STATUS_TEXT`). On a non-zero status ``tx`` keeps the last good values. SDO access
(:meth:`Transport.sdo_read` / :meth:`Transport.sdo_write`) is for setup, outside the cycle,
and raises :class:`SdoAbortError` naming the axis and the decoded abort code. The errors live
in :mod:`drivers.errors` (re-exported here).
"""

from __future__ import annotations

import importlib
import struct
import time
from abc import ABC, abstractmethod
from types import TracebackType
from typing import Any

import numpy as np

from drivers.cia402.pdo import new_rx, new_tx
from drivers.errors import SdoAbortError as SdoAbortError  # re-exported
from drivers.errors import TransportError

# Status codes returned by exchange(). Backends may add their own codes >= 100.
STATUS_OK = 0
STATUS_NOT_OPEN = 1
STATUS_NO_RESPONSE = 2  # frame lost / no reply within the cycle
STATUS_WKC_MISMATCH = 3  # EtherCAT: working counter lower than expected
STATUS_PARTIAL = 4  # some axes did not answer (CANopen: missing TPDO)
STATUS_BUS_ERROR = 5  # link down, bus-off, socket error

STATUS_TEXT: dict[int, str] = {
    STATUS_OK: "ok",
    STATUS_NOT_OPEN: "transport not open",
    STATUS_NO_RESPONSE: "no response from the bus within the cycle (frame lost)",
    STATUS_WKC_MISMATCH: "working counter mismatch (a slave did not process its data)",
    STATUS_PARTIAL: "some drives did not answer this cycle",
    STATUS_BUS_ERROR: "bus error (link down or bus-off)",
}


def describe_status(code: int) -> str:
    """Plain words for an exchange() status code."""
    return STATUS_TEXT.get(code, f"transport status {code}")


_FORMATS = {"u8": "<B", "i8": "<b", "u16": "<H", "i16": "<h", "u32": "<I", "i32": "<i"}


class Transport(ABC):
    """Base class of every backend.

    Subclasses implement :meth:`open`, :meth:`exchange`, :meth:`close`, :meth:`sdo_read`,
    :meth:`sdo_write`. ``cycle_time`` [s] is the nominal bus cycle; ``axis_names`` label
    axes in error messages.
    """

    def __init__(self, n_axes: int, cycle_time: float, axis_names: list[str] | None = None):
        if n_axes < 1:
            raise ValueError(f"n_axes must be >= 1 (got {n_axes})")
        if cycle_time <= 0:
            raise ValueError(f"cycle_time must be > 0 s (got {cycle_time})")
        self.n_axes = n_axes
        self.cycle_time = float(cycle_time)
        self.axis_names = list(axis_names) if axis_names else [f"axis{i}" for i in range(n_axes)]
        #: how far the drives' sampling clock moved since the last new sample [s], when the
        #: bus knows it (EtherCAT with DC: the reference clock's system time); 0.0 when it does
        #: not (then the master's own cycle-to-cycle time is the best estimate); -1.0 when the
        #: bus knows the clock and this cycle brought no new sample (a lost frame)
        self.sample_dt = 0.0
        if len(self.axis_names) != n_axes:
            raise ValueError(f"{len(self.axis_names)} axis names for {n_axes} axes")
        #: RxPDO image, master -> drives, shape (n_axes,)
        self.rx: np.ndarray = new_rx(n_axes)
        #: TxPDO image, drives -> master, shape (n_axes,)
        self.tx: np.ndarray = new_tx(n_axes)
        #: the drives' own wire layouts (:class:`drivers.cia402.wire.WireImage`) when the
        #: backend runs per-axis profiles; None: every drive has every canonical field
        self.wire: Any = None
        #: signals some drives do not report, computed after each fresh decode
        #: (:class:`drivers.cia402.fallbacks.DerivedSignals`); None: nothing to compute
        self.derived: Any = None
        self._deadline = 0.0

    def use_fallbacks(self, profiles: Any) -> None:
        """Compute what the drives' ``profiles`` (one per axis, None: built-in) say they do
        not report (torque from current, velocity from position): sets :attr:`derived`."""
        from drivers.cia402.fallbacks import DerivedSignals, derived_masks

        tau, vel = derived_masks(profiles)
        self.derived = (
            DerivedSignals(self.tx, tau, vel, self.cycle_time) if tau.any() or vel.any() else None
        )

    @property
    def torque_from_current(self) -> np.ndarray:
        """bool (n_axes,): axes whose canonical torque field carries the drive's current
        (profile fallback ``torque: current``; the drive group scales it with kt)."""
        if self.derived is None:
            return np.zeros(self.n_axes, dtype=bool)
        return self.derived.tau_mask

    def present(self, field: str) -> np.ndarray:
        """bool (n_axes,): which drives map canonical process-image ``field`` (e.g.
        ``torque_offset``, ``error_code``); all True without per-axis layouts."""
        if self.wire is None:
            return np.ones(self.n_axes, dtype=bool)
        return self.wire.present[field]

    # ------------------------------------------------------------------ lifecycle

    @abstractmethod
    def open(self) -> None:
        """Bring the bus to cyclic operation (EtherCAT: OP, CANopen: operational)."""

    @abstractmethod
    def exchange(self) -> int:
        """Send ``rx``, receive ``tx``; returns a status code, 0 = ok. Never raises."""

    @abstractmethod
    def close(self) -> None:
        """Stop cyclic exchange and release the bus. Safe to call twice."""

    def wait_next_cycle(self) -> None:
        """Block until the next cycle boundary (setup loops only, not the real-time tick).

        Real buses sleep on a monotonic clock; simulated buses override this with a no-op
        because their time advances with each exchange.
        """
        now = time.monotonic()
        if self._deadline <= 0.0 or now - self._deadline > 10 * self.cycle_time:
            self._deadline = now
        self._deadline += self.cycle_time
        delay = self._deadline - now
        if delay > 0:
            time.sleep(delay)

    def __enter__(self) -> Transport:
        self.open()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # ------------------------------------------------------------------------ SDO

    @abstractmethod
    def sdo_read(self, axis: int, index: int, subindex: int) -> bytes:
        """Upload object ``index:subindex`` of drive ``axis``; raises SdoAbortError."""

    @abstractmethod
    def sdo_write(self, axis: int, index: int, subindex: int, data: bytes) -> None:
        """Download ``data`` to ``index:subindex`` of drive ``axis``; raises SdoAbortError."""

    def read_value(self, axis: int, index: int, subindex: int, kind: str) -> int:
        """SDO read decoded as ``kind`` (u8, i8, u16, i16, u32, i32)."""
        fmt = _FORMATS[kind]
        data = self.sdo_read(axis, index, subindex)
        size = struct.calcsize(fmt)
        if len(data) < size:
            raise TransportError(
                f"{self._who(axis)}: SDO read 0x{index:04X}:{subindex:02X} returned "
                f"{len(data)} bytes, expected {size} ({kind})"
            )
        return int(struct.unpack_from(fmt, data)[0])

    def write_value(self, axis: int, index: int, subindex: int, kind: str, value: int) -> None:
        """SDO write of ``value`` encoded as ``kind`` (u8, i8, u16, i16, u32, i32)."""
        try:
            data = struct.pack(_FORMATS[kind], int(value))
        except struct.error:
            raise TransportError(
                f"{self._who(axis)}: value {value} does not fit object "
                f"0x{index:04X}:{subindex:02X} ({kind})"
            ) from None
        self.sdo_write(axis, index, subindex, data)

    def _who(self, axis: int) -> str:
        return f"axis {axis} ({self.axis_names[axis]})"

    def _check_axis(self, axis: int) -> None:
        if not 0 <= axis < self.n_axes:
            raise TransportError(f"axis {axis} does not exist (bus has {self.n_axes} axes)")


#: transport name in config -> "module:Class". Backends add themselves here (one line).
BACKENDS: dict[str, str] = {
    "sim": "drivers.sim.simbus:SimBus",
    "ethercat": "drivers.ethercat.master:EtherCATTransport",
    "canopen": "drivers.canopen.master:CANopenTransport",
}


def backend_class(name: str) -> Any:
    """The transport class registered as ``name`` (imported on demand)."""
    try:
        target = BACKENDS[name]
    except KeyError:
        raise TransportError(
            f"bus.transport: unknown transport {name!r} (known: {', '.join(sorted(BACKENDS))})"
        ) from None
    module_path, cls_name = target.split(":")
    return getattr(importlib.import_module(module_path), cls_name)
