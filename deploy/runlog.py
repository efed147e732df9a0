"""Run logs: decisions as JSON lines and per-tick records in npz chunks, written by background threads.

    LOG_DIR/events.jsonl         one JSON object per decision: phase changes, faults, clamps, operator, overruns
    LOG_DIR/ticks/chunk_NNNNN.npz every command and state, per-tick timing
    LOG_DIR/summary.json         written by the CLI at the end

The control loop never waits for the disk and never sees a write error: it hands lines and tick rows to a writer
thread, which writes them at most a second after they happened (sooner at `sync()`: the runtime calls it after
the commands of a tick that changed phase are out, and at the end; those writes are fsynced). A write that fails
(disk full, disk gone) is counted with what it lost and the last error; `report()` says so for summary.json. The
in-memory events stay complete either way.

`load_ticks(LOG_DIR)` concatenates the chunks back into one dict of arrays.
"""

from __future__ import annotations

import io
import json
import logging
import os
import queue
import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np

from deploy.atomic import atomic_write_bytes
from deploy.clock import Clock

log = logging.getLogger("deploy.runtime")

FLUSH_EVERY_S = 1.0  # longest a record stays only in memory (unless the writer is stuck on the disk)


def _jsonable(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.integer | np.floating | np.bool_):
        return value.item()
    return str(value)


class _Writer:
    """A thread that runs write jobs in order. A failed job is counted with the records it carried; nothing is
    raised to the thread that submitted it."""

    def __init__(self, name: str):
        self.errors = 0
        self.lost = 0
        self.last_error: str | None = None
        self._queue: queue.Queue = queue.Queue()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, job: Callable[[], None], records: int) -> None:
        self._queue.put((job, records))

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            try:
                if item is None:
                    return
                job, records = item
                try:
                    job()
                except Exception as exc:  # disk full, disk gone, permissions: count it, keep going
                    self.errors += 1
                    self.lost += records
                    self.last_error = str(exc)
            finally:
                self._queue.task_done()

    def wait_idle(self, timeout_s: float) -> bool:
        """Wait up to timeout_s for the submitted jobs (False: the disk is still busy with them)."""
        done = threading.Event()
        self._queue.put((done.set, 0))
        return done.wait(timeout_s)

    def close(self, timeout_s: float) -> None:
        self._queue.put(None)
        self._thread.join(timeout_s)

    def report(self) -> dict:
        return {"errors": self.errors, "lost": self.lost, "last_error": self.last_error}


NO_WRITES = {"errors": 0, "lost": 0, "last_error": None}


class _BackgroundLog:
    """What the event log and the tick recorder share: records go to the disk on a _Writer thread (None: nothing is
    written); `_written` keeps that writer after close() for report()."""

    _writer: _Writer | None
    _written: _Writer | None

    def _hand_over(self) -> None:
        """Pass every pending record to the writer, to be written and fsynced."""
        raise NotImplementedError

    def sync(self, wait_s: float | None = None) -> None:
        """Hand everything pending to the writer, to be written and fsynced; wait up to wait_s for the disk."""
        if self._writer is None:
            return
        self._hand_over()
        if wait_s is not None:
            self._writer.wait_idle(wait_s)

    def wait_idle(self, timeout_s: float) -> bool:
        return True if self._writer is None else self._writer.wait_idle(timeout_s)

    def report(self) -> dict:
        """Failed writes, the records they lost and the last error (summary.json 'logs')."""
        return NO_WRITES.copy() if self._written is None else self._written.report()


class EventLog(_BackgroundLog):
    """Structured decision log: kept in memory (for the summary and tests) and appended to events.jsonl."""

    def __init__(self, clock: Clock, path: str | Path | None = None, max_in_memory: int = 10000,
                 flush_every_s: float = FLUSH_EVERY_S):
        self.clock = clock
        self.events: list[dict] = []
        self.max_in_memory = max_in_memory
        self.dropped = 0
        self.flush_every_s = flush_every_s
        self._file = None
        self._writer: _Writer | None = None
        self._pending: list[str] = []
        self._last_flush = float("-inf")
        if path is not None:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            self._file = open(path, "a")  # opened here: an unwritable log dir fails at start-up, not mid-run
            self._writer = _Writer("event-writer")
        self._written = self._writer  # kept after close() for report()

    def log(self, event: str, **fields) -> dict:
        """Record a decision; never raises (the loop calls this between a fault and its damping command)."""
        now = self.clock.now()
        record = {"t": now, "event": event, **fields}
        if len(self.events) < self.max_in_memory:
            self.events.append(record)
        else:
            self.dropped += 1
        if self._writer is not None:
            try:
                line = json.dumps(record, default=_jsonable)
            except (TypeError, ValueError):  # e.g. a value that contains itself: keep what it was
                line = json.dumps({"t": now, "event": event, "fields": repr(fields)})
            self._pending.append(line + "\n")
        level = logging.WARNING if event in ("fault", "overrun", "error") else logging.INFO
        log.log(level, "%s %s", event, {k: v for k, v in fields.items()})
        return record

    def flush_due(self) -> None:
        """Hand the pending lines to the writer if the last hand-over is flush_every_s old (the loop calls this
        once a tick, after its commands are out)."""
        now = self.clock.now()
        if self._writer is not None and self._pending and now - self._last_flush >= self.flush_every_s:
            self._submit(sync=False, now=now)

    def _submit(self, sync: bool, now: float) -> None:
        self._last_flush = now
        lines, self._pending = self._pending, []
        if lines or sync:
            self._writer.submit(lambda: self._write(lines, sync), len(lines))

    def _write(self, lines: list[str], sync: bool) -> None:
        try:
            self._file.write("".join(lines))
            self._file.flush()
        except BaseException:
            self._reopen()
            raise
        if sync:
            os.fsync(self._file.fileno())

    def _reopen(self) -> None:
        """After a failed write: drop what is stuck in the file's buffer (counted as lost) and start afresh."""
        name = getattr(self._file, "name", None)
        try:
            self._file.close()
        except (OSError, ValueError):
            pass
        if isinstance(name, str):
            try:
                self._file = open(name, "a")
            except OSError:
                pass

    def _hand_over(self) -> None:
        self._submit(sync=True, now=self.clock.now())

    def of_kind(self, event: str) -> list[dict]:
        return [e for e in self.events if e["event"] == event]

    def close(self, timeout_s: float = 5.0) -> None:
        if self._writer is None:
            return
        self.sync()
        self._writer.close(timeout_s)
        try:
            self._file.close()
        except OSError as exc:
            log.warning("events.jsonl: %s", exc)
        self._writer = None


