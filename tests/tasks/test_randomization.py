"""Domain randomisation: each term changes what it should, only when on, and its draws follow the env's seed."""

import numpy as np
import pytest
import torch

from robot_hoi.data.objects import box_asset
from robot_hoi.embodiment import load_embodiment
from robot_hoi.errors import UserError
from robot_hoi.tasks.interaction.env import InteractionEnv
from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg, RandomizationCfg
from robot_hoi.tasks.interaction.mdp.observations import STUDENT_TERMS
from robot_hoi.tasks.interaction.scene_setup import InteractionScene

from .test_interaction_env import standing_reference

N = 6
HARDWARE = dict(object_friction_scale=(0.5, 1.5), floor_friction_scale=(0.5, 1.5), kp_scale=(0.7, 1.3),
                kd_scale=(0.7, 1.3), actuator_delay_s=(0.0, 0.025), push_velocity=0.6,
                torso_com_offset=(0.025, 0.05, 0.05), joint_pos_noise=0.01, joint_vel_noise=0.2,
                imu_rot_noise=0.01, gyro_noise=0.05, tracker_pos_noise=0.005, tracker_rot_noise=0.01)


@pytest.fixture(scope="module")
def scene():
    return InteractionScene(load_embodiment("g1_inspire"), box_asset((0.4, 0.4, 0.3)))


@pytest.fixture(scope="module")
def reference(scene):
    return standing_reference(scene)


def make_env(scene, reference, seed=3, **randomization) -> InteractionEnv:
    cfg = InteractionEnvCfg(num_envs=N, nthread=2, seed=seed, student_obs_terms=tuple(STUDENT_TERMS),
                            randomization=RandomizationCfg(**randomization))
    cfg.init.joint_noise = 0.0
    cfg.init.stand_start_probability = 1.0
    return InteractionEnv(cfg, scene, [reference])


def test_off_by_default_makes_no_draw_and_changes_nothing(scene, reference):
    env = make_env(scene, reference)
    dr = env.randomization
    assert dr.noise_std == {} and not dr.delayed_on and env.backend._own_models is False  # one shared model
    state = env.generator.get_state()
    dr.reset(torch.arange(N), env.joint_pos)
    targets = torch.randn(N, env.num_actions)
    assert dr.delayed(targets) is targets
    qvel = env.backend.qvel.clone()
    dr.push(env.dt)
    value = torch.randn(N, 3)
    assert dr.noisy("joint_pos", value) is value
    assert torch.equal(env.generator.get_state(), state) and torch.equal(env.backend.qvel, qvel)


def test_friction_draws_scale_the_object_and_the_floor_contacts(scene, reference):
    env = make_env(scene, reference, object_friction_scale=(0.4, 0.6), floor_friction_scale=(1.4, 1.6))
    model = scene.model
    obj = model.geom_bodyid == scene.object_body_id()
    sliding = torch.tensor(np.array([m.geom_friction[:, 0] for m in env.backend._models]))  # (envs, geoms)
    nominal = torch.as_tensor(model.geom_friction[:, 0])
    ratio = sliding / nominal
    assert ((ratio[:, obj] >= 0.4 - 1e-6) & (ratio[:, obj] <= 0.6 + 1e-6)).all()
    assert ((ratio[:, ~obj] >= 1.4 - 1e-6) & (ratio[:, ~obj] <= 1.6 + 1e-6)).all()  # floor and robot alike
    assert ratio[:, obj][:, 0].unique().numel() == N  # a draw per env
    assert torch.equal(ratio[:, ~obj], ratio[:, ~obj][:, :1].expand_as(ratio[:, ~obj]))  # one per env, every geom
    assert (torch.tensor(np.array([m.geom_friction[:, 1:] for m in env.backend._models])) ==
            torch.as_tensor(model.geom_friction[:, 1:])).all()  # torsional and rolling untouched


