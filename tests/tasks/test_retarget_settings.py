"""The task config's retarget settings (its retarget: block: leg-load and dynamics compensation, finger closure, ...)
reach the reference the env tracks, and a cached reference made with other settings, or from another version of the
clip, is refused instead of silently reused. The block has one spelling; runs saved with the old flat keys load."""

from dataclasses import asdict, replace

import numpy as np
import pytest

from robot_hoi.cli import main
from robot_hoi.embodiment import build_model, load_embodiment
from robot_hoi.errors import UserError
from robot_hoi.paths import TASK_CONFIG
from robot_hoi.retarget.pipeline import RetargetOptions
from robot_hoi.tasks.interaction import factory
from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg, RetargetCfg, saved_env_cfg, split_overrides
from robot_hoi.utils.config import apply_overrides, load_dataclass, load_yaml_dataclass

# A run's task.json before the retarget: block: its settings were flat env keys (here the table-drag recipe's, with
# leg loads on); saved_env_cfg moves them into the block.
FLAT_KEYS = {"retarget_leg_loads": True, "retarget_dynamics": False, "retarget_finger_closure": 1.0,
             "retarget_squeeze_toward": "surface", "retarget_squeeze_depth": 0.12,
             "retarget_fingertip_underside_reach": None, "retarget_solver": None, "retarget_grasp": None}


def _saved_before_the_block(cfg: InteractionEnvCfg, flat: dict) -> dict:
    data = asdict(cfg)
    del data["retarget"]
    return {**data, **flat}


def test_the_shipped_config_retargets_with_the_retargets_own_defaults():
    """The retarget: block as shipped changes nothing: its options are the retarget's defaults, but for the task's
    object (collision shape, density), setting for setting as before the block."""
    options = factory.retarget_options(load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG))
    defaults = RetargetOptions()
    assert options == replace(defaults, mapping=replace(defaults.mapping, object_collision="decomposed"),
                              grasp_plan=replace(defaults.grasp_plan, object_density=25.0))
    assert (options.executable.compensate_leg_loads, options.executable.compensate_dynamics, options.grasp.closure,
            options.executable.squeeze_toward, options.executable.squeeze_depth,
            options.ik.solver, options.grasp_plan.enabled,
            options.mapping.anchor_mode) == (False, False, 0.6, "other_hand", 0.06, "dls", False, "distance")
    assert factory.retarget_options(InteractionEnvCfg()) == replace(
        defaults, grasp_plan=replace(defaults.grasp_plan, object_density=25.0))


def test_a_run_saved_with_flat_retarget_keys_loads_into_the_block(tmp_path):
    """Old run folders and exported policies keep loading (the flat keys move into the block); a config of the
    user's that still spells them so is an error naming the new spelling."""
    old = _saved_before_the_block(InteractionEnvCfg(num_envs=8, object_collision="decomposed"), FLAT_KEYS)
    cfg = saved_env_cfg(old, "run/task.json")
    assert cfg.retarget == RetargetCfg(leg_loads=True, finger_closure=1.0, squeeze_toward="surface",
                                       squeeze_depth=0.12)
    assert (cfg.num_envs, cfg.object_collision) == (8, "decomposed")
    assert saved_env_cfg(asdict(cfg), "run/task.json") == cfg  # saved with the block
    older = {k: v for k, v in old.items() if k not in ("retarget_grasp", "retarget_solver")}  # before those keys
    assert saved_env_cfg(older, "run/task.json").retarget == cfg.retarget

    task = tmp_path / "my_task.yaml"
    task.write_text(TASK_CONFIG.read_text() + "retarget_squeeze_depth: 0.12\n")
    with pytest.raises(UserError, match=r"my_task\.yaml: retarget_squeeze_depth has moved: it is spelled "
                                        r"retarget\.squeeze_depth now"):
        load_yaml_dataclass(InteractionEnvCfg, task)


