"""Drive profiles as the drivers use them: the built-in profile and profile -> wire layout.

A :class:`hofto_hw.config.drive_profile.DriveProfile` says how a drive model runs (PDOs,
start-up SDOs, DC, CANopen communication). An axis whose ``bus.drives[i].profile`` is not
set runs the stack's own layout (:func:`builtin_profile`: RxPDO 0x1600 / TxPDO 0x1A00 of
:mod:`drivers.cia402.pdo` on EtherCAT, the two RPDOs / two TPDOs of
:mod:`drivers.canopen.layout` on CANopen), so every master has exactly one code path: the
profile's.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from drivers.cia402.pdo import RXPDO_INDEX, RXPDO_MAPPING, TXPDO_INDEX, TXPDO_MAPPING, PdoEntry
from drivers.cia402.wire import AxisLayout, WireEntry
from hofto_hw.config.drive_profile import DriveProfile, find_profile, load_profile
from hofto_hw.errors import ConfigError


def _pdo(index: int, entries: Sequence[PdoEntry], fixed: bool = False) -> dict[str, Any]:
    return {
        "index": index,
        "fixed": fixed,
        "entries": [
            {"index": e.index, "subindex": e.subindex, "bits": e.bit_length} for e in entries
        ],
    }


#: the emulated drives' brake objects (drivers/sim/drive.py): vendor object 0x2110, delays
#: in ms, and their manufacturer-specific brake fault code 0xFF21 (CiA 402 has none)
BRAKE_OBJECT = 0x2110
BRAKE_FAULT_CODE = 0xFF21
BUILTIN_BRAKE: dict[str, Any] = {
    "release_delay": {"index": BRAKE_OBJECT, "subindex": 1, "bits": 16, "unit": 0.001},
    "engage_delay": {"index": BRAKE_OBJECT, "subindex": 2, "bits": 16, "unit": 0.001},
    "fault_codes": [(BRAKE_FAULT_CODE, BRAKE_FAULT_CODE)],
}
#: STO of the emulated drives: 0x60FD bit 16, in the TxPDO on EtherCAT (the built-in
#: ethercat profile's ``sto``), by SDO on CANopen (its layout does not map 0x60FD)
_STO_CAN: dict[str, Any] = {"source": "object", "index": 0x60FD, "bits": 32, "bit": 16}
_FALLBACKS_EC: dict[str, str] = {}
_FALLBACKS_CAN = {"error_code": "emcy", "digital_inputs": "none"}


def builtin_profile(
    bus: str = "ethercat", vendor_id: int = 0, product_code: int = 0
) -> DriveProfile:
    """The stack's own layout as a profile (an axis without ``profile``): on EtherCAT
    RxPDO 0x1600 and TxPDO 0x1A00 written by the master; on CANopen RPDO1/2 and TPDO1/2 of
    :mod:`drivers.canopen.layout`, synchronous, no start-up SDOs, no DC."""
    common: dict[str, Any] = {
        "profile": 1,
        "name": f"builtin-{bus}",
        "description": "the hofto-hw layout every emulated drive accepts",
        "identity": {"vendor_id": vendor_id, "product_code": product_code},
        "bus": bus,
        "modes": {"supported": ["csp", "csv", "cst"], "loop": "csp", "set_by": "pdo"},
        "brake": BUILTIN_BRAKE,
    }
    if bus == "ethercat":
        return DriveProfile.model_validate(
            common
            | {
                "rx_pdos": [_pdo(RXPDO_INDEX, RXPDO_MAPPING)],
                "tx_pdos": [_pdo(TXPDO_INDEX, TXPDO_MAPPING)],
                "fallbacks": _FALLBACKS_EC,
                "sto": {"source": "input", "bit": 16},
            }
        )
    from drivers.canopen import layout

    return DriveProfile.model_validate(
        common
        | {
            "rx_pdos": [_pdo(p.map_index, p.entries) for p in layout.RPDOS],
            "tx_pdos": [_pdo(p.map_index, p.entries) for p in layout.TPDOS],
            "fallbacks": _FALLBACKS_CAN,
            "sto": _STO_CAN,
            "canopen": {
                "bitrates": [125_000, 250_000, 500_000, 1_000_000],
                "max_entries": 8,
                "rpdo": [
                    {"cob_id_base": p.cob_base, "transmission_type": 1, "enabled_by_default": True}
                    for p in layout.RPDOS
                ],
                "tpdo": [
                    {"cob_id_base": p.cob_base, "transmission_type": 1, "enabled_by_default": True}
                    for p in layout.TPDOS
                ],
            },
        }
    )


def profile_for(drive: Any, bus: str, base_dir: Path | None = None) -> DriveProfile:
    """The profile of one ``bus.drives[i]``: its ``profile`` (a loaded DriveProfile, a file
    or a profile name in configs/drives/) or, when unset, :func:`builtin_profile` with the
    drive's configured identity."""
    spec = getattr(drive, "profile", None)
    if spec is None:
        ident = getattr(drive, "identity", None)
        return builtin_profile(
            bus,
            getattr(ident, "vendor_id", 0) if ident is not None else 0,
            getattr(ident, "product_code", 0) if ident is not None else 0,
        )
    if isinstance(spec, DriveProfile):
        return spec
    loaded = getattr(spec, "loaded", None)  # a reference object that carries its profile
    if isinstance(loaded, DriveProfile):
        return loaded
    return load_profile(find_profile(str(spec), base_dir))


