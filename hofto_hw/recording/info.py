"""What an MCAP log holds: topics with their types and message counts, time span, size,
attachments and metadata — from the summary when the file is complete, else by streaming."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from hofto_hw.recording.recover import check_magic


@dataclass
class LogInfo:
    """``topics``: topic -> (type, count); ``start_ns``/``end_ns`` log times [ns];
    ``complete``: the file has its summary (False: truncated, run `log recover`)."""

    path: Path
    size: int
    complete: bool
    topics: dict[str, tuple[str, int]] = field(default_factory=dict)
    start_ns: int = 0
    end_ns: int = 0
    attachments: list[str] = field(default_factory=list)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)

    @property
    def duration(self) -> float:
        """[s] from the first to the last message."""
        return (self.end_ns - self.start_ns) * 1e-9

    def as_dict(self) -> dict[str, Any]:
        return {
            "file": str(self.path),
            "size": self.size,
            "complete": self.complete,
            "duration": self.duration,
            "start_ns": self.start_ns,
            "end_ns": self.end_ns,
            "topics": {t: {"type": ty, "messages": n} for t, (ty, n) in self.topics.items()},
            "attachments": self.attachments,
            "metadata": self.metadata,
        }


def log_info(path: Path) -> LogInfo:
    """Describe ``path``; raises UserError for a missing or non-MCAP file."""
    check_magic(path)
    info = LogInfo(path, path.stat().st_size, complete=False)
    try:
        with path.open("rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is None or summary.statistics is None:
                raise ValueError("no summary")
            stats = summary.statistics
            for cid, ch in summary.channels.items():
                schema = summary.schemas.get(ch.schema_id)
                count = stats.channel_message_counts.get(cid, 0)
                info.topics[ch.topic] = (schema.name if schema else "", count)
            info.start_ns, info.end_ns = stats.message_start_time, stats.message_end_time
            info.attachments = [a.name for a in reader.iter_attachments()]
            info.metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
            info.complete = True
            return info
    except Exception:
        pass
    _stream(path, info)
    return info


def _stream(path: Path, info: LogInfo) -> None:
    types: dict[int, str] = {}
    topics: dict[int, tuple[str, str]] = {}
    counts: Counter[int] = Counter()
    first = last = None
    with path.open("rb") as f:
        try:
            for rec in StreamReader(f, record_size_limit=1 << 30).records:
                if isinstance(rec, Message):
                    counts[rec.channel_id] += 1
                    first = rec.log_time if first is None else min(first, rec.log_time)
                    last = rec.log_time if last is None else max(last, rec.log_time)
                elif isinstance(rec, Schema):
                    types[rec.id] = rec.name
                elif isinstance(rec, Channel):
                    topics[rec.id] = (rec.topic, types.get(rec.schema_id, ""))
                elif isinstance(rec, Attachment):
                    info.attachments.append(rec.name)
                elif isinstance(rec, Metadata):
                    info.metadata[rec.name] = dict(rec.metadata)
        except Exception:
            pass
    for cid, (topic, ty) in topics.items():
        info.topics[topic] = (ty, counts.get(cid, 0))
    info.start_ns, info.end_ns = first or 0, last or 0
