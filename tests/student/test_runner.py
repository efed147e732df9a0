"""The distillation runner (InterMimic Alg. 1) on a tiny interaction env: schedule, executed actions, stored
teacher actions, behaviour cloning, checkpoints and resume."""

import pytest
import torch

from robot_hoi.errors import UserError
from robot_hoi.rl.budget import Budget
from robot_hoi.rl.logger import MemoryWriter
from robot_hoi.student.checkpoint import is_student_checkpoint, load_student
from robot_hoi.student.config import STUDENT_FAST_CONFIG, load_student_config
from robot_hoi.student.reference_view import ReferenceTimeline, ReferenceView
from robot_hoi.student.runner import DistillationRunner
from robot_hoi.student.student_env import StudentEnv
from robot_hoi.student.teachers import CompositeTeacher, TeacherMember
from robot_hoi.student.tokens import token_layout
from robot_hoi.tasks.interaction.mdp.observations import student_observation_spec

from .conftest import make_env, make_reference, tiny_teacher

TINY = ["runner.progress=false", "runner.tensorboard=false", "student.width=16", "student.heads=2",
        "student.layers=1", "student.feedforward=32", "model.critic_hidden_dims=[32]", "ppo.horizon=4",
        "ppo.num_minibatches=2", "ppo.num_epochs=2", "eval_episodes=0"]


def build(scene, overrides=(), log_dir=None, num_envs=4):
    cfg, _ = load_student_config(STUDENT_FAST_CONFIG, overrides=[*TINY, *overrides])
    env = make_env(scene, [make_reference(scene, 40, drift=0.005)], num_envs=num_envs)
    teacher = tiny_teacher(env)
    view = ReferenceView(env, ReferenceTimeline(env.references, env), env.cfg.keyframes,
                         env.cfg.warmup_frames)
    composite = CompositeTeacher([TeacherMember("t", teacher, None, view=view)], [0])
    memory = MemoryWriter()
    layout = token_layout(student_observation_spec(env), env.cfg.student_keyframes)
    runner = DistillationRunner(StudentEnv(env), cfg, composite, layout, log_dir, writers=[memory],
                                student_info={"sources": ["test"]})
    return runner, memory, composite


def record_executed(runner):
    executed, step = [], runner.env.step

    def recording_step(actions):
        executed.append(actions.clone())
        return step(actions)

    runner.env.step = recording_step
    return executed


def test_schedule_mixture_and_stored_actions(scene):
    runner, memory, composite = build(scene, ["distill.beta=4", "distill.weights=schedule"])
    executed = record_executed(runner)
    runner.learn(Budget(iterations=1))
    # t = 0: every executed action is the teacher's (Alg. 1 line 10) ...
    storage = runner.alg.storage
    assert torch.equal(torch.stack(executed), storage.extra_obs["teacher_mean"])
    # ... while PPO stores the student's own sample a^(S) (line 12), so its likelihood ratio stays on-policy
    assert not torch.equal(storage.actions, storage.extra_obs["teacher_mean"])
    expected = torch.distributions.Normal(storage.action_means, storage.action_stds).log_prob(storage.actions)
    assert torch.allclose(storage.log_probs, expected.sum(-1), atol=1e-4)
    runner.learn(Budget(iterations=5))
    probability = [v for _, v in memory.scalars["Distill/student_probability"]]
    assert probability == [0.0, 0.25, 0.5, 0.75, 1.0, 1.0]
    assert [v for _, v in memory.scalars["Distill/w_ppo"]] == probability
    assert [v for _, v in memory.scalars["Distill/w_distill"]] == [1 - p for p in probability]
    fraction = [v for _, v in memory.scalars["Distill/student_fraction"]]
    assert fraction[0] == 0.0 and fraction[-1] == 1.0 and 0.0 < fraction[2] < 1.0
    assert runner.alg.surrogate_coef == 1.0
    # p = 1: the student's samples are executed; the teacher's action is still stored as the target
    assert torch.equal(torch.stack(executed[-4:]), storage.actions)
    assert "Loss/extra_actor" in memory.scalars and "Distill/action_error" in memory.scalars


def test_behaviour_cloning_reduces_the_action_error(scene):
    runner, memory, _ = build(scene, ["distill.weights=fixed", "distill.lambda_ppo=0.0", "distill.lambda_kd=1.0",
                                      "ppo.actor_lr=1e-3", "ppo.num_epochs=4"])
    runner.learn(Budget(iterations=12))
    errors = [v for _, v in memory.scalars["Distill/action_error"]]
    assert errors[-1] < 0.6 * errors[0], errors


def test_kl_loss_is_logged_as_kl(scene):
    runner, memory, _ = build(scene, ["distill.loss=kl", "distill.beta=0"])
    runner.learn(Budget(iterations=2))
    assert memory.last("Distill/kl") > 0 and memory.last("Distill/student_fraction") == 1.0


class Counter:
    def __init__(self):
        self.value = 0

    def state_dict(self):
        return {"value": self.value}

    def load_state_dict(self, state):
        self.value = state["value"]


