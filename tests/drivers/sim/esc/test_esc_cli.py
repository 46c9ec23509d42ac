"""`hofto-hw sim-ethercat` start-up errors (no root needed) and the veth helper's checks."""

from __future__ import annotations

from pathlib import Path

import pytest

from drivers.sim.esc import veth
from hofto_hw.cli import main
from hofto_hw.errors import UserError

CONFIG = Path(__file__).resolve().parents[4] / "configs" / "er3a.yaml"


def test_missing_interface_is_one_clear_line(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["sim-ethercat", "--iface", "nosuchif0", "--config", str(CONFIG)])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1
    assert "'nosuchif0' does not exist" in err


def test_creating_a_veth_pair_without_root_says_so(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("os.geteuid", lambda: 1000)
    with pytest.raises(UserError, match="needs root"):
        veth.create_pair("xm0", "xs0")
