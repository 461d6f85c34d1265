"""``beastbt recover RUN``: a recording cut short (a power cut, a full disk) rewritten as a whole MCAP file.

The writer leaves a valid MCAP file after every chunk, which ``mcap``'s own
readers read to its last chunk; but a write torn by the cut, or a file
system that lost its last blocks, can leave anything at the end. Recovery
reads the file linearly, record by record, checking each chunk's CRC, and
keeps the longest prefix of valid records: every schema, channel, message,
metadata record and attachment before the first bad byte. It writes them
again with the ``mcap`` library's writer, with the summary section (chunk
indexes, statistics) that seeking readers and Foxglove use, and metadata
``beastbt.recovered`` saying from what.

The recovered file takes the place of the cut one, which is kept beside it
as ``<name>.cut`` (so ``beastbt report``, ``replay``, ``runs`` and Foxglove
all see the recovered run); a complete file is left alone. In a run folder
whose ``summary.json`` is missing or empty, the summary is rebuilt: the one
stored in the recording when there is one, else what the recording shows
(status ``stopped``, ticks, time, distance, the events, and ``recovered``),
with ``events.log`` from its events.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional, Union

from mcap.exceptions import InvalidMagic
from mcap.records import Attachment, Channel, Chunk, DataEnd, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from beastbt.recording.config import compression_type
from beastbt.recording.reader import BoundedFile, RecordClaim, chunk_records, find_recording, read_recording

BACKUP_SUFFIX = ".cut"
"""The cut file is kept as ``<name>.mcap.cut``: not an ``.mcap``, so no tool takes it for the run's recording."""

RECOVERED_METADATA = "beastbt.recovered"
"""Metadata of a recovered file: ``from`` (the cut file's name), ``bytes_kept`` of ``bytes``, ``reason``."""


@dataclass
class Recovery:
    """What :func:`recover` did: the files, what was kept, and the sentences to show."""

    recording: Path
    complete: bool = False
    """The file was whole already: nothing rewritten."""
    backup: Optional[Path] = None
    messages: int = 0
    bytes_kept: int = 0
    bytes_total: int = 0
    reason: str = ""
    """Why reading stopped (the first bad record), or the end of the file."""
    summary: Optional[Path] = None
    """The summary.json written (rebuilt), or None."""
    notes: list[str] = field(default_factory=list)


class RecoveryError(Exception):
    """The run cannot be recovered (not an MCAP file, a backup in the way, a write failed); says why."""


def _valid_records(path: Path) -> Any:
    """Yield ``(record, end offset)`` for each record of the longest valid prefix of ``path``, chunks checked;
    then one last ``(None, reason)``."""
    with open(path, "rb") as raw:
        f = BoundedFile(raw)  # no read beyond the file's end, whatever a record claims (issue 38)
        reader = StreamReader(f, emit_chunks=True, validate_crcs=False,  # type: ignore[arg-type]  # has read()
                              record_size_limit=os.path.getsize(path))
        records = reader.records
        while True:
            f.record_start = f.tell()
            try:
                rec = next(records)
            except StopIteration:
                yield None, "the file ends after its footer"
                return
            except InvalidMagic as exc:
                raise RecoveryError(f"{path}: not an MCAP file ({exc})") from None
            except RecordClaim as exc:
                yield None, str(exc)
                return
            except Exception as exc:  # noqa: BLE001 - a cut record parses as anything: stop before it
                yield None, f"record cut short at byte {f.tell()} ({type(exc).__name__})"
                return
            if isinstance(rec, Chunk):
                try:
                    inner = chunk_records(rec, f.record_start, validate_crc=True)
                except RecordClaim as exc:
                    yield None, str(exc)
                    return
                except Exception as exc:  # noqa: BLE001 - a chunk cut short fails its CRC or its decompression
                    yield None, f"chunk cut short ({type(exc).__name__})"
                    return
                yield inner, f.tell()
            else:
                yield rec, f.tell()
            if isinstance(rec, (DataEnd, Footer)):
                yield None, "the file ends validly after its last complete chunk"
                return


def is_complete(path: Path) -> bool:
    """The file ends with its footer after a summary section (a finished recording)."""
    return read_recording(path, topics=[]).complete


def recover_file(path: Path, out: Path, kept_as: Optional[str] = None) -> tuple[int, int, str]:
    """Write the longest valid prefix of ``path`` to ``out`` as a whole MCAP file; (messages, bytes kept, why
    reading stopped). ``kept_as``: the name the cut file will go by (metadata ``beastbt.recovered``)."""
    from mcap.writer import Writer
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    messages = 0
    kept = 0
    reason = ""
    header: Optional[Header] = None
    with open(out, "wb") as f:
        writer: Optional[Writer] = None

        def started() -> Writer:
            nonlocal writer
            if writer is None:
                writer = Writer(f, compression=compression_type("auto"))
                writer.start(profile=header.profile if header else "",
                             library=header.library if header else "beastbt recover")
            return writer

        def take(rec: Any) -> None:
            nonlocal messages
            if isinstance(rec, Schema):
                if rec.id not in schema_ids:
                    schema_ids[rec.id] = started().register_schema(rec.name, rec.encoding, rec.data)
            elif isinstance(rec, Channel):
                if rec.id not in channel_ids:
                    channel_ids[rec.id] = started().register_channel(rec.topic, rec.message_encoding,
                                                                     schema_ids.get(rec.schema_id, 0),
                                                                     dict(rec.metadata))
            elif isinstance(rec, Message):
                cid = channel_ids.get(rec.channel_id)
                if cid is not None:
                    started().add_message(cid, rec.log_time, rec.data, rec.publish_time, rec.sequence)
                    messages += 1

        for rec, end in _valid_records(path):
            if rec is None:
                reason = str(end)
                break
            kept = int(end)
            if isinstance(rec, Header):
                header = rec
            elif isinstance(rec, list):  # a chunk's records
                for inner in rec:
                    take(inner)
            elif isinstance(rec, Metadata):
                started().add_metadata(rec.name, dict(rec.metadata))
            elif isinstance(rec, Attachment):
                started().add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data)
            else:
                take(rec)
        w = started()
        w.add_metadata(RECOVERED_METADATA, {"from": kept_as or path.name, "bytes_kept": str(kept),
                                            "bytes": str(path.stat().st_size), "reason": reason,
                                            "messages": str(messages)})
        w.finish()
        f.flush()
        os.fsync(f.fileno())
    return messages, kept, reason


