"""Read an EtherCAT ESI file (ETG.2000 ``EtherCATInfo`` XML) into device descriptions.

Also reads what the IgH master's ``ethercat xml`` prints from live slaves' SII (same root
element, no dictionary, every PDO marked fixed): such a file is told apart and said so.

Parsing is safe: ``defusedxml`` with DTDs refused, so an entity-expansion bomb or an external
entity (``<!DOCTYPE ... SYSTEM "file:///etc/passwd">``) is refused before anything is expanded or
read; the standard library's parsers would expand internal entities. Numbers are read as the
files write them (``#x1A00`` or decimal); a UTF-8 BOM is accepted.
"""

from __future__ import annotations

from pathlib import Path
from xml.etree.ElementTree import Element, ParseError

import defusedxml
import defusedxml.ElementTree as SafeET

from drivers.profiles.description import (
    DcMode,
    DeviceDescription,
    InitCommand,
    ObjectInfo,
    PdoOption,
    ProfileImportError,
    file_sha256,
    parse_number,
    read_vendor_file,
)

WHAT = "ESI file (EtherCATInfo XML)"


def parse_xml(raw: bytes, path: Path) -> Element:
    """The root element of ``raw``, parsed without DTDs or entities; one-line errors."""
    start = raw.lstrip(b"\xef\xbb\xbf \t\r\n")
    if not start.startswith(b"<"):
        raise ProfileImportError(f"{path}: not XML (does not start with '<'): not an {WHAT}")
    try:
        root = SafeET.fromstring(raw, forbid_dtd=True, forbid_entities=True, forbid_external=True)
    except defusedxml.DTDForbidden:
        raise ProfileImportError(
            f"{path}: refused: the XML declares a DOCTYPE (entity definitions are not expanded: "
            "an entity bomb or external entity cannot be read safely; ESI files have none)"
        ) from None
    except (defusedxml.EntitiesForbidden, defusedxml.ExternalReferenceForbidden) as exc:
        raise ProfileImportError(f"{path}: refused: the XML uses entities ({exc})") from None
    except ParseError as exc:
        line, column = exc.position
        text = str(exc).split(":")[0]
        hint = (
            " (the file ends early: truncated?)"
            if "no element found" in text or ("unclosed token" in text)
            else ""
        )
        raise ProfileImportError(
            f"{path}: line {line} column {column + 1}: not valid XML{hint}: {text}"
        ) from None
    for el in root.iter():  # drop namespaces: ESI elements are matched by local name
        if isinstance(el.tag, str) and el.tag.startswith("{"):
            el.tag = el.tag.split("}", 1)[1]
    return root


def _text(el: Element | None, tag: str | None = None) -> str:
    node = el if tag is None or el is None else el.find(tag)
    return "" if node is None or node.text is None else node.text.strip()


def _num(text: str | None, path: Path, what: str) -> int | None:
    try:
        return parse_number(text)
    except ValueError:
        raise ProfileImportError(f"{path}: {what}: not a number (got {text!r})") from None


def _hexdata(text: str, path: Path, what: str) -> int:
    """Little-endian hex bytes (ESI ``Data``/``DefaultData``) -> int."""
    t = text.strip()
    try:
        if t.startswith(("#x", "0x")):
            return int(t[2:], 16)
        return int.from_bytes(bytes.fromhex(t), "little")
    except ValueError:
        raise ProfileImportError(f"{path}: {what}: not hex data (got {text!r})") from None


def read_esi(path: Path) -> list[DeviceDescription]:
    """Every device of the ESI file ``path`` (identical devices listed once).

    Raises:
        ProfileImportError: one line: not XML, truncated, a DOCTYPE (entity bomb, external entity),
            not an EtherCATInfo, no device, or malformed numbers / PDOs.
    """
    raw = read_vendor_file(path, WHAT)
    root = parse_xml(raw, path)
    if root.tag != "EtherCATInfo":
        raise ProfileImportError(
            f"{path}: root element <{root.tag}>, not <EtherCATInfo>: not an {WHAT}"
        )
    sha = file_sha256(raw)
    vendor = root.find("Vendor")
    vendor_id = _num(_text(vendor, "Id"), path, "Vendor/Id")
    if vendor_id is None:
        raise ProfileImportError(f"{path}: Vendor/Id missing")
    vendor_name = _text(vendor, "Name")
    devices = root.findall("Descriptions/Devices/Device")
    if not devices:
        raise ProfileImportError(f"{path}: describes no device (Descriptions/Devices/Device)")
    modules = {
        _num(m.find("Type").get("ModuleIdent"), path, "Module/Type@ModuleIdent"): m
        for m in root.findall("Descriptions/Modules/Module")
        if m.find("Type") is not None and m.find("Type").get("ModuleIdent")
    }
    # IgH's `ethercat xml` output: no Descriptions/Groups, no dictionaries, bare vendor id
    dump = root.find("Descriptions/Groups") is None and all(
        d.find("Profile") is None for d in devices
    )
    out: list[DeviceDescription] = []
    seen: set[str] = set()
    for dev in devices:
        desc = _device(dev, modules, path, sha, vendor_id, vendor_name, dump)
        key = repr((desc.product_code, desc.revision, desc.device, desc.pdos, desc.init))
        if key in seen:
            continue
        seen.add(key)
        out.append(desc)
    return out


