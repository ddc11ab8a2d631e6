"""sim_node's main loop: step the backend to each publish tick, paced by the clock mode.

realtime: paced to the wall clock (callbacks served while waiting; far behind, it stops trying to
catch up). fast: no pacing. lockstep: before each tick the loop waits for every commanded robot's
answer to the last state (at most `lockstep_timeout` s of wall time, `lockstep_start_timeout` at
the first tick; on timeout it logs and steps on). Paused (start_paused, /sim/control PAUSE, or
a RESUME budget spent) it only serves callbacks and, in a run that starts paused, publishes
/clock every PAUSED_CLOCK_PERIOD wall s (the controllers' sign of a deliberate pause: their
stall check comes after 1 s; a pause mid-run sends its first one that period after pausing).
"""
from __future__ import annotations

import time
from typing import Any

PAUSED_CLOCK_PERIOD = 0.5   # wall s between the /clock messages of a paused sim (start_paused)


class TickLoop:
    """Tick count, pause state and pacing of one SimNode (see the module docstring)."""

    def __init__(self, host: Any, opts: Any) -> None:
        """host: the SimNode (node, sim, names, commands, state, now_ns(), warn(), log);
        opts: its SimOptions."""
        self.host = host
        self.clock_mode = opts.clock_mode
        self.publish_rate = opts.publish_rate
        self.lockstep_timeout = opts.lockstep_timeout
        self.lockstep_start_timeout = opts.lockstep_start_timeout
        self.max_sim_time = opts.max_sim_time
        self.start_paused = opts.start_paused
        self.paused = opts.start_paused
        self.pause_at_tick: int | None = None    # RESUME with steps: pause after this tick
        self._last_clock = -1e9                  # wall time of the last paused /clock
        self.tick = 0
        self._wall0 = time.monotonic()
        self._sim0 = 0.0
        self._run_mark: tuple | None = None     # (wall, CPU, sim time) at the run's first tick

    # ---- control (services) ------------------------------------------------------------
    def restart(self) -> None:
        """After a reset: tick 0 at sim time 0; paused again when the run starts paused."""
        self.tick = 0
        self._wall0, self._sim0 = time.monotonic(), 0.0
        if self.start_paused:          # deterministic runs: the client resumes when ready
            self.paused, self.pause_at_tick = True, None

    def pause(self) -> None:
        self._paused_now()

    def _paused_now(self) -> None:
        """Pause mid-run; the paused /clock starts a period from now (a short pause between
        two RESUME chunks sends none)."""
        self.paused, self.pause_at_tick = True, None
        self._last_clock = time.monotonic()

    def resume(self, steps: int) -> float | None:
        """Run on; with steps > 0 until that many more physics steps are done (rounded up to a
        publish tick), returning the sim time it will pause at."""
        self.paused = False
        self._wall0, self._sim0 = time.monotonic(), self.host.sim.time
        if steps > 0:
            self.pause_at_tick, t_pause = self.tick_after(steps)
            return t_pause
        self.pause_at_tick = None
        return None

    def tick_after(self, steps: int) -> tuple[int, float]:
        """The first publish tick at which `steps` more physics steps are done, and the sim
        time then (summed step by step as the backend does, so equal to its stamp)."""
        sim = self.host.sim
        k, n, t, dt = self.tick, sim.steps, sim.time, sim.dt
        goal = n + steps
        while n < goal:
            k += 1
            m = max(1, int(round(k / self.publish_rate / dt)) - n)
            n += m
            for _ in range(m):
                t += dt
        return k, t

    # ---- the loop ----------------------------------------------------------------------
    def drain(self, timeout: float = 0.0) -> None:
        """Run the callbacks that are ready (waiting up to `timeout` for the first)."""
        node = self.host.node
        if node.spin_once(timeout_sec=timeout):
            while node.spin_once(timeout_sec=0):
                pass

    def wait_commands(self) -> None:
        """Lockstep: wait for a command stamped >= the current tick from every commanded robot
        (CommandInbox.late). At the first tick (after start or a reset) up to
        `lockstep_start_timeout`, later ticks up to `lockstep_timeout`; on timeout it logs and
        steps on. While waiting it republishes the state every 0.5 s (a late subscriber may
        have missed it), except in a paused start (every subscriber was there before)."""
        host = self.host
        t = host.now_ns()
        first = self.tick == 0
        limit = self.lockstep_start_timeout if first else self.lockstep_timeout
        end = time.monotonic() + limit
        next_pub = time.monotonic() + 0.5
        late = host.commands.late(t, first)
        while late:
            now = time.monotonic()
            if now >= end:
                host.warn("lockstep", f"lockstep: no command for t={t / 1e9:.3f} s from {late} "
                          f"within {limit:g} s; stepping on")
                return
            if now >= next_pub and not self.start_paused:
                host.state.publish()
                next_pub = now + 0.5
            self.drain(min(end - now, 0.02))
            late = host.commands.late(t, first)

    def run_tick(self) -> None:
        """Wait (lockstep), step to the next publish tick, publish."""
        sim = self.host.sim
        if self.clock_mode == "lockstep":
            self.wait_commands()
        if self.tick == 0:                  # the run (since start or the last reset) begins
            self._run_mark = (time.perf_counter(), time.process_time(), sim.time)
        self.tick += 1
        target = int(round(self.tick / self.publish_rate / sim.dt))
        sim.step(max(1, target - sim.steps))
        self.host.state.publish()

    def rate(self) -> str:
        """': S sim s in W wall s (Rx real time), C CPU s (Px per CPU s)' since the run's first
        tick ('' before one); the CPU is this process's, its transport threads included."""
        mark = self._run_mark
        if mark is None:
            return ""
        wall, cpu, sim = (time.perf_counter() - mark[0], time.process_time() - mark[1],
                          self.host.sim.time - mark[2])
        return (f": {sim:.3f} sim s in {wall:.3f} wall s ({sim / max(wall, 1e-9):.1f}x real time), "
                f"{cpu:.3f} CPU s ({sim / max(cpu, 1e-9):.1f}x per CPU s)")

    def spin(self) -> None:
        """Tick until shutdown, the node's end or max_sim_time."""
        from roszen import runtime as roszen
        host = self.host
        sim = host.sim
        while roszen.ok() and host.node._alive:
            if self.max_sim_time and sim.time >= self.max_sim_time:
                host.log.info(f"max_sim_time {self.max_sim_time:g} s reached{self.rate()}")
                return
            self.drain(0.0)
            if self.paused:
                if self.start_paused and time.monotonic() - self._last_clock >= PAUSED_CLOCK_PERIOD:
                    self._last_clock = time.monotonic()      # sim time for late nodes and
                    host.state.publish_clock()                # the recorder (no state)
                self.drain(0.05)
                continue
            self.run_tick()
            if self.pause_at_tick is not None and self.tick >= self.pause_at_tick:
                self._paused_now()
            if self.clock_mode == "realtime":
                ahead = (sim.time - self._sim0) - (time.monotonic() - self._wall0)
                while ahead > 0:           # serve callbacks while waiting for the wall clock
                    self.drain(ahead)
                    ahead = (sim.time - self._sim0) - (time.monotonic() - self._wall0)
                if ahead < -1.0:        # far behind: do not try to catch up in a burst
                    host.warn("behind", f"sim running behind real time by {-ahead:.1f} s")
                    self._wall0, self._sim0 = time.monotonic(), sim.time

