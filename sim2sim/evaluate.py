"""`robot-hoi sim2sim` end to end: policies and targets -> parallel episodes -> cells, plots, videos -> report.

Comparison mode evaluates a second ONNX policy on the same suite and seeds, or loads a previous run's
metrics.json; either way both appear side by side in one report.
"""

from __future__ import annotations

import hashlib
import platform
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np
import onnxruntime

from deploy.contract import PolicyContract, check_against_embodiment
from deploy.embodiment import resolve_embodiment_path
from robot_hoi.embodiment import build_model, load_embodiment
from robot_hoi.errors import UserError
from sim2sim import plots as plotting
from sim2sim.episode import SIM2SIM_SAFETY, EpisodeJob
from sim2sim.hands import DIRECT_TRANSPORTS
from sim2sim.layout import WorldLayout
from sim2sim.perturbations import resolve_suite
from sim2sim.physics import PhysicsSettings, differences, training_physics
from sim2sim.report import load_previous, write_report
from sim2sim.runner import default_workers, run_jobs
from sim2sim.scene import load_model
from sim2sim.summary import build_cells, episode_record
from sim2sim.targets import clip_targets, policy_targets, task_config
from sim2sim.verdict import ReadyThresholds, verdict
from sim2sim.video import VideoRequest, reference_qpos, render_videos


@dataclass
class Sim2SimOptions:
    policy: str
    motion: str | None = None
    clips: list[str] | None = None
    suite: str = "default"
    perturbations: list[str] | None = None
    episodes: int = 3
    output: str | None = None
    compare: str | None = None
    workers: int | None = None
    seconds: float | None = None  # evaluate only the first seconds of each clip
    hand_transport: str = "serial"
    hand_link: str | None = None  # default: direct for serial/modbus, pty for can
    embodiment: str = "g1_inspire"
    videos: int = 2
    seed: int = 0
    self_collision: bool = True
    tracker_rate_hz: float = 120.0
    quiet: bool = False
    argv: list[str] = field(default_factory=list)
    clip_options: dict = field(default_factory=dict)  # load_clip keywords (--objects, --repair)
    ready: ReadyThresholds = field(default_factory=ReadyThresholds)  # the verdict's thresholds


@dataclass
class PolicyEntry:
    label: str
    path: str
    contract: object
    targets: list = field(default_factory=list)
    task: object = None  # the task config it was trained with (sim2sim.targets.task_config), read once


def _sha256(path: str) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def _load_policy(path: str, label: str, embodiment: str):
    if not Path(path).is_file():
        raise UserError(f"{path}: policy file not found")
    contract = PolicyContract.from_onnx(path)
    if contract.policy_kind == "teacher":
        raise UserError(f"{path}: a teacher reads privileged simulation state; sim2sim runs deployable policies")
    check_against_embodiment(contract, resolve_embodiment_path(embodiment))
    return PolicyEntry(label, str(path), contract)


def _labels(a: str, b: str | None) -> tuple[str, str | None]:
    stem = lambda p: Path(p).name.removesuffix(".onnx").removesuffix(".json")  # noqa: E731
    la = stem(a)
    if b is None:
        return la, None
    lb = stem(b) if not Path(b).is_dir() else Path(b).name
    if la == lb:
        return f"A:{la}", f"B:{lb}"
    return la, lb


def machine() -> dict:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    cores = default_workers()
    return {"cpu": cpu, "cores": cores, "python": platform.python_version(), "mujoco": mujoco.__version__,
            "onnxruntime": onnxruntime.__version__, "description": f"{cpu}, {cores} core(s)"}


def _seed(base: int, perturbation_index: int, episode: int) -> int:
    return int(np.random.SeedSequence([base, perturbation_index, episode]).generate_state(1)[0])


