"""rosbag2 `metadata.yaml` (version 9, as ROS 2 Jazzy writes it) and QoS profile dicts."""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from roszen.qos import Durability, History, Liveliness, QoSProfile, Reliability

VERSION = 9
INFINITE = {"sec": 9223372036, "nsec": 854775807}   # rmw's RMW_DURATION_INFINITE
ROS_DISTRO = "jazzy"


class BagError(Exception):
    """A bag that cannot be read or written; the message names the directory or file."""


def _duration(sec: float) -> dict[str, int]:
    if not sec or sec <= 0 or sec == float("inf"):
        return dict(INFINITE)
    s = int(sec)
    return {"sec": s, "nsec": int(round((sec - s) * 1e9))}


def _seconds(d: Any) -> float:
    if not isinstance(d, dict):
        return 0.0
    sec, nsec = int(d.get("sec", 0)), int(d.get("nsec", 0))
    if (sec, nsec) == (INFINITE["sec"], INFINITE["nsec"]) or (sec == 0 and nsec == 0):
        return 0.0
    return sec + nsec * 1e-9


def qos_to_dict(q: QoSProfile) -> dict[str, Any]:
    """One offered QoS profile in rosbag2 v9 form (lower-case policy names)."""
    return {
        "history": q.history.name.lower(),
        "depth": int(q.depth),
        "reliability": q.reliability.name.lower(),
        "durability": q.durability.name.lower(),
        "deadline": _duration(q.deadline),
        "lifespan": _duration(q.lifespan),
        "liveliness": q.liveliness.name.lower(),
        "liveliness_lease_duration": _duration(q.liveliness_lease_duration),
        "avoid_ros_namespace_conventions": False,
    }


def _enum(cls, value, default):
    if isinstance(value, int):
        try:
            return cls(value)
        except ValueError:
            return default
    try:
        return cls[str(value).upper()]
    except KeyError:
        return default


def qos_from_dict(d: dict[str, Any]) -> QoSProfile:
    """Inverse of qos_to_dict; accepts the older integer enum form too."""
    return QoSProfile(
        depth=int(d.get("depth", 10) or 0),
        history=_enum(History, d.get("history", "keep_last"), History.KEEP_LAST),
        reliability=_enum(Reliability, d.get("reliability", "reliable"), Reliability.RELIABLE),
        durability=_enum(Durability, d.get("durability", "volatile"), Durability.VOLATILE),
        deadline=_seconds(d.get("deadline")), lifespan=_seconds(d.get("lifespan")),
        liveliness=_enum(Liveliness, d.get("liveliness", "automatic"), Liveliness.AUTOMATIC),
        liveliness_lease_duration=_seconds(d.get("liveliness_lease_duration")))


def qos_yaml(profiles: list[QoSProfile]) -> str:
    """The offered_qos_profiles YAML string stored in an MCAP channel's metadata."""
    return yaml.safe_dump([qos_to_dict(q) for q in profiles], sort_keys=False).rstrip("\n")


def parse_qos(value: Any) -> list[QoSProfile]:
    """offered_qos_profiles as a list of dicts (v9) or a YAML string (v8, MCAP channels)."""
    if isinstance(value, str):
        value = yaml.safe_load(value) if value.strip() else []
    return [qos_from_dict(d) for d in (value or []) if isinstance(d, dict)]


@dataclass
class TopicInfo:
    """One topic of a bag: name, type, offered QoS, type hash, message count."""

    name: str
    type: str
    offered_qos: list[QoSProfile] = field(default_factory=list)
    type_hash: str = ""
    serialization_format: str = "cdr"
    count: int = 0


@dataclass
class FileInfo:
    path: str
    start_ns: int = 0
    duration_ns: int = 0
    count: int = 0


