"""Reward terms on mock envs (types.SimpleNamespace holding the few attributes a term reads) with hand-computed
values, the two aggregations, and the reward sets of configs/tasks/rewards (issue 14: squared errors, feet weight,
anchor-relative terms, reward_mode product | sum). All of this is new in ab3d4d8: against the code before it the
terms do not exist (KeyError / AttributeError) and aggregate() has no mode.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest
import torch

from robot_hoi.tasks.interaction.mdp import rewards as R
from robot_hoi.utils.torch_rot import quat_from_yaw, quat_mul, quat_to_matrix

F64 = torch.float64


def _quat_x(angle: float) -> torch.Tensor:
    return torch.tensor([math.cos(angle / 2), math.sin(angle / 2), 0.0, 0.0], dtype=F64)


def _identity(*shape) -> torch.Tensor:
    q = torch.zeros(*shape, 4, dtype=F64)
    q[..., 0] = 1.0
    return q


# 6 links: 0 pelvis, 1 knee, 2-3 feet, 4-5 hand (wrist, fingertip); 5 actuators, the first 3 of the body
SCENE = SimpleNamespace(body_link_ids=[0, 1, 2, 3], feet_link_ids=[2, 3], hand_link_flat_ids=[4, 5])
REF_LINKS = torch.tensor([[0.0, 0.0, 0.8], [0.1, 0.1, 0.4], [0.0, 0.1, 0.05], [0.0, -0.1, 0.05],
                          [0.3, 0.2, 0.9], [0.4, 0.2, 0.9]], dtype=F64)


def _env(**fields) -> SimpleNamespace:
    """One env on a reference at the origin; `fields` override the simulated side (batch of 1 unless given)."""
    ref = SimpleNamespace(link_pos=REF_LINKS[None].clone(), root_pos=REF_LINKS[None, 0].clone(),
                          root_quat_wxyz=_identity(1), link_quat_wxyz=_identity(1, 6), joint_pos=torch.zeros(1, 5,
                          dtype=F64), joint_state=torch.zeros(1, 5, dtype=F64),
                          object_pos=torch.tensor([[0.6, 0.0, 0.15]], dtype=F64),
                          object_quat_wxyz=_identity(1), d_hat=torch.zeros(1, 6, 3, dtype=F64))
    env = SimpleNamespace(ref=ref, scene=SCENE, body_actuator_ids=[0, 1, 2], link_pos=ref.link_pos.clone(),
                          root_pos=ref.root_pos.clone(), root_quat=_identity(1), link_quat=_identity(1, 6),
                          joint_pos=torch.zeros(1, 5, dtype=F64), heading_matrix=torch.eye(3, dtype=F64)[None],
                          ref_heading_matrix=torch.eye(3, dtype=F64)[None], object_pos=ref.object_pos.clone(),
                          object_quat=_identity(1), d=torch.zeros(1, 6, 3, dtype=F64),
                          w_d=torch.tensor([[0.5, 0.1, 0.0, 0.0, 0.4, 0.0]], dtype=F64),
                          feet_link_mask=torch.tensor([0.0, 0.0, 1.0, 1.0, 0.0, 0.0], dtype=F64))
    for key, value in fields.items():
        setattr(env, key, value)
    return env


def _offsets(*rows) -> torch.Tensor:
    return torch.tensor(rows, dtype=F64)[None]


# ---- the anchor-relative terms -------------------------------------------------------------------------------------
def test_root_position_cost():
    env = _env(root_pos=torch.tensor([[0.1, -0.2, 0.7]], dtype=F64))
    assert R.root_position_cost(env).item() == pytest.approx(0.01 + 0.04 + 0.01)
    assert R.root_position_cost(_env()).item() == 0.0


def test_root_orientation_cost():
    yawed = _env(root_quat=quat_from_yaw(torch.tensor([0.3], dtype=F64)))
    assert R.root_orientation_cost(yawed).item() == pytest.approx(0.09)  # heading counts, squared
    tilted = _env(root_quat=_quat_x(0.5)[None])
    assert R.root_orientation_cost(tilted).item() == pytest.approx(0.25)


def test_body_position_cost_is_anchor_relative():
    """Link positions relative to the pelvis, each side in its own heading frame, mean over the body links
    (hands excluded): the same pose elsewhere and turned by 90 degrees costs 0; a knee 0.2 m off costs 0.04 / 4."""
    yaw = torch.tensor([math.pi / 2], dtype=F64)
    heading = quat_to_matrix(quat_from_yaw(yaw))  # (1, 3, 3)
    anchor = torch.tensor([1.0, 2.0, 0.0], dtype=F64)
    moved = (REF_LINKS - REF_LINKS[0]) @ heading[0].T + REF_LINKS[0] + anchor  # turned about the pelvis, moved
    moved[4:] += 1.0  # hands anywhere: not part of the body term
    env = _env(link_pos=moved[None].clone(), root_pos=moved[None, 0].clone(), heading_matrix=heading)
    assert R.body_position_cost(env).item() == pytest.approx(0.0, abs=1e-12)
    knee_off = moved.clone()
    knee_off[1] += heading[0] @ torch.tensor([0.2, 0.0, 0.0], dtype=F64)  # 0.2 m forward in the robot's heading
    env.link_pos = knee_off[None]
    assert R.body_position_cost(env).item() == pytest.approx(0.04 / 4)


def test_body_rotation_cost():
    quats = torch.stack([_quat_x(a) for a in (0.1, 0.2, 0.3, 0.4, 1.0, 1.0)])[None]  # hands excluded
    assert R.body_rotation_cost(_env(link_quat=quats)).item() == pytest.approx((0.01 + 0.04 + 0.09 + 0.16) / 4)


def test_feet_position_cost():
    offsets = _offsets([0.5, 0, 0], [0.5, 0, 0], [0.1, 0, 0], [0, 0.2, 0.2], [1, 0, 0], [1, 0, 0])
    assert R.feet_position_cost(_env(link_pos=REF_LINKS + offsets)).item() == pytest.approx((0.01 + 0.08) / 2)


def test_hand_position_cost():
    offsets = _offsets([0.5, 0, 0], [0.5, 0, 0], [0.5, 0, 0], [0.5, 0, 0], [0, 0.3, 0], [0, 0, -0.1])
    assert R.hand_position_cost(_env(link_pos=REF_LINKS + offsets)).item() == pytest.approx((0.09 + 0.01) / 2)


def test_joint_position_cost():
    env = _env(joint_pos=torch.tensor([[0.1, -0.2, 0.3, 5.0, 5.0]], dtype=F64))  # finger channels excluded
    assert R.joint_position_cost(env).item() == pytest.approx((0.01 + 0.04 + 0.09) / 3)


def test_joint_position_cost_is_zero_on_the_reference_state_whatever_the_squeeze():
    """The PD targets carry the grasp squeeze and load offsets; a robot exactly on the reference state measures
    the state's joints and is not charged for them (issue 48's 'fix on the way')."""
    env = _env()
    env.ref.joint_pos = torch.tensor([[0.3, -0.2, 0.1, 0.0, 0.0]], dtype=F64)  # squeezed PD targets
    env.ref.joint_state = torch.tensor([[0.1, 0.0, 0.1, 0.0, 0.0]], dtype=F64)
    env.joint_pos = env.ref.joint_state.clone()
    assert R.joint_position_cost(env).item() == 0.0


# ---- squared errors and the feet weight of the InterMimic terms ---------------------------------------------------
def test_link_position_cost_squared_and_feet_weight():
    """w_d = (0.5, 0.1, 0, 0, 0.4, 0), errors 0.1 .. 0.6 m: unsquared <w_d, e>; squared <w_d, e^2>; feet_weight
    0.25 adds 0.25 to each foot's weight and renormalises (total 1.5)."""
    errors = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6]
    env = _env(link_pos=REF_LINKS + _offsets(*[[0.0, 0.0, e] for e in errors]))
    assert R.link_position_cost(env).item() == pytest.approx(0.05 + 0.02 + 0.2)
    assert R.link_position_cost(env, squared=True).item() == pytest.approx(0.005 + 0.004 + 0.1)
    expected = (0.5 * 0.01 + 0.1 * 0.04 + 0.25 * 0.09 + 0.25 * 0.16 + 0.4 * 0.25) / 1.5
    assert R.link_position_cost(env, squared=True, feet_weight=0.25).item() == pytest.approx(expected)
    # a uniform 10 cm error: exp(-10 * 0.01) = 0.90 with the code's lambda 10, exp(-30 * 0.1) = 0.05 unsquared
    uniform = _env(link_pos=REF_LINKS + 0.1 * torch.tensor([[[1.0, 0.0, 0.0]]], dtype=F64))
    assert math.exp(-10 * R.link_position_cost(uniform, squared=True, feet_weight=0.25).item()) == \
        pytest.approx(0.905, abs=1e-3)
    assert math.exp(-30 * R.link_position_cost(uniform).item()) == pytest.approx(0.0498, abs=1e-4)


