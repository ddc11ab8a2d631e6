"""rclpy-style loggers: `[INFO] [<epoch>] [name]: msg` on stderr, optional /rosout sink."""
from __future__ import annotations

import enum
import os
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


if os.environ.get("ROSZEN_LOG_LEVEL"):
    try:
        _default_level = severity_from_name(os.environ["ROSZEN_LOG_LEVEL"])
    except ValueError:
        pass


class Logger:
    """A named logger; `sink(level, name, msg, file, func, line)` mirrors records (e.g. to /rosout)."""

    def __init__(self, name: str, level: Optional[LoggingSeverity] = None) -> None:
        self.name = name
        self.level = level
        self.sink: Optional[Callable] = None
        self._once: set = set()
        self._last: dict = {}

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
        if once or skip_first or throttle_duration_sec:
            caller = sys._getframe(2)
            site = (caller.f_code.co_filename, caller.f_lineno)
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
                self.sink(level, self.name, str(msg))
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
