"""Repairing a flight log file cut off by a crash or power loss, or damaged
(:func:`recover_log`): every intact message rewritten into a valid, indexed MCAP file."""

from __future__ import annotations

import dataclasses
import os
from collections import defaultdict
from collections.abc import Mapping
from importlib.metadata import version as _dist_version
from pathlib import Path

from mcap.records import Attachment, Channel, Chunk, Header, Message, Metadata, Schema

import holescan.flightlog.schemas as sch
from holescan.flightlog.errors import FlightLogError
from holescan.flightlog.mcapfile import McapFile
from holescan.flightlog.scan import DamagedRegion, ScanState, scan_records
from holescan.outputs import OutputPathError, check_output

__all__ = ["RecoveryReport", "recover_log"]


@dataclasses.dataclass(frozen=True)
class RecoveryReport:
    """What :func:`recover_log` saved.

    source_complete : the source had its footer (nothing was lost; it was rewritten).
    bytes_used : the source's bytes up to its last intact record, of ``bytes_total``.
    last_t_unix_ns : log time of the last message saved.
    stop_reason : why reading stopped early (None when complete).
    """

    src: Path
    dst: Path
    source_complete: bool
    messages: int
    topics: Mapping[str, int]
    frames: int
    bytes_used: int
    bytes_total: int
    last_t_unix_ns: int
    stop_reason: str | None
    damaged: tuple[DamagedRegion, ...] = ()
    messages_lost: int = 0

    def line(self) -> str:
        how = "complete" if self.source_complete else f"cut off: {self.stop_reason}"
        if self.damaged:
            how += (
                f"; {len(self.damaged)} damaged region(s) skipped, "
                f"{self.messages_lost} messages lost: "
                + "; ".join(d.describe() for d in self.damaged)
            )
        return (
            f"{self.dst}: {self.messages} messages, {self.frames} frames recovered from "
            f"{self.src} ({how}; {self.bytes_used} of {self.bytes_total} bytes used)"
        )


@dataclasses.dataclass
class _Copy:
    """The source's schemas and channels as registered in the copy, and what was copied."""

    schema_ids: dict[int, int] = dataclasses.field(default_factory=dict)
    channel_ids: dict[int, int] = dataclasses.field(default_factory=dict)
    channels: dict[int, Channel] = dataclasses.field(default_factory=dict)
    pending_schemas: dict[int, Schema] = dataclasses.field(default_factory=dict)
    topics: dict[str, int] = dataclasses.field(default_factory=lambda: defaultdict(int))
    messages: int = 0
    last_t: int = 0
    unschematic: int = 0  # messages whose channel (or its schema) was lost

    def add(self, out: McapFile, rec: object) -> None:
        if isinstance(rec, Schema):
            if rec.id not in self.schema_ids and rec.id not in self.pending_schemas:
                self.pending_schemas[rec.id] = rec
        elif isinstance(rec, Channel):
            if rec.id not in self.channel_ids:
                sid = 0
                if rec.schema_id != 0:
                    if rec.schema_id not in self.schema_ids:
                        s = self.pending_schemas.pop(rec.schema_id, None)
                        if s is None:  # its schema was lost with damaged bytes
                            return  # (so are its messages: counted below)
                        self.schema_ids[rec.schema_id] = out.copy_schema(s)
                    sid = self.schema_ids[rec.schema_id]
                self.channel_ids[rec.id] = out.copy_channel(rec, sid)
                self.channels[rec.id] = rec
        elif isinstance(rec, Message):
            if rec.channel_id not in self.channel_ids:
                self.unschematic += 1
                return
            cid = self.channel_ids[rec.channel_id]
            out.add_message(cid, rec.log_time, rec.data, rec.publish_time, rec.sequence)
            self.topics[self.channels[rec.channel_id].topic] += 1
            self.messages += 1
            self.last_t = max(self.last_t, rec.log_time)
        elif isinstance(rec, Metadata):
            out.add_metadata(rec.name, rec.metadata)
        elif isinstance(rec, Attachment):
            out.add_attachment(rec)


def recover_log(src: str | os.PathLike[str], dst: str | os.PathLike[str]) -> RecoveryReport:
    """Rewrite ``src`` (a flight log file, possibly cut off mid-write) as a valid, indexed
    MCAP file ``dst`` holding every message up to its last complete chunk, with its
    metadata and attachments.

    ``dst`` must not exist (and must not be ``src``); it is written under a temporary name
    and renamed when complete. Raises :class:`FlightLogError` when ``src`` is missing or
    not MCAP.
    """
    src_p, dst_p = Path(src), check_output(dst, inputs=[src])
    state = ScanState(src_p)
    header: Header | None = None
    out: McapFile | None = None
    copy = _Copy()
    try:
        for rec in scan_records(src_p, state):
            if isinstance(rec, Header):
                header = rec
                continue
            if out is None:  # the copy takes the source's compression, profile, library
                library = header.library if header is not None else ""
                out = McapFile(
                    dst_p,
                    library=f"{library} recovered-by holescan/{_dist_version('holescan')}".strip(),
                    profile=header.profile if header is not None else "",
                    compression=rec.compression if isinstance(rec, Chunk) else "zstd",
                )
            copy.add(out, rec)
        if out is None:
            raise FlightLogError(f"{src_p}: nothing to recover (cut off inside its header)")
        out.close()
    except OSError as err:
        if out is not None:
            out.abort()
        raise OutputPathError(f"cannot write {dst_p}: {err.strerror or err}") from err
    except BaseException:
        if out is not None:
            out.abort()
        raise
    frames = min(
        copy.topics.get(t, 0) for t in (sch.TOPIC_COLOR, sch.TOPIC_DEPTH, sch.TOPIC_FRAME_INFO)
    )
    return RecoveryReport(
        src=src_p,
        dst=dst_p,
        source_complete=state.complete,
        messages=copy.messages,
        topics=dict(copy.topics),
        frames=frames,
        bytes_used=state.good_bytes,
        bytes_total=state.size,
        last_t_unix_ns=copy.last_t,
        stop_reason=state.stop_reason,
        damaged=tuple(state.damaged),
        messages_lost=state.messages_lost + copy.unschematic,
    )
