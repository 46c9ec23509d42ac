"""Live view: the writer process serves the topics it logs over Foxglove's WebSocket protocol
(subprotocol ``foxglove.sdk.v1`` with foxglove-sdk 0.30, the successor of
``foxglove.websocket.v1``), so Foxglove (or any client of the protocol) shows a running arm.

Why here and why foxglove-sdk: the writer already has every record as encoded ROS 2 messages,
and it is the process that may be slow (never the loop's process: that one only copies records
into shared memory). foxglove-sdk is Foxglove's own implementation of the protocol (a Rust
server on its own threads, Python bindings, no dependencies); a channel's ``log`` hands the bytes
to per-client queues of bounded size and returns, dropping the oldest data for a client that
cannot keep up, so a slow or stuck viewer never slows the writer.

Rates: the log keeps every tick; the live side publishes at most ``rate_hz`` messages per topic
(the newest of each writer batch once the period has passed). Safety events are published all.
The URDF (``/robot_description``) and the fixed joints (``/tf_static``) are latched: logged once,
and again whenever a client subscribes to them.

Off by default; ``run.live_view: {host: 127.0.0.1, port: 8765}`` turns it on (localhost unless
configured: the protocol has no authentication). A port that cannot be bound is said on stderr
and the log goes on without the live view.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from typing import Any

from hofto_hw.recording import schemas as s

#: topics re-published to each new subscriber (latched)
LATCHED = (s.ROBOT_DESCRIPTION_TOPIC, s.TF_STATIC_TOPIC)
#: topics published in full (rare, every one matters)
UNTHROTTLED = (s.SAFETY_TOPIC,)


@dataclass(frozen=True)
class LiveSpec:
    """Where to serve (``host``, ``port``; port 0 = a free one, said on stderr) and the bound
    on messages per topic per second [Hz] for the live side."""

    host: str = "127.0.0.1"
    port: int = 8765
    rate_hz: float = 30.0


class LiveView:
    """The WebSocket server and one channel per logged topic (created as FlightFile declares
    them). :meth:`offer` is called with each batch's newest message, :meth:`poll` once per
    writer step, :meth:`close` at the end."""

    def __init__(self, spec: LiveSpec, name: str = "hofto-hw") -> None:
        import foxglove
        from foxglove.websocket import ServerListener

        self.spec = spec
        self.period = 1.0 / spec.rate_hz
        self._foxglove = foxglove
        self._channels: dict[str, Any] = {}
        self._last: dict[str, float] = {}
        self._latched: dict[str, tuple[bytes, int]] = {}
        self._resend: set[str] = set()
        self.published = 0
        resend = self._resend

        class _Listener(ServerListener):
            def on_subscribe(self, client: Any, channel: Any) -> None:
                if channel.topic in LATCHED:  # the server's thread: only mark it
                    resend.add(channel.topic)

        self.server = None
        try:
            self.server = foxglove.start_server(
                name=name,
                host=spec.host,
                port=spec.port,
                server_listener=_Listener(),
                supported_encodings=["cdr"],
            )
        except Exception as exc:  # the log matters more than the view: say it, go on
            print(
                f"hofto-hw flight recorder: live view: cannot serve on {spec.host}:{spec.port}:"
                f" {exc}",
                file=sys.stderr,
                flush=True,
            )
            return
        print(
            f"hofto-hw flight recorder: live view on ws://{spec.host}:{self.server.port} "
            "(Foxglove: open connection, Foxglove WebSocket)",
            file=sys.stderr,
            flush=True,
        )

    @property
    def port(self) -> int | None:
        return None if self.server is None else int(self.server.port)

    def declare(self, topic: str, type_name: str, msgdef: str) -> None:
        """A topic of the log (ROS 2 message ``type_name``, CDR, definition ``msgdef``)."""
        if self.server is None or topic in self._channels:
            return
        schema = self._foxglove.Schema(name=type_name, encoding="ros2msg", data=msgdef.encode())
        self._channels[topic] = self._foxglove.Channel(topic, message_encoding="cdr", schema=schema)
        self._last[topic] = -1e9

    def offer(self, topic: str, data: bytes, ns: int) -> None:
        """The newest message of ``topic`` (log time ``ns``): published if the topic's period
        has passed (always for latched topics and safety events)."""
        ch = self._channels.get(topic)
        if ch is None:
            return
        if topic in LATCHED:
            self._latched[topic] = (bytes(data), ns)
        elif topic not in UNTHROTTLED:
            now = time.monotonic()
            if now - self._last[topic] < self.period:
                return
            self._last[topic] = now
        ch.log(bytes(data), log_time=ns)
        self.published += 1

    def poll(self) -> None:
        """Re-publish latched topics to clients that subscribed since the last call."""
        while self._resend:
            topic = self._resend.pop()
            if topic in self._latched:
                data, ns = self._latched[topic]
                self._channels[topic].log(data, log_time=ns)
                self.published += 1

    def close(self) -> None:
        if self.server is not None:
            self.server.stop()
            self.server = None
