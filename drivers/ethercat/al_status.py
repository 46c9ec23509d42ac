"""EtherCAT AL states and AL status codes (ETG.1000.6 table 11, ETG.1020) in plain words."""

from __future__ import annotations

STATE_NONE = 0x00
STATE_INIT = 0x01
STATE_PREOP = 0x02
STATE_BOOT = 0x03
STATE_SAFEOP = 0x04
STATE_OP = 0x08
STATE_ERROR = 0x10

STATE_NAMES: dict[int, str] = {
    STATE_NONE: "NONE",
    STATE_INIT: "INIT",
    STATE_PREOP: "PRE-OP",
    STATE_BOOT: "BOOT",
    STATE_SAFEOP: "SAFE-OP",
    STATE_OP: "OP",
}

AL_STATUS_CODES: dict[int, str] = {
    0x0000: "no error",
    0x0001: "unspecified error",
    0x0002: "no memory",
    0x0003: "invalid device setup",
    0x0006: "SII/EEPROM information does not match the firmware",
    0x0007: "firmware update not successful, old firmware still running",
    0x000E: "license error",
    0x0011: "invalid requested state change",
    0x0012: "unknown requested state",
    0x0013: "bootstrap not supported",
    0x0014: "no valid firmware",
    0x0015: "invalid mailbox configuration (BOOT)",
    0x0016: "invalid mailbox configuration (PRE-OP)",
    0x0017: "invalid sync manager configuration",
    0x0018: "no valid inputs available",
    0x0019: "no valid outputs",
    0x001A: "synchronization error",
    0x001B: "sync manager watchdog (process data stopped arriving)",
    0x001C: "invalid sync manager types",
    0x001D: "invalid output configuration (RxPDO mapping or SM2 settings)",
    0x001E: "invalid input configuration (TxPDO mapping or SM3 settings)",
    0x001F: "invalid watchdog configuration",
    0x0020: "slave needs cold start",
    0x0021: "slave needs INIT",
    0x0022: "slave needs PRE-OP",
    0x0023: "slave needs SAFE-OP",
    0x0024: "invalid input mapping",
    0x0025: "invalid output mapping",
    0x0026: "inconsistent settings",
    0x0027: "free-run not supported",
    0x0028: "synchronization not supported",
    0x0029: "free-run needs 3-buffer mode",
    0x002A: "background watchdog",
    0x002B: "no valid inputs and outputs",
    0x002C: "fatal sync error",
    0x002D: "no sync error",
    0x002E: "cycle time too small",
    0x0030: "invalid DC SYNC configuration",
    0x0031: "invalid DC latch configuration",
    0x0032: "PLL error",
    0x0033: "DC sync IO error",
    0x0034: "DC sync timeout",
    0x0035: "DC invalid sync cycle time",
    0x0036: "DC SYNC0 cycle time",
    0x0037: "DC SYNC1 cycle time",
    0x0041: "mailbox AoE error",
    0x0042: "mailbox EoE error",
    0x0043: "mailbox CoE error",
    0x0044: "mailbox FoE error",
    0x0045: "mailbox SoE error",
    0x004F: "mailbox VoE error",
    0x0050: "EEPROM no access",
    0x0051: "EEPROM error",
    0x0052: "external hardware not ready",
    0x0060: "slave restarted locally",
    0x0061: "device identification value updated",
    0x0070: "detected module ident list does not match",
    0x0080: "supply voltage too low",
    0x0081: "supply voltage too high",
    0x0082: "temperature too low",
    0x0083: "temperature too high",
    0x00F0: "application controller available",
}


def describe_al_status_code(code: int) -> str:
    """``"0x001D (invalid output configuration ...)"``; vendor codes (>= 0x8000) are named so."""
    meaning = AL_STATUS_CODES.get(code)
    if meaning is None:
        meaning = "vendor-specific code" if code >= 0x8000 else "unknown AL status code"
    return f"0x{code:04X} ({meaning})"


def describe_state(al_status: int) -> str:
    """AL status byte in words, e.g. 0x14 -> ``"SAFE-OP + ERROR"``."""
    name = STATE_NAMES.get(al_status & 0x0F, f"state 0x{al_status & 0x0F:X}")
    return name + (" + ERROR" if al_status & STATE_ERROR else "")
