"""Read a CANopen EDS/DCF file (CiA 306, INI format) into a device description.

What the loop needs from it: identity ([DeviceInfo] VendorNumber, ProductNumber,
RevisionNumber, or 0x1018's defaults), the bitrates it supports (``BaudRate_<kbit>=1``), the
objects and whether each may be mapped (``PDOMapping=1``), the RPDO/TPDO communication
(0x1400../0x1800..: COB-ID as ``$NODEID+0x200``, bit 31 set = disabled by default, transmission
type) and mapping objects (0x1600../0x1A00..: the number of mapping sub-indices is the most
entries a PDO takes), 0x6502 (modes) and the units objects. Values are read as CiA 306 writes
them: ``0x`` hex or decimal, ``$NODEID+`` expressions, and hex limits of signed objects.
"""

from __future__ import annotations

import configparser
import re
from pathlib import Path

from drivers.profiles.description import (
    CanComm,
    DeviceDescription,
    ObjectInfo,
    PdoOption,
    ProfileImportError,
    file_sha256,
    read_vendor_file,
)

WHAT = "EDS file (CANopen INI)"
#: CiA 301 data types -> bit length (BOOLEAN .. UNSIGNED64)
DATA_BITS = {0x1: 1, 0x2: 8, 0x3: 16, 0x4: 32, 0x5: 8, 0x6: 16, 0x7: 32, 0x8: 32, 0x10: 24,
             0x11: 64, 0x12: 40, 0x13: 48, 0x14: 56, 0x15: 64, 0x16: 24, 0x18: 40, 0x19: 48,
             0x1A: 56, 0x1B: 64}  # fmt: skip
SIGNED = {0x2, 0x3, 0x4, 0x10, 0x12, 0x13, 0x14, 0x15}
_NODEID = re.compile(r"\$NODEID", re.IGNORECASE)


def eds_int(text: str | None, node_id: int = 0) -> int | None:
    """A CiA 306 number: ``0x..`` hex, decimal, or an expression with ``$NODEID`` (e.g.
    ``$NODEID+0x200``), evaluated with ``node_id``; None when empty."""
    if text is None:
        return None
    t = text.split(";")[0].strip()
    if not t:
        return None
    t = _NODEID.sub(str(node_id), t)
    total = 0
    for term in t.replace(" ", "").split("+"):
        if not term:
            continue
        neg = term.startswith("-")
        term = term.lstrip("-")
        value = int(term[2:], 16) if term[:2].lower() == "0x" else int(term, 10)
        total += -value if neg else value
    return total


def _value(text: str | None, dtype: int, bits: int | None) -> int | None:
    """A DefaultValue/LowLimit/HighLimit; a signed object's hex value (0x80000000) read as
    signed; None for strings or expressions that are not numbers."""
    try:
        value = eds_int(text)
    except ValueError:
        return None
    if value is not None and dtype in SIGNED and bits and value >= 1 << (bits - 1):
        value -= 1 << bits
    return value