def test_interaction_and_object_costs_squared():
    d = torch.zeros(1, 6, 3, dtype=F64)
    d[0, 0, 0], d[0, 4, 1] = 0.2, 0.1  # |d_hat - d| = 0.2 (w 0.5) and 0.1 (w 0.4)
    env = _env(d=d, object_pos=torch.tensor([[0.9, 0.4, 0.15]], dtype=F64),
               object_quat=quat_from_yaw(torch.tensor([0.5], dtype=F64)))
    assert R.interaction_geometry_cost(env).item() == pytest.approx(0.5 * 0.2 + 0.4 * 0.1)
    assert R.interaction_geometry_cost(env, squared=True).item() == pytest.approx(0.5 * 0.04 + 0.4 * 0.01)
    assert R.object_position_cost(env).item() == pytest.approx(0.5)
    assert R.object_position_cost(env, squared=True).item() == pytest.approx(0.25)
    assert R.object_rotation_cost(env).item() == pytest.approx(0.5)
    assert R.object_rotation_cost(env, squared=True).item() == pytest.approx(0.25)


def test_new_terms_are_registered():
    for name in ("root_position_cost", "root_orientation_cost", "body_position_cost", "body_rotation_cost",
                 "feet_position_cost", "hand_position_cost", "joint_position_cost"):
        assert R.REWARD_TERMS[name] is getattr(R, name)


