"""Flight-log replay of a run whose observers integrated the bus's sample interval (EtherCAT
DC: ``Transport.sample_dt``, whole cycles between the drives' samples, -1 over a lost frame)
rather than the loop's dt: the loop logs the interval per tick (``sample_dt``) and replay
integrates the same, so the replayed estimates are the loop's. Logs of older layouts (no
``sample_dt``) still read, and replay then falls back to the loop's dt."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from hofto_hw.config.loader import load_config
from hofto_hw.control.joint_motion import MOVE
from hofto_hw.observers import make_observer
from hofto_hw.recording import cdr
from hofto_hw.recording.flight_file import FlightFile, LogSpec
from hofto_hw.replay import reproduce as rep
from hofto_hw.replay.flight_log import FlightLog, _tick_status, read_flight_log
from hofto_hw.runtime.compose import build, build_model, loop_observer_table

ROOT = Path(__file__).resolve().parents[3]
CONFIG = ROOT / "configs" / "er3a.yaml"
TICKS = 1500


def _dc_interval(k: int, period: float) -> float:
    """The bus's sample interval of tick k: mostly one cycle, every 37th a late frame that
    spans two, every 53rd a lost one (-1: no new sample)."""
    if k % 53 == 0:
        return -1.0
    if k % 37 == 0:
        return 2.0 * period
    return period


@pytest.fixture(scope="module")
def dc_run(tmp_path_factory) -> tuple[FlightLog, object]:
    """A run of the real tick on the simulated arm (moving) with the bus reporting DC sample
    intervals that differ from the loop's dt, written through the flight file's writer."""
    cfg = load_config(CONFIG)
    system = build(cfg, clock="sim", contact=False)
    tick, transport = system.tick, system.group.transport
    tick.mode_request = MOVE
    period = 1.0 / system.rate_hz
    t = 0.0
    for k in range(1, TICKS + 1):
        transport.sample_dt = _dc_interval(k, period)
        t += period
        tick.step(t, period, 0.0, 0, 0.0)
    transport.sample_dt = 0.0
    ticks = system.sink.last_ticks()
    assert len(ticks) == TICKS
    events = system.sink.last_events()
    system.close()
    path = tmp_path_factory.mktemp("dclog") / "dc.mcap"
    spec = LogSpec(
        path=path,
        joint_names=list(cfg.robot.joints),
        observers=list(system.observer_names),
        metadata={"observer_backend": system.tick.backend},
    )
    f = FlightFile(spec, path, 0)
    f.write_ticks(ticks)
    f.write_events(events)
    f.finish()
    return read_flight_log(path), cfg


def _replayed(log: FlightLog, cfg, name: str) -> np.ndarray:
    ocfg = loop_observer_table(cfg)[name]
    obs = make_observer(ocfg, build_model(cfg), backend=rep.recorded_backend(log))
    rate = float(cfg.loop.rate_hz)
    return rep._run_with_dt(obs, log, rep.loop_dt(log, rate), 1.0 / rate)


def test_the_log_records_the_observers_interval(dc_run) -> None:
    log, cfg = dc_run
    assert log.sample_dt is not None and log.sample_dt.shape == (TICKS,)
    period = 1.0 / float(cfg.loop.rate_hz)
    expected = [_dc_interval(k, period) for k in range(1, TICKS + 1)]
    # held ticks are logged as 0 (the observers did not integrate)
    np.testing.assert_array_equal(log.sample_dt, np.maximum(expected, 0.0))


def test_replay_integrates_the_logged_interval(dc_run) -> None:
    log, cfg = dc_run
    for name in log.observers:
        diff = np.abs(_replayed(log, cfg, name) - log.tau_ext[name]).max(axis=1)
        assert diff[200:].max() < 1e-9, (name, float(diff[200:].max()))


def test_without_the_interval_the_replay_does_not_match(dc_run) -> None:
    """The same log read as an older one (no ``sample_dt``): replay integrates the loop's dt
    and misses the run's estimates (the difference the logged interval closes)."""
    log, cfg = dc_run
    old = dataclasses.replace(log, sample_dt=None)
    worst = max(
        float(np.abs(_replayed(old, cfg, name) - log.tau_ext[name])[200:].max())
        for name in log.observers
    )
    assert worst > 1e-3, worst


def test_an_older_status_layout_still_reads(dc_run) -> None:
    """Status messages without ``sample_dt`` (logs written before it was logged) still give
    ``monitored`` and ``qdd_cmd``; ``sample_dt`` stays None."""
    log, _ = dc_run
    n = len(log.joint_names)
    dtype, template = cdr.tick_status_layout(n, sample_dt=False)
    batch = cdr.fill_batch(dtype, template, log.n_ticks)
    batch["monitored"] = log.monitored
    batch["qdd_cmd"] = log.qdd_cmd
    raws = [batch[i].tobytes() for i in range(log.n_ticks)]
    old = dataclasses.replace(log, monitored=None, qdd_cmd=None, sample_dt=None)
    _tick_status(old, raws)
    assert old.sample_dt is None
    np.testing.assert_array_equal(old.monitored, log.monitored)
    np.testing.assert_array_equal(old.qdd_cmd, log.qdd_cmd)
