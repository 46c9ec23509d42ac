"""sd_notify for a Type=notify systemd service: READY, STATUS, STOPPING and a watchdog that is
petted only while the loop is alive.

A direct sender on the ``NOTIFY_SOCKET`` datagram socket (a path, or an abstract name written
with a leading '@'), a few lines instead of a dependency: ``sdnotify`` swallows errors and
systemd-python needs libsystemd headers to build. Without ``NOTIFY_SOCKET`` (not under
systemd) every call does nothing. A failed send raises :class:`NotifyError` naming the socket;
the watchdog thread, which cannot raise into the loop, counts failures instead.

    notifier = Notifier()
    dog = Watchdog(notifier, heartbeat=lambda: loop.ticks).start()   # no-op without systemd
    notifier.ready("running at 1000 Hz")
    ...
    notifier.stopping(); dog.stop()
"""

from __future__ import annotations

import os
import socket
import threading
from collections.abc import Callable, Mapping

from hofto_hw.errors import UserError


class NotifyError(UserError):
    """A notification could not be sent to systemd."""


class Notifier:
    """Sender of sd_notify messages to ``env['NOTIFY_SOCKET']`` (default: os.environ)."""

    def __init__(self, env: Mapping[str, str] | None = None) -> None:
        env = os.environ if env is None else env
        raw = env.get("NOTIFY_SOCKET", "")
        self.address = raw
        self._addr = "\0" + raw[1:] if raw.startswith("@") else raw
        self._sock: socket.socket | None = None
        usec = env.get("WATCHDOG_USEC", "")
        pid = env.get("WATCHDOG_PID", "")
        for_us = not pid or (pid.isdigit() and int(pid) == os.getpid())
        self.watchdog_usec = int(usec) if usec.isdigit() and int(usec) > 0 and for_us else 0

    @property
    def enabled(self) -> bool:
        """Running under systemd with a notify socket."""
        return bool(self._addr)

    @property
    def watchdog_interval(self) -> float | None:
        """How often to pet the watchdog [s] (half of WatchdogSec), None when it is off."""
        return self.watchdog_usec / 2e6 if self.enabled and self.watchdog_usec else None

    def send(self, message: str) -> None:
        """Send one notification (``KEY=value`` lines); raises NotifyError on failure."""
        if not self.enabled:
            return
        try:
            if self._sock is None:
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
            self._sock.sendto(message.encode(), self._addr)
        except OSError as exc:
            raise NotifyError(
                f"NOTIFY_SOCKET {self.address}: cannot notify systemd: {exc.strerror or exc}"
            ) from None

    def ready(self, status: str = "") -> None:
        """The service is up (systemd's start job completes)."""
        self.send("READY=1" + (f"\nSTATUS={status}" if status else ""))

    def status(self, text: str) -> None:
        """A one-line status shown by ``systemctl status``."""
        self.send(f"STATUS={text}")

    def stopping(self, status: str = "") -> None:
        """The service begins its shutdown."""
        self.send("STOPPING=1" + (f"\nSTATUS={status}" if status else ""))

    def watchdog(self) -> None:
        """Pet the watchdog once."""
        self.send("WATCHDOG=1")

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None


class Watchdog:
    """Pets systemd's watchdog every ``fraction`` of WatchdogSec while ``heartbeat()``
    (e.g. the loop's tick counter) has advanced since the previous check. A hung loop stops
    the petting, and systemd then kills and restarts the service (WatchdogSec).

    The thread only reads an int and sends a datagram; it never touches the loop.
    ``pets`` and ``missed`` count petted and skipped checks, ``errors`` failed sends.
    """

    def __init__(
        self, notifier: Notifier, heartbeat: Callable[[], int], fraction: float = 0.5
    ) -> None:
        self.notifier = notifier
        self.heartbeat = heartbeat
        self.fraction = fraction
        self.pets = 0
        self.missed = 0
        self.errors = 0
        self.last_error = ""
        self._last: int | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def interval(self) -> float | None:
        """Seconds between checks: ``fraction`` of WatchdogSec; None when the watchdog is off."""
        n = self.notifier
        return n.watchdog_usec * 1e-6 * self.fraction if n.enabled and n.watchdog_usec else None

    def check(self) -> bool:
        """One check: pet if the heartbeat advanced. Returns whether it petted."""
        beat = self.heartbeat()
        alive = self._last is None or beat != self._last
        self._last = beat
        if not alive:
            self.missed += 1
            return False
        try:
            self.notifier.watchdog()
        except NotifyError as exc:
            self.errors += 1
            self.last_error = str(exc)
            return False
        self.pets += 1
        return True

    def start(self) -> Watchdog:
        """Start the petting thread (nothing when the watchdog is off). Returns self."""
        interval = self.interval
        if interval is None or self._thread is not None:
            return self
        self._thread = threading.Thread(
            target=self._run, args=(interval,), name="hofto-hw-watchdog", daemon=True
        )
        self._thread.start()
        return self

    def _run(self, interval: float) -> None:
        while not self._stop.wait(interval):
            self.check()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