def test_one_spelling_per_retarget_setting_on_the_command_line():
    """--set retarget.KEY=VALUE goes to the task config's block; env.retarget_KEY, env.retarget.KEY and a bare
    retarget_KEY are refused with the spelling to use."""
    assert split_overrides(["env.num_envs=4", "retarget.solver=qp", "ppo.actor_lr=1e-4"]) == \
        (["num_envs=4", "retarget.solver=qp"], ["ppo.actor_lr=1e-4"])
    assert split_overrides(["num_envs=4", "retarget.grasp=true"], bare=True) == \
        (["num_envs=4", "retarget.grasp=true"], [])
    for item in ("env.retarget_squeeze_depth=0.1", "env.retarget.squeeze_depth=0.1", "retarget_squeeze_depth=0.1"):
        with pytest.raises(UserError, match=rf"--set {item}: .* spelled --set retarget\.squeeze_depth=0\.1"):
            split_overrides([item], bare=True)


class _Stop(Exception):
    pass


def test_every_command_that_retargets_takes_the_retarget_settings(tmp_path, monkeypatch, capsys):
    """train, retarget, eval and the student build their task config with --set retarget.KEY=VALUE; a value out of
    range or an old spelling is a one-line error naming the key."""
    from robot_hoi.commands import retarget as retarget_command
    from robot_hoi.rl.evaluation import apply_env_overrides
    from robot_hoi.student.config import load_student_config

    seen = {}

    def capture_job(job, clips):
        seen["train"] = job.env_cfg
        raise _Stop

    def capture_retarget(clip, cfg, model, task, options, scale=None):
        seen["retarget"] = (task, options)
        raise _Stop

    monkeypatch.setattr("robot_hoi.rl.teacher_job.train_teacher_group", capture_job)
    monkeypatch.setattr(retarget_command, "_retarget_and_gate", capture_retarget)
    with pytest.raises(_Stop):
        main(["train", "--skip-gate", "--init", "none", "--out", str(tmp_path / "run"),
              "--set", "retarget.squeeze_depth=0.1", "--set", "retarget.solver=qp"])
    assert (seen["train"].retarget.squeeze_depth, seen["train"].retarget.solver) == (0.1, "qp")
    with pytest.raises(_Stop):
        main(["retarget", "-o", str(tmp_path / "m.npz"), "--set", "retarget.squeeze_depth=0.1",
              "--set", "env.object_collision=hull"])
    task, options = seen["retarget"]
    assert (task.retarget.squeeze_depth, options.executable.squeeze_depth) == (0.1, 0.1)
    assert (task.object_collision, options.mapping.object_collision) == ("hull", "hull")
    assert apply_env_overrides(InteractionEnvCfg(), ["retarget.squeeze_depth=0.1"]).retarget.squeeze_depth == 0.1
    student, env = load_student_config(overrides=["retarget.squeeze_depth=0.1", "distill.beta=50"])
    assert "retarget.squeeze_depth=0.1" in env and student.distill.beta == 50

    for argv, message in [
        (["retarget", "-o", str(tmp_path / "m.npz"), "--set", "retarget.squeeze_depth=-1"],
         "retarget.squeeze_depth must be within [0, 0.3] m"),
        (["retarget", "-o", str(tmp_path / "m.npz"), "--set", "env.retarget_squeeze_depth=0.1"],
         "spelled --set retarget.squeeze_depth=0.1"),
        (["train", "--out", str(tmp_path / "run2"), "--set", "env.retarget_finger_closure=1.0"],
         "spelled --set retarget.finger_closure=1.0"),
        (["train", "--out", str(tmp_path / "run2"), "--set", "retarget.anchor_mode=labels"],
         "retarget.anchor_mode must be one of distance, contact, got 'labels'"),
    ]:
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert message in err and err.count("\n") == 0, err
    assert not (tmp_path / "run2").exists()


