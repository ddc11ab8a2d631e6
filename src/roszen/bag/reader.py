"""Reading rosbag2 MCAP directories, including ones whose writer was killed (SIGKILL).

A complete MCAP file is read through its summary, in log-time order. A file without a
summary (writer killed) is read sequentially and every complete chunk is recovered; the
incomplete tail is skipped. `reindex(dir)` rewrites such a bag into a complete one (new MCAP
with summary + metadata.yaml), after which every MCAP/rosbag2 tool reads it.
"""
from __future__ import annotations

import datetime
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from roszen.bag.metadata import (BagError, BagMetadata, FileInfo, TopicInfo, parse_qos,
                                 read_metadata, write_metadata)

MAGIC = b"\x89MCAP0\r\n"


@dataclass
class BagMessage:
    """One recorded message: its topic (with type and QoS), CDR bytes and receive time."""

    topic: TopicInfo
    data: bytes
    log_time_ns: int
    publish_time_ns: int = 0      # MCAP publish_time: our recorder's wall-clock receive time

    def __post_init__(self) -> None:
        if not self.publish_time_ns:
            self.publish_time_ns = self.log_time_ns


def _has_footer(path: Path) -> bool:
    size = path.stat().st_size
    if size < 2 * len(MAGIC) + 37:
        return False
    with open(path, "rb") as f:
        f.seek(size - len(MAGIC))
        return f.read(len(MAGIC)) == MAGIC


def _topic_from_channel(channel: Channel, schema: Schema | None) -> TopicInfo:
    meta = channel.metadata or {}
    return TopicInfo(name=channel.topic, type=schema.name if schema else "",
                     offered_qos=parse_qos(meta.get("offered_qos_profiles", "")),
                     type_hash=meta.get("topic_type_hash", ""),
                     serialization_format=channel.message_encoding or "cdr")


