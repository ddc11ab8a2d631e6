"""Timer (fired by the executor on a node clock) and Rate (sleeps a loop to a frequency)."""
from __future__ import annotations

import time
import traceback
from typing import TYPE_CHECKING, Callable, Optional

from .clock import Clock, Duration

if TYPE_CHECKING:
    from .node import Node


class Timer:
    """Periodic callback on the node clock (sim time when use_sim_time), run by the executor."""

    def __init__(self, node: "Node", period_sec: float, callback: Callable, clock: Clock) -> None:
        if period_sec <= 0:
            raise ValueError(f"timer period must be > 0, got {period_sec}")
        self.node = node
        self.callback = callback
        self.clock = clock
        self.timer_period_ns = int(round(period_sec * 1e9))
        self._canceled = False
        self._next = clock.now_ns() + self.timer_period_ns

    @property
    def is_canceled(self) -> bool:
        return self._canceled

    def is_canceled_(self) -> bool:
        return self._canceled

    def cancel(self) -> None:
        self._canceled = True

    def reset(self) -> None:
        self._canceled = False
        self._next = self.clock.now_ns() + self.timer_period_ns

    def time_until_next_call(self) -> Optional[int]:
        return None if self._canceled else self._next - self.clock.now_ns()

    def _is_due(self) -> bool:
        return not self._canceled and self.clock.now_ns() >= self._next

    def _wall_wait(self) -> Optional[float]:
        if self._canceled or self.clock.ros_time_is_active:
            return None
        return max(0.0, (self._next - time.time_ns()) * 1e-9)

    def _fire(self) -> None:
        now = self.clock.now_ns()
        self._next += self.timer_period_ns
        if self._next <= now:  # late by more than a period: realign to the grid
            self._next = now + self.timer_period_ns - ((now - self._next) % self.timer_period_ns)
        try:
            self.callback()
        except Exception:
            self.node.get_logger().error(f"timer callback raised:\n{traceback.format_exc().rstrip()}")

    def destroy(self) -> None:
        self.cancel()


class Rate:
    """Sleeps to keep a loop at a frequency on a clock (do not use inside callbacks)."""

    def __init__(self, clock: Clock, frequency: float) -> None:
        self._clock = clock
        self._period = Duration(seconds=1.0 / frequency)
        self._next = clock.now() + self._period

    def sleep(self) -> None:
        self._clock.sleep_until(self._next)
        self._next = self._next + self._period
        if self._next < self._clock.now():
            self._next = self._clock.now() + self._period