def test_leg_load_setting_reaches_the_env_and_guards_the_cache(tmp_path):
    embodiment = load_embodiment("g1_inspire")
    clip = factory.load_source("embedded:lift_place")
    plain = factory.load_or_retarget(clip, embodiment, None)
    cfg = InteractionEnvCfg(num_envs=2, backend="cpu", retarget=RetargetCfg(leg_loads=True))
    env = factory.make_env([clip], cfg, embodiment, cache=tmp_path)
    cached = tmp_path / f"{clip.name}.npz"
    assert cached.is_file()

    legs = [i for i, n in enumerate(embodiment.actuator_names) if any(k in n for k in ("hip", "knee", "ankle"))]
    arms = [i for i, n in enumerate(embodiment.actuator_names) if "shoulder" in n or "elbow" in n]
    tracked = env.ref_joint_pos.cpu().numpy()  # PD targets of every frame (one clip)
    leg_shift = np.abs(tracked[:, legs] - plain.joint_pos[:, legs]).max()
    assert leg_shift > 0.02  # the stance torques / kp moved the leg targets
    np.testing.assert_allclose(tracked[:, arms], plain.joint_pos[:, arms], atol=1e-5)  # arms as before
    np.testing.assert_allclose(plain.qpos, factory.load_or_retarget(clip, embodiment, cached.parent, factory.retarget_options(cfg)).qpos,
                               atol=1e-6)  # same states: only the PD targets differ

    with pytest.raises(UserError, match=rf"{cached.name}.*leg-load compensation on.*asks for it off"):
        factory.make_env([clip], InteractionEnvCfg(num_envs=2, backend="cpu"), embodiment, cache=tmp_path)


def test_flat_fingers_keep_the_squeeze_and_dynamics_move_the_targets(tmp_path):
    """Finger closure 0 leaves the fingers open while holding but the arms still squeeze (the squeeze ramp used to be
    divided by the closure, so flat fingers squeezed nothing); dynamics compensation shifts the PD targets of the
    moving joints and not the states; a cache made with the default closure is refused."""
    embodiment = load_embodiment("g1_inspire")
    clip = factory.load_source("embedded:lift_place")
    plain = factory.load_or_retarget(clip, embodiment, None)
    cfg = InteractionEnvCfg(num_envs=2, backend="cpu", retarget=RetargetCfg(finger_closure=0.0, dynamics=True))
    flat = factory.load_or_retarget(clip, embodiment, tmp_path, factory.retarget_options(cfg))

    names = list(flat.actuator_names)
    fingers = [names.index(c.joint) for hand in embodiment.hands.values() for c in hand.channels]
    open_pose = flat.joint_pos[0, fingers]
    assert np.abs(plain.joint_pos[:, fingers] - open_pose).max() > 0.3  # the default closes them while holding
    np.testing.assert_allclose(flat.joint_pos[:, fingers], np.broadcast_to(open_pose, (len(flat.joint_pos), len(fingers))),
                               atol=1e-6)
    arms = [names.index(n) for n in names if "shoulder" in n or "elbow" in n]
    model = build_model(embodiment)
    act_qadr = [int(model.jnt_qposadr[model.joint(n).id]) for n in names]
    squeeze_and_loads = flat.joint_pos[:, arms] - flat.qpos[:, act_qadr][:, arms]
    dynamic = factory.retarget_options(cfg)
    static = replace(dynamic, executable=replace(dynamic.executable, compensate_dynamics=False))
    no_dynamics = factory.load_or_retarget(clip, embodiment, None, static)
    np.testing.assert_allclose(no_dynamics.qpos, flat.qpos, atol=1e-9)  # dynamics touch the PD targets only
    held = no_dynamics.joint_pos[:, arms] - no_dynamics.qpos[:, act_qadr][:, arms]
    gravity_only = factory.load_or_retarget(clip, embodiment, None, replace(
        static, executable=replace(static.executable, squeeze_depth=0.0)))
    squeeze = held - (gravity_only.joint_pos[:, arms] - gravity_only.qpos[:, act_qadr][:, arms])
    assert np.abs(squeeze).max() > 0.05  # the flat hands still squeeze the box
    assert np.abs(squeeze_and_loads - held).max() > 0.02  # the motion's torques moved the arm targets

    with pytest.raises(UserError, match=r"finger closure 0, the task asks for it 0.6 \(retarget\.finger_closure\)"):
        factory.make_env([clip], InteractionEnvCfg(num_envs=2, backend="cpu", retarget=RetargetCfg(dynamics=True)),
                         embodiment, cache=tmp_path)


