"""Acceptance on the real UR10e recordings (../shared/data/ur10e), with the shipped
configs/ur10e/thresholds.yaml: every push found, no alarm on runs not calibrated on."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[3]
DATA = ROOT.parent / "shared" / "data" / "ur10e"
PARAMS = ROOT / "configs" / "ur10e" / "parameters.yaml"
THRESHOLDS = ROOT / "configs" / "ur10e" / "thresholds.yaml"
PUSH = DATA / "collision" / "ur-20_01_22-push_pose_1.csv"

pytestmark = [
    pytest.mark.data,
    pytest.mark.skipif(not DATA.is_dir(), reason="../shared/data/ur10e (UR10e recordings) absent"),
]


@pytest.fixture(scope="module")
def ctx():
    from hofto_hw.replay.setup import load_setup, load_thresholds_for

    setup = load_setup(PARAMS)
    return setup, load_thresholds_for(setup, THRESHOLDS)


def _pushes_in_raw_torque(path: Path) -> list[tuple[float, float]]:
    """Pushes counted without any model: joint torque leaving its resting value (the first
    0.5 s) by more than 18 N·m on any joint, runs closer than 0.5 s joined."""
    from hofto_hw.identify.data import load_csv

    rec = load_csv(path, ROOT / "configs" / "ur10e" / "columns_31.yaml")
    dev = np.max(np.abs(rec.tau - rec.tau[:50].mean(axis=0)), axis=1)
    on = dev > 18.0
    edges = np.flatnonzero(np.diff(on.astype(int)))
    spans: list[list[float]] = []
    for s, e in zip(edges[::2] + 1, edges[1::2], strict=False):
        if spans and rec.t[s] - spans[-1][1] < 0.5:
            spans[-1][1] = rec.t[e]
        else:
            spans.append([rec.t[s], rec.t[e]])
    return [(a, b) for a, b in spans]


def test_push_file_every_push_found_nothing_else(ctx) -> None:
    from hofto_hw.replay.session import load_for_replay, run_replay

    setup, thresholds = ctx
    pushes = _pushes_in_raw_torque(PUSH)
    assert len(pushes) == 4
    rec = load_for_replay(setup, PUSH, None)
    for name in thresholds.observers:
        episodes = run_replay(setup, rec, name, thresholds).episodes
        assert len(episodes) == 4, name
        for ep, (a, b) in zip(episodes, pushes, strict=True):
            # each episode overlaps its push (the estimate lags the torque a little)
            assert ep.start < b and ep.end > a, (name, ep, (a, b))


LEFT_OUT = [
    "ur-20_02_10-20sec_7harm.csv",
    "ur-20_02_19_15harm50sec.csv",
    "ur-20_01_31-unload.csv",
    "ur-19_09_27-15_11_06.csv",
    "ur-19_10_01-14_04_41.csv",
    "ur-20_02_10-30sec_12harm.csv",
]


@pytest.fixture(scope="module")
def left_out(ctx):
    """The shipped thresholds' settings (monitor timing, per-joint margins and rest weights
    from the provenance ``hofto-hw tune`` wrote) re-calibrated on every file it was tuned on
    except LEFT_OUT: the shipped file itself is calibrated on all of them."""
    from support.ur10e import refit_shipped

    from hofto_hw.replay.session import load_for_replay

    setup, th = ctx
    prov = th.provenance
    files = [f for f in prov["files"] if f not in LEFT_OUT]
    paths = [
        DATA / "identification" / f
        if (DATA / "identification" / f).is_file()
        else DATA / "validation" / f
        for f in files
    ]
    recs = [load_for_replay(setup, path, None) for path in paths]
    monitors = refit_shipped(setup, th, recs)
    observers = {
        obs: th.observers[obs].model_copy(update={"monitor": m}) for obs, m in monitors.items()
    }
    return setup, th.model_copy(update={"observers": observers, "calibrated_on": files})


@pytest.mark.slow
@pytest.mark.parametrize("name", LEFT_OUT)
def test_no_false_alarm_on_runs_not_calibrated_on(left_out, name: str) -> None:
    from hofto_hw.replay.session import load_for_replay, run_replay

    setup, thresholds = left_out
    assert name not in thresholds.calibrated_on
    rec = load_for_replay(setup, DATA / "identification" / name, None)
    for obs in ("momentum", "hofto"):
        assert run_replay(setup, rec, obs, thresholds).episodes == [], obs


def test_payload_runs_are_flagged(ctx) -> None:
    """A payload the model does not know is an external load: it must not go unseen."""
    from hofto_hw.replay.session import load_for_replay, run_replay

    setup, thresholds = ctx
    rec = load_for_replay(setup, DATA / "identification" / "ur-20_01_31-load.csv", None)
    assert run_replay(setup, rec, "momentum", thresholds).episodes


def test_25_column_layout_is_found_and_gives_the_same_episodes(ctx, tmp_path: Path) -> None:
    from hofto_hw.replay.session import load_for_replay, run_replay

    setup, thresholds = ctx
    p = tmp_path / "push25.csv"
    p.write_text("\n".join(",".join(ln.split(",")[:25]) for ln in PUSH.read_text().splitlines()))
    eps25 = run_replay(setup, load_for_replay(setup, p, None), "momentum", thresholds).episodes
    eps31 = run_replay(setup, load_for_replay(setup, PUSH, None), "momentum", thresholds).episodes
    assert [(e.start, e.end, e.joints) for e in eps25] == [
        (e.start, e.end, e.joints) for e in eps31
    ]
