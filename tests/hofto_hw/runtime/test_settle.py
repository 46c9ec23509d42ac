"""safety.collision.settle_time: the collision monitor does not judge while the observers
converge and the arm settles into its position loop after a (re)start; then it judges every
tick again. (At start-up on the simulated arm the fast HOFTO reads the arm settling into its
position loop as 2-3 N·m on joint 2: a contact-level report without the settle time.)"""

from __future__ import annotations

from hofto_hw.config.models import SystemConfig
from hofto_hw.recording.record import MemorySink, tick_dtype
from hofto_hw.runtime.compose import build


def _monitored_and_events(cfg: SystemConfig, settle: float, ticks: int) -> tuple[list, list]:
    col = cfg.safety.collision.model_copy(update={"settle_time": settle})
    cfg = cfg.model_copy(update={"safety": cfg.safety.model_copy(update={"collision": col})})
    system = build(cfg, clock="sim", contact=False, sink=MemorySink(tick_dtype(6, 2), 4096))
    seen: list[bool] = []

    def watch() -> bool:
        seen.append(bool(system.tick.tick_rec["monitored"]))
        return False

    system.loop.run(max_ticks=ticks, should_stop=watch)
    ev = system.tick.stop.events
    events = [(int(ev.tick[i]), int(ev.kind[i])) for i in range(ev.count)]
    return seen, events


def test_the_monitor_waits_out_the_settle_time_then_judges_every_tick(cfg) -> None:
    assert cfg.safety.collision.settle_time > 0.0  # shipped on
    settle = round(cfg.safety.collision.settle_time * cfg.loop.rate_hz)
    seen, events = _monitored_and_events(cfg, cfg.safety.collision.settle_time, settle + 50)
    assert not any(seen[:settle]), seen.index(True)
    assert all(seen[settle:]), seen[settle:].index(False)
    assert events == []


def test_without_the_settle_time_the_start_up_reads_as_a_contact(cfg) -> None:
    seen, events = _monitored_and_events(cfg, 0.0, 100)
    assert all(seen)
    assert events and events[0][0] <= 20, events  # the report the settle time avoids
