"""Pydantic models of the drive bus (``bus:`` section of a config file).

Per-axis values are SI at the joint side except the drive's own scaling data (counts,
mN·m, mA), which are the numbers printed on the drive/motor data sheet and written to the
drive's object dictionary (0x608F, 0x6091, 0x6075, 0x6076).

Loading and checking only; nothing here runs in the tick.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Annotated, Any, Literal

from pydantic import Field, field_validator, model_validator

from hofto_hw.config.base import FileModel, PositiveFloat

U32 = Annotated[int, Field(ge=0, le=0xFFFFFFFF)]
#: a wait at start-up or on a request [s]: bounded, so a typo cannot hang the start for hours
Timeout = Annotated[float, Field(gt=0.0, le=60.0)]


class DriveIdentity(FileModel):
    """CiA 301 identity object 0x1018 a drive must report (checked at bus start-up)."""

    vendor_id: U32 = Field(description="0x1018:1 vendor id")
    product_code: U32 = Field(description="0x1018:2 product code")
    revision: U32 | None = Field(None, description="0x1018:3 revision; None = any")


class HomingConfig(FileModel):
    """CiA 402 homing of one axis (mode 6), joint side SI; ``homing: none`` = absolute encoder.

    ``offset``: the joint angle the home position stands for (written as 0x607C in counts).
    """

    method: Annotated[int, Field(ge=-128, le=127)] = Field(
        description="0x6098 homing method (35/37: current position, 17: negative home "
        "switch, 1/2: negative/positive limit switch then the index pulse, 33/34: the next "
        "index pulse below/above)"
    )
    speeds: tuple[PositiveFloat, PositiveFloat] = Field(
        description="0x6099 search for switch, search for zero [rad/s]"
    )
    acceleration: PositiveFloat = Field(description="0x609A homing acceleration [rad/s²]")
    offset: float = Field(0.0, description="joint angle at the home position, 0x607C [rad]")
    timeout: PositiveFloat = Field(description="homing must end within this time [s]")
    tolerance: PositiveFloat = Field(
        0.01, description="largest distance of the end position from offset [rad]"
    )

    @model_validator(mode="after")
    def _method(self) -> HomingConfig:
        if self.method == 0:
            raise ValueError("method 0 is 'no homing'; write homing: none")
        return self


class BrakeConfig(FileModel):
    """Holding brake of one axis. ``control``: ``drive`` (the drive opens it on Operation
    enabled, after its own release delay) or ``output`` (the master sets 0x60FE:1 bit 0)."""

    control: Literal["drive", "output"] = Field("drive", description="who opens the brake")
    release_delay: Annotated[float, Field(ge=0.0, le=5.0)] = Field(
        description="time the brake takes to open [s]; no motion before it"
    )
    engage_delay: Annotated[float, Field(ge=0.0, le=5.0)] = Field(
        description="time the brake takes to close [s]; power stays on that long (cat 1)"
    )
    holding_torque: PositiveFloat = Field(description="rated holding torque, joint side [N·m]")
    release_bound: PositiveFloat = Field(
        5e-4, description="largest joint motion while the brake opens [rad]"
    )


class DriveConfig(FileModel):
    """One servo drive axis: identity, raw scaling, limits and supervision."""

    identity: DriveIdentity = Field(
        default_factory=lambda: DriveIdentity(vendor_id=0x00000000, product_code=0x00000000)
    )
    counts_per_rev: Annotated[int, Field(gt=0, le=2**31)] = Field(
        description="encoder counts per MOTOR revolution"
    )
    gear_ratio: PositiveFloat = Field(description="motor revolutions per joint revolution")
    direction: Literal[1, -1] = Field(1, description="joint sense for positive motor motion")
    zero_offset: int = Field(0, description="encoder count at joint angle 0 [counts]")
    rated_torque: PositiveFloat = Field(description="0x6076 rated motor torque [mN·m]")
    rated_current: PositiveFloat = Field(description="0x6075 rated motor current [mA]")
    torque_constant: PositiveFloat = Field(description="motor torque constant [N·m/A]")
    torque_limit: PositiveFloat = Field(description="joint-side torque limit, 0x6072 [N·m]")
    quick_stop_deceleration: PositiveFloat = Field(
        description="quick-stop ramp, 0x6085, joint side [rad/s²]"
    )
    following_error_window: PositiveFloat = Field(
        0.05, description="CSP following-error window, 0x6065, joint side [rad]"
    )
    following_error_timeout: Annotated[float, Field(ge=0.0, le=65.535)] = Field(
        0.01, description="time outside the window before the fault, 0x6066 [s]"
    )
    profile: str | None = Field(
        None,
        min_length=1,
        description="drive profile: a name in configs/drives/ (e.g. 'elmo_gold') or a YAML "
        "path relative to this config; None = the stack's built-in PDO layout "
        "(drivers/cia402/pdo.py). `hofto-hw config check` loads it and checks it against "
        "loop.rate_hz",
    )
    device: Annotated[int, Field(ge=0, le=511)] | None = Field(
        None,
        description="the drive device this joint is on (EtherCAT slave, CANopen node), "
        "counted from 0 in "
        "bus order; None = a device of its own (the next one). Joints sharing a device run "
        "one multi-axis drive: one profile with `axes` > 1, one identity",
    )
    device_axis: Annotated[int, Field(ge=0, le=7)] = Field(
        0,
        description="the CiA-402 axis of the device that drives this joint (its objects at "
        "0x6000 + 0x800·device_axis, its PDOs as the profile maps them)",
    )
    homing: HomingConfig | None = Field(
        None, description="homing of an incremental axis; none = absolute encoder"
    )
    brake: BrakeConfig | None = Field(None, description="holding brake; none = no brake")

    @field_validator("homing", "brake", mode="before")
    @classmethod
    def _no_homing(cls, value: object) -> object:
        return None if value == "none" else value

    @model_validator(mode="after")
    def _raw_ranges(self) -> DriveConfig:
        """The limits must fit the objects they are written to (the drive would get a
        clipped value): 0x6072 is u16 per mille of rated torque, 0x6085 u32 counts/s².
        Skipped while a value is not given here (taken from elsewhere)."""
        values = (self.rated_torque, self.gear_ratio, self.torque_limit, self.counts_per_rev)
        if any(v is None for v in (*values, self.quick_stop_deceleration)):
            return self
        most = 65535 * self.rated_torque * 1e-6 * self.gear_ratio
        if self.torque_limit > most:
            raise ValueError(
                f"torque_limit = {self.torque_limit:g} N·m is above what 0x6072 (u16 per "
                f"mille of rated_torque x gear_ratio) can hold: at most {most:.6g} N·m"
            )
        per_rad = self.counts_per_rev * self.gear_ratio / (2.0 * math.pi)
        if self.quick_stop_deceleration * per_rad > 0xFFFFFFFF:
            raise ValueError(
                f"quick_stop_deceleration = {self.quick_stop_deceleration:g} rad/s² is above "
                f"what 0x6085 (u32 counts/s²) can hold: at most {0xFFFFFFFF / per_rad:.6g} rad/s²"
            )
        return self


class EtherCATOptions(FileModel):
    """EtherCAT master options (``bus.ethercat``; used when ``transport: ethercat``)."""

    dc_sync: bool = Field(
        False, description="program DC SYNC0 at the loop period (1 / loop.rate_hz)"
    )
    recover_lost_slaves: bool = Field(
        False, description="bring lost slaves back when they answer again (else stop the bus)"
    )
    receive_timeout: Annotated[float, Field(gt=0.0, le=1.0)] | None = Field(
        None, description="wait for the process-data frame [s]; None = one bus cycle"
    )
    state_timeout: Timeout = Field(3.0, description="max time per AL state change [s]")
    pdo_watchdog: Annotated[float, Field(gt=0.0, le=6.5)] | None = Field(
        None,
        description="SM process-data watchdog written to every slave [s] (a gap in process "
        "data longer than this takes the slave out of OP); None = the slave's default",
    )


class CANopenOptions(FileModel):
    """CANopen master options (``bus.canopen``; used when ``transport: canopen``).

    ``bus.interface`` is the python-can channel (e.g. ``can0``, ``239.74.163.2``); the cycle
    time is ``1 / loop.rate_hz`` and the SYNC comes from the loop itself.
    """

    can_interface: str = Field(
        "socketcan",
        description="python-can interface: socketcan, pcan, kvaser, ixxat, virtual, udp_multicast",
    )
    bitrate: Annotated[int, Field(ge=10_000, le=1_000_000)] = Field(
        1_000_000, description="(nominal) bitrate [bit/s]"
    )
    data_bitrate: Annotated[int, Field(ge=10_000, le=12_000_000)] | None = Field(
        None, description="CAN FD data-phase bitrate [bit/s]; None = classic CAN"
    )
    node_ids: list[Annotated[int, Field(ge=1, le=127)]] | None = Field(
        None,
        description="CANopen node id per device (per drive unless joints share a multi-axis "
        "node: bus.drives[i].device), in bus order; None = 1, 2, ...",
    )
    load_limit: Annotated[float, Field(gt=0.0, le=1.0)] = Field(
        0.7, description="highest accepted worst-case bus load (fraction of the bus time)"
    )
    heartbeat_time: Annotated[float, Field(ge=0.001, le=65.535)] = Field(
        0.05, description="heartbeat producer time written to each node's 0x1017 [s]"
    )
    heartbeat_timeout: Annotated[float, Field(gt=0.0, le=65.535)] | None = Field(
        None, description="heartbeat consumer time [s]; None = 3 x heartbeat_time"
    )
    tpdo_deadline: Annotated[float, Field(gt=0.0, le=1.0)] | None = Field(
        None, description="wait for a cycle's TPDOs [s] after the SYNC; None = 0.8 cycle"
    )
    tpdo_resync: Annotated[float, Field(gt=0.0, le=65.535)] | None = Field(
        None,
        description="a node's TPDOs lagging the SYNC this long [s] (or one lost on the way) are "
        "written off and read as on time again; longer than safety.bus.lost_cycles cycles, or "
        "a lag ends unreported; None = heartbeat_timeout",
    )
    sdo_timeout: Timeout = Field(0.5, description="SDO response timeout [s]")
    boot_timeout: Timeout = Field(
        3.0, description="wait for boot-up / operational heartbeats at start-up [s]"
    )

    @model_validator(mode="after")
    def _unique_ids(self) -> CANopenOptions:
        if self.node_ids is not None and len(set(self.node_ids)) != len(self.node_ids):
            raise ValueError(f"node_ids must be unique (got {self.node_ids})")
        return self


def device_map(drives: Sequence[Any]) -> list[tuple[int, int]]:
    """(device, device axis) per joint: ``device`` as given, or for ``device: None`` (or a
    drive object without the attribute) the next device of its own."""
    out: list[tuple[int, int]] = []
    next_free = 0
    for d in drives:
        given = getattr(d, "device", None)
        dev = given if given is not None else next_free
        out.append((dev, int(getattr(d, "device_axis", 0))))
        next_free = max(next_free, dev + 1)
    return out


class BusConfig(FileModel):
    """The drive bus: which transport, where, and one drive per joint.

    The bus cycles at ``loop.rate_hz`` (:attr:`SystemConfig.cycle_time`): there is no
    separate bus cycle time to disagree with it.
    """

    transport: str = Field(
        min_length=1,
        description="transport backend, a name registered in drivers.transport.BACKENDS "
        "(e.g. 'sim', 'ethercat', 'canopen'; `hofto-hw config check` refuses others)",
    )
    interface: str | None = Field(
        None, description="network interface (ethercat, e.g. 'eth1') or CAN channel (canopen)"
    )
    transition_timeout: Timeout = Field(
        0.5, description="max time for one CiA-402 state transition or mode change [s]"
    )
    drives: list[DriveConfig] = Field(min_length=1, description="one drive per joint, in order")
    ethercat: EtherCATOptions | None = Field(None, description="EtherCAT master options")
    canopen: CANopenOptions | None = Field(None, description="CANopen master options")

    @model_validator(mode="after")
    def _interface(self) -> BusConfig:
        if self.transport != "sim" and not self.interface:
            raise ValueError(f"interface is required for transport {self.transport!r}")
        self._check_devices()
        ids = self.canopen.node_ids if self.canopen is not None else None
        devices = len({dev for dev, _k in device_map(self.drives)})
        if ids is not None and len(ids) != devices:
            on = f" on {devices} devices" if devices != len(self.drives) else ""
            raise ValueError(
                f"canopen.node_ids has {len(ids)} ids for {len(self.drives)} drives{on} "
                "(one node id per device)"
            )
        return self

    def _check_devices(self) -> None:
        """Devices numbered in bus order, one joint per device axis, one profile and one
        identity per device; several joints on one device on EtherCAT and CANopen."""
        seen: dict[tuple[int, int], int] = {}
        first: dict[int, int] = {}
        for i, ((dev, k), d) in enumerate(zip(device_map(self.drives), self.drives, strict=True)):
            if dev not in first:
                if dev != len(first):
                    raise ValueError(
                        f"drives[{i}].device: {dev}, but the next device in bus order is "
                        f"{len(first)} (devices are counted from 0 in the order joints "
                        "first name them)"
                    )
                first[dev] = i
            if (dev, k) in seen:
                raise ValueError(
                    f"drives[{i}]: device {dev} axis {k} already drives joint {seen[dev, k]}"
                )
            seen[dev, k] = i
            j = first[dev]
            if j != i:
                if self.transport not in ("ethercat", "canopen"):
                    raise ValueError(
                        f"drives[{i}].device: {dev} is shared with drives[{j}]; multi-axis "
                        f"drives run on transport ethercat or canopen only (got "
                        f"{self.transport!r})"
                    )
                other = self.drives[j]
                if d.profile != other.profile or d.profile is None:
                    raise ValueError(
                        f"drives[{i}].profile: {d.profile!r}, but device {dev} runs "
                        f"{other.profile!r} (drives[{j}]); a multi-axis device has one profile"
                    )
                if d.identity != other.identity:
                    raise ValueError(
                        f"drives[{i}].identity differs from drives[{j}]'s, on the same device {dev}"
                    )
