"""Errors of the EtherCAT master; each message names the interface, slave and values.

All derive from :class:`drivers.errors.EtherCATError` (a TransportError, a DriverError).
"""

from __future__ import annotations

from drivers.errors import EtherCATError

__all__ = [
    "EtherCATError",
    "IdentityMismatchError",
    "RegisterMismatchError",
    "SlaveLostError",
    "SlavePositionError",
    "StateChangeError",
]


class IdentityMismatchError(EtherCATError):
    """A slave's SII identity (vendor id, product code, revision) differs from the config."""

    def __init__(self, message: str, slave: int, what: str, expected: int, found: int) -> None:
        super().__init__(message)
        self.slave = slave
        self.what = what
        self.expected = expected
        self.found = found


class StateChangeError(EtherCATError):
    """Slaves did not reach a requested AL state; ``problems`` maps slave (1-based) to
    ``(al_status, al_status_code)``."""

    def __init__(self, message: str, problems: dict[int, tuple[int, int]]) -> None:
        super().__init__(message)
        self.problems = problems


class SlaveLostError(EtherCATError):
    """Slaves stopped answering during cyclic operation (and were not recovered)."""


class SlavePositionError(EtherCATError):
    """A line position asked for is beyond the slaves found on the line (bad input)."""


class RegisterMismatchError(EtherCATError):
    """An ESC register read back after the master wrote it holds another value."""