# ---- the tracking set's terms (issue 48, item 4) --------------------------------------------------------------------
def test_velocity_costs_read_the_reference_velocities():
    """Body links' world linear velocities (hands excluded) and body joints' velocities, mean squared errors."""
    ref_vel = torch.zeros(1, 6, 3, dtype=F64)
    env = _env(link_vel=ref_vel.clone(), joint_vel=torch.zeros(1, 5, dtype=F64))
    env.ref.link_vel, env.ref.joint_vel = ref_vel, torch.zeros(1, 5, dtype=F64)
    assert R.link_velocity_cost(env).item() == 0.0 and R.joint_velocity_cost(env).item() == 0.0
    env.link_vel = ref_vel.clone()
    env.link_vel[0, 1] = torch.tensor([0.0, 2.0, 0.0], dtype=F64)   # the knee 2 m/s off: 4 / 4 body links
    env.link_vel[0, 5] = torch.tensor([9.0, 0.0, 0.0], dtype=F64)   # a fingertip: not a body link
    assert R.link_velocity_cost(env).item() == pytest.approx(1.0)
    env.joint_vel = torch.tensor([[0.0, 3.0, 0.0, 7.0, 7.0]], dtype=F64)  # hand joints (3, 4) do not count
    assert R.joint_velocity_cost(env).item() == pytest.approx(3.0)


