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
