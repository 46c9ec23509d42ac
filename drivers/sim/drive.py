"""Emulated CiA-402 servo drives on the simulated arm (:class:`drivers.sim.plant.Plant`).

:class:`EmulatedDrives` is a group of n drives, one per joint, sharing one plant. Each cycle
:meth:`EmulatedDrives.step` takes the RxPDO records (shape (n,)), runs every drive's state
machine and control loops, applies the joint torques to the plant for one tick and writes
the TxPDO records. EtherCAT and CANopen emulators and the in-process SimBus all drive this
class; each drive's :class:`~drivers.sim.object_dictionary.ObjectDictionary` is in ``ods``.

Per drive (all in joint-side SI internally, raw units only at the process image):
- CiA 402 state machine (drivers.cia402.state_machine), quick-stop option codes 0-8;
- modes CSP (cascaded P position / PI velocity loop with velocity feed-forward from the
  target increments), CSV (PI velocity loop) and CST (torque), torque offset 0x60B2 in all;
- for a drive impersonating a profile that has them: interpolated position (7: the CSP
  loops on the target 0x60C1:01, active only while controlword bit 4 is set in Operation
  enabled and an interpolation period 0x60C2 is set, acknowledged in statusword bit 12;
  inactive it holds where it was; the feed-forward is the target's change per 0x60C2
  period) and profile velocity (3: the PI velocity loop on the target velocity 0x60FF
  ramped with the profile acceleration/deceleration 0x6083/0x6084; statusword bit 12
  "speed zero", bit 10 "target reached");
- torque limit 0x6072, quick-stop ramp 0x6085 then disable, following-error supervision
  0x6065/0x6066, communication watchdog;
- a motor holding brake while the power stage is off (the plant has none): a saturated
  spring-damper holding the position where the brake closed, so a disabled arm stays put;
  by default ideal (closes and opens with the power stage, the velocity integrator starts at
  the torque it held); :meth:`EmulatedDrives.configure_brake` makes an axis's brake real:
  it opens ``release_delay`` after Operation enabled and closes ``engage_delay`` after the
  power stage goes off, acts on top of the motor while closed, holds at most
  ``holding_torque`` (a worn brake slips) and the integrator starts at zero (the drive does
  not know the load: the torque offset 0x60B2 is how a master preloads gravity);
- fault injection (:meth:`EmulatedDrives.inject_fault`) with the CiA 402 error codes;
- homing mode 6 (0x6098 method, 0x6099 speeds, 0x609A acceleration, 0x607C home offset;
  controlword bit 4 starts, statusword bits 10/12/13): method 35 (37) sets the current
  position as home; method 17 searches the home switch (:meth:`EmulatedDrives.
  set_home_switch`) in the negative direction at the switch speed, returns at the zero speed
  to its edge and makes that edge the home offset; methods 1 (2) search the negative
  (positive) limit switch the same way, then go on away from it at the zero speed to the
  next index pulse of the encoder (one per motor revolution, :meth:`EmulatedDrives.
  set_index_phase`), which becomes home; 33 (34) go from where the axis is to the next
  index pulse below (above); no switch or pulse within ``homing_travel`` or an unsupported
  method ends in homing error. Homing redefines the drive's position (0x6064 and the
  targets it takes), never the plant;
- a brake delay object (0x2110:1/2, ms, what a master writes to a drive-controlled brake)
  and a stuck brake (``brake_stuck``): it does not open and the drive faults with the
  manufacturer-specific brake code 0xFF21 after the release delay.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.cia402 import state_machine as sm
from drivers.cia402.pdo import ImageFields, new_rx, new_tx
from drivers.cia402.profiles import BRAKE_FAULT_CODE, BRAKE_OBJECT
from drivers.cia402.state_machine import Command, Mode, State
from drivers.cia402.units import AxisScaling, Scaling
from drivers.sim.object_dictionary import (
    DriveObjects,
    ObjectDictionary,
    OdEntry,
    cia402_dictionary,
    impersonate,
)
from drivers.sim.plant import Plant
from hofto_hw.config.drive_profile import MODE_NUMBERS
from hofto_hw.config.drives import DriveConfig
from hofto_hw.config.models import ExternalTorqueConfig

#: injectable faults -> (0x603F error code, reaction: True = ramp down first, False = torque off)
FAULTS: dict[str, tuple[int, bool]] = {
    "over_current": (0x2310, False),
    "short_circuit": (0x2320, False),
    "over_voltage": (0x3210, False),
    "under_voltage": (0x3220, False),
    "over_temperature": (0x4310, False),
    "encoder": (0x7305, False),
    "following_error": (0x8611, True),
    "comm_loss": (0x8130, True),
    "brake": (BRAKE_FAULT_CODE, False),  # holding brake fault (manufacturer-specific code)
}
CODE_FOLLOWING_ERROR = 0x8611
CODE_COMM_LOSS = 0x8130
SUPPORTED_MODES = (
    Mode.NO_MODE,
    Mode.CSP,
    Mode.CSV,
    Mode.CST,
    Mode.HOMING,
    Mode.INTERPOLATED_POSITION,
    Mode.PROFILE_VELOCITY,
)
HOMING_METHODS = (1, 2, 17, 33, 34, 35, 37)
# homing progress per axis
_H_IDLE, _H_SEARCH, _H_BACK, _H_STOP, _H_DONE, _H_ERROR, _H_INDEX = range(7)

# Plain ints for the per-cycle code (enum attribute access is slow).
_NR, _SOD, _RTSO, _SO, _OE, _QSA, _FRA, _FLT = (int(s) for s in list(State)[:8])
_CSP, _CSV, _CST, _HM = int(Mode.CSP), int(Mode.CSV), int(Mode.CST), int(Mode.HOMING)
_IP, _PV = int(Mode.INTERPOLATED_POSITION), int(Mode.PROFILE_VELOCITY)
_CW_ENABLE_IP = 0x0010  # controlword bit 4 in ip mode
_PV_SPEED_ZERO = 0.01  # [rad/s] below which pv reports speed zero (statusword bit 12)
_N_COMMANDS = len(Command)
_POWERED = (_OE, _QSA, _FRA)
_WATCHED = (_SO, *_POWERED)  # states that fault when the bus goes silent
_STO_BLOCKED = (_RTSO, _SO, *_POWERED)
_NEXT = sm.NEXT_STATE.ravel().copy()
_NEXT_HOLD = sm.NEXT_STATE_QS_HOLD.ravel().copy()
#: per state code: needs an automatic transition check after the plant step
_HAS_AUTOMATIC = np.array([s in (_NR, _QSA, _FRA) for s in range(len(State))])
#: per state code: statusword state bits + remote + voltage enabled
_STATUS_BASE = np.array(
    [
        int(sm.STATUS_FROM_STATE[s])
        | sm.SW_REMOTE
        | (sm.SW_VOLTAGE_ENABLED if s in (_RTSO, _SO, *_POWERED) else 0)
        for s in range(len(State))
    ],
    dtype=np.uint16,
)
#: per mode byte (as uint8): supported by the emulated drive
_MODE_SUPPORTED = np.array([(m - 256 if m > 127 else m) in SUPPORTED_MODES for m in range(256)])
#: error-register (0x1001) bit per error class: generic, current, voltage, temperature, comm
_ERROR_REGISTER = {0x2: 0x03, 0x3: 0x05, 0x4: 0x09, 0x8: 0x11}


@dataclass(frozen=True)
class LoopTuning:
    """Drive control-loop gains per axis, joint side, arrays of shape (n,).

    position_gain [1/s]; velocity_gain [N·m·s/rad]; velocity_integral [N·m/rad];
    brake stiffness [N·m/rad], damping [N·m·s/rad] and holding torque [N·m].
    """

    position_gain: np.ndarray
    velocity_gain: np.ndarray
    velocity_integral: np.ndarray
    brake_stiffness: np.ndarray
    brake_damping: np.ndarray
    brake_torque: np.ndarray

    @classmethod
    def from_inertia(
        cls, inertia: np.ndarray, torque_limit: np.ndarray, bandwidth: float = 150.0
    ) -> LoopTuning:
        """Gains for a velocity-loop ``bandwidth`` [rad/s] on joints of ``inertia`` [kg·m²].

        PI zero and position gain at a quarter of the bandwidth; brake at twice it.
        """
        j = np.asarray(inertia, dtype=float)
        kv = j * bandwidth
        wb = 2.0 * bandwidth
        return cls(
            position_gain=np.full(j.shape, bandwidth / 4.0),
            velocity_gain=kv,
            velocity_integral=kv * bandwidth / 4.0,
            brake_stiffness=j * wb * wb / 4.0,
            brake_damping=j * wb,
            brake_torque=2.0 * np.asarray(torque_limit, dtype=float),
        )


class EmulatedDrives(ImageFields):
    """n emulated CiA-402 drives driving one plant; see the module docstring.

    ``rx``/``tx``: the drives' own process images (shape (n,)), what their object
    dictionaries read and write. ``watchdog_cycles``: cycles without an RxPDO before a
    powered drive faults with 0x8130 (communication lost).
    """

    def __init__(
        self,
        plant: Plant,
        drives: Sequence[DriveConfig],
        *,
        tuning: LoopTuning | None = None,
        watchdog_cycles: int = 3,
        names: Sequence[str] | None = None,
        profiles: Sequence[Any] | None = None,
    ) -> None:
        n = plant.n
        if len(drives) != n:
            raise ValueError(f"{len(drives)} drive configs for a plant with {n} joints")
        self.plant = plant
        self.n = n
        self.dt = plant.dt
        self.names = list(names) if names else [f"drive{i}" for i in range(n)]
        self.scaling = Scaling([AxisScaling.from_config(d) for d in drives])
        self.watchdog_cycles = int(watchdog_cycles)
        sc = self.scaling

        self.rx = new_rx(n)
        self.tx = new_tx(n)
        self.max_torque = np.array(
            [sc.torque_limit_permille(i, d.torque_limit) for i, d in enumerate(drives)],
            dtype=np.uint16,
        )
        self.quick_stop_decel = np.array(
            [sc.acceleration_to_raw(i, d.quick_stop_deceleration) for i, d in enumerate(drives)],
            dtype=np.uint32,
        )
        self.following_window = np.array(
            [sc.angle_to_counts(i, d.following_error_window) for i, d in enumerate(drives)],
            dtype=np.uint32,
        )
        self.following_timeout = np.array(
            [round(d.following_error_timeout * 1000.0) for d in drives], dtype=np.uint16
        )
        #: counts/s per unit of the velocities the drive takes and reports (0x60FF, 0x606C)
        #: and counts/s² per unit of its accelerations (0x6083-0x6085): 1 unless the
        #: profile it impersonates says rpm / rpm/s (``units``)
        self.velocity_unit, self.acceleration_unit = np.ones(n), np.ones(n)
        #: encoder counts per motor revolution per axis (the config's)
        self.counts_per_rev = [d.counts_per_rev for d in drives]
        for i, (d, prof) in enumerate(zip(drives, profiles or [None] * n, strict=True)):
            if prof is not None:
                self.velocity_unit[i], self.acceleration_unit[i] = prof.units.counts_per_drive_unit(
                    d.counts_per_rev
                )
        scaled = self.acceleration_unit != 1.0  # 0x6085 in the drive's unit (rpm/s)
        np.copyto(
            self.quick_stop_decel,
            np.maximum(1.0, np.rint(self.quick_stop_decel / self.acceleration_unit)),
            where=scaled,
            casting="unsafe",
        )
        self.quick_stop_option = np.full(n, 2, dtype=np.int16)
        self.error_register = np.zeros(n, dtype=np.uint8)
        objs = DriveObjects(
            self.rx,
            self.tx,
            self.max_torque,
            self.quick_stop_decel,
            self.following_window,
            self.following_timeout,
            self.quick_stop_option,
            self.error_register,
        )
        self.ods: list[ObjectDictionary] = []
        #: some drive impersonates a profile with ip / pv (their objects and loops exist)
        self._ip_pv_drive = False
        for i, d in enumerate(drives):
            motor, shaft = _gear_fraction(d.gear_ratio)
            self.ods.append(
                cia402_dictionary(
                    i,
                    objs,
                    vendor_id=d.identity.vendor_id,
                    product_code=d.identity.product_code,
                    revision=d.identity.revision or 0,
                    serial=0x5100 + i,
                    device_name=f"hofto-sim servo {self.names[i]}",
                    counts_per_rev=d.counts_per_rev,
                    gear_motor_revs=motor,
                    gear_shaft_revs=shaft,
                    rated_torque_mnm=round(d.rated_torque),
                    rated_current_ma=round(d.rated_current),
                )
            )
            prof = profiles[i] if profiles is not None else None
            if prof is not None:
                self._mode_objects(i, self.ods[-1], prof.modes.supported)
                impersonate(self.ods[-1], prof, serial=0x5100 + i)
        #: the profile each drive impersonates (None: the built-in hofto-sim drive)
        self.profiles = list(profiles) if profiles is not None else [None] * n

        self._ip_hold = plant.q_meas.copy()  # where an ip drive holds while ip is inactive
        self._ip_on = np.zeros(n, dtype=bool)
        self._ip_was = np.zeros(n, dtype=bool)
        self._ipm = np.zeros(n, dtype=bool)
        self._pvm = np.zeros(n, dtype=bool)
        self._pv_v = np.zeros(n)  # the pv ramp's velocity [rad/s]
        self._ff = np.ones(n)  # CSP / ip feed-forward scale: loop period / ip period
        # ip / pv scratch (no temporaries in a cycle), and whether the last cycle ran neither
        self._ip_any = np.zeros(n, dtype=bool)
        self._ip_b = np.zeros(n, dtype=bool)
        self._ip_per = np.zeros(n)
        self._ip_ffv = np.zeros(n)
        self._ip_idle = False
        # Homing (mode 6): objects in raw units, drive-internal progress and position shift.
        self.homing_method = np.full(n, 35, dtype=np.int8)  # 0x6098
        self.homing_speeds = np.zeros((2, n), dtype=np.uint32)  # 0x6099:1 switch, :2 zero
        self.homing_accel = np.zeros(n, dtype=np.uint32)  # 0x609A
        self.home_offset = np.zeros(n, dtype=np.int32)  # 0x607C
        for i, od in enumerate(self.ods):
            od.add_var(0x607C, "home offset", "i32", "rw", bound=(self.home_offset, i))
            od.add_var(0x6098, "homing method", "i8", "rw", bound=(self.homing_method, i))
            od.add_record(
                0x6099,
                "homing speeds",
                [
                    OdEntry(
                        0x6099,
                        1,
                        "speed during search for switch",
                        "u32",
                        "rw",
                        bound=(self.homing_speeds[0], i),
                    ),
                    OdEntry(
                        0x6099,
                        2,
                        "speed during search for zero",
                        "u32",
                        "rw",
                        bound=(self.homing_speeds[1], i),
                    ),
                ],
            )
            od.add_var(0x609A, "homing acceleration", "u32", "rw", bound=(self.homing_accel, i))
        # 0x60FE digital outputs: bit 0 releases the brake of an axis whose brake the
        # master drives (configure_brake(by_output=True)); power off closes it regardless and
        # clears the bit (as real drives may: the master must set it again after a re-enable;
        # ``clears_output`` False keeps it, the emulator of before)
        self.digital_outputs = np.zeros(n, dtype=np.uint32)
        self.output_mask = np.full(n, 0xFFFFFFFF, dtype=np.uint32)
        for i, od in enumerate(self.ods):
            od.add_record(
                0x60FE,
                "digital outputs",
                [
                    OdEntry(
                        0x60FE, 1, "physical outputs", "u32", "rw", bound=(self.digital_outputs, i)
                    ),
                    OdEntry(0x60FE, 2, "bit mask", "u32", "rw", bound=(self.output_mask, i)),
                ],
            )
        # vendor object 0x2110 (drivers.cia402.profiles.BRAKE_OBJECT): the brake release
        # (:1) and engage (:2) delays [ms], what a master writes to a drive-controlled brake
        self.brake_delay_ms = np.zeros((2, n), dtype=np.uint16)
        for i, od in enumerate(self.ods):
            od.add_record(
                BRAKE_OBJECT,
                "holding brake timing",
                [
                    OdEntry(
                        BRAKE_OBJECT, 1, "brake release delay [ms]", "u16", "rw",
                        bound=(self.brake_delay_ms[0], i),
                    ),
                    OdEntry(
                        BRAKE_OBJECT, 2, "brake engage delay [ms]", "u16", "rw",
                        bound=(self.brake_delay_ms[1], i),
                    ),
                ],
            )  # fmt: skip
        #: a brake that does not open when released (its drive then faults with
        #: BRAKE_FAULT_CODE once the release delay is over)
        self.brake_stuck = np.zeros(n, dtype=bool)
        #: true joint position of each axis's home switch edge [rad] (nan: no switch)
        self.home_switch = np.full(n, np.nan)
        #: travel [rad] a switch search may cover before it ends in homing error
        self.homing_travel = np.full(n, math.pi)
        self.homing = np.zeros(n, dtype=np.uint8)
        self._home_shift = np.zeros(n)  # drive position = plant position + shift [rad]
        self._home_v = np.zeros(n)
        self._home_start_q = np.zeros(n)
        self._home_prev_q = np.zeros(n)
        self._home_dir = np.full(n, -1.0)
        #: true joint position above which method 2's positive limit switch is made [rad]
        self.positive_switch = np.full(n, np.nan)
        #: the encoder's index pulse: once per motor revolution, at true joint positions
        #: ``index_phase + k·index_pitch`` [rad] (pitch: one motor turn through the gear)
        self.index_pitch = np.array([2.0 * math.pi / abs(d.gear_ratio) for d in drives])
        self.index_phase = np.zeros(n)
        self._hm = np.zeros(n, dtype=bool)

        if tuning is None:
            inertia = np.diag(plant.data.mass_matrix(plant.q)).copy()
            limit = np.array([d.torque_limit for d in drives])
            # Velocity-loop bandwidth: 150 rad/s, lower on slow buses (the loops run once per
            # cycle and the measurement is one cycle old: keep bandwidth·dt <= 0.2).
            tuning = LoopTuning.from_inertia(inertia, limit, min(150.0, 0.2 / self.dt))
        self.tuning = tuning

        # Drive-internal state.
        self.state = np.full(n, State.NOT_READY_TO_SWITCH_ON, dtype=np.uint8)
        self.mode_display = np.zeros(n, dtype=np.int8)
        self.prev_controlword = np.zeros(n, dtype=np.uint16)
        self.fault_code = np.zeros(n, dtype=np.uint16)
        self.fault_ramp = np.zeros(n, dtype=bool)
        self.fault_persistent = np.zeros(n, dtype=bool)
        self.encoder_failed = np.zeros(n, dtype=bool)
        self.sto = np.zeros(n, dtype=bool)
        self.missed_cycles = 0
        self._pending: list[tuple[int, int, bool]] = []
        self._fe_cycles = np.zeros(n, dtype=np.int64)
        self._integral = np.zeros(n)
        self._ramp_v = np.zeros(n)
        self._brake_q = plant.q_meas.copy()
        self._prev_target = np.zeros(n)
        self._target_valid = np.zeros(n, dtype=bool)
        self._md_prev = np.zeros(n, dtype=np.int8)
        self._md_changed = np.zeros(n, dtype=bool)
        self._limited = np.zeros(n, dtype=bool)
        self._fe_flag = np.zeros(n, dtype=bool)
        # Precomputed factors and process-image field views.
        self._abs_rpc = np.abs(sc.rad_per_count)
        self._acc_rpc = self._abs_rpc * self.acceleration_unit  # rad/s² per accel unit
        self._abs_nm = np.abs(sc.nm_per_permille)
        self._ki_dt = tuning.velocity_integral * self.dt
        self._neg_brake = -tuning.brake_torque
        self._inv_dt = 1.0 / self.dt
        self._encoder_ok = np.ones(n, dtype=bool)
        # Real brakes (configure_brake): physical state, delays [s], holding torque [N·m].
        self.real_brake = np.zeros(n, dtype=bool)
        self.brake_by_output = np.zeros(n, dtype=bool)
        self.brake_clears_output = np.ones(n, dtype=bool)
        self.brake_engaged = np.ones(n, dtype=bool)
        self.brake_release_delay = np.zeros(n)
        self.brake_engage_delay = np.zeros(n)
        self.brake_holding = np.zeros(n)
        self._brake_target = np.ones(n, dtype=bool)
        self._brake_timer = np.zeros(n)
        #: [s] left of holding the motor at zero velocity while a real brake engages after
        #: a controlled stop (the drive removes power only once the brake holds)
        self.brake_hold_time = np.zeros(n)
        #: added to the reported position 0x6064 only [rad]: an encoder or transmission
        #: glitch the drive's own loop does not see (:meth:`jump_position`)
        self.position_offset = np.zeros(n)
        self._q_rep = np.zeros(n)
        self._bind_image(self.rx, self.tx)
        self._rx_mode_u8 = self._rx_mode.view(np.uint8)
        # per drive and mode byte: whether the drive takes the mode (a drive impersonating a
        # profile only the modes its profile has, e.g. the Faulhaber no ip: 0x6060 <= 6)
        table = np.tile(_MODE_SUPPORTED, (n, 1))
        for i, prof in enumerate(self.profiles):
            if prof is not None:
                has = {0} | {MODE_NUMBERS[m] for m in prof.modes.supported}
                table[i] &= [(m - 256 if m > 127 else m) in has for m in range(256)]
        self._mode_table = table.ravel()
        self._mode_base = np.arange(n, dtype=np.intp) * 256
        self._mode_flat = np.zeros(n, dtype=np.intp)
        # Scratch (no allocation per cycle).
        f = np.zeros
        self._tau, self._qt, self._vt, self._tt, self._toff = (f(n) for _ in range(5))
        self._vcmd, self._err, self._lim, self._neg_lim = (f(n) for _ in range(4))
        self._w, self._w2, self._w3 = f(n), f(n), f(n)
        (
            self._b1,
            self._enabled,
            self._csp,
            self._csv,
            self._cst,
            self._ramping,
            self._loop,
            self._active,
        ) = (f(n, dtype=bool) for _ in range(8))
        self._u16 = f(n, dtype=np.uint16)
        self._cmd = f(n, dtype=np.uint8)
        self._next = f(n, dtype=np.uint8)
        self._next_hold = f(n, dtype=np.uint8)
        self._flat = f(n, dtype=np.intp)
        self._pos_raw = f(n, dtype=np.int32)
        for i, d in enumerate(drives):  # brakes the config describes are real
            b = getattr(d, "brake", None)
            if b is not None:
                self.configure_brake(
                    i, b.release_delay, b.engage_delay, b.holding_torque, b.control == "output"
                )
        self._update_tx()

    def _mode_objects(self, i: int, od: ObjectDictionary, modes: Sequence[str]) -> None:
        """The objects of interpolated position / profile velocity for a drive whose
        profile supports them (bound to this drive's arrays)."""
        if not self._ip_pv_drive:
            self._ip_pv_drive = True
            n = self.n
            #: 0x60C2:01 interpolation period value, 0x60C2:02 its exponent (10^x s)
            self.ip_period = np.zeros(n, dtype=np.uint8)
            self.ip_exponent = np.full(n, -3, dtype=np.int8)
            #: 0x60C0 interpolation sub-mode (0: linear)
            self.ip_submode = np.zeros(n, dtype=np.int16)
            #: 0x6083 / 0x6084 profile acceleration / deceleration [counts/s²]
            self.profile_accel = np.zeros(n, dtype=np.uint32)
            self.profile_decel = np.zeros(n, dtype=np.uint32)
        if "ip" in modes:
            od.add_var(0x60C0, "interpolation sub mode select", "i16", "rw",
                       bound=(self.ip_submode, i), pdo_mappable=True)  # fmt: skip
            od.add_record(
                0x60C1,
                "interpolation data record",
                [
                    OdEntry(
                        0x60C1,
                        1,
                        "X1: position",
                        "i32",
                        "rw",
                        pdo_mappable=True,
                        bound=(self.rx["target_position"], i),
                    ),
                    OdEntry(0x60C1, 2, "X2", "i32", "rw", pdo_mappable=True),
                ],
            )
            od.add_record(
                0x60C2,
                "interpolation time period",
                [
                    OdEntry(
                        0x60C2,
                        1,
                        "interpolation time period value",
                        "u8",
                        "rw",
                        bound=(self.ip_period, i),
                    ),
                    OdEntry(
                        0x60C2,
                        2,
                        "interpolation time index",
                        "i8",
                        "rw",
                        bound=(self.ip_exponent, i),
                    ),
                ],
            )
        if "pv" in modes:
            od.add_var(0x6083, "profile acceleration", "u32", "rw",
                       bound=(self.profile_accel, i), pdo_mappable=True)  # fmt: skip
            od.add_var(0x6084, "profile deceleration", "u32", "rw",
                       bound=(self.profile_decel, i), pdo_mappable=True)  # fmt: skip

    def reset(self, q0: np.ndarray, qd0: np.ndarray | None = None) -> None:
        """Power-cycle the drives and put the plant at ``q0`` [rad] (``qd0`` [rad/s])."""
        self.plant.reset(q0, qd0)
        self.state.fill(State.NOT_READY_TO_SWITCH_ON)
        for a in (self.mode_display, self.prev_controlword, self.fault_code, self.error_register):
            a.fill(0)
        for a in (self.fault_ramp, self.fault_persistent, self.encoder_failed, self.sto):
            a.fill(False)
        self._pending.clear()
        self.missed_cycles = 0
        self._integral.fill(0.0)
        self._ramp_v.fill(0.0)
        self._target_valid.fill(False)
        self._fe_cycles.fill(0)
        self._encoder_ok.fill(True)
        self.homing.fill(_H_IDLE)
        self.brake_engaged.fill(True)
        self._brake_target.fill(True)
        self.brake_hold_time.fill(0.0)
        self._home_v.fill(0.0)
        self._ip_on.fill(False)
        self._ip_was.fill(False)
        self._pv_v.fill(0.0)
        self._ip_idle = False
        np.copyto(self._ip_hold, self.plant.q_meas)
        np.copyto(self._brake_q, self.plant.q_meas)
        self.rx.fill(0)
        self._update_tx()

    # ------------------------------------------------------------------ faults

    def inject_fault(self, axis: int, kind: str, persistent: bool = False) -> None:
        """Make drive ``axis`` detect fault ``kind`` (a key of :data:`FAULTS`) next cycle.

        ``persistent``: the cause stays until :meth:`clear_fault`, so fault resets fail.
        ``encoder`` also freezes the reported position until cleared.
        """
        if kind not in FAULTS:
            raise ValueError(f"unknown fault {kind!r}; known: {', '.join(FAULTS)}")
        if not 0 <= axis < self.n:
            raise ValueError(f"axis {axis} does not exist ({self.n} drives)")
        code, ramp = FAULTS[kind]
        self._pending.append((axis, code, ramp))
        self.fault_persistent[axis] = persistent
        if kind == "encoder":
            self.encoder_failed[axis] = True
            self._encoder_ok[axis] = False

    def jump_position(self, axis: int, offset: float) -> None:
        """From now on report drive ``axis``'s position ``offset`` [rad] away from the true
        one (a position jump in the TxPDO; 0 puts it back)."""
        if not 0 <= axis < self.n:
            raise ValueError(f"axis {axis} does not exist ({self.n} drives)")
        self.position_offset[axis] = float(offset)

    def push_tool(self, force: Sequence[float], duration: float, ramp: float = 0.02) -> None:
        """A hand pushes the true arm's tool with ``force`` (3,) [N, world frame] from now
        for ``duration`` [s] of plant time, ramping in and out over ``ramp`` [s]."""
        f = tuple(float(x) for x in force)
        if len(f) != 3 or not all(math.isfinite(x) for x in f):
            raise ValueError(f"force must be 3 finite numbers [N], got {force!r}")
        if not (math.isfinite(duration) and duration > 0.0 and 0.0 < ramp <= duration / 2):
            raise ValueError(f"need duration > 0, 0 < ramp <= duration/2; got {duration}, {ramp}")
        c = ExternalTorqueConfig(
            kind="push", start=self.plant.t, duration=duration, force=f, ramp=ramp
        )
        self.plant.external.components.append(c)

    def set_safe_torque_off(self, axis: int, active: bool) -> None:
        """Safe torque off input of drive ``axis``: while active the power stage cannot be
        switched on (transition 2 is refused, a powered drive drops to Switch on disabled)
        and 0x60FD bit 16 is set."""
        self.sto[axis] = active

    def configure_brake(
        self,
        axis: int,
        release_delay: float,
        engage_delay: float,
        holding_torque: float,
        by_output: bool = False,
        clears_output: bool = True,
    ) -> None:
        """Give drive ``axis`` a real holding brake (see the module notes): delays [s] >= 0,
        holding torque [N·m] > 0 (below the load's torque: a worn brake that slips).
        ``by_output``: the master releases it with 0x60FE:1 bit 0 while the drive is powered
        (else the drive releases it on Operation enabled); ``clears_output``: the drive
        clears that bit when its power stage goes off (False: the bit stays set)."""
        if not (release_delay >= 0.0 and engage_delay >= 0.0 and holding_torque > 0.0):
            raise ValueError("brake delays must be >= 0 s and the holding torque > 0 N·m")
        self.real_brake[axis] = True
        self.brake_by_output[axis] = by_output
        self.brake_clears_output[axis] = clears_output
        self.brake_release_delay[axis] = release_delay
        self.brake_engage_delay[axis] = engage_delay
        self.brake_delay_ms[0, axis] = min(65535, round(release_delay * 1000.0))
        self.brake_delay_ms[1, axis] = min(65535, round(engage_delay * 1000.0))
        self.brake_holding[axis] = holding_torque
        self.brake_engaged[axis] = self._brake_target[axis] = True
        self._brake_q[axis] = self.plant.q_meas[axis]

    #: the commissioning requests both emulators' control sockets take (issue 28)
    COMMISSIONING_OPS = ("sto", "brake", "home_switch", "index_phase")

    def commissioning(self, axis: int, request: dict[str, Any]) -> dict[str, Any]:
        """One commissioning request of an emulator's control socket for drive ``axis``:
        ``sto`` (active: the STO input); ``brake`` (release_delay, engage_delay [s],
        holding_torque [N·m], by_output, stuck: configure a real brake; or only ``stuck``);
        ``home_switch`` (position [rad] or None, positive); ``index_phase`` (phase [rad]).
        Returns the reply's extra fields. ValueError on a bad request."""
        op = request["op"]
        if op == "sto":
            self.set_safe_torque_off(axis, bool(request.get("active", True)))
        elif op == "brake":
            if "holding_torque" in request:
                self.configure_brake(
                    axis,
                    float(request["release_delay"]),
                    float(request["engage_delay"]),
                    float(request["holding_torque"]),
                    bool(request.get("by_output", False)),
                )
            self.brake_stuck[axis] = bool(request.get("stuck", False))
        elif op == "home_switch":
            pos = request.get("position")
            self.set_home_switch(
                axis, None if pos is None else float(pos), bool(request.get("positive", False))
            )
        elif op == "index_phase":
            self.set_index_phase(axis, float(request["phase"]))
        else:
            raise ValueError(f"unknown op {op!r}")
        return {}

    def commissioning_status(self) -> dict[str, Any]:
        """Per drive: STO input, brake engaged, real brake, its delays as written [ms]."""
        return {
            "sto": [bool(x) for x in self.sto],
            "brake_engaged": [bool(x) for x in self.brake_engaged],
            "real_brake": [bool(x) for x in self.real_brake],
            "brake_delay_ms": [[int(x) for x in row] for row in self.brake_delay_ms],
            "home_shift": self._home_shift.tolist(),
        }

    def _command_brake(self, i: int, engaged: bool) -> None:
        self._brake_target[i] = engaged
        # the delays as the master last wrote them to 0x2110 (configure_brake sets both)
        self.brake_release_delay[i] = 1e-3 * float(self.brake_delay_ms[0, i])
        self.brake_engage_delay[i] = 1e-3 * float(self.brake_delay_ms[1, i])
        delay = self.brake_engage_delay[i] if engaged else self.brake_release_delay[i]
        self._brake_timer[i] = delay

    def set_home_switch(self, axis: int, position: float | None, positive: bool = False) -> None:
        """Put drive ``axis``'s home (negative limit) switch edge at true joint position
        ``position`` [rad] (the switch is made below it); ``positive``: the positive limit
        switch of method 2 instead (made above it). None removes the switch."""
        value = np.nan if position is None else float(position)
        if positive:
            self.positive_switch[axis] = value
        else:
            self.home_switch[axis] = value

    def set_index_phase(self, axis: int, phase: float) -> None:
        """Put drive ``axis``'s index pulses at true joint positions ``phase + k·pitch``
        [rad] (pitch: one motor revolution at the joint)."""
        self.index_phase[axis] = float(phase)

    def clear_fault(self, axis: int) -> None:
        """Remove the cause of an injected fault (a fault reset can then succeed)."""
        self.fault_persistent[axis] = False
        self.encoder_failed[axis] = False
        self._encoder_ok[axis] = True

    def _raise_fault(self, axis: int, code: int, ramp: bool) -> None:
        state = int(self.state[axis])
        if state in (_FLT, _FRA):
            return
        self.fault_code[axis] = code
        self.error_register[axis] = _ERROR_REGISTER.get(code >> 12, 0x01)
        self.fault_ramp[axis] = ramp and state in (_OE, _QSA)
        if self.fault_ramp[axis] and state == _OE:
            self._ramp_v[axis] = self.plant.qd_meas[axis]
        elif not self.fault_ramp[axis]:
            self._close_brake(axis)
        self.state[axis] = _FRA

    # ------------------------------------------------------------------- cycle

    def step(self, rx: np.ndarray | None) -> None:
        """One cycle: take ``rx`` (None = no frame arrived), control, plant step, fill tx.

        The common path (no state change, no fault) allocates no arrays.
        """
        if rx is None:
            self.missed_cycles += 1
            if self.missed_cycles > self.watchdog_cycles:
                for i in range(self.n):
                    if int(self.state[i]) in _WATCHED:
                        self._raise_fault(i, CODE_COMM_LOSS, True)
        else:
            self.missed_cycles = 0
            np.copyto(self.rx, rx)
        while self._pending:
            self._raise_fault(*self._pending.pop())
        if rx is not None:
            self._state_machine()
        if self.sto.any():
            for i in np.flatnonzero(self.sto):
                if int(self.state[i]) in _STO_BLOCKED:
                    self._close_brake(i)
                    self.state[i] = _SOD
        self._mode()
        self._control()
        self.plant.step(self._tau)
        self._automatic_transitions()
        self._update_tx()

    def _state_machine(self) -> None:
        cw = self._rx_cw
        np.bitwise_and(cw, 0x0F, out=self._u16)
        np.take(sm.COMMAND_FROM_CONTROL, self._u16, out=self._cmd)
        # Bit 7: rising edge = fault reset; held high = no command.
        np.bitwise_and(cw, 0x80, out=self._u16)
        if self._u16.any():
            for i in np.flatnonzero(self._u16):
                rising = not int(self.prev_controlword[i]) & 0x80
                self._cmd[i] = Command.FAULT_RESET if rising else Command.NONE
        np.equal(self.mode_display, _HM, out=self._hm)
        if self._hm.any():
            self._homing_edges(cw)
        np.copyto(self.prev_controlword, cw)
        np.multiply(self.state, _N_COMMANDS, out=self._flat)
        np.add(self._flat, self._cmd, out=self._flat)
        np.take(_NEXT, self._flat, out=self._next)
        np.greater_equal(self.quick_stop_option, 5, out=self._b1)
        if self._b1.any():
            np.take(_NEXT_HOLD, self._flat, out=self._next_hold)
            np.copyto(self._next, self._next_hold, where=self._b1)
        np.not_equal(self._next, self.state, out=self._b1)
        if self._b1.any():
            for i in np.flatnonzero(self._b1):
                self._enter(int(i), int(self.state[i]), int(self._next[i]))

    def _enter(self, i: int, old: int, new: int) -> None:
        if self.sto[i] and (new == _RTSO or new in _POWERED):
            return  # safe torque off: no power stage
        if old == _FLT:
            if self.fault_persistent[i]:
                return  # cause still present: stay in Fault
            self.fault_code[i] = 0
            self.error_register[i] = 0
        if new == _OE and old != _QSA:
            # Brake opens; start the integrator at the torque the brake was holding.
            self._integral[i] = 0.0 if self.real_brake[i] else self._brake_torque(i)
            if self.real_brake[i] and not self.brake_by_output[i]:
                self._command_brake(i, False)
            self._target_valid[i] = False
            self._fe_cycles[i] = 0
        elif new == _QSA:
            self._ramp_v[i] = self.plant.qd_meas[i]
            if self.quick_stop_option[i] == 0:
                new = _SOD
        if new not in _POWERED and old in _POWERED:
            controlled = old == _QSA or (old == _OE and new in (_SO, _RTSO))
            if self.real_brake[i] and controlled and not self.sto[i]:
                self.brake_hold_time[i] = self.brake_engage_delay[i]  # power until it holds
                self._ramp_v[i] = 0.0
            self._close_brake(i)
        self.state[i] = new

    def _mode(self) -> None:
        np.copyto(self._md_prev, self.mode_display)
        np.add(self._mode_base, self._rx_mode_u8, out=self._mode_flat)
        np.take(self._mode_table, self._mode_flat, out=self._b1)
        np.copyto(self.mode_display, self._rx_mode, where=self._b1)
        # a new mode starts its own interpolation: the first target of a cyclic mode after
        # another mode (homing: its target was not followed) carries no feed-forward
        np.not_equal(self._md_prev, self.mode_display, out=self._md_changed)
        np.copyto(self._target_valid, False, where=self._md_changed)

    def _control(self) -> None:
        p, tn, sc = self.plant, self.tuning, self.scaling
        q, qd = p.q_meas, p.qd_meas
        w, t = self._w, self._w2
        sc.position_to_si(self._rx_pos, self._qt)
        self._qt -= self._home_shift  # the drive's position reference -> the plant's
        sc.velocity_to_si(self._rx_vel, self._vt)
        self._vt *= self.velocity_unit
        sc.torque_to_si(self._rx_tau, self._tt)
        sc.torque_to_si(self._rx_off, self._toff)
        np.multiply(self.max_torque, self._abs_nm, out=self._lim)
        np.negative(self._lim, out=self._neg_lim)
        np.equal(self.state, _OE, out=self._enabled)
        np.equal(self.mode_display, _CSP, out=self._csp)
        np.equal(self.mode_display, _CSV, out=self._csv)
        np.equal(self.mode_display, _CST, out=self._cst)
        np.equal(self.state, _QSA, out=self._ramping)
        np.equal(self.state, _FRA, out=self._b1)
        self._b1 &= self.fault_ramp
        self._ramping |= self._b1
        if self.real_brake.any():  # powered at zero velocity while the brake engages
            np.greater(self.brake_hold_time, 0.0, out=self._b1)
            self._ramping |= self._b1
            self.brake_hold_time -= self.dt
            np.maximum(self.brake_hold_time, 0.0, out=self.brake_hold_time)

        np.equal(self.mode_display, _IP, out=self._ipm)
        self._ipm &= self._enabled
        np.equal(self.mode_display, _PV, out=self._pvm)
        self._pvm &= self._enabled
        if self._ip_pv_drive:
            np.logical_or(self._ipm, self._pvm, out=self._ip_any)
            if self._ip_any.any():
                self._ip_pv()
            else:
                self._ip_pv_idle()

        # Velocity command: CSP = feed-forward + P on position; CSV = target; ramps override.
        np.subtract(self._qt, self._prev_target, out=self._vcmd)
        self._vcmd *= self._inv_dt
        self._vcmd *= self._ff
        self._vcmd *= self._target_valid
        np.copyto(self._prev_target, self._qt)
        np.subtract(self._qt, q, out=self._err)
        np.multiply(self._err, tn.position_gain, out=w)
        self._vcmd += w
        np.copyto(self._vcmd, self._vt, where=self._csv)
        if self._pvm.any():
            np.copyto(self._vcmd, self._pv_v, where=self._pvm)
        np.equal(self.mode_display, _HM, out=self._hm)
        self._hm &= self._enabled
        if self._hm.any():
            self._advance_homing()
            np.copyto(self._vcmd, self._home_v, where=self._hm)
            self._csv |= self._hm  # the velocity loop runs while homing
        if self._ramping.any():
            self._advance_ramp()
            np.copyto(self._vcmd, self._ramp_v, where=self._ramping)

        # PI velocity loop where it runs (CSP, CSV, ramps); CST is torque straight through.
        np.logical_or(self._csp, self._csv, out=self._loop)
        self._loop &= self._enabled
        self._loop |= self._ramping
        np.logical_and(self._cst, self._enabled, out=self._cst)
        np.subtract(self._vcmd, qd, out=w)
        np.multiply(w, self._ki_dt, out=t)
        t *= self._loop
        self._integral += t
        np.clip(self._integral, self._neg_lim, self._lim, out=self._integral)
        np.multiply(w, tn.velocity_gain, out=self._tau)
        self._tau += self._integral
        np.copyto(self._tau, self._tt, where=self._cst)
        self._tau += self._toff
        np.logical_or(self._loop, self._cst, out=self._active)
        self._tau *= self._active
        np.abs(self._tau, out=t)
        np.greater(t, self._lim, out=self._limited)
        np.clip(self._tau, self._neg_lim, self._lim, out=self._tau)
        np.copyto(self._target_valid, self._enabled)

        # Following error (CSP, operation enabled) for longer than 0x6066.
        np.multiply(self.following_window, self._abs_rpc, out=t)
        np.abs(self._err, out=w)
        np.greater(w, t, out=self._fe_flag)
        self._fe_flag &= self._csp
        self._fe_flag &= self._enabled
        self._fe_cycles += 1
        self._fe_cycles *= self._fe_flag
        if self._fe_flag.any():
            np.multiply(self._fe_cycles, self.dt * 1000.0, out=w)
            np.greater(w, self.following_timeout, out=self._b1)
            for i in np.flatnonzero(self._b1):
                self._pending.append((int(i), CODE_FOLLOWING_ERROR, True))

        # Holding brake where the power stage is off.
        np.logical_or(self._active, self._ramping, out=self._b1)
        np.logical_not(self._b1, out=self._b1)
        if self.real_brake.any():
            self._real_brakes()
            self._b1 &= ~self.real_brake
        if self._b1.any():
            np.subtract(self._brake_q, q, out=w)
            w *= tn.brake_stiffness
            np.multiply(tn.brake_damping, qd, out=t)
            w -= t
            np.clip(w, self._neg_brake, tn.brake_torque, out=w)
            np.copyto(self._tau, w, where=self._b1)

    def _ip_pv(self) -> None:
        """Interpolated position and profile velocity: which axes run which loop, and their
        targets (the CSP loops run ip, the velocity loop pv; see the module docstring).
        Scratch arrays only: no temporaries (the pv ramp's per-axis loop aside)."""
        self._ip_idle = False
        q, b = self.plant.q_meas, self._ip_b
        # ip active: Operation enabled, bit 4 set, an interpolation period given
        np.bitwise_and(self._rx_cw, _CW_ENABLE_IP, out=self._u16)
        np.not_equal(self._u16, 0, out=self._ip_on)
        self._ip_on &= self._ipm
        np.greater(self.ip_period, 0, out=b)
        self._ip_on &= b
        # activation: no feed-forward from the hold position to the first target
        np.logical_not(self._ip_was, out=b)
        b &= self._ip_on
        np.copyto(self._target_valid, False, where=b)
        np.copyto(self._ip_was, self._ip_on)
        # inactive: hold where the drive was when it was enabled / ip went off
        np.logical_not(self._ip_on, out=b)
        b &= self._ipm
        np.copyto(self._qt, self._ip_hold, where=b)
        np.logical_not(self._ipm, out=b)
        b |= self._ip_on
        np.copyto(self._ip_hold, q, where=b)
        self._csp |= self._ipm  # the position loops run (holding or interpolating)
        # feed-forward scale: loop period / ip period (1 without a period and off ip)
        period, ff = self._ip_per, self._ip_ffv
        np.power(10.0, self.ip_exponent, out=period)
        np.multiply(self.ip_period, period, out=period)
        np.maximum(period, 1e-12, out=ff)
        np.divide(self.dt, ff, out=ff)
        np.greater(period, 0, out=b)
        b &= self._ipm
        self._ff.fill(1.0)
        np.copyto(self._ff, ff, where=b)
        # pv: the target velocity through the profile ramp
        if self._pvm.any():
            rpc = self._acc_rpc
            for i in np.flatnonzero(self._pvm):
                v, target = float(self._pv_v[i]), float(self._vt[i])
                speeding = abs(target) > abs(v) and target * v >= 0.0
                rate = self.profile_accel[i] if speeding else self.profile_decel[i]
                step = float(rate) * rpc[i] * self.dt
                self._pv_v[i] = v + min(max(target - v, -step), step)
        np.logical_not(self._pvm, out=b)
        np.copyto(self._pv_v, self.plant.qd_meas, where=b)
        self._csv |= self._pvm  # the velocity loop runs

    def _ip_pv_idle(self) -> None:
        """:meth:`_ip_pv` on a cycle where no axis runs ip or pv (every cycle of a CSP arm
        whose drives could): the hold position and the pv ramp follow the plant, the rest
        stays as the first such cycle left it. Two copies instead of ~30 numpy calls: this
        runs in every exchange of a simulated bus with such drives."""
        if not self._ip_idle:
            self._ip_on.fill(False)
            self._ip_was.fill(False)
            self._ff.fill(1.0)
            self._ip_idle = True
        np.copyto(self._ip_hold, self.plant.q_meas)
        np.copyto(self._pv_v, self.plant.qd_meas)

    def _real_brakes(self) -> None:
        """Delays, then the closed brakes' torque on top of the motor's (slipping beyond the
        holding torque: the anchor is dragged along)."""
        q, qd, tn = self.plant.q_meas, self.plant.qd_meas, self.tuning
        for i in np.flatnonzero(self.real_brake):
            if self.brake_by_output[i]:
                powered = int(self.state[i]) in _POWERED
                if not powered and self.brake_clears_output[i]:
                    self.digital_outputs[i] &= ~np.uint32(1)
                release = bool(self.digital_outputs[i] & self.output_mask[i] & 1)
                want = not (release and powered)
                if want != self._brake_target[i]:
                    self._command_brake(i, want)
            if self.brake_engaged[i] != self._brake_target[i]:
                self._brake_timer[i] -= self.dt
                if self._brake_timer[i] <= 0.0:
                    if self.brake_stuck[i] and not self._brake_target[i]:
                        self._brake_target[i] = True  # it did not open: the drive faults
                        self._pending.append((int(i), BRAKE_FAULT_CODE, False))
                    else:
                        self.brake_engaged[i] = self._brake_target[i]
                        self._brake_q[i] = q[i]
            if not self.brake_engaged[i]:
                continue
            hold = self.brake_holding[i]
            spring = tn.brake_stiffness[i] * (self._brake_q[i] - q[i])
            if abs(spring) > hold:  # slipping: the friction lining slides with the joint
                spring = math.copysign(hold, spring)
                self._brake_q[i] = q[i] + spring / tn.brake_stiffness[i]
            torque = spring - tn.brake_damping[i] * qd[i]
            self._tau[i] += min(max(torque, -hold), hold)

    def _homing_edges(self, cw: np.ndarray) -> None:
        """Controlword bit 4 in homing mode: a rising edge starts, low interrupts."""
        for i in np.flatnonzero(self._hm):
            bit = int(cw[i]) & sm.CW_HOMING_START
            if bit and not int(self.prev_controlword[i]) & sm.CW_HOMING_START:
                self._start_homing(int(i))
            elif not bit and self.homing[i] in (_H_SEARCH, _H_BACK, _H_INDEX):
                self.homing[i] = _H_STOP  # interrupted: stop, not attained

    def _start_homing(self, i: int) -> None:
        if int(self.state[i]) != _OE:
            return
        method = int(self.homing_method[i])
        q = float(self.plant.q_meas[i])
        offset = self._home_position(i)
        self._home_start_q[i] = q
        self._home_prev_q[i] = q
        if method in (35, 37):  # current position is home
            self._home_shift[i] = offset - q
            self._home_v[i] = 0.0
            self.homing[i] = _H_DONE
            self._target_valid[i] = False
        elif method in (1, 17):  # negative limit / home switch (then the index for 1)
            self._home_dir[i] = -1.0
            self.homing[i] = _H_SEARCH
        elif method == 2:  # positive limit switch, then the index
            self._home_dir[i] = 1.0
            self.homing[i] = _H_SEARCH
        elif method in (33, 34):  # the next index pulse below (33) / above (34)
            self._home_dir[i] = -1.0 if method == 33 else 1.0
            self.homing[i] = _H_INDEX
        else:
            self.homing[i] = _H_ERROR

    def _home_position(self, i: int) -> float:
        """The joint angle [rad] the home offset 0x607C [counts] stands for: after homing
        the drive reports 0x6064 = 0x607C at home."""
        sc = self.scaling
        return float(sc.rad_per_count[i] * (int(self.home_offset[i]) - sc.zero_offset[i]))

    def _switch_made(self, i: int, q: float) -> bool:
        """The switch the axis's method searches: method 2's positive limit switch is made
        above :attr:`positive_switch`, the others' below :attr:`home_switch` (nan: none)."""
        if int(self.homing_method[i]) == 2:
            return bool(q >= self.positive_switch[i])
        return bool(q <= self.home_switch[i])

    def _index_between(self, i: int, a: float, b: float) -> float:
        """The true joint position of an index pulse passed going from ``a`` to ``b`` [rad]
        (one per motor revolution, at ``index_phase + k·index_pitch``); nan if none."""
        pitch, phase = float(self.index_pitch[i]), float(self.index_phase[i])
        ka, kb = math.floor((a - phase) / pitch), math.floor((b - phase) / pitch)
        if ka == kb:
            return math.nan
        return phase + pitch * (max(ka, kb))

    def _advance_homing(self) -> None:
        q = self.plant.q_meas
        rpc = self._abs_rpc
        for i in np.flatnonzero(self._hm):
            h = int(self.homing[i])
            # 0x6099 / 0x609A in the drive's own units (counts/s, or rpm and rpm/s ...)
            fast = float(self.homing_speeds[0, i]) * rpc[i] * self.velocity_unit[i]
            slow = float(self.homing_speeds[1, i]) * rpc[i] * self.velocity_unit[i]
            acc = max(float(self.homing_accel[i]) * self._acc_rpc[i], 1e-6)
            direction = float(self._home_dir[i])
            method = int(self.homing_method[i])
            qi, prev = float(q[i]), float(self._home_prev_q[i])
            self._home_prev_q[i] = qi
            target = 0.0
            made = self._switch_made(int(i), qi)  # False for nan: no switch
            travelled = abs(qi - self._home_start_q[i]) > self.homing_travel[i]
            if h == _H_SEARCH:
                target = direction * fast
                if made:
                    self.homing[i] = h = _H_BACK
                elif travelled or fast <= 0.0:
                    self.homing[i] = h = _H_ERROR
            if h == _H_BACK:
                target = -direction * slow
                if not made:  # the switch edge
                    if method == 17:  # that edge is home
                        self._home_shift[i] = self._home_position(i) - qi
                        self._target_valid[i] = False
                        self.homing[i] = h = _H_DONE
                    else:  # methods 1/2: on, away from the switch, to the next index pulse
                        self._home_dir[i] = -direction
                        self.homing[i] = h = _H_INDEX
                        prev = qi
            if h == _H_INDEX:
                target = float(self._home_dir[i]) * slow
                at = self._index_between(int(i), prev, qi)
                if not math.isnan(at):  # the drive latches the pulse's own position
                    self._home_shift[i] = self._home_position(i) - at
                    self._target_valid[i] = False
                    self.homing[i] = h = _H_DONE
                elif travelled or slow <= 0.0:
                    self.homing[i] = h = _H_ERROR
            if h in (_H_DONE, _H_ERROR, _H_STOP):
                target = 0.0
            step = acc * self.dt
            self._home_v[i] += min(max(target - self._home_v[i], -step), step)

    def _homing_status(self, sw: np.ndarray) -> None:
        for i in np.flatnonzero(self._hm):
            stopped = self._home_v[i] == 0.0 and abs(float(self.plant.qd_meas[i])) < 0.01
            # bits 12/13 mean homing attained/error in this mode, not following (error)
            sw[i] &= ~np.uint16(sm.SW_FOLLOWING | sm.SW_FOLLOWING_ERROR | sm.SW_TARGET_REACHED)
            sw[i] |= np.uint16(_homing_status_bits(int(self.homing[i]), stopped))

    def _ip_pv_status(self, sw: np.ndarray) -> None:
        """Statusword bit 12 in ip: ip mode active; in pv: speed zero (bit 10: the ramp
        reached the target velocity; bit 13, max slippage, never)."""
        bits = np.uint16(sm.SW_FOLLOWING | sm.SW_FOLLOWING_ERROR | sm.SW_TARGET_REACHED)
        for i in np.flatnonzero(self._ipm | self._pvm):
            sw[i] &= ~bits
            if self._ipm[i]:
                sw[i] |= np.uint16(sm.SW_FOLLOWING if self._ip_on[i] else 0)
                if self._fe_flag[i]:
                    sw[i] |= np.uint16(sm.SW_FOLLOWING_ERROR)
                continue
            if abs(float(self.plant.qd_meas[i])) < _PV_SPEED_ZERO:
                sw[i] |= np.uint16(sm.SW_FOLLOWING)
            if self._pv_v[i] == self._vt[i]:
                sw[i] |= np.uint16(sm.SW_TARGET_REACHED)

    def _advance_ramp(self) -> None:
        step, sign = self._w2, self._w3
        np.multiply(self.quick_stop_decel, self._acc_rpc, out=step)
        step *= self.dt
        np.abs(self._ramp_v, out=sign)
        np.minimum(step, sign, out=step)
        np.sign(self._ramp_v, out=sign)
        step *= sign
        step *= self._ramping
        self._ramp_v -= step

    def _automatic_transitions(self) -> None:
        np.take(_HAS_AUTOMATIC, self.state, out=self._b1)
        if not self._b1.any():
            return
        qd = self.plant.qd_meas
        for i in np.flatnonzero(self._b1):
            s = int(self.state[i])
            if s == _NR:
                self.state[i] = _SOD  # transition 1: self test done
            elif s == _FRA:
                if not self.fault_ramp[i]:
                    self.state[i] = _FLT  # transition 14 (brake closed at the fault)
                elif self._stopped(i, qd[i]):
                    self._close_brake(i)
                    self.state[i] = _FLT  # transition 14 after the ramp
            elif s == _QSA and self.quick_stop_option[i] < 5 and self._stopped(i, qd[i]):
                if self.real_brake[i] and not self.sto[i]:  # category 1: hold until it holds
                    self.brake_hold_time[i] = self.brake_engage_delay[i]
                self._close_brake(i)
                self.state[i] = _SOD  # transition 12

    def _stopped(self, i: int, qd: float) -> bool:
        return self._ramp_v[i] == 0.0 and abs(qd) < 0.01

    def _close_brake(self, i: int) -> None:
        if self.real_brake[i]:
            if not self._brake_target[i]:
                self._command_brake(i, True)
            return
        self._brake_q[i] = self.plant.q_meas[i]

    def _brake_torque(self, i: int) -> float:
        tn = self.tuning
        p = self.plant
        t = tn.brake_stiffness[i] * (self._brake_q[i] - p.q_meas[i])
        t -= tn.brake_damping[i] * p.qd_meas[i]
        return float(np.clip(t, -tn.brake_torque[i], tn.brake_torque[i]))

    def _update_tx(self) -> None:
        p, sc = self.plant, self.scaling
        np.add(p.q_meas, self.position_offset, out=self._q_rep)
        self._q_rep += self._home_shift
        sc.position_to_raw(self._q_rep, self._pos_raw)
        np.copyto(self._tx_pos, self._pos_raw, where=self._encoder_ok)
        np.divide(p.qd_meas, self.velocity_unit, out=self._w)
        sc.velocity_to_raw(self._w, self._tx_vel)
        sc.torque_to_raw(p.tau_meas, self._tx_tau)
        np.divide(p.tau_meas, sc.gear_ratio, out=self._w)
        self._w /= sc.torque_constant
        sc.current_to_raw(self._w, self._tx_cur)
        sw, u16 = self._tx_sw, self._u16
        np.take(_STATUS_BASE, self.state, out=sw)
        np.equal(self.state, _OE, out=self._enabled)
        np.multiply(self._enabled, sm.SW_FOLLOWING, out=u16, casting="unsafe")
        sw |= u16
        np.logical_and(self._limited, self._enabled, out=self._b1)
        np.multiply(self._b1, sm.SW_INTERNAL_LIMIT, out=u16, casting="unsafe")
        sw |= u16
        np.multiply(self._fe_flag, sm.SW_FOLLOWING_ERROR, out=u16, casting="unsafe")
        sw |= u16
        np.equal(self.mode_display, _HM, out=self._hm)
        if self._hm.any():
            self._homing_status(sw)
        if self._ipm.any() or self._pvm.any():
            self._ip_pv_status(sw)
        np.copyto(self._tx_mode, self.mode_display)
        np.copyto(self._tx_err, self.fault_code)
        np.multiply(self.sto, sm.DIN_STO, out=self._tx_din, casting="unsafe")


def _homing_status_bits(progress: int, stopped: bool) -> int:
    """Statusword bits 10 (target reached), 12 (attained), 13 (error) in homing mode."""
    if progress == _H_DONE:
        return sm.SW_HOMING_ATTAINED | (sm.SW_TARGET_REACHED if stopped else 0)
    if progress == _H_ERROR:
        return sm.SW_HOMING_ERROR | (sm.SW_TARGET_REACHED if stopped else 0)
    if progress in (_H_IDLE, _H_STOP):
        return sm.SW_TARGET_REACHED if stopped else 0  # not started / interrupted
    return 0  # in progress


def _gear_fraction(ratio: float) -> tuple[int, int]:
    """Gear ratio as motor/shaft revolutions for 0x6091 (denominator up to 1000)."""
    from fractions import Fraction

    f = Fraction(ratio).limit_denominator(1000)
    return f.numerator, f.denominator
