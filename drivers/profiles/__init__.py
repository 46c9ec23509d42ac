"""Drive profiles from vendor files: ESI (EtherCAT) and EDS/DCF (CANopen) importers and the
layout chooser (docs/drives.md). Used by ``hofto-hw drive import``; never in the tick."""

from __future__ import annotations

from pathlib import Path

from drivers.profiles.description import DeviceDescription, ProfileImportError, read_vendor_file


def read_vendor_description(path: Path) -> list[DeviceDescription]:
    """The devices of a vendor file: ESI XML by a leading ``<``, EDS/DCF (INI) by a ``[``
    section; anything else is refused in one line."""
    from drivers.profiles.eds import read_eds
    from drivers.profiles.esi import read_esi

    raw = read_vendor_file(Path(path), "vendor file (ESI XML or EDS/DCF)")
    head = raw.lstrip(b"\xef\xbb\xbf \t\r\n")
    if head.startswith(b"<"):
        return read_esi(Path(path))
    if head.startswith((b"[", b";")):
        return read_eds(Path(path))
    raise ProfileImportError(
        f"{path}: neither XML (ESI) nor INI (EDS/DCF): the file starts with {raw[:16]!r}"
    )


__all__ = ["DeviceDescription", "ProfileImportError", "read_vendor_description"]
