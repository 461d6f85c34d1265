"""The recording's files on disk: MCAP files kept valid after every chunk, a free-space floor, a full disk.

:class:`RecordStream` takes the bytes of ``mcap``'s writer and writes them, a chunk at a time, to one file or
several, each followed by a valid end (a DataEnd record, a footer with no summary section, the magic) that the
next chunk overwrites: a run killed hard leaves a file ``mcap``'s own readers read up to its last chunk. A file
that cannot be written (a full disk, or below the runs' free-space floor) is set back to its last valid end and
given up on; the writer process (:mod:`beastbt.recording.writer`) tells the run. :func:`mcap_writer_class` is
``mcap``'s writer with a cheaper ``add_message``; :class:`NoFile` stands in for both when a run is only served
live.
"""

from __future__ import annotations

import errno
import itertools
import os
import shutil
import struct
from pathlib import Path
from typing import Any, Optional

COMMIT_MAX_BYTES = 8 << 20
"""The writer's bytes held for the next flush beyond this (bytes) are flushed at once (closing the chunk)."""

DISK_FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})
"""Write errors that mean the disk (or the user's quota, or the file system's largest file) is full."""


def _valid_end() -> bytes:
    """What ends the file between chunks: a DataEnd record, a Footer that says "no summary section", the magic.

    MCAP's readers then stop cleanly: the linear reader at the footer, the
    seeking reader (``mcap.reader.make_reader``) finds a footer at the end
    and, with no summary to seek by, reads the records from the start.
    """
    from mcap.data_stream import RecordBuilder
    from mcap.records import DataEnd, Footer
    from mcap.writer import MCAP0_MAGIC
    builder = RecordBuilder()
    DataEnd(data_section_crc=0).write(builder)  # 0: no CRC of the data section (the writer keeps none)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
    return builder.end() + MCAP0_MAGIC


FLOOR_RESERVE_BYTES = 1_000_000
"""Room the recording leaves above the free-space floor (bytes) for what the run writes after it: the summary,
the event log, the recording's own end and the prune log, so that the disk stays above the floor."""


class FreeSpaceFloor(OSError):
    """A commit that would take the disk below the runs' free-space floor (profile ``runs: min_free_mb``): the
    recording stops there as if the disk were full, leaving the floor free for the system and the next runs."""

    def __init__(self, floor_bytes: int, free_bytes: int) -> None:
        super().__init__(errno.ENOSPC, "free-space floor reached")
        self.floor_bytes = floor_bytes
        self.free_bytes = free_bytes


def describe_write_error(path: Path, exc: OSError) -> str:
    """Why writing ``path`` failed, for a person: a full disk with the space left (MB), or the OS's words."""
    if isinstance(exc, FreeSpaceFloor):
        return (f"the disk at {path} is down to its free-space floor ({exc.free_bytes / 1e6:.1f} MB free, "
                f"runs: min_free_mb {exc.floor_bytes / 1e6:g})")
    if exc.errno in DISK_FULL_ERRNOS:
        try:
            free_mb = shutil.disk_usage(path.parent).free / 1e6
            return f"disk full at {path} ({free_mb:.1f} MB free)"
        except OSError:
            return f"disk full at {path}"
    return f"cannot write {path} ({exc.strerror or exc!r})"


class _McapFile:
    """One file the recording goes to, kept a valid MCAP file after every commit (see :class:`RecordStream`)."""

    def __init__(self, path: Path, floor_bytes: int = 0) -> None:
        self.path = path
        self.floor_bytes = floor_bytes
        """Free bytes a commit must leave on the file's disk (0: none): below it the file is given up on."""
        path.parent.mkdir(parents=True, exist_ok=True)
        self.fd: Optional[int] = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self.end = 0
        """Bytes of records written and kept (before the valid end written after them)."""
        self.tail = b""
        """What follows them in the file now (the valid end, or nothing)."""

    def commit(self, data: bytes) -> None:
        """Write ``data`` (whole records, then an end) at :attr:`end` in one call; raises OSError when it fails,
        :class:`FreeSpaceFloor` when it would leave less than :attr:`floor_bytes` free."""
        if self.floor_bytes > 0 and self.fd is not None:
            st = os.fstatvfs(self.fd)  # once per chunk (about a second), a few microseconds
            free = st.f_bavail * st.f_frsize
            if free - max(0, self.end + len(data) - self._size()) < self.floor_bytes + FLOOR_RESERVE_BYTES:
                raise FreeSpaceFloor(self.floor_bytes, free)
        self._write_at(data, self.end)

    def _size(self) -> int:
        return os.fstat(self.fd).st_size if self.fd is not None else 0

    def rollback(self) -> None:
        """After a failed commit: cut what it wrote and put the valid end back (it fits where it was)."""
        try:
            os.ftruncate(self.fd, self.end)
            self._write_at(self.tail, self.end)
        except OSError:
            pass  # the file stays as it is: ``beastbt recover`` rebuilds what it can

    def _write_at(self, data: bytes, offset: int) -> None:
        view = memoryview(data)
        while view:
            # One pwrite normally; a short write (a disk filling up) goes round again and then raises.
            n = os.pwrite(self.fd, view, offset)
            view = view[n:]
            offset += n

    def close(self, truncate_at: Optional[int] = None) -> None:
        """Close the file (cut to ``truncate_at`` bytes first when given)."""
        if self.fd is None:
            return
        try:
            if truncate_at is not None:
                os.ftruncate(self.fd, truncate_at)
        except OSError:
            pass
        finally:
            os.close(self.fd)
            self.fd = None


