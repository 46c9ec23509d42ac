"""SII EEPROM image of an emulated slave (ETG.1000.6 / ETG.2010 layout).

The image is a little-endian byte string addressed in 16-bit words: the fixed header
(words 0x00-0x3F: ESC configuration, identity, mailbox layout) followed by categories, each
``type u16, length u16 (words), data``, ending with type 0xFFFF. The categories written are
the ones a master needs when it maps PDOs by CoE: Strings (10), General (30), FMMU (40) and
SyncM (41), and for a drive that needs distributed clocks DC (60) with its one op mode (what
``hofto-hw bus scan`` reads back into a profile's ``dc``).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from drivers.sim.esc import description as d

CAT_STRINGS = 10
CAT_GENERAL = 30
CAT_FMMU = 40
CAT_SYNCM = 41
#: ETG.2010 DC category: the ESI's DC op modes (cycle/shift times, AssignActivate)
CAT_DC = 60
CAT_END = 0xFFFF
#: one DC op mode: CycleTime0 u32 [ns] (0: the master's cycle), ShiftTime0 u32 [ns],
#: ShiftTime1 u32 [ns], Sync1CycleFactor i16, AssignActivate u16, Sync0CycleFactor i16,
#: name index u8, description index u8, 4 reserved bytes
DC_OPMODE = struct.Struct("<IIIhHhBB4x")

#: FMMU usage codes of the FMMU category.
FMMU_USAGE_OUTPUTS = 1
FMMU_USAGE_INPUTS = 2
FMMU_USAGE_MBX_STATE = 3

#: SyncManager control bytes written into the SyncM category.
SM_CONTROL_MBX_OUT = 0x26  # mailbox, ECAT writes, ECAT+PDI interrupt
SM_CONTROL_MBX_IN = 0x22  # mailbox, ECAT reads
SM_CONTROL_OUTPUTS = 0x64  # buffered, ECAT writes, watchdog on
SM_CONTROL_INPUTS = 0x20  # buffered, ECAT reads

#: Header word addresses.
WORD_ALIAS = 0x0004
WORD_CHECKSUM = 0x0007
WORD_VENDOR = 0x0008
WORD_PRODUCT = 0x000A
WORD_REVISION = 0x000C
WORD_SERIAL = 0x000E
WORD_BOOT_MBX = 0x0014
WORD_STD_MBX = 0x0018
WORD_MBX_PROTOCOL = 0x001C
WORD_SIZE = 0x003E
WORD_VERSION = 0x003F
WORD_CATEGORIES = 0x0040

#: EEPROM size reported in the header [KiBit] (2 KiB image).
EEPROM_KBIT = 16


def crc8(data: bytes) -> int:
    """CRC-8 of the ESC configuration area: polynomial x^8+x^2+x+1, initial value 0xFF."""
    crc = 0xFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


def _category(cat_type: int, data: bytes) -> bytes:
    if len(data) % 2:
        data += b"\x00"
    return struct.pack("<HH", cat_type, len(data) // 2) + data


def build_image(desc: d.SlaveDescription) -> bytes:
    """SII image (bytes, even length, ``EEPROM_KBIT`` KiBit padded with 0xFF) for ``desc``."""
    header = bytearray(WORD_CATEGORIES * 2)
    # ESC configuration area: PDI control 0x0C80-like values are not needed by a master;
    # keep zeros except the alias and the checksum, which masters and tools check.
    struct.pack_into("<H", header, WORD_ALIAS * 2, desc.alias)
    struct.pack_into("<H", header, WORD_CHECKSUM * 2, crc8(bytes(header[:14])))
    struct.pack_into(
        "<IIII",
        header,
        WORD_VENDOR * 2,
        desc.vendor_id,
        desc.product_code,
        desc.revision,
        desc.serial,
    )
    mbx = struct.pack(
        "<HHHH", desc.mbx_out_offset, desc.mbx_out_size, desc.mbx_in_offset, desc.mbx_in_size
    )
    header[WORD_BOOT_MBX * 2 : WORD_BOOT_MBX * 2 + 8] = mbx
    header[WORD_STD_MBX * 2 : WORD_STD_MBX * 2 + 8] = mbx
    struct.pack_into("<H", header, WORD_MBX_PROTOCOL * 2, d.MBX_PROTO_COE)
    struct.pack_into("<HH", header, WORD_SIZE * 2, EEPROM_KBIT - 1, 1)

    strings = [desc.name, desc.group]
    strings_data = bytes([len(strings)])
    for s in strings:
        raw = s.encode("ascii", errors="replace")[:255]
        strings_data += bytes([len(raw)]) + raw

    general = bytearray(32)
    general[0] = 2  # group name: string #2
    general[3] = 1  # device name: string #1
    general[5] = desc.coe_details
    general[14] = 2
    # bytes 12-13: current on E-bus [mA] stays 0; flag bit 1 (no LRW) stays 0

    fmmu = bytes([FMMU_USAGE_OUTPUTS, FMMU_USAGE_INPUTS, FMMU_USAGE_MBX_STATE, 0])

    syncm = b"".join(
        struct.pack("<HHBBBB", start, length, control, 0, 1, sm_type)
        for start, length, control, sm_type in (
            (desc.mbx_out_offset, desc.mbx_out_size, SM_CONTROL_MBX_OUT, d.SM_TYPE_MBX_OUT),
            (desc.mbx_in_offset, desc.mbx_in_size, SM_CONTROL_MBX_IN, d.SM_TYPE_MBX_IN),
            (
                desc.outputs_offset,
                desc.default_outputs_size,
                SM_CONTROL_OUTPUTS,
                d.SM_TYPE_OUTPUTS,
            ),
            (desc.inputs_offset, desc.default_inputs_size, SM_CONTROL_INPUTS, d.SM_TYPE_INPUTS),
        )
    )

    image = bytearray(header)
    image += _category(CAT_STRINGS, strings_data)
    image += _category(CAT_GENERAL, bytes(general))
    image += _category(CAT_FMMU, fmmu)
    image += _category(CAT_SYNCM, syncm)
    if desc.dc_required:
        image += _category(
            CAT_DC,
            DC_OPMODE.pack(
                desc.sync0_cycle_ns or 0,
                desc.sync0_shift_ns,
                0,
                0,
                desc.assign_activate,
                1,
                0,
                0,
            ),
        )
    image += struct.pack("<H", CAT_END)
    size = EEPROM_KBIT * 1024 // 8
    if len(image) > size:
        raise ValueError(f"SII image of {len(image)} bytes exceeds {size} bytes")
    image += b"\xff" * (size - len(image))
    return bytes(image)


@dataclass(frozen=True)
class SiiInfo:
    """What a master learns from an SII image (used by tests and diagnostics)."""

    vendor_id: int
    product_code: int
    revision: int
    serial: int
    alias: int
    mbx_out: tuple[int, int]
    mbx_in: tuple[int, int]
    mailbox_protocols: int
    strings: tuple[str, ...]
    coe_details: int
    fmmu_usage: tuple[int, ...]
    sync_managers: tuple[tuple[int, int, int, int, int], ...]  # start, len, ctrl, enable, type
    checksum_ok: bool


def parse_image(image: bytes) -> SiiInfo:
    """Decode an SII image; raises ``ValueError`` naming the category that is malformed."""
    if len(image) < WORD_CATEGORIES * 2 + 2:
        raise ValueError(f"SII image of {len(image)} bytes is shorter than its header")
    vendor, product, revision, serial = struct.unpack_from("<IIII", image, WORD_VENDOR * 2)
    alias = struct.unpack_from("<H", image, WORD_ALIAS * 2)[0]
    checksum = image[WORD_CHECKSUM * 2]
    mo, ml, mi, mil = struct.unpack_from("<HHHH", image, WORD_STD_MBX * 2)
    proto = struct.unpack_from("<H", image, WORD_MBX_PROTOCOL * 2)[0]
    strings: tuple[str, ...] = ()
    coe = 0
    fmmu: tuple[int, ...] = ()
    sms: list[tuple[int, int, int, int, int]] = []
    pos = WORD_CATEGORIES * 2
    while pos + 4 <= len(image):
        cat, words = struct.unpack_from("<HH", image, pos)
        if cat == CAT_END:
            break
        data = image[pos + 4 : pos + 4 + 2 * words]
        if len(data) != 2 * words:
            raise ValueError(f"SII category {cat} at byte {pos} runs past the image end")
        if cat == CAT_STRINGS:
            n, p, out = data[0], 1, []
            for _ in range(n):
                length = data[p]
                out.append(data[p + 1 : p + 1 + length].decode("ascii", errors="replace"))
                p += 1 + length
            strings = tuple(out)
        elif cat == CAT_GENERAL:
            coe = data[5]
        elif cat == CAT_FMMU:
            fmmu = tuple(data)
        elif cat == CAT_SYNCM:
            for k in range(len(data) // 8):
                start, length, ctrl, _status, enable, sm_type = struct.unpack_from(
                    "<HHBBBB", data, 8 * k
                )
                sms.append((start, length, ctrl, enable, sm_type))
        pos += 4 + 2 * words
    return SiiInfo(
        vendor_id=vendor,
        product_code=product,
        revision=revision,
        serial=serial,
        alias=alias,
        mbx_out=(mo, ml),
        mbx_in=(mi, mil),
        mailbox_protocols=proto,
        strings=strings,
        coe_details=coe,
        fmmu_usage=fmmu,
        sync_managers=tuple(sms),
        checksum_ok=crc8(bytes(image[:14])) == checksum,
    )