def test_object_relative_costs_follow_the_pelvis():
    """The object relative to the pelvis in its heading frame: robot and object moved and turned together cost 0;
    the object 0.1 m off the pelvis' frame costs 0.01; tilted 0.5 rad in that frame, 0.25."""
    yaw = torch.tensor([0.7], dtype=F64)
    turn = quat_from_yaw(yaw)
    heading = quat_to_matrix(turn)
    shift = torch.tensor([[1.0, -2.0, 0.0]], dtype=F64)
    ref = _env().ref
    obj = (ref.object_pos - ref.root_pos) @ heading[0].T + ref.root_pos + shift
    env = _env(root_pos=ref.root_pos + shift, root_quat=turn, heading_matrix=heading, object_pos=obj,
               object_quat=turn.clone())
    assert R.object_relative_position_cost(env).item() == pytest.approx(0.0, abs=1e-12)
    assert R.object_relative_rotation_cost(env).item() == pytest.approx(0.0, abs=1e-12)
    env.object_pos = obj + torch.tensor([[0.0, 0.0, 0.1]], dtype=F64)
    assert R.object_relative_position_cost(env).item() == pytest.approx(0.01)
    env.object_quat = quat_mul(turn, _quat_x(0.5)[None])
    assert R.object_relative_rotation_cost(env).item() == pytest.approx(0.25)


def test_contact_promotion_cost_counts_required_hands_without_contact():
    """The tracking set's held-contact term: hands the reference holds with that the contact sensors find off."""
    env = _env(hand_contact_found=torch.tensor([[True, False], [False, False], [True, True]]))
    env.ref.hand_contact = torch.tensor([[True, True], [False, True], [False, False]])
    assert R.contact_promotion_cost(env).tolist() == [1.0, 1.0, 0.0]  # a contact nobody asked for costs nothing here


def test_action_rate_and_joint_limit_penalties():
    env = _env(actions=torch.tensor([[1.0, 0.0, -1.0]]), last_actions=torch.tensor([[0.5, 0.0, 1.0]]))
    assert R.action_rate_cost(env).item() == pytest.approx(0.25 + 4.0)
    # soft limits (0.9) of the body joints: [-0.9, 0.9], [0.1, 1.9], [0, 0.9]; joints 3, 4 are the hand's
    low, high = torch.tensor([-1.0, 0.0, -0.05, 0.0, 0.0]), torch.tensor([1.0, 2.0, 0.95, 1.0, 1.0])
    pos = torch.tensor([[0.5, 1.0, 0.0, 0.0, 0.0], [0.95, 0.0, 0.0, 1.0, 1.0], [-1.0, 2.0, 1.0, 0.0, 0.0]])
    env = _env(ctrl_low=low, ctrl_high=high, joint_pos=pos)
    env.ref.joint_state = torch.tensor([[0.0, 1.0, 0.45, 0.0, 0.0]])  # the reference inside the soft limits
    assert R.joint_limit_cost(env).tolist() == pytest.approx([0.0, 0.05 + 0.1, 0.1 + 0.1 + 0.1])
    env.ref.joint_state = torch.tensor([[0.97, 1.0, 0.45, 0.0, 0.0]])  # the reference itself past joint 0's limit
    assert R.joint_limit_cost(env).tolist() == pytest.approx([0.0, 0.0 + 0.1, 0.1 + 0.1 + 0.1])


