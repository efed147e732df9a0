"""Runtime.run: tick on absolute deadlines, with the process set up for it, until the state machine stops.

Timing uses absolute deadlines on the runtime's clock: deadline_k = start + k * dt; the loop sleeps until the next
deadline (never `sleep(dt)` after compute), counts overruns (too many within a window, or one more than
max_stall_periods late, is a fault: deploy.loop_timing) and skips deadlines it has already missed. Each tick's
lateness, period and compute time are recorded. Around the loop (deploy.realtime): SCHED_FIFO when asked, memory
locked on real runs, gc frozen and off during POLICY, a short GIL switch interval; after each tick the watchdog
gets its heartbeat (deploy.watchdog). A crash sends damping first, then records why.

These functions drive a deploy.loop.Runtime and use its internals; they live here so loop.py holds the tick.
"""

from __future__ import annotations

import contextlib

from deploy.realtime import RealtimeRun
from deploy.safety import COMMANDING_PHASES, Phase


def run_loop(runtime, duration_s: float | None) -> dict:
    clock = runtime.clock
    crashed = False
    with RealtimeRun(runtime.gil_switch_interval_s, runtime.realtime_priority, runtime.lock_memory) as rt:
        runtime.scheduling, runtime.memory, runtime._realtime = rt.scheduling, rt.memory, rt
        memory_problem = None if rt.memory == "locked" or not runtime.lock_memory else f"memory {rt.memory}"
        for problem in (rt.scheduling_problem, memory_problem):
            if problem:
                runtime.events.log("warning", reason=problem)
        start = clock.now()
        runtime.phase_since = start
        deadline = start
        runtime.events.log("start", rate_hz=1.0 / runtime.dt, policy=runtime.contract.source, duration_s=duration_s,
                           scheduling=runtime.scheduling, memory=runtime.memory,
                           watchdog=runtime.watchdog.description)
        runtime.watchdog.start(lambda: runtime._send_damping(None))
        try:
            while True:
                wake = clock.now()
                if duration_s is not None and wake - start >= duration_s and runtime.stops.first is None:
                    runtime.request_stop("duration reached", "duration")
                    if runtime.phase == Phase.WAIT_STATE:
                        runtime.exit_reason = "duration reached before inputs were ready"
                keep_going = runtime.tick(deadline)
                runtime.watchdog.beat(commanding=runtime.phase != Phase.WAIT_STATE)
                done = clock.now()
                runtime.timing.record(wake, deadline, done)
                runtime._show_status()
                if not keep_going or (runtime.exit_reason and runtime.phase == Phase.WAIT_STATE):
                    break
                deadline += runtime.dt
                if done > deadline:
                    deadline += _overrun(runtime, done, deadline) * runtime.dt
                clock.sleep_until(deadline)
        except BaseException as exc:
            crashed = True
            _crash_damping(runtime, exc)
            raise
        finally:
            runtime._realtime = None
            runtime.watchdog.end(clean=not crashed)  # after a crash it stays armed: it damps when we are gone
            _close_phase_time(runtime, clock.now())
            with contextlib.suppress(Exception):  # the robot is damped; what is left is paperwork
                runtime.events.log("stop", reason=runtime.exit_reason or runtime.stops.reason or "",
                                   ticks=runtime.ticks, final_phase=runtime.phase.name, outcome=runtime.outcome.name)
                runtime.events.sync(wait_s=2.0)
                runtime.recorder.sync(wait_s=2.0)
    return runtime.summary()


def _close_phase_time(runtime, end: float) -> None:
    name = runtime.phase.name
    runtime.phase_time[name] = runtime.phase_time.get(name, 0.0) + (end - runtime.phase_since)
    runtime.phase_since = end


def _crash_damping(runtime, exc: BaseException) -> None:
    """The loop broke: damping goes out first, then the record of why."""
    try:
        runtime._send_damping(None)
    except Exception as send_exc:
        runtime.body_send_errors += 1
        exc.add_note(f"the damping command could not be sent either: {send_exc}")
    runtime.exit_reason = runtime.exit_reason or f"crashed: {type(exc).__name__}: {exc}"
    with contextlib.suppress(Exception):
        runtime.events.log("error", tick=runtime.ticks, reason=f"runtime crashed: {type(exc).__name__}: {exc}")


def _overrun(runtime, done: float, next_deadline: float) -> int:
    """Count it, log it, fault on too many or one too long; returns the deadlines to skip."""
    timing = runtime.timing
    skipped = timing.overrun(done, next_deadline)
    if timing.overruns <= 10 or timing.overruns % 100 == 0:
        runtime.events.log("overrun", tick=runtime.ticks, late_ms=(done - next_deadline) * 1e3, skipped=skipped,
                           count=timing.overruns)
    problem = timing.overrun_fault()
    if problem and runtime.phase in COMMANDING_PHASES and problem not in runtime._deferred_faults:
        runtime._deferred_faults.append(problem)
    return skipped
