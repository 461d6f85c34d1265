"""Reading a run recording back, including one cut short by a hard kill.

:func:`read_recording` reads an MCAP file linearly with the ``mcap``
library's :class:`~mcap.stream_reader.StreamReader` (it needs no summary
section or footer), decompresses each chunk and checks its CRC, and stops at
the first record that is cut short: a run killed mid-write still yields every
message of its complete chunks. ``Recording.complete`` says whether the file
ended properly (with its summary section: a file the writer left after a
chunk ends with a footer too, but without one).

What a record claims is checked before anything is allocated for it (issue
38: a crafted chunk claiming 1 TB made ``beastbt report`` try to allocate
it): no read may claim more bytes than the file has left, a chunk may claim
at most :data:`MAX_CHUNK_BYTES` uncompressed, and it is decompressed within
what it claims, whatever its compressed frame's own header says. Reading
stops there, as at a record cut short, and ``stopped_because`` names the
file and the record's byte offset.
"""

from __future__ import annotations

import dataclasses
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Optional, Union

from mcap.exceptions import EndOfFile, InvalidMagic
from mcap.records import Attachment, Channel, Chunk, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

from beastbt.recording.schemas import OFFSET_KEY


@dataclass
class Recording:
    """A decoded run recording.

    ``messages``: topic -> list of ``(clock_ns, message dict)`` in file
    order, the run's clock in nanoseconds (the file's log time, Unix epoch
    nanoseconds, minus :attr:`log_time_offset_ns`); ``schemas``: topic -> (schema name, JSON Schema dict);
    ``metadata``: name -> dict of strings; ``attachments``: name -> bytes;
    ``complete``: the file ended with its footer; ``stopped_because``: why
    reading stopped early (a truncated record), or None.
    """

    path: Path
    messages: dict[str, list[tuple[int, dict]]] = field(default_factory=dict)
    schemas: dict[str, tuple[str, dict]] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: dict[str, bytes] = field(default_factory=dict)
    complete: bool = False
    stopped_because: Optional[str] = None
    order: list[tuple[str, int, dict]] = field(default_factory=list)
    """Every message in file order as ``(topic, log_time_ns, message)`` (filled when asked for)."""
    counts: dict[str, int] = field(default_factory=dict)
    """Messages per topic in the file (read whole), decoded or not."""
    log_time_offset_ns: int = 0
    """What was taken off every log time: the file logs Unix epoch nanoseconds, ``messages`` and ``order``
    hold the run's clock (ns, 0 at the start in the simulator); 0 for files that logged clock time."""

    @property
    def info(self) -> dict[str, str]:
        """The ``beastbt.run`` metadata (mission, seed, robot, world...), empty if absent."""
        return self.metadata.get("beastbt.run", {})

    @property
    def summary(self) -> Optional[dict]:
        """The run summary stored at the end of the run, or None (run cut short, or recorded without one)."""
        raw = self.metadata.get("beastbt.summary", {}).get("json")
        return json.loads(raw) if raw else None

    def topic(self, name: str) -> list[dict]:
        """The messages of one topic (empty when there are none)."""
        return [m for _, m in self.messages.get(name, [])]

    def times_s(self, name: str) -> list[float]:
        """The clock times of one topic's messages (their log times less the offset), seconds."""
        return [t * 1e-9 for t, _ in self.messages.get(name, [])]

    def text(self, attachment: str) -> Optional[str]:
        """An attachment as text (``mission.yaml``...), or None."""
        data = self.attachments.get(attachment)
        return data.decode("utf-8") if data is not None else None

    def message_count(self) -> int:
        """How many messages the file holds (as far as it could be read), decoded or not."""
        return sum(self.counts.values())


MAX_CHUNK_BYTES = 256 << 20
"""The most a chunk may claim uncompressed, in bytes (256 MiB): the recorder closes a chunk at
``chunk_max_bytes`` (a few MB) after its last message, and one camera frame is well under a megabyte."""