def profiles_for(
    drives: Sequence[Any], bus: str, base_dir: Path | None = None
) -> list[DriveProfile]:
    """:func:`profile_for` of every drive."""
    return [profile_for(d, bus, base_dir) for d in drives]


def layout_of(profile: DriveProfile) -> AxisLayout:
    """The wire layout the profile says the drive will run (its PDOs in assignment order)."""
    return AxisLayout(
        rx=tuple(
            WireEntry(e.index, e.subindex, e.bits) for p in profile.rx_pdos for e in p.entries
        ),
        tx=tuple(
            WireEntry(e.index, e.subindex, e.bits) for p in profile.tx_pdos for e in p.entries
        ),
        rx_pdos=tuple(p.index for p in profile.rx_pdos),
        tx_pdos=tuple(p.index for p in profile.tx_pdos),
    )


def csp_adapter(
    profiles: Sequence[DriveProfile | None],
    cycle_time: float,
    counts_per_rev: Sequence[float] | None = None,
) -> Any:
    """The :class:`~drivers.cia402.csp_adapter.CspAdapter` of axes running ``profiles`` (None:
    the built-in CSP drive) at ``cycle_time`` [s]: ip and pv axes adapted, others untouched;
    ``counts_per_rev`` per axis (encoder counts per motor revolution) scales the velocities
    of drives whose profile says rpm (None: every drive takes counts/s)."""
    from drivers.cia402.csp_adapter import CspAdapter

    loops = [p.modes.loop if p is not None else "csp" for p in profiles]
    gains = [p.modes.position_gain if p is not None else None for p in profiles]
    cpr = list(counts_per_rev) if counts_per_rev is not None else [60.0] * len(profiles)
    units = [
        p.units.counts_per_drive_unit(c) if p is not None and counts_per_rev else (1.0, 1.0)
        for p, c in zip(profiles, cpr, strict=True)
    ]
    return CspAdapter(loops, gains, cycle_time, units)


def refuse_unknown_units(names: Sequence[str], profiles: Sequence[DriveProfile | None]) -> None:
    """Raise :class:`ConfigError` (one line) for the first axis whose profile does not know
    the drive's velocity or acceleration unit (``units.velocity`` / ``units.acceleration``
    ``unknown``). A master of a real bus calls it before anything is configured or enabled:
    a wrong guess would move the drive many times too fast or too slow."""
    for name, p in zip(names, profiles, strict=True):
        if p is None:
            continue
        if p.units.velocity == "unknown":
            raise ConfigError(
                f"{name} ({p.name}): the drive's velocity unit is not stated in its file; set "
                "units.velocity in the profile (counts/s or rpm) after checking the drive's "
                "manual"
            )
        if p.units.acceleration == "unknown":
            raise ConfigError(
                f"{name} ({p.name}): the drive's acceleration unit is not stated in its file; "
                "set units.acceleration in the profile (counts/s^2, rpm/s or rev/s^2) after "
                "checking the drive's manual"
            )


def with_counts_units(profile: DriveProfile) -> tuple[DriveProfile, str | None]:
    """``profile`` with unknown velocity/acceleration units taken as counts/s, counts/s^2,
    and the one line that says so (None: nothing unknown). For emulated drives only: the
    emulator and the master then agree on counts, which proves the layout, not the unit."""
    u = profile.units
    if "unknown" not in (u.velocity, u.acceleration):
        return profile, None
    units = u.model_copy(
        update={
            "velocity": "counts/s" if u.velocity == "unknown" else u.velocity,
            "acceleration": "counts/s^2" if u.acceleration == "unknown" else u.acceleration,
        }
    )
    note = (
        f"{profile.name}: velocity unit unknown in the profile; the emulated drive runs in "
        "counts/s and counts/s^2 (a real bus refuses the axis until units.velocity is set)"
    )
    return profile.model_copy(update={"units": units}), note


def mode_number(profile: DriveProfile) -> int:
    """0x6060 value of the profile's loop mode."""
    from hofto_hw.config.drive_profile import MODE_NUMBERS

    return MODE_NUMBERS[profile.modes.loop]


def startup_int(
    profile: DriveProfile, index: int, sub: int, value: int | str, cycle_time: float
) -> int:
    """The integer a start-up write sends: ``value`` itself, or for ``'loop_period'``
    (0x60C2:01, the interpolation period) the loop period in units of 10^0x60C2:02 s
    (default 10^-3 s)."""
    if isinstance(value, int):
        return value
    exponent = profile.startup_value(0x60C2, 2)
    exponent = -3 if not isinstance(exponent, int) else exponent
    if exponent > 127:
        exponent -= 256
    return round(cycle_time / 10.0**exponent)


def profiles_of_bus(bus: Any) -> list[DriveProfile | None]:
    """Per ``bus.drives[i]``: its loaded profile, or None when it names none (built-in)."""
    return [
        profile_for(d, str(bus.transport)) if getattr(d, "profile", None) else None
        for d in bus.drives
    ]


