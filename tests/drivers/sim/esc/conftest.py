"""Fixtures for the emulated EtherCAT slave tests."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

# --import-mode=importlib does not put test directories on sys.path; the helpers module
# next to this file is shared by the test modules here.
sys.path.insert(0, str(Path(__file__).resolve().parent))

from esc_helpers import Mailbox, make_desc, make_od, request_state, setup_mailbox

from drivers.sim.esc import registers as r
from drivers.sim.esc.esc import Esc


@pytest.fixture()
def esc() -> Esc:
    return Esc(make_desc(), make_od())


@pytest.fixture()
def mailbox(esc: Esc) -> Mailbox:
    setup_mailbox(esc)
    request_state(esc, r.STATE_PREOP)
    assert esc.al_state == r.STATE_PREOP
    return Mailbox(esc)
