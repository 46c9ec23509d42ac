"""Choose the process-data layout the loop needs from what a vendor file allows.

Input: a :class:`~drivers.profiles.description.DeviceDescription` (ESI or EDS). Output: a
validated :class:`~hofto_hw.config.drive_profile.DriveProfile` and the reasons, one line each,
that ``hofto-hw drive import`` prints.

EtherCAT: two candidate assignments per direction are compared by how much of what the loop
wants they map (weights in :data:`WEIGHTS`; the loop cannot run without the controlword,
statusword, position and the loop mode's target):

- fixed PDOs, picked greedily (most wanted objects first, then the smaller PDO), never two
  that exclude each other (``<Exclude>``) or map one object twice, within the sync manager;
- the configurable PDOs (``Fixed="0"``), filled with the wanted objects the dictionary lets
  map in that direction, in the built-in layout's order, up to each PDO's mapping entries.

A tie goes to the fixed PDOs (nothing is written; the vendor's own layout). CANopen: every PDO
is configurable; the wanted objects are packed first-fit into as few PDOs as the frame size
(64 bits) and the mapping entries allow, in the built-in CANopen layout's order; error code and
digital inputs do not travel cyclically there (EMCY; no input), as in drivers/canopen/layout.py.

Objects the layout cannot map get a fallback (:data:`hofto_hw.config.drive_profile.FALLBACKS`);
the mode, when 0x6060 cannot be mapped, becomes a start-up write.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace

from pydantic import ValidationError

from drivers.canopen.layout import MAX_PDOS_BY_RULE, pdo_cob_base
from drivers.profiles.description import DeviceDescription, PdoOption, ProfileImportError
from hofto_hw.config.drive_profile import (
    CIA402_OBJECTS,
    CYCLIC_TARGETS,
    FIELD_OBJECTS,
    LOOP_OBJECTS,
    LOOP_TARGET_OBJECTS,
    LOOP_TARGETS,
    MODE_NUMBERS,
    SETTING_OBJECTS,
    SUB_OBJECTS,
    DriveProfile,
    format_profile_error,
    modes_from_bits,
)

#: what each object is worth to the loop (essential ones dominate everything else)
WEIGHTS: dict[str, int] = {
    "controlword": 1000,
    "statusword": 1000,
    "position": 1000,
    "target_position": 20,
    "target_velocity": 20,
    "target_torque": 20,
    "velocity": 40,
    "torque": 40,
    "current": 10,
    "mode": 15,
    "torque_offset": 12,
    "error_code": 8,
    "digital_inputs": 8,
    "mode_display": 3,
}
WANTED_RX = ("controlword", "mode", "target_position", "target_velocity", "target_torque",
             "torque_offset")  # fmt: skip
WANTED_TX = ("statusword", "mode_display", "position", "velocity", "torque", "current",
             "error_code", "digital_inputs")  # fmt: skip
#: CANopen packing order (drivers/canopen/layout.py's frames: controlword + position target
#: + torque offset fill 64 bits; status + position + torque likewise)
CAN_RX = ("controlword", "target_position", "torque_offset", "target_velocity", "target_torque",
          "mode")  # fmt: skip
CAN_TX = ("statusword", "position", "torque", "velocity", "current", "mode_display")
CAN_FRAME_BITS = 64
#: ip / pv: the wanted RxPDO objects (the target is the mode's own; no other target travels)
NON_CYCLIC_RX = ("controlword", "target", "torque_offset", "mode")
#: loop pv: the master's position-loop gain [1/s] the importer writes (modes.position_gain):
#: a quarter of the 40 rad/s velocity-loop bandwidth a drive keeps at a 200 Hz CANopen cycle
#: (bandwidth x period <= 0.2), and 0.05 per cycle of the two cycles a SYNC round trip lags
PV_POSITION_GAIN = 10.0
#: PDO configuration objects an ESI InitCmd may write: the profile's PDO lists replace them
PDO_CONFIG = (range(0x1600, 0x1800), range(0x1A00, 0x1C00), range(0x1C12, 0x1C14))


@dataclass
class Choice:
    """The imported profile and why it looks as it does."""

    profile: DriveProfile
    reasons: list[str] = field(default_factory=list)


def is_drive(desc: DeviceDescription) -> bool:
    """Whether the description is a CiA-402 drive: controlword, statusword and position
    actual value (0x6040, 0x6041, 0x6064, 16/16/32 bits) in its dictionary or PDOs."""
    need = {0x6040: 16, 0x6041: 16, 0x6064: 32}
    return all(
        (info := desc.objects.get((index, 0))) is not None and info.bits in (None, bits)
        for index, bits in need.items()
    )


def slug(text: str) -> str:
    """A profile name from free text: lower case, ``[a-z0-9_]``."""
    return re.sub(r"[^a-z0-9]+", "_", text.lower()).strip("_") or "drive"


def _field(index: int, sub: int) -> str | None:
    known = CIA402_OBJECTS.get(index) if sub == 0 else SUB_OBJECTS.get((index, sub))
    return known[0] if known else None


def _key(name: str, loop: str) -> tuple[int, int]:
    """(index, sub-index) that carries process-image field ``name`` when the loop runs
    ``loop``: the loop target's own object (ip: 0x60C1:01), else the CiA-402 object."""
    if name == LOOP_TARGETS[loop]:
        return LOOP_TARGET_OBJECTS[loop]
    return FIELD_OBJECTS[name], 0


