"""`robot-hoi export`: a trained policy -> ONNX carrying the deploy contract, verified on the way out."""

from __future__ import annotations

import argparse
from pathlib import Path

from robot_hoi.paths import POLICIES_DIR, REPO_ROOT


def register(subparsers) -> None:
    p = subparsers.add_parser("export", help="export a policy to ONNX (with the metadata a runtime needs)",
                              description=__doc__)
    sub = p.add_subparsers(dest="export_command", metavar="FORMAT", required=True)
    o = sub.add_parser("onnx", help="export a checkpoint to ONNX and verify it (checker, ORT == torch, latency)")
    o.add_argument("checkpoint", nargs="?", default=None,
                   help="model_*.pt (default: the newest checkpoint under runs/)")
    o.add_argument("-o", "--output", default=None, help="output .onnx (default policies/<run>-<group>.onnx)")
    o.add_argument("--recorded", type=int, default=1000, help="recorded observations to verify against")
    o.set_defaults(func=run_onnx)
    c = sub.add_parser("check", help="check an ONNX policy file against the deploy contract")
    c.add_argument("file")
    c.add_argument("--embodiment", default=None, help="also check it against this embodiment config")
    c.set_defaults(func=run_check)


def newest_checkpoint(root: Path = REPO_ROOT / "runs") -> Path:
    from robot_hoi.errors import UserError

    found = sorted(root.glob("**/model_*.pt"), key=lambda p: p.stat().st_mtime)
    if not found:
        raise UserError(f"no checkpoint under {root}; train one first (robot-hoi train) or name it")
    return found[-1]


def run_onnx(args: argparse.Namespace) -> int:
    import numpy as np
    import torch

    from robot_hoi.embodiment import build_model, load_embodiment
    from robot_hoi.errors import UserError
    from robot_hoi.export.metadata import clip_identity, policy_metadata
    from robot_hoi.export.onnx_export import export_policy
    from robot_hoi.rl.checkpoint import load_policy
    from robot_hoi.tasks.interaction import factory
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg
    from robot_hoi.tasks.interaction.mdp.observations import teacher_observation_spec
    from robot_hoi.utils.config import load_dataclass

    ckpt = Path(args.checkpoint) if args.checkpoint else newest_checkpoint()
    if not ckpt.is_file():
        raise UserError(f"{ckpt}: no such checkpoint")
    model, train_cfg, _ = load_policy(ckpt)
    task = factory.read_task(ckpt)
    embodiment = load_embodiment(task["embodiment"])
    env_cfg = load_dataclass(InteractionEnvCfg, task["env"], f"{ckpt} task")
    env_cfg.num_envs = 16
    clips = [factory.load_source(s) for s in task["sources"]]
    env = factory.make_env(clips, env_cfg, embodiment, cache=ckpt.parent / "references")
    if env.obs_dims["policy"] != model.num_actor_obs:
        raise UserError(f"{ckpt}: policy expects {model.num_actor_obs} observations, the task now gives "
                        f"{env.obs_dims['policy']}; the task code changed since training")

    recorded = []
    obs = env.reset()
    with torch.no_grad():
        while sum(len(r) for r in recorded) < args.recorded:
            recorded.append(obs["policy"].numpy().copy())
            obs, *_ = env.step(model.act_inference(obs["policy"]))
    recorded_obs = np.concatenate(recorded)[: args.recorded]

    out = Path(args.output) if args.output else POLICIES_DIR / f"{ckpt.parent.parent.name}-{ckpt.parent.name}.onnx"
    metadata = policy_metadata(
        embodiment, build_model(embodiment), policy_kind="teacher", obs_spec=teacher_observation_spec(env),
        keyframes=env_cfg.keyframes, action_clip=env_cfg.action_clip,
        clips=[clip_identity(c, s) for c, s in zip(clips, task["sources"], strict=True)],
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
