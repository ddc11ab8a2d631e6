"""The mission's one progress line: \\r-updated on a terminal, a plain line every few s otherwise."""
from __future__ import annotations

import sys
import time


class Progress:
    """One progress line: \\r-updated on a tty, a plain line every `period` s otherwise."""

    def __init__(self, stream=None, period: float = 5.0) -> None:
        self.stream = stream or sys.stdout
        self.tty = self.stream.isatty()
        self.period = period
        self._last = 0.0
        self._width = 0

    def update(self, text: str) -> None:
        now = time.monotonic()
        if self.tty:
            if now - self._last < 0.1:
                return
            self.stream.write("\r" + text.ljust(self._width))
            self._width = len(text)
        else:
            if now - self._last < self.period:
                return
            self.stream.write(text + "\n")
        self._last = now
        self.stream.flush()

    def done(self, text: str) -> None:
        if self.tty:
            self.stream.write("\r" + text.ljust(self._width) + "\n")
        else:
            self.stream.write(text + "\n")
        self._width = 0
        self._last = 0.0
        self.stream.flush()