class BagReader:
    """Reads a rosbag2 directory with MCAP storage; `recovered` tells if a file was cut short."""

    def __init__(self, directory: str | os.PathLike):
        self.directory = Path(directory)
        if not self.directory.exists():
            raise BagError(f"bag directory does not exist: {self.directory}")
        if not self.directory.is_dir():
            raise BagError(f"not a bag directory: {self.directory}")
        self.meta: BagMetadata | None = None
        self.meta_problem = ""      # why metadata.yaml was set aside (half-written, lists no file)
        files: list[Path] = []
        if (self.directory / "metadata.yaml").is_file():
            try:
                self.meta = read_metadata(self.directory)
            except BagError as exc:     # half-written by a writer that died: read the .mcap
                self.meta_problem = str(exc)
            if self.meta is not None:
                if self.meta.storage_identifier not in ("mcap", ""):
                    raise BagError(f"{self.directory}: storage '{self.meta.storage_identifier}' "
                                   "is not supported (only mcap)")
                files = [self.directory / f.path for f in self.meta.files]
                missing = [str(p) for p in files if not p.is_file()]
                if missing:
                    raise BagError(f"{self.directory}: bag file missing: {missing[0]}")
                if not files:
                    self.meta_problem = "metadata.yaml lists no bag file"
                    self.meta = None
        if self.meta is None:
            files = sorted(self.directory.glob("*.mcap"))
        if not files:
            if self.meta_problem:
                raise BagError(f"{self.directory}: no .mcap file ({self.meta_problem})")
            raise BagError(f"{self.directory}: no metadata.yaml and no .mcap file")
        for p in files:
            if not os.access(p, os.R_OK):
                raise BagError(f"{p}: permission denied")
            with open(p, "rb") as f:
                if f.read(len(MAGIC)) != MAGIC:
                    raise BagError(f"{p}: not an MCAP file")
        self.files = files
        self.recovered = any(not _has_footer(p) for p in files)

    # ---- messages -----------------------------------------------------------------------
    def messages(self, topics: list[str] | None = None) -> Iterator[BagMessage]:
        """Every message (of `topics` if given) in log-time order per file."""
        wanted = set(topics) if topics else None
        for path in self.files:
            if _has_footer(path):
                yield from self._read_indexed(path, wanted)
            else:
                yield from self._read_stream(path, wanted)

    def _topic(self, channel: Channel, schema: Schema | None, cache: dict) -> TopicInfo:
        info = cache.get(channel.id)
        if info is None:
            info = _topic_from_channel(channel, schema)
            if self.meta:   # metadata.yaml knows the offered QoS even for foreign bags
                for t in self.meta.topics:
                    if t.name == info.name:
                        info.offered_qos = info.offered_qos or t.offered_qos
                        info.type_hash = info.type_hash or t.type_hash
                        info.type = info.type or t.type
            cache[channel.id] = info
        return info

    def _read_indexed(self, path: Path, wanted) -> Iterator[BagMessage]:
        cache: dict[int, TopicInfo] = {}
        try:
            with open(path, "rb") as f:
                reader = make_reader(f)
                for schema, channel, msg in reader.iter_messages(
                        topics=list(wanted) if wanted else None, log_time_order=True):
                    yield BagMessage(self._topic(channel, schema, cache), msg.data, msg.log_time,
                                     msg.publish_time)
        except Exception as exc:   # noqa: BLE001 - a damaged chunk raises zstd/lz4/struct errors too
            kind = type(exc).__name__
            raise BagError(f"{path}: unreadable MCAP, damaged at some chunk ({kind}: {exc})") from None

    def _read_stream(self, path: Path, wanted) -> Iterator[BagMessage]:
        """Sequential read of a file without summary; stops at the first incomplete record."""
        schemas: dict[int, Schema] = {}
        channels: dict[int, Channel] = {}
        cache: dict[int, TopicInfo] = {}
        with open(path, "rb") as f:
            records = StreamReader(f, record_size_limit=1 << 31).records
            while True:
                try:
                    rec = next(records)
                except StopIteration:
                    return
                except Exception:       # truncated or corrupt tail: keep what was complete
                    return
                if isinstance(rec, Schema):
                    schemas[rec.id] = rec
                elif isinstance(rec, Channel):
                    channels[rec.id] = rec
                elif isinstance(rec, Message):
                    ch = channels.get(rec.channel_id)
                    if ch is None or (wanted and ch.topic not in wanted):
                        continue
                    yield BagMessage(self._topic(ch, schemas.get(ch.schema_id), cache),
                                     rec.data, rec.log_time, rec.publish_time)

    # ---- summary ------------------------------------------------------------------------
    def schemas(self) -> dict[str, str]:
        """type name -> ros2msg definition text, for every schema in the files."""
        out: dict[str, str] = {}
        for path in self.files:
            with open(path, "rb") as f:
                try:
                    for rec in StreamReader(f, record_size_limit=1 << 31).records:
                        if isinstance(rec, Schema):
                            out.setdefault(rec.name, rec.data.decode())
                except Exception:
                    pass
        return out

    def metadata(self) -> BagMetadata:
        """metadata.yaml contents, rebuilt from the messages when a file was cut short."""
        if self.meta is not None and not self.recovered:
            return self.meta
        return rebuild_metadata(self)


def rebuild_metadata(reader: BagReader) -> BagMetadata:
    """Count every readable message of `reader` into a fresh BagMetadata."""
    topics: dict[str, TopicInfo] = {}
    files = []
    start_all, end_all = None, 0
    for path in reader.files:
        start, end, count = None, 0, 0
        for m in BagReader._read_stream(reader, path, None):
            t = topics.get(m.topic.name)
            if t is None:
                t = topics[m.topic.name] = TopicInfo(m.topic.name, m.topic.type,
                                                     m.topic.offered_qos, m.topic.type_hash,
                                                     m.topic.serialization_format)
            t.count += 1
            count += 1
            start = m.log_time_ns if start is None else min(start, m.log_time_ns)
            end = max(end, m.log_time_ns)
        files.append(FileInfo(path.name, start or 0, (end - start) if start is not None else 0,
                              count))
        if start is not None:
            start_all = start if start_all is None else min(start_all, start)
            end_all = max(end_all, end)
    return BagMetadata(topics=list(topics.values()), files=files, start_ns=start_all or 0,
                       duration_ns=(end_all - start_all) if start_all is not None else 0)


