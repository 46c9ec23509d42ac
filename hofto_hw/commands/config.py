"""``hofto-hw config schema`` and ``hofto-hw config check FILE``."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from hofto_hw.errors import ConfigError

if TYPE_CHECKING:
    from hofto_hw.config.models import SystemConfig


def configure(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    sub.add_parser("schema", help="print the JSON schema of the config files")
    check = sub.add_parser("check", help="validate config files (and their URDFs)")
    check.add_argument(
        "files", type=Path, nargs="+", metavar="FILE|ROBOT", help="config files or robot names"
    )


def check_transport(cfg: SystemConfig, source: str) -> None:
    """Refuse a ``bus.transport`` that no backend registers in drivers.transport.BACKENDS.

    The schema cannot check it: backends live in drivers/, above the config layer.
    """
    from drivers.transport import BACKENDS

    if cfg.bus is None or cfg.bus.transport in BACKENDS:
        return
    raise ConfigError(
        f"{source}: bus.transport: no transport backend of that name; the backends are "
        f"{', '.join(sorted(BACKENDS))} (got {cfg.bus.transport!r})"
    )


def run(args: argparse.Namespace) -> int:
    from hofto_hw.config import json_schema, load_config
    from hofto_hw.config.locate import find_config
    from hofto_hw.errors import ConfigError

    if args.action == "schema":
        print(json_schema())
        return 0
    from hofto_hw.model import RobotModel
    from hofto_hw.observers import make_observer
    from hofto_hw.observers.stability import check_observer
    from hofto_hw.runtime.compose import build_model
    from hofto_hw.runtime.motion_check import check_motion

    for spec in args.files:
        path = find_config(spec, option="config check")
        cfg = load_config(path)
        check_transport(cfg, str(path))
        model = RobotModel.from_config(cfg.robot)  # URDF, joints and tool frame exist
        try:
            check_motion(cfg, build_model(cfg))
        except ConfigError as exc:
            raise ConfigError(f"{path}: {exc}") from None
        for name, obs in cfg.observers.items():
            try:
                check_observer(name, obs, model, cfg.loop.rate_hz)
            except ConfigError as exc:
                raise ConfigError(f"{path}: {exc} (rate: loop.rate_hz)") from None
            make_observer(obs, model)
        if cfg.bus is not None:
            from hofto_hw.config.drive_profile import resolve_profiles

            profiles = resolve_profiles(cfg.bus, cfg.cycle_time, str(path), Path(path).parent)
        if cfg.bus is not None and cfg.bus.transport == "canopen":
            from drivers.canopen.busload import check_bus_load, configured_load
            from drivers.canopen.layout import bus_cob_id_clashes

            clashes = bus_cob_id_clashes(cfg.bus, profiles)
            if clashes:
                raise ConfigError(f"{path}: bus.canopen: {clashes[0]}")

            load = configured_load(cfg.bus, cfg.loop.rate_hz)
            check_bus_load(load, f"{path}: loop.rate_hz with bus.canopen")
            print(
                f"{path}: CANopen bus load {load.load * 100:.0f} % at {cfg.loop.rate_hz:g} Hz "
                f"(limit {load.limit * 100:.0f} %, highest feasible rate "
                f"{load.highest_rate():.0f} Hz)"
            )
        print(
            f"{path}: ok ({cfg.robot.name}, {model.n} joints, "
            f"{len(cfg.observers)} observers, loop {cfg.loop.rate_hz:g} Hz)"
        )
    return 0
