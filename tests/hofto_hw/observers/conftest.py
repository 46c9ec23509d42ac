"""Fixtures for observer tests."""

from __future__ import annotations

import pytest

from hofto_hw.config.models import ExternalTorqueConfig


@pytest.fixture()
def ext():
    def make(kind: str, **kw) -> list[ExternalTorqueConfig]:
        return [ExternalTorqueConfig(kind=kind, **kw)]

    return make