def reindex(directory: str | os.PathLike, compression: str = "zstd") -> BagMetadata:
    """Make a bag whose writer died complete again: rewrite its MCAP + metadata.yaml, the
    originals kept beside as *.orig; a bag with nothing to recover is refused, unchanged."""
    reader = BagReader(directory)
    if not reader.recovered and reader.meta is not None:
        return reader.meta
    schemas = reader.schemas()
    meta = rebuild_metadata(reader)
    old = reader.meta
    if old is None and (Path(directory) / "metadata.yaml").is_file():
        try:
            old = read_metadata(directory)
        except BagError:
            old = None
    if meta.message_count == 0 and (old is None or old.message_count > 0 or old.topics):
        said = f" (metadata.yaml lists {old.message_count} messages on {len(old.topics)} topics)" if old else ""
        raise BagError(f"{directory}: no complete chunk to recover{said}; nothing changed")
    # what is replaced is kept beside: the cut file may hold more than this reader recovers
    for path in [*reader.files, Path(directory) / "metadata.yaml"]:
        backup = path.with_name(path.name + ".orig")
        if path.is_file() and not backup.exists():
            shutil.copy2(path, backup)
    for path in reader.files:
        tmp = path.with_name(path.name + ".reindex.tmp")
        try:
            with open(tmp, "wb") as f:
                w = Writer(f, compression=CompressionType.ZSTD if compression == "zstd"
                           else CompressionType.LZ4)
                w.start(profile="ros2", library="roszen-bag reindex")
                sids: dict[str, int] = {}
                cids: dict[str, int] = {}
                for m in BagReader._read_stream(reader, path, None):
                    t = m.topic
                    if t.name not in cids:
                        if t.type not in sids:
                            sids[t.type] = w.register_schema(
                                t.type, "ros2msg", schemas.get(t.type, "").encode())
                        from roszen.bag.metadata import qos_yaml
                        md = {"offered_qos_profiles": qos_yaml(t.offered_qos)}
                        if t.type_hash:
                            md["topic_type_hash"] = t.type_hash
                        cids[t.name] = w.register_channel(t.name, "cdr", sids[t.type], md)
                    w.add_message(cids[t.name], m.log_time_ns, m.data, m.publish_time_ns)
                w.add_metadata("rosbag2", {"serialized_metadata": meta.to_yaml(),
                                           "ROS_DISTRO": meta.ros_distro})
                w.finish()
            os.replace(tmp, path)
        finally:
            if tmp.exists():
                tmp.unlink()
    write_metadata(directory, meta)
    return meta


def _fmt_size(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024.0
    return f"{n:.1f} GiB"


def _fmt_time(ns: int) -> str:
    t = datetime.datetime.fromtimestamp(ns / 1e9)
    return f"{t.strftime('%b %d %Y %H:%M:%S')}.{ns % 1_000_000_000:09d} ({ns // 1_000_000_000}.{ns % 1_000_000_000:09d})"


def info_text(directory: str | os.PathLike) -> str:
    """The `bag info` report, laid out like `ros2 bag info`."""
    reader = BagReader(directory)
    meta = reader.metadata()
    size = sum(p.stat().st_size for p in reader.files)
    lines = [
        f"Files:             {', '.join(p.name for p in reader.files)}",
        f"Bag size:          {_fmt_size(size)}",
        f"Storage id:        {meta.storage_identifier or 'mcap'}",
        f"ROS Distro:        {meta.ros_distro or 'unknown'}",
        f"Duration:          {meta.duration_ns / 1e9:.9f}s",
        f"Start:             {_fmt_time(meta.start_ns)}",
        f"End:               {_fmt_time(meta.start_ns + meta.duration_ns)}",
        f"Messages:          {meta.message_count}",
    ]
    head = "Topic information: "
    for i, t in enumerate(meta.topics):
        lines.append(f"{head if i == 0 else ' ' * len(head)}Topic: {t.name} | Type: {t.type} | "
                     f"Count: {t.count} | Serialization Format: {t.serialization_format}")
    if not meta.topics:
        lines.append(head.rstrip())
    lines += ["Services:          0", "Service information: "]
    if reader.meta_problem:
        lines.append(f"Note:              metadata.yaml set aside ({reader.meta_problem}); "
                     "read from the .mcap file; `bag reindex` rewrites it")
    if reader.recovered:
        lines.append("Note:              the MCAP file has no summary (writer was killed); "
                     "complete chunks were counted; `bag reindex` repairs it")
    return "\n".join(lines)
