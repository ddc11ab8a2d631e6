"""Ctrl-C and zenoh: SIGINT handlers that never let a KeyboardInterrupt be swallowed by zenoh.

zenoh-python runs some callbacks on the calling thread (a put delivered to a subscriber of the
same session runs it inside the put) and swallows what they raise ("callback error"). Python's
default handler raises wherever the main thread is, so a Ctrl-C landing at such a callback's
first line, before its guard's try, was lost. Two handlers:
- `install_deferred` (node_main, a node executable): the first SIGINT is queued and raised at
  the next executor step or publish, outside zenoh; a second one raises at once.
- `install_guard` (a context's start, as rclpy.init installs its handlers; only over Python's
  default handler): raises at once like the default, except inside a zenoh callback, where it
  queues the interrupt the same way.
"""
from __future__ import annotations

import signal
import threading
from types import CodeType, FrameType
from typing import Any, Callable, Optional

_ZENOH_CALLBACKS: set[CodeType] = set()


def zenoh_callback(fn: Callable) -> Callable:
    """Mark `fn` as a function zenoh may call on the main thread (inside a put or get); a SIGINT
    that finds it on the main thread's stack is deferred. Returns `fn` unchanged (no cost)."""
    _ZENOH_CALLBACKS.add(fn.__code__)
    return fn


def in_zenoh_callback(frame: Optional[FrameType]) -> bool:
    """Whether `frame` or one of its callers is a marked zenoh callback (or the put around it)."""
    while frame is not None:
        if frame.f_code in _ZENOH_CALLBACKS:
            return True
        frame = frame.f_back
    return False


def _set(handler: Callable) -> Any:
    if threading.current_thread() is not threading.main_thread():
        return None
    try:
        return signal.signal(signal.SIGINT, handler)
    except ValueError:
        return None


def install_deferred() -> Any:
    """Make SIGINT a deferred KeyboardInterrupt: the previous handler, or None off the main thread."""
    from .executor import request_interrupt
    count = [0]

    def deferred(signum: int, frame: Optional[FrameType]) -> None:  # noqa: ARG001
        count[0] += 1
        if count[0] > 1:
            raise KeyboardInterrupt
        request_interrupt()
    return _set(deferred)


def _guard(signum: int, frame: Optional[FrameType]) -> None:  # noqa: ARG001
    if in_zenoh_callback(frame):
        from .executor import request_interrupt
        request_interrupt()
        return
    raise KeyboardInterrupt


def install_guard() -> None:
    """Over Python's default SIGINT handler only (a program's own handler is left alone): raise
    at once, but defer inside a zenoh callback. Idempotent; a no-op off the main thread."""
    if threading.current_thread() is threading.main_thread() and \
            signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        _set(_guard)
