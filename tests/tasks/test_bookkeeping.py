"""Regression tests of the interaction env's bookkeeping (issue 14, item 3; fixes in ab16be1).

Each test fails on the code before that commit: run against `git archive ab16be1^` with this file copied in, the
failures are the ones named in each docstring ("old: ..."). Small envs (2-4 worlds, CPU backend), few steps.
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from robot_hoi.data.objects import box_asset
from robot_hoi.embodiment import load_embodiment
from robot_hoi.tasks.interaction.env import InteractionEnv
from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg, PsiCfg
from robot_hoi.tasks.interaction.psi import PsiBuffer
from robot_hoi.tasks.interaction.scene_setup import InteractionScene

from .test_interaction_env import standing_reference


@pytest.fixture(scope="module")
def scene():
    return InteractionScene(load_embodiment("g1_inspire"), box_asset((0.4, 0.4, 0.3)))


def make_env(scene, references=None, *, num_envs: int = 2, psi: bool | PsiCfg = False, joint_noise: float = 0.0,
             stand: float = 0.0, start_range=(0.0, 0.0), terminations: dict | None = None, **fields):
    """A small CPU env on standing references: RSI starts at frame 0 without noise unless asked otherwise."""
    cfg = InteractionEnvCfg(num_envs=num_envs, nthread=1, seed=3, backend="cpu")
    cfg.init.joint_noise = joint_noise
    cfg.init.stand_start_probability = stand
    cfg.init.spawn_noise_xy = 0.0
    cfg.init.start_range = start_range
    if isinstance(psi, PsiCfg):
        cfg.psi = psi
    else:
        cfg.psi.enabled = psi
    if terminations:
        cfg.terminations = dataclasses.replace(cfg.terminations, **terminations)
    for key, value in fields.items():
        setattr(cfg, key, value)
    return InteractionEnv(cfg, scene, references or [standing_reference(scene)])


def force_terminations(env, forced) -> list[dict]:
    """Add a reason "forced" (forced(step) -> bool per env) to the env's terminations; returns the per-step record
    of the env's own reasons (before the resets of that step)."""
    original = env._terminations
    record: list[dict] = []

    def wrapped():
        reasons = original()
        record.append({k: v.clone() for k, v in reasons.items()})
        reasons["forced"] = forced(len(record))
        return reasons

    env._terminations = wrapped
    return record


def zeros(env):
    return torch.zeros(env.num_envs, env.num_actions)


def finished_episodes(env, steps: int) -> list[dict]:
    """Step with zero actions; the `episode` stats of every step that ended some episode."""
    out = []
    for _ in range(steps):
        _, _, terminated, truncated, extras = env.step(zeros(env))
        if (terminated | truncated).any():
            out.append({k: v.clone() for k, v in extras["episode"].items()})
    return out


# ---- 1. contact loss counted once per env step ---------------------------------------------------------------------
def test_contact_loss_counted_once_per_step_whatever_other_envs_do(scene):
    """The left hand must touch the box (0.6 m ahead of a standing robot) and never does: its miss counter rises by
    exactly 1 per step and `contact_lost` fires on step max_contact_loss_frames + 1, whether or not other envs reset
    in the same step and for any num_envs.

    Old: `_reset_envs` re-ran `_update_state` (and so the counter) for every env: +1 at the initial reset and +2 in
    every step with a reset: with env 0 reset every step, env 1 counted 2, 4, ... and lost its contact on step 3
    instead of 5 (step 4 without other resets)."""
    max_frames = 4
    reference = standing_reference(scene)
    reference.hand_contact[:, 0] = True
    counts, fired_on = {}, {}
    for num_envs, reset_env0 in ((2, False), (2, True), (5, True)):
        # the surface rule: the standing reference's own hand is as far from the box as the robot's
        env = make_env(scene, [reference], num_envs=num_envs,
                       terminations={"max_contact_loss_frames": max_frames, "contact_from_reference": False})
        forced = torch.zeros(num_envs, dtype=torch.bool)
        forced[0] = reset_env0
        record = force_terminations(env, lambda _step, forced=forced: forced)
        hand = torch.stack([env.d.norm(dim=-1)[:, ids].amin(-1) for ids in env.scene.hand_link_ids], -1)
        assert (hand[:, 0] > 0.05).all() and not env.hand_contact_found[:, 0].any()  # far from the box
        key = (num_envs, reset_env0)
        counts[key] = []
        for step in range(1, max_frames + 3):
            env.step(zeros(env))
            lost = record[-1]["contact_lost"][1:]  # the envs never forced to reset
            if lost.any():
                assert lost.all(), "every never-reset env loses its contact on the same step"
                fired_on[key] = step
                break
            assert (env.contact_loss_frames[1:, 0] == env.contact_loss_frames[1, 0]).all()
            assert (env.contact_loss_frames[1:, 1] == 0).all()  # the right hand is not required
            counts[key].append(int(env.contact_loss_frames[1, 0]))
    expected = list(range(1, max_frames + 1))
    assert counts == {key: expected for key in counts}
    assert fired_on == {key: max_frames + 1 for key in counts}


