"""CiA 402 (IEC 61800-7-201) drive state machine, master side and drive side.

States are small integers (:class:`State`) so that six axes are handled with lookup tables
on uint8 arrays. Statusword bits 0-3, 5, 6 give the state; controlword bits 0-3 and 7 give
the command. Fault reset is the RISING edge of controlword bit 7, so the drive side needs the
previous controlword.

Transitions (numbers as in CiA 402-2):
  0  start               -> Not ready to switch on   (automatic)
  1  Not ready           -> Switch on disabled       (automatic, after self test)
  2  Switch on disabled  -> Ready to switch on       Shutdown
  3  Ready to switch on  -> Switched on              Switch on (also Switch on + enable op.)
  4  Switched on         -> Operation enabled        Enable operation
  5  Operation enabled   -> Switched on              Disable operation
  6  Switched on         -> Ready to switch on       Shutdown
  7  Ready to switch on  -> Switch on disabled       Disable voltage / Quick stop
  8  Operation enabled   -> Ready to switch on       Shutdown
  9  Operation enabled   -> Switch on disabled       Disable voltage
  10 Switched on         -> Switch on disabled       Disable voltage / Quick stop
  11 Operation enabled   -> Quick stop active        Quick stop
  12 Quick stop active   -> Switch on disabled       Disable voltage, or ramp finished
  13 any                 -> Fault reaction active    fault detected (automatic)
  14 Fault reaction      -> Fault                    reaction finished (automatic)
  15 Fault               -> Switch on disabled       Fault reset (rising edge of bit 7)
  16 Quick stop active   -> Operation enabled        Enable operation (option codes 5-8)
Any other command in a state is illegal and leaves the state unchanged.
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np


class State(IntEnum):
    """CiA 402 drive states; ``UNKNOWN`` marks a statusword matching no state."""

    NOT_READY_TO_SWITCH_ON = 0
    SWITCH_ON_DISABLED = 1
    READY_TO_SWITCH_ON = 2
    SWITCHED_ON = 3
    OPERATION_ENABLED = 4
    QUICK_STOP_ACTIVE = 5
    FAULT_REACTION_ACTIVE = 6
    FAULT = 7
    UNKNOWN = 8


STATE_NAMES: tuple[str, ...] = (
    "Not ready to switch on",
    "Switch on disabled",
    "Ready to switch on",
    "Switched on",
    "Operation enabled",
    "Quick stop active",
    "Fault reaction active",
    "Fault",
    "unknown state",
)

#: (mask, value) of the statusword for each state, CiA 402-2 table "state coding".
STATUS_PATTERNS: dict[State, tuple[int, int]] = {
    State.NOT_READY_TO_SWITCH_ON: (0x004F, 0x0000),
    State.SWITCH_ON_DISABLED: (0x004F, 0x0040),
    State.READY_TO_SWITCH_ON: (0x006F, 0x0021),
    State.SWITCHED_ON: (0x006F, 0x0023),
    State.OPERATION_ENABLED: (0x006F, 0x0027),
    State.QUICK_STOP_ACTIVE: (0x006F, 0x0007),
    State.FAULT_REACTION_ACTIVE: (0x004F, 0x000F),
    State.FAULT: (0x004F, 0x0008),
}

# Statusword bits other than the state coding.
SW_VOLTAGE_ENABLED = 1 << 4
SW_WARNING = 1 << 7
SW_REMOTE = 1 << 9
SW_TARGET_REACHED = 1 << 10
SW_INTERNAL_LIMIT = 1 << 11
#: CSP/CSV/CST: "drive follows the command value" (bit 12); CSP bit 13: following error.
SW_FOLLOWING = 1 << 12
SW_FOLLOWING_ERROR = 1 << 13
#: homing mode (6): bit 12 = homing attained, bit 13 = homing error (CiA 402 homing mode)
SW_HOMING_ATTAINED = 1 << 12
SW_HOMING_ERROR = 1 << 13


class Command(IntEnum):
    """Device-control commands decoded from a controlword."""

    NONE = 0
    DISABLE_VOLTAGE = 1
    QUICK_STOP = 2
    SHUTDOWN = 3
    SWITCH_ON = 4  # also "disable operation" (same bits)
    ENABLE_OPERATION = 5  # "switch on + enable operation"
    FAULT_RESET = 6


#: controlword bits sent for each command (bits 4-6, 8 are mode specific and left 0).
CW_SHUTDOWN = 0x0006
CW_SWITCH_ON = 0x0007
CW_DISABLE_OPERATION = 0x0007
CW_ENABLE_OPERATION = 0x000F
CW_DISABLE_VOLTAGE = 0x0000
CW_QUICK_STOP = 0x0002
CW_FAULT_RESET = 0x0080
CW_HALT = 0x0100
#: 0x60FD digital input bit of an active safe torque off (the emulated drives' source; a
#: real drive profile may name another bit or object)
DIN_STO = 1 << 16
#: homing mode (6): rising edge starts homing
CW_HOMING_START = 0x0010


class Mode(IntEnum):
    """Modes of operation (0x6060 / 0x6061) this stack uses."""

    NO_MODE = 0
    PROFILE_POSITION = 1
    PROFILE_VELOCITY = 3
    HOMING = 6
    INTERPOLATED_POSITION = 7
    CSP = 8
    CSV = 9
    CST = 10


def _build_state_lut() -> np.ndarray:
    lut = np.full(128, State.UNKNOWN, dtype=np.uint8)
    for sw in range(128):
        for state, (mask, value) in STATUS_PATTERNS.items():
            if sw & mask == value:
                lut[sw] = state
                break
    return lut


#: statusword & 0x7F -> State
STATE_FROM_STATUS: np.ndarray = _build_state_lut()


def _build_command_lut() -> np.ndarray:
    # Bits 0..3 with bit 7 clear. Priority follows the CiA 402 command table:
    # bit 1 clear -> disable voltage; bit 2 clear -> quick stop; bit 0 clear -> shutdown;
    # bits 0-2 set -> switch on (bit 3 clear) or enable operation (bit 3 set).
    lut = np.zeros(16, dtype=np.uint8)
    for cw in range(16):
        if not cw & 0x2:
            lut[cw] = Command.DISABLE_VOLTAGE
        elif not cw & 0x4:
            lut[cw] = Command.QUICK_STOP
        elif not cw & 0x1:
            lut[cw] = Command.SHUTDOWN
        elif not cw & 0x8:
            lut[cw] = Command.SWITCH_ON
        else:
            lut[cw] = Command.ENABLE_OPERATION
    return lut


#: controlword & 0x0F -> Command (valid when bit 7 is clear)
COMMAND_FROM_CONTROL: np.ndarray = _build_command_lut()

S = State
C = Command
#: (state, command) -> (next state, transition number) for every LEGAL command-driven move.
TRANSITIONS: dict[tuple[State, Command], tuple[State, int]] = {
    (S.SWITCH_ON_DISABLED, C.SHUTDOWN): (S.READY_TO_SWITCH_ON, 2),
    (S.READY_TO_SWITCH_ON, C.SWITCH_ON): (S.SWITCHED_ON, 3),
    (S.READY_TO_SWITCH_ON, C.ENABLE_OPERATION): (S.SWITCHED_ON, 3),
    (S.SWITCHED_ON, C.ENABLE_OPERATION): (S.OPERATION_ENABLED, 4),
    (S.OPERATION_ENABLED, C.SWITCH_ON): (S.SWITCHED_ON, 5),
    (S.SWITCHED_ON, C.SHUTDOWN): (S.READY_TO_SWITCH_ON, 6),
    (S.READY_TO_SWITCH_ON, C.DISABLE_VOLTAGE): (S.SWITCH_ON_DISABLED, 7),
    (S.READY_TO_SWITCH_ON, C.QUICK_STOP): (S.SWITCH_ON_DISABLED, 7),
    (S.OPERATION_ENABLED, C.SHUTDOWN): (S.READY_TO_SWITCH_ON, 8),
    (S.OPERATION_ENABLED, C.DISABLE_VOLTAGE): (S.SWITCH_ON_DISABLED, 9),
    (S.SWITCHED_ON, C.DISABLE_VOLTAGE): (S.SWITCH_ON_DISABLED, 10),
    (S.SWITCHED_ON, C.QUICK_STOP): (S.SWITCH_ON_DISABLED, 10),
    (S.OPERATION_ENABLED, C.QUICK_STOP): (S.QUICK_STOP_ACTIVE, 11),
    (S.QUICK_STOP_ACTIVE, C.DISABLE_VOLTAGE): (S.SWITCH_ON_DISABLED, 12),
    (S.FAULT, C.FAULT_RESET): (S.SWITCH_ON_DISABLED, 15),
}
#: Transition 16 exists only with quick-stop option codes 5-8.
TRANSITION_16: tuple[tuple[State, Command], tuple[State, int]] = (
    (S.QUICK_STOP_ACTIVE, C.ENABLE_OPERATION),
    (S.OPERATION_ENABLED, 16),
)
del S, C


def _build_next_lut(allow_16: bool) -> np.ndarray:
    lut = np.zeros((len(State), len(Command)), dtype=np.uint8)
    for s in State:
        lut[s, :] = s  # illegal or no command: stay
    for (s, c), (nxt, _) in TRANSITIONS.items():
        lut[s, c] = nxt
    if allow_16:
        (s, c), (nxt, _) = TRANSITION_16
        lut[s, c] = nxt
    return lut


#: [state, command] -> next state (drive side; quick-stop option codes 0-4 / 5-8)
NEXT_STATE: np.ndarray = _build_next_lut(allow_16=False)
NEXT_STATE_QS_HOLD: np.ndarray = _build_next_lut(allow_16=True)


# ------------------------------------------------------------------------ both sides


def decode_state(statusword: int) -> State:
    """State coded in one statusword."""
    return State(int(STATE_FROM_STATUS[statusword & 0x7F]))


def decode_states(statusword: np.ndarray, out: np.ndarray, scratch: np.ndarray) -> np.ndarray:
    """Vectorised :func:`decode_state`: ``out`` (uint8, shape (n,)) from ``statusword``.

    ``scratch`` is a preallocated uint16 array of the same shape (no allocation).
    """
    np.bitwise_and(statusword, 0x7F, out=scratch)
    np.take(STATE_FROM_STATUS, scratch, out=out)
    return out


def status_bits(state: State) -> int:
    """Statusword state-coding bits a drive reports in ``state`` (voltage bit not included)."""
    if state == State.UNKNOWN:
        raise ValueError("UNKNOWN has no statusword coding")
    return STATUS_PATTERNS[state][1]


#: State -> statusword state bits, for vectorised drive-side encoding (UNKNOWN -> 0).
STATUS_FROM_STATE: np.ndarray = np.array(
    [STATUS_PATTERNS[State(s)][1] for s in range(8)] + [0], dtype=np.uint16
)


def decode_command(controlword: int, previous_controlword: int) -> Command:
    """Command in ``controlword``; fault reset only on a rising edge of bit 7.

    While bit 7 stays set, no command is recognised (the reset was already seen).
    """
    if controlword & 0x80:
        return Command.FAULT_RESET if not previous_controlword & 0x80 else Command.NONE
    return Command(int(COMMAND_FROM_CONTROL[controlword & 0x0F]))


def next_state(
    state: State, controlword: int, previous_controlword: int, allow_16: bool = False
) -> State:
    """Drive side: the state after receiving ``controlword`` in ``state``.

    Only command-driven transitions; automatic ones (0, 1, 12 at ramp end, 13, 14) belong to
    the drive. Illegal commands leave the state unchanged. A fault reset returns Switch on
    disabled here; a drive whose fault is still present must stay in Fault itself.
    """
    cmd = decode_command(controlword, previous_controlword)
    lut = NEXT_STATE_QS_HOLD if allow_16 else NEXT_STATE
    return State(int(lut[state, cmd]))


def transition_number(state: State, command: Command, allow_16: bool = False) -> int | None:
    """CiA 402 transition number taken by ``command`` in ``state``; None when illegal."""
    hit = TRANSITIONS.get((state, command))
    if hit is not None:
        return hit[1]
    if allow_16 and (state, command) == TRANSITION_16[0]:
        return TRANSITION_16[1][1]
    return None


# ------------------------------------------------------------------------- master side

_TARGETS = (
    State.SWITCH_ON_DISABLED,
    State.READY_TO_SWITCH_ON,
    State.SWITCHED_ON,
    State.OPERATION_ENABLED,
)


def _build_toward_lut() -> np.ndarray:
    # [current state, target state] -> controlword bringing the drive one step closer.
    # Fault needs the rising edge and is handled by controlword_toward.
    dv, sd, so, eo = CW_DISABLE_VOLTAGE, CW_SHUTDOWN, CW_SWITCH_ON, CW_ENABLE_OPERATION
    lut = np.zeros((len(State), len(State)), dtype=np.uint16)
    table = {
        State.SWITCH_ON_DISABLED: {
            State.SWITCH_ON_DISABLED: dv,
            State.READY_TO_SWITCH_ON: sd,
            State.SWITCHED_ON: sd,
            State.OPERATION_ENABLED: sd,
        },
        State.READY_TO_SWITCH_ON: {
            State.SWITCH_ON_DISABLED: dv,
            State.READY_TO_SWITCH_ON: sd,
            State.SWITCHED_ON: so,
            State.OPERATION_ENABLED: so,
        },
        State.SWITCHED_ON: {
            State.SWITCH_ON_DISABLED: dv,
            State.READY_TO_SWITCH_ON: sd,
            State.SWITCHED_ON: so,
            State.OPERATION_ENABLED: eo,
        },
        State.OPERATION_ENABLED: {
            State.SWITCH_ON_DISABLED: dv,
            State.READY_TO_SWITCH_ON: sd,
            State.SWITCHED_ON: CW_DISABLE_OPERATION,
            State.OPERATION_ENABLED: eo,
        },
        # Quick stop active: leave through Switch on disabled (transition 12).
        State.QUICK_STOP_ACTIVE: dict.fromkeys(_TARGETS, dv),
    }
    for cur, row in table.items():
        for tgt, cw in row.items():
            lut[cur, tgt] = cw
    # Not ready, fault reaction active, unknown: nothing to command, send disable voltage.
    return lut


CONTROL_TOWARD: np.ndarray = _build_toward_lut()


def controlword_toward(state: State, target: State, previous_controlword: int) -> int:
    """Master side: the controlword moving a drive in ``state`` one step toward ``target``.

    ``target`` is one of Switch on disabled, Ready to switch on, Switched on, Operation
    enabled. From Fault the result alternates 0x0000 / 0x0080 so bit 7 rises (a fault reset).
    """
    if target not in _TARGETS:
        raise ValueError(f"target must be one of {[STATE_NAMES[t] for t in _TARGETS]}")
    if state == State.FAULT:
        return CW_DISABLE_VOLTAGE if previous_controlword & 0x80 else CW_FAULT_RESET
    return int(CONTROL_TOWARD[state, target])


def controlwords_toward(
    states: np.ndarray, target: State, previous: np.ndarray, out: np.ndarray
) -> np.ndarray:
    """Vectorised :func:`controlword_toward` for all axes (out: uint16, shape (n,)).

    Axes in Fault get a fault reset edge; use :func:`controlwords_toward_no_reset` where
    faults must stay latched.
    """
    controlwords_toward_no_reset(states, target, out)
    faulted = states == State.FAULT
    if faulted.any():
        edge = np.where(previous & 0x80, CW_DISABLE_VOLTAGE, CW_FAULT_RESET)
        out[faulted] = edge[faulted]
    return out


def controlwords_toward_no_reset(states: np.ndarray, target: State, out: np.ndarray) -> np.ndarray:
    """Vectorised master step toward ``target``; faulted axes get disable voltage."""
    np.take(CONTROL_TOWARD[:, target], states, out=out)
    return out


def mode_ok(mode_display: int, mode: Mode | int) -> bool:
    """True when the drive displays (0x6061) the requested mode of operation."""
    return int(mode_display) == int(mode)


def describe_statusword(statusword: int) -> str:
    """Plain words for a statusword, e.g. ``'Fault (statusword 0x0218, warning)'``."""
    state = decode_state(statusword)
    extras = []
    if statusword & SW_VOLTAGE_ENABLED:
        extras.append("voltage enabled")
    if statusword & SW_WARNING:
        extras.append("warning")
    if statusword & SW_INTERNAL_LIMIT:
        extras.append("internal limit active")
    if statusword & SW_FOLLOWING_ERROR:
        extras.append("following error")
    tail = ", " + ", ".join(extras) if extras else ""
    return f"{STATE_NAMES[state]} (statusword 0x{statusword:04X}{tail})"
