"""``hofto_hw.client``: the Python interface of a running ``hofto-hw run`` (docs/client.md).

:class:`Robot` (``Robot.connect(socket=...)``), its :class:`State` snapshot (with an
:class:`Axis` per drive and the :class:`ActivePayload`), the
:class:`Motion` handle of a move or replay, :class:`TickRecord` of ``Robot.stream``, and the
exceptions: :class:`Refused` (the service said no: its one-line reason) and
:class:`ServiceError` (not reachable, no answer, a malformed answer).
"""

from hofto_hw.client.connection import Refused, ServiceError
from hofto_hw.client.robot import ActivePayload, Axis, Enabling, Motion, Robot, State
from hofto_hw.client.stream import TickRecord

__all__ = [
    "ActivePayload",
    "Axis",
    "Enabling",
    "Motion",
    "Refused",
    "Robot",
    "ServiceError",
    "State",
    "TickRecord",
]
