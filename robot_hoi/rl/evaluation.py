"""Policy evaluation: the protocol that draws each episode's start, the rollout, and the statistics reported.

A protocol (configs/eval/<name>.yaml) says how each episode starts: the default stand at the clip's start (with the
15-frame approach warmup), its position, heading and joints perturbed, and the object's start pose perturbed, every
draw from the env's generator seeded with the evaluation seed (so a seed reproduces every start). `randomized` is
the default; `stand` is one deterministic start, which the policy mean and MuJoCo turn into one trajectory however
many episodes run.

Each episode is scored under two success definitions on the same starts: ours (the task's terminations, with the
object line at 0.12 m, plus interaction success) and InterMimic's (its termination thresholds, supp. E: object and
interaction lines at 0.5 m, a required contact lost for over 10 frames with no distance tolerance). Rates come with
95 % Wilson intervals, means with 95 % t intervals over episodes.

Model selection (the in-training evaluation that keeps model_best.pt) draws its starts from VALIDATION_SEED on:
seeds disjoint from the ones `robot-hoi eval` uses by default, so the score eval reports is not the one the
checkpoint was picked on.
"""

from __future__ import annotations

import copy
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from robot_hoi.errors import UserError
from robot_hoi.paths import CONFIGS_DIR
from robot_hoi.tasks.interaction.env_cfg import RandomizationCfg, split_overrides
from robot_hoi.termination import Thresholds
from robot_hoi.utils.config import apply_overrides, load_yaml_dataclass

DEFAULT_PROTOCOL = "randomized"
DEFAULT_EPISODES = 32
EVAL_SEED = 0                # robot-hoi eval's default
VALIDATION_SEED = 100_000    # + the job's eval seed: the in-training evaluation (model selection)
DEFINITIONS = ("ours", "intermimic")
_Z95 = 1.959963984540054


@dataclass
class EvalProtocol:
    """How evaluation draws each episode's start. Sizes are half-widths of uniform draws unless said otherwise;
    0 makes no draw."""

    stand_xy: float = 0.0           # m, the stand's pelvis position about the reference root's
    stand_yaw: float = 0.0          # rad, the stand's heading about the reference root's
    stand_joint_noise: float = 0.0  # rad, normal std on the stand's actuated body joints
    object_xy: float = 0.0          # m, the object's start position about the clip's
    object_yaw: float = 0.0         # rad, the object's start heading about the clip's
    # object mass x scale, drawn log-uniform per episode (inertia alike); (1, 1): the clip's own mass
    object_mass_scale: tuple[float, float] = (1.0, 1.0)

    @property
    def deterministic(self) -> bool:
        return not any((self.stand_xy, self.stand_yaw, self.stand_joint_noise, self.object_xy, self.object_yaw)) \
            and tuple(self.object_mass_scale) == (1.0, 1.0)


def protocol_names() -> list[str]:
    return sorted(p.stem for p in (CONFIGS_DIR / "eval").glob("*.yaml"))


def load_protocol(name: str) -> tuple[str, EvalProtocol]:
    """(name, protocol) of configs/eval/<name>.yaml or of a YAML path."""
    path = Path(name) if name.endswith((".yaml", ".yml")) else CONFIGS_DIR / "eval" / f"{name}.yaml"
    if not path.is_file():
        raise UserError(f"{path}: no such evaluation protocol (choose from {', '.join(protocol_names())} or a "
                        "YAML path)")
    return path.stem, load_yaml_dataclass(EvalProtocol, path)


def intermimic_thresholds(ours: Thresholds) -> Thresholds:
    """InterMimic's termination (supp. E.1, Sec. 3.2): joints 0.5 m on average, root under 0.15 m, object points
    0.5 m on average, weighted interaction distance 0.5 m, a required contact lost for over 10 frames. Its contact
    is the simulator's: no distance tolerance, not measured from the reference's hand."""
    return Thresholds(max_mean_link_error=0.5, min_root_height=0.15, max_mean_object_point_error=0.5,
                      max_interaction_distance_error=0.5, max_contact_loss_frames=10, contact_tolerance=0.0,
                      contact_from_reference=False)


def evaluation_settings(env_cfg, episodes: int, seed: int, protocol: EvalProtocol | None = None) -> None:
    """Turn a training env config into an evaluation one (in place): `episodes` stand starts drawn by `protocol`
    (None: the one deterministic stand), no PSI, no assist wrenches, no randomisation but the protocol's mass."""
    p = protocol or EvalProtocol()
    env_cfg.num_envs = episodes
    env_cfg.seed = seed
    init = env_cfg.init
    init.stand_start_probability = 1.0
    init.spawn_noise_xy, init.spawn_noise_yaw, init.stand_joint_noise = p.stand_xy, p.stand_yaw, p.stand_joint_noise
    init.object_noise_xy, init.object_noise_yaw = p.object_xy, p.object_yaw
    env_cfg.psi.enabled = False
    env_cfg.assist.enabled = False  # a training curriculum: never in evaluation
    env_cfg.randomization = RandomizationCfg(object_mass_scale=tuple(p.object_mass_scale))


