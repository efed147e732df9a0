"""Real-time setup of the control loop's process: SCHED_FIFO for the loop thread, memory locked, the garbage
collector kept out of POLICY.

    set_realtime / restore_scheduling   SCHED_FIFO at a priority (Linux; root or CAP_SYS_NICE)
    lock_memory / unlock_memory         mlockall(MCL_CURRENT | MCL_FUTURE): no page fault (a swapped-out page, a
                                        lazily mapped library) stalls a tick (root, CAP_IPC_LOCK or a high enough
                                        RLIMIT_MEMLOCK)
    GcGuard                             gc.freeze() at the start (every object alive then is never scanned again)
                                        and gc disabled while the policy runs: a full collection is a pause of
                                        tens of milliseconds at an unknown tick
    RealtimeRun                         all of it (and a short GIL switch interval) for one run, undone after
Where the OS refuses, the run goes on with a note saying why (events.jsonl, summary.json).
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import os
import sys

MCL_CURRENT, MCL_FUTURE = 1, 2  # sys/mman.h (Linux)


def set_realtime(priority: int | None) -> tuple[str, str | None]:
    """Give the calling thread SCHED_FIFO at `priority` (threads started before keep their own scheduling).
    Returns (scheduling, problem): problem says why it fell back to normal scheduling."""
    if priority is None:
        return "normal", None
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (AttributeError, PermissionError, OSError) as exc:
        return "normal", f"real-time priority not available ({exc}); normal scheduling"
    return f"SCHED_FIFO {priority}", None


def restore_scheduling(priority: int | None) -> None:
    if priority is not None:
        with contextlib.suppress(AttributeError, PermissionError, OSError):
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


def _libc():
    return ctypes.CDLL(None, use_errno=True)


def _mlockall(flags: int) -> int:
    """0, or the errno of mlockall(flags)."""
    if _libc().mlockall(flags) == 0:
        return 0
    return ctypes.get_errno()


def _munlockall() -> None:
    _libc().munlockall()


def lock_memory() -> str | None:
    """Lock the process's memory, present and future; None when locked, else why not (the run goes on)."""
    try:
        err = _mlockall(MCL_CURRENT | MCL_FUTURE)
    except (OSError, AttributeError) as exc:  # no libc mlockall (not Linux)
        return f"not locked ({exc})"
    if err:
        return (f"not locked ({os.strerror(err)}: needs root, CAP_IPC_LOCK or an RLIMIT_MEMLOCK above the "
                "process size)")
    return None


def unlock_memory() -> None:
    with contextlib.suppress(OSError, AttributeError):
        _munlockall()


class GcGuard:
    """gc.freeze() for the run, gc off during POLICY; `end()` puts everything back as it was."""

    def __init__(self) -> None:
        self._was_enabled = gc.isenabled()
        gc.collect()
        gc.freeze()

    def policy_running(self, running: bool) -> None:
        if running and gc.isenabled():
            gc.disable()
        elif not running and self._was_enabled and not gc.isenabled():
            gc.enable()

    def end(self) -> None:
        gc.unfreeze()
        if self._was_enabled:
            gc.enable()


class RealtimeRun:
    """Context manager around Runtime.run: what the loop changes about its process, undone at the end.
    `scheduling` and `memory` say what it got (for events.jsonl and summary.json)."""

    def __init__(self, gil_switch_interval_s: float | None, priority: int | None, lock: bool):
        self.gil_switch_interval_s = gil_switch_interval_s
        self.priority = priority
        self.lock = lock
        self.scheduling = "normal"
        self.scheduling_problem: str | None = None
        self.memory = "not locked (not requested)"
        self._gc: GcGuard | None = None

    def __enter__(self) -> RealtimeRun:
        self._previous_interval = sys.getswitchinterval()
        if self.gil_switch_interval_s is not None:
            sys.setswitchinterval(self.gil_switch_interval_s)
        self.scheduling, self.scheduling_problem = set_realtime(self.priority)
        if self.lock:
            problem = lock_memory()
            self.memory = problem or "locked"
        self._gc = GcGuard()
        return self

    def policy_running(self, running: bool) -> None:
        self._gc.policy_running(running)

    def __exit__(self, *exc_info) -> None:
        self._gc.end()
        if self.memory == "locked":
            unlock_memory()
        restore_scheduling(self.priority)
        sys.setswitchinterval(self._previous_interval)
