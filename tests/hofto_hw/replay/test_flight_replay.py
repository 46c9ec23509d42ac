"""`hofto-hw replay` on flight-recorder logs: read back, reproduce the collision decision."""

from __future__ import annotations

import json

import numpy as np
import pytest
from support.flight_run import ONSET, recorded_run

from hofto_hw.cli import main
from hofto_hw.replay.flight_log import read_flight_log


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return recorded_run(tmp_path_factory.mktemp("flight"))


@pytest.fixture(scope="module")
def late_run(tmp_path_factory):
    return recorded_run(tmp_path_factory.mktemp("late"), event_delay=3)


def test_the_recorded_run_detected_the_push(run):
    assert run["detected_at"] is not None and ONSET <= run["detected_at"] <= ONSET + 20


def test_flight_log_reads_back_what_the_loop_pushed(run):
    log = read_flight_log(run["path"])
    assert log.n_ticks == run["t"].shape[0]
    assert np.array_equal(log.ticks, np.arange(log.n_ticks))
    assert np.array_equal(log.t, run["t"])  # integer-ns stamps: exact
    for name in ("q", "qd", "tau"):
        assert np.array_equal(getattr(log, name), run[name])
    for i, name in enumerate(log.observers):
        assert np.array_equal(log.tau_ext[name], run["tau_ext"][:, i])
    assert [(e.tick, e.kind_name) for e in log.events] == [(run["detected_at"], "collision")]
    assert log.metadata["detector"] == "momentum" and log.metadata["robot"] == "er3a"


def test_replay_reproduces_the_detection_tick_bit_exactly(run, capsys):
    assert main(["replay", str(run["path"]), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["match"] is True and d["detector"] == "momentum"
    assert d["recorded"]["tick"] == d["replayed"]["tick"] == run["detected_at"]
    assert d["max_abs_diff"] == {"hofto": 0.0, "momentum": 0.0}
    assert main(["replay", str(run["path"]), "--reproduce"]) == 0
    assert "MATCH" in capsys.readouterr().out


def test_replay_flags_a_log_whose_decision_differs(late_run, capsys):
    assert main(["replay", str(late_run["path"])]) == 1
    out = capsys.readouterr().out
    assert "MISMATCH" in out
    assert (
        f"tick {late_run['detected_at'] + 3}" in out and f"tick {late_run['detected_at']}," in out
    )


def test_flight_log_with_params_is_refused_with_one_line(run, capsys):
    assert main(["replay", "configs/ur10e/parameters.yaml", str(run["path"])]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "without PARAMS" in err


def test_reproduce_needs_a_flight_log(tmp_path, capsys):
    csv = tmp_path / "x.csv"
    csv.write_text("1,2,3\n")
    assert main(["replay", str(csv)]) == 2
    assert "give PARAMS FILE" in capsys.readouterr().err
