"""Observer settings for replaying recordings sampled at about 100 Hz (the public UR10e
recordings), used when neither the thresholds file nor the system config names the
observer. The values live in the observer registry (hofto_hw.observers.registry, where
they are documented); this module names them for the replay commands.
"""

from __future__ import annotations

from hofto_hw.config.models import ObserverConfig
from hofto_hw.observers.registry import OBSERVERS, levant_gains, replay_default

OBSERVER_NAMES = tuple(OBSERVERS)

__all__ = ["OBSERVER_NAMES", "default_observer", "levant_gains"]


def default_observer(name: str, n_joints: int) -> ObserverConfig:
    """The default config of observer ``name`` for ~100 Hz recordings of an n-joint arm."""
    return replay_default(name, n_joints)
