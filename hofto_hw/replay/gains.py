"""The observer gains ``hofto-hw tune`` tries: a few per observer, each checked for stability
at the recordings' rate (hofto_hw.observers.stability) before any replay.

- momentum: the gains K [1/s] given (stable iff K < 2·rate);
- hofto: the replay default (Levant's recursive form, hofto_hw.observers.registry) and eq. (17)
  with its linearisation's n + 2 poles all at -p [rad/s] for each p given, L_i = C(n+2, i)·p^i
  (the runtime's parameterisation, configs/er3a.yaml ``loop.observers``; sigma -0.05), run
  with ``substeps`` per sample. At 100 Hz, measured with the stability check: p <= 30 is stable
  with 1 substep, <= 50 with 2, <= 100 with 4, <= 150 with 8;
- the others: their replay default only.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from math import comb

from hofto_hw.config.models import HoftoConfig, MomentumConfig, ObserverConfig
from hofto_hw.errors import ConfigError
from hofto_hw.model.robot import RobotModel
from hofto_hw.observers.stability import check_observer

#: eq. (17) power parameter of the pole-placed HOFTO variants (the runtime's)
SIGMA = -0.05


@dataclass(frozen=True)
class Variant:
    """One observer setting to tune: ``label`` for reports, the config."""

    label: str
    config: ObserverConfig


def pole_gains(order: int, pole: float, n_joints: int) -> list[list[float]]:
    """eq. (17) gains L_1..L_{order+2} (each per joint) placing every pole of the
    linearisation (powers 1) at -pole [rad/s]: L_i = C(order + 2, i)·pole^i."""
    k = order + 2
    return [[float(comb(k, i) * pole**i)] * n_joints for i in range(1, k + 1)]


def hofto_by_poles(pole: float, n_joints: int, substeps: int, order: int = 2) -> HoftoConfig:
    """HOFTO in eq. (17) form with its poles at -pole [rad/s], ``substeps`` per sample."""
    return HoftoConfig(
        order=order,
        form="eq17",
        sigma=SIGMA,
        gains=pole_gains(order, pole, n_joints),
        substeps=substeps,
    )


def variants(
    name: str,
    default: ObserverConfig,
    model: RobotModel,
    rate: float,
    gains: list[float],
    poles: list[float],
    substeps: int,
    say: Callable[[str], None] = lambda _m: None,
) -> tuple[list[Variant], list[dict[str, object]]]:
    """The stable settings of observer ``name`` to try at ``rate`` [Hz] (``default``: its
    replay default), and the grid as records (label, stable) for the provenance. Unstable
    settings are reported through ``say`` and left out."""
    tried: list[Variant] = []
    if isinstance(default, MomentumConfig):
        n = len(default.gain)
        tried = [
            Variant(f"gain {g:g}", default.model_copy(update={"gain": [g] * n})) for g in gains
        ]
    elif isinstance(default, HoftoConfig):
        n = len(default.gains[0])
        tried = [Variant("replay default", default)]
        tried += [
            Variant(f"poles -{p:g} rad/s, {substeps} substeps", hofto_by_poles(p, n, substeps))
            for p in poles
        ]
    else:
        tried = [Variant("replay default", default)]
    stable, grid = [], []
    for v in tried:
        try:
            check_observer(name, v.config, model, rate)
        except ConfigError as exc:
            say(f"{name} {v.label}: unstable at {rate:.4g} Hz, skipped ({exc})")
            grid.append({"label": v.label, "stable": False})
            continue
        stable.append(v)
        grid.append({"label": v.label, "stable": True})
    return stable, grid
