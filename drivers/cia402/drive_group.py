"""The drive layer above any transport: n CiA-402 axes as one group, SI in, SI out.

Every cycle (hot path, no allocation): :meth:`DriveGroup.read` decodes the TxPDO into
``q`` [rad], ``qd`` [rad/s], ``tau`` [N·m] (joint side), ``current`` [A] and ``states``
(uint8 :class:`~drivers.cia402.state_machine.State` codes), all shape (n,);
:meth:`DriveGroup.command_position` / ``command_velocity`` / ``command_torque`` encode SI
commands into the RxPDO; :meth:`DriveGroup.cycle` exchanges and reads, returns the
transport status and sets ``fresh`` (False when the data is stale after a lost frame or a
working-counter error).

Setup (blocking, outside the tick): :meth:`configure`, :meth:`set_mode` (with the 0x6061
mode-display check), :meth:`enable`, :meth:`disable`, :meth:`quick_stop`,
:meth:`fault_reset`. Each state transition has a timeout counted in bus cycles; a timeout
raises :class:`DriveTimeoutError` naming the axis, its state and statusword. Faults are
decoded from 0x603F (:meth:`fault_messages`).

The service, the EtherCAT master and the CANopen transport all use this class unchanged.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers.cia402 import state_machine as sm
from drivers.cia402.codes import describe_error_code
from drivers.cia402.pdo import ImageFields
from drivers.cia402.state_machine import STATE_NAMES, Mode, State
from drivers.cia402.units import AxisScaling, Scaling
from drivers.errors import DriveError as DriveError  # re-exported
from drivers.errors import TransportError
from drivers.transport import STATUS_OK, Transport, describe_status
from hofto_hw.errors import ConfigError

if TYPE_CHECKING:  # the kernels (and numba) load when the first group is built
    from drivers.cia402.kernels import Backend


class DriveTimeoutError(DriveError):
    """A state transition or mode change did not complete within its timeout."""


class DriveFaultError(DriveError):
    """A drive is in Fault (or fault reaction); ``error_code`` is its 0x603F value."""

    def __init__(self, message: str, axis: int, state: int, statusword: int, error_code: int):
        super().__init__(message, axis, state, statusword)
        self.error_code = error_code


_FAULTY = (State.FAULT, State.FAULT_REACTION_ACTIVE)


class DriveGroup(ImageFields):
    """All axes of one transport as a CiA-402 group (see module docstring).

    ``transition_timeout`` [s] bounds each single state transition; it is converted to bus
    cycles with ``transport.cycle_time`` so simulated buses time out in simulated time.
    ``backend``: the read and commands are the kernels of :mod:`drivers.cia402.kernels`
    (their one implementation), ``numba`` compiled, ``python`` their Python source run by the
    interpreter (for tests and debugging; ~75 µs a call against ~0.5), ``auto`` (default)
    compiled when numba works. The numpy reference of the same arithmetic is a test's
    (tests/drivers/cia402/reference.py).
    """

    def __init__(
        self,
        transport: Transport,
        scaling: Scaling,
        *,
        transition_timeout: float = 0.5,
        backend: Backend = "auto",
        profile_acceleration: Sequence[float] | None = None,
        hot: Mapping[str, np.ndarray] | None = None,
    ) -> None:
        n = transport.n_axes
        if scaling.n != n:
            raise ValueError(f"scaling has {scaling.n} axes, transport has {n}")
        self.transport = transport
        self.scaling = scaling
        self.n = n
        self.names = transport.axis_names
        self.timeout_cycles = max(1, round(transition_timeout / transport.cycle_time))
        self.transition_timeout = transition_timeout
        #: [rad/s²] per axis: profile acceleration/deceleration 0x6083/0x6084 written to the
        #: axes streamed in profile velocity (pv) when CSP is selected; None: not written
        self.profile_acceleration = (
            None if profile_acceleration is None else np.asarray(profile_acceleration, float)
        )
        # the group's SI values as the first rows of one float64 workspace, the scale rows the
        # compiled read and command use after them (one argument: drivers/cia402/kernels.py)
        self._si = np.zeros((10, n)) if hot is None else hot["si"]
        #: joint angle [rad], (n,)
        self.q = self._si[0]
        #: joint velocity [rad/s], (n,)
        self.qd = self._si[1]
        #: joint-side motor torque [N·m], (n,)
        self.tau = self._si[2]
        #: motor current [A] in the joint's sense, (n,)
        self.current = self._si[3]
        from drivers.cia402.fallbacks import torque_scale

        self._si[4:] = (
            scaling.zero_offset,
            scaling.rad_per_count,
            # N·m per raw torque unit: the current's x kt x gear where the drive reports
            # no torque (profile fallback ``torque: current``)
            torque_scale(scaling, transport.torque_from_current),
            scaling.amp_per_permille,
            scaling.count_per_rad,
            scaling.permille_per_nm,
        )
        #: q, qd, tau as the rows of one (3, n) view (one copy of the whole sample)
        self.sample = self._si[:3]
        #: State code per axis, uint8 (n,)
        self.states = np.zeros(n, dtype=np.uint8) if hot is None else hot["states"]
        #: status of the last exchange (0 = ok, see drivers.transport.STATUS_TEXT)
        self.status = STATUS_OK
        #: True only when the last :meth:`cycle` brought new TxPDO data; after a lost frame
        #: or a short working counter the transport keeps the last good ``tx`` and q, qd, tau,
        #: current, states are those of an earlier cycle (stale)
        self.fresh = False
        #: consecutive cycles without fresh data (0 after a good cycle)
        self.stale_cycles = 0
        self._bind_image(transport.rx, transport.tx)
        self._cw = np.zeros(n, dtype=np.uint16)
        self._flags = np.zeros(n, dtype=bool)
        self._u32 = np.zeros(n, dtype=np.uint32)
        from drivers.cia402 import kernels
        from hofto_hw.jit import compiled_or_python

        if not kernels.layout_matches():
            raise RuntimeError(
                "drivers/cia402/kernels.py: its PDO layout literals are not those of "
                "drivers/cia402/pdo.py and state_machine.py (change both together)"
            )
        # the images' raw bytes (uint8 views) the kernels decode and encode
        self._tx_bytes = kernels.image_bytes(transport.tx)
        self._rx_bytes = kernels.image_bytes(transport.rx)
        #: the implementation of read and command: the kernels of drivers/cia402/kernels.py,
        #: ``numba`` compiled, ``python`` their Python source run by the interpreter
        self.backend = kernels.resolve(backend)
        if self.backend == "numba" and not kernels.ready(backend, self._warm):
            self.backend = "python"
        #: the kernels module when the compiled kernels run, else None (the tick's fused call
        #: needs them: hofto_hw/runtime/fused.py)
        self._fast: Any = kernels if self.backend == "numba" else None
        self._read_si = compiled_or_python(kernels.read_si, self.backend)
        self._command_raw = compiled_or_python(kernels.command_raw, self.backend)
        # read() as the kernel call itself: no Python frame around it in the tick (an
        # instance attribute, so tests and tools/bench_tick.py can still wrap it)
        self.read = partial(self._read_si, self._tx_bytes, self._si, self.states)  # type: ignore[method-assign]
        self._init_commissioning()

    @staticmethod
    def hot_fields(n: int) -> dict[str, np.dtype]:
        """The arrays the tick's compiled call reads, as fields of a caller-owned record
        (``hot=``: the constructor then takes these arrays, zeroed, instead of allocating)."""
        return {"si": np.dtype((np.float64, (10, n))), "states": np.dtype((np.uint8, (n,)))}

    def _init_commissioning(self) -> None:
        """Per axis from its profile (issue 28): where STO is read and how the drive runs a
        brake it controls. An axis without a profile is the built-in emulated drive."""
        from drivers.cia402.profiles import BUILTIN_BRAKE
        from hofto_hw.config.drive_profile import ProfileBrake, StoSource

        n = self.n
        profiles = list(getattr(self.transport, "profiles", None) or [None] * n)
        din = self.present("digital_inputs")
        #: per axis: the profile's STO source (:class:`hofto_hw.config.drive_profile.StoSource`)
        self.sto_sources = [
            p.sto_source() if p is not None else StoSource(source="input") for p in profiles
        ]
        builtin = ProfileBrake.model_validate(BUILTIN_BRAKE)
        #: per axis: brake delay objects and fault codes of its drive (None: none known)
        self.brake_objects = [p.brake if p is not None else builtin for p in profiles]
        # the process image's STO reading: axes with an input source mapped in the TxPDO
        # (bit mask, active-low flag); the others are judged by their state in the loop
        self._sto_mask = np.zeros(n, dtype=np.uint32)
        self._sto_low = np.zeros(n, dtype=bool)
        for i, src in enumerate(self.sto_sources):
            if src.source == "input" and din[i]:
                self._sto_mask[i] = 1 << src.bit
                self._sto_low[i] = src.active_low
        self._sto_by_image = self._sto_mask != 0
        #: what :meth:`write_brake_delays` wrote at :meth:`configure`, one line per axis
        self.brake_setup: list[str] = []
        #: the setting objects :meth:`configure` left out, one line per axis that lacks some
        self.settings_notes: list[str] = []

    def _warm(self) -> None:
        """Compile the kernels for this image's exact array types (outputs: scratch)."""
        from drivers.cia402 import kernels

        # the read only reads the TxPDO: warm it on the image itself (a read-only or
        # differently aligned buffer is another signature); the commands on a copy of the RxPDO
        si = self._si.copy()
        kernels.read_si(self._tx_bytes, si, np.zeros_like(self.states))
        rx = kernels.image_bytes(self.transport.rx.copy())
        q = np.zeros(self.n)
        for what in range(4):
            kernels.command_raw(q, q, rx, si, what)

    @classmethod
    def from_config(
        cls,
        transport: Transport,
        bus: Any,
        backend: Backend = "auto",
        hot: Mapping[str, np.ndarray] | None = None,
    ) -> DriveGroup:
        """From a :class:`hofto_hw.config.drives.BusConfig`; ``backend`` and ``hot`` as the
        constructor's (``auto``: the compiled read/command when numba is available, else their
        Python source; ``numba``: compiled; ``python``: the kernels' Python source)."""
        scaling = Scaling([AxisScaling.from_config(d) for d in bus.drives])
        return cls(
            transport,
            scaling,
            transition_timeout=bus.transition_timeout,
            backend=backend,
            profile_acceleration=[d.quick_stop_deceleration for d in bus.drives],
            hot=hot,
        )

    # ------------------------------------------------------------ hot path (tick)

    def read(self) -> None:
        """Decode the TxPDO into q, qd, tau, current, states (no allocation):
        :func:`drivers.cia402.kernels.read_si` (the instance's ``read`` is that call)."""
        self._read_si(self._tx_bytes, self._si, self.states)

    def cycle(self) -> int:
        """Exchange the process image, then :meth:`read`. Returns the transport status
        (0 = ok) and sets :attr:`fresh` (new TxPDO data this cycle) and :attr:`stale_cycles`.
        """
        status = self.exchange()
        self.read()
        return status

    def exchange(self) -> int:
        """Exchange the process image without reading it (:meth:`cycle` without
        :meth:`read`; the tick's fused call reads it). Returns the transport status and sets
        :attr:`fresh` and :attr:`stale_cycles` as :meth:`cycle` does."""
        self.status = status = self.transport.exchange()
        self.fresh = fresh = status == STATUS_OK
        self.stale_cycles = 0 if fresh else self.stale_cycles + 1
        return status

    @property
    def sample_dt(self) -> float:
        """How far the drives' samples moved since the last cycle [s] when the bus knows it
        (the transport's :attr:`~drivers.transport.Transport.sample_dt`), else 0.0; -1.0 when
        the bus knows the clock and this cycle brought no new sample."""
        return self.transport.sample_dt

    def command_position(self, q: np.ndarray, tau_offset: np.ndarray | None = None) -> None:
        """CSP target q [rad] (n,) and optional torque feed-forward [N·m] (n,)
        (:func:`drivers.cia402.kernels.command_raw`)."""
        if tau_offset is None:
            self._command_raw(q, q, self._rx_bytes, self._si, 0)  # POSITION
        else:
            self._command_raw(q, tau_offset, self._rx_bytes, self._si, 2)  # + WITH_TAU

    def command_velocity(self, qd: np.ndarray, tau_offset: np.ndarray | None = None) -> None:
        """CSV target qd [rad/s] (n,) and optional torque feed-forward [N·m] (n,)
        (:func:`drivers.cia402.kernels.command_raw`)."""
        if tau_offset is None:
            self._command_raw(qd, qd, self._rx_bytes, self._si, 1)  # VELOCITY
        else:
            self._command_raw(qd, tau_offset, self._rx_bytes, self._si, 3)  # + WITH_TAU

    def command_torque(self, tau: np.ndarray) -> None:
        """CST target torque [N·m] (n,), joint side."""
        self.scaling.torque_to_raw(tau, self._rx_tau)

    def command_quick_stop(self) -> None:
        """Send Quick stop to every axis this cycle (stop category 1); non-blocking."""
        self._rx_cw.fill(sm.CW_QUICK_STOP)

    def command_disable_voltage(self) -> None:
        """Send Disable voltage to every axis this cycle (stop category 0); non-blocking."""
        self._rx_cw.fill(sm.CW_DISABLE_VOLTAGE)

    def any_fault(self) -> bool:
        """True when any axis is in Fault or Fault reaction active (no allocation)."""
        np.greater_equal(self.states, State.FAULT_REACTION_ACTIVE, out=self._flags)
        # UNKNOWN (8) also counts: a statusword matching no state is not trustworthy.
        return bool(self._flags.any())

    def all_in(self, state: State) -> bool:
        """True when every axis is in ``state`` (no allocation)."""
        np.equal(self.states, state, out=self._flags)
        return bool(self._flags.all())

    def hold(self) -> None:
        """Bumpless targets for every mode: CSP the measured position, CSV zero velocity,
        CST the torque last given to :meth:`command_torque` (kept, not zeroed: a caller
        holding the arm against gravity keeps holding it). The torque offset is kept too.
        """
        np.copyto(self._rx_pos, self._tx_pos)
        self._rx_vel.fill(0)

    def set_zero_offset(self, axis: int, counts: float) -> float:
        """Re-zero ``axis``: encoder count ``counts`` now reads joint angle 0 (between two
        cycles; the reference and compiled conversions both take it). Returns the shift of
        the axis's joint angle [rad] (new reading minus old) for the caller's references."""
        sc = self.scaling
        shift = float((sc.zero_offset[axis] - counts) * sc.rad_per_count[axis])
        sc.zero_offset[axis] = counts
        self._si[4, axis] = counts
        self.q[axis] += shift
        return shift

    # ------------------------------------------------------------------ setup

    def configure(self, drives: Sequence[Any]) -> None:
        """Check identity and ratings by SDO and write limits (DriveConfig list, one per axis)
        and the delays of drive-controlled brakes (:meth:`write_brake_delays`).

        Only the setting objects the axis's drive has are read or written: those its profile
        lists in ``objects.absent_settings`` are left out (an axis without a profile, the
        built-in drive, has them all); :attr:`settings_notes` says per axis which ones and what
        the stack does instead.

        Raises ConfigError naming the axis and the object when a drive's 0x1018 identity,
        its position encoder resolution 0x608F (increments per motor revolution, where the
        drive has the object: the config's ``counts_per_rev`` scales every position and,
        for a drive in rpm, every velocity) or its rated torque/current (which set the
        scaling) differ from the config.
        """
        t, sc, unit = self.transport, self.scaling, self._accel_unit
        absent = self._absent_settings()
        self.settings_notes = self._settings_notes(absent)
        resolution = self._has_encoder_resolution()
        for i, d in enumerate(drives):
            who = f"axis {i} ({self.names[i]})"
            ident = d.identity
            if ident.vendor_id or ident.product_code:
                checks = [
                    (1, "vendor id", ident.vendor_id),
                    (2, "product code", ident.product_code),
                ]
                if ident.revision is not None:
                    checks.append((3, "revision", ident.revision))
                for sub, what, want in checks:
                    got = t.read_value(i, 0x1018, sub, "u32")
                    if got != want:
                        raise ConfigError(
                            f"bus.drives[{i}].identity: {who} reports {what} 0x{got:08X}, "
                            f"config expects 0x{want:08X}"
                        )
            if resolution[i]:
                inc, revs = t.read_value(i, 0x608F, 1, "u32"), t.read_value(i, 0x608F, 2, "u32")
                if revs == 0 or inc != d.counts_per_rev * revs:
                    raise ConfigError(
                        f"bus.drives[{i}].counts_per_rev: {who} object 0x608F (position "
                        f"encoder resolution) says {inc} increments per {revs} motor "
                        f"revolutions, config expects {d.counts_per_rev} per 1"
                    )
            lacks = absent[i].__contains__
            for index, what, want in (
                (0x6076, "rated_torque", d.rated_torque),
                (0x6075, "rated_current", d.rated_current),
            ):
                if lacks(what):
                    continue
                got = t.read_value(i, index, 0, "u32")
                if got != round(want):
                    raise ConfigError(
                        f"bus.drives[{i}].{what}: {who} object 0x{index:04X} says {got}, "
                        f"config says {want:g}"
                    )
            if not lacks("max_torque"):
                t.write_value(i, 0x6072, 0, "u16", sc.torque_limit_permille(i, d.torque_limit))
            if not lacks("quick_stop_deceleration"):
                decel = max(1, sc.acceleration_to_raw(i, d.quick_stop_deceleration, unit(i)))
                t.write_value(i, 0x6085, 0, "u32", decel)
            if not lacks("following_error_window"):
                window = sc.angle_to_counts(i, d.following_error_window)
                t.write_value(i, 0x6065, 0, "u32", window)
            if not lacks("following_error_timeout"):
                t.write_value(i, 0x6066, 0, "u16", round(d.following_error_timeout * 1000.0))
        self.brake_setup = self.write_brake_delays(drives)

    def _has_encoder_resolution(self) -> list[bool]:
        """Per axis: its drive has 0x608F (the built-in drive has; a profile says)."""
        profiles = getattr(self.transport, "profiles", None) or [None] * self.n
        return [
            p is None
            or p.name.startswith("builtin-")
            or p.units.position_encoder_resolution.present
            for p in profiles
        ]

    def _absent_settings(self) -> list[frozenset[str]]:
        """Per axis: the setting objects its profile says the drive does not have."""
        profiles = getattr(self.transport, "profiles", None) or [None] * self.n
        return [frozenset(() if p is None else p.objects.absent_settings) for p in profiles]

    def _settings_notes(self, absent: list[frozenset[str]]) -> list[str]:
        """One line per axis whose drive lacks setting objects: which, and what the stack
        does instead (printed once at start-up)."""
        from hofto_hw.config.drive_profile import SETTING_OBJECTS

        profiles = getattr(self.transport, "profiles", None) or [None] * self.n
        out = []
        for i, names in enumerate(absent):
            if not names:
                continue
            parts = [
                f"no 0x{index:04X} {name}: {how}"
                for name, (index, how) in SETTING_OBJECTS.items()
                if name in names
            ]
            out.append(f"axis {i} ({self.names[i]}, {profiles[i].name}): " + "; ".join(parts))
        return out

    def write_brake_delays(self, drives: Sequence[Any]) -> list[str]:
        """Write the release and engage delays of every drive-controlled brake
        (``drives[i].brake.control: drive``) to the objects its profile names, by SDO, and
        read each back; one line per axis saying what was written or why nothing was (the
        profile names no object: the drive's own setting stays). Setup only.

        Raises ConfigError naming the axis and object when the drive keeps another value."""
        t = self.transport
        out = []
        for i, d in enumerate(drives):
            b = getattr(d, "brake", None)
            if b is None or b.control != "drive":
                continue
            who = f"axis {i} ({self.names[i]})"
            objs = self.brake_objects[i]
            done = []
            delays = (("release_delay", b.release_delay), ("engage_delay", b.engage_delay))
            for what, value in delays:
                obj = None if objs is None else getattr(objs, what)
                if obj is None:
                    done.append(f"{what} not written (the profile names no object)")
                    continue
                kind = f"u{obj.bits}"
                raw = obj.raw(value)
                t.write_value(i, obj.index, obj.subindex, kind, raw)
                got = t.read_value(i, obj.index, obj.subindex, kind)
                if got != raw:
                    raise ConfigError(
                        f"bus.drives[{i}].brake.{what}: {who} object "
                        f"0x{obj.index:04X}:{obj.subindex:02X} reads {got} after writing {raw}"
                    )
                done.append(f"{what} {value:g} s -> 0x{obj.index:04X}:{obj.subindex:02X} = {raw}")
            out.append(f"{who}: brake " + ", ".join(done))
        return out

    def sto_in_image(self, out: np.ndarray, by_state: bool) -> np.ndarray:
        """bool (n,) into ``out``: the axes whose STO the process image shows active: an
        input source mapped in the TxPDO by its bit; with ``by_state``, every other axis
        that is in Switch on disabled (its drive dropped the power stage without a fault:
        what STO does where no signal is mapped). No allocation."""
        np.bitwise_and(self._tx_din, self._sto_mask, out=self._u32)
        np.not_equal(self._u32, 0, out=out)
        np.not_equal(out, self._sto_low, out=out)
        out &= self._sto_by_image
        if by_state:
            np.equal(self.states, State.SWITCH_ON_DISABLED, out=self._flags)
            self._flags &= ~self._sto_by_image
            out |= self._flags
        return out

    def sto_of(self, axis: int) -> bool:
        """Whether ``axis``'s STO shows active in the process image (an input source by its
        bit, else the drive state: Switch on disabled). For the loop's rare path."""
        if self._sto_by_image[axis]:
            bit = bool(int(self._tx_din[axis]) & int(self._sto_mask[axis]))
            return bit != bool(self._sto_low[axis])
        return int(self.states[axis]) == State.SWITCH_ON_DISABLED

    def sto_axes(self) -> list[int]:
        """The axes whose STO is known active now (setup, not the tick): the process image
        for a mapped input, an SDO read of the source object otherwise (an SDO that fails
        counts as not known); an axis whose source is the drive state is not known here."""
        t = self.transport
        out = []
        for i, src in enumerate(self.sto_sources):
            if self._sto_by_image[i]:
                if self.sto_of(i):
                    out.append(i)
                continue
            if src.source == "state":
                continue
            try:
                value = int(t.read_value(i, src.index, src.subindex, f"u{src.bits}"))
            except TransportError:
                continue
            if bool(value >> src.bit & 1) != src.active_low:
                out.append(i)
        return out

    def is_brake_fault(self, axis: int, code: int) -> bool:
        """Whether 0x603F ``code`` of ``axis``'s drive is a holding-brake fault (its profile's
        ``brake.fault_codes``)."""
        objs = self.brake_objects[axis]
        return objs is not None and objs.is_brake_fault(code)

    def _step(self) -> None:
        self.transport.wait_next_cycle()
        self.cycle()

    def present(self, field: str) -> np.ndarray:
        """bool (n,): which axes' drives map canonical process-image ``field`` (their
        profile's layout as read back from the drive); e.g. ``torque_offset`` False: the
        feed-forward of :meth:`command_position` does not reach that drive."""
        return self.transport.present(field)

    def unavailable(self) -> list[str]:
        """One line per axis and signal its drive does not map, saying how the stack does
        without it (setup and diagnostics, not the tick)."""
        how = {
            "torque_offset": "no torque feed-forward in CSP/CSV (only through the target "
            "torque in CST)",
            "error_code": "the error code is read by SDO (or EMCY) on a fault",
            "digital_inputs": "no enabling or STO input from this drive",
            "mode": "the mode is written by SDO",
            "mode_display": "the mode display is read by SDO",
            "torque": "no measured torque",
            "current": "no measured current",
            "velocity": "computed from the position difference over the sample interval "
            "(low-pass filtered)",
            "target_velocity": "no CSV",
            "target_torque": "no CST",
        }
        from_current = self.transport.torque_from_current
        out = []
        for field, what in how.items():
            for i in np.flatnonzero(~self.present(field)):
                if field == "torque" and from_current[i]:
                    what_i = "computed from the current x torque_constant x gear_ratio"
                else:
                    what_i = what
                out.append(f"axis {i} ({self.names[i]}): {field} not mapped: {what_i}")
        return out

    def feedforward_notes(self, mode: Mode | int = Mode.CSP) -> list[str]:
        """One line per axis whose drive has no torque offset (0x60B2) mapped, saying what
        becomes of the gravity feed-forward in ``mode`` (the loop prints them at start-up;
        setup, not the tick). The profile's fallback says which: ``target_torque_in_cst``
        (the feed-forward is part of the target torque in CST, absent in CSP/CSV) or
        ``unavailable``."""
        profiles = getattr(self.transport, "profiles", None) or [None] * self.n
        cst = int(mode) == Mode.CST
        out = []
        for i in np.flatnonzero(~self.present("torque_offset")):
            p = profiles[i]
            how = "unavailable" if p is None else p.fallbacks.get("torque_offset", "unavailable")
            who = f"axis {i} ({self.names[i]}): no torque offset 0x60B2 mapped"
            if how == "target_torque_in_cst" and cst:
                continue  # the target torque carries the whole command, feed-forward included
            if how == "target_torque_in_cst":
                out.append(
                    f"{who}: the gravity feed-forward reaches this drive only through the "
                    f"target torque in CST; in {Mode(int(mode)).name} this joint runs without it"
                )
            else:
                out.append(f"{who}: no gravity feed-forward on this joint (profile: unavailable)")
        return out

    def _adapter(self) -> Any:
        return getattr(getattr(self.transport, "wire", None), "adapter", None)

    def drive_units(self, axis: int) -> tuple[float, float]:
        """(counts/s per unit of the velocities, counts/s² per unit of the accelerations)
        ``axis``'s drive takes: its profile's ``units`` (rpm, rpm/s, rev/s²), (1, 1) for
        counts. For the setup writes in those units (homing 0x6099/0x609A)."""
        adapter = self._adapter()
        if adapter is None:
            return 1.0, 1.0
        return float(adapter.vel_from_drive[axis]), float(adapter.accel_unit[axis])

    def _accel_unit(self, axis: int) -> float:
        """counts/s² per unit of the accelerations ``axis``'s drive takes (0x6083-0x6085;
        its profile's ``units.acceleration``)."""
        adapter = self._adapter()
        return 1.0 if adapter is None else float(adapter.accel_unit[axis])

    def set_mode(self, mode: Mode | int) -> None:
        """Select the mode of operation on every axis and wait for 0x6061 to show it.

        CSP on an axis whose drive has no cyclic synchronous mode selects the mode its
        profile runs instead (interpolated position 7 or profile velocity 3; the loop keeps
        commanding positions, :mod:`drivers.cia402.csp_adapter`); a profile-velocity axis
        gets its profile acceleration and deceleration 0x6083/0x6084 from
        :attr:`profile_acceleration` first. Axes whose drive does not map 0x6060 get it by
        SDO; those that do not map 0x6061 have it read by SDO (and kept as the canonical
        mode display of that axis)."""
        mode = Mode(int(mode))
        adapter = self._adapter()
        modes = np.full(self.n, int(mode), dtype=np.int8)
        if mode == Mode.CSP and adapter is not None:
            np.copyto(modes, adapter.csp_modes)
        np.copyto(self._rx_mode, modes)
        t = self.transport
        if mode == Mode.CSP and adapter is not None and self.profile_acceleration is not None:
            for i in np.flatnonzero(adapter.pv):
                accel = float(self.profile_acceleration[i])
                raw = max(1, self.scaling.acceleration_to_raw(int(i), accel, adapter.accel_unit[i]))
                t.write_value(int(i), 0x6083, 0, "u32", raw)
                t.write_value(int(i), 0x6084, 0, "u32", raw)
        for i in np.flatnonzero(~self.present("mode")):
            t.write_value(int(i), 0x6060, 0, "i8", int(modes[i]))
        by_sdo = [int(i) for i in np.flatnonzero(~self.present("mode_display"))]
        for _ in range(self.timeout_cycles):
            self._step()
            for i in by_sdo:
                t.wire.set_default(i, "mode_display", t.read_value(i, 0x6061, 0, "i8"))
                self._tx_mode[i] = t.wire.defaults["mode_display"][i]
            np.equal(self._tx_mode, modes, out=self._flags)
            if self._flags.all():
                return
        bad = int(np.flatnonzero(self._tx_mode != modes)[0])
        shown = int(self._tx_mode[bad])
        shown_name = Mode(shown).name if shown in Mode._value2member_map_ else "unknown mode"
        want = Mode(int(modes[bad]))
        raise DriveTimeoutError(
            f"axis {bad} ({self.names[bad]}): mode of operation display 0x6061 shows "
            f"{shown} ({shown_name}) {self.transition_timeout:g} s after selecting "
            f"{int(want)} ({want.name}); {self._describe(bad)}",
            bad,
            int(self.states[bad]),
            int(self._tx_sw[bad]),
        )

    def enable(self) -> None:
        """Bring every axis to Operation enabled, bumpless (see :meth:`hold`): CSP holds the
        measured position, CSV commands zero velocity, CST applies the torque the caller
        commanded before (e.g. gravity) from the first enabled cycle.

        Raises DriveFaultError if an axis is (or falls) in Fault (call :meth:`fault_reset`
        first; faults latch), DriveError naming the axis while its safe torque off is active
        (0x60FD, ``sm.DIN_STO``: no power stage, not a fault) and DriveTimeoutError if an axis
        stays in one state longer than the transition timeout, or an axis in interpolated
        position mode does not acknowledge "enable ip mode" (statusword bit 12) within it.
        """
        self._drive_to(State.OPERATION_ENABLED, hold=True)
        adapter = self._adapter()
        if adapter is not None and adapter.ip.any():
            self._await_ip(adapter.ip & (self._tx_mode == Mode.INTERPOLATED_POSITION))

    def _await_ip(self, ip: np.ndarray) -> None:
        """Cycle (holding) until every ``ip`` axis reports ip mode active (statusword bit 12:
        the drive took controlword bit 4, which the adapter sets once it is enabled)."""
        from drivers.cia402.csp_adapter import SW_IP_ACTIVE

        for _ in range(self.timeout_cycles + 2):
            self.hold()
            self._step()
            if self.any_fault():
                self._raise_fault()
            if not ((self._tx_sw & SW_IP_ACTIVE) == 0)[ip].any():
                return
        i = int(np.flatnonzero(ip & ((self._tx_sw & SW_IP_ACTIVE) == 0))[0])
        raise DriveTimeoutError(
            f"axis {i} ({self.names[i]}): interpolated position mode not active "
            f"{self.transition_timeout:g} s after controlword bit 4 (enable ip mode) in "
            "Operation enabled: statusword bit 12 stays 0 (check 0x60C2, the interpolation "
            f"period, is the loop period); {self._describe(i)}" + self._bus_note(),
            i,
            int(self.states[i]),
            int(self._tx_sw[i]),
        )

    def disable(self) -> None:
        """Bring every axis to Switch on disabled (power stage off, brakes closed)."""
        self._drive_to(State.SWITCH_ON_DISABLED, hold=True, allow_fault=True)

    def _drive_to(self, target: State, hold: bool, allow_fault: bool = False) -> None:
        n = self.n
        self.cycle()
        enabling = target == State.OPERATION_ENABLED
        if enabling:
            sto = self.sto_axes()
            if sto:
                names = ", ".join(f"axis {i} ({self.names[i]})" for i in sto)
                where = ", ".join(sorted({self._sto_where(i) for i in sto}))
                raise DriveError(
                    f"{names}: safe torque off is active ({where}): the power stage cannot be "
                    "switched on; release STO, then enable"
                )
        since = np.zeros(n, dtype=np.int64)
        last = self.states.copy()
        seen = np.zeros(n, dtype=bool)
        for k in range(1, 100 * self.timeout_cycles):
            if not allow_fault and self.any_fault():
                self._raise_fault()
            if enabling and self.sto_in_image(seen, by_state=False).any():
                self._sto_while_enabling(int(np.flatnonzero(seen)[0]))
            at = self.states == target
            if allow_fault:
                at |= self.states == State.FAULT
            if at.all():
                return
            moved = self.states != last
            since[moved] = k
            last[:] = self.states
            late = ~at & (k - since > self.timeout_cycles)
            if late.any():
                i = int(np.flatnonzero(late)[0])
                sto = ""
                if enabling and i in self.sto_axes():
                    sto = f"; safe torque off active ({self._sto_where(i)})"
                    self._rx_cw.fill(sm.CW_DISABLE_VOLTAGE)  # as when STO is seen at once:
                    self.hold()  # nothing left half enabled
                    self._step()
                elif enabling and self.states[i] == State.SWITCH_ON_DISABLED:
                    sto = "; safe torque off active? (the drive stays in switch on disabled)"
                raise DriveTimeoutError(
                    f"axis {i} ({self.names[i]}): no transition toward {STATE_NAMES[target]} "
                    f"within {self.transition_timeout:g} s; {self._describe(i)}{sto}"
                    + self._bus_note(),
                    i,
                    int(self.states[i]),
                    int(self._tx_sw[i]),
                )
            sm.controlwords_toward_no_reset(self.states, target, self._cw)
            np.copyto(self._rx_cw, self._cw)
            if hold:
                self.hold()
            self._step()
        raise DriveTimeoutError(f"drives did not reach {STATE_NAMES[target]}")

    def _sto_where(self, i: int) -> str:
        src = self.sto_sources[i]
        if src.source == "state":
            return "drive state"
        return f"0x{src.index:04X}:{src.subindex:02X} bit {src.bit}"

    def _sto_while_enabling(self, i: int) -> None:
        """STO became active on axis ``i`` while the group was being enabled: the defined
        outcome is every axis commanded to Disable voltage (power off, brakes close) for a
        cycle and one line naming the axis; nothing is left half enabled."""
        self._rx_cw.fill(sm.CW_DISABLE_VOLTAGE)
        self.hold()
        self._step()
        raise DriveError(
            f"axis {i} ({self.names[i]}): safe torque off became active while enabling "
            f"({self._sto_where(i)}): enabling stopped, every drive commanded to disable "
            "voltage; release STO, then enable again",
            i,
            int(self.states[i]),
            int(self._tx_sw[i]),
        )

    def quick_stop(self, timeout: float = 5.0) -> None:
        """Quick stop every enabled axis (ramp 0x6085), wait until all are disabled.

        ``timeout`` [s] covers the whole ramp. Axes already off stay off.
        """
        self.cycle()
        enabled = self.states == State.OPERATION_ENABLED
        cw = np.where(enabled, sm.CW_QUICK_STOP, sm.CW_DISABLE_VOLTAGE)
        np.copyto(self._rx_cw, cw, casting="unsafe")
        cycles = max(1, round(timeout / self.transport.cycle_time))
        for _ in range(cycles):
            self._step()
            # Option codes 5-8 hold in Quick stop active once stopped: that also counts.
            st = self.states
            done = (st == State.SWITCH_ON_DISABLED) | (st == State.FAULT)
            done |= (st == State.QUICK_STOP_ACTIVE) & (np.abs(self.qd) < 1e-3)
            if done.all():
                np.copyto(self._rx_cw, sm.CW_DISABLE_VOLTAGE)
                return
        i = int(np.flatnonzero(~done)[0])
        raise DriveTimeoutError(
            f"axis {i} ({self.names[i]}): quick stop not finished within {timeout:g} s; "
            f"{self._describe(i)}",
            i,
            int(self.states[i]),
            int(self._tx_sw[i]),
        )

    def fault_reset(self) -> None:
        """Reset latched faults (rising edge of controlword bit 7) and wait for the result.

        Raises DriveFaultError naming the axis and decoded 0x603F code when a fault stays.
        """
        self.cycle()
        faulted = self.states == State.FAULT
        if not faulted.any():
            return
        self._rx_cw[faulted] = sm.CW_DISABLE_VOLTAGE  # bit 7 low first: the edge must rise
        self._step()
        self._rx_cw[faulted] = sm.CW_FAULT_RESET
        for _ in range(self.timeout_cycles):
            self._step()
            if not (self.states[faulted] == State.FAULT).any():
                break
        self._rx_cw[faulted] = sm.CW_DISABLE_VOLTAGE
        self._step()
        if (self.states == State.FAULT).any():
            self._raise_fault(prefix="fault reset refused, cause still present: ")

    # ---------------------------------------------------------------- faults

    def error_code(self, axis: int) -> int:
        """0x603F of ``axis`` read by SDO (falls back to the PDO value if the SDO fails:
        an abort or a mailbox failure, both :class:`~drivers.errors.TransportError`)."""
        try:
            return self.transport.read_value(axis, 0x603F, 0, "u16")
        except TransportError:
            return int(self._tx_err[axis])

    def fault_messages(self) -> list[str]:
        """One plain-words line per axis in Fault / Fault reaction active (reads 0x603F)."""
        out = []
        for i in range(self.n):
            if self.states[i] in _FAULTY:
                out.append(
                    f"axis {i} ({self.names[i]}): {self._describe(i)}: "
                    f"{describe_error_code(self.error_code(i))}"
                )
        return out

    def _raise_fault(self, prefix: str = "") -> None:
        for i in range(self.n):
            if self.states[i] in _FAULTY:
                code = self.error_code(i)
                raise DriveFaultError(
                    f"{prefix}axis {i} ({self.names[i]}): {self._describe(i)}: "
                    f"{describe_error_code(code)}",
                    i,
                    int(self.states[i]),
                    int(self._tx_sw[i]),
                    code,
                )
        raise DriveError(f"{prefix}statusword matches no CiA 402 state")

    def _describe(self, i: int) -> str:
        return sm.describe_statusword(int(self._tx_sw[i]))

    def _bus_note(self) -> str:
        return "" if self.status == 0 else f" (last bus status: {describe_status(self.status)})"
