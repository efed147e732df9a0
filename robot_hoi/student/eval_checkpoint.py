"""`robot-hoi eval STUDENT_CHECKPOINT`: the teachers' metrics (success, duration, E_h, E_o, return) for a student.

Same protocol as for a teacher (robot_hoi/rl/evaluation.py): every episode from the stand at the clip start, drawn
by the evaluation protocol, no PSI, deterministic actions, scored under both success definitions. The student is rebuilt from its checkpoint and the task.json beside it, and
is evaluated per clip against
  - the MoCap retarget ("mocap"), the reference the teachers were scored on, and
  - its distilled reference ("distilled"), when it trained on one: the reference its export deploys with.
With --data, the given clips are evaluated against their MoCap retargets only (generalisation to unseen clips).
"""

from __future__ import annotations

from pathlib import Path

from robot_hoi.embodiment import load_embodiment
from robot_hoi.errors import UserError
from robot_hoi.rl.checkpoint import resolve_checkpoint
from robot_hoi.rl.evaluation import (
    EvalProtocol,
    apply_env_overrides,
    clip_record,
    evaluate_definitions,
    overall_record,
)
from robot_hoi.rl.policy_eval import make_record, resolve_protocol
from robot_hoi.student.checkpoint import load_student
from robot_hoi.student.evaluation import GroupsAsPolicy
from robot_hoi.student.history import HistoryProvider, feature_index
from robot_hoi.student.skillmimic import ENCODER_FILE, load_history_encoder
from robot_hoi.student.student_env import StudentEnv
from robot_hoi.student.task import (
    evaluation_cfg,
    mocap_reference,
    object_scenes,
    read_student_task,
    retarget_cache,
    task_folder,
    task_references,
)
from robot_hoi.tasks.interaction import factory
from robot_hoi.tasks.interaction.env import InteractionEnv
from robot_hoi.tasks.interaction.env_cfg import saved_env_cfg
from robot_hoi.tasks.interaction.mdp.observations import student_observation_spec

REFERENCES = ("mocap", "distilled")


def student_providers(groups: list[str], env, cfg, folder: Path) -> dict:
    """Observation providers for the student's extra actor groups (the SkillMimic-V2 history embedding)."""
    providers = {}
    for group in groups[1:]:
        if group != "history":
            raise UserError(f"the student reads observation group {group!r}, which evaluation cannot rebuild")
        index = feature_index(student_observation_spec(env))
        encoder = load_history_encoder(folder.parent / ENCODER_FILE, index.numel(), cfg.skillmimic)
        providers[group] = HistoryProvider(encoder, index, env.num_envs)
    return providers


def evaluate_student(checkpoint: str | Path, data: list[str] | None = None, episodes: int = 8,
                     seed: int = 0, overrides: list[str] | None = None,
                     protocol: EvalProtocol | None = None) -> dict[str, dict[str, dict]]:
    """results[reference][clip] -> the clip's evaluation record (robot_hoi.rl.evaluation.clip_record), reference in
    REFERENCES ("distilled" only where the student had one). `protocol` None: the one deterministic stand."""
    if episodes < 1:
        raise UserError(f"--episodes must be at least 1, got {episodes}")
    checkpoint = Path(checkpoint)
    model, cfg, stored = load_student(checkpoint)
    task = read_student_task(checkpoint)
    folder = task_folder(checkpoint)
    env_cfg = evaluation_cfg(saved_env_cfg(task["env"], f"{folder}/task.json"), episodes, seed,
                             protocol)
    env_cfg = apply_env_overrides(env_cfg, overrides or [])  # after: `--set` may evaluate under other settings
    groups = list(cfg.runner.actor_obs_groups)
    cases: list[tuple[str, object, object]] = []  # (reference kind, clip, reference motion)
    if data:
        embodiment = load_embodiment(task["embodiment"])
        for source in factory.expand_sources(data):
            clip = factory.load_source(source, task.get("clip_options"))
            cache = retarget_cache(task, folder, clip)
            cases.append(("mocap", clip, mocap_reference(clip, embodiment, env_cfg, cache)))
    else:
        embodiment, clips, _, mocap = task_references(task, folder, env_cfg, "mocap")
        _, _, _, trained = task_references(task, folder, env_cfg, "trained")
        for clip, rel, mocap_ref, trained_ref in zip(clips, task["references"], mocap, trained, strict=True):
            cases.append(("mocap", clip, mocap_ref))
            if rel is not None:
                cases.append(("distilled", clip, trained_ref))
    results: dict[str, dict[str, dict[str, float]]] = {}
    scenes = object_scenes([clip for _, clip, _ in cases], embodiment, env_cfg)
    for kind, clip, reference in cases:
        env = InteractionEnv(env_cfg, scenes[clip.object_name], [reference])
        spec = student_observation_spec(env)
        if spec != stored["student"].get("obs_spec", spec)[:len(spec)]:
            raise UserError(f"{checkpoint}: the student's observation terms differ from what the task gives now; "
                            "the observation code changed since training")
        wrapped = StudentEnv(env, student_providers(groups, env, cfg, folder))
        width = sum(wrapped.obs_dims[g] for g in groups)
        if width != model.num_actor_obs:
            raise UserError(f"{checkpoint}: the student expects {model.num_actor_obs} observations, clip "
                            f"{clip.name} gives {width}")
        results.setdefault(kind, {})[clip.name] = clip_record(
            evaluate_definitions(GroupsAsPolicy(wrapped, groups), model, seed))
    return results


def student_record(request) -> dict:
    """The evaluation record (robot_hoi.rl.policy_eval) of the student checkpoint `request.checkpoint`: its MoCap
    reference per clip, and its distilled reference beside it where it trained on one."""
    name, protocol = resolve_protocol(request)
    ckpt = resolve_checkpoint(request.checkpoint)
    clips = evaluate_student(ckpt, request.data, request.episodes, request.seed, request.overrides, protocol)
    record = make_record(request, name, protocol, "student", ckpt, clips["mocap"])
    if "distilled" in clips:
        record["distilled"] = {"clips": clips["distilled"], "overall": overall_record(clips["distilled"])}
    return record
