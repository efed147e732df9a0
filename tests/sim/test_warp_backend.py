"""MuJoCo Warp backend vs the CPU backend: same model, same states and targets, short horizons.

Runs on warp's CPU device here (a CUDA device when present); every comparison is made on the CPU. Tolerances are float32 round-off grown over
15 control steps of the standing G1 with a resting box (measured: qpos ~1e-6, qvel ~5e-5, link positions ~1e-6,
contact forces ~1e-2 N). Outside that regime the engines may part on purpose: MJWarp keeps up to 8 box-plane
contacts where MuJoCo C keeps 4, so a sole driven centimetres into the floor diverges within a step.
"""

import pytest
import torch

pytest.importorskip("mujoco_warp")

from robot_hoi.commands.train import TASK_CONFIG  # noqa: E402
from robot_hoi.data.synth import default_clip  # noqa: E402
from robot_hoi.embodiment import load_embodiment  # noqa: E402
from robot_hoi.sim import make_backend  # noqa: E402
from robot_hoi.tasks.interaction import factory  # noqa: E402
from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg  # noqa: E402
from robot_hoi.tasks.interaction.scene_setup import InteractionScene  # noqa: E402
from robot_hoi.utils.config import load_yaml_dataclass  # noqa: E402

NUM_ENVS = 4


@pytest.fixture(scope="module")
def scene():
    return InteractionScene(load_embodiment("g1_inspire"), default_clip().object)


def _standing_states(scene):
    model, layout = scene.model, scene.layout
    qpos = torch.tensor(model.qpos0, dtype=torch.float64).repeat(NUM_ENVS, 1)
    qpos[:, : layout.robot_nq] = scene.default_robot_qpos().double()
    obj = layout.object_qpos
    qpos[:, obj:obj + 3] = torch.tensor([0.45, 0.0, 0.4], dtype=torch.float64)
    qpos[:, obj] += torch.linspace(0.0, 0.1, NUM_ENVS, dtype=torch.float64)  # distinct worlds
    return qpos, torch.zeros(NUM_ENVS, model.nv, dtype=torch.float64)


def test_warp_steps_like_the_cpu_backend(scene):
    cpu = scene.make_backend(NUM_ENVS, "cpu", nthread=2)
    warp = scene.make_backend(NUM_ENVS, "warp")
    assert warp.qpos.shape == cpu.qpos.shape and warp.sensordata.shape == cpu.sensordata.shape
    ids = torch.arange(NUM_ENVS)
    qpos, qvel = _standing_states(scene)
    cpu.set_state(ids, qpos, qvel)
    warp.set_state(ids, qpos, qvel)
    layout = scene.layout
    generator = torch.Generator().manual_seed(0)
    default = torch.tensor(scene.embodiment.default_pos, dtype=torch.float64)
    for _ in range(15):
        ctrl = default + 0.03 * torch.randn(NUM_ENVS, scene.model.nu, generator=generator, dtype=torch.float64)
        cpu.step(ctrl)
        warp.step(ctrl)
    w_qpos, w_qvel, w_sens = warp.qpos.double().cpu(), warp.qvel.double().cpu(), warp.sensordata.double().cpu()
    torch.testing.assert_close(w_qpos, cpu.qpos, atol=1e-4, rtol=0)
    torch.testing.assert_close(w_qvel, cpu.qvel, atol=1e-3, rtol=0)
    torch.testing.assert_close(w_sens[:, layout.link_pos], cpu.sensordata[:, layout.link_pos], atol=1e-4, rtol=0)
    contacts = lambda s: s[:, layout.contact].reshape(NUM_ENVS, -1, 4)  # noqa: E731  found, force xyz
    assert torch.equal(contacts(w_sens)[..., 0] > 0, contacts(cpu.sensordata)[..., 0] > 0)
    torch.testing.assert_close(contacts(w_sens)[..., 1:], contacts(cpu.sensordata)[..., 1:], atol=0.5, rtol=0)
    # the feet carry the robot's weight in both (a contact force of hundreds of newtons, not a vacuous match)
    feet = [layout.contact_names.index(n) for n in ("left_foot", "right_foot")]
    assert (contacts(w_sens)[:, feet, 1:].norm(dim=-1).sum(-1) > 200.0).all()
    # the worlds are independent: different object positions stayed different
    assert len(set(w_qpos[:, layout.object_qpos].round(decimals=4).tolist())) == NUM_ENVS