def _bits(key: tuple[int, int]) -> int:
    return (CIA402_OBJECTS[key[0]] if key[1] == 0 else SUB_OBJECTS[key])[1]


def _rx_mappable(desc: DeviceDescription, key: tuple[int, int]) -> bool:
    return "rx" in getattr(desc.objects.get(key), "mappable", "")


def _non_cyclic_loop(desc: DeviceDescription, modes: list[str], reasons: list[str]) -> str | None:
    """ip or pv for a drive without a cyclic synchronous mode (None: neither can run)."""
    period = desc.objects.get((0x60C2, 1))
    if "ip" in modes and _rx_mappable(desc, (0x60C1, 1)) and period and period.writable:
        reasons.append(
            "loop: ip (interpolated position, 0x6060 = 7): no cyclic synchronous mode; the "
            "loop's position target goes to 0x60C1:01 every SYNC, the interpolation period "
            "0x60C2 is the loop period and controlword bit 4 enables ip mode once the drive "
            "is in Operation enabled (statusword bit 12 acknowledges): csp to the loop"
        )
        return "ip"
    if "pv" in modes and _rx_mappable(desc, (0x60FF, 0)):
        reasons.append(
            "loop: pv (profile velocity, 0x6060 = 3) streamed: no cyclic synchronous mode"
            + (" and no ip" if "ip" not in modes else " and ip cannot be mapped")
            + "; the target velocity 0x60FF is sent every SYNC and the master closes the "
            f"position loop on top (modes.position_gain {PV_POSITION_GAIN:g}/s, velocity "
            "feed-forward from the target's change per cycle): csp to the loop; the profile "
            "acceleration/deceleration 0x6083/0x6084 are written when the mode is selected "
            "(the joint's quick_stop_deceleration), so the drive's ramp does not filter the stream"
        )
        return "pv"
    return None


def _fields(pdo: PdoOption) -> set[str]:
    return {f for i, s, _ in pdo.entries if (f := _field(i, s)) is not None}


def _worth(names: set[str]) -> int:
    return sum(WEIGHTS.get(n, 0) for n in names)


def supported_modes(desc: DeviceDescription, reasons: list[str]) -> list[str]:
    """Modes from 0x6502's default; without one, inferred from the targets and InitCmds."""
    value = desc.default_of(0x6502)
    if value:
        modes = modes_from_bits(value)
        reasons.append(f"modes: 0x6502 = 0x{value:X}: {', '.join(modes) or 'none'}")
        return modes
    modes = [m for m, t in CYCLIC_TARGETS.items() if desc.has(FIELD_OBJECTS[t])]
    for cmd in desc.init:
        for name, number in MODE_NUMBERS.items():
            if cmd.index == 0x6060 and cmd.value == number and name not in modes:
                modes.append(name)
    why = "the file has no dictionary" if not desc.has_dictionary else "0x6502 has no default"
    reasons.append(
        f"modes: {why}; assumed from the targets it can map and its start-up writes: "
        f"{', '.join(modes) or 'none'}"
    )
    return modes


