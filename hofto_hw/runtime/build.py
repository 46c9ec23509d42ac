"""Config-to-object builders (the one place that turns a SystemConfig into driver objects).

- :func:`build_plant`: the simulated "true" arm ticking once per bus cycle;
- :func:`build_sim_bus`: that plant behind emulated CiA-402 drives, as the ``sim`` transport;
- :func:`build_emulated_network`: the same plant and drives as emulated EtherCAT slaves
  (``hofto-hw sim-ethercat``);
- :func:`build_transport`: the transport named by ``bus.transport``, looked up in
  :data:`drivers.transport.BACKENDS` (a backend is one line there; it needs an entry in
  ``_SPECIAL`` below only when it cannot be built by
  ``Class.from_config(bus, axis_names=..., cycle_time=...)``);
- :func:`build_drive_group`: the CiA-402 drive layer over a transport.

All raise :class:`hofto_hw.errors.ConfigError` naming the missing or wrong field.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from hofto_hw.config.drives import BusConfig
from hofto_hw.config.models import SimulationConfig, SystemConfig
from hofto_hw.errors import ConfigError

if TYPE_CHECKING:
    from drivers.cia402.drive_group import DriveGroup
    from drivers.sim.drive import EmulatedDrives
    from drivers.sim.esc.network import EmulatedNetwork
    from drivers.sim.plant import Plant
    from drivers.sim.simbus import SimBus
    from drivers.transport import Transport


def cycle_time(cfg: SystemConfig) -> float:
    """The bus cycle time [s]: 1 / ``loop.rate_hz``, the single source every builder uses."""
    return cfg.cycle_time


def _bus(cfg: SystemConfig, who: str) -> BusConfig:
    if cfg.bus is None:
        raise ConfigError(f"bus: section missing; {who} needs the drive data")
    return cfg.bus


def build_plant(cfg: SystemConfig, *, external: bool = True) -> Plant:
    """The simulated arm of ``cfg`` (``robot`` + optional ``simulation``), one tick per bus
    cycle. ``external=False`` leaves out the scripted external torques (a quiet arm)."""
    from drivers.sim.plant import Plant
    from hofto_hw.model.robot import RobotModel

    dt = cycle_time(cfg)
    sim = cfg.simulation if cfg.simulation is not None else SimulationConfig()
    if not external:
        sim = sim.model_copy(update={"external": []})
    return Plant(RobotModel.from_config(cfg.robot), sim, dt)


def build_sim_bus(cfg: SystemConfig, *, external: bool = True) -> SimBus:
    """The in-process ``sim`` transport: :func:`build_plant` behind ``bus.drives``."""
    from drivers.sim.simbus import SimBus

    bus = _bus(cfg, "the simulated bus")
    plant = build_plant(cfg, external=external)
    return SimBus.from_config(bus, plant, axis_names=list(cfg.robot.joints))


def apply_true_load(plant: Plant, cfg: SystemConfig) -> None:
    """Put the load the simulated arm really holds on ``plant``'s true arm:
    ``run.simulated_payload``, else the configured ``safety.payload`` (none when its mass is
    0). The run's model carries ``safety.payload``; without the same load on the emulated
    arm, its weight reads as a contact."""
    from hofto_hw.model.payload import apply_payload, payload_from_config

    load = cfg.run.simulated_payload or cfg.safety.payload
    if load.mass > 0.0:
        apply_payload(plant.true_model, payload_from_config(load))


def build_emulated_drives(
    cfg: SystemConfig, *, external: bool = True, load: bool = False
) -> EmulatedDrives:
    """Emulated CiA-402 drives (``bus.drives``) on :func:`build_plant`: what the EtherCAT and
    CANopen emulators serve; ``load``: the arm holds the run's load
    (:func:`apply_true_load`; the emulator commands set it)."""
    from drivers.sim.drive import EmulatedDrives

    bus = _bus(cfg, "the emulated drives")
    plant = build_plant(cfg, external=external)
    if load:
        apply_true_load(plant, cfg)
    return EmulatedDrives(plant, bus.drives, names=list(cfg.robot.joints), profiles=_profiles(bus))


def _profiles(bus: BusConfig) -> list | None:
    """The drives' profiles (None per drive without one); None when no drive names one."""
    if not any(d.profile for d in bus.drives):
        return None
    from drivers.cia402.profiles import profiles_of_bus

    return profiles_of_bus(bus)


def build_emulated_network(
    cfg: SystemConfig, *, external: bool = True, load: bool = False, first: int | None = None
) -> EmulatedNetwork:
    """Emulated EtherCAT slaves (identity from ``bus.drives[i].identity``) serving
    :func:`build_emulated_drives`: what ``hofto-hw sim-ethercat`` serves; ``first``: only
    the slaves of the first that many drives (a bench; the arm's other joints have none)."""
    from drivers.sim.esc.description import slave_descriptions
    from drivers.sim.esc.network import EmulatedNetwork
    from hofto_hw.config.drives import device_map

    drives = build_emulated_drives(cfg, external=external, load=load)
    bus = _bus(cfg, "the network")
    k = len(bus.drives) if first is None else first
    return EmulatedNetwork(
        slave_descriptions(bus.drives[:k], drives.profiles[:k]),
        drives,
        device_map(bus.drives)[:k],
    )


#: backends that need more than ``Class.from_config(bus, axis_names=, cycle_time=)``
_SPECIAL: dict[str, Callable[[SystemConfig], Transport]] = {"sim": build_sim_bus}


def build_transport(cfg: SystemConfig) -> Transport:
    """The transport ``bus.transport`` names (not opened); ConfigError for an unknown name,
    listing the registered backends."""
    from drivers.transport import BACKENDS, backend_class

    bus = _bus(cfg, "the transport")
    name = str(bus.transport)
    if name not in BACKENDS:
        raise ConfigError(
            f"bus.transport: unknown transport {name!r} (known: {', '.join(sorted(BACKENDS))})"
        )
    special = _SPECIAL.get(name)
    if special is not None:
        return special(cfg)
    cls = backend_class(name)
    return cls.from_config(bus, axis_names=list(cfg.robot.joints), cycle_time=cycle_time(cfg))


def build_drive_group(
    cfg: SystemConfig, transport: Transport, hot: dict[str, Any] | None = None
) -> DriveGroup:
    """The CiA-402 drive layer for ``bus.drives`` over ``transport`` (scaling, timeouts),
    with the compiled read/command when numba is available (the same numbers as the kernels'
    Python source); ``hot``: its hot arrays in the tick's record (DriveGroup.hot_fields)."""
    from drivers.cia402.drive_group import DriveGroup
    from hofto_hw.commands.backend import observer_backend

    return DriveGroup.from_config(
        transport, _bus(cfg, "the drive group"), backend=observer_backend(), hot=hot
    )
