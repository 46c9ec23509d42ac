"""Errors of the driver stack: one root, :class:`DriverError` (python-can's CanError pattern).

Code above ``drivers/`` can catch every driver failure with ``except DriverError`` and still
tell them apart::

    hofto_hw.errors.UserError
    └── DriverError
        ├── TransportError        a bus cannot be opened or used (names device/interface)
        │   ├── SdoAbortError     an SDO transfer was aborted (axis, index, subindex, code)
        │   └── EtherCATError     the EtherCAT master (drivers.ethercat.errors adds subclasses)
        └── DriveError            a drive did not do what was asked (axis, state, statusword)

Every message is one line naming the device, the axis and the values involved.
"""

from __future__ import annotations

from drivers.cia402.codes import describe_sdo_abort
from hofto_hw.errors import UserError


class DriverError(UserError):
    """Root of every error raised by ``drivers/``; ``str(err)`` is the whole message."""


class TransportError(DriverError):
    """A transport cannot be opened or used; the message names the device/interface."""


class SdoAbortError(TransportError):
    """An SDO transfer was aborted by a drive (or timed out).

    Attributes: ``axis`` (0-based), ``index``, ``subindex``, ``code`` (CiA 301 abort code).
    """

    def __init__(
        self, axis: int, index: int, subindex: int, code: int, action: str, device: str = ""
    ) -> None:
        self.axis = axis
        self.index = index
        self.subindex = subindex
        self.code = code
        who = f"axis {axis}" + (f" ({device})" if device else "")
        super().__init__(
            f"{who}: SDO {action} 0x{index:04X}:{subindex:02X} aborted: {describe_sdo_abort(code)}"
        )


class EtherCATError(TransportError):
    """The EtherCAT bus cannot be brought up or used."""


class DriveError(DriverError):
    """A drive did not do what was asked; ``axis``, ``state``, ``statusword`` name it."""

    def __init__(self, message: str, axis: int = -1, state: int = -1, statusword: int = 0):
        super().__init__(message)
        self.axis = axis
        self.state = state
        self.statusword = statusword
