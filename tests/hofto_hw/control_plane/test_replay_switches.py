"""`hofto-hw replay` of a real service run in which a client switched the safety profile and
set a payload: replay takes both at their ticks, so it decides the scripted collision in the
run's tick (MATCH) and recomputes the run's estimates; the same log without those events (what
replay did before it read them) decides elsewhere and misses the estimates by the payload."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml
from support.control_service import Service, settled, socket_config, wait_for

from hofto_hw.cli import main
from hofto_hw.client import Robot
from hofto_hw.replay.flight_log import read_flight_log
from hofto_hw.replay.reproduce import reproduce


@pytest.fixture(scope="module")
def run_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("switch")
    path = socket_config(tmp, collision_start=8.0)
    data = yaml.safe_load(path.read_text())
    # a slow push: the thresholds' scale moves its detection by many ticks
    data["run"]["collision"].update(rise_time=0.05)
    # what is replayed here is the collision decision: a stall of this shared machine must
    # not stop the run before the scripted collision (replay integrates stalls as the loop)
    data["safety"]["overrun_streak"] = 2000
    path.write_text(yaml.safe_dump(data))
    svc = Service(tmp, "--hold", config=path)
    try:
        with Robot.connect(socket=svc.sock) as robot:
            wait_for(settled(robot), "hold at rest")
            robot.set_safety_profile("reduced")
            robot.set_payload(2.4, [0.0, 0.0, 0.05])  # the arm holds 3 kg: 0.6 kg not modelled
            assert robot.state().faults == [], "a stop before the scripted collision"
            s = wait_for(lambda: (st := robot.state()).faults and st, "the scripted collision")
            assert s.faults == ["collision"], s.faults
        svc.stop()
    finally:
        svc.kill()
    (log,) = sorted(svc.logs.glob("run-*.mcap"))
    return log


def test_replay_takes_the_profile_switch_and_the_payload_at_their_ticks(run_log, capsys) -> None:
    log = read_flight_log(run_log)
    kinds = [e.kind_name for e in log.events]
    assert "profile" in kinds and "payload" in kinds and "collision" in kinds
    r = reproduce(log)
    assert r.match, r.as_dict()
    assert _diff(r, log) < 1e-6
    assert main(["replay", str(run_log), "--json"]) == 0
    assert '"match": true' in capsys.readouterr().out

    # what replay did before: the run as if nobody had switched or set anything
    blind = dataclasses.replace(
        log, events=[e for e in log.events if e.kind_name not in ("profile", "payload")]
    )
    b = reproduce(blind)
    assert not b.match and b.replayed_tick != r.replayed_tick, b.as_dict()
    assert _diff(b, log) > 0.5  # 0.6 kg at the tool, on the shoulder
    only_profile = dataclasses.replace(
        log, events=[e for e in log.events if e.kind_name != "payload"]
    )
    assert _diff(reproduce(only_profile), log) > 0.5


def _diff(r, log) -> float:
    """Largest |replayed - recorded| estimate [N·m] after the first 100 ticks (a real-clock
    run's start differs by its first wake-ups: reproduce.py's _run_with_dt)."""
    return max(float(np.abs(r.replayed[o][100:] - log.tau_ext[o][100:]).max()) for o in r.replayed)


def test_the_runs_figure_scales_its_thresholds_at_the_switch(run_log) -> None:
    from hofto_hw.replay.levels_track import detector_levels, track_thresholds
    from hofto_hw.replay.reproduce import loop_dt, profile_switches

    log = read_flight_log(run_log)
    ((tick, scale),) = profile_switches(log)
    assert scale == pytest.approx(0.8)
    est = np.stack([log.tau_ext[o] for o in log.observers], axis=1)
    h = loop_dt(log, 1000.0)
    h = np.where(log.sample_dt > 0.0, log.sample_dt, h) if log.sample_dt is not None else h
    tracks = []
    for switches in (profile_switches(log), []):
        _, row, mon = detector_levels(log)
        mon.reset()
        args = (est, log.qd, log.qdd_cmd, h, log.ticks, log.monitored)
        tracks.append(track_thresholds(mon, row, *args, switches))
    after = (log.ticks > tick) & (log.monitored != 0)
    before = (log.ticks <= tick) & (log.monitored != 0)
    assert after.sum() > 1000  # (the switch may come before the monitor's first tick)
    np.testing.assert_array_equal(tracks[0][before], tracks[1][before])
    np.testing.assert_allclose(tracks[0][after], 0.8 * tracks[1][after], rtol=1e-12)


def test_the_live_thresholds_topic_follows_the_profile_switch(run_log) -> None:
    """/safety/thresholds, written by the recorder's writer process while the service ran,
    carries the switched profile's thresholds from the tick after the switch on: equal to the
    whole log's re-computation with the switch, and 0.8 of the unswitched one after it."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from hofto_hw.recording import schemas as s
    from hofto_hw.replay.levels_track import detector_levels, track_thresholds
    from hofto_hw.replay.reproduce import loop_dt, profile_switches

    log = read_flight_log(run_log)
    ((tick, _scale),) = profile_switches(log)
    with run_log.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        msgs = {
            m.sequence: (msg.contact, msg.collision)
            for _s, _c, m, msg in reader.iter_decoded_messages(topics=[s.THRESHOLDS_TOPIC])
        }
    est = np.stack([log.tau_ext[o] for o in log.observers], axis=1)
    h = loop_dt(log, 1000.0)
    h = np.where(log.sample_dt > 0.0, log.sample_dt, h) if log.sample_dt is not None else h
    tracks = []
    for switches in (profile_switches(log), []):
        _, row, mon = detector_levels(log)
        mon.reset()
        args = (est, log.qd, log.qdd_cmd, h, log.ticks, log.monitored)
        tracks.append(track_thresholds(mon, row, *args, switches))
    judged = np.flatnonzero(log.monitored)
    assert sorted(msgs) == [int(t) & 0xFFFFFFFF for t in log.ticks[judged]]
    live = np.array([msgs[int(t) & 0xFFFFFFFF] for t in log.ticks[judged]])
    after = log.ticks[judged] > tick
    assert after.sum() > 1000
    np.testing.assert_array_equal(live, tracks[0][judged])
    np.testing.assert_allclose(live[after], 0.8 * tracks[1][judged][after], rtol=1e-12)