def choose(desc: DeviceDescription, loop: str | None = None, name: str | None = None) -> Choice:
    """Build the profile of ``desc`` for the loop mode ``loop`` (None: csp, else csv, cst).

    Raises:
        ProfileImportError: one line: not a CiA-402 drive, no cyclic synchronous mode, the loop
            mode's target cannot be mapped, or a PDO larger than its sync manager.
    """
    where = f"{desc.path}: {desc.device}"
    if not is_drive(desc):
        raise ProfileImportError(
            f"{where}: no CiA-402 drive described (no controlword 0x6040, statusword 0x6041 "
            "and position actual value 0x6064)"
        )
    _check_sync_managers(desc, where)
    reasons: list[str] = []
    modes = supported_modes(desc, reasons)
    cyclic = [m for m in CYCLIC_TARGETS if m in modes]
    if loop is None and not cyclic:
        loop = _non_cyclic_loop(desc, modes, reasons)
        if loop is None:
            absent = [
                f"0x{FIELD_OBJECTS[n]:04X} {n}"
                for n in LOOP_OBJECTS
                if not desc.has(FIELD_OBJECTS[n])
            ]
            raise ProfileImportError(
                f"{where}: no cyclic synchronous mode (csp, csv, cst) for the loop, nor ip "
                "with 0x60C1:01 mappable and 0x60C2:01 writable, nor pv with 0x60FF mappable: "
                f"the drive supports {', '.join(modes) or 'none'}"
                + (f"; absent too: {', '.join(absent)}" if absent else "")
            )
    elif loop is None:
        mappable = [
            m
            for m in cyclic
            if "rx"
            in getattr(desc.objects.get((FIELD_OBJECTS[CYCLIC_TARGETS[m]], 0)), "mappable", "")
        ]
        loop = (mappable or cyclic)[0]
        if loop != cyclic[0]:
            reasons.append(
                f"loop: {loop}, the first cyclic mode whose target the drive can map "
                f"({', '.join(m for m in cyclic if m not in mappable)}: target not mappable)"
            )
    elif loop not in modes:
        raise ProfileImportError(
            f"{where}: --loop {loop}: the drive supports {', '.join(modes) or 'none'}"
        )
    target = LOOP_TARGETS[loop]
    if loop not in CYCLIC_TARGETS:
        wanted_rx = tuple(target if n == "target" else n for n in NON_CYCLIC_RX)
        can_rx = wanted_rx
    else:
        wanted_rx, can_rx = WANTED_RX, CAN_RX
    if desc.bus == "ethercat":
        rx, rx_why = _ethercat_side(desc, "rx", wanted_rx, loop)
        tx, tx_why = _ethercat_side(desc, "tx", WANTED_TX, loop)
    else:
        rx, rx_why = _can_side(desc, "rx", can_rx, target, loop)
        tx, tx_why = _can_side(desc, "tx", CAN_TX, target, loop)
    reasons += [rx_why, tx_why]
    mapped = set().union(*(_fields(p) for p in rx + tx))
    for needed in ("controlword", "statusword", "position", target):
        if needed not in mapped:
            raise ProfileImportError(
                f"{where}: cannot map {needed} (0x{_key(needed, loop)[0]:04X}) that the {loop} "
                "loop needs: no PDO of the file carries it"
            )
    fallbacks, objects = _fallbacks(desc, mapped, reasons)
    objects["absent_settings"] = _absent_settings(desc, reasons)
    set_by = "pdo" if "mode" in mapped else "startup"
    vendor = desc.vendor_name.split()[0] if desc.vendor_name else f"vendor{desc.vendor_id:x}"
    startup = _startup(desc, loop, set_by, reasons)
    data = {
        "profile": 1,
        "name": name or slug(f"{vendor}_{desc.device}"),
        "description": f"{desc.vendor_name} {desc.device} (product 0x{desc.product_code:08X}"
        + (f", revision 0x{desc.revision:08X}" if desc.revision is not None else "")
        + f"), imported from {desc.path.name}"
        + (
            " (an IgH `ethercat xml` SII dump, not the vendor's ESI)"
            if desc.kind == "igh-sii-dump"
            else ""
        ),
        "source": {"file": desc.path.name, "device": desc.device, "sha256": desc.sha256},
        "identity": {
            "vendor_id": desc.vendor_id,
            "product_code": desc.product_code,
            "revision_min": desc.revision,
        },
        "bus": desc.bus,
        "axes": 1,
        "modes": {"supported": modes, "loop": loop, "set_by": set_by}
        | ({"position_gain": PV_POSITION_GAIN} if loop == "pv" else {}),
        "rx_pdos": [_pdo_dict(p) for p in rx],
        "tx_pdos": [_pdo_dict(p) for p in tx],
        "objects": objects,
        "fallbacks": fallbacks,
        "startup": startup,
        "dc": _dc(desc, reasons) if desc.bus == "ethercat" else None,
        "process_data": {"rx_bytes": desc.sm_rx_bytes, "tx_bytes": desc.sm_tx_bytes},
        "canopen": _canopen(desc, rx, tx, reasons) if desc.bus == "canopen" else None,
        "units": _units(desc, loop, reasons),
        "brake": _brake(desc, reasons),
    }
    axes = sum(desc.has(0x6040 + 0x800 * k) for k in range(8))
    if axes > 1:
        reasons.append(f"axes: the device has {axes} CiA-402 axes; this profile maps axis 0")
    try:
        profile = DriveProfile.model_validate(data)
    except ValidationError as err:
        first = format_profile_error(str(desc.path), err).splitlines()[0]
        raise ProfileImportError(f"{first} (device {desc.device})") from None
    return Choice(profile, reasons)


