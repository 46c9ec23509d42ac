"""What the flight recorder's writer is told (:class:`LogSpec`) and the names of a rotated
log's files: no MCAP here, so the loop's process, which builds the spec and sends it, does not
import the MCAP writer (only the writer process, hofto_hw.recording.flight_file, does)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

CHUNK_BYTES = 64 * 1024


@dataclass
class LogSpec:
    """What the writer process needs to know (picklable; sent once at start).

    ``joint_names`` (n,), ``observers`` the tau_ext rows' names in order, ``attachments``
    (name, media type, bytes) e.g. the config, parameters and thresholds files,
    ``metadata`` extra strings, ``event_kinds`` event code -> name (the safety fault classes).
    Rotation starts a new file after ``rotate_bytes`` or ``rotate_seconds`` (0 = never).
    ``flush_seconds`` bounds what a SIGKILL can lose (a chunk is closed at least that often).
    ``fail_after_bytes`` is a fault hook for tests: writes raise ENOSPC past that total.
    ``tool_frame`` (URDF frame of the tool): the wrench's frame is its aligned frame (tool
    origin, root axes) unless ``wrench_frame`` names one; ``tf_rate_hz`` bounds ``/tf``.
    ``live_view``: serve the topics live over Foxglove's WebSocket protocol (None: off).
    """

    path: Path
    joint_names: list[str]
    observers: list[str]
    attachments: list[tuple[str, str, bytes]] = field(default_factory=list)
    metadata: dict[str, str] = field(default_factory=dict)
    event_kinds: dict[int, str] = field(default_factory=dict)
    wrench_frame: str = ""
    tool_frame: str = ""
    tf_rate_hz: float = 50.0
    live_view: Any = None  # hofto_hw.recording.live.LiveSpec
    compression: str = "zstd"
    chunk_bytes: int = CHUNK_BYTES
    rotate_bytes: int = 0
    rotate_seconds: float = 0.0
    flush_seconds: float = 0.25
    retry_seconds: float = 2.0
    fail_after_bytes: int | None = None


def rotated_path(path: Path, index: int) -> Path:
    """File ``index`` of a rotated log: the path itself, then ``<stem>.1<suffix>``, ..."""
    return path if index == 0 else path.with_name(f"{path.stem}.{index}{path.suffix}")
