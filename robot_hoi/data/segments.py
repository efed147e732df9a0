"""Runs of True in a per-frame mask, as frame ranges and readable text ("3-5, 9")."""

from __future__ import annotations

import numpy as np


def mask_segments(mask: np.ndarray) -> list[tuple[int, int]]:
    """[(first, last_inclusive), ...] for every run of True frames."""
    mask = np.asarray(mask, dtype=bool).ravel()
    if mask.size == 0:
        return []
    padded = np.concatenate([[False], mask, [False]])
    edges = np.flatnonzero(padded[1:] != padded[:-1])
    return [(int(a), int(b) - 1) for a, b in zip(edges[0::2], edges[1::2], strict=True)]


def format_segments(mask: np.ndarray, limit: int = 6) -> str:
    parts = [f"{a}" if a == b else f"{a}-{b}" for a, b in mask_segments(mask)]
    if len(parts) > limit:
        parts = parts[:limit] + [f"... ({len(parts) - limit} more)"]
    return ", ".join(parts)