def test_pd_gain_draws_scale_the_body_motors_only(scene, reference):
    env = make_env(scene, reference, kp_scale=(0.5, 0.5), kd_scale=(2.0, 2.0))
    model = scene.model
    body = env.randomization._body_actuators.tolist()
    hands = [i for i in range(model.nu) if i not in body]
    for m in env.backend._models:
        assert m.actuator_gainprm[body, 0] == pytest.approx(0.5 * model.actuator_gainprm[body, 0])
        assert m.actuator_biasprm[body, 1] == pytest.approx(0.5 * model.actuator_biasprm[body, 1])
        assert m.actuator_biasprm[body, 2] == pytest.approx(2.0 * model.actuator_biasprm[body, 2])
        assert m.actuator_gainprm[hands, 0] == pytest.approx(model.actuator_gainprm[hands, 0])
    # the physics uses them: a soft body sags further from the stand than the nominal one under the same targets
    nominal = make_env(scene, reference)
    for e in (env, nominal):
        for _ in range(10):
            e.step(torch.zeros(N, e.num_actions))
    sag = lambda e: (e.joint_pos - e.default_joint_pos)[:, e.body_actuator_ids].abs().mean()  # noqa: E731
    assert sag(env) > 1.5 * sag(nominal)


def test_torso_com_offset_moves_the_torso_centre_of_mass_within_its_half_widths(scene, reference):
    env = make_env(scene, reference, torso_com_offset=(0.02, 0.04, 0.0))
    torso = env.randomization._torso
    offsets = torch.tensor(np.array([m.body_ipos[torso] - scene.model.body_ipos[torso] for m in env.backend._models]))
    assert (offsets[:, 0].abs() <= 0.02).all() and (offsets[:, 1].abs() <= 0.04).all()
    assert (offsets[:, 2] == 0).all() and offsets[:, 0].unique().numel() == N
    others = [i for i in range(scene.model.nbody) if i != torso]
    assert all((m.body_ipos[others] == scene.model.body_ipos[others]).all() for m in env.backend._models)


def test_actuator_delay_holds_the_previous_target_for_the_delayed_sub_steps(scene, reference):
    env = make_env(scene, reference, actuator_delay_s=(0.02, 0.02))  # 20 ms = 4 physics steps of 4.76 ms
    dr = env.randomization
    assert (dr.delay == 4).all() and dr.decimation == 7
    first, second = torch.full((N, env.num_actions), 1.0), torch.full((N, env.num_actions), 2.0)
    dr.delayed(first)
    ctrl = dr.delayed(second)
    assert ctrl.shape == (N, 7, env.num_actions)
    assert (ctrl[:, :4] == 1.0).all() and (ctrl[:, 4:] == 2.0).all()
    # 40 ms = 8 physics steps, more than one control step: sub-step 0 still sees the target of two steps ago
    env = make_env(scene, reference, actuator_delay_s=(0.04, 0.04))
    for value in (1.0, 2.0):
        env.randomization.delayed(torch.full((N, env.num_actions), value))
    ctrl = env.randomization.delayed(torch.full((N, env.num_actions), 3.0))
    assert (ctrl[:, 0] == 1.0).all() and (ctrl[:, 1:] == 2.0).all()
    # after a reset the motors hold the reset pose until the first target arrives
    env.randomization.reset(torch.arange(N), env.joint_pos)
    ctrl = env.randomization.delayed(torch.full((N, env.num_actions), 3.0))
    assert torch.allclose(ctrl[:, 0], env.joint_pos)
    env.step(torch.zeros(N, env.num_actions))  # and the env steps with per-sub-step targets


def test_delay_changes_the_motion(scene, reference):
    """The same actions move the joints later in an env whose targets arrive 25 ms late."""
    prompt, late = make_env(scene, reference), make_env(scene, reference, actuator_delay_s=(0.025, 0.025))
    kick = torch.zeros(N, prompt.num_actions)
    kick[:, prompt.body_actuator_ids] = 1.0
    for e in (prompt, late):
        e.step(kick)
    moved = lambda e: (e.joint_pos - e.default_joint_pos)[:, e.body_actuator_ids].abs().mean()  # noqa: E731
    assert moved(late) < 0.7 * moved(prompt)