# ------------------------------------------------------------ configuring a drive by SDO


def write_startup(t: Any, axis: int, profile: DriveProfile, transitions: tuple[str, ...]) -> int:
    """Write ``profile``'s start-up SDOs of ``transitions`` to drive ``axis`` of transport
    ``t``, in the profile's order; returns how many were written."""
    count = 0
    for w in profile.startup:
        if w.transition not in transitions:
            continue
        value = startup_int(profile, w.index, w.subindex, w.value, t.cycle_time)
        value &= (1 << w.bits) - 1  # signed values as their two's complement
        t.sdo_write(axis, w.index, w.subindex, value.to_bytes(w.bits // 8, "little"))
        count += 1
    return count


def _read_u(t: Any, axis: int, index: int, sub: int, size: int) -> int:
    data = t.sdo_read(axis, index, sub)
    return int.from_bytes(bytes(data[:size]).ljust(size, b"\0"), "little")


def assignment(t: Any, axis: int, assign: int) -> list[int]:
    """The PDO indices assigned in ``assign`` (0x1C12/0x1C13) as drive ``axis`` reports."""
    count = _read_u(t, axis, assign, 0, 1)
    return [_read_u(t, axis, assign, k, 2) for k in range(1, count + 1)]


def read_mapping(t: Any, axis: int, index: int) -> list[WireEntry]:
    """The entries of PDO mapping object ``index`` as drive ``axis`` reports them."""
    count = _read_u(t, axis, index, 0, 1)
    out = []
    for k in range(1, count + 1):
        raw = _read_u(t, axis, index, k, 4)
        out.append(WireEntry(raw >> 16, (raw >> 8) & 0xFF, raw & 0xFF))
    return out


def fmt_entries(entries: Sequence[Any]) -> str:
    """``[0x6040:00/16, ...]``."""
    return "[" + ", ".join(f"0x{e[0]:04X}:{e[1]:02X}/{e[2]}" for e in entries) + "]"


def fmt_indices(indices: Sequence[int]) -> str:
    """``[0x1600, ...]``."""
    return "[" + ", ".join(f"0x{i:04X}" for i in indices) + "]"


def configure_pdos(t: Any, axis: int, profile: DriveProfile, error: type[Exception]) -> AxisLayout:
    """Configure drive ``axis`` as ``profile`` says over CoE-style objects (EtherCAT, and the
    in-process simulated bus): the configurable PDOs written (count 0, entries, count), the
    assignment 0x1C12/0x1C13 written where it differs (fixed PDOs only assigned); then the
    assignment and every assigned mapping READ BACK. Returns the layout the drive reports;
    a difference from the profile raises ``error`` in one line naming ``t``'s name of the
    axis, the object, the expected and the found value."""
    from drivers.cia402.pdo import RXPDO_ASSIGN_INDEX, TXPDO_ASSIGN_INDEX

    for assign, pdos in (
        (RXPDO_ASSIGN_INDEX, profile.rx_pdos),
        (TXPDO_ASSIGN_INDEX, profile.tx_pdos),
    ):
        want = [p.index for p in pdos]
        if assignment(t, axis, assign) != want:
            t.write_value(axis, assign, 0, "u8", 0)
            for k, index in enumerate(want):
                t.write_value(axis, assign, k + 1, "u16", index)
            t.write_value(axis, assign, 0, "u8", len(want))
        for p in pdos:
            if p.fixed:
                continue
            t.write_value(axis, p.index, 0, "u8", 0)
            for k, e in enumerate(p.entries):
                t.write_value(
                    axis, p.index, k + 1, "u32", (e.index << 16) | (e.subindex << 8) | e.bits
                )
            t.write_value(axis, p.index, 0, "u8", len(p.entries))
    found: dict[str, tuple[list[int], list[WireEntry]]] = {}
    who = t._who(axis)
    for side, assign, pdos in (
        ("rx", RXPDO_ASSIGN_INDEX, profile.rx_pdos),
        ("tx", TXPDO_ASSIGN_INDEX, profile.tx_pdos),
    ):
        got = assignment(t, axis, assign)
        want = [p.index for p in pdos]
        if got != want:
            raise error(
                f"{who}: 0x{assign:04X} reads back {fmt_indices(got)}, profile {profile.name} "
                f"expects {fmt_indices(want)}"
            )
        entries: list[WireEntry] = []
        for p in pdos:
            read = read_mapping(t, axis, p.index)
            expect = [WireEntry(e.index, e.subindex, e.bits) for e in p.entries]
            if read != expect:
                raise error(
                    f"{who}: 0x{p.index:04X} reads back {fmt_entries(read)}, profile "
                    f"{profile.name} expects {fmt_entries(expect)}"
                )
            entries.extend(read)
        found[side] = (got, entries)
    return AxisLayout(
        rx=tuple(found["rx"][1]),
        tx=tuple(found["tx"][1]),
        rx_pdos=tuple(found["rx"][0]),
        tx_pdos=tuple(found["tx"][0]),
    )
