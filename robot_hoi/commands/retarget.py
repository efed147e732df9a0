"""`robot-hoi retarget [CLIP | DIR] -o OUT [--video OUT.mp4] [--json]`: IK retarget onto the robot + the physics gate."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import fields
from pathlib import Path

from robot_hoi.data.cli_options import add_clip_options, clip_options
from robot_hoi.tasks.interaction.env_cfg import RetargetCfg


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "retarget",
        help="kinematic IK retarget of an HOI clip onto the robot (reference motion for the teachers)",
        description="Map a human-object clip onto the robot: scaled body, real-size object, hands anchored to "
        "the object, per-frame IK. Writes OUT.npz + OUT.json, prints the residuals and ends with the physics gate's "
        "verdict (the reference replayed in the training scene, pelvis held, zero residual: PASS when the object "
        "stays within the object termination line and every held segment stays held).",
    )
    p.add_argument("clip", nargs="?", help="clip file (.pt InterMimic or .npz native), embedded:KIND, or a folder of clips "
                   "(one feasibility table row per clip); default: the embedded stand-lift-place clip "
                   "(embedded:lift_place)")
    p.add_argument("--embodiment", default="g1_inspire", help="embodiment name or YAML path (default g1_inspire)")
    p.add_argument("-o", "--output", help="motion file to write (.npz; a .json sidecar goes next to it); with a folder of "
                   "clips: a folder for their motion files (optional)")
    p.add_argument("--video", help="also write an mp4 of the retargeted motion")
    p.add_argument("--video-backend", choices=("auto", "mujoco", "matplotlib"), default="auto",
                   help="auto: MuJoCo offscreen (EGL, then OSMesa) if it works, else a matplotlib stick figure")
    p.add_argument("--pretty", action="store_true", help="video with Unitree meshes and shadows (slow on CPU GL)")
    p.add_argument("--video-stride", type=int, default=1, help="render every Nth frame (default 1)")
    p.add_argument("--scale", type=float, help="human->robot scale (default robot_height / subject height)")
    add_clip_options(p, "--objects-dir")  # --objects-dir: the old spelling, kept working
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="retarget.KEY=VALUE",
                   help="a retarget setting, as for training: the retarget: block of configs/tasks/interaction.yaml "
                        f"({', '.join(f.name for f in fields(RetargetCfg))}), e.g. --set retarget.solver=qp; or "
                        "another task setting, e.g. --set env.object_collision=hull; the retarget and the physics "
                        "gate both use them (repeatable)")
    p.add_argument("--json", action="store_true", help="print the report as JSON on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from robot_hoi.errors import UserError

    folder = args.clip is not None and Path(args.clip).is_dir()
    if folder:
        if args.video:
            raise UserError("--video renders one clip; give a clip file, not a folder")
        if args.output and Path(args.output).suffix:
            raise UserError(f"{args.output}: with a folder of clips, -o names a folder for the motion files")
    elif args.output is None:
        raise UserError("-o OUT.npz: the motion file to write is required for one clip")
    elif Path(args.output).suffix != ".npz":
        raise UserError(f"{args.output}: the motion file must end in .npz")
    if args.video and Path(args.video).suffix != ".mp4":
        raise UserError(f"{args.video}: the video must end in .mp4")
    if args.video_stride < 1:
        raise UserError(f"--video-stride must be >= 1, got {args.video_stride}")
    if args.video and args.video_backend != "matplotlib":
        from robot_hoi.retarget.video import choose_gl_backend

        choose_gl_backend()  # must run before mujoco is imported

    from robot_hoi.embodiment import build_model, load_embodiment
    from robot_hoi.paths import TASK_CONFIG
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg, split_overrides
    from robot_hoi.tasks.interaction.factory import retarget_options
    from robot_hoi.utils.config import apply_overrides, load_yaml_dataclass

    cfg = load_embodiment(args.embodiment)
    model = build_model(cfg)
    settings, others = split_overrides(args.overrides)
    if others:
        raise UserError(f"--set {others[0]}: retarget takes task settings only, spelled retarget.KEY=VALUE or "
                        "env.KEY=VALUE")
    task = load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG)  # the task's settings
    task = apply_overrides(task, settings, "--set")
    options = retarget_options(task)
    if folder:
        return _run_folder(args, cfg, model, task, options)
    clip = _load(args, args.clip or None)
    report, motion, _ = _retarget_and_gate(clip, cfg, model, task, options, args.scale)
    npz, sidecar = motion.save(Path(args.output))
    report["output"] = {"motion": str(npz), "sidecar": str(sidecar)}
    if args.video:
        from robot_hoi.retarget.video import write_video

        renderer = write_video(motion, cfg, model, args.video, clip.object, backend=args.video_backend,
                               stride=args.video_stride, pretty=args.pretty)
        report["video"] = {"path": str(args.video), "renderer": renderer}
    if args.json:
        json.dump(report, sys.stdout, indent=1)
        sys.stdout.write("\n")
    else:
        from robot_hoi.retarget.report import format_report
        from robot_hoi.tasks.interaction.feasibility import format_verdict

        print(f"clip {clip.name}")
        print(format_report(report))
        print(format_feasibility(report["feasibility"]))
        print(f"wrote {npz} and {sidecar}")
        if args.video:
            print(f"wrote {args.video} (rendered with {report['video']['renderer']})")
        print(f"physics gate: {format_verdict(report['feasibility']['gate'])}")
    return 0


def _retarget_and_gate(clip, cfg, model, task, options, scale=None):
    """(report, motion, seconds {"retarget", "gate"}): the retarget, its figures and the physics gate's verdict."""
    import time

    from robot_hoi.retarget.pipeline import retarget_clip
    from robot_hoi.retarget.report import build_report

    started = time.perf_counter()
    result = retarget_clip(clip, cfg, model, scale=scale, options=options)
    report = build_report(result)
    report["clip"] = clip.name
    seconds = {"retarget": time.perf_counter() - started}
    started = time.perf_counter()
    report["feasibility"] = _feasibility(clip, cfg, result.motion, task)
    seconds["gate"] = time.perf_counter() - started
    report["seconds"] = {k: round(v, 2) for k, v in seconds.items()}
    result.motion.meta["report"] = report
    result.motion.meta["feasibility"] = report["feasibility"]
    return report, result.motion, seconds


