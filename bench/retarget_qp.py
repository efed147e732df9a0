"""QP retarget speed: wall seconds of `retarget_clip` (retarget.solver=qp, the task's other settings) per
second of clip, and of the physics gate after it (issue 48: a clip retargets with its gate in at most twice its
own duration).

    PYTHONPATH=. python bench/retarget_qp.py [--repeats 3] [--clips sub2_woodchair_006 ...] [--no-gate]

The embedded lift_place clip always; with ../shared, also OMOMO clips from reference/motions/clips (default: the
chair, the slowest; skipped cleanly without ../shared). Per clip: frames, clip seconds, the object's convex
decomposition (CoACD, done once per process before the timed runs: read from the cache folder, or made and
written there), the median retarget over --repeats runs and its ratio to the clip's duration, and the gate's
median. Wall times include any share of the CPU taken by other work (the load average is printed): compare runs
made in the same conditions. The last line, `qp_retarget_seconds_per_clip_second: <value>`, is lift_place's
retarget ratio (goal: with the gate, <= 2).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def timed(fn, repeats: int) -> tuple[float, object]:
    """(median wall seconds, the last result) of `repeats` calls."""
    seconds, out = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        seconds.append(time.perf_counter() - start)
    return statistics.median(seconds), out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--clips", nargs="*", default=["sub2_woodchair_006"],
                        help="OMOMO clip names in ../shared/reference/motions/clips (default: the chair)")
    parser.add_argument("--no-gate", action="store_true", help="time the retarget only")
    args = parser.parse_args(argv)

    from robot_hoi.embodiment import build_model, load_embodiment
    from robot_hoi.paths import TASK_CONFIG, shared_dir
    from robot_hoi.retarget.pipeline import retarget_clip
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg
    from robot_hoi.tasks.interaction.factory import load_source, retarget_options
    from robot_hoi.tasks.interaction.feasibility import physics_gate
    from robot_hoi.utils.config import apply_overrides, load_yaml_dataclass

    cfg = load_embodiment("g1_inspire")
    model = build_model(cfg)
    task = apply_overrides(load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG), ["retarget.solver=qp"], "--set")
    options = retarget_options(task)
    sources = ["embedded:lift_place"]
    folder = shared_dir() / "reference" / "motions" / "clips" if shared_dir() is not None else None
    for name in args.clips:
        if folder is not None and (folder / f"{name}.pt").is_file():
            sources.append(str(folder / f"{name}.pt"))
        else:
            print(f"{name}: skipped (no ../shared/reference/motions/clips/{name}.pt)")
    print(f"load average {os.getloadavg()[0]:.1f} at start, {os.cpu_count()} core(s), "
          f"object collision {task.object_collision}")
    headline = None
    for source in sources:
        clip = load_source(source)
        start = time.perf_counter()
        if task.object_collision == "decomposed":
            clip.object.convex_parts()
        decomposition = time.perf_counter() - start
        retarget, result = timed(lambda clip=clip: retarget_clip(clip, cfg, model, options=options), args.repeats)
        ratio = retarget / clip.duration
        line = (f"{clip.name}: {clip.num_frames} frames, {clip.duration:.1f} s; decomposition {decomposition:.2f} s; "
                f"QP retarget {retarget:.2f} s ({ratio:.2f} x the clip, {result.motion.meta['qp_fallbacks']} "
                "fallbacks)")
        if not args.no_gate:
            gate, verdict = timed(lambda clip=clip, result=result: physics_gate(clip, task, cfg, result.motion),
                                  args.repeats)
            line += f"; gate {gate:.2f} s ({verdict['verdict']}); with it {(retarget + gate) / clip.duration:.2f} x"
        print(line, flush=True)
        if headline is None:
            headline = ratio
    print(f"load average {os.getloadavg()[0]:.1f} at the end")
    print(f"qp_retarget_seconds_per_clip_second: {headline:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