def test_object_collision_reaches_the_scene_and_guards_the_cache(tmp_path, table_object):
    """object_collision "decomposed": the simulated object is its convex pieces, the retarget kept the hands out of
    the same pieces, and a cache made with them is refused by a task that collides with the hull."""
    embodiment = load_embodiment("g1_inspire")
    clip = replace(factory.load_source("embedded:lift_place"), object=table_object)
    cfg = InteractionEnvCfg(num_envs=2, backend="cpu", object_collision="decomposed")
    env = factory.make_env([clip], cfg, embodiment, cache=tmp_path)
    model = env.scene.model
    object_body = model.jnt_bodyid[model.njnt - 1]
    assert model.body_geomnum[object_body] == len(clip.object.convex_parts()) > 1
    cached = tmp_path / f"{clip.name}.npz"
    with pytest.raises(UserError, match=rf"{cached.name}.*object collision shape decomposed.*asks for it hull"):
        factory.make_env([clip], InteractionEnvCfg(num_envs=2, backend="cpu"), embodiment, cache=tmp_path)
    with pytest.raises(ValueError, match="object_collision must be one of hull, decomposed, not 'mesh'"):
        InteractionEnvCfg(object_collision="mesh")


def test_a_cached_reference_of_another_version_of_the_clip_is_refused(tmp_path):
    """The cache is keyed by clip name: a clip regenerated under the same name (e.g. a synthetic clip whose seed draws
    changed) used to be tracked against the old reference and crash indexing past its end."""
    embodiment = load_embodiment("g1_inspire")
    clip = factory.load_source("embedded:lift_place")
    factory.load_or_retarget(clip, embodiment, tmp_path)
    cached = tmp_path / f"{clip.name}.npz"
    assert factory.load_or_retarget(clip, embodiment, tmp_path).num_frames == clip.num_frames  # same clip: reused
    moved = clip.copy()
    moved.object_pos = moved.object_pos + np.array([0.0, 0.0, 0.01])
    with pytest.raises(UserError, match=rf"{cached.name}.*another version of clip {clip.name}"):
        factory.load_or_retarget(moved, embodiment, tmp_path)
    with pytest.raises(UserError, match=r"another version.*frames, the clip has"):
        factory.load_or_retarget(clip.select_frames(slice(0, clip.num_frames - 5)), embodiment, tmp_path)


def test_the_removed_fingertip_underside_reach_is_refused_by_name_and_in_old_caches(tmp_path):
    """A config that still sets it is an error saying why it went; a run saved with it off still loads; a cached
    reference made with it on is refused, not silently reused."""
    with pytest.raises(UserError, match=r"retarget.fingertip_underside_reach was removed: .*grasp"):
        load_dataclass(InteractionEnvCfg, {"retarget": {"fingertip_underside_reach": 0.15}}, "task.yaml")
    with pytest.raises(UserError, match=r"retarget.fingertip_underside_reach=0.15.*was removed: .*grasp"):
        apply_overrides(InteractionEnvCfg(), ["retarget.fingertip_underside_reach=0.15"], "--set")
    saved = asdict(InteractionEnvCfg())
    saved["retarget"]["fingertip_underside_reach"] = None
    assert saved_env_cfg(saved, "task.json").retarget == RetargetCfg()
    embodiment = load_embodiment("g1_inspire")
    clip = factory.load_source("embedded:lift_place")
    motion = factory.load_or_retarget(clip, embodiment, tmp_path)
    motion.meta["mapping"]["fingertip_underside_reach"] = 0.15
    motion.save(tmp_path / f"{clip.name}.npz")
    with pytest.raises(UserError, match=r"fingertip_underside_reach 0.15, a setting that was removed"):
        factory.load_or_retarget(clip, embodiment, tmp_path)