def _check_sync_managers(desc: DeviceDescription, where: str) -> None:
    for pdo in desc.pdos:
        limit = desc.sm_rx_bytes if pdo.direction == "rx" else desc.sm_tx_bytes
        if pdo.bits % 8 == 0 and limit is not None and pdo.bits // 8 > limit:
            sm = 2 if pdo.direction == "rx" else 3
            raise ProfileImportError(
                f"{where}: PDO 0x{pdo.index:04X} is {pdo.bits // 8} bytes, more than sync "
                f"manager {sm}'s MaxSize {limit}"
            )


def _max_entries(desc: DeviceDescription, pdo: PdoOption) -> int:
    if pdo.max_entries:
        return pdo.max_entries
    subs = [s for (i, s) in desc.objects if i == pdo.index and s > 0]
    return len(subs) or 8


def _ethercat_side(
    desc: DeviceDescription, side: str, wanted: tuple[str, ...], loop: str = "csp"
) -> tuple[list[PdoOption], str]:
    options = [p for p in desc.pdos if p.direction == side]
    notes = []
    if loop == "ip":  # a fixed PDO with 0x607A (pp's target) would map the target twice
        dropped = [p for p in options if p.fixed and any(i == 0x607A for i, _, _ in p.entries)]
        options = [p for p in options if p not in dropped]
        if dropped:
            notes.append(
                f"{len(dropped)} fixed PDO(s) with 0x607A left out: ip's target is 0x60C1:01"
            )
    if not desc.pdo_config:  # mappings cannot be written: every PDO is as the file gives it
        options = [replace(p, fixed=True) for p in options if p.entries]
        notes.append("PdoConfig=0: no mapping is written")
    if not desc.pdo_assign:  # the default assignment is the only one
        options = [replace(p, mandatory=p.fixed) for p in options if p.default]
        notes.append("PdoAssign=0: the default assignment is kept")
    limit = desc.sm_rx_bytes if side == "rx" else desc.sm_tx_bytes
    fixed = _greedy_fixed([p for p in options if p.fixed and p.entries], wanted, limit)
    mandatory = [p for p in options if p.fixed and p.mandatory]
    conf = _configurable(
        desc, [p for p in options if not p.fixed], side, wanted, limit, mandatory, loop
    )
    if all(p.fixed for p in conf):
        conf = []  # nothing configurable: the fixed branch holds the mandatory PDOs too
    got_fixed = set().union(*(_fields(p) for p in fixed)) & set(wanted)
    got_conf = set().union(*(_fields(p) for p in conf)) & set(wanted)
    names = lambda ps: " + ".join(f"0x{p.index:04X}" for p in ps) or "none"  # noqa: E731
    missing = lambda got: sorted(set(wanted) - got)  # noqa: E731
    if fixed and _worth(got_fixed) >= _worth(got_conf):
        why = (
            f"{side}: fixed {names(fixed)}: maps {len(got_fixed)} of {len(wanted)} wanted objects"
            + (f" (not {', '.join(missing(got_fixed))})" if missing(got_fixed) else "")
            + (
                f"; configurable {names(conf)} would map no more: the vendor's fixed PDOs "
                "need no writing"
                if conf
                else "; the file has no configurable PDO"
            )
        )
        return fixed, why + "".join(f"; {n}" for n in notes)
    if not conf:
        return [], f"{side}: no PDO maps what the loop needs"
    unused = [p for p in options if not p.fixed and p.default and p not in conf and p.entries]
    if not desc.pdo_assign and any(p.index not in {c.index for c in conf} for p in unused):
        raise ProfileImportError(
            f"{desc.path}: {desc.device}: PdoAssign=0 keeps configurable PDO "
            f"0x{unused[0].index:04X} assigned, but the layout does not need it: not supported"
        )
    why = (
        f"{side}: configurable {names(conf)} written with {len(got_conf)} of {len(wanted)} "
        "wanted objects"
        + (f" (not mappable: {', '.join(missing(got_conf))})" if missing(got_conf) else "")
        + (
            f"; the best fixed set {names(fixed)} maps {len(got_fixed)}"
            + (f" (not {', '.join(missing(got_fixed))})" if missing(got_fixed) else "")
            if fixed
            else "; the file has no fixed PDO"
        )
    )
    return conf, why + "".join(f"; {n}" for n in notes)


