"""QoS profiles (rclpy-like) and their rmw_zenoh liveliness-token encoding."""
from __future__ import annotations

import enum
from dataclasses import dataclass, replace


class Reliability(enum.IntEnum):
    """rmw reliability enum values."""
    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2


class Durability(enum.IntEnum):
    """rmw durability enum values."""
    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


class History(enum.IntEnum):
    """rmw history enum values."""
    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


class Liveliness(enum.IntEnum):
    """rmw liveliness enum values (only AUTOMATIC is meaningful over zenoh)."""
    SYSTEM_DEFAULT = 0
    AUTOMATIC = 1
    MANUAL_BY_TOPIC = 3


# rclpy-style aliases
ReliabilityPolicy = Reliability
DurabilityPolicy = Durability
HistoryPolicy = History
LivelinessPolicy = Liveliness

DEFAULT_DEPTH = 42  # rmw_zenoh's depth for depth 0 / system default


@dataclass(frozen=True)
class QoSProfile:
    """A ROS 2 QoS profile; durations in seconds (0 = infinite/unset)."""
    depth: int = 10
    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    history: History = History.KEEP_LAST
    deadline: float = 0.0
    lifespan: float = 0.0
    liveliness: Liveliness = Liveliness.AUTOMATIC
    liveliness_lease_duration: float = 0.0

    def __post_init__(self) -> None:
        if int(self.depth) < 0:
            raise ValueError(f"QoS depth must be >= 0, got {self.depth}")
        # normalise SYSTEM_DEFAULT the way rmw_zenoh does
        object.__setattr__(self, "reliability", Reliability(self.reliability) if self.reliability else Reliability.RELIABLE)
        object.__setattr__(self, "durability", Durability(self.durability) if self.durability else Durability.VOLATILE)
        object.__setattr__(self, "history", History(self.history) if self.history else History.KEEP_LAST)
        object.__setattr__(self, "liveliness", Liveliness(self.liveliness) if self.liveliness else Liveliness.AUTOMATIC)
        object.__setattr__(self, "depth", int(self.depth))

    @property
    def effective_depth(self) -> int:
        """Depth used for queues and caches (0 means rmw_zenoh's default 42)."""
        return self.depth if self.depth > 0 else DEFAULT_DEPTH

    @property
    def keep_all(self) -> bool:
        return self.history == History.KEEP_ALL

    @property
    def reliable(self) -> bool:
        return self.reliability == Reliability.RELIABLE

    @property
    def transient_local(self) -> bool:
        return self.durability == Durability.TRANSIENT_LOCAL

    def with_(self, **kw) -> "QoSProfile":
        """Copy with some fields changed."""
        return replace(self, **kw)

    def to_token(self) -> str:
        """Encode as the last field of an rmw_zenoh liveliness token (defaults left empty)."""
        rel = "" if self.reliability == Reliability.RELIABLE else str(int(self.reliability))
        dur = "" if self.durability == Durability.VOLATILE else str(int(self.durability))
        hist = "" if self.history == History.KEEP_LAST else str(int(self.history))
        depth = "" if self.effective_depth == DEFAULT_DEPTH else str(self.effective_depth)
        return (f"{rel}:{dur}:{hist},{depth}:{_dur(self.deadline)}:{_dur(self.lifespan)}:"
                f"{'' if self.liveliness == Liveliness.AUTOMATIC else int(self.liveliness)},"
                f"{_dur(self.liveliness_lease_duration)}")

    @classmethod
    def from_token(cls, text: str) -> "QoSProfile":
        """Decode the QoS field of a liveliness token."""
        parts = text.split(":")
        if len(parts) != 6:
            raise ValueError(f"bad QoS token {text!r}")
        rel, dur, hist_depth, deadline, lifespan, live = parts
        hist, _, depth = hist_depth.partition(",")
        lv, _, lease = live.partition(",")
        return cls(
            depth=int(depth) if depth else DEFAULT_DEPTH,
            reliability=Reliability(int(rel)) if rel else Reliability.RELIABLE,
            durability=Durability(int(dur)) if dur else Durability.VOLATILE,
            history=History(int(hist)) if hist else History.KEEP_LAST,
            deadline=_undur(deadline), lifespan=_undur(lifespan),
            liveliness=Liveliness(int(lv)) if lv else Liveliness.AUTOMATIC,
            liveliness_lease_duration=_undur(lease))


def _dur(sec: float) -> str:
    if not sec or sec <= 0 or sec == float("inf"):
        return ","
    s = int(sec)
    return f"{s},{int(round((sec - s) * 1e9))}"


def _undur(text: str) -> float:
    s, _, ns = text.partition(",")
    if not s and not ns:
        return 0.0
    return float(int(s or 0)) + int(ns or 0) * 1e-9


def as_qos(qos: "QoSProfile | int | None") -> QoSProfile:
    """Accept a depth int (like rclpy) or a profile."""
    if qos is None:
        return QoSProfile()
    if isinstance(qos, QoSProfile):
        return qos
    if isinstance(qos, bool) or not isinstance(qos, int):
        raise TypeError(f"qos must be a QoSProfile or an int depth, got {qos!r}")
    return QoSProfile(depth=qos)


LATCHED = QoSProfile(depth=1, durability=Durability.TRANSIENT_LOCAL)
SENSOR_DATA = QoSProfile(depth=5, reliability=Reliability.BEST_EFFORT)
SERVICES_DEFAULT = QoSProfile(depth=10)
PARAMETER_EVENTS = QoSProfile(depth=1000)
CLOCK = QoSProfile(depth=1, reliability=Reliability.BEST_EFFORT)
ROSOUT = QoSProfile(depth=1000, durability=Durability.TRANSIENT_LOCAL)
qos_profile_sensor_data = SENSOR_DATA
qos_profile_services_default = SERVICES_DEFAULT