class RecordClaim(Exception):
    """A record (or a chunk's content) that claims more than there can be: ``offset`` is the record's first byte
    in the file; the message says what it claims and what there is."""

    def __init__(self, offset: int, message: str) -> None:
        super().__init__(message)
        self.offset = offset


class BoundedFile:
    """The recording file as ``mcap``'s StreamReader reads it: a read that asks for more than the file has left
    raises :class:`RecordClaim` instead of allocating what a record's length field says."""

    def __init__(self, f: Any) -> None:
        self._f = f
        self._size = os.fstat(f.fileno()).st_size
        self.record_start = 0
        """Where the record being read starts (set by the reader before each record)."""

    def tell(self) -> int:
        """The position in the file (bytes)."""
        return self._f.tell()

    def read(self, n: int = -1) -> bytes:
        """Up to ``n`` bytes; RecordClaim when ``n`` is beyond the end of the file."""
        left = self._size - self._f.tell()
        if n is not None and n > left:
            raise RecordClaim(self.record_start, f"the record at byte {self.record_start:,} claims {n:,} bytes, "
                                                 f"but the file has {left:,} left (cut short, or damaged)")
        return self._f.read(n)


def _decompressed(chunk: Chunk, offset: int) -> bytes:
    """A chunk's records, decompressed within what it claims (:data:`MAX_CHUNK_BYTES` at most): a compressed frame
    whose header claims more, or that holds more, is a RecordClaim at ``offset``."""
    claim = chunk.uncompressed_size
    if claim > MAX_CHUNK_BYTES:
        raise RecordClaim(offset, f"the chunk at byte {offset:,} claims {claim:,} bytes uncompressed: a chunk holds "
                                  f"at most {MAX_CHUNK_BYTES:,}")
    if chunk.compression == "zstd":
        import zstandard
        framed = zstandard.frame_content_size(chunk.data)  # -1 when the frame does not say
        if framed > claim:  # zstandard would allocate what the frame says, whatever the limit given
            raise RecordClaim(offset, f"the chunk at byte {offset:,} holds a frame of {framed:,} bytes, more than "
                                      f"the {claim:,} it claims")
        data = zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=claim)
    elif chunk.compression == "lz4":
        import lz4.frame
        decompressor = lz4.frame.LZ4FrameDecompressor()
        data = decompressor.decompress(chunk.data, max_length=claim)
        if not decompressor.eof:
            raise RecordClaim(offset, f"the chunk at byte {offset:,} holds more than the {claim:,} bytes it claims")
    else:
        data = chunk.data
    if len(data) > claim:
        raise RecordClaim(offset, f"the chunk at byte {offset:,} holds {len(data):,} bytes, more than the {claim:,} "
                                  f"it claims")
    return data


def chunk_records(chunk: Chunk, offset: int, validate_crc: bool) -> list:
    """The records of a chunk that starts at byte ``offset``, decompressed within what it claims
    (:func:`_decompressed`; RecordClaim beyond it), its CRC checked with ``validate_crc``."""
    plain = dataclasses.replace(chunk, compression="", data=_decompressed(chunk, offset))
    return breakup_chunk(plain, validate_crc=validate_crc)


CUT_AT_CHUNK = "the recording ends at its last complete chunk (the run was cut short)"
"""``Recording.stopped_because`` of a file that ends with the valid end written after each chunk."""