# ---- 2. d_hat from the simulated surface samples -------------------------------------------------------------------
def test_d_hat_matches_d_on_the_reference_state(scene):
    """Reset exactly onto the reference (RSI, no noise): the simulated link-to-surface vectors d and the reference's
    d_hat must coincide. The reference's own d_hat (as build_reference computes it) uses all the object's surface
    samples, the simulation a strided subset of `object_surface_points`.

    Old: the env kept the reference's d_hat: |d_hat - d| = 3.1 cm here on the reference state itself (1.4 cm on
    embedded:lift_carry)."""
    reference = standing_reference(scene)
    reference.object_pos[:, :2] = torch.tensor([0.35, 0.05])  # box close to the right hand and knees
    reference.d_hat = _d_hat_all_samples(reference)
    assert reference.object_points.shape[0] > 256
    env = make_env(scene, [reference], object_surface_points=256)
    assert torch.allclose(env.link_pos, reference.link_pos[0], atol=1e-4)  # the simulated state is the reference
    assert torch.allclose(env.object_pos, reference.object_pos[0], atol=1e-6)
    gap = (env.d - env.ref.d_hat).norm(dim=-1)
    assert gap.max() < 1e-4, f"|d - d_hat| up to {100 * gap.max():.2f} cm on the reference state"


def _d_hat_all_samples(reference):
    from robot_hoi.tasks.interaction.reference import nearest_surface_vectors
    from robot_hoi.utils.torch_rot import quat_apply

    points = quat_apply(reference.object_quat_wxyz[:, None], reference.object_points[None]) + \
        reference.object_pos[:, None]
    return nearest_surface_vectors(reference.link_pos, points)


# ---- 3. the episode limit covers the longest clip ------------------------------------------------------------------
def test_episode_limit_covers_longest_clip_plus_warmup(scene):
    """A stand start holds the reference for warmup_frames, then needs T - 1 steps to reach a T-frame clip's end.

    Old: max_episode_length = max_episode_frames (300): a clip over 286 frames could never succeed."""
    env = make_env(scene, [standing_reference(scene, 40), standing_reference(scene, 320)])
    assert env.cfg.max_episode_frames == 300
    assert env.max_episode_length >= 320 + env.cfg.warmup_frames + 1


def test_clip_longer_than_max_episode_frames_succeeds_from_the_stand(scene):
    """The same at a size that rolls out in a second: a 20-frame clip with a 5-frame warmup and max_episode_frames
    10 ends in success on step 5 + 19.

    Old: every episode was cut at step 10 (time-out, no success)."""
    env = make_env(scene, [standing_reference(scene, 20)], stand=1.0, warmup_frames=5, max_episode_frames=10)
    episodes = finished_episodes(env, 5 + 19)
    assert len(episodes) == 1, "the only episodes end on the clip's last frame"
    assert episodes[0]["success"].tolist() == [1.0, 1.0]
    assert episodes[0]["duration_s"] == pytest.approx([19 * env.dt] * 2)


# ---- 4. success needs the clip covered; duration after the warmup -------------------------------------------------
def test_success_needs_the_clip_covered(scene):
    """An RSI start on frame 16 of a 20-frame clip reaches the end in 3 steps without termination: not a success
    (covered 3 of 19 frames < success_min_frames_fraction). From frame 0 the same clip is a success.

    Old: `success_min_frames_fraction` was unused: the late start counted as a success."""
    env = make_env(scene, [standing_reference(scene, 20)], start_range=(0.85, 0.85))
    assert env.ref_index.tolist() == [16, 16]
    episodes = finished_episodes(env, 3)
    assert [e["success"].tolist() for e in episodes] == [[0.0, 0.0]]
    env.cfg.init.start_range = (0.0, 0.0)
    env.reset()
    episodes = finished_episodes(env, 19)
    assert [e["success"].tolist() for e in episodes] == [[1.0, 1.0]]


