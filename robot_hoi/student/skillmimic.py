"""SkillMimic-V2 wired into the student run: STF starts (with stitching and ATS) through the env's start sampler,
the masked frames through StudentEnv, and the frozen history encoder as the "history" observation group."""

from __future__ import annotations

from pathlib import Path

import torch

from deploy.atomic import atomic_path
from robot_hoi.errors import UserError
from robot_hoi.student.ats import AdaptiveTrajectorySampler
from robot_hoi.student.config import SkillMimicConfig
from robot_hoi.student.history import (
    HistoryEncoder,
    HistoryProvider,
    feature_index,
    pretrain,
    reference_features,
)
from robot_hoi.student.samplers import StartSampler
from robot_hoi.student.stf import StateTransitionField, StitchedGraph, reference_track
from robot_hoi.tasks.interaction.mdp.observations import student_observation_spec

ENCODER_FILE = "history_encoder.pt"


def load_history_encoder(path: Path, num_features: int, cfg: SkillMimicConfig) -> HistoryEncoder:
    """The frozen encoder a SkillMimic-V2 run saved (OUT/history_encoder.pt), in eval mode."""
    encoder = HistoryEncoder(num_features, cfg.history_length, cfg.history_dim)
    try:
        encoder.load_state_dict(torch.load(path, weights_only=True)["state"])
    except FileNotFoundError:
        raise UserError(f"{path}: the student's history encoder is missing (written by `robot-hoi train student` "
                        "with SkillMimic-V2; keep the run folder together)") from None
    except (RuntimeError, KeyError, TypeError) as exc:
        raise UserError(f"{path}: not this student's history encoder ({type(exc).__name__}: {exc})") from None
    encoder.eval()
    encoder.requires_grad_(False)
    return encoder


class SkillMimicSetup:
    def __init__(self, cfg: SkillMimicConfig, env, out: Path, seed: int = 0) -> None:
        self.cfg, self.env = cfg, env
        self.generator = torch.Generator().manual_seed(seed + 7919)
        self.encoder: HistoryEncoder | None = None
        self.index = feature_index(student_observation_spec(env))
        if cfg.history:
            self.encoder = self._history_encoder(Path(out) / ENCODER_FILE, seed)

    def _history_encoder(self, path: Path, seed: int) -> HistoryEncoder:
        cfg = self.cfg
        if path.exists():
            print(f"[skillmimic] history encoder from {path}")
            return load_history_encoder(path, self.index.numel(), cfg)
        encoder = HistoryEncoder(self.index.numel(), cfg.history_length, cfg.history_dim)
        sequences = [reference_features(self.env, ref) for ref in self.env.references]
        losses = pretrain(encoder, sequences, cfg, seed)
        with atomic_path(path) as tmp:
            torch.save({"state": encoder.state_dict(), "losses": torch.tensor(losses)}, tmp)
        shown = f"{losses[0]:.3g} -> {losses[-1]:.3g}" if losses else "no steps"
        print(f"[skillmimic] history encoder pre-trained by behaviour cloning ({shown}), frozen: {path}")
        return encoder

    def providers(self) -> dict:
        if self.encoder is None:
            return {}
        return {"history": HistoryProvider(self.encoder, self.index, self.env.num_envs)}

    def spec_extra(self) -> list[dict]:
        return [] if self.encoder is None else [{"name": "history", "size": self.cfg.history_dim}]

    def attach(self, runner, student_env) -> None:
        cfg, env = self.cfg, self.env
        ats = None
        if cfg.ats:
            ats = AdaptiveTrajectorySampler(env.clip_start, env.clip_end, env.max_episode_length, cfg.ats_lambda,
                                            cfg.class_lambda, cfg.ats_ema_decay)
            student_env.listeners.append(ats.observe)
            runner.stateful["ats"] = ats
        graph = None
        if cfg.stf and cfg.stitching and len(env.references) > 1:
            graph = StitchedGraph(reference_track(env), env.ref_robot_qpos[:, :2].cpu(), env.clip_start.cpu(),
                                  env.clip_end.cpu(), cfg)
            edges = {c: graph.num_edges(c) for c in range(len(env.references))}
            print(f"[skillmimic] stitched trajectory graph: connections per clip {edges}")
        field = StateTransitionField(env, cfg, self.generator, ats, graph)
        sampler = StartSampler(env.num_envs, len(env.references), self.generator,
                               ats.clip_probabilities if ats is not None else None, field)
        env.start_sampler = sampler
        runner.stateful["start_sampler"] = sampler

        def scalars(iteration: int) -> dict[str, float]:
            out = {"Sampling/masked_frames_mean": float(sampler.records["hold"].float().mean())}
            if ats is not None:
                out["Sampling/ats_frames_visited"] = float((ats.visits > 0).float().mean())
                out["Sampling/ats_mean_reward"] = float(ats.mean_reward[ats.visits > 0].mean()) \
                    if bool((ats.visits > 0).any()) else 0.0
            return out

        runner.iteration_hooks.append(scalars)
