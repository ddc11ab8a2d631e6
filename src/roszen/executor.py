"""Single-threaded executor: zenoh threads enqueue work, spin()/spin_once() run callbacks.

Hand-off protocol (cheap for the zenoh threads): a producer appends its item to the entity's
deque and, when the entity is not yet scheduled, the entity to the executor's ready deque; it
pokes the wake-up queue only when the executor said it is idle (one wake-up per batch, not per
message). Both deques are thread-safe for append/popleft.
"""
from __future__ import annotations

import collections
import queue
import threading
import time
import weakref
from typing import Optional


_pending_interrupts: list = []
_executors: "weakref.WeakSet" = weakref.WeakSet()


def raise_pending() -> None:
    """Raise a KeyboardInterrupt/SystemExit that a zenoh callback caught (see node._reraise_on_main)."""
    if _pending_interrupts:
        exc = _pending_interrupts[0]
        _pending_interrupts.clear()
        raise exc


def request_interrupt() -> None:
    """Deliver a KeyboardInterrupt at the next executor step or publish (signal-handler safe).

    For a SIGINT handler: raising KeyboardInterrupt in the handler itself can land inside a
    zenoh callback running on the main thread, where zenoh swallows it ("callback error") and
    the node keeps running. Queued here, it is raised on the main thread outside zenoh, and
    every executor is woken so a blocked spin sees it at once."""
    _pending_interrupts.append(KeyboardInterrupt())
    for ex in list(_executors):
        ex.wake()


class Executor:
    """Runs the callbacks of its nodes one at a time on the spinning thread."""

    def __init__(self) -> None:
        self._ready: collections.deque = collections.deque()
        self._wakeq: "queue.SimpleQueue" = queue.SimpleQueue()
        self._idle = False
        self._nodes: list = []
        self._spin_lock = threading.Lock()
        self._shutdown = False
        _executors.add(self)

    # -- called from zenoh threads ------------------------------------------------------------
    def schedule(self, ent) -> None:
        """Mark an entity with pending work; it is queued once until its buffer is drained.

        Lock-free: no wake-up is lost because the executor publishes `_idle` before re-checking
        the ready deque, and a producer reads `_idle` after appending; a spurious wake-up is
        harmless (the executor finds no work and waits again).
        """
        if not ent._scheduled:
            ent._scheduled = True
            self._ready.append(ent)
            if self._idle:
                self._idle = False
                self._wakeq.put(None)

    def wake(self) -> None:
        """Interrupt a wait (timers changed, node destroyed, shutdown)."""
        self._wakeq.put(None)

    # -- nodes --------------------------------------------------------------------------------
    def add_node(self, node) -> bool:
        if node in self._nodes:
            return False
        old = getattr(node, "_executor", None)
        if old is not None and old is not self:
            old.remove_node(node)
        self._nodes.append(node)
        node._executor = self
        for ent in node._entities_with_work():
            ent._scheduled = False
            self.schedule(ent)
        self.wake()
        return True

    def remove_node(self, node) -> None:
        if node in self._nodes:
            self._nodes.remove(node)

    def get_nodes(self) -> list:
        return list(self._nodes)

    def shutdown(self, timeout_sec: Optional[float] = None) -> bool:
        self._shutdown = True
        self.wake()
        return True

    # -- running ------------------------------------------------------------------------------
    def _timers(self) -> list:
        nodes = self._nodes
        if len(nodes) == 1:
            return nodes[0]._timers
        out = []
        for n in nodes:
            out.extend(n._timers)
        return out

    def _run_due_timer(self) -> bool:
        for t in self._timers():
            if t._is_due():
                t._fire()
                return True
        return False

    def _wait_for_timers(self) -> Optional[float]:
        """Wall seconds until the next wall-clock timer (None: no such timer)."""
        best = None
        for t in self._timers():
            w = t._wall_wait()
            if w is not None and (best is None or w < best):
                best = w
        return best

    def _wait(self, timeout: Optional[float]) -> None:
        """Block until work is scheduled, wake() is called or `timeout` (None: forever) passes."""
        self._idle = True
        if self._ready:  # scheduled between the caller's check and `_idle` being seen
            self._idle = False
            return
        try:
            if timeout is None:
                self._wakeq.get()
            elif timeout > 0:
                self._wakeq.get(timeout=timeout)
        except queue.Empty:
            pass
        self._idle = False

    def _next_entity(self, timeout: Optional[float]):
        """The next ready entity, waiting up to `timeout` (capped by wall timers); None if none."""
        ready = self._ready
        if not ready:
            tw = self._wait_for_timers()
            if tw is not None:
                timeout = tw if timeout is None else min(timeout, tw)
            if timeout is not None and timeout <= 0:
                return None
            self._wait(timeout)
            if not ready:
                return None
        return ready.popleft()

    def spin_once(self, timeout_sec: Optional[float] = None) -> bool:
        """Run at most one callback; wait up to timeout_sec (None = forever) for work."""
        with self._spin_lock:
            raise_pending()
            if self._run_due_timer():
                return True
            ent = self._next_entity(timeout_sec)
            if ent is None:
                return self._run_due_timer()
            return self._run_entity(ent, 1)

    def _run_entity(self, ent, batch: int) -> bool:
        """Run up to `batch` pending items of one entity, then requeue it if work is left.

        A KeyboardInterrupt/SystemExit raised by a callback propagates out of spin (callbacks
        catch only Exception); the entity is requeued first so a later spin still serves it.
        """
        ran = False
        try:
            ran = ent._run(batch)
        finally:
            if ent._has_work():
                self._ready.append(ent)  # more pending: go to the back of the line (fairness)
            else:
                ent._scheduled = False
                if ent._has_work():  # raced with a producer that saw the flag still set: take it back
                    ent._scheduled = True
                    self._ready.append(ent)
        return ran

    def _spin_some(self, timeout_sec: float, batch: int = 64) -> None:
        """spin()'s step: like spin_once but drains up to `batch` items of one entity."""
        with self._spin_lock:
            raise_pending()
            if self._run_due_timer():
                return
            ent = self._next_entity(timeout_sec)
            if ent is None:
                self._run_due_timer()
                return
            self._run_entity(ent, batch)

    def spin(self) -> None:
        """Run callbacks until shutdown or every node is destroyed."""
        self._shutdown = False
        while not self._shutdown and any(n._alive for n in self._nodes) and \
                all(n.context.ok() for n in self._nodes):
            self._spin_some(0.5)

    def spin_until_future_complete(self, future, timeout_sec: Optional[float] = None) -> None:
        end = None if timeout_sec is None else time.monotonic() + timeout_sec
        while not future.done():
            rem = None if end is None else end - time.monotonic()
            if rem is not None and rem <= 0:
                return
            self.spin_once(0.05 if rem is None else min(0.05, rem))


SingleThreadedExecutor = Executor


def spin_once(node, *, executor: Optional[Executor] = None, timeout_sec: Optional[float] = None) -> bool:
    return (executor or node._executor).spin_once(timeout_sec)


def spin(node, executor: Optional[Executor] = None) -> None:
    ex = executor or node._executor
    if node not in ex._nodes:
        ex.add_node(node)
    ex.spin()


def spin_until_future_complete(node, future, executor: Optional[Executor] = None,
                               timeout_sec: Optional[float] = None) -> None:
    (executor or node._executor).spin_until_future_complete(future, timeout_sec)
