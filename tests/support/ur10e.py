"""The UR10e tests' shared step: the shipped thresholds' settings re-fitted on fewer runs."""

from __future__ import annotations

from typing import Any


def refit_shipped(setup: Any, thresholds: Any, recs: list[Any]) -> dict[str, Any]:
    """Per observer (momentum, HOFTO), the shipped thresholds file's monitor re-calibrated on
    ``recs`` (replay recordings) with the settings `hofto-hw tune` chose and wrote in its
    provenance (per-joint margins, rest weights, standstill margins): {name: monitor}."""
    from hofto_hw.replay.runner import run_observer
    from hofto_hw.replay.session import observer_for
    from hofto_hw.replay.tuning import refit

    out = {}
    for obs in ("momentum", "hofto"):
        entry = thresholds.observers[obs]
        ests = [run_observer(r, observer_for(obs, entry.observer, setup, r, "auto")) for r in recs]
        chosen = thresholds.provenance["observers"][obs]
        out[obs] = refit(
            recs,
            ests,
            entry.monitor,
            chosen["margin"],
            chosen.get("rest_weight"),
            rest_margin=chosen.get("rest_margin"),
        )
    return out
