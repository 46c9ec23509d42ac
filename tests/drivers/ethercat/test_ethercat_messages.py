"""Plain-word AL states/codes and the master's start-up errors that need no root."""

from __future__ import annotations

import pytest

from drivers.ethercat.al_status import describe_al_status_code, describe_state
from drivers.ethercat.errors import EtherCATError
from drivers.ethercat.master import EtherCATTransport
from drivers.transport import STATUS_NOT_OPEN, backend_class


def test_al_status_codes_in_words() -> None:
    assert describe_al_status_code(0x001D).startswith("0x001D (invalid output configuration")
    assert "sync manager watchdog" in describe_al_status_code(0x001B)
    assert "vendor-specific" in describe_al_status_code(0x8001)
    assert "unknown" in describe_al_status_code(0x00EE)


@pytest.mark.parametrize(
    ("status", "words"),
    [(0x08, "OP"), (0x14, "SAFE-OP + ERROR"), (0x12, "PRE-OP + ERROR"), (0x01, "INIT")],
)
def test_states_in_words(status: int, words: str) -> None:
    assert describe_state(status) == words


def test_missing_interface_is_named(er3a_config) -> None:
    t = EtherCATTransport("nosuchif0", er3a_config.bus.drives, 0.001)
    with pytest.raises(EtherCATError, match="'nosuchif0' does not exist"):
        t.open()
    assert t.exchange() == STATUS_NOT_OPEN


def test_registered_as_the_ethercat_backend() -> None:
    assert backend_class("ethercat") is EtherCATTransport
