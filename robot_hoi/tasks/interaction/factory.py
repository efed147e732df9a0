"""From user inputs to environments: load clips, group them into teachers, retarget, build the env.

Clip sources are recorded as strings so a run can be rebuilt later: a file path, or `embedded:<kind>` for the
project's own synthetic clip (license-free, generated on demand).
"""

from __future__ import annotations

import copy
import json
import re
from collections import OrderedDict, defaultdict
from dataclasses import asdict, replace
from pathlib import Path

from deploy.atomic import atomic_write_text
from robot_hoi.data.clip import load_clip
from robot_hoi.data.synth import BASE_MOTIONS, embedded_clip
from robot_hoi.embodiment import build_model
from robot_hoi.errors import UserError
from robot_hoi.retarget.feasibility import kinematic_feasibility
from robot_hoi.retarget.motion import RobotMotion
from robot_hoi.retarget.pipeline import RetargetOptions, retarget_clip
from robot_hoi.tasks.interaction.env import InteractionEnv
from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg, RetargetCfg
from robot_hoi.tasks.interaction.reference import build_reference
from robot_hoi.tasks.interaction.scene_setup import InteractionScene
from robot_hoi.utils.fingerprint import fingerprint

EMBEDDED_PREFIX = "embedded:"
CLIP_SUFFIXES = (".pt", ".npz")
# The embedded stand-lift-place clip: the first clip a teacher completes on a CPU budget (no walking).
DEFAULT_SOURCE = f"{EMBEDDED_PREFIX}lift_place"
GROUP_KEYS = ("subject", "object", "clip")
TASK_FILE = "task.json"


def expand_sources(data: list[str] | None) -> list[str]:
    """Files and folders -> clip sources (sorted); nothing -> the embedded default clip."""
    if not data:
        return [DEFAULT_SOURCE]
    sources: list[str] = []
    for item in data:
        if item == f"{EMBEDDED_PREFIX}base":  # the base-motion library (robot_hoi.data.synth.BASE_MOTIONS)
            sources += [f"{EMBEDDED_PREFIX}{kind}:{seed}" for kind, seed in BASE_MOTIONS]
            continue
        if item.startswith(EMBEDDED_PREFIX):
            sources.append(item)
            continue
        path = Path(item)
        if path.is_dir():
            found = sorted(p for p in path.iterdir() if p.suffix in CLIP_SUFFIXES)
            if not found:
                raise UserError(f"{path}: no clips (*.pt, *.npz) in this folder")
            sources += [str(p) for p in found]
        elif path.is_file():
            sources.append(str(path))
        else:
            raise UserError(f"{path}: no such clip file or folder")
    return sources


def load_source(source: str, clip_options: dict | None = None):
    """One clip from a source string (validated by the data layer); clip_options: load_clip keywords
    (robot_hoi.data.cli_options: objects folder, repair)."""
    if source.startswith(EMBEDDED_PREFIX):
        return embedded_clip(source[len(EMBEDDED_PREFIX):])
    return load_clip(source, **(clip_options or {}))


def group_sources(sources: list[str], clips: list, by: str) -> dict[str, list[int]]:
    """Teacher groups (InterMimic trains one teacher per subject). Clips of different objects never share an env,
    so a group spanning several objects is split per object."""
    if by not in GROUP_KEYS:
        raise UserError(f"--group must be one of {', '.join(GROUP_KEYS)}, not {by!r}")
    groups: dict[str, list[int]] = defaultdict(list)
    for i, clip in enumerate(clips):
        key = {"subject": clip.subject or "unknown", "object": clip.object_name, "clip": clip.name}[by]
        groups[_safe(f"{key}") if by != "subject" else _safe(f"{key}-{clip.object_name}")].append(i)
    return dict(sorted(groups.items()))


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


# Retargets made in this process, by content of (clip, embodiment): an IK retarget of a clip takes seconds, and
# evaluation, student and test code build several envs of the same clip. Bounded; entries are deep-copied out.
_RETARGETS: OrderedDict[str, object] = OrderedDict()
_RETARGETS_KEPT = 8


# The retarget settings a task chooses, each as the user spells it: (key, the RetargetOptions value it sets, its name
# in errors). The retarget.* keys are the task config's retarget: block (env_cfg.RetargetCfg)
_RETARGET_SETTINGS = (
    ("retarget.leg_loads", ("executable", "compensate_leg_loads"), "leg-load compensation"),
    ("retarget.dynamics", ("executable", "compensate_dynamics"), "dynamics compensation"),
    ("retarget.finger_closure", ("grasp", "closure"), "finger closure"),
    ("retarget.squeeze_toward", ("executable", "squeeze_toward"), "squeeze"),
    ("retarget.squeeze_depth", ("executable", "squeeze_depth"), "squeeze depth"),
    ("env.object_collision", ("mapping", "object_collision"), "object collision shape"),
    ("retarget.solver", ("ik", "solver"), "IK solver"),
    ("retarget.grasp", ("grasp_plan", "enabled"), "grasp planning"),
    ("retarget.anchor_mode", ("mapping", "anchor_mode"), "anchor mode"),
)
_RETARGET_GROUPS = tuple(dict.fromkeys(group for _, (group, _), _ in _RETARGET_SETTINGS))  # where a cache records them


def _task_setting(env_cfg: InteractionEnvCfg, key: str):
    section, name = key.split(".")
    return getattr(env_cfg.retarget if section == "retarget" else env_cfg, name)


