"""The one reader of a run's recording (a rosbag2 directory): decoded messages of the topics
asked for, optionally only those received in a wall-clock window (one leg of a multi-leg run,
whose sim clock restarts at each reset). The run summary, the video renderer and the Task's
judgement of a recorded flight all read through it; stamps are read with msgconv's helpers.

It lives in the lab layer (the lowest that may import roszen besides the node modules) so
astrobee_lab.recorded can use it; roszen is imported when a recording is opened.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Iterator

from astrobee.msgconv import stamp_ns, stamp_s

__all__ = ["Recorded", "RecordingError", "Recording", "stamp_ns", "stamp_s"]


class RecordingError(Exception):
    """A recording that cannot be opened (missing, no metadata, unreadable; one line)."""


@dataclass(frozen=True)
class Recorded:
    """One decoded message: its topic, type, receive (publish) and log times (ns), the message."""

    topic: str
    type: str
    publish_ns: int
    log_ns: int
    msg: Any


class Recording:
    """A rosbag2 directory opened for reading: its topics and their decoded messages."""

    def __init__(self, bag_dir: str | os.PathLike):
        from roszen.bag.metadata import BagError
        from roszen.bag.reader import BagReader
        self.path = bag_dir
        try:
            self._reader = BagReader(bag_dir)
            self.topics: dict[str, str] = {t.name: t.type
                                           for t in self._reader.metadata().topics}
        except (BagError, OSError) as exc:
            raise RecordingError(str(exc)) from None

    def names(self, keep: Callable[[str, str], bool]) -> list[str]:
        """The recorded topics for which keep(name, type) holds."""
        return [n for n, ty in self.topics.items() if keep(n, ty)]

    def messages(self, topics: Iterable[str],
                 log_window: tuple[float, float] | None = None) -> Iterator[Recorded]:
        """Decoded messages of `topics` (those recorded) in recording order; with `log_window`
        (wall-clock s) only those received in it. A record that does not decode is skipped
        (one bad record must not lose a plot or a video); a damaged chunk of the MCAP ends the
        reading with RecordingError (one line)."""
        from roszen import typestore
        from roszen.bag.metadata import BagError
        wanted = [t for t in dict.fromkeys(topics) if t in self.topics]
        if not wanted:
            return
        decode = {t: typestore.deserializer(self.topics[t]) for t in wanted}
        lo, hi = (log_window[0] * 1e9, log_window[1] * 1e9) if log_window else (-1.0, math.inf)
        try:
            yield from self._decoded(self._reader.messages(wanted), decode, lo, hi)
        except (BagError, OSError) as exc:
            raise RecordingError(str(exc)) from None

    @staticmethod
    def _decoded(records: Iterable[Any], decode: dict[str, Callable[[bytes], Any]],
                 lo: float, hi: float) -> Iterator[Recorded]:
        for m in records:
            if not lo <= m.publish_time_ns <= hi:  # wall receive time (log time may be sim time)
                continue
            try:
                msg = decode[m.topic.name](m.data)
            except Exception:  # noqa: BLE001 - see messages' docstring
                continue
            yield Recorded(m.topic.name, m.topic.type, int(m.publish_time_ns),
                           int(m.log_time_ns), msg)


def read(bag_dir: str | os.PathLike, topics: Iterable[str],
         log_window: tuple[float, float] | None = None) -> Iterator[Recorded]:
    """Recording(bag_dir).messages(topics, log_window)."""
    return Recording(bag_dir).messages(topics, log_window)
