"""SkillMimic-V2's mechanics: similarity and connection rule (Eq. 6, 19, 20), epsilon-NSI, stitching, ATS (Eq. 8),
masked frames through the env's start hook, and the behaviour-cloned history encoder (Eq. 21-23)."""

import math

import pytest
import torch

from robot_hoi.student.ats import AdaptiveTrajectorySampler, ats_probabilities, trackable_frames
from robot_hoi.student.config import SkillMimicConfig
from robot_hoi.student.history import (
    HistoryEncoder,
    HistoryProvider,
    feature_index,
    pretrain,
    reference_features,
    windows,
)
from robot_hoi.student.samplers import StartSampler
from robot_hoi.student.stf import (
    KinematicTrack,
    StateLayout,
    StateTransitionField,
    StitchedGraph,
    connect,
    masked_frames,
    perturb_states,
    reference_states,
    reference_track,
    similarity,
)
from robot_hoi.student.student_env import StudentEnv
from robot_hoi.tasks.interaction.mdp.observations import student_observation_spec

from .conftest import make_env, make_reference

CFG = SkillMimicConfig()


def track(link, joint, obj):
    return KinematicTrack(torch.tensor(link, dtype=torch.float32), torch.tensor(joint, dtype=torch.float32),
                          torch.tensor(obj, dtype=torch.float32))


def test_similarity_and_connection_rule():
    a = track([[0.0, 0.0, 1.0], [0.0, 0.2, 1.0]], [0.0, 0.0], [0.5, 0.0, 0.5])
    assert similarity(a, a, CFG).item() == pytest.approx(1.0)
    b = track([[0.1, 0.0, 1.0], [0.1, 0.2, 1.0]], [0.0, 0.3], [0.5, 0.0, 0.5])
    # links: mse 0.1^2 / 3 over xyz -> 20 * 0.01 / 3; joints: mse 0.09 / 2 -> 20 * 0.045; object: 0;
    # relative to the object: the same 0.1 m link shift -> 20 * 0.01 / 3
    expected = math.exp(-(20 * 0.01 / 3 + 20 * 0.045 + 20 * 0.01 / 3))
    assert similarity(a, b, CFG).item() == pytest.approx(expected, rel=1e-5)
    n, valid = masked_frames(torch.tensor([1.0, 0.5, 0.05, 1e-5, 1e-12]), 1e-10, 10)
    assert n.tolist() == [0, 1, 2, 5, 10] and valid.tolist() == [True, True, True, True, False]


def test_connect_finds_the_nearest_reference_state(scene):
    ref = make_reference(scene, 20, drift=0.02)
    tr = KinematicTrack(ref.link_pos, ref.joint_pos, ref.object_pos)
    probe = tr[torch.tensor([7, 12])]
    probe = KinematicTrack(probe.link_pos + 0.004, probe.joint_pos, probe.object_pos + 0.004)
    j, beta = connect(probe, tr, CFG)
    assert j.tolist() == [7, 12] and (beta > 0.99).all()


def test_epsilon_neighbourhood_stays_within_bounds(scene):
    env = make_env(scene, [make_reference(scene, 10)])
    lay = StateLayout.of(env)
    states = reference_states(env)
    moved = perturb_states(states, lay, CFG, torch.Generator().manual_seed(0))
    diff = moved - states
    assert diff[:, 0:2].abs().max() <= 0.1 + 1e-6 and ((diff[:, 2] >= 0) & (diff[:, 2] <= 0.1 + 1e-6)).all()
    joints = moved[:, lay.actuator_qpos]
    assert (joints >= lay.joint_low - 1e-6).all() and (joints <= lay.joint_high + 1e-6).all()
    assert diff[:, lay.actuator_qpos].abs().max() <= 0.1 + 1e-6
    assert torch.allclose(moved[:, 3:7].norm(dim=-1), torch.ones(10), atol=1e-5)
    # root rotation: a rotation vector inside the +-0.1 cube turns by at most sqrt(3) * 0.1
    dot = (moved[:, 3:7] * states[:, 3:7]).sum(-1).abs().clamp(max=1.0)
    assert (2 * torch.acos(dot)).max() <= math.sqrt(3) * 0.1 + 1e-4
    o = lay.object
    assert ((diff[:, o + 2] >= 0) & (diff[:, o + 2] <= 0.1 + 1e-6)).all()


