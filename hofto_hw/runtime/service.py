"""sd_notify for ``hofto-hw run``: :class:`Supervisor`, run by the control-plane process
(hofto_hw/control_plane/process.py) on the channel's view of the loop.

It sends READY once, STATUS every ``status_interval``, WATCHDOG at the interval systemd
asked for but only while the loop finished a tick since the last pet (a hung loop stops the
pets and systemd kills the service), and STOPPING at the end. The control socket is
hofto_hw/control_plane/server.py's.
"""

from __future__ import annotations

import threading
import time
from typing import Any

from hofto_hw.runtime.notify import Notifier, NotifyError, Watchdog


class Supervisor:
    """sd_notify READY/STATUS/WATCHDOG/STOPPING for ``loop`` (see the module docstring).

    Sending is :class:`~hofto_hw.runtime.notify.Notifier`'s, petting is
    :class:`~hofto_hw.runtime.notify.Watchdog`'s with the loop's ``alive_ns`` as heartbeat;
    a failed send is counted (``errors``, ``last_error``), never raised into the service.
    """

    def __init__(
        self,
        system: Any,
        fraction: float = 0.5,
        status_interval: float = 1.0,
        status: Any = None,
    ):
        self.system = system
        self.status = status if status is not None else _no_status
        self.notifier = Notifier()
        self.watchdog = Watchdog(self.notifier, lambda: system.loop.alive_ns, fraction)
        self.interval = self.watchdog.interval
        self.status_interval = status_interval
        self.errors = 0
        self.last_error = ""
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="hofto-notify", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._done.set()
        self._thread.join(timeout=2.0)
        self.watchdog.stop()
        self._send("STOPPING=1")

    def _send(self, message: str) -> None:
        try:
            self.notifier.send(message)
        except NotifyError as exc:
            self.errors += 1
            self.last_error = str(exc)

    def _run(self) -> None:
        loop = self.system.loop
        while loop.alive_ns == 0 and not self._done.wait(0.01):
            pass  # READY only once the loop has run a tick
        self._send("READY=1")
        self.watchdog.start()  # pets only while the loop finished a tick since the last pet
        next_status = 0.0
        stopping_sent = False
        step = min(self.interval or self.status_interval, self.status_interval)
        while not self._done.wait(step):
            if self.system.tick.exit_requested and not stopping_sent:
                self._send("STOPPING=1")
                stopping_sent = True
            now = time.monotonic()
            tick = getattr(self.system, "tick", None)
            if tick is not None and hasattr(loop, "wakeup"):
                tick.wakeup_p99_us = loop.wakeup.percentile(99.0)  # for the diag records
                tick.compute_p99_us = loop.compute.percentile(99.0)
            if now >= next_status:
                s = self.status(self.system)
                self._send(
                    f"STATUS={s['state']}, {s['ticks']} ticks, faults: "
                    f"{', '.join(s['faults']) or 'none'}"
                )
                next_status = now + self.status_interval


def _no_status(system: Any) -> dict[str, Any]:
    return {"state": "running", "ticks": 0, "faults": []}
