"""Training progress: rich's live bar on a terminal, plain periodic lines anywhere else (nohup, batch jobs, CI),
where a live bar would print nothing until it ends.

Both take the same calls: `with progress: task = progress.add_task(text, total=N); progress.update(task, ...)`.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

from rich.progress import (
    BarColumn,
    Progress,
    TaskProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

PLAIN_INTERVAL_S = 30.0  # one line at most this often (and always for the first and the last iteration)


class PlainProgress:
    """Writes `[ 12%] 0:01:30 <description>` lines, flushed, at most every `interval_s` seconds."""

    def __init__(self, interval_s: float = PLAIN_INTERVAL_S, stream: TextIO | None = None, disable: bool = False):
        self.interval_s = interval_s
        self.stream = stream or sys.stdout
        self.disable = disable
        self._start = time.monotonic()
        self._last_line = -float("inf")
        self._state: dict[int, dict] = {}
        self._printed: dict[int, str] = {}

    def __enter__(self) -> PlainProgress:
        return self

    def __exit__(self, *exc) -> None:
        for task in self._state:
            self._write(task)  # the final state, unless it was the last line written

    def add_task(self, description: str, total: float = 100.0) -> int:
        task = len(self._state)
        self._state[task] = {"description": description, "total": total, "completed": 0.0}
        self._start = time.monotonic()
        return task

    def update(self, task: int, completed: float | None = None, description: str | None = None) -> None:
        state = self._state[task]
        if completed is not None:
            state["completed"] = completed
        if description is not None:
            state["description"] = description
        now = time.monotonic()
        if now - self._last_line >= self.interval_s or task not in self._printed:
            self._write(task)

    def _write(self, task: int) -> None:
        state = self._state[task]
        elapsed = int(time.monotonic() - self._start)
        percent = 100.0 * state["completed"] / max(state["total"], 1e-9)
        line = (f"[{percent:3.0f}%] {elapsed // 3600}:{elapsed // 60 % 60:02d}:{elapsed % 60:02d} "
                f"{state['description']}")
        if self.disable or self._printed.get(task) == state["description"]:
            return
        print(line, file=self.stream, flush=True)
        self._printed[task] = state["description"]
        self._last_line = time.monotonic()


def training_progress(enabled: bool, stream: TextIO | None = None):
    """rich's bar when `stream` (stdout) is a terminal, else PlainProgress."""
    stream = stream or sys.stdout
    if stream.isatty():
        return Progress(TextColumn("[bold]{task.description}"), BarColumn(), TaskProgressColumn(),
                        TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(), disable=not enabled,
                        transient=False)
    return PlainProgress(stream=stream, disable=not enabled)


def progress_text(iteration: int, samples_per_s: float, scalars: dict[str, float]) -> str:
    """One line: iteration, throughput, return, episode length and the episode metrics when logged."""
    parts = [f"it {iteration}", f"{samples_per_s:,.0f} samples/s"]
    for key, label, fmt in (("Train/mean_return", "return", ".3g"), ("Train/mean_episode_length", "ep len", ".0f"),
                            ("Metrics/success", "success", ".2f"), ("Metrics/E_h_cm", "E_h", ".1f"),
                            ("Metrics/E_o_cm", "E_o", ".1f")):
        if key in scalars:
            unit = " cm" if key.endswith("_cm") else ""
            parts.append(f"{label} {scalars[key]:{fmt}}{unit}")
    parts += [f"{k.split('/', 1)[1]} {v:.3g}" for k, v in scalars.items() if k.startswith("Eval/")]
    return " | ".join(parts)