def test_squeeze_depth_scales_the_arm_squeeze_and_guards_the_cache(tmp_path):
    """A deeper squeeze moves only the holding arms' PD targets, further than the default does (twice the depth,
    about twice the offset); the states stay; a cache made with another depth is refused; a depth out of range is
    an error naming the key."""
    embodiment = load_embodiment("g1_inspire")
    clip = factory.load_source("embedded:lift_place")
    plain = factory.load_or_retarget(clip, embodiment, None)
    deep_cfg = InteractionEnvCfg(num_envs=2, backend="cpu", retarget=RetargetCfg(squeeze_depth=0.12))
    deep = factory.load_or_retarget(clip, embodiment, tmp_path, factory.retarget_options(deep_cfg))
    assert deep.meta["executable"]["squeeze_depth"] == 0.12
    np.testing.assert_allclose(deep.qpos, plain.qpos, atol=1e-6)

    names = list(deep.actuator_names)
    arms = [names.index(n) for n in names if "shoulder" in n or "elbow" in n]
    legs = [names.index(n) for n in names if any(k in n for k in ("hip", "knee", "ankle"))]
    no_squeeze = replace(factory.retarget_options(), executable=replace(factory.retarget_options().executable,
                                                                        squeeze_depth=0.0))
    bare = factory.load_or_retarget(clip, embodiment, None, no_squeeze).joint_pos
    default_offset = np.abs(plain.joint_pos[:, arms] - bare[:, arms]).max()
    deep_offset = np.abs(deep.joint_pos[:, arms] - bare[:, arms]).max()
    assert default_offset > 0.02
    assert 1.6 * default_offset < deep_offset < 2.4 * default_offset
    np.testing.assert_allclose(deep.joint_pos[:, legs], plain.joint_pos[:, legs], atol=1e-6)

    with pytest.raises(UserError, match=r"squeeze depth 0.12, the task asks for it 0.06 \(retarget\.squeeze_depth\)"):
        factory.load_or_retarget(clip, embodiment, tmp_path, factory.retarget_options(InteractionEnvCfg()))
    # a run saved before the retarget: block (flat keys) asks for what its cached reference was made with
    old_run = saved_env_cfg(_saved_before_the_block(deep_cfg, {"retarget_squeeze_depth": 0.12}), "run/task.json")
    again = factory.load_or_retarget(clip, embodiment, tmp_path, factory.retarget_options(old_run))
    assert again.meta["executable"]["squeeze_depth"] == 0.12
    np.testing.assert_allclose(again.joint_pos, deep.joint_pos, atol=1e-6)  # the cache, stored as float32
    with pytest.raises(UserError, match=r"retarget\.squeeze_depth must be within"):
        RetargetCfg(squeeze_depth=-0.1)


def test_grasp_setting_reaches_the_reference_and_guards_the_cache(tmp_path):
    """retarget.grasp plans the held segments' hands (retarget/grasp.py) with the task's object density; a
    cache made without it is refused."""
    embodiment = load_embodiment("g1_inspire")
    clip = factory.load_source("embedded:lift_place")
    cfg = InteractionEnvCfg(num_envs=2, backend="cpu", retarget=RetargetCfg(grasp=True), object_density=40.0)
    options = factory.retarget_options(cfg)
    assert options.grasp_plan.enabled and options.grasp_plan.object_density == 40.0
    assert not factory.retarget_options(InteractionEnvCfg()).grasp_plan.enabled
    planned = factory.load_or_retarget(clip, embodiment, tmp_path, options)
    plain = factory.load_or_retarget(clip, embodiment, None)
    assert planned.meta["grasp_plan"]["enabled"]
    wrists = [planned.link_names.index(n) for n in ("left_wrist_yaw_link", "right_wrist_yaw_link")]
    assert np.abs(planned.link_pos[:, wrists] - plain.link_pos[:, wrists]).max() > 0.03  # the hands moved
    np.testing.assert_allclose(planned.object_pos, plain.object_pos)  # the object did not
    env = factory.make_env([clip], cfg, embodiment, cache=tmp_path)
    np.testing.assert_allclose(env.references[0].source_object_pos.numpy(), planned.object_pos, atol=1e-5)
    with pytest.raises(UserError, match=r"grasp planning on, the task asks for it off"):
        factory.load_or_retarget(clip, embodiment, tmp_path, factory.retarget_options(InteractionEnvCfg()))