def test_set_state_recomputes_sensors_of_reset_worlds_only(scene):
    cpu = scene.make_backend(NUM_ENVS, "cpu", nthread=2)
    warp = scene.make_backend(NUM_ENVS, "warp")
    qpos, qvel = _standing_states(scene)
    ids = torch.arange(NUM_ENVS)
    warp.set_state(ids, qpos, qvel)
    warp.step(torch.tensor(scene.embodiment.default_pos).repeat(NUM_ENVS, 1))
    untouched = warp.sensordata[0].clone()
    moved = qpos[2:3].clone()
    moved[:, 0:2] += torch.tensor([0.3, -0.2], dtype=torch.float64)
    warp.set_state(torch.tensor([2]), moved, qvel[2:3])
    cpu.set_state(torch.tensor([2]), moved, qvel[2:3])
    layout = scene.layout
    torch.testing.assert_close(warp.sensordata[2, layout.link_pos].double().cpu(),
                               cpu.sensordata[2, layout.link_pos], atol=1e-5, rtol=0)
    assert torch.equal(warp.sensordata[0], untouched)  # both on the warp device
    assert warp.qpos[2, 0].item() == pytest.approx(moved[0, 0].item(), abs=1e-6)


# Stand starts: reference-state starts land hands and feet in contact, where the float32 (warp) and float64 (CPU)
# solvers part ways within a few steps; from the stand both step the same physics for the steps compared here.
STAND_STARTS = "init.stand_start_probability=1.0"


def _env_pair() -> dict:
    """{"cpu": env, "warp": env}: the default task on each backend, same seed, stand starts."""
    embodiment, clip = load_embodiment("g1_inspire"), default_clip()
    envs = {}
    for backend in ("cpu", "warp"):
        cfg = load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG, [f"backend={backend}", f"num_envs={NUM_ENVS}",
                                                                   STAND_STARTS])
        envs[backend] = factory.make_env([clip], cfg, embodiment)
    return envs


def test_interaction_env_runs_unchanged_on_warp():
    """Same env code, same seed, same actions: observations, rewards and terminations agree."""
    envs = _env_pair()
    on_cpu = lambda *values: [v.cpu() for v in values]  # noqa: E731
    obs = {name: env.reset() for name, env in envs.items()}
    torch.testing.assert_close(*on_cpu(obs["warp"]["policy"], obs["cpu"]["policy"]), atol=1e-4, rtol=0)
    generator = torch.Generator().manual_seed(1)
    for _ in range(10):
        actions = 0.2 * torch.randn(NUM_ENVS, envs["cpu"].num_actions, generator=generator)
        o_c, r_c, t_c, tr_c, _ = envs["cpu"].step(actions)
        o_w, r_w, t_w, tr_w, _ = envs["warp"].step(actions.to(envs["warp"].device))
        o_w, r_w, t_w, tr_w = on_cpu(o_w["policy"], r_w, t_w, tr_w)
        torch.testing.assert_close(o_w, o_c["policy"], atol=2e-2, rtol=0)
        torch.testing.assert_close(r_w, r_c, atol=1e-2, rtol=0)
        assert torch.equal(t_w, t_c) and torch.equal(tr_w, tr_c)


def test_auto_picks_a_backend_that_exists(scene):
    backend = make_backend("auto", scene.model, 2, scene.embodiment.decimation)
    assert type(backend).__name__ == ("MujocoWarpBackend" if torch.cuda.is_available() else "MujocoCpuBackend")


