"""CSP to the loop, ip or pv to the drive: the per-axis step between the canonical RxPDO the
loop writes and the bytes a drive without a cyclic synchronous mode needs.

The loop, the safety reactions, ``DriveGroup.hold`` and the compiled tick all command a
position target (CSP) in the canonical record. Two kinds of drive cannot take one every
cycle as it is, and this module turns it into what they take, per axis, in raw units, at
the one place every writer's command passes: the wire encode of the transport
(:meth:`drivers.cia402.wire.WireImage.encode_rx`), on a copy of the canonical record (the
loop's own record stays CSP):

- **ip** (interpolated position, 0x6060 = 7; e.g. Technosoft iPOS): the target already
  travels in 0x60C1:01 (the wire layout maps it from the canonical target position), and
  the interpolation period 0x60C2 is the loop period (a start-up write). What remains is
  controlword bit 4 "enable ip mode": set while the loop commands Enable operation AND the
  drive reported Operation enabled in the last cycle, so the bit rises once the drive is
  enabled (a drive that starts interpolating on the edge sees it in OE) and falls with any
  other command (quick stop, disable). The drive acknowledges with statusword bit 12
  "ip mode active" (``DriveGroup.enable`` waits for it).
- **pv** (profile velocity streamed, 0x6060 = 3; e.g. Faulhaber MCBL 300x): the drive
  takes a target velocity 0x60FF every SYNC and closes only its velocity loop. The position
  loop a CSP drive closes in its firmware is closed here, once per cycle, in counts:
  ``v = (target - previous target) / period + gain x (target - measured position)``
  [counts/s]. The feed-forward term makes the drive follow the loop's reference (its stop
  ramps, drag motion) without lag; the proportional term removes the drift. It runs only
  while the loop commands Enable operation and the drive is enabled; else the velocity
  command is 0 and the feed-forward restarts from the next target (bumpless enable).

Why here and not in the controller: the loop thinks in CSP for every drive, so stopping and
dragging need no mode-specific code above drivers/; this position loop only stands in for
the position controller a CSP drive has inside (same input, the position target; same
output, what the drive's velocity loop gets), needs no model and no SI (counts in, counts
per second out), and must act on every target whoever wrote it (the compiled tick writes
the record directly). Its formula lives here only; the emulated drive's own CSP loop
(drivers/sim/drive.py) is the emulated firmware's, not the stack's.

Drive units: a drive whose profile says ``units.velocity: rpm`` takes and reports velocities
in motor min^-1, not counts/s. The adapter multiplies the streamed velocity by the axis's
factor (rpm per count/s = 60 / counts per motor revolution, the axis's
``counts_per_rev`` = the drive's 0x608F) before rounding and, after each decode
(:meth:`CspAdapter.decode`), turns the reported 0x606C back into counts/s, so the canonical
image stays in counts above this module; :attr:`CspAdapter.accel_unit` is the unit of
the acceleration writes 0x6083-0x6085 (``units.acceleration: rpm/s`` or ``rev/s^2``).

No allocation per cycle: every array is preallocated, and an arm without ip/pv axes never
calls :meth:`CspAdapter.apply`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from drivers.cia402.state_machine import Mode

#: controlword bit 4 in interpolated position mode: "enable ip mode"
CW_ENABLE_IP = 0x0010
#: statusword bit 12 in interpolated position mode: "ip mode active"
SW_IP_ACTIVE = 0x1000
#: (mask, value) of a controlword commanding Enable operation (bits 0-3 set, 7 clear)
_CW_ENABLE_MASK, _CW_ENABLE = 0x008F, 0x000F
#: (mask, value) of a statusword reporting Operation enabled
_SW_OE_MASK, _SW_OE = 0x006F, 0x0027
_I32 = (-(2**31), 2**31 - 1)

#: the 0x6060 value of each loop mode the adapter knows
LOOP_MODE_NUMBERS = {
    "csp": int(Mode.CSP),
    "csv": int(Mode.CSV),
    "cst": int(Mode.CST),
    "ip": int(Mode.INTERPOLATED_POSITION),
    "pv": int(Mode.PROFILE_VELOCITY),
}


class CspAdapter:
    """Per-axis ip / pv handling of n axes (see the module docstring).

    ``loops``: each axis's loop mode (``csp``, ``csv``, ``cst``, ``ip``, ``pv``);
    ``gains``: the pv axes' position-loop gain [1/s] (others ignored); ``cycle_time`` [s];
    ``units``: per axis (counts/s per drive velocity unit, counts/s² per drive acceleration
    unit); None: counts everywhere.
    """

    def __init__(
        self,
        loops: Sequence[str],
        gains: Sequence[float | None],
        cycle_time: float,
        units: Sequence[tuple[float, float]] | None = None,
    ):
        n = len(loops)
        units = list(units) if units is not None else [(1.0, 1.0)] * n
        #: drive velocity units per count/s, counts/s per drive velocity unit (n,)
        self.vel_to_drive = np.array([1.0 / u[0] for u in units])
        self.vel_from_drive = np.array([float(u[0]) for u in units])
        #: counts/s² per drive acceleration unit (n,): 0x6083/0x6084/0x6085 writes
        self.accel_unit = np.array([float(u[1]) for u in units])
        #: bool (n,): axes whose drive velocity unit is not counts/s
        self.scaled = self.vel_from_drive != 1.0
        #: bool (n,): csv axes among them (their target velocity is scaled as it is)
        self._csv_scaled = self.scaled & np.array([m == "csv" for m in loops])
        self.n = n
        self.loops = tuple(loops)
        #: 0x6060 each axis runs when the loop asks for CSP (ip / pv axes: their own mode)
        self.csp_modes = np.array(
            [LOOP_MODE_NUMBERS[m] if m in ("ip", "pv") else int(Mode.CSP) for m in loops],
            dtype=np.int8,
        )
        #: bool (n,): axes run in interpolated position / streamed profile velocity
        self.ip = np.array([m == "ip" for m in loops])
        self.pv = np.array([m == "pv" for m in loops])
        self.active = bool(self.ip.any() or self.pv.any() or self.scaled.any())
        self._gain = np.array(
            [g if m == "pv" and g else 0.0 for m, g in zip(loops, gains, strict=True)]
        )
        self._inv_dt = 1.0 / cycle_time
        self._prev = np.zeros(n)  # previous position target [counts]
        self._valid = np.zeros(n, dtype=bool)  # the previous target is this run's
        self._go = np.zeros(n, dtype=bool)
        self._b = np.zeros(n, dtype=bool)
        self._u16 = np.zeros(n, dtype=np.uint16)
        self._t = np.zeros(n)
        self._v = np.zeros(n)
        self._w = np.zeros(n)
        self._s = np.zeros(n)

    def apply(self, rx: np.ndarray, tx: np.ndarray) -> None:
        """Adapt ``rx`` (a copy of the canonical RxPDO about to be encoded, shape (n,)) with
        the last decoded canonical TxPDO ``tx`` (n,). No allocation."""
        cw, sw = rx["controlword"], tx["statusword"]
        go, b, u = self._go, self._b, self._u16
        # the loop commands Enable operation and the drive is in Operation enabled
        np.bitwise_and(cw, _CW_ENABLE_MASK, out=u)
        np.equal(u, _CW_ENABLE, out=go)
        np.bitwise_and(sw, _SW_OE_MASK, out=u)
        np.equal(u, _SW_OE, out=b)
        go &= b
        # ip: controlword bit 4 while enabled
        np.logical_and(go, self.ip, out=b)
        np.multiply(b, CW_ENABLE_IP, out=u, casting="unsafe")
        cw |= u
        # pv: velocity from the position target [counts/s]
        t, v, w = self._t, self._v, self._w
        np.copyto(t, rx["target_position"], casting="unsafe")
        np.subtract(t, self._prev, out=v)
        v *= self._inv_dt
        v *= self._valid
        np.subtract(t, tx["position"], out=w)
        w *= self._gain
        v += w
        v *= go
        v *= self.vel_to_drive  # counts/s -> the drive's unit (rpm) before rounding
        np.clip(v, *_I32, out=v)
        np.rint(v, out=v)
        np.copyto(rx["target_velocity"], v, where=self.pv, casting="unsafe")
        np.copyto(self._prev, t)
        np.copyto(self._valid, go)
        if self._csv_scaled.any():  # csv: the loop's own target velocity, in the drive's unit
            s = self._s
            np.multiply(rx["target_velocity"], self.vel_to_drive, out=s)
            np.clip(s, *_I32, out=s)
            np.rint(s, out=s)
            np.copyto(rx["target_velocity"], s, where=self._csv_scaled, casting="unsafe")

    def decode(self, tx: np.ndarray) -> None:
        """The velocity the drives reported in ``tx`` (the canonical TxPDO just decoded,
        shape (n,)) in the drive's unit -> counts/s, in place, on the scaled axes. No
        allocation."""
        s = self._s
        np.multiply(tx["velocity"], self.vel_from_drive, out=s)
        np.clip(s, *_I32, out=s)
        np.rint(s, out=s)
        np.copyto(tx["velocity"], s, where=self.scaled, casting="unsafe")
