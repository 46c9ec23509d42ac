"""Errors of the CANopen master; each message names the node and the cause.

They derive from :class:`drivers.transport.TransportError` (the drivers' error root until
``drivers.errors.DriverError`` lands; TransportError will derive from it).
"""

from __future__ import annotations

from drivers.transport import TransportError


class CANopenError(TransportError):
    """The CANopen bus or a node cannot be brought up or used."""


class NodeMissingError(CANopenError):
    """A node did not answer (no boot-up, no heartbeat, no SDO answer)."""


class IdentityMismatchError(CANopenError):
    """A node's 0x1018 identity differs from the configured one."""

    def __init__(self, message: str, node: int, what: str, expected: int, found: int) -> None:
        super().__init__(message)
        self.node = node
        self.what = what
        self.expected = expected
        self.found = found
