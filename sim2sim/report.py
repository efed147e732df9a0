"""Write a run's report folder: metrics.json, summary.md, report.html (plots embedded as PNG), videos/*.mp4.

Every file is written atomically (deploy.atomic). `load_previous` reads another run's metrics.json for
comparison mode.
"""

from __future__ import annotations

import base64
import html
import json
import math
import os
from pathlib import Path

import numpy as np

from deploy.atomic import atomic_write_bytes, atomic_write_text
from robot_hoi.errors import UserError
from sim2sim.tables import Table, perturbation_table, result_tables, setup_table
from sim2sim.verdict import verdict_lines

FORMAT = "robot-hoi sim2sim report"
VERSION = 1


def _plain(value):
    """JSON-ready copy: numpy scalars and arrays as Python values, nan and inf as null."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if value is None or isinstance(value, bool | int | float | str):
        return value
    return str(value)


def write_metrics(report: dict, folder: Path) -> Path:
    path = folder / "metrics.json"
    atomic_write_text(path, json.dumps(_plain(report), indent=1, allow_nan=False) + "\n")
    return path


def load_previous(path: str | os.PathLike) -> dict:
    """A previous run's metrics.json (the file, or the report folder holding it)."""
    path = Path(path)
    if path.is_dir():
        path = path / "metrics.json"
    if not path.is_file():
        raise UserError(f"{path}: no metrics.json of a previous sim2sim run here")
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise UserError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT or not isinstance(data.get("cells"), list):
        raise UserError(f"{path}: not a sim2sim metrics.json (format {data.get('format') if isinstance(data, dict) else '?'!r})")
    return data


# ---------------------------------------------------------------------------------------------------- markdown
def _md_table(table: Table) -> str:
    esc = lambda s: str(s).replace("|", "\\|")  # noqa: E731
    lines = [f"### {table.title}", ""]
    if table.note:
        lines += [f"_{table.note}_", ""]
    lines.append("| " + " | ".join(esc(h) for h in table.headers) + " |")
    lines.append("|" + "|".join("---" for _ in table.headers) + "|")
    lines += ["| " + " | ".join(esc(c) for c in row) + " |" for row in table.rows]
    return "\n".join(lines) + "\n"


def _overview(report: dict) -> list[str]:
    t = report["timing"]
    physics = report["physics"]
    lines = [
        f"- created {report['created']} on {report['machine']['description']}",
        f"- suite `{report['suite']}`: {len(report['perturbations'])} perturbation(s), "
        f"{report['settings']['episodes']} episode(s) each, clips: "
        + ", ".join(f"`{c['name']}` ({c['frames']} frames)" for c in report["clips"]),
        f"- physics: {physics['nominal_description']}; differs from training in: "
        + "; ".join(physics["differences"]),
        f"- runtime: deploy.loop.Runtime on a simulated clock; hands: {report['settings']['hand_transport']} "
        f"bytes ({report['settings']['hand_link']} link) to simulated Inspire devices; mocap "
        f"{report['settings']['tracker_rate_hz']:g} Hz",
        f"- run: {t['episodes']} episode(s), {t['simulated_s']:.1f} simulated s in {t['wall_s']:.1f} s wall on "
        f"{t['workers']} worker(s) (start-up included: {fmt_rtf(t.get('realtime_factor_per_core'))} x real time per "
        f"core); an episode ran at {fmt_rtf(t.get('realtime_factor_per_episode'))} x real time, "
        f"{fmt_rtf(t.get('realtime_factor_per_cpu_second'))} x per CPU second"
        + (f" (load average {t['load_average']:.1f})" if t.get("load_average") is not None else ""),
    ]
    render = report.get("render", {})
    if render.get("message"):
        lines.append(f"- video: {render['message']}")
    return lines


def fmt_rtf(value) -> str:
    return "-" if value is None else f"{value:.1f}"


def _verdict(report: dict) -> list[str]:
    return verdict_lines(report["verdict"]) if report.get("verdict") else []