class RecordStream:
    """The output of the ``mcap`` writer: the same bytes to several files, each a valid MCAP file at every flush.

    The writer's bytes wait here until :meth:`flush` (the writer's
    ``flush()`` at every closed chunk). A flush writes them with the valid end
    (:func:`_valid_end`) after them, in one write per file, where the last
    valid end was: a run killed hard (a power cut, the OOM killer) leaves a
    file that MCAP's own readers read to its last flushed chunk.
    ``close()`` writes the writer's real end (summary section, footer).

    A file that cannot be written (a full disk) is set back to its last
    valid state and written no more; the others go on. Its failure is in
    :attr:`failures` until taken (:meth:`take_failures`). ``tell()`` is the
    offset the ``mcap`` writer indexes by: the same in every file.
    """

    def __init__(self, paths: list[Path], floor_bytes: int = 0) -> None:
        self._files = [_McapFile(p, floor_bytes) for p in paths]
        self._buffer = bytearray()
        self._end = 0
        self._tail = _valid_end()
        self.failures: list[tuple[Path, OSError]] = []
        """Files that failed and were given up on, with their error, not yet taken."""

    @property
    def writing(self) -> bool:
        """Some file still takes the recording."""
        return bool(self._files)

    @property
    def paths(self) -> list[Path]:
        """The files still written."""
        return [f.path for f in self._files]

    @property
    def pending_bytes(self) -> int:
        """Bytes written by the ``mcap`` writer and not yet flushed to the files."""
        return len(self._buffer)

    def write(self, data: bytes) -> int:
        """Take bytes from the ``mcap`` writer (whole records, or the magic); kept until :meth:`flush`."""
        if self._files:
            self._buffer += data
        return len(data)

    def tell(self) -> int:
        """The offset of the next byte written, as the ``mcap`` writer indexes records."""
        return self._end + len(self._buffer)

    def flush(self) -> None:
        """Write what was taken, then the valid end, to every file still written."""
        self._commit(self._tail)

    def take_failures(self) -> list[tuple[Path, OSError]]:
        """The files given up on since the last call, with their error."""
        out, self.failures = self.failures, []
        return out

    def close(self) -> None:
        """Write the rest (the ``mcap`` writer's summary and footer: no valid end of ours after them); close."""
        self._commit(b"")
        for f in self._files:
            f.close(truncate_at=f.end)
        self._files = []

    def _commit(self, tail: bytes) -> None:
        if not self._files:
            self._buffer = bytearray()
            return
        if not self._buffer and all(f.tail == tail for f in self._files):
            return  # nothing new: the files already end validly
        data = bytes(self._buffer) + tail
        kept = []
        for f in self._files:
            try:
                f.commit(data)
            except OSError as exc:
                f.rollback()
                f.close()
                self.failures.append((f.path, exc))
                continue
            kept.append(f)
        self._files = kept
        self._end += len(self._buffer)
        for f in kept:
            f.end, f.tail = self._end, tail
        self._buffer = bytearray()


_MESSAGE_RECORD = struct.Struct("<BQHIQQ")
"""An MCAP Message record's opcode (0x05), length (22 + data) and fields before the data, as ``mcap`` writes them."""

_MCAP_WRITER_PARTS = ("_Writer__statistics", "_Writer__chunk_builder", "_Writer__chunk_size", "_Writer__finalize_chunk")

_fast_writer: Optional[type] = None


