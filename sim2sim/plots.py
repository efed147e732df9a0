"""Report figures as PNG bytes (matplotlib's object API, no pyplot state, no display needed)."""

from __future__ import annotations

import io

import numpy as np
from matplotlib.figure import Figure

from sim2sim.summary import METRIC_LABELS, cell_value

COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b")


def _png(fig) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100, bbox_inches="tight")
    return buffer.getvalue()


def _figure(width: float, height: float, rows: int = 1, cols: int = 1):
    fig = Figure(figsize=(width, height))
    axes = fig.subplots(rows, cols, squeeze=False)
    return fig, axes


def series_name(cell: dict, multi_clip: bool) -> str:
    return f"{cell['policy']} / {cell['clip']}" if multi_clip else cell["policy"]


def metric_bars(cells: list[dict], keys: tuple[str, ...], perturbations: list[str]) -> bytes:
    """One panel per metric: x = perturbation, one bar per policy (and clip), error bars = std over episodes."""
    multi_clip = len({c["clip"] for c in cells}) > 1
    series = list(dict.fromkeys(series_name(c, multi_clip) for c in cells))
    cols = 2 if len(keys) > 1 else 1
    rows = (len(keys) + cols - 1) // cols
    fig, axes = _figure(cols * max(5.0, 0.55 * len(perturbations) + 2), 3.0 * rows, rows, cols)
    width = 0.8 / max(len(series), 1)
    x = np.arange(len(perturbations))
    for ax in axes.ravel()[len(keys):]:
        ax.set_visible(False)
    for ax, key in zip(axes.ravel(), keys, strict=False):
        for i, name in enumerate(series):
            values, errors = [], []
            for p in perturbations:
                cell = next((c for c in cells if series_name(c, multi_clip) == name and c["perturbation"] == p), None)
                v = cell_value(cell, key) if cell else None
                values.append(np.nan if v is None else v)
                std = cell.get(key, {}).get("std") if cell and isinstance(cell.get(key), dict) else None
                errors.append(0.0 if std is None else std)
            ax.bar(x + (i - (len(series) - 1) / 2) * width, values, width, yerr=errors, capsize=2,
                   label=name, color=COLORS[i % len(COLORS)])
        shown = [cell_value(c, key) for c in cells]
        if key == "success_rate" and not any(v for v in shown if v is not None):
            ax.text(0.5, 0.5, "no successes", transform=ax.transAxes, ha="center", va="center", fontsize=14,
                    color="#a40")  # a row of zero-height bars looks like a plotting failure
        elif all(v is None or v != v for v in shown):
            ax.text(0.5, 0.5, "no data", transform=ax.transAxes, ha="center", va="center", fontsize=14)
        ax.set_ylabel(METRIC_LABELS.get(key, key))
        ax.set_xticks(x)
        ax.set_xticklabels(perturbations, rotation=30, ha="right", fontsize=8)
        if key == "success_rate":
            ax.set_ylim(0, 1.05)
        ax.grid(axis="y", alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="best")
    fig.tight_layout()
    return _png(fig)


def error_timelines(traces: dict[str, dict], title: str) -> bytes:
    """Per-frame mean link error and object point error (cm) of one episode per perturbation."""
    fig, axes = _figure(9.0, 5.0, 2, 1)
    for i, (name, trace) in enumerate(traces.items()):
        color = COLORS[i % len(COLORS)]
        t = trace["frame_time_s"]
        axes[0, 0].plot(t, 100 * trace["link_error_m"], color=color, label=name, lw=1.2)
        axes[1, 0].plot(t, 100 * trace["object_error_m"], color=color, label=name, lw=1.2)
    axes[0, 0].set_ylabel("mean link error (cm)")
    axes[1, 0].set_ylabel("object point error (cm)")
    axes[1, 0].set_xlabel("policy time (s)")
    axes[0, 0].set_title(title, fontsize=10)
    for ax in axes[:, 0]:
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, ncol=2)
    fig.tight_layout()
    return _png(fig)


def hand_channels(trace: dict, channel_names: list[str], title: str) -> bytes:
    """Commanded ANGLE_SET vs measured ANGLE_ACT for the 12 channels, and FORCE_ACT, over the policy ticks."""
    cmd, meas, force = trace["hand_command"], trace["hand_measured"], trace["hand_force_g"]
    t = np.arange(len(cmd)) / 30.0 if len(cmd) else np.zeros(0)
    if len(trace.get("frame_time_s", [])) and len(cmd):
        t = np.linspace(0.0, float(trace["frame_time_s"][-1]), len(cmd))
    fig, axes = _figure(10.0, 6.0, 3, 2)
    for side in range(2):
        for j in range(6):
            k = 6 * side + j
            color = COLORS[j % len(COLORS)]
            if len(cmd):
                axes[0, side].plot(t, cmd[:, k], color=color, lw=1.0, label=channel_names[j])
                axes[1, side].plot(t, meas[:, k], color=color, lw=1.0)
                axes[2, side].plot(t, force[:, k], color=color, lw=1.0)
        axes[0, side].set_title(("left", "right")[side] + " hand", fontsize=9)
    axes[0, 0].set_ylabel("ANGLE_SET")
    axes[1, 0].set_ylabel("ANGLE_ACT")
    axes[2, 0].set_ylabel("FORCE_ACT (g)")
    for ax in axes[2]:
        ax.set_xlabel("policy time (s)")
    for ax in axes.ravel():
        ax.grid(alpha=0.3)
    axes[0, 1].legend(fontsize=7, ncol=3)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return _png(fig)


def tick_timing(samples: dict[str, np.ndarray], period_ms: float) -> bytes:
    """Histogram of the wall time of one policy tick (runtime + ONNX + hand bytes), per policy."""
    fig, axes = _figure(7.0, 3.0)
    ax = axes[0, 0]
    for i, (name, values) in enumerate(samples.items()):
        if len(values):
            ax.hist(np.asarray(values) * 1e3, bins=40, alpha=0.6, color=COLORS[i % len(COLORS)], label=name)
    ax.axvline(period_ms, color="k", ls="--", lw=1, label=f"control period {period_ms:.1f} ms")
    ax.set_xlabel("wall time of one policy tick (ms)")
    ax.set_ylabel("ticks")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return _png(fig)