def markdown(report: dict) -> str:
    verdict = _verdict(report)
    parts = [f"# sim2sim: {' vs '.join(p['label'] for p in report['policies'])}", ""]
    if verdict:
        parts += [f"**{verdict[0]}**", "", *[f"- {line}" for line in verdict[1:]], ""]
    parts += [*_overview(report), ""]
    for table in [setup_table(report), perturbation_table(report), *result_tables(report)]:
        parts.append(_md_table(table))
    if report.get("videos"):
        parts.append("### Videos\n")
        parts += [f"- [{v['title']}]({v['file']})" for v in report["videos"]]
        parts.append("")
    parts.append("Plots: see report.html. Raw numbers: metrics.json.\n")
    return "\n".join(parts)


# ---------------------------------------------------------------------------------------------------- html
STYLE = """
body { font-family: -apple-system, Segoe UI, Helvetica, Arial, sans-serif; margin: 24px; color: #222; }
h1 { font-size: 22px; } h2 { font-size: 18px; margin-top: 28px; } h3 { font-size: 15px; }
table { border-collapse: collapse; margin: 8px 0 4px 0; font-size: 13px; }
th, td { border: 1px solid #ccc; padding: 3px 8px; text-align: left; font-variant-numeric: tabular-nums; }
th { background: #f0f3f7; }
.note { color: #666; font-size: 12px; margin-bottom: 14px; }
figure { margin: 12px 0; } figcaption { color: #555; font-size: 12px; }
img.plot { max-width: 100%; border: 1px solid #ddd; }
.warn { color: #a40; }
"""

LOADED_SCRIPT = """
window.addEventListener('load', function () {
  var imgs = Array.prototype.slice.call(document.querySelectorAll('img.plot'));
  var ok = imgs.filter(function (i) { return i.complete && i.naturalWidth > 0; }).length;
  document.body.setAttribute('data-plots-loaded', String(ok));
});
"""


def _html_table(table: Table) -> str:
    e = html.escape
    head = "".join(f"<th>{e(h)}</th>" for h in table.headers)
    body = "".join("<tr>" + "".join(f"<td>{e(str(c))}</td>" for c in row) + "</tr>" for row in table.rows)
    note = f'<div class="note">{e(table.note)}</div>' if table.note else ""
    return f"<h3>{e(table.title)}</h3><table><tr>{head}</tr>{body}</table>{note}"


def html_page(report: dict, plots: list[tuple[str, bytes]]) -> str:
    e = html.escape
    title = f"sim2sim: {' vs '.join(p['label'] for p in report['policies'])}"
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{e(title)}</title>",
             f"<style>{STYLE}</style></head><body data-plots='{len(plots)}'>", f"<h1>{e(title)}</h1>"]
    verdict = _verdict(report)
    if verdict:
        color = "#070" if report["verdict"]["ready"] else "#a40"
        parts.append(f"<h2 id='verdict' style='color:{color}'>{e(verdict[0])}</h2><ul>"
                     + "".join(f"<li>{e(line)}</li>" for line in verdict[1:]) + "</ul>")
    parts.append("<ul>")
    parts += [f"<li>{e(line[2:])}</li>" for line in _overview(report)]
    parts.append("</ul>")
    parts.append(_html_table(setup_table(report)))
    parts.append(_html_table(perturbation_table(report)))
    parts.append("<h2>Plots</h2>")
    for caption, png in plots:
        data = base64.b64encode(png).decode("ascii")
        parts.append(f"<figure><img class='plot' alt='{e(caption)}' src='data:image/png;base64,{data}'>"
                     f"<figcaption>{e(caption)}</figcaption></figure>")
    parts.append("<h2>Results</h2>")
    parts += [_html_table(t) for t in result_tables(report)]
    parts.append("<h2>Videos</h2>")
    if report.get("videos"):
        for v in report["videos"]:
            parts.append(f"<figure><video controls width='640' src='{e(v['file'])}'></video>"
                         f"<figcaption>{e(v['title'])}</figcaption></figure>")
    else:
        parts.append(f"<p class='warn'>{e(report.get('render', {}).get('message', 'no videos'))}</p>")
    parts.append(f"<script>{LOADED_SCRIPT}</script></body></html>")
    return "\n".join(parts)


def write_report(report: dict, plots: list[tuple[str, bytes]], folder: str | os.PathLike) -> dict[str, Path]:
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = {"metrics": write_metrics(report, folder)}
    paths["summary"] = folder / "summary.md"
    atomic_write_text(paths["summary"], markdown(report))
    paths["html"] = folder / "report.html"
    atomic_write_bytes(paths["html"], html_page(report, plots).encode("utf-8"))
    return paths