def apply_env_overrides(env_cfg, overrides: list[str]):
    """`--set` values for the environment: "env.key=value" or "key=value" (InteractionEnvCfg keys), and
    "retarget.key=value" (its retarget: block)."""
    items, _ = split_overrides(overrides, bare=True)
    return apply_overrides(env_cfg, items, "--set") if items else env_cfg


def evaluate(env, model, stochastic: bool = False) -> dict[str, Any]:
    """Run each env until its first episode ends; InterMimic's metrics averaged over those episodes, and each
    episode's own values under "per_episode".

    Actions are the policy mean, or samples of the policy's Gaussian with `stochastic` (seed torch first). The
    model runs where its parameters are, the env where its physics is: observations and actions cross over."""
    # torch loads here, not at the top: `robot-hoi --help` imports this module (commands/eval.py's defaults)
    import torch

    from robot_hoi.sim.device import module_device  # imports torch

    policy_device = module_device(model, env.device)
    obs = env.reset()
    finished: dict[str, list[torch.Tensor]] = {}
    counted = torch.zeros(env.num_envs, dtype=torch.bool, device=env.device)
    returns = torch.zeros(env.num_envs, device=env.device)
    with torch.no_grad():
        for _ in range(env.max_episode_length + env.cfg.warmup_frames + 2):
            policy_obs = obs["policy"].to(policy_device)
            actions = model.act(policy_obs) if stochastic else model.act_inference(policy_obs)
            obs, reward, terminated, truncated, extras = env.step(actions.to(env.device))
            returns += torch.where(counted, 0.0, reward)
            done = terminated | truncated
            new = done & ~counted
            if new.any():
                keep = new[done]  # rows of extras["episode"] that belong to first episodes
                for key, value in extras["episode"].items():
                    finished.setdefault(key, []).append(value[keep])
                counted |= new
            if counted.all():
                break
    stats = {k: torch.cat(v) for k, v in finished.items()}
    reasons = {k.split("/", 1)[1]: v for k, v in stats.items() if k.startswith("ended_by/")}
    per_episode = {key: stats[key].tolist() for key in
                   ("success", "interaction_success", "duration_s", "E_h_cm", "E_o_cm", "E_o_max_cm", "E_o_source_cm")}
    per_episode["ended_by"] = [[name for name, fired in reasons.items() if fired[i] > 0] or ["clip_end"]
                               for i in range(int(counted.sum()))]
    return {
        "episodes": int(counted.sum()),
        "success_rate": stats["success"].mean().item(),
        # success that also tracked the object and body (env_cfg success_max_*): a policy that reaches the clip's
        # end without doing the interaction has success but not this
        "interaction_success_rate": stats["interaction_success"].mean().item(),
        "duration_s": stats["duration_s"].mean().item(),
        "E_h_cm": stats["E_h_cm"].mean().item(),
        "E_o_cm": stats["E_o_cm"].mean().item(),
        "E_o_max_cm": stats["E_o_max_cm"].mean().item(),
        # against the clip's own object path; differs from E_o where a planned grasp moved the reference's object
        "E_o_source_cm": stats["E_o_source_cm"].mean().item(),
        "return": returns[counted].mean().item(),
        # share of the episodes each termination ended (several can fire on one step; none: the clip's end)
        "ended_by": {name: v.mean().item() for name, v in reasons.items()},
        "clip_duration_s": env.total_frames / env.references[0].fps,
        # how executable the reference is (robot_hoi.retarget.feasibility), when the env knows
        "reference_feasibility": (getattr(env, "reference_feasibility", None) or [None])[0],
        "per_episode": per_episode,
    }


def evaluate_definitions(env, model, seed: int) -> dict[str, dict[str, Any]]:
    """`evaluate` under each success definition, every one from the same starts (the generator re-seeded)."""
    ours = env.cfg.terminations
    results = {}
    try:
        for name, thresholds in (("ours", ours), ("intermimic", intermimic_thresholds(ours))):
            env.set_terminations(thresholds)
            env.generator.manual_seed(seed)
            results[name] = evaluate(env, model)
    finally:
        env.set_terminations(ours)
    return results


SUMMARY_METRICS = ("success_rate", "interaction_success_rate", "duration_s", "E_h_cm", "E_o_cm", "E_o_max_cm", "return")


def summarise(results: dict[str, dict[str, float]]) -> dict[str, float]:
    """Mean over clips of each per-clip metric (teachers and students alike)."""
    return {k: sum(r[k] for r in results.values()) / max(len(results), 1) for k in SUMMARY_METRICS}