def evaluate(o: Sim2SimOptions) -> tuple[dict, dict[str, Path]]:
    if o.episodes < 1:
        raise UserError(f"--episodes must be >= 1, got {o.episodes}")
    if o.seconds is not None and o.seconds <= 0:
        raise UserError(f"--seconds must be positive, got {o.seconds}")
    hand_link = o.hand_link or ("direct" if o.hand_transport in DIRECT_TRANSPORTS else "pty")
    if hand_link == "direct" and o.hand_transport not in DIRECT_TRANSPORTS:
        raise UserError(f"--hand-link direct serves {', '.join(DIRECT_TRANSPORTS)}; use --hand-link pty with "
                        f"--hand-bus {o.hand_transport}")
    label_a, label_b = _labels(o.policy, o.compare)
    entries = [_load_policy(o.policy, label_a, o.embodiment)]
    previous = None
    if o.compare:
        if o.compare.endswith(".onnx"):
            entries.append(_load_policy(o.compare, label_b, o.embodiment))
        else:
            previous = load_previous(o.compare)
    perturbations = resolve_suite(o.suite, o.perturbations)
    out = Path(o.output) if o.output else Path("reports") / time.strftime("sim2sim-%Y%m%d-%H%M%S")
    if out.exists() and not out.is_dir():
        raise UserError(f"{out}: exists and is not a folder")

    say = (lambda *a: None) if o.quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    for entry in entries:
        say(f"sim2sim: preparing {entry.label} ({entry.path})")
        entry.task = task_config(entry.contract)  # each policy's episodes end and succeed by the rules it learnt with
        entry.targets = (clip_targets(entry.contract, o.clips, o.embodiment, o.self_collision, o.clip_options,
                                      entry.task)
                         if o.clips else
                         policy_targets(entry.contract, o.motion, o.embodiment, o.self_collision, o.clip_options,
                                        entry.task))
    jobs = []
    for entry in entries:
        task = entry.task
        thresholds = task.terminations  # the env config's terminations are a Thresholds
        success_bounds = (task.success_max_object_error, task.success_max_link_error)
        for target in entry.targets:
            max_frames = None if o.seconds is None else max(1, int(round(o.seconds * target.motion.fps)))
            for pi, perturbation in enumerate(perturbations):
                for ep in range(o.episodes):
                    jobs.append(EpisodeJob(entry.path, entry.label, target, perturbation, ep, _seed(o.seed, pi, ep),
                                           thresholds=thresholds, hand_transport=o.hand_transport,
                                           hand_link=hand_link, tracker_rate_hz=o.tracker_rate_hz,
                                           max_frames=max_frames, success_bounds=success_bounds))
    workers = o.workers or default_workers()
    say(f"sim2sim: {len(jobs)} episode(s) on {min(workers, len(jobs))} worker process(es) -> {out}")
    counter = {"done": 0}

    def progress(result: dict) -> None:
        counter["done"] += 1
        status = result.get("error") or result["outcome"]
        say(f"  [{counter['done']}/{len(jobs)}] {result['policy']} {result['clip']} {result['perturbation']} "
            f"ep{result['episode']}: {status}")

    results, timing = run_jobs(jobs, workers, progress)
    timing["episodes"] = len(results)
    cells = build_cells(results)

    cfg = load_embodiment(o.embodiment)
    training = training_physics(build_model(cfg))
    nominal = PhysicsSettings()
    report = {
        "format": "robot-hoi sim2sim report",
        "version": 1,
        "created": time.strftime("%Y-%m-%d %H:%M:%S"),
        "command": o.argv,
        "machine": machine(),
        "policies": [{"label": e.label, "path": e.path, "sha256": _sha256(e.path),
                      "policy_kind": e.contract.policy_kind, "robot_hoi_version": e.contract.robot_hoi_version,
                      "control_dt": e.contract.control_dt, "data": e.contract.data, "origin": "evaluated here"}
                     for e in entries],
        "clips": [dict(t.describe(), policy=e.label) for e in entries for t in e.targets],
        "suite": o.suite if not o.perturbations else "custom",
        "perturbations": [{"name": p.name, "description": p.description, "changes": p.changes(),
                           "physics": p.physics.describe()} for p in perturbations],
        "physics": {"nominal": nominal.to_dict(), "nominal_description": nominal.describe(), "training": training,
                    "differences": differences(nominal, training)
                    + (["robot self-collision on (off in training)"] if o.self_collision else [])},
        "settings": {"episodes": o.episodes, "seconds": o.seconds, "hand_transport": o.hand_transport,
                     "hand_link": hand_link, "tracker_rate_hz": o.tracker_rate_hz, "seed": o.seed,
                     "self_collision": o.self_collision, "thresholds": vars(thresholds).copy(),
                     "runtime_safety": _safety()},
        "cells": cells,
        "episodes": [episode_record(r) for r in results],
        "timing": timing,
    }
    report["verdict"] = verdict(report, o.ready)  # before merging: it judges the policy evaluated here
    if previous is not None:
        _merge_previous(report, previous)

    plots = _plots(report, results, entries, perturbations)
    report["videos"], report["render"] = _videos(results, entries, out, o.videos, say)
    paths = write_report(report, plots, out)
    return report, paths


def _safety() -> dict:
    return dict(SIM2SIM_SAFETY)