def test_checkpoint_resume_and_reload(scene, tmp_path):
    runner, _, _ = build(scene, ["runner.save_interval=2"], log_dir=tmp_path / "a")
    counter = Counter()
    runner.stateful["counter"] = counter
    runner.iteration_hooks.append(lambda t: setattr(counter, "value", counter.value + 1) or {"Test/hook": t})
    runner.learn(Budget(iterations=3))
    ckpt = tmp_path / "a" / "model_3.pt"
    assert is_student_checkpoint(ckpt) and counter.value == 3

    resumed, memory, _ = build(scene, log_dir=tmp_path / "b")
    other = Counter()
    resumed.stateful["counter"] = other
    resumed.resume(ckpt)
    assert resumed.iteration == 3 and other.value == 3
    for (name, a), (_, b) in zip(runner.model.state_dict().items(), resumed.model.state_dict().items(), strict=True):
        assert torch.equal(a, b), name
    resumed.learn(Budget(iterations=1))
    # the schedule continues at t = 3
    assert memory.last("Distill/student_probability") == pytest.approx(3 / resumed.cfg.distill.beta)

    model, cfg, data = load_student(ckpt)
    obs = torch.randn(2, model.num_actor_obs)
    assert torch.equal(model.act_inference(obs), runner.model.eval().act_inference(obs))
    assert data["student"]["sources"] == ["test"] and cfg.student.width == 16


def test_teacher_checkpoints_are_refused_where_a_student_is_expected(scene, tmp_path):
    from robot_hoi.rl.checkpoint import save_checkpoint

    runner, _, _ = build(scene)
    path = runner.save(tmp_path / "s.pt")
    data = torch.load(path, weights_only=True)
    data.pop("policy_kind")
    save_checkpoint(tmp_path / "t.pt", {k: v for k, v in data.items() if k not in ("format", "version")})
    with pytest.raises(UserError, match="not a student checkpoint"):
        load_student(tmp_path / "t.pt")
    with pytest.raises(UserError, match="not a student checkpoint"):
        runner.load(tmp_path / "t.pt")


def test_student_checkpoints_hold_the_runners_contents_and_take_extras(scene, tmp_path):
    """One assembly of the checkpoint contents (OnPolicyRunner.save): a student's adds only its own keys, and
    takes the runner's `extra` (the in-training evaluation saves model_best.pt with one)."""
    from robot_hoi.rl.runner import OnPolicyRunner

    runner, _, _ = build(scene)
    data = torch.load(runner.save(tmp_path / "s.pt", extra={"eval": {"success": 1.0}}), weights_only=True)
    teacher_keys = torch.load(OnPolicyRunner.save(runner, tmp_path / "t.pt"), weights_only=True).keys()
    assert set(data) == set(teacher_keys) | {"policy_kind", "student", "sampler_state", "eval"}
    assert data["eval"] == {"success": 1.0} and data["student"]["sources"] == ["test"]


def test_weight_average_and_decaying_learning_rate(scene, tmp_path):
    """stability: the average folds in each update's weights at the ramped decay; the actor's rate halves every
    lr_half_life iterations down to its floor; evaluation, model_best.pt and load_student use the average."""
    runner, memory, _ = build(scene, ["stability.ema_decay=0.5", "stability.lr_half_life=2",
                                      "stability.lr_floor=0.4", "ppo.actor_lr=1e-3"], log_dir=tmp_path / "a")
    weights = []
    end = runner._on_iteration_end

    def recording_end():
        weights.append([p.detach().clone() for p in runner.model.parameters()])
        end()

    runner._on_iteration_end = recording_end
    runner.learn(Budget(iterations=4))
    expected = weights[0]
    for n, current in enumerate(weights[1:], start=2):
        decay = runner.cfg.stability.ema_weight(n)
        expected = [decay * e + (1 - decay) * c for e, c in zip(expected, current, strict=True)]
    for got, want in zip(runner.ema.parameters(), expected, strict=True):
        torch.testing.assert_close(got, want)
    assert any(not torch.equal(a, b) for a, b in zip(runner.ema.parameters(), runner.model.parameters(), strict=True))
    for a, b in zip(runner.ema.buffers(), runner.model.buffers(), strict=True):  # normaliser statistics: as trained
        assert torch.equal(a, b)
    assert [v for _, v in memory.scalars["LR/actor"]] == pytest.approx([1e-3, 1e-3 * 0.5 ** 0.5, 5e-4, 4e-4])  # floor at t = 3
    # evaluation scores the average, and the checkpoints carry it
    seen = []
    runner.evaluator = lambda model: seen.append(model) or {"success_rate": 1.0, "duration_s": 1.0}
    runner.evaluate_and_keep_best()
    assert seen == [runner.ema] and not runner.ema.training
    obs = torch.randn(2, runner.model.num_actor_obs)
    averaged, _, _ = load_student(tmp_path / "a" / "model_best.pt")
    last, _, _ = load_student(tmp_path / "a" / "model_4.pt", averaged=False)
    torch.testing.assert_close(averaged.act_inference(obs), runner.ema.act_inference(obs))  # a fused path may round
    assert torch.equal(last.act_inference(obs), runner.model.eval().act_inference(obs))
    # resume continues the average where it was
    resumed, _, _ = build(scene, ["stability.ema_decay=0.5", "stability.lr_half_life=2", "stability.lr_floor=0.4",
                                  "ppo.actor_lr=1e-3"], log_dir=tmp_path / "b")
    resumed.resume(tmp_path / "a" / "model_4.pt")
    assert resumed.ema_updates == 4
    for a, b in zip(resumed.ema.parameters(), runner.ema.parameters(), strict=True):
        assert torch.equal(a, b)


def test_a_decaying_rate_refuses_the_adaptive_one(scene):
    with pytest.raises(UserError, match="lr_half_life with ppo.desired_kl"):
        build(scene, ["stability.lr_half_life=10", "ppo.desired_kl=0.01"])