def test_interaction_success_needs_the_object_tracked(scene):
    """A clip whose reference lifts the box 0.2 m at frame 5 while the robot (zero actions) leaves it on the floor
    reaches the clip's end without a termination (object error 0.2 m < 0.5 m): InterMimic's success, but not an
    interaction success (the object's error passed success_max_object_error). Unshifted, both are successes."""
    env = make_env(scene, [standing_reference(scene, 20)])
    episodes = finished_episodes(env, 19)
    assert [e["success"].tolist() for e in episodes] == [[1.0, 1.0]]
    assert episodes[0]["interaction_success"].tolist() == [1.0, 1.0]
    assert (episodes[0]["E_o_max_cm"] < 1.0).all()

    env.ref_object_pos[5:, 2] += 0.2  # the reference lifts the box; the simulated one stays where it was
    env.reset()
    episodes = finished_episodes(env, 19)
    assert [e["success"].tolist() for e in episodes] == [[1.0, 1.0]]
    assert episodes[0]["interaction_success"].tolist() == [0.0, 0.0]
    assert episodes[0]["E_o_max_cm"].tolist() == pytest.approx([20.0, 20.0], abs=1.0)


def test_duration_excludes_the_warmup(scene):
    """A stand start terminated on the first step after its warmup tracked one step: duration dt, not
    (warmup + 1) dt.

    Old: duration_s = episode_length * dt = 16 / 30 = 0.53 s."""
    env = make_env(scene, stand=1.0)
    warmup = env.cfg.warmup_frames
    force_terminations(env, lambda step: torch.full((env.num_envs,), step == warmup + 1))
    episodes = finished_episodes(env, warmup + 1)
    assert len(episodes) == 1
    assert episodes[0]["duration_s"] == pytest.approx([env.dt] * 2)


# ---- 5. PSI ---------------------------------------------------------------------------------------------------------
def test_psi_seeds_spread_over_all_clips(scene):
    """Three 40-frame clips (117 start frames) seeded into a 30-state buffer: every clip has seeds, spread from the
    first clip's start to the last clip's end.

    Old: the buffer kept the last buffer_size frames: all in the last clip, the others never drawn."""
    references = [standing_reference(scene) for _ in range(3)]
    env = make_env(scene, references, psi=PsiCfg(buffer_size=30), start_range=(0.0, 1.0))
    frames = env.psi.frames[: len(env.psi)]
    assert len(env.psi) == 30
    clips = torch.bucketize(frames, env.clip_end)
    assert set(clips.tolist()) == {0, 1, 2}
    assert frames.min() <= 5 and frames.max() >= env.total_frames - 6


def test_psi_seed_rows_draw_fresh_noise(scene):
    """With one seed row that every reset draws (sample_probability 1), each draw gets its own RSI noise: the
    seeded rows are placeholders (NaN), not a frozen state.

    Old: the seed held one noisy state: every env started with the same joint noise, reset after reset."""
    env = make_env(scene, psi=PsiCfg(buffer_size=1, sample_probability=1.0), num_envs=3, joint_noise=0.05,
                   start_range=(0.0, 1.0))
    body_q = torch.as_tensor(env.layout.actuator_qpos)[env.body_actuator_ids]
    first = env.backend.qpos[:, body_q].clone()
    env.reset()
    second = env.backend.qpos[:, body_q].clone()
    draws = torch.cat([first, second])  # six draws from the same seed row
    assert torch.cdist(draws, draws).add(torch.eye(6, dtype=draws.dtype)).min() > 1e-3
    assert env.psi.states[: len(env.psi)].isnan().all()


class _CandidateEnv(SimpleNamespace):
    """What PsiBuffer.observe reads of an env."""

    def current_states(self):
        return torch.zeros(self.num_envs, 5)


