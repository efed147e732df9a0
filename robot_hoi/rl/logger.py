"""Scalar logging with pluggable writers: TensorBoard, JSON lines (machine-readable) and in-memory (tests).

A writer only needs `add_scalar(name, value, step)`; `flush()` and `close()` are optional.
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from pathlib import Path
from typing import Protocol


class LogWriter(Protocol):
    def add_scalar(self, name: str, value: float, step: int) -> None: ...


class MemoryWriter:
    """Keeps every scalar: `scalars[name] == [(step, value), ...]`."""

    def __init__(self) -> None:
        self.scalars: dict[str, list[tuple[int, float]]] = defaultdict(list)

    def add_scalar(self, name: str, value: float, step: int) -> None:
        self.scalars[name].append((step, value))

    def last(self, name: str) -> float:
        return self.scalars[name][-1][1]


class JsonlWriter:
    """One JSON object per logged step in `path`: {"step": i, "<name>": value, ...}; appends across resumes."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self.path.open("a", encoding="utf-8")
        self._step: int | None = None
        self._row: dict[str, float] = {}

    def add_scalar(self, name: str, value: float, step: int) -> None:
        if self._step is not None and step != self._step:
            self.flush()
        self._step = step
        self._row[name] = value if math.isfinite(value) else str(value)

    def flush(self) -> None:
        if self._step is not None and self._row:
            self._file.write(json.dumps({"step": self._step, **self._row}) + "\n")
            self._file.flush()
        self._step, self._row = None, {}

    def close(self) -> None:
        self.flush()
        self._file.close()


class TensorBoardWriter:
    def __init__(self, log_dir: str | Path) -> None:
        # ~0.3 s to import beyond torch: only when TensorBoard is wanted
        from torch.utils.tensorboard import SummaryWriter

        self._writer = SummaryWriter(log_dir=str(log_dir), flush_secs=30)

    def add_scalar(self, name: str, value: float, step: int) -> None:
        self._writer.add_scalar(name, value, step)

    def flush(self) -> None:
        self._writer.flush()

    def close(self) -> None:
        self._writer.close()


class Logger:
    """Fans scalars out to every writer."""

    def __init__(self, writers: list[LogWriter] | None = None) -> None:
        self.writers: list[LogWriter] = list(writers or [])

    def log_scalars(self, scalars: dict[str, float], step: int) -> None:
        for name, value in scalars.items():
            value = float(value)
            for writer in self.writers:
                writer.add_scalar(name, value, step)
        self.flush()

    def flush(self) -> None:
        for writer in self.writers:
            if hasattr(writer, "flush"):
                writer.flush()

    def close(self) -> None:
        for writer in self.writers:
            if hasattr(writer, "close"):
                writer.close()