def _device(
    dev: Element,
    modules: dict[int | None, Element],
    path: Path,
    sha: str,
    vendor_id: int,
    vendor_name: str,
    dump: bool,
) -> DeviceDescription:
    type_el = dev.find("Type")
    name = _text(type_el) or _text(dev, "Name") or "?"
    product = _num(type_el.get("ProductCode") if type_el is not None else None, path, "ProductCode")
    revision = _num(type_el.get("RevisionNo") if type_el is not None else None, path, "RevisionNo")
    where = f"{path}: device {name!r}"
    desc = DeviceDescription(
        path=path,
        sha256=sha,
        kind="igh-sii-dump" if dump else "esi",
        bus="ethercat",
        device=name,
        vendor_name=vendor_name,
        vendor_id=vendor_id,
        product_code=product or 0,
        revision=revision,
    )
    # sync managers: SM2 outputs (RxPDOs), SM3 inputs (TxPDOs)
    sms = dev.findall("Sm")
    for i, sm in enumerate(sms):
        kind = _text(sm)
        size = _num(sm.get("MaxSize"), path, f"Sm[{i}]@MaxSize")
        if kind == "Outputs" or (not kind and i == 2):
            desc.sm_rx_bytes = size or None
        elif kind == "Inputs" or (not kind and i == 3):
            desc.sm_tx_bytes = size or None
    # dictionaries: the device's own and those of the modules its slots load by default
    dicts = [d for d in dev.findall("Profile/Dictionary")]
    for slot in dev.findall("Slots/Slot"):
        if (_num(slot.get("MinInstances"), path, "Slot@MinInstances") or 0) < 1:
            continue
        for ident in slot.findall("ModuleIdent"):
            if ident.get("Default") == "1":
                module = modules.get(_num(_text(ident), path, "ModuleIdent"))
                if module is not None:
                    dicts += module.findall("Profile/Dictionary")
    desc.has_dictionary = bool(dicts)
    for d in dicts:
        _dictionary(d, desc, path)
    for tag, direction in (("RxPdo", "rx"), ("TxPdo", "tx")):
        for pdo in dev.findall(tag):
            desc.pdos.append(_pdo(pdo, direction, where, path))
    for pdo in desc.pdos:  # PDOs give mappability where the dictionary has no flags
        for index, sub, bits in pdo.entries:
            if index == 0:
                continue
            info = desc.objects.setdefault((index, sub), ObjectInfo(index, sub, bits))
            if pdo.direction not in info.mappable:
                info.mappable += pdo.direction
    coe = dev.find("Mailbox/CoE")
    if coe is not None:  # ETG.2000: both default to false; a file without CoE: the dump's
        desc.pdo_assign = coe.get("PdoAssign", "0").lower() in ("1", "true")
        desc.pdo_config = coe.get("PdoConfig", "0").lower() in ("1", "true")
    elif dump:
        desc.pdo_assign = desc.pdo_config = False  # what the live drives ran, as it was
    for cmd in dev.findall("Mailbox/CoE/InitCmd"):
        data = _text(cmd, "Data")
        if not data:
            continue
        index = _num(_text(cmd, "Index"), path, "InitCmd/Index")
        sub = _num(_text(cmd, "SubIndex"), path, "InitCmd/SubIndex") or 0
        nbytes = len(data.replace(" ", "")) // 2
        desc.init.append(
            InitCommand(
                index=index or 0,
                subindex=sub,
                value=_hexdata(data, path, f"InitCmd 0x{index or 0:04X} Data"),
                bits=8 * nbytes,
                transitions=[_text(t) for t in cmd.findall("Transition")],
                comment=_text(cmd, "Comment"),
            )
        )
    for op in dev.findall("Dc/OpMode"):
        desc.dc.append(_dc_mode(op, path))
    return desc


def _pdo(pdo: Element, direction: str, where: str, path: Path) -> PdoOption:
    index = _num(_text(pdo, "Index"), path, f"{direction} PDO Index")
    if index is None:
        raise ProfileImportError(f"{where}: a {direction.upper()}Pdo without an Index")
    entries = []
    for e in pdo.findall("Entry"):
        ei = _num(_text(e, "Index"), path, f"PDO 0x{index:04X} Entry/Index") or 0
        es = _num(_text(e, "SubIndex"), path, f"PDO 0x{index:04X} Entry/SubIndex") or 0
        eb = _num(_text(e, "BitLen"), path, f"PDO 0x{index:04X} Entry/BitLen")
        if not eb or eb < 0 or eb > 64:
            raise ProfileImportError(
                f"{where}: PDO 0x{index:04X} entry 0x{ei:04X}:{es:02X}: bit length {eb}"
            )
        entries.append((ei, es if ei else 0, eb))
    seen: set[tuple[int, int]] = set()
    for ei, es, _ in entries:
        if ei and (ei, es) in seen:
            raise ProfileImportError(
                f"{where}: PDO 0x{index:04X} maps 0x{ei:04X}:{es:02X} twice (overlapping entries)"
            )
        seen.add((ei, es))
    return PdoOption(
        index=index,
        direction=direction,  # type: ignore[arg-type]
        fixed=pdo.get("Fixed", "0") in ("1", "true"),
        entries=entries,
        excludes={
            x for x in (_num(_text(x), path, "Exclude") for x in pdo.findall("Exclude")) if x
        },
        default=pdo.get("Sm") is not None,
        mandatory=pdo.get("Mandatory", "0") in ("1", "true"),
        name=_text(pdo, "Name"),
    )


