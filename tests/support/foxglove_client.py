"""A plain client of Foxglove's WebSocket protocol, independent of the SDK that serves it:
JSON control messages (serverInfo, advertise, subscribe), binary message data frames (opcode 1,
u32 subscription id, u64 receive time [ns], payload). It offers the subprotocol names of the
protocol's versions (foxglove-sdk 0.30 speaks ``foxglove.sdk.v1``, earlier servers
``foxglove.websocket.v1``; the messages used here are the same in both)."""

from __future__ import annotations

import json
import struct
import time
from dataclasses import dataclass, field

from websockets.sync.client import connect

SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA = 0x01


@dataclass
class Received:
    """What a subscription brought: per topic the channel and the payloads."""

    channels: dict[str, dict] = field(default_factory=dict)
    messages: dict[str, list[bytes]] = field(default_factory=dict)
    server_info: dict = field(default_factory=dict)


def receive_topics(url: str, topics: list[str], count: dict[str, int], timeout: float) -> Received:
    """Connect, subscribe to ``topics`` once advertised, collect until each topic has
    ``count[topic]`` messages (or ``timeout`` [s] passes; the caller checks what came)."""
    out = Received()
    sub_topic: dict[int, str] = {}
    deadline = time.monotonic() + timeout
    with connect(url, subprotocols=SUBPROTOCOLS, open_timeout=timeout, max_size=None) as ws:
        while time.monotonic() < deadline:
            if sub_topic and all(len(out.messages.get(t, [])) >= count[t] for t in topics):
                break
            try:
                frame = ws.recv(timeout=max(0.01, deadline - time.monotonic()))
            except TimeoutError:
                break
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg.get("op") == "serverInfo":
                    out.server_info = msg
                elif msg.get("op") == "advertise":
                    subs = []
                    for ch in msg["channels"]:
                        out.channels[ch["topic"]] = ch
                        if ch["topic"] in topics and ch["topic"] not in sub_topic.values():
                            sid = len(sub_topic) + 1
                            sub_topic[sid] = ch["topic"]
                            subs.append({"id": sid, "channelId": ch["id"]})
                    if subs:
                        ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
                continue
            if frame[0] == MESSAGE_DATA:
                sid, _t = struct.unpack_from("<IQ", frame, 1)
                topic = sub_topic.get(sid)
                if topic is not None:
                    out.messages.setdefault(topic, []).append(bytes(frame[13:]))
    return out
