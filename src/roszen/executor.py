"""Single-threaded executor: zenoh threads enqueue work, spin()/spin_once() run callbacks."""
from __future__ import annotations

import queue
import threading
import time
from typing import Optional


class Executor:
    """Runs the callbacks of its nodes one at a time on the spinning thread."""

    def __init__(self) -> None:
        self._ready: "queue.SimpleQueue" = queue.SimpleQueue()
        self._nodes: list = []
        self._spin_lock = threading.Lock()
        self._shutdown = False

    # -- called from zenoh threads ------------------------------------------------------------
    def schedule(self, ent) -> None:
        """Mark an entity with pending work; it is queued once until its buffer is drained.

        Lock-free: a lost wake-up is impossible because the executor re-checks the buffer after
        clearing the flag; a duplicate entry in the ready queue is harmless (it finds no work).
        """
        if not ent._scheduled:
            ent._scheduled = True
            self._ready.put(ent)

    def wake(self) -> None:
        self._ready.put(None)

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
        out = []
        for n in self._nodes:
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

    def spin_once(self, timeout_sec: Optional[float] = None) -> bool:
        """Run at most one callback; wait up to timeout_sec (None = forever) for work."""
        with self._spin_lock:
            if self._run_due_timer():
                return True
            wait = timeout_sec
            tw = self._wait_for_timers()
            if tw is not None:
                wait = tw if wait is None else min(wait, tw)
            try:
                if wait is None:
                    ent = self._ready.get()
                elif wait <= 0:
                    ent = self._ready.get_nowait()
                else:
                    ent = self._ready.get(timeout=wait)
            except queue.Empty:
                return self._run_due_timer()
            if ent is None:
                return self._run_due_timer()
            return self._run_entity(ent, 1)

    def _run_entity(self, ent, batch: int) -> bool:
        """Run up to `batch` pending items of one entity, then requeue it if work is left."""
        ran = False
        for _ in range(batch):
            item = ent._pop()
            if item is None:
                ent._scheduled = False
                if ent._has_work():  # raced with a producer: take it back
                    ent._scheduled = True
                    self._ready.put(ent)
                return ran
            ent._execute(item)
            ran = True
        self._ready.put(ent)  # more may be pending: go to the back of the line (fairness)
        return ran

    def _spin_some(self, timeout_sec: float, batch: int = 32) -> None:
        """spin()'s step: like spin_once but drains up to `batch` items of one entity."""
        with self._spin_lock:
            if self._run_due_timer():
                return
            wait = timeout_sec
            tw = self._wait_for_timers()
            if tw is not None:
                wait = min(wait, tw)
            try:
                ent = self._ready.get(timeout=wait) if wait > 0 else self._ready.get_nowait()
            except queue.Empty:
                self._run_due_timer()
                return
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