def test_stitched_graph_aligns_other_clips(scene):
    here = make_reference(scene, 12, name="here")
    there = make_reference(scene, 12, name="there", offset_x=2.0)  # the same motion 2 m away
    env = make_env(scene, [here, there])
    graph = StitchedGraph(reference_track(env), env.ref_robot_qpos[:, :2], env.clip_start, env.clip_end, CFG)
    src, dst, offset = graph.edges[0]
    assert src.min() >= 12 and (dst < 11).all()  # sources from clip 1, targets in clip 0 (not its last frame)
    assert torch.allclose(offset, torch.tensor([-2.0, 0.0]).expand_as(offset), atol=1e-5)
    strict = SkillMimicConfig(similarity_threshold=0.5)
    other = make_reference(scene, 12, name="other")
    other.joint_pos = other.joint_pos + 1.0  # a very different pose: no connection passes tau = 0.5
    env2 = make_env(scene, [here, other])
    assert StitchedGraph(reference_track(env2), env2.ref_robot_qpos[:, :2], env2.clip_start, env2.clip_end,
                         strict).num_edges(0) == 0


def test_ats_probabilities_and_records():
    assert ats_probabilities(torch.tensor([0.0, 0.5]), 10.0).tolist() == pytest.approx(
        [1 / (1 + math.exp(-5)), math.exp(-5) / (1 + math.exp(-5))])
    assert trackable_frames(torch.tensor([5, 90]), torch.tensor([99, 99]), 60, torch.tensor([3, 0])).tolist() == [57, 9]
    ats = AdaptiveTrajectorySampler(torch.tensor([0, 10]), torch.tensor([9, 19]), 300, 10.0, 5.0, decay=0.5)
    ats.record(torch.tensor([3, 3, 12]), torch.tensor([0.8, 0.4, 1.0]))
    assert ats.mean_reward[3].item() == pytest.approx(0.6) and ats.mean_reward[12].item() == 1.0
    p = ats.frame_probabilities(0)
    assert p.shape == (9,) and p[3].item() == pytest.approx(math.exp(-6) / (8 + math.exp(-6)))
    clip_mean = torch.tensor([0.6 / 9, 1.0 / 9])
    assert ats.clip_probabilities().tolist() == pytest.approx(torch.softmax(-5.0 * clip_mean, 0).tolist())


def field_env(scene, references, cfg, num_envs=4):
    env = make_env(scene, references, num_envs=num_envs)
    gen = torch.Generator().manual_seed(1)
    ats = AdaptiveTrajectorySampler(env.clip_start, env.clip_end, env.max_episode_length, cfg.ats_lambda,
                                    cfg.class_lambda, cfg.ats_ema_decay)
    sampler = StartSampler(num_envs, len(references), gen, None, StateTransitionField(env, cfg, gen, ats))
    env.start_sampler = sampler
    return env, sampler, ats


