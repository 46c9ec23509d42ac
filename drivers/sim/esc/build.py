"""Build an emulated EtherCAT network from a system configuration (``bus:`` section)."""

from __future__ import annotations

from drivers.sim.drive import EmulatedDrives
from drivers.sim.esc.description import SlaveDescription
from drivers.sim.esc.network import EmulatedNetwork
from drivers.sim.plant import Plant
from hofto_hw.config.drives import BusConfig
from hofto_hw.config.models import SimulationConfig, SystemConfig
from hofto_hw.errors import ConfigError


def slave_descriptions(bus: BusConfig, names: list[str]) -> list[SlaveDescription]:
    """One slave per drive of ``bus``: identity from ``bus.drives[i].identity``."""
    out = []
    for i, d in enumerate(bus.drives):
        ident = d.identity
        out.append(
            SlaveDescription(
                vendor_id=ident.vendor_id,
                product_code=ident.product_code,
                revision=ident.revision or 0,
                serial=0x5100 + i,
                name="hofto-sim CiA-402 servo",
            )
        )
    return out


def build_network(cfg: SystemConfig, *, external: bool = True) -> EmulatedNetwork:
    """Plant + emulated drives + emulated slaves for ``cfg`` (one plant tick per bus cycle).

    ``external=False`` leaves out the scripted external torques (a quiet arm for tests).
    Raises ConfigError when the config has no ``bus`` section.
    """
    from hofto_hw.model.robot import RobotModel

    if cfg.bus is None:
        raise ConfigError("bus: section missing; the emulated EtherCAT drives need it")
    sim = cfg.simulation if cfg.simulation is not None else SimulationConfig()
    if not external:
        sim = sim.model_copy(update={"external": []})
    model = RobotModel.from_config(cfg.robot)
    plant = Plant(model, sim, cfg.cycle_time)
    names = list(cfg.robot.joints)
    drives = EmulatedDrives(plant, cfg.bus.drives, names=names)
    return EmulatedNetwork(slave_descriptions(cfg.bus, names), drives)