def test_overflow_flags_are_read_cleared_and_name_the_buffer_to_raise(scene):
    import mujoco_warp

    from robot_hoi.errors import UserError

    warp = scene.make_backend(NUM_ENVS, "warp")
    qpos, qvel = _standing_states(scene)
    warp.set_state(torch.arange(NUM_ENVS), qpos, qvel)
    warp.step(torch.tensor(scene.embodiment.default_pos).repeat(NUM_ENVS, 1))
    kind = mujoco_warp.OverflowType
    warp._overflow_t[1] = int(kind.ITERATIONS)  # a solver limit: counted, not an error
    report = warp.physics_report()
    assert report["Physics/solver_iteration_limit_worlds"] == 1.0
    assert 0 < report["Physics/constraint_rows_max"] <= 544 and report["Physics/contacts_per_world_max"] > 0
    assert warp.physics_report()["Physics/solver_iteration_limit_worlds"] == 0.0  # cleared after reading
    warp._overflow_t[2] = int(kind.NEFC)
    with pytest.raises(UserError, match="EXTRA_CONSTRAINT_ROWS"):
        warp.physics_report()
    warp._overflow_t[3] = int(kind.NARROWPHASE)
    with pytest.raises(UserError, match="CONTACTS_PER_WORLD"):
        warp.physics_report()


def test_train_cli_runs_a_teacher_and_its_student_on_the_warp_backend(tmp_path):
    from robot_hoi.cli import main

    out = tmp_path / "run"
    code = main(["train", "--backend", "warp", "--budget", "2it", "--out", str(out), "--set", "env.num_envs=4",
                 "--set", "ppo.horizon=8", "--set", "runner.tensorboard=false", "--eval-episodes", "1",
                 # episodes end on their first step: the evaluation (until an episode ends) takes one warp step, not
                 # the ~80 of a fresh policy (warp's CPU device launches each kernel from Python: ~0.9 s a step)
                 "--set", "env.warmup_frames=0", "--set", "env.terminations.max_mean_link_error=0.001"])
    assert code == 0
    group = next(p for p in out.iterdir() if p.is_dir())
    assert (group / "model_2.pt").exists() and (group / "eval.json").exists()
    task = (group / "task.json").read_text()
    assert '"backend": "warp"' in task
    # the student pipeline on the same warp teacher: rollouts, distillation and its evaluation on warp's device
    # (MoCap reference: this teacher's episodes end on their first step, too short to distil a reference from)
    student = tmp_path / "student"
    code = main(["train", "student", "--teachers", str(out), "--backend", "warp", "--budget", "2it", "--out",
                 str(student), "--set", "env.num_envs=4", "--set", "ppo.horizon=8", "--set", "runner.tensorboard=false",
                 "--eval-episodes", "1", "--set", "distill.reference=mocap"])
    assert code == 0
    assert (student / "student" / "model_2.pt").exists() and (student / "student" / "eval.json").exists()
    assert '"backend": "warp"' in (student / "student" / "task.json").read_text()


def test_sim_device_picks_the_warp_device_and_refuses_unknown_ones():
    from robot_hoi.errors import UserError

    embodiment, clip = load_embodiment("g1_inspire"), default_clip()
    cfg = load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG, ["backend=warp", "sim_device=cpu", "num_envs=2"])
    env = factory.make_env([clip], cfg, embodiment)
    assert env.device.type == "cpu" and env.reset()["policy"].device.type == "cpu"
    cfg = load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG, ["backend=warp", "sim_device=tpu:7", "num_envs=2"])
    with pytest.raises(UserError, match="tpu:7"):
        factory.make_env([clip], cfg, embodiment)


def test_finite_difference_accelerations_match_the_cpu_backend():
    """link_acc / object_acc difference velocities across steps: on warp the velocities are views of the live
    physics memory, so a kept previous value that is not a copy would make them exactly zero."""
    envs = _env_pair()
    cpu, warp = envs["cpu"], envs["warp"]
    cpu.reset()
    warp.reset()
    generator = torch.Generator().manual_seed(1)
    for _ in range(4):
        actions = 0.2 * torch.randn(NUM_ENVS, cpu.num_actions, generator=generator)
        cpu.step(actions)
        warp.step(actions.to(warp.device))
        assert warp.link_acc.abs().max() > 10.0  # the robot's links accelerate by tens of m/s^2 here
        torch.testing.assert_close(warp.link_acc.cpu(), cpu.link_acc, atol=1e-2, rtol=0)
        torch.testing.assert_close(warp.object_acc.cpu(), cpu.object_acc, atol=0.5, rtol=0)  # a light box (25 kg/m^3) chatters on the floor in float32
