"""The student's task: which clips, which references (distilled or MoCap), which env config; saved as task.json
beside the student checkpoints so export and evaluation rebuild the exact environment the student trained in."""

from __future__ import annotations

import copy
import json
import re
from dataclasses import asdict
from pathlib import Path

from deploy.atomic import atomic_write_text
from deploy.safety import SafetyConfig
from robot_hoi.embodiment import load_embodiment
from robot_hoi.errors import UserError
from robot_hoi.rl.evaluation import protocol_env_cfg
from robot_hoi.student.reference_distill import load_reference
from robot_hoi.tasks.interaction import factory
from robot_hoi.tasks.interaction.env import InteractionEnv
from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg, saved_env_cfg
from robot_hoi.tasks.interaction.mdp.observations import DEFAULT_STUDENT_TERMS
from robot_hoi.tasks.interaction.reference import build_reference
from robot_hoi.tasks.interaction.scene_setup import InteractionScene

TASK_FILE = factory.TASK_FILE
STUDENT_GROUP = "student"


def evaluation_cfg(env_cfg: InteractionEnvCfg, num_envs: int, seed: int = 0, protocol=None) -> InteractionEnvCfg:
    """As `robot-hoi eval`: every episode from the stand at the clip start drawn by `protocol` (None: the one
    deterministic stand), no PSI, no assist."""
    return protocol_env_cfg(env_cfg, protocol, num_envs, seed)


def student_env_cfg(env_cfg: InteractionEnvCfg) -> InteractionEnvCfg:
    """The teachers' env config with the deployable observation group switched on (its terms: the config's, e.g.
    from --option object_free, else DEFAULT_STUDENT_TERMS) and the robot runtime's limit on how fast PD targets
    move (unless the config sets one): a student that leaned on faster target steps fell in sim2sim's turns, where
    the runtime cut them."""
    cfg = copy.deepcopy(env_cfg)
    cfg.student_obs_terms = tuple(cfg.student_obs_terms) or DEFAULT_STUDENT_TERMS
    if cfg.command_rate_limit is None:
        cfg.command_rate_limit = SafetyConfig().max_target_rate
    cfg.assist.enabled = False  # the teachers' curriculum; the student learns from teachers that no longer need it
    return cfg


def mocap_reference(clip, embodiment, env_cfg: InteractionEnvCfg, cache: Path | None):
    return build_reference(clip, factory.load_or_retarget(clip, embodiment, cache, factory.retarget_options(env_cfg)),
                           env_cfg.reference_links)


def make_scene(clip, embodiment, env_cfg: InteractionEnvCfg):
    if clip.object is None:
        raise UserError(f"clip {clip.name}: no object mesh loaded; the simulation needs it")
    return InteractionScene.for_task(embodiment, clip.object, env_cfg)


def object_scenes(clips, embodiment, env_cfg: InteractionEnvCfg) -> dict[str, InteractionScene]:
    """One scene per object the clips use (a scene holds one object), keyed by object name."""
    scenes: dict[str, InteractionScene] = {}
    for clip in clips:
        if clip.object_name not in scenes:
            scenes[clip.object_name] = make_scene(clip, embodiment, env_cfg)
    return scenes


def write_student_task(folder: Path, *, sources: list[str], references: list[str | None],
                       env_cfg: InteractionEnvCfg, embodiment_name: str, extra: dict) -> None:
    """references[i]: path of clip i's distilled reference relative to `folder`, or None (MoCap retarget)."""
    info = {"sources": sources, "references": references, "group": STUDENT_GROUP, "embodiment": embodiment_name,
            "env": asdict(env_cfg), **extra}
    atomic_write_text(folder / TASK_FILE, json.dumps(info, indent=2) + "\n")


def read_student_task(checkpoint: Path) -> dict:
    task = factory.read_task(Path(checkpoint))
    if task.get("group") != STUDENT_GROUP or "references" not in task:
        raise UserError(f"{checkpoint}: the {TASK_FILE} beside it is not a student task")
    return task


def task_folder(checkpoint: Path) -> Path:
    for folder in (checkpoint.parent, checkpoint.parent.parent):
        if (folder / TASK_FILE).exists():
            return folder
    raise UserError(f"{checkpoint}: no {TASK_FILE} beside it")


def task_references(task: dict, folder: Path, env_cfg: InteractionEnvCfg, reference: str = "trained"):
    """(embodiment, clips, sources, references) of a student task. reference "trained": the references it trained
    on (distilled where it had them); "mocap": the clips' MoCap retargets."""
    embodiment = load_embodiment(task["embodiment"])
    sources = list(task["sources"])
    clips = [factory.load_source(s, task.get("clip_options")) for s in sources]
    references = []
    for clip, rel in zip(clips, task["references"], strict=True):
        if rel is not None and reference == "trained":
            path = (folder / rel).resolve()
            if not path.exists():
                raise UserError(f"{path}: the student's distilled reference is missing (it is written by "
                                "`robot-hoi train student`; keep the run folder together)")
            references.append(load_reference(path)[0])
        else:
            references.append(mocap_reference(clip, embodiment, env_cfg, retarget_cache(task, folder, clip)))
    return embodiment, clips, sources, references


def retarget_cache(task: dict, folder: Path, clip) -> Path:
    """Where the clip's MoCap retarget is cached: the teacher run's references/ that holds it (the retarget the
    student trained with), else the student's own references/."""
    name = f"{re.sub(r'[^A-Za-z0-9_.-]+', '_', clip.name)}.npz"
    for teacher in task.get("teachers", []):
        cache = Path(teacher).parent / "references"
        if (cache / name).is_file():
            return cache
    return folder / "references"


def build_task_env(task: dict, folder: Path, env_cfg: InteractionEnvCfg | None = None,
                   reference: str = "trained", clip: str | None = None):
    """(InteractionEnv, clips, sources, references, index) of a student task on its `reference`s (see
    task_references); the env holds the clips of the object of clip `clip` (a name; default the first): a scene
    holds one object. `index`: that clip's among `clips`."""
    cfg = env_cfg or saved_env_cfg(task["env"], f"{folder / TASK_FILE}")
    embodiment, clips, sources, references = task_references(task, folder, cfg, reference)
    names = [c.name for c in clips]
    if clip is not None and clip not in names:
        raise UserError(f"--clip {clip!r}: the student trained on {names}")
    index = names.index(clip) if clip is not None else 0
    same_object = [r for c, r in zip(clips, references, strict=True) if c.object_name == clips[index].object_name]
    env = InteractionEnv(cfg, make_scene(clips[index], embodiment, cfg), same_object)
    return env, clips, sources, references, index