@dataclass
class BagMetadata:
    """The contents of metadata.yaml."""

    topics: list[TopicInfo] = field(default_factory=list)
    files: list[FileInfo] = field(default_factory=list)
    start_ns: int = 0
    duration_ns: int = 0
    compression_format: str = ""
    compression_mode: str = ""
    storage_identifier: str = "mcap"
    ros_distro: str = ROS_DISTRO
    version: int = VERSION
    custom_data: dict[str, str] | None = None

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self.topics)

    def to_dict(self) -> dict[str, Any]:
        return {"rosbag2_bagfile_information": {
            "version": self.version,
            "storage_identifier": self.storage_identifier,
            "duration": {"nanoseconds": int(self.duration_ns)},
            "starting_time": {"nanoseconds_since_epoch": int(self.start_ns)},
            "message_count": self.message_count,
            "topics_with_message_count": [{
                "topic_metadata": {
                    "name": t.name, "type": t.type,
                    "serialization_format": t.serialization_format,
                    "offered_qos_profiles": [qos_to_dict(q) for q in t.offered_qos],
                    "type_description_hash": t.type_hash,
                },
                "message_count": t.count,
            } for t in self.topics],
            "compression_format": self.compression_format,
            "compression_mode": self.compression_mode,
            "relative_file_paths": [f.path for f in self.files],
            "files": [{
                "path": f.path,
                "starting_time": {"nanoseconds_since_epoch": int(f.start_ns)},
                "duration": {"nanoseconds": int(f.duration_ns)},
                "message_count": f.count,
            } for f in self.files],
            "custom_data": self.custom_data or None,
            "ros_distro": self.ros_distro,
        }}

    def to_yaml(self) -> str:
        return yaml.safe_dump(self.to_dict(), sort_keys=False, default_flow_style=False)

    @classmethod
    def from_dict(cls, data: Any, where: str = "metadata.yaml") -> "BagMetadata":
        try:
            info = data["rosbag2_bagfile_information"]
            topics = [TopicInfo(
                name=t["topic_metadata"]["name"], type=t["topic_metadata"]["type"],
                offered_qos=parse_qos(t["topic_metadata"].get("offered_qos_profiles")),
                type_hash=t["topic_metadata"].get("type_description_hash", "") or "",
                serialization_format=t["topic_metadata"].get("serialization_format", "cdr"),
                count=int(t.get("message_count", 0)))
                for t in info.get("topics_with_message_count") or []]
            files = [FileInfo(path=f["path"],
                              start_ns=int(f["starting_time"]["nanoseconds_since_epoch"]),
                              duration_ns=int(f["duration"]["nanoseconds"]),
                              count=int(f.get("message_count", 0)))
                     for f in info.get("files") or []]
            if not files:
                files = [FileInfo(path=p) for p in info.get("relative_file_paths") or []]
            return cls(topics=topics, files=files,
                       start_ns=int(info["starting_time"]["nanoseconds_since_epoch"]),
                       duration_ns=int(info["duration"]["nanoseconds"]),
                       compression_format=info.get("compression_format", "") or "",
                       compression_mode=info.get("compression_mode", "") or "",
                       storage_identifier=info.get("storage_identifier", "mcap"),
                       ros_distro=info.get("ros_distro", "") or "",
                       version=int(info.get("version", VERSION)),
                       custom_data=info.get("custom_data"))
        except (KeyError, TypeError, ValueError) as exc:
            raise BagError(f"{where}: not a rosbag2 metadata file ({exc!r})") from None


def write_metadata(directory: str | os.PathLike, meta: BagMetadata) -> Path:
    """Write metadata.yaml atomically (a reader never sees half a file)."""
    path = Path(directory) / "metadata.yaml"
    tmp = path.with_suffix(".yaml.tmp")
    tmp.write_text(meta.to_yaml())
    os.replace(tmp, path)
    return path


def read_metadata(directory: str | os.PathLike) -> BagMetadata:
    """Parse `<directory>/metadata.yaml`; BagError naming the problem otherwise."""
    path = Path(directory) / "metadata.yaml"
    if not Path(directory).is_dir():
        raise BagError(f"not a bag directory: {directory}")
    if not path.is_file():
        raise BagError(f"no metadata.yaml in {directory} (try `bag reindex {directory}`)")
    try:
        data = yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise BagError(f"{path}: invalid YAML ({str(exc).splitlines()[0]})") from None
    return BagMetadata.from_dict(data, str(path))