def _greedy_fixed(
    options: list[PdoOption], wanted: tuple[str, ...], limit: int | None
) -> list[PdoOption]:
    chosen = [p for p in options if p.mandatory]  # ESI Mandatory="1": always assigned
    covered = set().union(*(_fields(p) for p in chosen))
    keys = {(i, s) for p in chosen for i, s, _ in p.entries if i}
    total = sum(p.bits // 8 for p in chosen)
    while True:
        best: tuple[tuple[int, int, int], PdoOption] | None = None
        for p in options:
            if p in chosen or any(p.index in c.excludes or c.index in p.excludes for c in chosen):
                continue
            pk = {(i, s) for i, s, _ in p.entries if i}
            if pk & keys or p.bits % 8 or (limit is not None and total + p.bits // 8 > limit):
                continue
            gain = _worth((_fields(p) & set(wanted)) - covered)
            if gain <= 0:
                continue
            score = (gain, -p.bits, -p.index)
            if best is None or score > best[0]:
                best = (score, p)
        if best is None:
            return chosen
        p = best[1]
        chosen.append(p)
        covered |= _fields(p)
        keys |= {(i, s) for i, s, _ in p.entries if i}
        total += p.bits // 8


def _configurable(
    desc: DeviceDescription,
    options: list[PdoOption],
    side: str,
    wanted: tuple[str, ...],
    limit: int | None,
    mandatory: list[PdoOption] = (),  # type: ignore[assignment]
    loop: str = "csp",
) -> list[PdoOption]:
    """Wanted objects mappable in ``side``, written into the configurable PDOs in order
    (default-assigned ones first), each up to its mapping entries, within the sync manager;
    after the ``mandatory`` fixed PDOs, whose objects are not mapped again."""
    objs = []
    for name in wanted:
        key = _key(name, loop)
        info = desc.objects.get(key)
        if info is not None and side in info.mappable:
            objs.append((*key, _bits(key)))
    out = [p for p in mandatory if p.direction == side]  # assigned whatever is written
    carried = {(i, s) for p in out for i, s, _ in p.entries}
    objs = [o for o in objs if o[:2] not in carried]
    fixed_bits = sum(p.bits for p in out)
    if limit is not None:
        while objs and (fixed_bits + sum(b for _, _, b in objs)) // 8 > limit:
            objs.pop()
    for p in sorted(options, key=lambda p: (not p.default, p.index)):
        if not objs:
            break
        if any(p.index in c.excludes or c.index in p.excludes for c in out):
            continue
        n = _max_entries(desc, p)
        take, objs = objs[:n], objs[n:]
        out.append(
            PdoOption(
                p.index, p.direction, fixed=False, entries=take, excludes=p.excludes,
                default=True, max_entries=n, name=p.name,
            )
        )  # fmt: skip
    return out


def _can_side(
    desc: DeviceDescription, side: str, order: tuple[str, ...], target: str, loop: str = "csp"
) -> tuple[list[PdoOption], str]:
    names = list(order)
    if side == "rx":  # controlword, then the loop's target
        names.remove(target)
        names.insert(1, target)
    options = sorted(
        (p for p in desc.pdos if p.direction == side and not p.fixed), key=lambda p: p.index
    )
    objs = []
    skipped = []
    for n in names:
        key = _key(n, loop)
        info = desc.objects.get(key)
        if info is not None and side in info.mappable:
            objs.append((*key, _bits(key)))
        else:
            skipped.append(n)
    frames: list[list[tuple[int, int, int]]] = []
    caps = [min(_max_entries(desc, p), 64) for p in options]
    for obj in objs:  # first fit, in priority order
        for k, frame in enumerate(frames):
            if sum(b for _, _, b in frame) + obj[2] <= CAN_FRAME_BITS and len(frame) < caps[k]:
                frame.append(obj)
                break
        else:
            if len(frames) < len(options):
                frames.append([obj])
            else:
                skipped.append(_field(obj[0], 0) or f"0x{obj[0]:04X}")
    pdos = [
        PdoOption(
            p.index,
            side,
            fixed=False,
            entries=frame,
            default=True,  # type: ignore[arg-type]
            max_entries=caps[k],
            name=p.name,
        )
        for k, (p, frame) in enumerate(zip(options[: len(frames)], frames, strict=True))
    ]
    why = (
        f"{side}: {' + '.join(f'0x{p.index:04X}' for p in pdos)} written, first-fit into "
        f"{CAN_FRAME_BITS}-bit frames of at most {min(caps) if caps else 0} entries"
        + (f" (not mapped: {', '.join(skipped)})" if skipped else "")
    )
    return pdos, why


def _pdo_dict(p: PdoOption) -> dict:
    return {
        "index": p.index,
        "fixed": p.fixed,
        "entries": [{"index": i, "subindex": s, "bits": b} for i, s, b in p.entries],
    }


def _fallbacks(
    desc: DeviceDescription, mapped: set[str], reasons: list[str]
) -> tuple[dict[str, str], dict[str, list[str]]]:
    fallbacks: dict[str, str] = {}
    objects: dict[str, list[str]] = {"mapped": [], "sdo": [], "absent": []}
    can = desc.bus == "canopen"
    for name in LOOP_OBJECTS:
        if name in mapped:
            objects["mapped"].append(name)
            continue
        present = desc.has(FIELD_OBJECTS[name])
        objects["sdo" if present else "absent"].append(name)
        how = {
            "mode": "startup",
            "mode_display": "sdo" if present else "unavailable",
            "torque_offset": "target_torque_in_cst" if "target_torque" in mapped else "unavailable",
            "velocity": "position_derivative",
            "torque": "current" if "current" in mapped else "unavailable",
            "error_code": "sdo" if present and not can else "emcy",
            "digital_inputs": "none",
        }.get(name, "unavailable")
        fallbacks[name] = how
        where = "not mapped" if present else "absent"
        if not desc.has_dictionary and not present:
            where = "not mapped (the file has no dictionary)"
        reasons.append(f"object 0x{FIELD_OBJECTS[name]:04X} {name}: {where} -> {how}")
    return fallbacks, objects


def _absent_settings(desc: DeviceDescription, reasons: list[str]) -> list[str]:
    """The setting objects (SETTING_OBJECTS) the file's dictionary lacks; a file without a
    dictionary says nothing about them: all are taken as present (configure writes them)."""
    if not desc.has_dictionary:
        reasons.append(
            "settings: the file has no dictionary; 0x6072, 0x6075, 0x6076, 0x6065, 0x6066, "
            "0x6085 taken as present (configure writes them; list any the drive lacks in "
            "objects.absent_settings)"
        )
        return []
    out = []
    for name, (index, how) in SETTING_OBJECTS.items():
        if not desc.has(index):
            out.append(name)
            reasons.append(f"object 0x{index:04X} {name}: absent -> {how}")
    return out


def _startup(desc: DeviceDescription, loop: str, set_by: str, reasons: list[str]) -> list[dict]:
    can = desc.bus == "canopen"
    out: list[dict] = []
    for cmd in desc.init:
        what = f"InitCmd 0x{cmd.index:04X}:{cmd.subindex:02X}"
        if any(cmd.index in r for r in PDO_CONFIG):
            reasons.append(f"startup: {what} dropped: the profile's PDO lists configure the PDOs")
            continue
        if cmd.bits not in (8, 16, 32, 64):
            reasons.append(f"startup: {what} dropped: {cmd.bits // 8} bytes of data")
            continue
        value: int | str = cmd.value
        comment = cmd.comment or "from the vendor file"
        if (cmd.index, cmd.subindex) == (0x6060, 0):
            if set_by == "pdo":
                reasons.append(f"startup: {what} dropped: the mode is mapped")
                continue
            value = MODE_NUMBERS[loop]
            if cmd.value != value:
                comment += f" (file: {cmd.value}; the loop runs {loop})"
        elif (cmd.index, cmd.subindex) == (0x60C2, 1):
            value = "loop_period"
            comment += f" (file: {cmd.value}; the master writes the loop period)"
        bits = cmd.bits
        info = desc.objects.get((cmd.index, cmd.subindex))
        if info is not None and info.bits in (8, 16, 32, 64) and info.bits != bits:
            if isinstance(value, str) or 0 <= value < 1 << info.bits:
                bits = info.bits  # the object's size, not the length the file wrote the data in
        if isinstance(value, int) and value >= 1 << (bits - 1) and _signed(cmd.index):
            value -= 1 << bits
        for transition in cmd.transitions or ["PS"]:
            out.append(
                {
                    "index": cmd.index,
                    "subindex": cmd.subindex,
                    "value": value,
                    "bits": bits,
                    "transition": "PO" if can else transition,
                    "comment": comment,
                }
            )
    has = {(s["index"], s["subindex"]) for s in out}
    period = desc.objects.get((0x60C2, 1))
    if (0x60C2, 1) not in has and period is not None and period.writable:
        out.append(
            {
                "index": 0x60C2,
                "subindex": 1,
                "value": "loop_period",
                "bits": period.bits if period.bits in (8, 16, 32) else 8,
                "transition": "PO" if can else "PS",
                "comment": "interpolation period = the loop period (CiA 402; the master writes it)",
            }
        )
        has.add((0x60C2, 1))
    unit = desc.objects.get((0x60C2, 2))
    if (
        (0x60C2, 1) in has
        and (0x60C2, 2) not in has
        and unit is not None
        and (unit.writable or not unit.access)
    ):
        out.append(
            {
                "index": 0x60C2,
                "subindex": 2,
                "value": -3,
                "bits": 8,
                "transition": "PO" if can else "PS",
                "comment": "interpolation period unit 1e-3 s (the master's loop_period unit)",
            }
        )
    submode = desc.objects.get((0x60C0, 0))
    if loop == "ip" and (0x60C0, 0) not in has and submode is not None and submode.writable:
        out.append(
            {
                "index": 0x60C0,
                "subindex": 0,
                "value": 0,
                "bits": 16,
                "transition": "PO" if can else "PS",
                "comment": "interpolation sub-mode 0: linear interpolation (CiA 402)",
            }
        )
    if set_by == "startup" and (0x6060, 0) not in has:
        out.append(
            {
                "index": 0x6060,
                "subindex": 0,
                "value": MODE_NUMBERS[loop],
                "bits": 8,
                "transition": "PO" if can else "PS",
                "comment": f"mode {loop}: 0x6060 cannot be mapped",
            }
        )
    if out:
        reasons.append(
            f"startup: {len(out)} write(s): "
            + ", ".join(f"0x{s['index']:04X}:{s['subindex']:02X}={s['value']}" for s in out)
        )
    return out


def _signed(index: int) -> bool:
    return index in (0x6060, 0x60C2, 0x60C0)


def _dc(desc: DeviceDescription, reasons: list[str]) -> dict | None:
    for op in desc.dc:
        if op.assign_activate:
            reasons.append(
                f"dc: op mode {op.name!r}: AssignActivate 0x{op.assign_activate:04X}, SYNC0 "
                + (
                    f"fixed at {op.sync0_cycle_ns} ns"
                    if op.sync0_cycle_ns
                    else "at the loop period"
                )
                + f", shift {op.sync0_shift_ns} ns"
                + (f", SYNC1 {op.sync1_cycle_ns} ns" if op.sync1_cycle_ns else "")
            )
            return {
                "assign_activate": op.assign_activate,
                "sync0_cycle_ns": op.sync0_cycle_ns,
                "sync0_shift_ns": op.sync0_shift_ns,
                "sync1_cycle_ns": op.sync1_cycle_ns,
                "sync1_shift_ns": op.sync1_shift_ns if op.sync1_cycle_ns else None,
            }
    reasons.append(
        "dc: the file describes no DC op mode: free run / SM-synchronous"
        + (
            " (an SII dump carries none; add a dc: section if the drive needs it)"
            if desc.kind == "igh-sii-dump"
            else ""
        )
    )
    return None


def _canopen(
    desc: DeviceDescription, rx: list[PdoOption], tx: list[PdoOption], reasons: list[str]
) -> dict:
    def comm(p: PdoOption) -> dict:
        c = desc.comm.get(p.index)
        number = (p.index & 0x1FF) + 1
        if c is not None:
            base = c.cob_id_base
        elif number <= MAX_PDOS_BY_RULE:  # CiA 301's default, beyond PDO4 our rule
            base = pdo_cob_base("rpdo" if p.direction == "rx" else "tpdo", number)
        else:
            raise ProfileImportError(
                f"{desc.path}: {desc.device}: 0x{p.index:04X}: PDO{number} has no COB-ID in "
                f"the file and the master's rule covers PDOs 1..{MAX_PDOS_BY_RULE} "
                "(docs/canopen.md)"
            )
        tt = c.transmission_type if c is not None else None
        enabled = c.enabled if c is not None else False
        reasons.append(
            f"canopen: 0x{p.index:04X}: COB-ID 0x{base:03X} + node id"
            + ("" if enabled else " (disabled in the file: bit 31 set; the master enables it)")
            + (
                f", transmission type {tt} in the file -> 1 (every SYNC)"
                if tt not in (None, 1)
                else ", transmission type 1 (every SYNC)"
            )
        )
        return {"cob_id_base": base, "transmission_type": 1, "enabled_by_default": enabled}

    caps = [p.max_entries or 8 for p in rx + tx]
    rates = sorted(desc.bitrates) or [1_000_000]
    reasons.append(f"canopen: bitrates {', '.join(f'{r // 1000} kbit/s' for r in rates)}")
    ids = (1, 127)
    if desc.node_id is not None and 1 <= desc.node_id <= 127:
        ids = (desc.node_id, desc.node_id)
        reasons.append(f"canopen: node id {desc.node_id} (the DCF's [DeviceComissioning])")
    return {
        "node_ids": ids,
        "bitrates": rates,
        "max_entries": min(caps),
        "rpdo": [comm(p) for p in rx],
        "tpdo": [comm(p) for p in tx],
        "heartbeat_ms": None,
    }


#: vendor id -> the objects of the holding-brake delays of a drive that controls its brake
#: (CiA 402 has no standard one): (release, engage), each (index, sub), SI unit per count; from
#: the vendors' object names: Inovance H02-10 "Delay from brake output on to command received"
#: and H02-11 "... off to motor de-energized"; Nanotec 2038h:04 "Start Operation delay time"
#: and :01 "Close Brake idle time"; Synapticon 0x2004:3 "Pull time" and :5 "Controller
#: disable delay"; all in ms. Used only when the vendor file has both objects, writable.
BRAKE_DELAYS: dict[int, tuple[tuple[int, int], tuple[int, int], float]] = {
    0x00100000: ((0x2002, 10), (0x2002, 11), 0.001),
    0x0000026C: ((0x2038, 4), (0x2038, 1), 0.001),
    0x000022D2: ((0x2004, 3), (0x2004, 5), 0.001),
}


def _brake(desc: DeviceDescription, reasons: list[str]) -> dict | None:
    known = BRAKE_DELAYS.get(desc.vendor_id)
    if known is None:
        return None
    out: dict = {}
    for what, (index, sub) in (("release_delay", known[0]), ("engage_delay", known[1])):
        info = desc.objects.get((index, sub))
        if info is None or info.bits not in (8, 16, 32) or not info.writable:
            return None
        out[what] = {"index": index, "subindex": sub, "bits": info.bits, "unit": known[2]}
        named = f"{info.name!r}, " if info.name and info.name != "Elements" else ""
        reasons.append(f"brake: {what} written to 0x{index:04X}:{sub:02X} ({named}ms)")
    return out


#: loop modes that send the drive velocities (target velocity 0x60FF, profile ramps)
VELOCITY_LOOPS = ("pv", "csv")
#: velocity encoder factor, gear ratio on velocity, velocity factor, acceleration factor
VELOCITY_FACTOR_OBJECTS = (0x6094, 0x6095, 0x6096, 0x6097)


def _units(desc: DeviceDescription, loop: str, reasons: list[str]) -> dict:
    out = {}
    for key, index in (
        ("position_encoder_resolution", 0x608F),
        ("gear_ratio", 0x6091),
        ("feed_constant", 0x6092),
    ):
        present = desc.has(index, 1) or desc.has(index, 0)
        a, b = desc.default_of(index, 1), desc.default_of(index, 2)
        out[key] = {
            "present": present,
            "default": (a, b) if a is not None and b is not None else None,
        }
    factors = [i for i in VELOCITY_FACTOR_OBJECTS if desc.has(i, 1) or desc.has(i, 0)]
    if loop in VELOCITY_LOOPS and not factors:
        out["velocity"] = out["acceleration"] = "unknown"
        out["scaling"] = (
            "position in encoder increments; velocity and acceleration units not stated in "
            "the file; torque and current in per mille of rated"
        )
        reasons.append(
            f"units: velocity and acceleration unknown: the {loop} loop sends velocities "
            "(0x60FF, 0x6083-0x6085) but the file has no velocity factor objects "
            "(0x6094-0x6097) to say their unit; set units.velocity and units.acceleration "
            "after checking the drive's manual (a real bus refuses the axis until then)"
        )
    return out
