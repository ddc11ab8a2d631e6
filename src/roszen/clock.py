"""Time, Duration and a clock that follows /clock when use_sim_time is set."""
from __future__ import annotations

import threading
import time as _time
from functools import total_ordering
from typing import Any, Callable, Optional


@total_ordering
class Duration:
    """A signed duration in integer nanoseconds."""
    __slots__ = ("nanoseconds",)

    def __init__(self, *, seconds: float = 0, nanoseconds: int = 0) -> None:
        self.nanoseconds = int(round(seconds * 1e9)) + int(nanoseconds)

    def __eq__(self, o: object) -> bool:
        return isinstance(o, Duration) and o.nanoseconds == self.nanoseconds

    def __lt__(self, o: "Duration") -> bool:
        return self.nanoseconds < o.nanoseconds

    def __hash__(self) -> int:
        return hash(self.nanoseconds)

    def __add__(self, o: "Duration") -> "Duration":
        return Duration(nanoseconds=self.nanoseconds + o.nanoseconds)

    def __sub__(self, o: "Duration") -> "Duration":
        return Duration(nanoseconds=self.nanoseconds - o.nanoseconds)

    def __repr__(self) -> str:
        return f"Duration(nanoseconds={self.nanoseconds})"

    def to_sec(self) -> float:
        return self.nanoseconds * 1e-9

    def to_msg(self) -> Any:
        from . import typestore
        m = typestore.message_class("builtin_interfaces/msg/Duration")()
        m.sec, m.nanosec = divmod(self.nanoseconds, 1_000_000_000)
        return m


@total_ordering
class Time:
    """A point in time (ns since the epoch, or since sim start for sim time)."""
    __slots__ = ("nanoseconds",)

    def __init__(self, *, seconds: float = 0, nanoseconds: int = 0) -> None:
        self.nanoseconds = int(round(seconds * 1e9)) + int(nanoseconds)

    @classmethod
    def from_msg(cls, msg: Any) -> "Time":
        return cls(nanoseconds=int(msg.sec) * 1_000_000_000 + int(msg.nanosec))

    def to_msg(self) -> Any:
        from . import typestore
        m = typestore.message_class("builtin_interfaces/msg/Time")()
        m.sec, m.nanosec = divmod(self.nanoseconds, 1_000_000_000)
        return m

    def seconds_nanoseconds(self) -> tuple:
        return divmod(self.nanoseconds, 1_000_000_000)

    def to_sec(self) -> float:
        return self.nanoseconds * 1e-9

    def __eq__(self, o: object) -> bool:
        return isinstance(o, Time) and o.nanoseconds == self.nanoseconds

    def __lt__(self, o: "Time") -> bool:
        return self.nanoseconds < o.nanoseconds

    def __hash__(self) -> int:
        return hash(self.nanoseconds)

    def __add__(self, d: Duration) -> "Time":
        return Time(nanoseconds=self.nanoseconds + d.nanoseconds)

    def __sub__(self, o: "Time | Duration") -> "Time | Duration":
        if isinstance(o, Time):
            return Duration(nanoseconds=self.nanoseconds - o.nanoseconds)
        return Time(nanoseconds=self.nanoseconds - o.nanoseconds)

    def __repr__(self) -> str:
        return f"Time(nanoseconds={self.nanoseconds})"


class Clock:
    """ROS time: the wall clock, or the last /clock value while sim time is active."""

    def __init__(self, use_sim_time: bool = False) -> None:
        self._sim = bool(use_sim_time)
        self._sim_ns = 0
        self._cond = threading.Condition()
        self._listeners: list = []

    @property
    def ros_time_is_active(self) -> bool:
        return self._sim

    def set_sim_time_active(self, active: bool) -> None:
        with self._cond:
            self._sim = bool(active)
            self._cond.notify_all()

    def now(self) -> Time:
        return Time(nanoseconds=self._sim_ns if self._sim else _time.time_ns())

    def now_ns(self) -> int:
        return self._sim_ns if self._sim else _time.time_ns()

    def set_sim_time(self, ns: int) -> None:
        """Called for each /clock sample; wakes sleepers and listeners."""
        with self._cond:
            self._sim_ns = int(ns)
            self._cond.notify_all()
        for cb in list(self._listeners):
            cb(ns)

    def add_listener(self, cb: Callable[[int], None]) -> None:
        self._listeners.append(cb)

    def sleep_until(self, t: Time, timeout: Optional[float] = None) -> bool:
        """Block until the clock reaches t (True) or the wall timeout passes (False)."""
        deadline = None if timeout is None else _time.monotonic() + timeout
        if not self._sim:
            delay = (t.nanoseconds - _time.time_ns()) * 1e-9
            if deadline is not None and delay > timeout:
                _time.sleep(max(0.0, timeout))
                return False
            if delay > 0:
                _time.sleep(delay)
            return True
        with self._cond:
            while self._sim and self._sim_ns < t.nanoseconds:
                rem = None if deadline is None else deadline - _time.monotonic()
                if rem is not None and rem <= 0:
                    return False
                self._cond.wait(rem if rem is not None else 0.5)
            return True

    def sleep_for(self, d: Duration, timeout: Optional[float] = None) -> bool:
        return self.sleep_until(self.now() + d, timeout)


class ClockSource:
    """One /clock publisher per graph: the clock is the first publisher heard; samples of any
    other are ignored (each such publisher logged once). When the adopted publisher has left
    the graph (its liveliness token gone: a restarted sim), the next one heard is adopted.

    A second /clock (a `bag play --clock` on a live graph, a stray `topic pub /clock`) would
    otherwise interleave two time lines: every step back looks like a sim reset."""

    def __init__(self, graph, topic: str = "/clock", log: Optional[Callable[[str], None]] = None) -> None:
        self.graph = graph
        self.topic = topic
        self.log = log or (lambda text: None)
        self.gid: Optional[bytes] = None
        self._ignored: set = set()

    def accept(self, gid: bytes) -> bool:
        """True when a sample from publisher `gid` is this graph's clock (called per sample)."""
        if gid == self.gid:
            return True
        if self.gid is not None and self._present(self.gid):
            if gid not in self._ignored:
                self._ignored.add(gid)
                self.log(f"ignoring {self.topic} from publisher {gid.hex()} ({self._who(gid)}): this "
                         f"graph's clock is {self.gid.hex()} ({self._who(self.gid)}); one clock per graph")
            return False
        if self.gid is not None:
            self.log(f"{self.topic} publisher {self.gid.hex()} left the graph: the clock is now "
                     f"{gid.hex()} ({self._who(gid)})")
        self.gid = gid
        self._ignored.discard(gid)
        return True

    def _entities(self) -> list:
        try:
            return list(self.graph.get_publishers_info_by_topic(self.topic))
        except Exception:   # a graph being closed: keep the adopted clock
            return []

    def _present(self, gid: bytes) -> bool:
        ents = self._entities()
        return not ents or any(e.gid == gid for e in ents)

    def _who(self, gid: bytes) -> str:
        for e in self._entities():
            if e.gid == gid:
                return f"node {e.node_fqn}"
        return "node unknown"
