"""Plain-word meanings of CiA 301 SDO abort codes and CiA 301/402 error codes.

Error codes appear in 0x603F (CiA 402 error code), 0x1003 (pre-defined error field) and
emergency messages; the high byte gives the class, so unknown codes still get a meaning.
"""

from __future__ import annotations

#: CiA 301 SDO abort codes (u32).
SDO_ABORT_CODES: dict[int, str] = {
    0x05030000: "toggle bit not alternated",
    0x05040000: "SDO protocol timed out",
    0x05040001: "client/server command specifier not valid or unknown",
    0x05040002: "invalid block size",
    0x05040003: "invalid sequence number",
    0x05040004: "CRC error",
    0x05040005: "out of memory",
    0x06010000: "unsupported access to an object",
    0x06010001: "attempt to read a write-only object",
    0x06010002: "attempt to write a read-only object",
    0x06010003: "sub-index cannot be written, sub-index 0 must be 0 for write access",
    0x06010004: "complete access not supported for this object",
    0x06020000: "object does not exist in the object dictionary",
    0x06040041: "object cannot be mapped to the PDO",
    0x06040042: "the number and length of the objects to be mapped would exceed the PDO length",
    0x06040043: "general parameter incompatibility",
    0x06040047: "general internal incompatibility in the device",
    0x06060000: "access failed due to a hardware error",
    0x06070010: "data type does not match, length of service parameter does not match",
    0x06070012: "data type does not match, length of service parameter too high",
    0x06070013: "data type does not match, length of service parameter too low",
    0x06090011: "sub-index does not exist",
    0x06090030: "invalid value for parameter (download only)",
    0x06090031: "value of parameter written too high (download only)",
    0x06090032: "value of parameter written too low (download only)",
    0x06090036: "maximum value is less than minimum value",
    0x060A0023: "resource not available: SDO connection",
    0x08000000: "general error",
    0x08000020: "data cannot be transferred or stored to the application",
    0x08000021: "data cannot be transferred or stored because of local control",
    0x08000022: "data cannot be transferred or stored because of the present device state",
    0x08000023: "object dictionary not present or dynamic generation failed",
    0x08000024: "no data available",
}

# Frequently raised abort codes, by name.
ABORT_TOGGLE = 0x05030000
ABORT_TIMEOUT = 0x05040000
ABORT_UNSUPPORTED_ACCESS = 0x06010000
ABORT_WRITE_ONLY = 0x06010001
ABORT_READ_ONLY = 0x06010002
ABORT_SUBINDEX0_NOT_ZERO = 0x06010003
ABORT_NO_OBJECT = 0x06020000
ABORT_NOT_MAPPABLE = 0x06040041
ABORT_PDO_LENGTH = 0x06040042
ABORT_LENGTH = 0x06070010
ABORT_LENGTH_HIGH = 0x06070012
ABORT_LENGTH_LOW = 0x06070013
ABORT_NO_SUBINDEX = 0x06090011
ABORT_VALUE_RANGE = 0x06090030
ABORT_VALUE_HIGH = 0x06090031
ABORT_VALUE_LOW = 0x06090032
ABORT_GENERAL = 0x08000000
ABORT_DEVICE_STATE = 0x08000022

#: CiA 301 / CiA 402 error codes (u16) with their exact meaning.
ERROR_CODES: dict[int, str] = {
    0x0000: "no error",
    0x1000: "generic error",
    0x2000: "current error",
    0x2100: "current on device input side",
    0x2200: "current inside the device",
    0x2220: "continuous over-current inside the device",
    0x2300: "current on device output side",
    0x2310: "continuous over-current",
    0x2311: "continuous over-current (motor)",
    0x2320: "short circuit or earth leakage",
    0x2330: "earth leakage",
    0x2340: "short circuit",
    0x3000: "voltage error",
    0x3100: "mains voltage error",
    0x3130: "mains phase failure",
    0x3200: "DC link voltage error",
    0x3210: "DC link over-voltage",
    0x3220: "DC link under-voltage",
    0x3300: "output voltage error",
    0x4000: "temperature error",
    0x4100: "ambient temperature error",
    0x4200: "device temperature error",
    0x4210: "device over-temperature",
    0x4300: "drive temperature error",
    0x4310: "drive (motor) over-temperature",
    0x5000: "device hardware error",
    0x5100: "supply error",
    0x5400: "power section error",
    0x5441: "safe torque off active",
    0x5500: "data storage error",
    0x6000: "device software error",
    0x6100: "internal software error",
    0x6200: "user software error",
    0x6300: "data set error",
    0x6320: "parameter error",
    0x7000: "additional modules error",
    0x7100: "power error",
    0x7110: "brake chopper error",
    0x7120: "motor error",
    0x7121: "motor blocked",
    0x7300: "position sensor (encoder) error",
    0x7303: "resolver 1 fault",
    0x7305: "incremental encoder 1 fault (signal lost)",
    0x7306: "incremental encoder 2 fault",
    0x7310: "speed error",
    0x7320: "position error",
    0x7500: "communication error",
    0x8000: "monitoring error",
    0x8100: "communication error",
    0x8110: "CAN overrun (objects lost)",
    0x8120: "CAN in error passive mode",
    0x8130: "communication lost (life guard, heartbeat or watchdog timeout)",
    0x8140: "recovered from bus-off",
    0x8200: "protocol error",
    0x8210: "PDO not processed due to length error",
    0x8220: "PDO length exceeded",
    0x8400: "velocity speed controller error",
    0x8500: "position controller error",
    0x8600: "positioning controller error",
    0x8611: "following error too large",
    0x8612: "reference limit reached",
    0x8700: "sync controller error (sync signal lost)",
    0x8800: "fieldbus error",
    0x9000: "external error",
    0xF000: "additional functions error",
    0xFF00: "device-specific error",
}

_CLASSES: dict[int, str] = {
    0x00: "no error",
    0x10: "generic error",
    0x20: "current error",
    0x21: "current error on the device input side",
    0x22: "current error inside the device",
    0x23: "current error on the device output side",
    0x30: "voltage error",
    0x31: "mains voltage error",
    0x32: "DC link voltage error",
    0x33: "output voltage error",
    0x40: "temperature error",
    0x41: "ambient temperature error",
    0x42: "device temperature error",
    0x43: "motor temperature error",
    0x50: "device hardware error",
    0x60: "device software error",
    0x70: "additional modules error",
    0x73: "position sensor (encoder) error",
    0x80: "monitoring error",
    0x81: "communication error",
    0x82: "protocol error",
    0x84: "velocity controller error",
    0x85: "position controller error",
    0x86: "positioning controller error",
    0x87: "sync controller error",
    0x90: "external error",
    0xF0: "additional functions error",
    0xFF: "device-specific error",
}


def describe_error_code(code: int) -> str:
    """Meaning of a CiA 301/402 error code, e.g. ``'0x8611 following error too large'``.

    Codes not listed are described by their class (high byte or high nibble).
    """
    code &= 0xFFFF
    meaning = ERROR_CODES.get(code)
    if meaning is None:
        cls = _CLASSES.get(code >> 8) or _CLASSES.get((code >> 12) << 4)
        meaning = f"{cls} (code not listed)" if cls else "unknown error code"
    return f"0x{code:04X} {meaning}"


def describe_sdo_abort(code: int) -> str:
    """Meaning of a CiA 301 SDO abort code, e.g. ``'0x06020000 object does not exist ...'``."""
    code &= 0xFFFFFFFF
    return f"0x{code:08X} {SDO_ABORT_CODES.get(code, 'unknown SDO abort code')}"