# ---- statistics ---------------------------------------------------------------------------------------------------
def wilson_interval(successes: int, n: int, z: float = _Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial rate (95 % by default): honest at 0/n and n/n, unlike the normal one."""
    if n <= 0:
        return 0.0, 1.0
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    # exact ends at 0/n and n/n (the closed form leaves a rounding residue there)
    return (0.0 if successes == 0 else max(0.0, centre - half)), (1.0 if successes == n else min(1.0, centre + half))


def mean_interval(values: list[float], confidence: float = 0.95) -> dict[str, float | None]:
    """Mean and its two-sided t interval (None bounds for fewer than two values)."""
    n = len(values)
    mean = sum(values) / n if n else float("nan")
    if n < 2:
        return {"mean": mean, "lo": None, "hi": None, "n": n}
    from scipy.stats import t  # ~0.5 s to import, and --help imports this module (see evaluate)

    sd = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1))
    half = t.ppf(0.5 + confidence / 2, n - 1) * sd / math.sqrt(n)
    return {"mean": mean, "lo": mean - half, "hi": mean + half, "n": n}


def rate(flags: list[float]) -> dict[str, float]:
    k, n = int(round(sum(flags))), len(flags)
    lo, hi = wilson_interval(k, n)
    return {"rate": k / n if n else float("nan"), "lo": lo, "hi": hi, "k": k, "n": n}


def definition_report(per_episode: dict[str, list], clip_duration_s: list[float] | float) -> dict[str, Any]:
    """Rates with Wilson intervals, duration (s and share of the clip) and errors with t intervals, and what ended
    the episodes, from per-episode values (one clip, or several pooled with each episode's clip duration)."""
    n = len(per_episode["success"])
    clip_s = clip_duration_s if isinstance(clip_duration_s, list) else [clip_duration_s] * n
    ended: dict[str, int] = {}
    for reasons in per_episode["ended_by"]:
        for name in reasons:
            ended[name] = ended.get(name, 0) + 1
    return {
        "episodes": n,
        "success": rate(per_episode["success"]),
        "interaction_success": rate(per_episode["interaction_success"]),
        "duration_s": mean_interval(per_episode["duration_s"]),
        "duration_share": mean_interval([d / c for d, c in zip(per_episode["duration_s"], clip_s, strict=True)]),
        "E_h_cm": mean_interval(per_episode["E_h_cm"]),
        "E_o_cm": mean_interval(per_episode["E_o_cm"]),
        "E_o_max_cm": mean_interval(per_episode["E_o_max_cm"]),
        "E_o_source_cm": mean_interval(per_episode["E_o_source_cm"]) if "E_o_source_cm" in per_episode else None,
        "ended_by": {k: v / n for k, v in sorted(ended.items(), key=lambda kv: -kv[1])},
    }


def clip_record(results: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """One clip's evaluation record: per definition its report and its per-episode values."""
    any_result = next(iter(results.values()))
    record: dict[str, Any] = {"clip_duration_s": any_result["clip_duration_s"],
                              "reference_feasibility": any_result.get("reference_feasibility")}
    for name, result in results.items():
        record[name] = {**definition_report(result["per_episode"], result["clip_duration_s"]),
                        "per_episode": result["per_episode"]}
    return record


def overall_record(clips: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Every episode of every clip pooled, per definition."""
    overall = {}
    for name in DEFINITIONS:
        pooled: dict[str, list] = {}
        durations: list[float] = []
        for clip in clips.values():
            if name not in clip:
                continue
            for key, values in clip[name]["per_episode"].items():
                pooled.setdefault(key, []).extend(values)
            durations += [clip["clip_duration_s"]] * len(clip[name]["per_episode"]["success"])
        if durations:
            overall[name] = definition_report(pooled, durations)
    return overall


def protocol_record(name: str, protocol: EvalProtocol, episodes: int, seed: int) -> dict[str, Any]:
    return {"name": name, "episodes_per_clip": episodes, "seed": seed, "validation_seed": VALIDATION_SEED,
            "deterministic": protocol.deterministic, **asdict(protocol)}


def protocol_env_cfg(env_cfg, protocol: EvalProtocol | None, episodes: int, seed: int):
    """A deep copy of `env_cfg` set up for `protocol` (evaluation_settings)."""
    cfg = copy.deepcopy(env_cfg)
    evaluation_settings(cfg, episodes, seed, protocol)
    return cfg


def selection_env_cfg(env_cfg, episodes: int, seed: int):
    """What model selection (model_best.pt of teachers and students) validates on: the default protocol's starts,
    under the training's domain randomisation where the run trains with any. A policy meant for the robot is picked
    on the conditions it trains for: picked on nominal physics, a hardware-recipe teacher kept its first checkpoint
    with success 1.00 (0.06 at object mass x2, where its last checkpoint had 0.78)."""
    cfg = protocol_env_cfg(env_cfg, load_protocol(DEFAULT_PROTOCOL)[1], episodes, seed)
    if env_cfg.randomization.is_on():
        cfg.randomization = copy.deepcopy(env_cfg.randomization)
    return cfg


def validation_label(env_cfg) -> dict[str, str]:
    """Added to each model-selection row: what it validated under. Absent for the protocol alone (as in older
    rows); a run's best is compared only with rows validated alike."""
    return {"validation": "training randomization"} if env_cfg.randomization.is_on() else {}