def _dc_mode(op: Element, path: Path) -> DcMode:
    def cycle(tag: str) -> int | None:
        el = op.find(tag)
        if el is None:
            return None
        value = _num(_text(el), path, f"Dc/OpMode/{tag}") or 0
        factor = _num(el.get("Factor"), path, f"Dc/OpMode/{tag}@Factor")
        # ETG.2000: a Factor makes the cycle a multiple of the master's cycle; 0 = the same
        return None if factor or value == 0 else value

    return DcMode(
        name=_text(op, "Name"),
        assign_activate=_num(_text(op, "AssignActivate"), path, "AssignActivate") or 0,
        sync0_cycle_ns=cycle("CycleTimeSync0"),
        sync0_shift_ns=_num(_text(op, "ShiftTimeSync0"), path, "ShiftTimeSync0") or 0,
        sync1_cycle_ns=cycle("CycleTimeSync1"),
        sync1_shift_ns=_num(_text(op, "ShiftTimeSync1"), path, "ShiftTimeSync1"),
    )


def _mapping_flag(flags: Element | None) -> str:
    text = _text(flags, "PdoMapping").upper() if flags is not None else ""
    return ("rx" if "R" in text else "") + ("tx" if "T" in text else "")


def _dictionary(d: Element, desc: DeviceDescription, path: Path) -> None:
    types: dict[str, Element] = {_text(t, "Name"): t for t in d.findall("DataTypes/DataType")}

    def subitems(type_name: str) -> list[tuple[int, int | None, str, str, str]]:
        """(subindex, bits, name, mapping flag, access) of a record/array type."""
        t = types.get(type_name)
        out: list[tuple[int, int | None, str, str, str]] = []
        if t is None:
            return out
        for s in t.findall("SubItem"):
            sub = _num(_text(s, "SubIdx"), path, f"DataType {type_name} SubIdx")
            bits = _num(_text(s, "BitSize"), path, f"DataType {type_name} BitSize")
            access = _text(s, "Flags/Access").lower()
            if sub is not None:
                out.append((sub, bits, _text(s, "Name"), _mapping_flag(s.find("Flags")), access))
                continue
            arr = types.get(_text(s, "Type"))  # array of elements, sub-indices LBound..
            info = arr.find("ArrayInfo") if arr is not None else None
            if info is None:
                continue
            lo = _num(_text(info, "LBound"), path, "ArrayInfo/LBound") or 1
            n = _num(_text(info, "Elements"), path, "ArrayInfo/Elements") or 0
            base = types.get(_text(arr, "BaseType"))
            ebits = _num(_text(base, "BitSize"), path, "BitSize") if base is not None else None
            flag = _mapping_flag(s.find("Flags"))
            out += [(lo + k, ebits, _text(s, "Name"), flag, access) for k in range(n)]
        return out

    for obj in d.findall("Objects/Object"):
        index = _num(_text(obj, "Index"), path, "Object/Index")
        if index is None:
            continue
        type_name = _text(obj, "Type")
        bits = _num(_text(obj, "BitSize"), path, f"Object 0x{index:04X} BitSize")
        flag = _mapping_flag(obj.find("Flags"))
        access = _text(obj, "Flags/Access").lower()
        subs = subitems(type_name)
        info_subs = obj.findall("Info/SubItem")
        if not subs:
            default = _text(obj, "Info/DefaultData")
            desc.objects[(index, 0)] = ObjectInfo(
                index,
                0,
                bits,
                flag,
                _hexdata(default, path, f"0x{index:04X} DefaultData") if default else None,
                _text(obj, "Name"),
                access=access,
            )
            continue
        for k, (sub, sbits, sname, sflag, saccess) in enumerate(subs):
            default = None
            for s in info_subs:  # the object's Info/SubItem of that sub-index, by name
                if _text(s, "Name") == sname or _text(s, "Name").endswith(f"{sub:03d}"):
                    default = _text(s, "Info/DefaultData")
                    break
            else:
                if k < len(info_subs):
                    default = _text(info_subs[k], "Info/DefaultData")
            desc.objects[(index, sub)] = ObjectInfo(
                index,
                sub,
                sbits,
                sflag or flag,
                _hexdata(default, path, f"0x{index:04X}:{sub} DefaultData") if default else None,
                sname,
                access=saccess or access,
            )