def read_recording(path: Union[str, Path], topics: Optional[Iterable[str]] = None, keep_order: bool = False,
                   validate_crcs: bool = True, skip_topics: Iterable[str] = ()) -> Recording:
    """Read and decode a recording; ``topics`` limits which messages are decoded, ``skip_topics`` leaves some out.

    Long runs hold many messages: decoding only what is needed keeps the
    memory of ``beastbt report`` and ``replay`` down.

    Never raises for a file that merely ends early; raises ``mcap``'s
    ``InvalidMagic`` for a file that is not MCAP at all.
    """
    path = Path(path)
    wanted = set(topics) if topics is not None else None
    skipped = set(skip_topics)
    out = Recording(path)
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    loads = json.loads

    def take(records: Iterable[Any]) -> None:
        for rec in records:
            if isinstance(rec, Message):
                ch = channels.get(rec.channel_id)
                if ch is None:
                    continue
                out.counts[ch.topic] = out.counts.get(ch.topic, 0) + 1
                if (wanted is not None and ch.topic not in wanted) or ch.topic in skipped:
                    continue
                msg = loads(rec.data)
                t = rec.log_time - out.log_time_offset_ns
                out.messages.setdefault(ch.topic, []).append((t, msg))
                if keep_order:
                    out.order.append((ch.topic, t, msg))
            elif isinstance(rec, Channel):
                channels[rec.id] = rec
                schema = schemas.get(rec.schema_id)
                if schema is not None and rec.topic not in out.schemas:
                    out.schemas[rec.topic] = (schema.name, json.loads(schema.data) if schema.data else {})
            elif isinstance(rec, Schema):
                schemas[rec.id] = rec

    with open(path, "rb") as raw:
        f = BoundedFile(raw)
        # No record_size_limit (4 GiB by default): BoundedFile holds every read to what the file has left.
        reader = StreamReader(f, emit_chunks=True, validate_crcs=False,  # type: ignore[arg-type]  # has read()
                              record_size_limit=None)
        records = reader.records
        while True:
            f.record_start = f.tell()
            try:
                rec = next(records)
            except StopIteration:
                break
            except InvalidMagic:
                raise  # not an MCAP file at all
            except RecordClaim as exc:
                out.stopped_because = f"{path.name}: {exc}"
                break
            except EndOfFile:
                out.stopped_because = "the file ends before its footer (the run was cut short)"
                break
            except Exception as exc:  # a record cut short parses as garbage: stop at the last good one
                out.stopped_because = f"unreadable record ({type(exc).__name__}: {exc})"
                break
            if isinstance(rec, Chunk):
                try:
                    inner = chunk_records(rec, f.record_start, validate_crcs)
                except RecordClaim as exc:
                    out.stopped_because = f"{path.name}: {exc}"
                    break
                except Exception as exc:
                    out.stopped_because = f"incomplete chunk ({type(exc).__name__}: {exc})"
                    break
                take(inner)
            elif isinstance(rec, (Schema, Channel, Message)):
                take([rec])
            elif isinstance(rec, Metadata):
                out.metadata[rec.name] = dict(rec.metadata)
                if rec.name == "beastbt.run":
                    # Written right after the header, before any message: every log time read after it is
                    # turned back into clock time, which replay and the report work in.
                    out.log_time_offset_ns = int(rec.metadata.get(OFFSET_KEY, 0) or 0)
            elif isinstance(rec, Attachment):
                out.attachments[rec.name] = bytes(rec.data)
            elif isinstance(rec, Footer):
                # A run's recording ends with its summary section; a footer without one is the valid end the
                # writer keeps after each chunk while it records: the run was cut there.
                out.complete = rec.summary_start != 0
                if not out.complete:
                    out.stopped_because = CUT_AT_CHUNK
                break
    return out


def find_recording(run: Union[str, Path]) -> Path:
    """The ``.mcap`` of a run: the file itself, or ``run.mcap`` (or the only ``.mcap``) in a run folder."""
    p = Path(run)
    if p.is_dir():
        candidate = p / "run.mcap"
        if candidate.exists():
            return candidate
        found = sorted(p.glob("*.mcap"))
        if len(found) == 1:
            return found[0]
        raise FileNotFoundError(f"{p}: no run.mcap in this folder")
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such run folder or file")
    return p


__all__ = ["Recording", "read_recording", "find_recording", "RecordClaim", "MAX_CHUNK_BYTES", "BoundedFile",
           "chunk_records"]