def recover(run: Union[str, Path]) -> Recovery:
    """Recover the recording of ``run`` (a run folder or an ``.mcap`` file) in place, and a missing summary."""
    try:
        path = find_recording(run)
    except FileNotFoundError as exc:
        raise RecoveryError(str(exc)) from None
    result = Recovery(path, bytes_total=path.stat().st_size)
    try:
        result.complete = is_complete(path)
    except InvalidMagic as exc:
        raise RecoveryError(f"{path}: not an MCAP file ({exc})") from None
    if not result.complete:
        backup = path.with_name(path.name + BACKUP_SUFFIX)
        if backup.exists():
            raise RecoveryError(f"{backup} is in the way (a recovery before?): move it elsewhere, then run again")
        tmp = path.with_name(path.name + ".recovering")
        try:
            result.messages, result.bytes_kept, result.reason = recover_file(path, tmp, kept_as=backup.name)
            os.replace(path, backup)
            os.replace(tmp, path)
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            raise RecoveryError(f"could not write the recovered file beside {path}: {exc.strerror or exc}; "
                                f"{path} is as it was") from None
        result.backup = backup
    folder = path.parent
    if path.name == "run.mcap" and _summary_missing(folder / "summary.json"):
        result.summary = _rebuild_summary(path, folder, result)
    return result


def _summary_missing(path: Path) -> bool:
    try:
        json.loads(path.read_text(encoding="utf-8"))
        return False
    except (OSError, ValueError):
        return True


def _rebuild_summary(path: Path, folder: Path, result: Recovery) -> Optional[Path]:
    """summary.json (and events.log) of a run folder from its recording; None when they cannot be written."""
    from beastbt.run.run_folder import events_log_text, save_text
    rec = read_recording(path, topics=["/events", "/cmd/gate", "/truth", "/estimate/odom"])
    if rec.summary is None and not rec.info:
        result.notes.append(f"{path} holds nothing of the run (it was cut before its first record): no summary "
                            f"to rebuild")
        return None
    summary = rec.summary or recorded_summary(rec, result)
    problem = save_text(folder / "summary.json", json.dumps(summary, indent=2) + "\n")
    if problem is not None:
        result.notes.append(problem)
        return None
    events_log = folder / "events.log"
    if not events_log.exists() or events_log.stat().st_size == 0:
        problem = save_text(events_log, events_log_text(summary.get("events", [])))
        if problem is not None:
            result.notes.append(problem)
    return folder / "summary.json"


def recorded_summary(rec: Any, result: Recovery) -> dict:
    """A run summary from what a recording shows, for a run that could not write its own (status ``stopped``)."""
    info = rec.info
    gates = rec.topic("/cmd/gate")
    truth = rec.topic("/truth")
    odom = rec.topic("/estimate/odom")
    sim_time_s = gates[-1]["now_s"] - gates[0]["now_s"] if gates else 0.0
    distance = max_speed = 0.0
    if truth:
        distance = sum(math.hypot(b["x"] - a["x"], b["y"] - a["y"]) for a, b in zip(truth, truth[1:]))
        max_speed = max(abs(m["v_mps"] or 0.0) for m in truth)
    elif odom:
        distance = float(odom[-1].get("distance_m") or 0.0)
        max_speed = max(abs(m.get("speed_mps") or 0.0) for m in odom)
    events = [{"time_s": m["time_s"], "kind": m["kind"], "text": m["text"]} for m in rec.topic("/events")]
    try:
        seed = int(info.get("seed", 0))
    except ValueError:
        seed = 0
    mission = info.get("mission") or result.recording.parent.name.split("_", 1)[-1]
    return {
        "mission": mission, "status": "stopped", "seed": seed,
        "robot": info.get("robot_profile", ""), "world": info.get("world") or None,
        "sim_time_s": round(max(0.0, sim_time_s), 3), "wall_time_s": 0.0, "ticks": len(gates),
        "distance_m": round(distance, 4), "max_speed_mps": round(max_speed, 4), "waypoints": [],
        "events": events,
        "recovered": {"from": result.backup.name if result.backup else result.recording.name,
                      "reason": result.reason or "the run ended without writing its summary",
                      "note": "rebuilt from the recording by beastbt recover: the run was cut short here; "
                              "wall_time_s is unknown (0)"},
    }


__all__ = ["recover", "recover_file", "recorded_summary", "Recovery", "RecoveryError", "BACKUP_SUFFIX",
           "RECOVERED_METADATA"]