# ---- aggregation ---------------------------------------------------------------------------------------------------
def test_aggregate_product_and_sum():
    costs = {"a": torch.tensor([1.0, 0.0]), "b": torch.tensor([0.5, 2.0])}
    weights, scales = {"a": 2.0, "b": 1.0}, {"a": 1.0, "b": 3.0}
    exp_a, exp_b = torch.exp(-2.0 * costs["a"]), torch.exp(-costs["b"])
    reward, per_term = R.aggregate(costs, weights, "product", scales)  # scales ignored
    assert torch.allclose(reward, torch.exp(-(2.0 * costs["a"] + costs["b"])))
    assert torch.allclose(per_term["a"], exp_a) and torch.allclose(per_term["b"], exp_b)
    assert torch.allclose(R.aggregate(costs, weights)[0], reward)  # product is the default
    reward, per_term = R.aggregate(costs, weights, "sum", scales)
    assert torch.allclose(reward, (1.0 * exp_a + 3.0 * exp_b) / 4.0)
    assert torch.allclose(per_term["b"], exp_b)
    assert torch.allclose(R.aggregate(costs, weights, "sum")[0], (exp_a + exp_b) / 2)  # no scales: the mean
    with pytest.raises(ValueError):
        R.aggregate(costs, weights, "max")


def test_aggregate_subtracts_penalty_terms_as_they_are():
    """A penalty term is -lambda E on top of either aggregate, outside the sum's normalisation, logged negative."""
    costs = {"a": torch.tensor([1.0, 0.0]), "rate": torch.tensor([2.0, 30.0])}
    weights = {"a": 2.0, "rate": 0.01}
    for mode in ("sum", "product"):
        reward, per_term = R.aggregate(costs, weights, mode, {"a": 3.0}, penalties=frozenset({"rate"}))
        assert torch.allclose(reward, torch.exp(-2.0 * costs["a"]) - 0.01 * costs["rate"])
        assert torch.allclose(per_term["rate"], torch.tensor([-0.02, -0.3]))


# ---- the reward sets ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def scene():
    from robot_hoi.data.objects import box_asset
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.tasks.interaction.scene_setup import InteractionScene

    return InteractionScene(load_embodiment("g1_inspire"), box_asset((0.4, 0.4, 0.3)))


def test_reward_sets_load_and_build_an_env(scene):
    """Every configs/tasks/rewards/*.yaml goes through apply_reward_set into an env that steps: rewards in [0, 1],
    one logged exp per enabled term, the set's mode. A standing robot on a standing reference scores well."""
    from robot_hoi.errors import UserError
    from robot_hoi.tasks.interaction.env import InteractionEnv
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg, apply_reward_set, reward_set_names

    from .test_interaction_env import standing_reference

    names = reward_set_names()
    assert {"anchor_additive", "intermimic_code", "intermimic_paper"} <= set(names)
    reference = standing_reference(scene, 10)
    for name in names:
        cfg = InteractionEnvCfg(num_envs=2, nthread=1, seed=0, backend="cpu")
        cfg.psi.enabled = False
        cfg.init.joint_noise = 0.0
        cfg.init.stand_start_probability = 0.0
        cfg.init.start_range = (0.0, 0.0)
        apply_reward_set(cfg, name)
        assert cfg.reward_mode in ("product", "sum")
        enabled = {k for k, v in cfg.rewards.items() if v is not None}
        assert enabled and all(cfg.rewards[k].func in R.REWARD_TERMS for k in enabled)
        env = InteractionEnv(cfg, scene, [reference])
        for _ in range(2):
            _, reward, terminated, _, _ = env.step(torch.zeros(2, env.num_actions))
            assert torch.isfinite(reward).all() and ((reward >= 0) & (reward <= 1)).all(), name
            assert not terminated.any()
        assert set(env.episode_sums) == enabled
        if cfg.reward_mode == "sum":
            assert reward.min() > 0.5, name
    with pytest.raises(UserError):
        apply_reward_set(InteractionEnvCfg(), "no_such_set")