def test_pushes_kick_the_pelvis_at_their_interval(scene, reference):
    quiet = make_env(scene, reference)
    pushed = make_env(scene, reference, push_velocity=1.0, push_interval_s=(0.05, 0.05))  # every ~1.5 steps
    for e in (quiet, pushed):
        for _ in range(3):
            e.step(torch.zeros(N, e.num_actions))
    assert (pushed.randomization.pushes == 2).all()
    assert (pushed.root_lin_vel[:, :2] - quiet.root_lin_vel[:, :2]).norm(dim=-1).mean() > 0.1
    assert quiet.root_lin_vel[:, :2].norm(dim=-1).max() < 0.05


def test_noise_reaches_the_sensor_terms_of_the_student_observation_only(scene, reference):
    clean = make_env(scene, reference)
    noisy = make_env(scene, reference, joint_pos_noise=0.1, tracker_rot_noise=0.2)
    spec = clean.obs_dims
    a, b = clean._observations(), noisy._observations()
    assert torch.equal(a["policy"], b["policy"]) and torch.equal(a["critic"], b["critic"])  # teachers: exact
    start, diffs = 0, {}
    from robot_hoi.tasks.interaction.mdp.observations import student_observation_spec

    for term in student_observation_spec(clean):
        diffs[term["name"]] = (b["student"] - a["student"])[:, start:start + term["size"]]
        start += term["size"]
    assert start == spec["student"]
    assert 0.07 < float(diffs["joint_pos"].std()) < 0.13
    assert 0.14 < float(diffs["object_rot"].std()) < 0.26 and float(diffs["ref_root_rot"].std()) > 0.14
    for name in ("joint_vel", "hand_force", "last_action", "object_pos", "ref_joint_pos", "projected_gravity"):
        assert torch.equal(diffs[name], torch.zeros_like(diffs[name])), name


def test_draws_follow_the_seed(scene, reference):
    def draws(seed):
        env = make_env(scene, reference, seed=seed, object_mass_scale=(0.5, 2.0), **HARDWARE)
        for _ in range(2):
            env.step(torch.zeros(N, env.num_actions))
        models = env.backend._models
        return (torch.tensor(np.array([m.geom_friction[:, 0] for m in models])),
                torch.tensor(np.array([m.actuator_gainprm[:, 0] for m in models])),
                torch.tensor(np.array([m.body_ipos[env.randomization._torso] for m in models])),
                env.object_mass.clone(), env.randomization.delay.clone(), env.randomization.push_timer.clone(),
                env._observations()["student"])

    a, b, c = draws(3), draws(3), draws(4)
    assert all(torch.equal(x, y) for x, y in zip(a, b, strict=True))
    assert all(not torch.equal(x, z) for x, z in zip(a[:4], c[:4], strict=True))


def test_bad_settings_name_their_key(scene, reference):
    for key, value in (("kp_scale", (1.3, 0.7)), ("object_friction_scale", (0.0, 1.0)),
                       ("actuator_delay_s", (-0.01, 0.02)), ("push_interval_s", (0.0, 1.0)),
                       ("torso_com_offset", (0.1, -0.1, 0.0)), ("gyro_noise", -1.0)):
        with pytest.raises(UserError, match=f"env.randomization.{key}"):
            make_env(scene, reference, **{key: value})


def test_the_hardware_recipe_turns_every_term_on():
    from robot_hoi.rl.recipe import load_recipe

    cfg = load_recipe("hardware").apply("env", InteractionEnvCfg())
    r, neutral = cfg.randomization, RandomizationCfg()
    off = [k for k in vars(neutral) if k != "push_interval_s" and getattr(r, k) == getattr(neutral, k)]
    assert off == []
    assert tuple(r.object_mass_scale) == (0.5, 2.0)
