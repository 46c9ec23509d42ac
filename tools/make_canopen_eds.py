"""Write configs/canopen/emulated_drive.eds from the emulated drive's object dictionary.

Usage: ``python tools/make_canopen_eds.py [--config configs/er3a.yaml] [-o PATH]``. The EDS
describes drive 1 of the config (identity, ratings); COB-IDs are ``$NODEID``-relative.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from drivers.sim.canopen_node import eds_text, node_dictionary
from hofto_hw.config.loader import load_config

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_OUT = ROOT / "configs" / "canopen" / "emulated_drive.eds"


def build(config: Path = ROOT / "configs" / "er3a.yaml") -> str:
    """EDS text for drive 1 of ``config``."""
    cfg = load_config(config)
    assert cfg.bus is not None
    return eds_text(node_dictionary(cfg.bus.drives[0], 1, cfg.robot.joints[0]), 1) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config", type=Path, default=ROOT / "configs" / "er3a.yaml")
    p.add_argument("-o", "--output", type=Path, default=DEFAULT_OUT)
    a = p.parse_args()
    a.output.write_text(build(a.config))
    print(a.output)


if __name__ == "__main__":
    main()
