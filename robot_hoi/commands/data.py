"""`robot-hoi data`: synthesise, inspect, convert and view HOI clips.

Only argparse here; numpy/scipy/trimesh/matplotlib/mujoco are imported inside the handlers.
"""

from __future__ import annotations

import argparse
import json
import sys

from robot_hoi.data.cli_options import add_clip_options

KINDS = ("lift_carry", "push", "lift_place", "walk", "carry", "squat", "turn", "walk_back")  # robot_hoi.data.synth.KINDS (not imported: keeps --help light)
ARTIFACTS = ("noise", "floating_contact", "penetration", "missing_frames", "dropped_frames")


def _split_list(values: list[str] | None) -> list[str]:
    return [v.strip() for item in values or [] for v in item.split(",") if v.strip()]


def _add_loading_options(p: argparse.ArgumentParser) -> None:
    add_clip_options(p)
    p.add_argument(
        "--object-name", metavar="NAME", help="the object when the file is not named subX_OBJECT_NNN"
    )
    p.add_argument(
        "--object-optional", action="store_true",
        help="no object files: go on without an object (no inferred contacts) instead of estimating a box",
    )
    p.add_argument(
        "--min-duration", type=float, default=2.0, metavar="S", help="shortest acceptable clip in seconds"
    )


def _load(args: argparse.Namespace):
    from robot_hoi.data.clip import load_clip

    return load_clip(
        args.clip,
        objects_dir=args.objects,
        object_name=args.object_name,
        object_optional=args.object_optional,
        repair_missing=args.repair,
        min_duration_s=args.min_duration,
    )


def _synth(args: argparse.Namespace) -> int:
    from robot_hoi.data.summary import clip_summary, format_summary
    from robot_hoi.data.synth import default_clip
    from robot_hoi.data.validate import nonfinite_frames

    clip = default_clip(args.kind, seed=args.seed, artifacts=_split_list(args.artifacts))
    path = clip.save(args.output)
    if nonfinite_frames(clip).any():  # missing_frames: the summary needs finite data
        print(
            f"{clip.name}: {clip.num_frames} frames at {clip.fps:g} fps, with NaN frames ({clip.problems[0]})"
        )
    else:
        print(format_summary(clip_summary(clip, str(path))))
    print(f"wrote {path} and {path.with_suffix('.json')}")
    return 0


def _inspect(args: argparse.Namespace) -> int:
    from robot_hoi.data.summary import clip_summary, format_summary

    report = clip_summary(_load(args), str(args.clip))
    if args.json:
        json.dump(report, sys.stdout, indent=1)
        sys.stdout.write("\n")
    else:
        print(format_summary(report))
    return 0


def _convert(args: argparse.Namespace) -> int:
    from robot_hoi.data.resample import resample_clip
    from robot_hoi.data.scale import human_to_robot_scale, robot_height_from_embodiment, scale_clip

    clip = _load(args)
    if args.to_robot:
        clip = scale_clip(clip, human_to_robot_scale(clip, robot_height_from_embodiment(args.to_robot)))
    if args.fps:
        clip = resample_clip(clip, args.fps)
    path = clip.save(args.output)
    print(f"wrote {path} ({clip.num_frames} frames at {clip.fps:g} fps) and {path.with_suffix('.json')}")
    return 0


def _view(args: argparse.Namespace) -> int:
    from robot_hoi.embodiment.clip_view import render_view

    if args.clip.startswith("embedded:"):
        from robot_hoi.data.synth import embedded_clip

        clip = embedded_clip(args.clip.split(":", 1)[1])
    else:
        clip = _load(args)
    path = render_view(clip, args.output, embodiment=args.embodiment or None, keyframes=args.keyframes,
                       side_offset=args.side_offset)  # fmt: skip
    print(f"wrote {path}")
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("data", help="HOI clips: synthesise, inspect, convert, view")
    sub = p.add_subparsers(dest="data_command", metavar="ACTION", required=True)

    s = sub.add_parser("synth", help="write the project's synthetic clip (npz + json)")
    s.add_argument("-o", "--output", required=True, metavar="FILE.npz")
    s.add_argument("--kind", choices=KINDS, default="lift_carry")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument(
        "--artifacts", nargs="*", metavar="NAME", help=f"comma or space separated: {', '.join(ARTIFACTS)}"
    )
    s.set_defaults(func=_synth)

    i = sub.add_parser("inspect", help="frames, subject, object, contact timeline, lift, problems")
    i.add_argument("clip", metavar="CLIP", help=".pt (InterMimic) or .npz (native)")
    i.add_argument("--json", action="store_true", help="machine-readable report on stdout")
    _add_loading_options(i)
    i.set_defaults(func=_inspect)

    c = sub.add_parser("convert", help="write a clip as native npz + json (optionally resampled / scaled)")
    c.add_argument("clip", metavar="CLIP")
    c.add_argument("-o", "--output", required=True, metavar="FILE.npz")
    c.add_argument("--fps", type=float, help="resample to this rate (positions linear, rotations slerp)")
    c.add_argument(
        "--to-robot", metavar="EMBODIMENT", help="scale by robot_height / subject height (e.g. g1_inspire)"
    )
    _add_loading_options(c)
    c.set_defaults(func=_convert)

    v = sub.add_parser("view", help="draw human, object and robot at one metric scale (png strip or mp4)")
    v.add_argument("clip", metavar="CLIP", help=".pt, .npz, or embedded:lift_carry / embedded:push / embedded:lift_place")
    v.add_argument("--embodiment", default="g1_inspire", help="robot drawn beside the human ('' for none)")
    v.add_argument("-o", "--output", required=True, metavar="OUT.png|OUT.mp4")
    v.add_argument("--keyframes", type=int, default=6, help="panels in a png strip (default 6)")
    v.add_argument(
        "--side-offset", type=float, default=1.0, metavar="M", help="robot distance to the human's right"
    )
    _add_loading_options(v)
    v.set_defaults(func=_view)
