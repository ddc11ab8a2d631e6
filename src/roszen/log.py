"""rclpy-style loggers: `[INFO] [<epoch>] [name]: msg` on stderr, optional /rosout sink."""
from __future__ import annotations

import enum
import os
import re
import sys
import threading
import time
from typing import Callable, Optional


class LoggingSeverity(enum.IntEnum):
    UNSET = 0
    DEBUG = 10
    INFO = 20
    WARN = 30
    ERROR = 40
    FATAL = 50


_NAMES = {LoggingSeverity.DEBUG: "DEBUG", LoggingSeverity.INFO: "INFO", LoggingSeverity.WARN: "WARN",
          LoggingSeverity.ERROR: "ERROR", LoggingSeverity.FATAL: "FATAL"}
_lock = threading.Lock()
_default_level = LoggingSeverity.INFO


def severity_from_name(name: str) -> LoggingSeverity:
    key = name.strip().upper()
    key = {"WARNING": "WARN"}.get(key, key)
    try:
        return LoggingSeverity[key]
    except KeyError:
        raise ValueError(f"unknown log level {name!r} (DEBUG, INFO, WARN, ERROR, FATAL)") from None


def _env_int(name: str, default: int) -> int:
    try:
        return int(os.environ.get(name, default))
    except ValueError:
        return default


# Flood control (a hostile peer can make a node log once per bad sample):
# RATE_LIMIT records a second of one message shape from one call site (0: unlimited), SITE_LIMIT
# records a second from one call site whatever the text, MAX_CHARS characters per record.
RATE_LIMIT = _env_int("ROSZEN_LOG_RATE_LIMIT", 10)
SITE_LIMIT = _env_int("ROSZEN_LOG_SITE_LIMIT", 50)
MAX_CHARS = _env_int("ROSZEN_LOG_MAX_CHARS", 8192)
_VARYING = re.compile(r"[0-9a-fA-F]{8,}|\d+")


def truncate(msg: str, limit: int = 0) -> str:
    """`msg` cut to `limit` (default MAX_CHARS) characters with a note of its full length."""
    limit = limit or MAX_CHARS
    if limit <= 0 or len(msg) <= limit:
        return msg
    return f"{msg[:limit]}... [truncated, {len(msg)} characters]"


class _Limiter:
    """Per-second budgets keyed by call site and by (site, message shape), counting what it drops.

    The shape is the message with numbers and hex runs blanked, so "bad sample (12 bytes) from
    ab12..." floods count as one message. allow() returns (emit, suppressed since last emit).
    """

    def __init__(self) -> None:
        self._win: dict = {}       # key -> [window start, count in window]
        self._suppressed: dict = {}
        self.clock = time.monotonic

    def _take(self, key, limit: int, now: float) -> bool:
        w = self._win.get(key)
        if w is None or now - w[0] >= 1.0:
            if len(self._win) > 4096:   # bounded: forget old windows
                self._win.clear()
            self._win[key] = [now, 1]
            return True
        if w[1] >= limit:
            return False
        w[1] += 1
        return True

    def allow(self, site, msg: str) -> "tuple[bool, int]":
        if RATE_LIMIT <= 0:
            return True, 0
        now = self.clock()
        shape = (site, _VARYING.sub("#", msg[:256]))
        ok = self._take(shape, RATE_LIMIT, now) and (SITE_LIMIT <= 0 or self._take(site, SITE_LIMIT, now))
        if not ok:
            if len(self._suppressed) > 4096:
                self._suppressed.clear()
            self._suppressed[shape] = self._suppressed.get(shape, 0) + 1
            return False, 0
        return True, self._suppressed.pop(shape, 0)


if os.environ.get("ROSZEN_LOG_LEVEL"):
    try:
        _default_level = severity_from_name(os.environ["ROSZEN_LOG_LEVEL"])
    except ValueError:
        pass


class Logger:
    """A named logger; `sink(level, name, msg, site)` mirrors records (e.g. to /rosout).

    Records go through flood control: at most RATE_LIMIT a second of one message (numbers
    blanked) from one call site, SITE_LIMIT from one site; the next record emitted says how
    many were suppressed. Records longer than MAX_CHARS are truncated.
    """

    def __init__(self, name: str, level: Optional[LoggingSeverity] = None) -> None:
        self.name = name
        self.level = level
        self.sink: Optional[Callable] = None
        self._once: set = set()
        self._last: dict = {}
        self._limiter = _Limiter()

    def get_child(self, suffix: str) -> "Logger":
        child = Logger(f"{self.name}.{suffix}" if self.name else suffix, self.level)
        child.sink = self.sink
        return child

    def set_level(self, level: "LoggingSeverity | str | int") -> None:
        self.level = severity_from_name(level) if isinstance(level, str) else LoggingSeverity(level)

    def get_effective_level(self) -> LoggingSeverity:
        return self.level if self.level else _default_level

    def is_enabled_for(self, level: LoggingSeverity) -> bool:
        return level >= self.get_effective_level()

    def log(self, msg: str, level: LoggingSeverity, *, once: bool = False,
            throttle_duration_sec: Optional[float] = None, skip_first: bool = False) -> bool:
        if not self.is_enabled_for(level):
            return False
        caller = sys._getframe(2)
        site = (caller.f_code.co_filename, caller.f_lineno, caller.f_code.co_name)
        del caller  # hold no frame (it would pin the caller's locals)
        msg = str(msg)
        if once or skip_first or throttle_duration_sec:
            if once:
                if site in self._once:
                    return False
                self._once.add(site)
            if skip_first and site not in self._last:
                self._last[site] = time.monotonic()
                return False
            if throttle_duration_sec:
                now = time.monotonic()
                if site in self._last and now - self._last[site] < throttle_duration_sec:
                    return False
                self._last[site] = now
        with _lock:
            emit, suppressed = self._limiter.allow(site, msg)
        if not emit:
            return False
        msg = truncate(msg)
        if suppressed:
            msg += f" (suppressed {suppressed} similar messages)"
        now = time.time()
        line = f"[{_NAMES.get(level, str(int(level)))}] [{now:.9f}] [{self.name}]: {msg}\n"
        with _lock:
            try:
                sys.stderr.write(line)
                sys.stderr.flush()
            except (OSError, ValueError):
                pass
        if self.sink is not None:
            try:
                self.sink(level, self.name, msg, site)
            except Exception:
                pass
        return True

    def debug(self, msg: str, **kw) -> bool:
        return self.log(msg, LoggingSeverity.DEBUG, **kw)

    def info(self, msg: str, **kw) -> bool:
        return self.log(msg, LoggingSeverity.INFO, **kw)

    def warning(self, msg: str, **kw) -> bool:
        return self.log(msg, LoggingSeverity.WARN, **kw)

    warn = warning

    def error(self, msg: str, **kw) -> bool:
        return self.log(msg, LoggingSeverity.ERROR, **kw)

    def fatal(self, msg: str, **kw) -> bool:
        return self.log(msg, LoggingSeverity.FATAL, **kw)


def get_logger(name: str) -> Logger:
    return Logger(name)


def set_default_level(level: "LoggingSeverity | str") -> None:
    global _default_level
    _default_level = severity_from_name(level) if isinstance(level, str) else LoggingSeverity(level)
