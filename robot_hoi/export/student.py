"""Student checkpoint -> ONNX with the deploy contract (policy_kind "student") and the motion sidecar.

The student reads only the deployable observation, so its file is what the robot runs. Each clip it learnt is a
skill with a sidecar: the reference the student tracked in training for that clip (the teacher's rollout with
reference distillation); `--clip` names the default one (<name>.motion.npz), the others are
<name>.<clip>.motion.npz, listed in the metadata's data.clips. The export is verified like every export:
onnx.checker, ORT vs torch on random and recorded observations. The sidecars' joint angles, the PD targets of a
zero action (action_offset "reference"), must lie inside the joint limits.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
from pathlib import Path

import numpy as np

from deploy.motion import file_sha256
from robot_hoi.embodiment import build_model, load_embodiment
from robot_hoi.errors import UserError
from robot_hoi.export.metadata import actuator_limits, clip_identity, policy_metadata
from robot_hoi.export.motion_sidecar import deploy_motion
from robot_hoi.export.onnx_export import export_policy
from robot_hoi.export.recording import offset_settings, record_observations
from robot_hoi.paths import EXPORT_DIR
from robot_hoi.student.checkpoint import load_student
from robot_hoi.student.reference_distill import LIMIT_MARGIN
from robot_hoi.student.task import build_task_env, read_student_task, task_folder
from robot_hoi.tasks.interaction.env_cfg import saved_env_cfg
from robot_hoi.tasks.interaction.mdp.observations import student_observation_spec


def run_student_export(args: argparse.Namespace, ckpt: Path) -> int:
    model, cfg, data = load_student(ckpt)
    if model.layout.obs_dim != data["dims"]["actor_obs"] or cfg.runner.actor_obs_groups != ["student"]:
        raise UserError(f"{ckpt}: this student also reads {cfg.runner.actor_obs_groups[1:]} (the SkillMimic-V2 "
                        "history embedding); the deploy contract has no history observation yet, so it cannot be "
                        "exported: train a deployable one with --option skillmimic_deployable "
                        "(= --set skillmimic.history=false)")
    task = read_student_task(ckpt)
    folder = task_folder(ckpt)
    env_cfg = saved_env_cfg(task["env"], f"{folder}/task.json")
    env_cfg.num_envs = 16
    env_cfg.psi.enabled = False
    env, clips, sources, references, index = build_task_env(task, folder, env_cfg, clip=getattr(args, "clip", None))
    spec = student_observation_spec(env)
    if env.obs_dims["student"] != model.num_actor_obs or spec != data["student"].get("obs_spec", spec):
        raise UserError(f"{ckpt}: the student expects {model.num_actor_obs} observations, its task now gives "
                        f"{env.obs_dims['student']}; the observation code changed since training")
    recorded = record_observations(env, lambda o: model.act_inference(o["student"]), "student", args.recorded)

    out = Path(args.output) if args.output else EXPORT_DIR / f"{folder.parent.name}-student.onnx"
    embodiment = load_embodiment(task["embodiment"])
    mj_model = build_model(embodiment)
    lower, upper, _ = actuator_limits(mj_model, embodiment.actuator_names)
    # one sidecar per clip (a skill): the chosen clip's is the default <name>.motion.npz
    identities = []
    for i, clip in enumerate(clips):
        stem = out.stem if i == index else f"{out.stem}.{re.sub(r'[^A-Za-z0-9_-]+', '_', clip.name)}"
        motion_file = out.with_name(stem + ".motion.npz")
        write_sidecar(references[i], motion_file, lower, upper)
        identities.append({**clip_identity(clip, sources[i]),
                           "motion": {"file": motion_file.name, "sha256": file_sha256(motion_file)}})
        print(f"wrote {motion_file} (reference of {clip.name}, {references[i].num_frames} frames"
              f"{', the default skill' if i == index else ''})")
    metadata = policy_metadata(
        embodiment, mj_model, policy_kind="student", obs_spec=spec,
        keyframes=env_cfg.student_keyframes, action_clip=env_cfg.action_clip,
        clips=[identities[index]] + identities[:index] + identities[index + 1:],
        reference=identities[index]["motion"],
        **offset_settings(env_cfg), env_cfg=env_cfg,
    )
    report = export_policy(model.exported_policy(), model.num_actor_obs, metadata, out, recorded_obs=recorded)
    for line in report.lines():
        print(line)
    return 0


def write_sidecar(reference, path: Path, lower, upper) -> None:
    """The deploy sidecar of a reference; joints clipped into the limits where an old distilled reference left
    them (reference_distill.FORMAT 1)."""
    motion = deploy_motion(reference, source=str(path))
    outside = reference_outside_limits(motion.joint_pos, lower, upper)
    if outside:
        motion = dataclasses.replace(motion, joint_pos=np.clip(motion.joint_pos, lower + LIMIT_MARGIN,
                                                               upper - LIMIT_MARGIN))
        print(f"note: {path.name}: reference joints clipped into the joint limits ({outside})")
    motion.save(path)


def reference_outside_limits(joint_pos, lower, upper) -> str:
    """'' when every reference joint angle lies inside [lower, upper], else which joints leave them and by how much."""
    excess = np.maximum(lower - joint_pos, joint_pos - upper)  # (T, A), > 0 outside
    bad = np.flatnonzero((excess > 0).any(axis=0))
    if bad.size == 0:
        return ""
    return (f"{bad.size} joint(s) on {int((excess > 0).any(axis=1).sum())} of {len(joint_pos)} frames, "
            f"at most {1e3 * float(excess.max()):.2f} mrad outside")
