"""CiA 402 state machine: statusword decoding, command decoding, all transitions, master side."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from drivers.cia402 import state_machine as sm
from drivers.cia402.state_machine import Command, Mode, State

S = State
# CiA 402-2 statusword state coding, as printed: (mask, value).
STATUS_TABLE = {
    S.NOT_READY_TO_SWITCH_ON: (0b0100_1111, 0b0000_0000),
    S.SWITCH_ON_DISABLED: (0b0100_1111, 0b0100_0000),
    S.READY_TO_SWITCH_ON: (0b0110_1111, 0b0010_0001),
    S.SWITCHED_ON: (0b0110_1111, 0b0010_0011),
    S.OPERATION_ENABLED: (0b0110_1111, 0b0010_0111),
    S.QUICK_STOP_ACTIVE: (0b0110_1111, 0b0000_0111),
    S.FAULT_REACTION_ACTIVE: (0b0100_1111, 0b0000_1111),
    S.FAULT: (0b0100_1111, 0b0000_1000),
}

# CiA 402-2 controlword command coding, bits 7..0 (x = don't care), as printed.
CONTROL_TABLE = {
    "shutdown": "0xxxx110",
    "switch_on": "0xxx0111",
    "enable_operation": "0xxx1111",
    "disable_voltage": "0xxxxx0x",
    "quick_stop": "0xxxx01x",
}
CW = {
    "disable_voltage": 0x0000,
    "quick_stop": 0x0002,
    "shutdown": 0x0006,
    "switch_on": 0x0007,
    "enable_operation": 0x000F,
}

# Expected next state for (state, command name); anything not listed keeps the state.
LEGAL = {
    (S.SWITCH_ON_DISABLED, "shutdown"): S.READY_TO_SWITCH_ON,  # 2
    (S.READY_TO_SWITCH_ON, "switch_on"): S.SWITCHED_ON,  # 3
    (S.READY_TO_SWITCH_ON, "enable_operation"): S.SWITCHED_ON,  # 3 (then 4 next cycle)
    (S.SWITCHED_ON, "enable_operation"): S.OPERATION_ENABLED,  # 4
    (S.OPERATION_ENABLED, "switch_on"): S.SWITCHED_ON,  # 5 (disable operation)
    (S.SWITCHED_ON, "shutdown"): S.READY_TO_SWITCH_ON,  # 6
    (S.READY_TO_SWITCH_ON, "disable_voltage"): S.SWITCH_ON_DISABLED,  # 7
    (S.READY_TO_SWITCH_ON, "quick_stop"): S.SWITCH_ON_DISABLED,  # 7
    (S.OPERATION_ENABLED, "shutdown"): S.READY_TO_SWITCH_ON,  # 8
    (S.OPERATION_ENABLED, "disable_voltage"): S.SWITCH_ON_DISABLED,  # 9
    (S.SWITCHED_ON, "disable_voltage"): S.SWITCH_ON_DISABLED,  # 10
    (S.SWITCHED_ON, "quick_stop"): S.SWITCH_ON_DISABLED,  # 10
    (S.OPERATION_ENABLED, "quick_stop"): S.QUICK_STOP_ACTIVE,  # 11
    (S.QUICK_STOP_ACTIVE, "disable_voltage"): S.SWITCH_ON_DISABLED,  # 12
    (S.FAULT, "fault_reset"): S.SWITCH_ON_DISABLED,  # 15
}
REAL_STATES = [s for s in State if s != S.UNKNOWN]
COMMANDS = [*CW, "fault_reset"]


def _matches(cw: int, pattern: str) -> bool:
    bits = [7, 6, 5, 4, 3, 2, 1, 0]
    return all(p == "x" or ((cw >> b) & 1) == int(p) for p, b in zip(pattern, bits, strict=True))


@pytest.mark.parametrize("state", list(STATUS_TABLE))
def test_statusword_decodes_every_state_whatever_the_dont_care_bits(state: State) -> None:
    mask, value = STATUS_TABLE[state]
    rng = np.random.default_rng(int(state))
    for noise in rng.integers(0, 0x10000, 200):
        sw = (int(noise) & ~mask & 0xFFFF) | value
        assert sm.decode_state(sw) == state, hex(sw)


def test_statuswords_matching_no_state_are_unknown() -> None:
    unknown = [sw for sw in range(128) if not any(sw & m == v for m, v in STATUS_TABLE.values())]
    assert unknown  # e.g. 0x01: ready bit without "quick stop" bit
    for sw in unknown:
        assert sm.decode_state(sw) == S.UNKNOWN


def test_vectorised_decoding_matches_scalar() -> None:
    sw = np.arange(0, 0x10000, 7, dtype=np.uint16)
    out = np.zeros(sw.shape, dtype=np.uint8)
    sm.decode_states(sw, out, np.zeros_like(sw))
    assert all(out[i] == sm.decode_state(int(sw[i])) for i in range(0, len(sw), 13))


def test_every_controlword_low_nibble_decodes_like_the_cia402_table() -> None:
    names = {
        "shutdown": Command.SHUTDOWN,
        "switch_on": Command.SWITCH_ON,
        "enable_operation": Command.ENABLE_OPERATION,
        "disable_voltage": Command.DISABLE_VOLTAGE,
        "quick_stop": Command.QUICK_STOP,
    }
    for cw in range(16):
        hits = [name for name, pat in CONTROL_TABLE.items() if _matches(cw, pat)]
        assert len(hits) == 1, (cw, hits)  # the table is unambiguous on bits 0-3
        assert sm.decode_command(cw | 0x70, 0) == names[hits[0]]  # bits 4-6 don't matter


@pytest.mark.parametrize(("state", "command"), list(itertools.product(REAL_STATES, COMMANDS)))
def test_every_state_and_command(state: State, command: str) -> None:
    if command == "fault_reset":
        cw, prev = 0x0080, 0x0000
    else:
        cw, prev = CW[command], 0x0000
    expected = LEGAL.get((state, command), state)  # illegal: unchanged
    assert sm.next_state(state, cw, prev) == expected


def test_transition_16_only_with_quick_stop_hold_option() -> None:
    assert sm.next_state(S.QUICK_STOP_ACTIVE, 0x0F, 0) == S.QUICK_STOP_ACTIVE
    assert sm.next_state(S.QUICK_STOP_ACTIVE, 0x0F, 0, allow_16=True) == S.OPERATION_ENABLED
    assert sm.transition_number(S.QUICK_STOP_ACTIVE, Command.ENABLE_OPERATION) is None
    assert sm.transition_number(S.QUICK_STOP_ACTIVE, Command.ENABLE_OPERATION, True) == 16


def test_transition_numbers() -> None:
    assert sm.transition_number(S.SWITCH_ON_DISABLED, Command.SHUTDOWN) == 2
    assert sm.transition_number(S.OPERATION_ENABLED, Command.QUICK_STOP) == 11
    assert sm.transition_number(S.FAULT, Command.FAULT_RESET) == 15
    assert sm.transition_number(S.FAULT, Command.ENABLE_OPERATION) is None


def test_fault_reset_only_on_rising_edge_of_bit_7() -> None:
    assert sm.next_state(S.FAULT, 0x0080, 0x0000) == S.SWITCH_ON_DISABLED
    assert sm.next_state(S.FAULT, 0x0080, 0x0080) == S.FAULT  # held high: no new edge
    assert sm.next_state(S.FAULT, 0x008F, 0x0006) == S.SWITCH_ON_DISABLED  # other bits: x
    assert sm.next_state(S.FAULT, 0x0000, 0x0080) == S.FAULT  # falling edge
    # While bit 7 is held, no other command is recognised either.
    assert sm.next_state(S.SWITCH_ON_DISABLED, 0x0086, 0x0086) == S.SWITCH_ON_DISABLED


@pytest.mark.parametrize(
    ("start", "target"),
    list(
        itertools.product(
            REAL_STATES,
            [S.SWITCH_ON_DISABLED, S.READY_TO_SWITCH_ON, S.SWITCHED_ON, S.OPERATION_ENABLED],
        )
    ),
)
def test_master_reaches_every_target_from_every_state(start: State, target: State) -> None:
    if start in (S.NOT_READY_TO_SWITCH_ON, S.FAULT_REACTION_ACTIVE):
        # Only automatic transitions leave these; the master must just wait (disable voltage).
        assert sm.controlword_toward(start, target, 0) == sm.CW_DISABLE_VOLTAGE
        return
    state, prev = start, 0x0080  # previous bit 7 high: the master must lower it first
    for _ in range(8):
        if state == target:
            break
        cw = sm.controlword_toward(state, target, prev)
        state, prev = sm.next_state(state, cw, prev), cw
    assert state == target


def test_vectorised_master_matches_scalar() -> None:
    states = np.array([s for s in REAL_STATES] * 2, dtype=np.uint8)
    prev = np.array([0] * len(REAL_STATES) + [0x80] * len(REAL_STATES), dtype=np.uint16)
    out = np.zeros(states.shape, dtype=np.uint16)
    for target in (S.SWITCH_ON_DISABLED, S.OPERATION_ENABLED):
        sm.controlwords_toward(states, target, prev, out)
        for i, s in enumerate(states):
            assert out[i] == sm.controlword_toward(State(int(s)), target, int(prev[i]))


def test_master_rejects_unreachable_target() -> None:
    with pytest.raises(ValueError, match="target must be one of"):
        sm.controlword_toward(S.OPERATION_ENABLED, S.FAULT, 0)


def test_mode_display_check() -> None:
    assert sm.mode_ok(8, Mode.CSP)
    assert not sm.mode_ok(9, Mode.CSP)
    assert Mode.CSP == 8 and Mode.CSV == 9 and Mode.CST == 10


def test_describe_statusword_names_state_and_flags() -> None:
    text = sm.describe_statusword(0x2000 | 0x0237)
    assert text.startswith("Operation enabled")
    assert "0x2237" in text and "following error" in text and "voltage enabled" in text
    assert sm.describe_statusword(0x0008).startswith("Fault")
