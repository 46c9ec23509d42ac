"""One root error for the driver stack (python-can's CanError pattern)."""

from __future__ import annotations

import pytest

from drivers.cia402.drive_group import DriveFaultError, DriveTimeoutError
from drivers.errors import DriveError, DriverError, EtherCATError, SdoAbortError, TransportError
from drivers.ethercat.errors import IdentityMismatchError, SlaveLostError, StateChangeError
from hofto_hw.errors import UserError


@pytest.mark.parametrize(
    "cls, parent",
    [
        (DriverError, UserError),
        (TransportError, DriverError),
        (SdoAbortError, TransportError),
        (EtherCATError, TransportError),
        (DriveError, DriverError),
        (DriveTimeoutError, DriveError),
        (DriveFaultError, DriveError),
        (IdentityMismatchError, EtherCATError),
        (StateChangeError, EtherCATError),
        (SlaveLostError, EtherCATError),
    ],
)
def test_every_driver_error_has_one_root(cls: type, parent: type) -> None:
    assert issubclass(cls, parent)
    assert issubclass(cls, DriverError)


def test_an_sdo_abort_is_caught_as_a_transport_error() -> None:
    with pytest.raises(TransportError) as err:
        raise SdoAbortError(1, 0x603F, 0, 0x06020000, "read", "joint_2")
    assert err.value.axis == 1 and err.value.code == 0x06020000
    assert str(err.value).startswith("axis 1 (joint_2): SDO read 0x603F:00 aborted: 0x06020000")


def test_old_import_paths_still_work() -> None:
    import drivers.cia402.drive_group as dg
    import drivers.ethercat.errors as ee
    import drivers.transport as tr

    assert tr.SdoAbortError is SdoAbortError and tr.TransportError is TransportError
    assert ee.EtherCATError is EtherCATError and dg.DriveError is DriveError