def test_masked_frames_hold_the_reference_and_earn_no_reward(scene):
    cfg = SkillMimicConfig(neighbourhood_probability=1.0)  # every start from the neighbourhood
    env, sampler, ats = field_env(scene, [make_reference(scene, 30, drift=0.01)], cfg)
    env.cfg.init.stand_start_probability = 0.0
    wrapped = StudentEnv(env)
    episodes = []
    wrapped.listeners.append(episodes.append)
    wrapped.listeners.append(ats.observe)
    wrapped.reset()
    hold = sampler.records["hold"].clone()
    assert sampler.records["custom"].all() and (hold >= 0).all() and hold.max() <= 10
    assert torch.equal(env.warmup_left, hold) and torch.equal(env.ref_index, sampler.records["start_frame"])
    start = env.ref_index.clone()
    for step in range(int(hold.max()) + 1):
        _, reward, terminated, truncated, _ = wrapped.step(torch.zeros(env.num_envs, env.num_actions))
        alive = ~(terminated | truncated)
        masked = (step < hold) & alive
        assert (reward[masked] == 0).all()
        assert torch.equal(env.ref_index[masked], start[masked])  # the clock is held while masked
    for _ in range(40):
        wrapped.step(torch.zeros(env.num_envs, env.num_actions))
    # finished episodes report how they started; ATS folded them into r_i of their start (centroid) frames
    ended = [e for e in episodes if len(e.clip)]
    assert ended and all(bool(e.start["custom"].all()) for e in ended)
    centroids = torch.cat([e.start["centroid"] for e in ended])
    assert (ats.visits[centroids] > 0).all() and int(ats.visits.sum()) == centroids.numel()


def test_field_starts_at_reference_frames_without_neighbourhood(scene):
    cfg = SkillMimicConfig(neighbourhood_probability=0.0, external_probability=0.0)
    env, sampler, _ = field_env(scene, [make_reference(scene, 30, drift=0.01)], cfg)
    env.cfg.init.stand_start_probability = 0.0
    env.reset()
    frames = sampler.records["start_frame"]
    assert torch.equal(sampler.records["centroid"], frames) and (sampler.records["hold"] == 0).all()
    expected = reference_states(env)[frames]
    assert torch.allclose(env.backend.qpos[:, : env.layout.robot_nq].float(), expected[:, : env.layout.robot_nq],
                          atol=1e-5)


def test_history_features_match_the_student_observation(scene):
    reference = make_reference(scene, 30, drift=0.01)
    cfg = SkillMimicConfig(neighbourhood_probability=0.0, external_probability=0.0, ats=False)
    env, sampler, _ = field_env(scene, [reference], cfg)
    env.cfg.init.stand_start_probability = 0.0
    obs = env.reset()
    index = feature_index(student_observation_spec(env))
    assert index.numel() == 3 + 3 + 41 + 29 + 3 + 6
    features = reference_features(env, env.references[0])
    got = obs["student"][:, index]
    assert torch.allclose(got, features[sampler.records["start_frame"]], atol=1e-4)


def test_history_windows_pretraining_and_provider():
    seq = torch.arange(5, dtype=torch.float32)[:, None]
    past, now, after = windows(seq, 3)
    assert past[:, :, 0].tolist() == [[0, 0, 0], [0, 0, 0], [0, 0, 1], [0, 1, 2]]
    assert now[:, 0].tolist() == [0, 1, 2, 3] and after[:, 0].tolist() == [1, 2, 3, 4]

    torch.manual_seed(0)
    t = torch.linspace(0, 6, 80)[:, None]
    sequences = [torch.cat([torch.sin(t), torch.cos(t), t / 6], 1), torch.cat([torch.cos(t), torch.sin(t), -t / 6], 1)]
    encoder = HistoryEncoder(3, 8, 3)
    losses = pretrain(encoder, sequences, SkillMimicConfig(history_pretrain_steps=300, history_length=8), seed=0)
    assert losses[-1] < 0.5 * losses[0] and not any(p.requires_grad for p in encoder.parameters())

    provider = HistoryProvider(encoder, torch.tensor([0, 1, 2]), num_envs=2)
    first = {"student": torch.tensor([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])}
    provider(None, first, torch.tensor([True, True]))
    assert torch.equal(provider.buffer[0], torch.tensor([[1.0, 2.0, 3.0]]).repeat(8, 1))
    provider(None, {"student": torch.zeros(2, 3)}, torch.tensor([False, False]))
    assert torch.equal(provider.buffer[1, -1], torch.zeros(3)) and torch.equal(provider.buffer[1, -2],
                                                                              torch.tensor([4.0, 5.0, 6.0]))