def retarget_options(env_cfg: InteractionEnvCfg | None = None):
    """RetargetOptions with the task's retarget settings (the retarget's defaults where the config has none; the
    values were checked when the config was built, env_cfg.RetargetCfg)."""
    options = RetargetOptions()
    if env_cfg is None:
        return options
    for key, (group, name), _ in _RETARGET_SETTINGS:
        value = _task_setting(env_cfg, key)
        if value is not None:
            options = replace(options, **{group: replace(getattr(options, group), **{name: value})})
    # planned grips carry the weight the simulation gives the object
    return replace(options, grasp_plan=replace(options.grasp_plan, object_density=env_cfg.object_density))


def load_or_retarget(clip, embodiment, cache: Path | None, options=None):
    """The clip's robot-space reference (RobotMotion), cached as npz next to the run. `options`: RetargetOptions
    (retarget_options(env_cfg); None = the defaults); a cached reference made with other task settings (the task
    config's retarget: block, env.object_collision) is an error, not silently reused."""
    options = options if options is not None else retarget_options()
    path = cache / f"{_safe(clip.name)}.npz" if cache is not None else None
    clip_key = fingerprint(clip)
    if path is not None and path.exists():
        motion = RobotMotion.load(path)
        made_from = motion.meta.get("clip_fingerprint")  # older files: only the frame count can be checked
        if motion.num_frames != clip.num_frames or made_from not in (None, clip_key):
            raise UserError(f"{path}: this reference was retargeted from another version of clip {clip.name} "
                            f"({motion.num_frames} frames, the clip has {clip.num_frames}); delete the file to "
                            "retarget, or use the clip it was made from")
        for name in RetargetCfg.REMOVED_KEYS:  # a removed setting left on in the cache: refused, not ignored
            made_with = next((motion.meta[group][name] for group in _RETARGET_GROUPS
                              if motion.meta.get(group, {}).get(name)), None)
            if made_with:
                raise UserError(f"{path}: this reference was retargeted with {name} {made_with}, a setting that was "
                                "removed; delete the file to retarget")
        defaults = retarget_options()
        for setting, (group, name), label in _RETARGET_SETTINGS:
            default = getattr(getattr(defaults, group), name)
            made_with = motion.meta.get(group, {}).get(name, default)  # older files: the default of its time
            wanted = getattr(getattr(options, group), name)
            if made_with != wanted:
                raise UserError(f"{path}: this reference was retargeted with {label} {_setting(made_with)}, the task "
                                f"asks for it {_setting(wanted)} ({setting}); delete the file to retarget, or keep the "
                                "setting it was made with")
        return motion
    key = fingerprint((clip, embodiment, options))
    if key in _RETARGETS:
        _RETARGETS.move_to_end(key)
        motion = copy.deepcopy(_RETARGETS[key])
    else:
        motion = retarget_clip(clip, embodiment, options=options).motion
        motion.meta["feasibility"] = kinematic_report(motion, embodiment)
        _RETARGETS[key] = copy.deepcopy(motion)
        while len(_RETARGETS) > _RETARGETS_KEPT:
            _RETARGETS.popitem(last=False)
    motion.meta["clip_fingerprint"] = clip_key
    if path is not None:
        motion.save(path)
    return motion


def _setting(value) -> str:
    if isinstance(value, str):
        return value
    return ("on" if value else "off") if isinstance(value, bool) else f"{value:g}"


def kinematic_report(motion, embodiment) -> dict:
    """Foot slide, CoM outside support, joint speeds and self-penetration of a retarget
    (robot_hoi.retarget.feasibility)."""
    hand_joints = {c.joint for hand in embodiment.hands.values() for c in hand.channels}
    body = [i for i, n in enumerate(embodiment.actuator_names) if n not in hand_joints]
    feet = [n for n in embodiment.link_map if "ankle_roll" in n]
    return kinematic_feasibility(build_model(embodiment), motion, feet, body,
                                 self_collision_model=build_model(embodiment, self_collision=True))


def make_env(clips: list, env_cfg: InteractionEnvCfg, embodiment, cache: Path | None = None, motions=None):
    """An InteractionEnv tracking `clips` (all with the same object); `motions`: their retargets, if at hand."""
    objects = {c.object_name for c in clips}
    if len(objects) != 1:
        raise UserError(f"one environment holds one object; these clips use {sorted(objects)}")
    if clips[0].object is None:
        raise UserError(f"clip {clips[0].name}: no object mesh loaded; the simulation needs it")
    scene = InteractionScene.for_task(embodiment, clips[0].object, env_cfg)
    motions = motions or [load_or_retarget(c, embodiment, cache, retarget_options(env_cfg)) for c in clips]
    references = [build_reference(c, m, env_cfg.reference_links) for c, m in zip(clips, motions, strict=True)]
    env = InteractionEnv(env_cfg, scene, references)
    # the retarget's feasibility figures where the retarget carries them (retargets made here and cached ones do);
    # motions handed in without them are not re-analysed: that compiles another model per env
    env.reference_feasibility = [m.meta.get("feasibility") for m in motions]
    return env


def write_task(run_dir: Path, sources: list[str], env_cfg: InteractionEnvCfg, embodiment_name: str,
               group: str, clip_options: dict | None = None) -> None:
    info = {"sources": sources, "clip_options": clip_options or {}, "group": group, "embodiment": embodiment_name,
            "env": asdict(env_cfg)}
    atomic_write_text(run_dir / TASK_FILE, json.dumps(info, indent=2) + "\n")


def read_task(checkpoint: Path) -> dict:
    """task.json beside a checkpoint (or in its parent folder)."""
    for folder in (checkpoint.parent, checkpoint.parent.parent):
        path = folder / TASK_FILE
        if path.exists():
            try:
                return json.loads(path.read_text())
            except json.JSONDecodeError as exc:
                raise UserError(f"{path}: not valid JSON ({exc})") from None
    raise UserError(f"{checkpoint}: no {TASK_FILE} next to the checkpoint; pass --data to say what to evaluate")
