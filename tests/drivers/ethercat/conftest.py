"""Emulated EtherCAT network on a veth pair, served by `hofto-hw sim-ethercat` in a child
process, for the master tests. Needs root: skipped when unprivileged, a failure under CI
(the plumbing is tests/support/rootnet.py, shared with the other root tests)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from support.rootnet import ROOT, emulator, sim_ethercat_args, veth_pair

CONFIG = ROOT / "configs" / "er3a.yaml"


@dataclass
class EmulatedBus:
    """A running emulator: the master's interface, the control socket, the config."""

    master_iface: str
    slave_iface: str
    control: str
    proc: object
    cfg: object

    def call(self, **request: object) -> dict:
        from drivers.sim.esc.network import ControlClient

        return ControlClient(self.control).call(**request)


@pytest.fixture()
def emulated_bus(tmp_path: Path) -> Iterator[EmulatedBus]:
    from hofto_hw.config.loader import load_config

    with (
        veth_pair("hm", "hs") as (master, slave),
        emulator(sim_ethercat_args(slave, CONFIG), tmp_path, timeout=30.0) as emu,
    ):
        yield EmulatedBus(master, slave, emu.control, emu.proc, load_config(CONFIG))
