"""The transport interface: abstract base, status codes, errors, backend registry."""

from __future__ import annotations

import pytest

from drivers.transport import (
    BACKENDS,
    SdoAbortError,
    Transport,
    TransportError,
    backend_class,
    describe_status,
)
from hofto_hw.errors import UserError


def test_transport_is_abstract() -> None:
    with pytest.raises(TypeError):
        Transport(6, 0.001)  # type: ignore[abstract]


def test_sim_backend_is_registered() -> None:
    from drivers.sim.simbus import SimBus

    assert backend_class("sim") is SimBus
    assert issubclass(SimBus, Transport)
    assert "sim" in BACKENDS


def test_unknown_backend_names_the_config_field() -> None:
    with pytest.raises(TransportError, match=r"bus\.transport: unknown transport 'profibus'"):
        backend_class("profibus")


def test_status_codes_in_plain_words() -> None:
    assert describe_status(0) == "ok"
    assert "frame lost" in describe_status(2)
    assert "working counter" in describe_status(3)
    assert describe_status(123) == "transport status 123"


def test_sdo_abort_error_is_a_user_error_with_decoded_code() -> None:
    err = SdoAbortError(3, 0x6060, 0, 0x06090030, "write", "joint_4")
    assert isinstance(err, UserError)
    assert str(err) == (
        "axis 3 (joint_4): SDO write 0x6060:00 aborted: "
        "0x06090030 invalid value for parameter (download only)"
    )
