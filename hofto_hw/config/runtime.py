"""Pydantic models of the ``run:`` and ``service:`` sections (the ``hofto-hw run`` process).

``run`` describes the demo job on the simulated arm: the joint path the arm moves along, the
scripted collision and the held load; ``service`` the control socket and sd_notify. Units SI.
Loading and checking only: nothing here runs in the tick.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, model_validator

from hofto_hw.config.base import FileModel
from hofto_hw.config.payload import PayloadConfig

Finite = Annotated[float, Field(allow_inf_nan=False)]
NonNeg = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
#: longest finite run [s] (a week): a longer one is a typo, not a plan
MAX_RUN_SECONDS = 7 * 86400.0


class DemoPathConfig(FileModel):
    """Smooth periodic joint motion about the home pose:
    q_ref = home + amplitude·sin(2π·t/period + phase)·fade(t), fade a quintic over ``ramp``."""

    amplitude: list[Finite] = Field(description="per joint [rad]")
    period: list[Positive] = Field(description="per joint [s]")
    phase: list[Finite] | None = Field(None, description="per joint [rad]")
    ramp: Positive = Field(1.0, description="fade-in time [s]")


class ScriptedCollisionConfig(FileModel):
    """A contact on the simulated arm: the torque on ``joint`` ramps linearly to ``peak``
    [N·m] in ``rise_time`` [s] from ``start`` [s] and stays for ``hold`` [s]."""

    joint: Annotated[int, Field(ge=0)] = 1
    peak: Finite = 20.0
    rise_time: Positive = 0.01
    start: NonNeg = 3.0
    hold: Positive = 0.3


class ScriptedDragConfig(FileModel):
    """The scripted hand of the run (after the collision stop), loop times [s]: ``reset``
    the latched stop, request drag mode at ``mode``, hold the enabling input from ``press``
    to ``release``; a hand pushes the tool with ``force`` [N] (world frame) from
    ``push_start`` to ``push_end`` with linear ramps of ``ramp`` [s]."""

    reset: NonNeg = 3.5
    mode: NonNeg = 3.9
    press: NonNeg = 4.0
    push_start: NonNeg = 4.5
    push_end: NonNeg = 5.7
    release: NonNeg = 5.9
    force: tuple[Finite, Finite, Finite] = (20.0, 0.0, 0.0)
    ramp: Positive = 0.02
    settle: Positive = Field(0.5, description="steady speed measured from push_start + this")
    replay: NonNeg | None = Field(
        None,
        description="loop time [s] to replay the path taught from press to release (recorded "
        "by the tick; the release's stop is reset 0.2 s before); None = no replay. Sim clock only",
    )

    @model_validator(mode="after")
    def _ordered(self) -> ScriptedDragConfig:
        order = ("reset", "mode", "press", "push_start", "push_end", "release")
        for a, b in itertools.pairwise(order):
            ta, tb = getattr(self, a), getattr(self, b)
            if tb <= ta:
                raise ValueError(f"drag.{b} = {tb} s must come after drag.{a} = {ta} s")
        if self.replay is not None and self.replay < self.release + 1.0:
            raise ValueError(
                f"drag.replay = {self.replay} s must come at least 1 s after drag.release = "
                f"{self.release} s (the drag figures' window: rest and drift after the release)"
            )
        if self.push_end - self.push_start <= self.settle + 0.05:
            raise ValueError(
                f"drag.push_end - push_start = {self.push_end - self.push_start:g} s leaves no "
                f"steady window after settle = {self.settle:g} s"
            )
        return self


class LiveViewConfig(FileModel):
    """``run.live_view``: serve the logged topics live over Foxglove's WebSocket protocol
    (from the flight recorder's writer process; docs/recording.md)."""

    host: str = Field(
        "127.0.0.1", min_length=1, description="bind address (the protocol has no login)"
    )
    port: Annotated[int, Field(ge=0, le=65535)] = Field(8765, description="TCP port; 0: any")
    rate_hz: Annotated[float, Field(gt=0.0, le=1000.0)] = Field(
        30.0, description="most messages per topic per second sent live (the log keeps all)"
    )


class RunConfig(FileModel):
    """The ``run:`` section: what ``hofto-hw run`` does on the simulated arm."""

    duration: Positive | None = Field(
        5.0,
        le=MAX_RUN_SECONDS,
        description="default run time [s]; None: until stopped (SIGTERM, Ctrl-C)",
    )
    clock: Literal["sim", "real"] = "real"
    path: DemoPathConfig | None = None
    collision: ScriptedCollisionConfig | None = Field(default_factory=ScriptedCollisionConfig)
    simulated_payload: PayloadConfig | None = Field(
        None, description="load the simulated arm really holds; None = safety.payload"
    )
    model_error: NonNeg | None = Field(
        None, description="override simulation.model_error for the run (relative, 1 sigma)"
    )
    log_dir: Path = Field(
        Path("out/logs"),
        description="folder of the flight-recorder logs; relative: from the config's folder "
        "(config.locate.output_folder: a shipped config of an installed wheel writes to ./out)",
    )
    drag: ScriptedDragConfig | None = Field(
        None, description="scripted drag after the collision stop (needs a drag: section)"
    )
    live_view: LiveViewConfig | None = Field(
        None, description="Foxglove live view of the logged topics (off when absent)"
    )


class ServiceConfig(FileModel):
    """The ``service:`` section: local control socket and systemd integration."""

    socket: Path = Field(Path("/run/hofto-hw/control.sock"), description="AF_UNIX control socket")
    socket_mode: Annotated[int, Field(ge=0, le=0o777)] = 0o660
    watchdog_fraction: Annotated[float, Field(gt=0.0, lt=1.0)] = Field(
        0.5, description="pet the systemd watchdog every fraction·WatchdogSec"
    )
    status_interval: Positive = Field(
        1.0, le=3600.0, description="sd_notify STATUS update period [s]"
    )
