"""``hofto-hw tune`` end to end on shipped UR10e recordings, fast settings."""

from __future__ import annotations

import pytest

from hofto_hw.cli import main
from tests.conftest import CONFIGS, SHARED_DATA

IDN = SHARED_DATA / "ur10e" / "identification"
FILES = [
    IDN / "ur-19_10_01-13_51_41.csv",
    IDN / "ur-19_09_27-15_11_06.csv",
    IDN / "ur-19_10_01-14_04_13.csv",
    IDN / "ur-19_10_01-14_04_41.csv",
]
pytestmark = pytest.mark.skipif(
    not all(f.is_file() for f in FILES), reason=f"UR10e recordings not found at {IDN}"
)


@pytest.mark.slow
def test_tune_writes_thresholds_with_provenance(tmp_path, capsys) -> None:
    from hofto_hw.replay.thresholds import read_thresholds

    out = tmp_path / "tuned.yaml"
    args = ["tune", str(CONFIGS / "ur10e" / "parameters.yaml"), *map(str, FILES), "-o", str(out)]
    fast = ["--gains", "20,500", "--margins", "2", "--pulses", "1", "--amplitudes", "10,20"]
    fast += ["--observers", "momentum", "--moving-times", "0.5", "--standstill-times", "0"]
    assert main(args + fast) == 0
    captured = capsys.readouterr()
    assert "gain 500: unstable" in captured.err  # refused by the stability check
    assert "sensitivity on the left-out runs" in captured.out and "20 N·m" in captured.out
    th = read_thresholds(out)
    assert th.observers["momentum"].observer.gain == [20.0] * 6
    prov = th.provenance
    assert set(prov["files"]) == {f.name for f in FILES}
    assert all(len(h) == 64 for h in prov["files"].values())
    assert prov["observers"]["momentum"]["margin"] == [2.0] * 6
    rates = prov["observers"]["momentum"]["sensitivity"]["motion"]["20"]["rate"]
    assert len(rates) == 6 and max(r for r in rates if r is not None) > 0.5  # some joints find them
    # the file replays: 0 false alarms on a left-out run it was tuned against
    assert (
        main(
            [
                "replay",
                str(CONFIGS / "ur10e" / "parameters.yaml"),
                str(FILES[1]),
                "--thresholds",
                str(out),
                "--json",
            ]
        )
        == 0
    )


def test_tune_refuses_bad_gains(capsys) -> None:
    args = [
        "tune",
        str(CONFIGS / "ur10e" / "parameters.yaml"),
        *map(str, FILES[:2]),
        "-o",
        "x.yaml",
    ]
    assert main(args + ["--gains", "fast"]) == 2
    assert "--gains" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("option", "named"),
    [
        (["--folds", "9"], "--folds"),
        (["--observers", "momentum,sta"], "'sta'"),
        (["--rest-weights", "0"], "--rest-weights"),
        (["--moving-times", "0"], "--moving-times"),
    ],
)
def test_tune_refuses_bad_settings_naming_them(option, named, capsys) -> None:
    args = ["tune", str(CONFIGS / "ur10e" / "parameters.yaml"), *map(str, FILES), "-o", "x.yaml"]
    assert main(args + option) == 2
    assert named in capsys.readouterr().err


@pytest.mark.slow
def test_tune_searches_hofto_poles_and_calibrates_the_fused_ratio(tmp_path, capsys) -> None:
    import numpy as np

    from hofto_hw.replay.thresholds import read_thresholds
    from safety.collision import CollisionLevels, from_thresholds

    out = tmp_path / "fused.yaml"
    args = ["tune", str(CONFIGS / "ur10e" / "parameters.yaml"), *map(str, FILES), "-o", str(out)]
    fast = ["--gains", "20", "--hofto-poles", "20,300", "--margins", "1,2", "--pulses", "1"]
    fast += ["--amplitudes", "20", "--observers", "momentum,hofto", "--moving-times", "2"]
    fast += ["--rest-margins", "0.5,2"]
    assert main(args + fast) == 0
    captured = capsys.readouterr()
    assert "poles -300 rad/s, 4 substeps: unstable" in captured.err  # refused, not replayed
    assert "fusion (mean of hofto and momentum)" in captured.out and "decision:" in captured.out
    th = read_thresholds(out)
    grid = th.provenance["observers"]["hofto"]["grid"]
    assert [g["label"] for g in grid] == [
        "replay default",
        "poles -20 rad/s, 4 substeps",
        "poles -300 rad/s, 4 substeps",
    ]
    assert [g["stable"] for g in grid] == [True, True, False]
    assert sum(bool(g.get("chosen")) for g in grid) == 1 and not grid[2].get("chosen")
    chosen = th.observers["hofto"].observer
    if grid[1]["chosen"]:  # the pole-placed setting: the runtime's eq. (17) form
        assert chosen.form == "eq17" and chosen.substeps == 4 and chosen.gains[0] == [80.0] * 6
    else:
        assert chosen.form == "recursive"
    assert th.fusion is not None and set(th.fusion.monitors) == {"hofto", "momentum"}
    fused = th.provenance["observers"]["fusion"]
    assert fused["logic"] == "mean" and len(fused["margin"]) == 6
    assert th.provenance["decision"]["decides"] in ("momentum", "hofto", "fusion")
    # the fused thresholds are built by the one monitor and trip nowhere on a tuned-on run
    from hofto_hw.replay.runner import run_observer
    from hofto_hw.replay.session import load_for_replay, observer_for
    from hofto_hw.replay.setup import load_setup

    setup = load_setup(CONFIGS / "ur10e" / "parameters.yaml")
    rec = load_for_replay(setup, FILES[0], None)
    rows = ("hofto", "momentum")
    est = np.stack(
        [
            run_observer(rec, observer_for(r, th.observers[r].observer, setup, rec, "auto"))
            for r in rows
        ],
        axis=1,
    )
    mon = CollisionLevels.from_params(
        from_thresholds({r: th.fusion.monitors[r] for r in rows}, logic="mean"), backend="auto"
    )
    mon.reset(rec.qd[0])
    hits = [
        mon.step(est[k], rec.qd[k], None, float(rec.t[k] - rec.t[k - 1]), k)
        for k in range(1, rec.n_samples)
    ]
    assert not any(hits)