def _merge_previous(report: dict, previous: dict) -> None:
    """Bring a previous run's policies and cells into this report (a label already taken gets "(previous)")."""
    taken = {p["label"] for p in report["policies"]}
    rename = {p["label"]: p["label"] if p["label"] not in taken else f"{p['label']} (previous)"
              for p in previous["policies"]}
    for p in previous["policies"]:
        report["policies"].append(dict(p, label=rename[p["label"]], origin=f"previous run ({previous['created']})"))
    for c in previous["cells"]:
        report["cells"].append(dict(c, policy=rename.get(c["policy"], c["policy"])))
    known = {p["name"] for p in report["perturbations"]}
    report["perturbations"] += [p for p in previous["perturbations"] if p["name"] not in known]
    report["compared_with"] = {"created": previous["created"], "suite": previous["suite"],
                               "timing": previous.get("timing")}


def _plots(report, results, entries, perturbations) -> list[tuple[str, bytes]]:
    names = [p["name"] for p in report["perturbations"]]
    cells = report["cells"]
    out = [
        ("Success rate, duration and tracking errors (InterMimic) per perturbation; bars = mean, whiskers = std",
         plotting.metric_bars(cells, ("success_rate", "duration_s", "E_h_cm", "E_o_cm"), names)),
        ("ComplexMimic errors over the frames each episode lasted",
         plotting.metric_bars(cells, ("mpjpe_g_mm", "mpjpe_mm", "e_acc_mm", "e_vel_mm"), names)),
    ]
    traced = [r for r in results if "trace" in r and r["episode"] == 0]
    main = entries[0]
    for target in main.targets:
        series = {r["perturbation"]: r["trace"] for r in traced if r["policy"] == main.label
                  and r["clip"] == target.name}
        if series:
            out.append((f"Per-frame errors of episode 0 of every perturbation ({main.label}, {target.name})",
                        plotting.error_timelines(series, f"{main.label} on {target.name}")))
    first = next((r for r in traced if r["policy"] == main.label and r["perturbation"] == perturbations[0].name),
                 None)
    if first is not None:
        channels = [c.name for c in main.contract.hands["left"]]
        out.append((f"Hand commands and readings ({main.label}, {first['perturbation']}, episode 0)",
                    plotting.hand_channels(first["trace"], channels, f"{main.label}: {first['perturbation']}")))
    samples = {e.label: np.concatenate([r["trace"]["tick_wall_s"] for r in results
                                        if "trace" in r and r["policy"] == e.label] or [np.zeros(0)])
               for e in entries}
    out.append(("Wall time of one policy tick on this machine (all episodes)",
                plotting.tick_timing(samples, 1e3 * main.contract.control_dt)))
    return out


def _videos(results, entries, out: Path, count: int, say) -> tuple[list[dict], dict]:
    if count <= 0:
        return [], {"backend": None, "message": "videos not requested (--videos 0)"}
    done = [r for r in results if "trace" in r]
    chosen = []
    for entry in entries:  # episode 0 of the first perturbation, per policy
        first = next((r for r in done if r["policy"] == entry.label), None)
        if first is not None:
            chosen.append((first, "first"))
    taken = {id(c) for c, _ in chosen}
    rest = sorted((r for r in done if id(r) not in taken),
                  key=lambda r: (r["success"], r["duration_s"], -(r["E_h_cm"] if r["E_h_cm"] == r["E_h_cm"] else 0)))
    chosen += [(r, "worst") for r in rest]
    chosen = chosen[:count]
    targets = {(e.label, t.name): t for e in entries for t in e.targets}
    contracts = {e.label: e.contract for e in entries}
    requests, videos = [], []
    for r, why in chosen:
        target = targets[(r["policy"], r["clip"])]
        file = f"videos/{r['policy']}_{r['clip']}_{r['perturbation']}_ep{r['episode']}.mp4".replace(":", "-")
        title = (f"{r['policy']} on {r['clip']}, {r['perturbation']}, episode {r['episode']} ({why}): "
                 f"{r['outcome']}, {r['duration_s']:.1f} s")
        contract = contracts[r["policy"]]
        layout = WorldLayout.resolve(load_model(target.scene), contract)
        ghost = reference_qpos(r["trace"], target.motion, layout, contract.warmup_frames)
        requests.append(VideoRequest(Path(file).name, title + " (ghost: the reference)", target.scene,
                                     r["trace"]["qpos"], target.motion.fps, ghost))
        videos.append({"file": file, "title": title})
    say(f"sim2sim: rendering {len(requests)} video(s)")
    render = render_videos(requests, out / "videos")
    if render["backend"] is None:
        say(f"sim2sim: {render['message']}")
        return [], render
    return videos, render
