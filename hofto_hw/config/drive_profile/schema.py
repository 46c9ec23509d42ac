"""The drive-profile schema: everything the stack needs to run one drive model.

A profile says how a real servo drive is run: its identity (0x1018), its bus, the process-data
layout as the drive will run it (which PDOs in which order, each entry index:sub:bits, padding,
fixed or configurable), which CiA-402 objects are mapped, only reachable by SDO or absent and
how the stack does without each one it lacks, the start-up SDO writes (with the EtherCAT state
transition they belong to), the modes, the distributed-clock settings (EtherCAT) or the
node-id range, bitrates and PDO communication parameters (CANopen), and the units objects.

``hofto-hw drive import`` writes profiles from vendor ESI/EDS files; a robot config names one
per axis (``bus.drives[i].profile``). A profile is validated on load (:class:`DriveProfile`)
and against the loop's period when a config uses it (:func:`check_profile_against_loop`).

Nothing here runs in the tick: the masters turn a profile into offsets into their process
image once, at start-up.

CiA-402 objects of axis k of a multi-axis device sit at ``0x6000 + 0x800·k`` (CiA 402-1);
:func:`cia402_object` maps an index back to the axis-0 object and the axis.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from hofto_hw.config.base import FileModel
from hofto_hw.errors import ConfigError

FORMAT_VERSION = 1

U8 = Annotated[int, Field(ge=0, le=0xFF)]
U16 = Annotated[int, Field(ge=0, le=0xFFFF)]
U32 = Annotated[int, Field(ge=0, le=0xFFFFFFFF)]

#: CiA-402 object (axis 0, sub-index 0) -> (process-image field name, bits). The names are the
#: ones of ``drivers.cia402.pdo.OBJECT_FIELDS`` (a test keeps them in step), plus a few
#: objects real drives map that the built-in layout does not.
CIA402_OBJECTS: dict[int, tuple[str, int]] = {
    0x6040: ("controlword", 16),
    0x6060: ("mode", 8),
    0x607A: ("target_position", 32),
    0x60FF: ("target_velocity", 32),
    0x6071: ("target_torque", 16),
    0x60B2: ("torque_offset", 16),
    0x60B1: ("velocity_offset", 32),
    0x6041: ("statusword", 16),
    0x6061: ("mode_display", 8),
    0x6064: ("position", 32),
    0x606C: ("velocity", 32),
    0x6077: ("torque", 16),
    0x6078: ("current", 16),
    0x603F: ("error_code", 16),
    0x60FD: ("digital_inputs", 32),
    0x60FE: ("digital_outputs", 32),
    0x60F4: ("following_error", 32),
    0x60B8: ("touch_probe_function", 16),
    0x60B9: ("touch_probe_status", 16),
}
FIELD_OBJECTS: dict[str, int] = {name: index for index, (name, _) in CIA402_OBJECTS.items()}
#: CiA-402 objects at a sub-index other than 0 that carry a process-image field: 0x60C1:01,
#: X1 of the interpolation data record, is the position target of interpolated position
#: mode (``modes.loop: ip``; ``drivers.cia402.pdo.EXTRA_FIELDS``)
SUB_OBJECTS: dict[tuple[int, int], tuple[str, int]] = {(0x60C1, 1): ("target_position", 32)}

#: the objects the stack's loop reads or writes, and the direction (rx: master -> drive)
LOOP_OBJECTS: dict[str, Literal["rx", "tx"]] = {
    "controlword": "rx",
    "mode": "rx",
    "target_position": "rx",
    "target_velocity": "rx",
    "target_torque": "rx",
    "torque_offset": "rx",
    "statusword": "tx",
    "mode_display": "tx",
    "position": "tx",
    "velocity": "tx",
    "torque": "tx",
    "current": "tx",
    "error_code": "tx",
    "digital_inputs": "tx",
}

#: how the stack can do without an object it cannot map, per object (first = preferred):
#: - target_torque_in_cst: the gravity feed-forward goes through the target torque (CST only);
#: - sdo: read by SDO when needed (error code on a fault; mode display after a mode change);
#: - emcy: the error code comes from the drive's EMCY message (CANopen);
#: - current: the torque is computed from the actual current 0x6078 (must be mapped);
#: - position_derivative: the velocity is the finite difference of the position;
#: - startup: the mode is written once as a start-up SDO (``modes.set_by: startup``);
#: - none: no such signal from that drive (no enabling/STO input from 0x60FD);
#: - unavailable: the stack runs without it and reports it as unavailable.
FALLBACKS: dict[str, tuple[str, ...]] = {
    "mode": ("startup",),
    "mode_display": ("sdo", "unavailable"),
    "target_position": ("unavailable",),
    "target_velocity": ("unavailable",),
    "target_torque": ("unavailable",),
    "torque_offset": ("target_torque_in_cst", "unavailable"),
    "velocity": ("position_derivative",),
    "torque": ("current", "unavailable"),
    "current": ("unavailable",),
    "error_code": ("sdo", "emcy"),
    "digital_inputs": ("none",),
}
#: the setting objects ``DriveGroup.configure`` reads or writes by SDO at start-up (axis 0,
#: sub-index 0), by name, with what the stack does on a drive that does not have one
#: (``objects.absent_settings``): configure leaves it out and says so once per axis
SETTING_OBJECTS: dict[str, tuple[int, str]] = {
    "max_torque": (
        0x6072,
        "the drive's torque limit is not set; the stack's joint torque limit "
        "(safety.limits) applies",
    ),
    "rated_current": (
        0x6075,
        "the rated current is not checked against the drive; the config's rated_current "
        "sets the current scaling",
    ),
    "rated_torque": (
        0x6076,
        "the rated torque is not checked against the drive; the config's rated_torque sets "
        "the torque scaling",
    ),
    "following_error_window": (
        0x6065,
        "the drive does not supervise the following error; the stack's following-error "
        "limit (safety.limits.following_error) applies",
    ),
    "following_error_timeout": (0x6066, "the drive's own following-error timeout stays"),
    "quick_stop_deceleration": (0x6085, "the drive's own quick-stop ramp stays"),
}
#: objects the loop cannot run without whatever the mode (no fallback exists)
ALWAYS_NEEDED = ("controlword", "statusword", "position")

Mode = Literal["pp", "vl", "pv", "tq", "hm", "ip", "csp", "csv", "cst"]
#: CiA-402 mode names -> 0x6060 values, and their 0x6502 "supported drive modes" bit
MODE_NUMBERS: dict[str, int] = {
    "pp": 1,
    "vl": 2,
    "pv": 3,
    "tq": 4,
    "hm": 6,
    "ip": 7,
    "csp": 8,
    "csv": 9,
    "cst": 10,
}
MODE_BITS: dict[str, int] = {"pp": 0, "vl": 1, "pv": 2, "tq": 3, "hm": 5, "ip": 6, "csp": 7,
                             "csv": 8, "cst": 9}  # fmt: skip
#: the target object each cyclic mode needs
CYCLIC_TARGETS: dict[str, str] = {
    "csp": "target_position",
    "csv": "target_velocity",
    "cst": "target_torque",
}
#: the modes the loop can run a drive in, and the process-image field of their target: the
#: cyclic synchronous ones, and for drives without them interpolated position (ip, target
#: 0x60C1:01, controlword bit 4) and profile velocity streamed every cycle (pv, target
#: 0x60FF); with ip and pv the loop still commands positions (drivers/cia402/csp_adapter.py)
LOOP_TARGETS: dict[str, str] = CYCLIC_TARGETS | {
    "ip": "target_position",
    "pv": "target_velocity",
}
#: the object that carries the loop mode's target: (index, sub-index)
LOOP_TARGET_OBJECTS: dict[str, tuple[int, int]] = {
    "csp": (0x607A, 0),
    "csv": (0x60FF, 0),
    "cst": (0x6071, 0),
    "ip": (0x60C1, 1),
    "pv": (0x60FF, 0),
}

#: EtherCAT state transitions a start-up SDO may belong to (ETG.2000 InitCmd ``Transition``;
#: I init, P pre-op, S safe-op, O op, B bootstrap); CANopen start-up SDOs are written in
#: pre-operational before the node is started: ``PO``.
Transition = Literal["IP", "PS", "PI", "SP", "SO", "SI", "OS", "OP", "OI", "IB", "BI", "II",
                     "PP", "SS", "PO"]  # fmt: skip


def modes_from_bits(value: int) -> list[str]:
    """The mode names of a 0x6502 "supported drive modes" value."""
    return [m for m, bit in MODE_BITS.items() if value >> bit & 1]


def cia402_object(index: int) -> tuple[int, int] | None:
    """(axis-0 object index, axis k) of a CiA-402 object at ``0x6000 + 0x800·k``; None outside
    0x6000..0x9FFF (eight axes)."""
    if not 0x6000 <= index <= 0x9FFF:
        return None
    k, base = divmod(index - 0x6000, 0x800)
    return 0x6000 + base, k


def _hex(index: int, sub: int) -> str:
    return f"0x{index:04X}:{sub:02X}"


class ProfileSource(FileModel):
    """Where the profile came from (``hofto-hw drive import``); informative."""

    file: str = Field(description="vendor file name (ESI .xml, EDS/DCF) or 'hand-written'")
    device: str | None = Field(None, description="device/type name in that file")
    sha256: str | None = Field(
        None, pattern=r"^[0-9a-f]{64}$", description="sha256 of the vendor file (hex)"
    )


class ProfileIdentity(FileModel):
    """CiA 301 identity 0x1018 a drive must report to run this profile."""

    vendor_id: U32 = Field(description="0x1018:1 vendor id")
    product_code: U32 = Field(description="0x1018:2 product code")
    revision_min: U32 | None = Field(None, description="lowest 0x1018:3 revision; None = any")
    revision_max: U32 | None = Field(None, description="highest 0x1018:3 revision; None = any")

    @model_validator(mode="after")
    def _range(self) -> ProfileIdentity:
        lo, hi = self.revision_min, self.revision_max
        if lo is not None and hi is not None and lo > hi:
            raise ValueError(f"revision_min 0x{lo:08X} is above revision_max 0x{hi:08X}")
        return self

    def matches(self, vendor_id: int, product_code: int, revision: int) -> bool:
        """Whether a drive reporting these 0x1018 values runs this profile."""
        lo, hi = self.revision_min, self.revision_max
        return (
            vendor_id == self.vendor_id
            and product_code == self.product_code
            and (lo is None or revision >= lo)
            and (hi is None or revision <= hi)
        )


class ProfileModes(FileModel):
    """Operation modes (CiA-402 0x6060 / 0x6502)."""

    supported: list[Mode] = Field(
        min_length=1, description="modes the drive supports (0x6502 or the vendor file)"
    )
    loop: Literal["csp", "csv", "cst", "ip", "pv"] = Field(
        "csp",
        description="the mode the loop runs the drive in: a cyclic synchronous one, or for a "
        "drive without them ip (interpolated position, target 0x60C1:01) or pv (profile "
        "velocity streamed every cycle, the position loop in the master)",
    )
    set_by: Literal["pdo", "startup"] = Field(
        "pdo",
        description="'pdo': 0x6060 is mapped and written every cycle; 'startup': written once "
        "as a start-up SDO (the drive cannot map it)",
    )
    position_gain: Annotated[float, Field(gt=0.0, le=1000.0)] | None = Field(
        None,
        description="loop pv only: gain [1/s] of the master's position loop over the drive's "
        "profile velocity mode (velocity command = the target's change per cycle + gain x "
        "position error); well below the drive's velocity-loop bandwidth",
    )

    @model_validator(mode="after")
    def _gain(self) -> ProfileModes:
        if self.loop == "pv" and self.position_gain is None:
            raise ValueError("loop pv needs position_gain (the master's position loop [1/s])")
        if self.loop != "pv" and self.position_gain is not None:
            raise ValueError(f"position_gain is for loop pv only (loop is {self.loop})")
        return self


class ProfilePdoEntry(FileModel):
    """One mapped object of a PDO, in wire order; ``index: 0`` is a gap of ``bits``."""

    index: U16 = Field(description="object index (0 = padding)")
    subindex: U8 = Field(0, description="object sub-index")
    bits: Annotated[int, Field(ge=1, le=64)] = Field(description="bit length on the wire")
    field: str | None = Field(
        None,
        description="process-image field name of a CiA-402 object (controlword, ...), filled "
        "in from the object; None for padding and vendor objects",
    )
    axis: Annotated[int, Field(ge=0, le=7)] = Field(
        0, description="CiA-402 axis of the object (0x6000 + 0x800·axis); filled in"
    )

    @model_validator(mode="after")
    def _known(self) -> ProfilePdoEntry:
        if self.index == 0:
            if self.subindex != 0 or self.field is not None:
                raise ValueError("padding (index 0) has sub-index 0 and no field")
            return self
        found = cia402_object(self.index)
        known = CIA402_OBJECTS.get(found[0]) if found and self.subindex == 0 else None
        if found and self.subindex:
            known = SUB_OBJECTS.get((found[0], self.subindex))
        if known is None:
            if self.field is not None:
                raise ValueError(
                    f"{_hex(self.index, self.subindex)} is not a known CiA-402 object: field "
                    f"must be empty (got {self.field!r})"
                )
            return self
        name, bits = known
        if self.field not in (None, name):
            raise ValueError(f"{_hex(self.index, self.subindex)} is {name}, not {self.field!r}")
        if self.bits != bits:
            raise ValueError(
                f"{_hex(self.index, self.subindex)} ({name}) is {bits} bits, not {self.bits}"
            )
        self.field = name
        self.axis = found[1]
        return self


class ProfilePdo(FileModel):
    """One PDO of the assignment: its mapping object and entries in wire order."""

    index: U16 = Field(description="mapping object: 0x1600.. (Rx) / 0x1A00.. (Tx)")
    fixed: bool = Field(
        description="True: the drive's mapping is fixed (only assigned, never written); "
        "False: the master writes the entries into the mapping object"
    )
    entries: list[ProfilePdoEntry] = Field(min_length=1, description="entries in wire order")

    @property
    def bits(self) -> int:
        """Total length [bit]."""
        return sum(e.bits for e in self.entries)


class ObjectsSection(FileModel):
    """Where each CiA-402 object the loop uses is: ``mapped`` (in an assigned PDO), ``sdo``
    (in the dictionary but not mapped) or ``absent`` (not in the drive)."""

    mapped: list[str] = Field(default_factory=list, description="objects in the assigned PDOs")
    sdo: list[str] = Field(default_factory=list, description="in the dictionary, not mapped")
    absent: list[str] = Field(default_factory=list, description="not in the drive at all")
    absent_settings: list[str] = Field(
        default_factory=list,
        description="setting objects (SETTING_OBJECTS: 0x6072, 0x6075, 0x6076, 0x6065, 0x6066, "
        "0x6085) the drive does not have: configure neither reads nor writes them",
    )

    @field_validator("mapped", "sdo", "absent")
    @classmethod
    def _names(cls, names: list[str]) -> list[str]:
        for name in names:
            if name not in LOOP_OBJECTS:
                raise ValueError(
                    f"unknown object {name!r}; the loop's objects are {', '.join(LOOP_OBJECTS)}"
                )
        return names

    @field_validator("absent_settings")
    @classmethod
    def _settings(cls, names: list[str]) -> list[str]:
        for name in names:
            if name not in SETTING_OBJECTS:
                raise ValueError(
                    f"unknown setting object {name!r}; the settings are "
                    f"{', '.join(SETTING_OBJECTS)}"
                )
        if len(set(names)) != len(names):
            raise ValueError(f"a setting object is listed twice: {names}")
        return names


class StartupSdo(FileModel):
    """One start-up SDO write, in the order given."""

    index: U16 = Field(description="object index")
    subindex: U8 = Field(0, description="sub-index")
    value: int | Literal["loop_period"] = Field(
        description="value written (signed or unsigned, fits `bits`); 'loop_period' (only "
        "0x60C2:01, the interpolation period): the loop period in units of 10^(0x60C2:02) s, "
        "computed by the master from loop.rate_hz"
    )
    bits: Literal[8, 16, 32, 64] = Field(description="object size [bit]")
    transition: Transition = Field(
        "PS", description="EtherCAT state transition (PS = PREOP->SAFEOP); CANopen: PO"
    )
    comment: str = Field("", description="why (from the vendor file or the importer)")

    @model_validator(mode="after")
    def _fits(self) -> StartupSdo:
        if self.value == "loop_period":
            if (self.index, self.subindex) != (0x60C2, 1):
                raise ValueError(
                    f"{_hex(self.index, self.subindex)}: 'loop_period' is only for 0x60C2:01"
                )
            return self
        lo, hi = -(1 << (self.bits - 1)), (1 << self.bits) - 1
        if not lo <= self.value <= hi:
            raise ValueError(
                f"{_hex(self.index, self.subindex)}: value {self.value} does not fit "
                f"{self.bits} bits"
            )
        return self


class DcSection(FileModel):
    """EtherCAT distributed clocks (ESI ``<Dc><OpMode>``)."""

    assign_activate: U16 = Field(description="0x0980 AssignActivate word (0x300: SYNC0; 0x700 "
                                 "SYNC0+SYNC1; Nanotec 0x330)")  # fmt: skip
    sync0_cycle_ns: Annotated[int, Field(gt=0)] | None = Field(
        None,
        description="SYNC0 cycle [ns]; None = the loop period; a value = what the drive "
        "requires (must equal the loop period)",
    )
    sync0_shift_ns: int = Field(0, description="SYNC0 shift [ns]")
    sync1_cycle_ns: Annotated[int, Field(ge=0)] | None = Field(
        None, description="SYNC1 cycle [ns] (after SYNC0); None = no SYNC1"
    )
    sync1_shift_ns: int | None = Field(None, description="SYNC1 shift [ns]")


class ProcessDataLimits(FileModel):
    """Sync-manager sizes (EtherCAT ESI ``<Sm MaxSize>``): the layout must fit."""

    rx_bytes: Annotated[int, Field(gt=0)] | None = Field(None, description="SM2 max [byte]")
    tx_bytes: Annotated[int, Field(gt=0)] | None = Field(None, description="SM3 max [byte]")


class CanPdoComm(FileModel):
    """CANopen PDO communication parameter (0x1400.. / 0x1800..) for one PDO."""

    cob_id_base: Annotated[int, Field(ge=0x080, le=0x7FF)] = Field(
        description="COB-ID = cob_id_base + node id (e.g. RPDO1 0x200, TPDO1 0x180; CiA 301 "
        "defaults exist for PDOs 1-4 only: PDO n >= 5 takes PDO ((n-1) mod 4)+1's + 0x40, the "
        "COB-IDs of node id + 64, drivers/canopen/layout.pdo_cob_base)"
    )
    transmission_type: U8 = Field(
        1, description="0: acyclic synchronous; 1..240: every n-th SYNC; 254/255: event"
    )
    enabled_by_default: bool = Field(
        False,
        description="False: the file's default COB-ID has bit 31 set (the master enables the PDO)",
    )


class CANopenSection(FileModel):
    """CANopen specifics of a drive (EDS/DCF)."""

    node_ids: tuple[Annotated[int, Field(ge=1, le=127)], Annotated[int, Field(ge=1, le=127)]] = (
        Field((1, 127), description="[min, max] node id the drive accepts")
    )
    bitrates: list[Annotated[int, Field(ge=10_000, le=1_000_000)]] = Field(
        min_length=1, description="bitrates the drive supports [bit/s]"
    )
    max_entries: Annotated[int, Field(ge=1, le=64)] = Field(
        8, description="mapping entries per PDO (number of mapping sub-indices)"
    )
    rpdo: list[CanPdoComm] = Field(description="one per rx_pdos item, same order")
    tpdo: list[CanPdoComm] = Field(description="one per tx_pdos item, same order")
    heartbeat_ms: Annotated[int, Field(ge=0, le=65535)] | None = Field(
        None,
        description="heartbeat producer time written to 0x1017 [ms]; None = the "
        "master's bus.canopen.heartbeat_time",
    )
    emcy_axis_byte: Annotated[int, Field(ge=3, le=7)] | None = Field(
        None,
        description="multi-axis node: the byte of the EMCY's manufacturer-specific field "
        "(3..7) that carries the CiA-402 axis (0-based) the emergency is of; None = the "
        "EMCY does not say (the master reads 0x603F of each axis by SDO)",
    )

    @model_validator(mode="after")
    def _ids(self) -> CANopenSection:
        if self.node_ids[0] > self.node_ids[1]:
            raise ValueError(f"node_ids [min, max] reversed (got {list(self.node_ids)})")
        for name, comms in (("rpdo", self.rpdo), ("tpdo", self.tpdo)):
            for i, c in enumerate(comms):
                if c.cob_id_base + self.node_ids[1] > 0x7FF:
                    raise ValueError(
                        f"{name}[{i}].cob_id_base 0x{c.cob_id_base:03X} + node id "
                        f"{self.node_ids[1]} exceeds the 11-bit COB-ID 0x7FF"
                    )
        return self


class UnitsObject(FileModel):
    """One CiA-402 factor object (two UNSIGNED32 sub-indices, numerator and denominator)."""

    present: bool = Field(description="the drive has the object")
    default: tuple[int, int] | None = Field(
        None, description="[sub 1, sub 2] default values from the file; None = not given"
    )


class UnitsSection(FileModel):
    """Units objects: how the drive scales position (counts) to the motor and load."""

    position_encoder_resolution: UnitsObject = Field(
        default_factory=lambda: UnitsObject(present=False),
        description="0x608F: encoder increments / motor revolutions",
    )
    gear_ratio: UnitsObject = Field(
        default_factory=lambda: UnitsObject(present=False),
        description="0x6091: motor revolutions / shaft revolutions",
    )
    feed_constant: UnitsObject = Field(
        default_factory=lambda: UnitsObject(present=False),
        description="0x6092: feed / shaft revolutions",
    )
    scaling: str = Field(
        "position in encoder increments, velocity in increments/s, torque and current in "
        "per mille of rated",
        description="what the drive reports in its PDOs, in words",
    )
    velocity: Literal["counts/s", "rpm", "unknown"] = Field(
        "counts/s",
        description="unit of the velocities the drive takes and reports (0x60FF, 0x606C): "
        "counts/s (encoder increments/s), rpm (motor min^-1: counts/s x 60 / 0x608F), or "
        "unknown (the file does not say: a real bus refuses the axis until it is set)",
    )
    acceleration: Literal["counts/s^2", "rpm/s", "rev/s^2", "unknown"] = Field(
        "counts/s^2",
        description="unit of the accelerations written to 0x6083/0x6084/0x6085: counts/s^2, "
        "rpm/s (motor min^-1 per s), rev/s^2 (motor revolutions per s^2, Faulhaber's 1/s^2), "
        "or unknown",
    )

    def counts_per_drive_unit(self, counts_per_rev: float) -> tuple[float, float]:
        """(velocity, acceleration) factors: counts/s per drive velocity unit, counts/s^2
        per drive acceleration unit (1.0 for counts/s, counts/s^2 and unknown), with
        ``counts_per_rev`` encoder counts per motor revolution (the axis's, = 0x608F)."""
        per_rpm = counts_per_rev / 60.0
        accel = {"rpm/s": per_rpm, "rev/s^2": float(counts_per_rev)}
        return (
            per_rpm if self.velocity == "rpm" else 1.0,
            accel.get(self.acceleration, 1.0),
        )


class StoSource(FileModel):
    """Where the stack reads an axis's safe torque off (STO) state.

    ``input``: bit ``bit`` of the digital inputs 0x60FD (from the TxPDO when mapped, else
    by SDO outside the loop); ``object``: bit ``bit`` of a vendor object ``index:subindex``
    (``bits`` wide), read by SDO outside the loop; ``state``: no signal: an axis that drops
    to Switch on disabled without a fault, or will not leave it, is taken as STO. Inside the
    loop only the process image counts: ``object`` (and an unmapped ``input``) is judged
    there as ``state``.
    """

    source: Literal["input", "object", "state"] = Field(description="where STO is read")
    index: U16 = Field(0x60FD, description="object of the STO bit (input: 0x60FD)")
    subindex: U8 = Field(0, description="its sub-index")
    bits: Literal[8, 16, 32] = Field(32, description="the object's size [bit]")
    bit: Annotated[int, Field(ge=0, le=31)] = Field(16, description="bit set while STO is active")
    active_low: bool = Field(False, description="the bit is CLEAR while STO is active")

    @model_validator(mode="after")
    def _fits(self) -> StoSource:
        if self.bit >= self.bits:
            raise ValueError(f"bit {self.bit} does not fit a {self.bits}-bit object")
        if self.source == "input" and (self.index, self.subindex) != (0x60FD, 0):
            raise ValueError("source 'input' is 0x60FD:00; a vendor object is source 'object'")
        return self


class SdoParameter(FileModel):
    """One drive parameter written by SDO in SI (``unit``: seconds per count, e.g. 0.001)."""

    index: U16 = Field(description="object index")
    subindex: U8 = Field(0, description="sub-index")
    bits: Literal[8, 16, 32] = Field(description="object size [bit] (unsigned)")
    unit: Annotated[float, Field(gt=0.0)] = Field(0.001, description="SI value of one count")

    def raw(self, value: float) -> int:
        """``value`` in counts, clipped to the object's range."""
        return max(0, min((1 << self.bits) - 1, round(value / self.unit)))


class ProfileBrake(FileModel):
    """How the drive runs a holding brake it controls (``bus.drives[i].brake.control:
    drive``): the vendor objects of its release and engage delays (CiA 402 has no standard
    one; None = the drive has none the stack knows: its own setting stays), and the 0x603F
    error codes that mean a brake fault (``[low, high]`` ranges, inclusive)."""

    release_delay: SdoParameter | None = Field(
        None, description="brake release (open) delay: time from enable to motion [s]"
    )
    engage_delay: SdoParameter | None = Field(
        None, description="brake engage (close) delay: time power stays on after close [s]"
    )
    fault_codes: list[tuple[U16, U16]] = Field(
        default_factory=list, description="0x603F ranges [low, high] read as a brake fault"
    )

    @field_validator("fault_codes")
    @classmethod
    def _ranges(cls, ranges: list[tuple[int, int]]) -> list[tuple[int, int]]:
        for lo, hi in ranges:
            if lo > hi:
                raise ValueError(f"fault_codes range [0x{lo:04X}, 0x{hi:04X}] is reversed")
        return ranges

    def is_brake_fault(self, code: int) -> bool:
        return any(lo <= code <= hi for lo, hi in self.fault_codes)


class DriveProfile(FileModel):
    """One drive model: identity, bus, process data, objects, start-up, DC / CANopen, units."""

    profile: Literal[1] = Field(description="profile format version")
    name: str = Field(min_length=1, description="profile name (vendor_model)")
    description: str = Field("", description="what drive this is, in words")
    source: ProfileSource = Field(
        default_factory=lambda: ProfileSource(file="hand-written"),
        description="vendor file it was imported from",
    )
    identity: ProfileIdentity
    bus: Literal["ethercat", "canopen"]
    axes: Annotated[int, Field(ge=1, le=8)] = Field(
        1, description="CiA-402 axes in the device (axis k's objects at 0x6000 + 0x800·k)"
    )
    modes: ProfileModes
    rx_pdos: list[ProfilePdo] = Field(min_length=1, description="RxPDOs in assignment order")
    tx_pdos: list[ProfilePdo] = Field(min_length=1, description="TxPDOs in assignment order")
    objects: ObjectsSection = Field(default_factory=ObjectsSection)
    fallbacks: dict[str, str] = Field(
        default_factory=dict, description="object not mapped -> how the stack does without it"
    )
    startup: list[StartupSdo] = Field(default_factory=list, description="start-up SDO writes")
    dc: DcSection | None = Field(None, description="EtherCAT DC; None = no DC (free run)")
    process_data: ProcessDataLimits = Field(default_factory=ProcessDataLimits)
    canopen: CANopenSection | None = Field(None, description="CANopen specifics (bus: canopen)")
    units: UnitsSection = Field(default_factory=UnitsSection)
    sto: StoSource | None = Field(
        None,
        description="where the axis's safe torque off is read; None = the drive state (bits "
        "16-31 of 0x60FD are the vendor's: a profile names its STO bit when it has one)",
    )
    brake: ProfileBrake | None = Field(
        None, description="brake delay objects and brake fault codes; None = none known"
    )

    # ------------------------------------------------------------------ validation
    @model_validator(mode="after")
    def _check(self) -> DriveProfile:
        self._check_bus_sections()
        for side, pdos in (("rx_pdos", self.rx_pdos), ("tx_pdos", self.tx_pdos)):
            self._check_pdos(side, pdos)
        self._check_objects()
        self._check_modes()
        return self

    def _check_bus_sections(self) -> None:
        if self.bus == "canopen":
            if self.canopen is None:
                raise ValueError("bus canopen needs a canopen: section")
            if self.dc is not None:
                raise ValueError("dc: is EtherCAT only (bus is canopen)")
            c = self.canopen
            if len(c.rpdo) != len(self.rx_pdos) or len(c.tpdo) != len(self.tx_pdos):
                raise ValueError(
                    f"canopen.rpdo/tpdo: {len(c.rpdo)}/{len(c.tpdo)} communication entries "
                    f"for {len(self.rx_pdos)}/{len(self.tx_pdos)} PDOs"
                )
            bad = [s.transition for s in self.startup if s.transition != "PO"]
            if bad:
                raise ValueError(
                    f"startup: CANopen start-up writes are transition PO (got {bad[0]})"
                )
        elif self.canopen is not None:
            raise ValueError("canopen: section given but bus is ethercat")

    def _check_pdos(self, side: str, pdos: list[ProfilePdo]) -> None:
        seen_pdo: set[int] = set()
        seen: dict[tuple[int, int], int] = {}
        for i, pdo in enumerate(pdos):
            where = f"{side}[{i}] (0x{pdo.index:04X})"
            if pdo.index in seen_pdo:
                raise ValueError(f"{where}: PDO assigned twice")
            seen_pdo.add(pdo.index)
            if pdo.bits % 8:
                raise ValueError(
                    f"{where}: {pdo.bits} bits, not a whole number of bytes (add padding)"
                )
            for e in pdo.entries:
                if e.index == 0:
                    continue
                key = (e.index, e.subindex)
                if key in seen:
                    raise ValueError(
                        f"{where}: {_hex(*key)} mapped twice (also in 0x{seen[key]:04X})"
                    )
                seen[key] = pdo.index
                if e.axis >= self.axes:
                    raise ValueError(
                        f"{where}: {_hex(*key)} is an object of axis {e.axis}; the device has "
                        f"{self.axes}"
                    )
                want = LOOP_OBJECTS.get(e.field or "")
                if want is not None and want != side[:2]:
                    raise ValueError(f"{where}: {_hex(*key)} ({e.field}) belongs in {want}_pdos")
            if self.canopen is not None:
                if len(pdo.entries) > self.canopen.max_entries:
                    raise ValueError(
                        f"{where}: {len(pdo.entries)} entries, the drive takes at most "
                        f"{self.canopen.max_entries} per PDO (canopen.max_entries)"
                    )
                if pdo.bits > 64:
                    raise ValueError(f"{where}: {pdo.bits} bits, a CAN frame carries 64")
        limit = self.process_data.rx_bytes if side == "rx_pdos" else self.process_data.tx_bytes
        total = sum(p.bits for p in pdos) // 8
        if limit is not None and total > limit:
            raise ValueError(
                f"{side}: {total} bytes exceed the sync manager's {limit} "
                f"(process_data.{side[:2]}_bytes)"
            )

    def mapped_fields(self, axis: int = 0) -> set[str]:
        """Field names of the CiA-402 objects of ``axis`` in the assigned PDOs."""
        return {
            e.field
            for p in self.rx_pdos + self.tx_pdos
            for e in p.entries
            if e.field is not None and e.axis == axis
        }

    def _check_objects(self) -> None:
        o = self.objects
        lists = {"mapped": o.mapped, "sdo": o.sdo, "absent": o.absent}
        owner: dict[str, str] = {}
        for kind, names in lists.items():
            for name in names:
                if name in owner:
                    raise ValueError(f"objects: {name} is both {owner[name]} and {kind}")
                owner[name] = kind
        for axis in range(self.axes):
            mapped = self.mapped_fields(axis) & set(LOOP_OBJECTS)
            if axis == 0 and o.mapped and set(o.mapped) != mapped:
                raise ValueError(
                    f"objects.mapped {sorted(o.mapped)} differs from the PDOs' {sorted(mapped)}"
                )
            for name in ALWAYS_NEEDED + (LOOP_TARGETS[self.modes.loop],):
                if name not in mapped:
                    raise ValueError(
                        f"{name} (0x{FIELD_OBJECTS[name]:04X}) of axis {axis} is not mapped: "
                        f"the {self.modes.loop} loop cannot run without it"
                    )
            for name in LOOP_OBJECTS:
                if name in mapped:
                    if name in self.fallbacks and axis == 0:
                        raise ValueError(f"fallbacks.{name}: the object is mapped")
                    continue
                if name not in self.fallbacks:
                    raise ValueError(
                        f"{name} (0x{FIELD_OBJECTS[name]:04X}) of axis {axis} is not mapped and "
                        f"fallbacks.{name} is not set (one of {', '.join(FALLBACKS[name])})"
                    )
        for name, how in self.fallbacks.items():
            allowed = FALLBACKS.get(name)
            if allowed is None:
                raise ValueError(
                    f"fallbacks.{name}: no fallback exists for it (objects with one: "
                    f"{', '.join(FALLBACKS)})"
                )
            if how not in allowed:
                raise ValueError(
                    f"fallbacks.{name}: {how!r} is not a way to do without it (one of "
                    f"{', '.join(allowed)})"
                )
        mapped0 = self.mapped_fields(0)
        if self.fallbacks.get("torque") == "current" and "current" not in mapped0:
            raise ValueError("fallbacks.torque: 'current' needs 0x6078 (current) mapped")
        if self.fallbacks.get("torque_offset") == "target_torque_in_cst" and (
            "target_torque" not in mapped0
        ):
            raise ValueError("fallbacks.torque_offset: 'target_torque_in_cst' needs 0x6071 mapped")

    def _check_modes(self) -> None:
        m = self.modes
        carriers: dict[str, list[tuple[int, int]]] = {}
        for p in self.rx_pdos:
            for e in p.entries:
                if e.field is not None and e.axis == 0:
                    carriers.setdefault(e.field, []).append((e.index, e.subindex))
        for name, keys in carriers.items():
            if len(keys) > 1:
                raise ValueError(
                    f"{name} is mapped twice ({', '.join(_hex(*k) for k in keys)}): one object "
                    "carries it"
                )
        target = LOOP_TARGETS[m.loop]
        want = LOOP_TARGET_OBJECTS[m.loop]
        got = carriers.get(target, [want])[0]
        if got != want:
            raise ValueError(
                f"modes.loop {m.loop}: its target {target} goes through {_hex(*want)}, the PDOs "
                f"map {_hex(*got)}"
            )
        if m.loop == "ip" and self.startup_value(0x60C2, 1) is None:
            raise ValueError(
                "modes.loop ip needs a start-up write of 0x60C2:01 (the interpolation period: "
                "'loop_period')"
            )
        if m.loop not in m.supported:
            raise ValueError(
                f"modes.loop: {m.loop} is not among the drive's modes ({', '.join(m.supported)})"
            )
        mapped = "mode" in self.mapped_fields(0)
        if m.set_by == "pdo" and not mapped:
            raise ValueError("modes.set_by: 'pdo' but 0x6060 (mode) is not mapped")
        if m.set_by == "startup":
            if mapped:
                raise ValueError("modes.set_by: 'startup' but 0x6060 (mode) is mapped")
            for axis in range(self.axes):
                index = 0x6060 + 0x800 * axis
                writes = [s for s in self.startup if s.index == index and s.subindex == 0]
                if not writes or writes[-1].value != MODE_NUMBERS[m.loop]:
                    raise ValueError(
                        f"modes.set_by: 'startup' needs a start-up write of 0x{index:04X} = "
                        f"{MODE_NUMBERS[m.loop]} ({m.loop})"
                    )

    # ------------------------------------------------------------------ helpers
    def image_bits(self, side: Literal["rx", "tx"]) -> int:
        """Length of one axis-device's ``side`` process data [bit] (its PDOs back to back)."""
        return sum(p.bits for p in (self.rx_pdos if side == "rx" else self.tx_pdos))

    def field_offsets(self, side: Literal["rx", "tx"], axis: int = 0) -> dict[str, tuple[int, int]]:
        """field name -> (bit offset, bits) of axis ``axis``'s CiA-402 objects in the ``side``
        process data of the device (PDOs in assignment order, entries in wire order)."""
        out: dict[str, tuple[int, int]] = {}
        at = 0
        for pdo in self.rx_pdos if side == "rx" else self.tx_pdos:
            for e in pdo.entries:
                if e.field is not None and e.axis == axis:
                    out[e.field] = (at, e.bits)
                at += e.bits
        return out

    def sto_source(self) -> StoSource:
        """The STO source as the stack uses it (the default spelled out, see ``sto``)."""
        return self.sto if self.sto is not None else StoSource(source="state")

    def startup_value(self, index: int, subindex: int = 0) -> int | str | None:
        """The last start-up value written to ``index:subindex``, or None."""
        for s in reversed(self.startup):
            if s.index == index and s.subindex == subindex:
                return s.value
        return None


def check_profile_against_loop(profile: DriveProfile, cycle_time: float, source: str) -> None:
    """Refuse a profile whose fixed timing disagrees with the loop period ``cycle_time`` [s].

    Checks a fixed DC SYNC0 cycle and an interpolation period 0x60C2 written at start-up.
    ``source`` names where the profile is used (``FILE: bus.drives[2].profile``).

    Raises:
        ConfigError: one line naming the field, the drive's value and the loop's.
    """
    period_ns = round(cycle_time * 1e9)
    rate = f"loop.rate_hz {1.0 / cycle_time:g} Hz, a {period_ns} ns period"
    dc = profile.dc
    if dc is not None and dc.sync0_cycle_ns is not None and dc.sync0_cycle_ns != period_ns:
        raise ConfigError(
            f"{source}: profile {profile.name}: dc.sync0_cycle_ns: the drive runs SYNC0 every "
            f"{dc.sync0_cycle_ns} ns, not the loop's period ({rate})"
        )
    units = profile.startup_value(0x60C2, 1)
    if units is not None:
        exponent = profile.startup_value(0x60C2, 2)
        exponent = -3 if not isinstance(exponent, int) else exponent
        if exponent > 127:
            exponent -= 256  # INTEGER8 written as unsigned
        if units == "loop_period":
            units = round(cycle_time / 10.0**exponent)
            if not 1 <= units <= 255:
                raise ConfigError(
                    f"{source}: profile {profile.name}: startup 0x60C2:01 (interpolation "
                    f"period, UNSIGNED8 in units of 1e{exponent} s) cannot hold the loop's "
                    f"period ({rate})"
                )
        got_ns = round(int(units) * 10.0**exponent * 1e9)
        if got_ns != period_ns:
            raise ConfigError(
                f"{source}: profile {profile.name}: startup 0x60C2 interpolation period "
                f"{units}e{exponent} s is not the loop's period ({rate})"
            )
