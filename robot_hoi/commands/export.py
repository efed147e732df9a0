"""`robot-hoi export`: a trained policy -> ONNX carrying the deploy contract, verified on the way out."""

from __future__ import annotations

import argparse
from pathlib import Path

from robot_hoi.data.cli_options import add_clip_options, clip_options
from robot_hoi.paths import EXPORT_DIR


def register(subparsers) -> None:
    p = subparsers.add_parser("export", help="export a policy to ONNX (with the metadata a runtime needs)",
                              description=__doc__)
    sub = p.add_subparsers(dest="export_command", metavar="FORMAT", required=True)
    o = sub.add_parser("onnx", help="export a checkpoint to ONNX and verify it (checker, ORT == torch, latency)")
    o.add_argument("checkpoint", nargs="?", default=None,
                   help="model_*.pt, or a run or group folder (its latest checkpoint); required unless --untrained")
    o.add_argument("-o", "--output", default=None, help="output .onnx (default policies/<run>-<group>.onnx)")
    o.add_argument("--recorded", type=int, default=1000,
                   help="observations recorded in the training env to compare ONNX Runtime with torch on")
    o.add_argument("--untrained", action="store_true",
                   help="export a freshly initialised deployable (student-observation) policy for development, "
                        "with the reference motion of --data (default: the embedded clip)")
    o.add_argument("--data", nargs="*", default=None, help="with --untrained: the clip to track")
    o.add_argument("--embodiment", default="g1_inspire",
                   help="with --untrained: robot name under configs/embodiments/ or a YAML path")
    o.add_argument("--seed", type=int, default=0, help="with --untrained")
    o.add_argument("--clip", default=None,
                   help="student: the default skill, whose reference is <name>.motion.npz (every clip it learnt "
                        "gets a sidecar)")
    add_clip_options(o)
    o.set_defaults(func=run_onnx)
    c = sub.add_parser("check", help="check an ONNX policy file against the deploy contract (exit 1: not "
                                     "deployable, e.g. a teacher)")
    c.add_argument("file")
    c.add_argument("--embodiment", default=None,
                   help="also check it against this robot (a name under configs/embodiments/ or a YAML path)")
    c.set_defaults(func=run_check)


def _no_checkpoint_named() -> None:
    """Exporting whatever happens to be newest would deploy the wrong policy without a word: make the user say."""
    from robot_hoi.errors import UserError

    found = sorted(Path("runs").glob("**/model_*.pt"), key=lambda p: p.stat().st_mtime)
    hint = f"; the newest here is {found[-1]}" if found else ""
    raise UserError(f"name the checkpoint to export (a model_*.pt or its run folder){hint}; or --untrained")


def run_onnx(args: argparse.Namespace) -> int:
    if args.untrained:
        return run_untrained(args)

    from robot_hoi.embodiment import build_model, load_embodiment
    from robot_hoi.errors import UserError
    from robot_hoi.export.metadata import clip_identity, policy_metadata
    from robot_hoi.export.onnx_export import export_policy
    from robot_hoi.export.recording import offset_settings, record_observations
    from robot_hoi.rl.checkpoint import load_policy, resolve_checkpoint
    from robot_hoi.tasks.interaction import factory
    from robot_hoi.tasks.interaction.env_cfg import saved_env_cfg
    from robot_hoi.tasks.interaction.mdp.observations import teacher_observation_spec

    if not args.checkpoint:
        _no_checkpoint_named()
    ckpt = resolve_checkpoint(args.checkpoint)
    from robot_hoi.student.checkpoint import is_student_checkpoint

    if is_student_checkpoint(ckpt):
        from robot_hoi.export.student import run_student_export

        return run_student_export(args, ckpt)
    model, train_cfg, _ = load_policy(ckpt)
    task = factory.read_task(ckpt)
    embodiment = load_embodiment(task["embodiment"])
    env_cfg = saved_env_cfg(task["env"], f"{ckpt} task")
    env_cfg.num_envs = 16
    clips = [factory.load_source(s, clip_options(args, task.get("clip_options"))) for s in task["sources"]]
    env = factory.make_env(clips, env_cfg, embodiment, cache=ckpt.parent / "references")
    if env.obs_dims["policy"] != model.num_actor_obs:
        raise UserError(f"{ckpt}: policy expects {model.num_actor_obs} observations, the task now gives "
                        f"{env.obs_dims['policy']}; the task code changed since training")

    recorded_obs = record_observations(env, lambda o: model.act_inference(o["policy"]), "policy", args.recorded)

    out = Path(args.output) if args.output else EXPORT_DIR / f"{ckpt.parent.parent.name}-{ckpt.parent.name}.onnx"
    metadata = policy_metadata(
        embodiment, build_model(embodiment), policy_kind="teacher", obs_spec=teacher_observation_spec(env),
        keyframes=env_cfg.keyframes, action_clip=env_cfg.action_clip,
        clips=[clip_identity(c, s) for c, s in zip(clips, task["sources"], strict=True)],
        **offset_settings(env_cfg), env_cfg=env_cfg,
    )
    report = export_policy(model.exported_policy(), model.num_actor_obs, metadata, out, recorded_obs=recorded_obs)
    for line in report.lines():
        print(line)
    print("note: a teacher reads privileged simulation state; deploy a distilled student on hardware")
    return 0