def mcap_writer_class() -> type:
    """``mcap.writer.Writer`` with a cheaper ``add_message`` for chunked files (built at the first call).

    ``mcap``'s own ``add_message`` costs about 3.3 us a message here (a
    Message object, then six writes and two seeks into the chunk's buffer),
    a third of the writer process's time. This one updates the same
    statistics, chunk bounds and message indexes and writes the same record
    bytes in two writes, and each chunk's message indexes in one pack a
    channel (``tests/test_recording_writer.py`` compares whole
    files byte for byte with ``mcap``'s). It uses the writer's private
    parts; when they are not there (another ``mcap`` version) or the file is
    not chunked, ``mcap``'s own ``add_message`` runs.
    """
    global _fast_writer
    if _fast_writer is not None:
        return _fast_writer
    from mcap.records import MessageIndex
    from mcap.writer import Writer

    class FastMessageIndex(MessageIndex):  # type: ignore[misc, valid-type]
        """A chunk's index of one channel's messages, written in one pack (``mcap``'s writes two per message)."""

        def write(self, stream: Any) -> None:
            """Write the MessageIndex record (the same bytes as ``mcap``'s)."""
            records = self.records
            stream.start_record(0x07)  # Opcode.MESSAGE_INDEX
            stream.write2(self.channel_id)
            stream.write4(len(records) * 16)
            stream.write(struct.pack(f"<{2 * len(records)}Q", *itertools.chain.from_iterable(records)))
            stream.finish_record()

    class FastWriter(Writer):  # type: ignore[misc, valid-type]
        """``mcap.writer.Writer`` whose chunked ``add_message`` writes the record in one go (same bytes)."""

        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            chunks = getattr(self, "_Writer__chunk_builder", None)
            self._fast = (all(hasattr(self, name) for name in _MCAP_WRITER_PARTS) and chunks is not None
                          and all(hasattr(chunks, a) for a in ("message_indices", "num_messages", "record_writer",
                                                                 "message_start_time", "message_end_time"))
                          and hasattr(chunks.record_writer, "_buffer"))

        def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int,
                        sequence: int = 0) -> None:
            """Add a message to the current chunk (as ``mcap``'s ``add_message`` does, in fewer steps)."""
            if not self._fast:
                return super().add_message(channel_id=channel_id, log_time=log_time, data=data,
                                           publish_time=publish_time, sequence=sequence)
            stats = self._Writer__statistics
            if stats.message_count == 0 or log_time < stats.message_start_time:
                stats.message_start_time = log_time
            if log_time > stats.message_end_time:
                stats.message_end_time = log_time
            stats.channel_message_counts[channel_id] += 1
            stats.message_count += 1
            chunk = self._Writer__chunk_builder
            if chunk.num_messages == 0 or log_time < chunk.message_start_time:
                chunk.message_start_time = log_time
            if log_time > chunk.message_end_time:
                chunk.message_end_time = log_time
            buffer = chunk.record_writer._buffer  # a new one after each chunk
            index = chunk.message_indices.get(channel_id)
            if not index:
                index = chunk.message_indices[channel_id] = FastMessageIndex(channel_id=channel_id, records=[])
            index.records.append((log_time, buffer.tell()))
            chunk.num_messages += 1
            buffer.write(_MESSAGE_RECORD.pack(0x05, 22 + len(data), channel_id, sequence, log_time, publish_time))
            buffer.write(data)
            if buffer.tell() > self._Writer__chunk_size:
                self._Writer__finalize_chunk()
            return None

    _fast_writer = FastWriter
    return FastWriter



class NoFile:
    """Stands in for the MCAP writer and its file when the run is only served live (``--foxglove --no-record``)."""

    def __init__(self) -> None:
        self._ids = 0

    def _next_id(self, **_: Any) -> int:
        self._ids += 1
        return self._ids

    register_schema = register_channel = _next_id

    def start(self, **_: Any) -> None:
        """Nothing to write."""

    def add_message(self, *_: Any, **__: Any) -> None:
        """Nothing to write: the message went live only."""

    def add_metadata(self, *_: Any) -> None:
        """Nothing to write."""

    def add_attachment(self, **_: Any) -> None:
        """Nothing to write."""

    def flush(self) -> None:
        """Nothing to flush."""

    def finish(self) -> None:
        """Nothing to close."""

    def close(self) -> None:
        """Nothing to close."""

    writing = True
    """Served live: every message counts as written."""
    pending_bytes = 0

    def take_failures(self) -> list:
        """Nothing written, nothing failed."""
        return []


__all__ = ["COMMIT_MAX_BYTES", "DISK_FULL_ERRNOS", "FLOOR_RESERVE_BYTES", "FreeSpaceFloor", "NoFile",
           "RecordStream", "describe_write_error", "mcap_writer_class"]