def test_psi_admits_relative_to_the_running_returns():
    """Candidates whose per-step reward is ~0.1 (a typical value): after the first batch sets the running
    statistics, those above the mean are admitted, whatever the reward scale.

    Old: admitted only above a fixed per-step return of 0.5: with rewards of 0.1 the buffer never grew."""
    num_envs, horizon = 8, 3
    psi = PsiBuffer(PsiCfg(update_probability=1.0), state_dim=5, generator=torch.Generator().manual_seed(0),
                    horizon=horizon)
    env = _CandidateEnv(num_envs=num_envs, warmup_left=torch.zeros(num_envs, dtype=torch.long),
                        ref_index=torch.arange(num_envs))
    reward = 0.1 + 0.02 * torch.linspace(-1, 1, num_envs)
    done = torch.zeros(num_envs, dtype=torch.bool)
    for _ in range(4 * (horizon + 1)):
        psi.observe(env, reward, done)
    assert psi.admitted > 0 and len(psi) == psi.admitted
    assert (psi.frames[: len(psi)] >= num_envs // 2).all(), "only the better half of the candidates"


def test_psi_admit_is_scale_free():
    """PsiBuffer.admit on returns ~0.1 and on the same returns x100: the same candidates enter."""
    returns = 0.1 + 0.01 * torch.randn(3, 64, generator=torch.Generator().manual_seed(1))
    kept = []
    for scale in (1.0, 100.0):
        psi = PsiBuffer(PsiCfg(), state_dim=5, generator=torch.Generator().manual_seed(0))
        assert not psi.admit(scale * returns[0]).any()  # the first batch only sets the statistics
        kept.append(torch.stack([psi.admit(scale * r) for r in returns[1:]]))
    assert torch.equal(kept[0], kept[1])
    assert 0.2 < kept[0].float().mean() < 0.8


# ---- 6. RSI noise on the actuated body joints only -----------------------------------------------------------------
def test_rsi_noise_only_on_body_joints(scene):
    """A reference start with joint noise: finger channels and their passive (mimic) joints keep the reference's
    values exactly; the actuated body joints are noisy.

    Old: noise on every joint of qpos[7:], which breaks the mimic couplings of the fingers."""
    env = make_env(scene, num_envs=4, joint_noise=0.1)
    qpos = env.backend.qpos[:, : env.layout.robot_nq].float()
    reference = env.ref_robot_qpos[env.ref_index]
    body_q = set(np.asarray(env.layout.actuator_qpos)[env.body_actuator_ids].tolist())
    rest = [q for q in range(7, env.layout.robot_nq) if q not in body_q]
    assert len(rest) > 12  # 12 finger channels and their mimic joints
    assert torch.equal(qpos[:, rest], reference[:, rest])
    assert torch.equal(qpos[:, :7], reference[:, :7])
    noise = qpos[:, sorted(body_q)] - reference[:, sorted(body_q)]
    assert 0.05 < noise.std() < 0.2


# ---- 7. hand contact labels from inference -------------------------------------------------------------------------
def test_hand_contact_markers_follow_inference_where_it_disagrees():
    """Stored labels vs contacts inferred from the object's dynamics (supp. C.1), per hand and frame:
    inferred +1 on any hand body -> required; inferred -1 on all of them -> not required; inferred 0 -> stored.

    Old: the stored labels only."""
    from robot_hoi.data.layout import BODY_INDEX, NUM_BODIES
    from robot_hoi.tasks.interaction.reference import _hand_contact_markers

    frames = 4
    stored = np.zeros((frames, NUM_BODIES), np.int8)
    inferred = np.zeros((frames, NUM_BODIES), np.int8)
    left = [i for n, i in BODY_INDEX.items() if n == "L_Wrist" or (n.startswith("L_") and n[2:-1] in
            ("Index", "Middle", "Ring", "Pinky", "Thumb"))]
    right = [i for n, i in BODY_INDEX.items() if n == "R_Wrist" or (n.startswith("R_") and n[2:-1] in
             ("Index", "Middle", "Ring", "Pinky", "Thumb"))]
    stored[0, BODY_INDEX["R_Wrist"]] = 1          # frame 0: stored says right touches, inference says far
    inferred[0, right] = -1
    inferred[1, BODY_INDEX["L_Index2"]] = 1       # frame 1: stored says nothing, inference: left index touches
    stored[2, BODY_INDEX["L_Thumb1"]] = 1         # frame 2: inference neutral: the stored label stays
    stored[3, BODY_INDEX["R_Middle3"]] = 1        # frame 3: right inferred far on all but one body: stays
    inferred[3, right[1:]] = -1
    clip = SimpleNamespace(body_contact=stored, inferred_body_contact=inferred)
    need = _hand_contact_markers(clip, frames)
    assert need.tolist() == [[False, False], [True, False], [True, False], [False, True]]
    assert len(left) == len(right) == 16
    # without inference (all zeros) the stored labels stand
    clip = SimpleNamespace(body_contact=stored, inferred_body_contact=np.zeros_like(inferred))
    assert _hand_contact_markers(clip, frames).tolist() == [[False, True], [False, False], [True, False],
                                                            [False, True]]


# ---- 9. accelerations from a copy of the previous velocities --------------------------------------------------------
def _falling_box_reference(scene):
    reference = standing_reference(scene)
    reference.object_pos[:, 2] += 0.2  # released 20 cm above the floor: it falls freely for ~6 steps
    return reference


def test_accelerations_survive_resets_in_the_step(scene):
    """After a step in which env 0 resets, the other envs keep their finite-difference accelerations: the box falls
    freely (object_acc_z = -g) and link_acc = (v_t - v_{t-1}) / dt.

    Old: the reset re-ran `_update_state` for all envs with prev = current: link_acc and object_acc were 0."""
    env = make_env(scene, [_falling_box_reference(scene)], num_envs=3)
    force_terminations(env, lambda step: torch.tensor([True, False, False]))
    actions = 0.3 * torch.randn(3, env.num_actions, generator=torch.Generator().manual_seed(0))
    env.step(actions)  # one step for a nonzero velocity
    before = env.link_vel.clone()
    env.step(actions)
    assert env.object_acc[1:, 2] == pytest.approx([-9.81, -9.81], abs=0.05)
    expected = (env.link_vel[1:] - before[1:]) / env.dt
    assert expected.abs().max() > 0.1
    assert torch.allclose(env.link_acc[1:], expected, atol=1e-4)


class Float32LiveBackend:
    """The CPU backend seen as MuJoCo Warp presents its state: float32 tensors updated in place, so that
    `.to(torch.float32)` returns the live buffer itself and a kept reference to it changes with the next step."""

    def __init__(self, inner):
        self.inner = inner
        self._qpos, self._qvel = inner.qpos.float().clone(), inner.qvel.float().clone()
        self._sens = inner.sensordata.float().clone()

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def _sync(self):
        self._qpos.copy_(self.inner.qpos)
        self._qvel.copy_(self.inner.qvel)
        self._sens.copy_(self.inner.sensordata)

    def step(self, ctrl, wrench=None):
        self.inner.step(ctrl) if wrench is None else self.inner.step(ctrl, wrench)
        self._sync()

    def set_state(self, env_ids, qpos, qvel):
        self.inner.set_state(env_ids, qpos, qvel)
        self._sync()

    @property
    def qpos(self):
        return self._qpos

    @property
    def qvel(self):
        return self._qvel

    @property
    def sensordata(self):
        return self._sens


def test_accelerations_with_live_float32_state(scene):
    """On a backend whose state tensors are live float32 buffers (MuJoCo Warp's; emulated on the CPU backend), the
    previous velocities are a copy: a freely falling box has object_acc_z = -g after a step, links nonzero.

    Old: prev_link_vel / prev_object_vel were views of the live state, so the step updated them too: both 0."""
    env = make_env(scene, [_falling_box_reference(scene)], num_envs=2)
    env.backend = Float32LiveBackend(env.backend)
    env.reset()
    assert env.backend.sensordata.to(torch.float32) is env.backend.sensordata  # what makes a view "live"
    env.step(0.3 * torch.randn(2, env.num_actions, generator=torch.Generator().manual_seed(0)))
    assert env.object_acc[:, 2] == pytest.approx([-9.81, -9.81], abs=0.05)
    assert env.link_acc.abs().max() > 0.1


def test_object_error_is_reported_against_the_clip_s_own_path_too(scene):
    """A reference whose object path a grasp moved 5 cm off the clip's own: E_o follows the reference's path,
    E_o_source the clip's, so a reference cannot make the task easier by moving the object unnoticed."""
    moved = standing_reference(scene)
    moved.source_object_pos = moved.object_pos + torch.tensor([0.05, 0.0, 0.0])
    moved.source_object_quat_wxyz = moved.object_quat_wxyz.clone()
    env = make_env(scene, [moved], terminations={"max_mean_link_error": 10.0})
    done = torch.zeros(env.num_envs, dtype=torch.bool)
    for _ in range(5):
        _, _, terminated, truncated, extras = env.step(torch.zeros(env.num_envs, env.num_actions))
        done |= terminated | truncated
    assert not done.any()
    stats = env._episode_stats(torch.ones(env.num_envs, dtype=torch.bool), done, done)
    assert (stats["E_o_cm"] < 1.0).all()  # the box rests where the reference has it
    assert torch.allclose(stats["E_o_source_cm"], torch.full_like(stats["E_o_source_cm"], 5.0), atol=1.0)
    plain = make_env(scene)  # a reference without a source path of its own: the two agree
    plain.step(torch.zeros(plain.num_envs, plain.num_actions))
    ones = torch.ones(plain.num_envs, dtype=torch.bool)
    stats = plain._episode_stats(ones, ~ones, ~ones)
    assert torch.allclose(stats["E_o_cm"], stats["E_o_source_cm"])
