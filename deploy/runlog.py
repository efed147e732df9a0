"""Run logs: decisions as JSON lines (written as they happen) and per-tick records in npz chunks.

    LOG_DIR/events.jsonl         one JSON object per decision: phase changes, faults, clamps, operator, overruns
    LOG_DIR/ticks/chunk_NNNNN.npz every command and state, per-tick timing (written by a background thread)
    LOG_DIR/summary.json         written by the CLI at the end

`load_ticks(LOG_DIR)` concatenates the chunks back into one dict of arrays.
"""

from __future__ import annotations

import io
import json
import logging
import queue
import threading
from pathlib import Path

import numpy as np

from deploy.atomic import atomic_write_bytes
from deploy.clock import Clock

log = logging.getLogger("deploy.runtime")


def _jsonable(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.integer | np.floating | np.bool_):
        return value.item()
    return str(value)


class EventLog:
    """Structured decision log: kept in memory (for the summary and tests) and appended to events.jsonl."""

    def __init__(self, clock: Clock, path: str | Path | None = None, max_in_memory: int = 10000):
        self.clock = clock
        self.events: list[dict] = []
        self.max_in_memory = max_in_memory
        self.dropped = 0
        self._file = None
        if path is not None:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            self._file = open(path, "a", buffering=1)  # line-buffered: each decision is on disk at once

    def log(self, event: str, **fields) -> dict:
        record = {"t": self.clock.now(), "event": event, **fields}
        if len(self.events) < self.max_in_memory:
            self.events.append(record)
        else:
            self.dropped += 1
        if self._file is not None:
            self._file.write(json.dumps(record, default=_jsonable) + "\n")
        level = logging.WARNING if event in ("fault", "overrun", "error") else logging.INFO
        log.log(level, "%s %s", event, {k: v for k, v in fields.items()})
        return record

    def of_kind(self, event: str) -> list[dict]:
        return [e for e in self.events if e["event"] == event]

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


class TickRecorder:
    """Collects per-tick arrays; every `chunk_ticks` ticks a background thread writes one npz chunk."""

    def __init__(self, folder: str | Path | None, chunk_ticks: int = 1024):
        self.folder = Path(folder) / "ticks" if folder is not None else None
        self.chunk_ticks = chunk_ticks
        self._rows: list[dict[str, np.ndarray]] = []
        self._chunks_written = 0
        self.ticks = 0
        self._queue: queue.Queue = queue.Queue()
        self._thread = None
        if self.folder is not None:
            self.folder.mkdir(parents=True, exist_ok=True)
            self._thread = threading.Thread(target=self._writer, name="tick-writer", daemon=True)
            self._thread.start()

    def record(self, row: dict[str, np.ndarray | float | int]) -> None:
        self.ticks += 1
        if self.folder is None:
            return
        self._rows.append(row)
        if len(self._rows) >= self.chunk_ticks:
            self._flush()

    def _flush(self) -> None:
        if not self._rows:
            return
        rows, self._rows = self._rows, []
        self._queue.put((self._chunks_written, rows))
        self._chunks_written += 1

    def _writer(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            index, rows = item
            arrays = {key: np.stack([np.asarray(r[key]) for r in rows]) for key in rows[0]}
            buffer = io.BytesIO()
            np.savez(buffer, **arrays)
            atomic_write_bytes(self.folder / f"chunk_{index:05d}.npz", buffer.getvalue())

    def close(self) -> None:
        if self._thread is None:
            return
        self._flush()
        self._queue.put(None)
        self._thread.join()
        self._thread = None


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
