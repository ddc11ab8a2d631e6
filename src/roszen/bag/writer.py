"""rosbag2 MCAP writer: chunked, compressed MCAP + metadata.yaml, crash tolerant.

The MCAP file gets profile `ros2`, `ros2msg` schemas, `cdr` channels whose metadata holds
`offered_qos_profiles` and `topic_type_hash`, and on close a `rosbag2` metadata record, as
rosbag2's MCAP storage plugin writes them. Writes go through a queue to one writer thread
(subscription callbacks never wait on compression); every `flush_interval` seconds the open
chunk is closed and flushed to the OS, and metadata.yaml is rewritten, so a writer killed
with SIGKILL loses at most that much (the bag then reads with `reindex`, see reader.py).
"""
from __future__ import annotations

import os
import queue
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from mcap.writer import CompressionType, Writer

from roszen.bag.metadata import (BagError, BagMetadata, FileInfo, TopicInfo, qos_yaml,
                                 write_metadata)
from roszen.qos import QoSProfile

COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
                "none": CompressionType.NONE}
_STOP = object()


@dataclass
class _Topic:
    info: TopicInfo
    channel_id: int


class BagWriter:
    """Writes one rosbag2 directory (`<dir>/metadata.yaml`, `<dir>/<name>_0.mcap`)."""

    def __init__(self, directory: str | os.PathLike, *, compression: str = "zstd",
                 chunk_size: int = 1 << 20, flush_interval: float = 1.0,
                 queue_size: int = 0, library: str = "roszen-bag",
                 on_error: "Callable[[BaseException], None] | None" = None):
        if compression not in COMPRESSIONS:
            raise BagError(f"unknown compression '{compression}' (zstd, lz4 or none)")
        self.directory = Path(directory)
        if self.directory.exists():
            raise BagError(f"output directory already exists: {self.directory}")
        parent = self.directory.parent
        if not parent.is_dir():
            raise BagError(f"parent directory does not exist: {parent}")
        self.directory.mkdir()
        self.file_name = f"{self.directory.name}_0.mcap"
        self._file = open(self.directory / self.file_name, "wb")
        self._mcap = Writer(self._file, chunk_size=chunk_size,
                            compression=COMPRESSIONS[compression])
        self._mcap.start(profile="ros2", library=library)
        self.compression = compression
        self.flush_interval = flush_interval
        self._topics: dict[str, _Topic] = {}
        self._schemas: dict[str, int] = {}
        self._start_ns: int | None = None
        self._end_ns = 0
        self._queue: queue.Queue = queue.Queue(queue_size)
        self._error: BaseException | None = None
        self.on_error = on_error     # called once, on the writer thread, at the first failed write
        self._closed = False
        self.bytes_written = 0
        self._thread = threading.Thread(target=self._run, name="bag-writer", daemon=True)
        self._thread.start()

    # ---- public API (any thread) --------------------------------------------------------
    def add_topic(self, name: str, type_name: str, msgdef: str, type_hash: str = "",
                  offered_qos: list[QoSProfile] | None = None) -> None:
        """Declare a topic before its first message (msgdef: concatenated .msg text)."""
        self._queue.put(("topic", name, type_name, msgdef, type_hash, list(offered_qos or [])))

    def write(self, topic: str, data: bytes, log_time_ns: int | None = None,
              publish_time_ns: int | None = None) -> None:
        """Queue one serialised (CDR) message received at log_time_ns (default: now; the time
        players pace by) and publish_time_ns (default: log_time_ns; the recorder puts the
        wall-clock receive time there when log times are sim time)."""
        t = time.time_ns() if log_time_ns is None else log_time_ns    # 0 is a sim time
        self._queue.put(("msg", topic, bytes(data), t, t if publish_time_ns is None
                         else publish_time_ns))

    def has_topic(self, name: str) -> bool:
        return name in self._topics

    @property
    def error(self) -> BaseException | None:
        """The first write error (a full disk: OSError ENOSPC), None while all is well."""
        return self._error

    @property
    def pending(self) -> int:
        return self._queue.qsize()

    def close(self) -> BagMetadata:
        """Write everything queued, finish the MCAP (summary, metadata), write metadata.yaml."""
        if self._closed:
            return self.metadata()
        self._closed = True
        self._queue.put(_STOP)
        self._thread.join()
        if self._error:
            try:                     # what reached the file before the error stays readable
                self._file.close()
            except OSError:
                pass
            raise BagError(f"bag writer failed: {self._error}")
        meta = self.metadata()
        self._mcap.add_metadata("rosbag2", {"serialized_metadata": meta.to_yaml(),
                                            "ROS_DISTRO": meta.ros_distro})
        self._mcap.finish()
        self._file.close()
        write_metadata(self.directory, meta)
        return meta

    def metadata(self) -> BagMetadata:
        """metadata.yaml contents for what has been written so far."""
        start = self._start_ns or 0
        duration = max(0, self._end_ns - start) if self._start_ns is not None else 0
        topics = [t.info for t in self._topics.values()]
        count = sum(t.count for t in topics)
        return BagMetadata(topics=topics, start_ns=start, duration_ns=duration,
                           files=[FileInfo(self.file_name, start, duration, count)])

    # ---- writer thread ------------------------------------------------------------------
    def _run(self) -> None:
        next_flush = time.monotonic() + self.flush_interval
        while True:
            timeout = max(0.0, next_flush - time.monotonic())
            try:
                item = self._queue.get(timeout=timeout)
            except queue.Empty:
                item = None
            try:
                if item is _STOP:
                    return
                if item is not None:
                    self._handle(item)
                if time.monotonic() >= next_flush:
                    self._flush()
                    next_flush = time.monotonic() + self.flush_interval
            except BaseException as exc:   # keep draining so producers never block forever
                if self._error is None:
                    self._error = exc
                    if self.on_error is not None:
                        try:
                            self.on_error(exc)
                        except Exception:   # noqa: BLE001 - the report must not stop the drain
                            pass

    def _handle(self, item) -> None:
        if item[0] == "msg":
            _, topic, data, t, pt = item
            entry = self._topics.get(topic)
            if entry is None:
                return
            self._mcap.add_message(channel_id=entry.channel_id, log_time=t, publish_time=pt,
                                   data=data, sequence=entry.info.count)
            entry.info.count += 1
            self.bytes_written += len(data)
            if self._start_ns is None or t < self._start_ns:
                self._start_ns = t
            self._end_ns = max(self._end_ns, t)
        else:
            _, name, type_name, msgdef, type_hash, qos = item
            if name in self._topics:
                return
            schema = self._schemas.get(type_name)
            if schema is None:
                schema = self._mcap.register_schema(type_name, "ros2msg", msgdef.encode())
                self._schemas[type_name] = schema
            meta = {"offered_qos_profiles": qos_yaml(qos)}
            if type_hash:
                meta["topic_type_hash"] = type_hash
            cid = self._mcap.register_channel(name, "cdr", schema, meta)
            self._topics[name] = _Topic(TopicInfo(name, type_name, qos, type_hash), cid)

    def _flush(self) -> None:
        self._mcap.flush()
        self._file.flush()
        write_metadata(self.directory, self.metadata())
