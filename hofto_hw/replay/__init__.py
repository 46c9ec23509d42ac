"""Offline replay of observers over recordings, contact episodes, threshold calibration.

- :mod:`runner`: observer (and collision monitor) run causally, sample by sample;
- :mod:`episodes`: contact episodes from the monitor's output;
- :mod:`calibrate`: thresholds from free-motion recordings (a linear program per joint);
- :mod:`thresholds`: the thresholds file; :mod:`setup`: model, config, defaults;
- :mod:`plot`: the PNG; :mod:`defaults`: observer gains for ~100 Hz recordings.
"""

from hofto_hw.replay.episodes import Episode, find_episodes
from hofto_hw.replay.runner import ReplayResult, replay, run_monitor, run_observer

__all__ = ["Episode", "ReplayResult", "find_episodes", "replay", "run_monitor", "run_observer"]