def run_check(args: argparse.Namespace) -> int:
    import json

    from robot_hoi.export.onnx_export import check_onnx_file

    metadata = check_onnx_file(args.file)
    kind = json.loads(metadata.get("policy_kind", '"unknown"'))
    print(f"{args.file}: valid ONNX, policy_kind {kind}, {len(metadata)} metadata keys")
    if kind == "teacher":
        print("not deployable: a teacher reads privileged simulation state the robot cannot measure; distil a "
              "student (robot-hoi train student) and export that (robot-hoi play shows a teacher in simulation)")
        return 1
    if kind != "teacher":
        from deploy.contract import PolicyContract, check_against_embodiment

        contract = PolicyContract.from_onnx(args.file)
        print(f"deploy contract ok: {contract.num_actions} actuators, obs {contract.obs_dim}, "
              f"control_dt {contract.control_dt}")
        if args.embodiment:
            from robot_hoi.embodiment.config import resolve_embodiment_path

            check_against_embodiment(contract, resolve_embodiment_path(args.embodiment))
            print(f"matches embodiment {args.embodiment}")
    return 0


def run_untrained(args: argparse.Namespace) -> int:
    """A freshly initialised deployable policy + its motion sidecar: what deploy and sim2sim run before training."""
    import torch

    from deploy.motion import file_sha256
    from robot_hoi.embodiment import build_model, load_embodiment
    from robot_hoi.export.metadata import clip_identity, policy_metadata
    from robot_hoi.export.motion_sidecar import deploy_motion
    from robot_hoi.export.onnx_export import export_policy
    from robot_hoi.export.recording import offset_settings, record_observations
    from robot_hoi.paths import TASK_CONFIG
    from robot_hoi.rl.config import PRESETS, load_train_config
    from robot_hoi.rl.models import ActorCritic
    from robot_hoi.tasks.interaction import factory
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg
    from robot_hoi.tasks.interaction.mdp.observations import DEFAULT_STUDENT_TERMS, student_observation_spec
    from robot_hoi.utils.config import load_yaml_dataclass

    embodiment = load_embodiment(args.embodiment)
    env_cfg = load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG, ["num_envs=16", "psi.enabled=false"])
    env_cfg.student_obs_terms = DEFAULT_STUDENT_TERMS
    sources = factory.expand_sources(args.data)[:1]
    clip = factory.load_source(sources[0], clip_options(args))
    env = factory.make_env([clip], env_cfg, embodiment)
    torch.manual_seed(args.seed)
    model = ActorCritic(env.obs_dims["student"], env.obs_dims["critic"], env.num_actions,
                        load_train_config(PRESETS["fast"]).model).eval()
    recorded = record_observations(env, lambda o: model.act_inference(o["student"]), "student", args.recorded)

    out = Path(args.output) if args.output else EXPORT_DIR / "untrained.onnx"
    motion_file = out.with_name(out.stem + ".motion.npz")
    deploy_motion(env.references[0], source=str(motion_file)).save(motion_file)
    metadata = policy_metadata(
        embodiment, build_model(embodiment), policy_kind="untrained", obs_spec=student_observation_spec(env),
        keyframes=env_cfg.student_keyframes, action_clip=env_cfg.action_clip,
        clips=[clip_identity(clip, sources[0])],
        reference={"file": motion_file.name, "sha256": file_sha256(motion_file)},
        **offset_settings(env_cfg), env_cfg=env_cfg,
    )
    report = export_policy(model.exported_policy(), env.obs_dims["student"], metadata, out, recorded_obs=recorded)
    for line in report.lines():
        print(line)
    print(f"wrote {motion_file} (reference motion, {env.references[0].num_frames} frames)")
    return 0