ANCHOR_ADDITIVE_TIGHT_AS_A_FULL_COPY = """
reward_mode: sum
rewards:
  root_pos:       {func: root_position_cost,       weight: 44.4, scale: 1.0}
  root_rot:       {func: root_orientation_cost,    weight: 6.25, scale: 1.0}
  body_pos:       {func: body_position_cost,       weight: 11.1, scale: 1.0}
  body_rot:       {func: body_rotation_cost,       weight: 6.25, scale: 0.5}
  feet_pos:       {func: feet_position_cost,       weight: 44.4, scale: 0.5}
  joint_pos:      {func: joint_position_cost,      weight: 4.0,  scale: 0.5}
  hand_pos:       {func: hand_position_cost,       weight: 44.4, scale: 1.0}
  interaction:    {func: interaction_geometry_cost, weight: 44.4, scale: 1.0, params: {squared: true}}
  object_pos:     {func: object_position_cost,     weight: 156.0, scale: 1.0, params: {squared: true}}
  object_rot:     {func: object_rotation_cost,     weight: 6.25, scale: 0.5, params: {squared: true}}
  energy_links:   {func: link_acceleration_cost,   weight: 2.0e-4, scale: 0.5}
"""


def test_a_reward_set_with_a_base_holds_only_its_changes(tmp_path):
    """anchor_additive_tight is `base: anchor_additive` plus two weights, and loads exactly as the full copy it
    replaced; bases nest, a term's fields merge into the base's term, null disables one; a cycle names the file."""
    from robot_hoi.errors import UserError
    from robot_hoi.tasks.interaction.env_cfg import load_reward_set

    full = tmp_path / "full.yaml"
    full.write_text(ANCHOR_ADDITIVE_TIGHT_AS_A_FULL_COPY)
    assert load_reward_set("anchor_additive_tight") == load_reward_set(str(full))
    (tmp_path / "mid.yaml").write_text("base: anchor_additive_tight\nrewards:\n  energy_links: null\n"
                                       "  interaction: {params: {squared: false}}\n")
    (tmp_path / "leaf.yaml").write_text("base: mid.yaml\nreward_mode: product\nrewards:\n  hand_pos: {scale: 2.0}\n")
    mode, terms = load_reward_set(str(tmp_path / "leaf.yaml"))
    _, tight = load_reward_set("anchor_additive_tight")
    assert mode == "product" and terms["energy_links"] is None
    assert terms["object_pos"] == tight["object_pos"]  # from two bases up
    assert terms["interaction"].params == {"squared": False} and terms["interaction"].weight == 44.4
    assert terms["hand_pos"].scale == 2.0 and terms["hand_pos"].func == "hand_position_cost"
    (tmp_path / "a.yaml").write_text("base: b.yaml\n")
    (tmp_path / "b.yaml").write_text("base: a.yaml\nrewards: {}\n")
    with pytest.raises(UserError, match=r"b\.yaml: base 'a' makes a cycle"):
        load_reward_set(str(tmp_path / "a.yaml"))
    (tmp_path / "typo.yaml").write_text("base: anchor_additive\nreward: {}\n")
    with pytest.raises(UserError, match=r"typo\.yaml: unknown key\(s\) reward"):
        load_reward_set(str(tmp_path / "typo.yaml"))


def test_reference_link_velocities_are_the_links_finite_differences():
    """The env's reference link velocities (what link_velocity_cost compares with): a link moving at a constant
    1.5 m/s along x in a 30 fps clip has velocity 1.5 at every frame, ends included; a one-frame clip, zero."""
    from robot_hoi.tasks.interaction.env import link_velocities

    frames = torch.arange(5, dtype=torch.float32)[:, None, None]
    link_pos = torch.cat([frames * torch.tensor([0.05, 0.0, 0.0]), torch.zeros(5, 1, 3)], dim=1)  # (5, 2, 3)
    ref = SimpleNamespace(fps=30.0, link_pos=link_pos, num_frames=5)
    vel = link_velocities(ref)
    assert vel.shape == (5, 2, 3)
    assert torch.allclose(vel[:, 0, 0], torch.full((5,), 1.5)) and vel[:, 1].abs().max() == 0
    assert link_velocities(SimpleNamespace(fps=30.0, link_pos=link_pos[:1], num_frames=1)).abs().max() == 0