def read_eds(path: Path) -> list[DeviceDescription]:
    """The one device of the EDS/DCF file ``path``.

    Raises:
        ProfileImportError: one line: binary, not an INI file, no [DeviceInfo], malformed numbers.
    """
    raw = read_vendor_file(path, WHAT)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")  # CiA 306 files are ASCII; vendor names may be Latin-1
    cp = configparser.ConfigParser(strict=False, interpolation=None, comment_prefixes=(";",))
    cp.optionxform = str  # type: ignore[assignment,method-assign]
    try:
        cp.read_string(text, source=str(path))
    except configparser.Error as exc:
        first = " ".join(str(exc).split())[:160]
        raise ProfileImportError(f"{path}: not an INI file: {first}") from None
    sections = {s.upper(): s for s in cp.sections()}
    if "DEVICEINFO" not in sections:
        raise ProfileImportError(f"{path}: no [DeviceInfo] section: not an {WHAT}")
    info = cp[sections["DEVICEINFO"]]

    def number(value: str | None, what: str, node_id: int = 0) -> int | None:
        try:
            return eds_int(value, node_id)
        except ValueError:
            raise ProfileImportError(f"{path}: {what}: not a number (got {value!r})") from None

    def section(index: int, sub: int | None = None) -> configparser.SectionProxy | None:
        name = f"{index:04X}" if sub is None else f"{index:04X}SUB{sub:X}"
        real = sections.get(name)
        return None if real is None else cp[real]

    desc = DeviceDescription(
        path=path,
        sha256=file_sha256(raw),
        kind="eds",
        bus="canopen",
        device=info.get("ProductName", "").strip() or path.stem,
        vendor_name=info.get("VendorName", "").strip(),
        vendor_id=0,
        product_code=0,
        revision=None,
    )
    # objects: [XXXX] plain variables, [XXXXsubN] sub-indices
    for upper, real in sections.items():
        m = re.fullmatch(r"([0-9A-F]{4})(?:SUB([0-9A-F]+))?", upper)
        if not m:
            continue
        s = cp[real]
        index = int(m.group(1), 16)
        sub = int(m.group(2), 16) if m.group(2) else 0
        if m.group(2) is None and number(s.get("SubNumber"), f"[{real}] SubNumber"):
            continue  # record/array header: its sub-indices are sections of their own
        dtype = number(s.get("DataType"), f"[{real}] DataType") or 0
        bits = DATA_BITS.get(dtype)
        mappable = ""
        if (s.get("PDOMapping") or "0").strip() == "1":
            access = (s.get("AccessType") or "").strip().lower()
            mappable = ("rx" if access in ("rw", "rww", "wo") else "") + (
                "tx" if access in ("ro", "rw", "rwr", "const") else ""
            )
        default, low, high = (
            _value(s.get(key), dtype, bits) for key in ("DefaultValue", "LowLimit", "HighLimit")
        )
        desc.objects[(index, sub)] = ObjectInfo(
            index,
            sub,
            bits,
            mappable,
            default,
            (s.get("ParameterName") or "").strip(),
            low,
            high,
            (s.get("AccessType") or "").strip().lower(),
        )
    ident = {k: desc.default_of(0x1018, k) for k in (1, 2, 3)}
    desc.vendor_id = number(info.get("VendorNumber"), "[DeviceInfo] VendorNumber") or ident[1] or 0
    desc.product_code = (
        number(info.get("ProductNumber"), "[DeviceInfo] ProductNumber") or ident[2] or 0
    )
    rev = number(info.get("RevisionNumber"), "[DeviceInfo] RevisionNumber")
    desc.revision = rev if rev is not None else ident[3]
    for key, value in info.items():
        m = re.fullmatch(r"BaudRate_(\d+)", key, re.IGNORECASE)
        if m and (value or "").strip() == "1":
            desc.bitrates.append(int(m.group(1)) * 1000)
    desc.bitrates.sort()
    desc.heartbeat = desc.has(0x1017)
    commissioning = sections.get("DEVICECOMISSIONING")  # sic, CiA 306
    if commissioning is not None:
        desc.node_id = number(cp[commissioning].get("NodeID"), "[DeviceComissioning] NodeID")
    # PDOs: mapping 0x1600+k / 0x1A00+k with communication 0x1400+k / 0x1800+k
    for direction, comm_base, map_base in (("rx", 0x1400, 0x1600), ("tx", 0x1800, 0x1A00)):
        for k in range(512):
            head = section(map_base + k)
            if head is None:
                continue
            count = number(head.get("SubNumber"), f"[{map_base + k:04X}] SubNumber") or 1
            entries = []
            n_default = desc.default_of(map_base + k, 0) or 0
            for sub in range(1, n_default + 1):
                value = desc.default_of(map_base + k, sub) or 0
                if value:
                    entries.append((value >> 16 & 0xFFFF, value >> 8 & 0xFF, value & 0xFF))
            subs = [s for (i, s) in desc.objects if i == map_base + k and s > 0]
            ro = all(
                (cp[sections[f"{map_base + k:04X}SUB{s:X}"]].get("AccessType") or "").strip()
                in ("ro", "const")
                for s in subs
                if f"{map_base + k:04X}SUB{s:X}" in sections
            )
            desc.pdos.append(
                PdoOption(
                    index=map_base + k,
                    direction=direction,  # type: ignore[arg-type]
                    fixed=bool(subs) and ro,
                    entries=entries,
                    default=True,
                    max_entries=len(subs) or max(count - 1, 1),
                    name=(head.get("ParameterName") or "").strip(),
                )
            )
            cob_text = (section(comm_base + k, 1) or {}).get("DefaultValue")
            cob = number(cob_text, f"[{comm_base + k:04X}sub1] DefaultValue", node_id=0)
            if cob is not None and desc.node_id and not _NODEID.search(cob_text or ""):
                cob -= desc.node_id  # a DCF's COB-ID written with its node id included
            tt = desc.default_of(comm_base + k, 2)
            if cob is not None:
                desc.comm[map_base + k] = CanComm(
                    cob_id_base=cob & 0x7FF,
                    transmission_type=tt if tt is not None else 255,
                    enabled=not cob >> 31 & 1,
                )
    return [desc]