def _run_folder(args: argparse.Namespace, cfg, model, task, options) -> int:
    """One row per clip of the folder: retarget, gate, the feasibility table."""
    from robot_hoi.errors import DataError, UserError
    from robot_hoi.tasks.interaction.factory import _safe, expand_sources
    from robot_hoi.tasks.interaction.feasibility import format_table

    out = Path(args.output) if args.output else None
    rows = []
    for source in expand_sources([args.clip]):
        try:
            clip = _load(args, source)
        except (UserError, DataError) as exc:  # one bad clip does not hide the others' verdicts
            rows.append({"clip": Path(source).name, "error": str(exc)})
            continue
        report, motion, seconds = _retarget_and_gate(clip, cfg, model, task, options, args.scale)
        if out is not None:
            out.mkdir(parents=True, exist_ok=True)
            motion.save(out / f"{_safe(clip.name)}.npz")
        rows.append({"clip": clip.name, "frames": report["frames"], "gate": report["feasibility"]["gate"],
                     "retarget_s": seconds["retarget"], "gate_s": seconds["gate"]})
        if not args.json:
            print(f"{clip.name}: {rows[-1]['gate']['verdict']}", flush=True)
    if args.json:
        json.dump(rows, sys.stdout, indent=1)
        sys.stdout.write("\n")
    else:
        print(format_table(rows))
    return 0


def _feasibility(clip, cfg, motion, task) -> dict:
    """Can the robot execute it: kinematic figures and the physics gate (a root-held replay in the training
    scene)."""
    from robot_hoi.tasks.interaction.factory import kinematic_report
    from robot_hoi.tasks.interaction.feasibility import physics_gate

    report = kinematic_report(motion, cfg)
    report["gate"] = physics_gate(clip, task, cfg, motion)
    return report


def format_feasibility(f: dict) -> str:
    slide = ", ".join(f"{k.split('_')[0]} {v} cm" for k, v in f["foot_slide_cm"].items())
    gate = f.get("gate")
    lines = [f"feasibility: foot slide in contact {slide}; CoM outside support in "
             f"{100 * f['com_outside_support_fraction']:.0f}% of frames; joint speed peak "
             f"{f['joint_speed_peak_rad_s']} rad/s (p99 {f['joint_speed_p99_rad_s']})"]
    if "self_penetration_cm" in f:
        pairs = ", ".join(f"{k} {v} cm" for k, v in f["self_penetration_pairs"].items()) or "none over 1 cm"
        lines.append(f"self-penetration (self-collision on): deepest {f['self_penetration_cm']} cm, "
                     f"{100 * f['self_penetration_fraction']:.0f}% of frames over 1 cm ({pairs})")
    if gate and gate.get("first_held_frame") is None:
        lines.append("hold test: no frame where a hand holds the object")
    elif gate:
        end = "ran to the end" if gate["completed"] else f"ended by {gate.get('ended_by') or 'a termination'}"
        lines.append(f"hold test (from frame {gate['start_frame']}, a hand holds from frame "
                     f"{gate['first_held_frame']}; root held, zero residual): object drop {gate['object_drop_cm']} cm "
                     f"over {gate['frames_held']} held frames; {end} after {gate['frames']} frames")
    return "\n".join(lines)


def _load(args: argparse.Namespace, source: str | None):
    from robot_hoi.tasks.interaction.factory import DEFAULT_SOURCE, load_source

    return load_source(source or DEFAULT_SOURCE, clip_options(args))
