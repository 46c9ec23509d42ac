"""Salvage a truncated MCAP file (a writer killed mid-run) into a complete one.

mcap's indexed reader needs the summary at the end of the file, which a killed writer never
wrote. :class:`mcap.stream_reader.StreamReader` reads records front to back instead; every
complete record (schemas, channels, attachments, metadata, the messages of every complete
chunk) is copied into a new file, and reading stops at the first damaged or missing byte.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from mcap.records import Attachment, Channel, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from hofto_hw.config.loader import require_regular
from hofto_hw.errors import UserError
from hofto_hw.outputs import atomic_path

MAGIC = b"\x89MCAP0\r\n"


@dataclass
class Salvage:
    """What :func:`recover` copied: ``messages`` per topic, ``attachments``, ``metadata``
    records, ``complete`` (the input had its footer), ``stopped`` (why reading ended early,
    empty when the input was complete), ``end_ns`` the last message's log time [ns]."""

    messages: Counter[str] = field(default_factory=Counter)
    attachments: int = 0
    metadata: int = 0
    complete: bool = False
    stopped: str = ""
    end_ns: int = 0

    @property
    def total(self) -> int:
        return sum(self.messages.values())


def check_magic(path: Path) -> None:
    """Raise UserError unless ``path`` is a regular file that starts with the MCAP magic
    (a FIFO or a device is refused before it is opened)."""
    require_regular(path, "flight log (MCAP)", UserError)
    try:
        with path.open("rb") as f:
            head = f.read(len(MAGIC))
    except FileNotFoundError:
        raise UserError(f"{path}: file not found") from None
    except OSError as exc:
        raise UserError(f"{path}: cannot read: {exc.strerror}") from None
    if head != MAGIC:
        what = "empty" if not head else "not an MCAP file (no MCAP magic at the start)"
        raise UserError(f"{path}: {what}")


def default_output(path: Path) -> Path:
    """``<stem>.recovered.mcap`` beside the input."""
    return path.with_name(f"{path.stem}.recovered.mcap")


def recover(src: Path, dst: Path) -> Salvage:
    """Copy every complete record of ``src`` into a new complete MCAP file ``dst``.

    ``dst`` is written to a temporary name beside it and renamed at the end
    (:func:`hofto_hw.outputs.atomic_path`), so a failure leaves no half file and ``src`` is
    never touched (unless it is ``dst`` itself, named by the user). A read error of ``src``
    is a UserError naming ``src``; a write error one naming ``dst``.
    """
    check_magic(src)
    with atomic_path(dst, "the recovered log") as tmp:
        with src.open("rb") as f, tmp.open("wb") as g:
            w = Writer(g, compression=CompressionType.ZSTD)
            w.start(profile="ros2", library="hofto-hw log recover")
            copier = _Copier(w)
            try:
                for rec in StreamReader(f, record_size_limit=1 << 30).records:
                    copier.copy(rec)
            except Exception as exc:
                copier.out.stopped = type(exc).__name__ + (f": {exc}" if str(exc) else "")
            w.finish()
        if copier.out.total == 0 and not copier.out.complete:
            raise UserError(f"{src}: no complete message to recover ({copier.out.stopped})")
    return copier.out


class _Copier:
    """Re-registers schemas and channels under the new writer's ids and copies records."""

    def __init__(self, w: Writer) -> None:
        self.w = w
        self.out = Salvage()
        self.schemas: dict[int, int] = {}
        self.channels: dict[int, tuple[int, str]] = {}

    def copy(self, rec: object) -> None:
        w, out = self.w, self.out
        if isinstance(rec, Message):
            ch = self.channels.get(rec.channel_id)
            if ch is None:
                return  # its channel record was lost: nothing can decode it
            w.add_message(ch[0], rec.log_time, rec.data, rec.publish_time, rec.sequence)
            out.messages[ch[1]] += 1
            out.end_ns = max(out.end_ns, rec.log_time)
        elif isinstance(rec, Schema):
            self.schemas[rec.id] = w.register_schema(rec.name, rec.encoding, rec.data)
        elif isinstance(rec, Channel):
            sid = self.schemas.get(rec.schema_id, 0)
            new = w.register_channel(rec.topic, rec.message_encoding, sid, rec.metadata)
            self.channels[rec.id] = (new, rec.topic)
        elif isinstance(rec, Attachment):
            w.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data)
            out.attachments += 1
        elif isinstance(rec, Metadata):
            w.add_metadata(rec.name, dict(rec.metadata))
            out.metadata += 1
        elif isinstance(rec, Footer):
            out.complete = True