class TickRecorder(_BackgroundLog):
    """Collects per-tick arrays; a background thread writes them as npz chunks of up to `chunk_ticks` ticks, at
    least every `flush_every_s` seconds of run time, and at sync() (fsynced)."""

    def __init__(self, folder: str | Path | None, chunk_ticks: int = 1024, flush_every_s: float = FLUSH_EVERY_S):
        self.folder = Path(folder) / "ticks" if folder is not None else None
        self.chunk_ticks = chunk_ticks
        self.flush_every_s = flush_every_s
        self._rows: list[dict[str, np.ndarray]] = []
        self._chunks_written = 0
        self._first_t: float | None = None
        self.ticks = 0
        self._writer: _Writer | None = None
        if self.folder is not None:
            self.folder.mkdir(parents=True, exist_ok=True)
            self._writer = _Writer("tick-writer")
        self._written = self._writer  # kept after close() for report()

    def record(self, row: dict[str, np.ndarray | float | int]) -> None:
        self.ticks += 1
        if self.folder is None:
            return
        self._rows.append(row)
        t = float(row["t"])
        self._first_t = t if self._first_t is None else self._first_t
        if len(self._rows) >= self.chunk_ticks or t - self._first_t >= self.flush_every_s:
            self._flush(sync=False)

    def _flush(self, sync: bool) -> None:
        if not self._rows:
            return
        rows, self._rows, self._first_t = self._rows, [], None
        path = self.folder / f"chunk_{self._chunks_written:05d}.npz"
        self._chunks_written += 1
        self._writer.submit(lambda: self._write(path, rows, sync), len(rows))

    @staticmethod
    def _write(path: Path, rows: list[dict], sync: bool) -> None:
        arrays = {key: np.stack([np.asarray(r[key]) for r in rows]) for key in rows[0]}
        buffer = io.BytesIO()
        np.savez(buffer, **arrays)
        atomic_write_bytes(path, buffer.getvalue(), fsync=sync)

    def _hand_over(self) -> None:
        self._flush(sync=True)

    def close(self, timeout_s: float = 10.0) -> None:
        if self._writer is None:
            return
        self._flush(sync=True)
        self._writer.close(timeout_s)
        self._writer = None


def tick_row(now, deadline, phase, policy_tick, body, reading, poses, action, command, hand_units, num_body,
             num_actions) -> dict:
    """One tick's record; NaN (or -1 for hand units) where the tick had no value."""
    nan = np.full(num_body, np.nan)
    return {
        "t": now,
        "deadline": deadline,
        "phase": int(phase),
        "policy_tick": policy_tick if phase.name == "POLICY" else -1,
        "q": body.q if body is not None else nan,
        "dq": body.dq if body is not None else nan,
        "imu_quat_wxyz": body.imu_quat_wxyz if body is not None else np.full(4, np.nan),
        "gyro": body.gyro if body is not None else np.full(3, np.nan),
        "body_age": now - body.stamp if body is not None else np.inf,
        "hand_angles": reading.angles,
        "hand_forces": reading.forces,
        "hand_errors": reading.errors,
        "hand_age": reading.ages,  # each hand's own silence (0: its latest request is answered)
        "robot_pos": poses.robot.pos,
        "robot_quat_wxyz": poses.robot.quat_wxyz,
        "object_pos": poses.object.pos,
        "object_quat_wxyz": poses.object.quat_wxyz,
        "tracker_age": np.array([now - poses.robot.stamp, now - poses.object.stamp]),
        "action": action if action is not None else np.full(num_actions, np.nan),
        "cmd_q": command.q if command is not None else nan,
        "cmd_kp": command.kp if command is not None else nan,
        "cmd_kd": command.kd if command is not None else nan,
        "cmd_hand_units": hand_units if hand_units is not None else np.full(12, -1),
    }


def load_ticks(log_dir: str | Path) -> dict[str, np.ndarray]:
    chunks = sorted((Path(log_dir) / "ticks").glob("chunk_*.npz"))
    if not chunks:
        return {}
    parts = []
    for path in chunks:
        with np.load(path, allow_pickle=False) as npz:
            parts.append({k: npz[k] for k in npz.files})
    return {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}


def load_events(log_dir: str | Path) -> list[dict]:
    path = Path(log_dir) / "events.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
