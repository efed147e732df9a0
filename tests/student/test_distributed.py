"""Data-parallel student training: the merge arithmetic in one process, then two gloo ranks on the CPU through
the real launcher (spawned processes) on a tiny budget, and a resume."""

import json

import pytest
import torch

from robot_hoi.cli import build_parser
from robot_hoi.errors import UserError
from robot_hoi.rl.budget import Budget
from robot_hoi.rl.normalizer import RunningNormalizer
from robot_hoi.student import distributed
from robot_hoi.student.checkpoint import load_student
from robot_hoi.student.launch import resolve_nproc, train_distributed

from .conftest import student_args


def as_if_two_ranks(monkeypatch, other_rank_value):
    """all_reduce_sum as seen by rank 0 of two ranks whose rank 1 contributes other_rank_value(tensor)."""
    monkeypatch.setattr(distributed, "all_reduce_sum", lambda t: t.add_(other_rank_value(t)))


def test_synced_normaliser_equals_one_normaliser_fed_every_rank(monkeypatch):
    generator = torch.Generator().manual_seed(0)
    first, mine, theirs = (torch.randn(n, 3, generator=generator) * 2 + 5 for n in (7, 5, 9))
    plain = RunningNormalizer(3)
    plain.update(first)
    synced = distributed.SyncedNormalizer.replacing(plain)
    reference = distributed.SyncedNormalizer.replacing(plain)
    shift = synced.mean.double()
    other = torch.cat([torch.tensor([9.0], dtype=torch.float64), (theirs.double() - shift).sum(0),
                       (theirs.double() - shift).square().sum(0)])
    as_if_two_ranks(monkeypatch, lambda t: other)
    synced.update(mine)
    plain.update(torch.cat([mine, theirs]))
    assert float(synced.count) == 21.0
    assert torch.allclose(synced.mean, plain.mean, atol=1e-6) and torch.allclose(synced.var, plain.var, atol=1e-5)
    assert not torch.allclose(reference.mean, synced.mean)
    reference.eval()
    reference.update(mine)  # frozen in eval mode, no collective
    assert float(reference.count) == 7.0


def test_gradient_average_is_the_mean_over_ranks(monkeypatch):
    params = [torch.nn.Parameter(torch.zeros(2, 2)), torch.nn.Parameter(torch.zeros(3))]
    params[0].grad = torch.ones(2, 2)  # params[1] has no gradient on this rank: it counts as zeros
    as_if_two_ranks(monkeypatch, lambda t: torch.full_like(t, 3.0))
    distributed.GradientAverage(2)(params)
    assert torch.equal(params[0].grad, torch.full((2, 2), 2.0)) and torch.equal(params[1].grad, torch.full((3,), 1.5))


def test_shared_budget_counts_every_ranks_samples():
    budget = distributed.SharedBudget(Budget(samples=1000), world_size=4, device="cpu")
    assert budget.fraction_done(0.0, 250, 1) == 1.0 and "4 ranks" in budget.describe()


def test_nproc_defaults_and_refusals():
    args = build_parser().parse_args(["train", "student"])
    assert resolve_nproc(args) == 1  # CPU: one process unless asked
    args.nproc = 0
    with pytest.raises(UserError, match="at least 1"):
        resolve_nproc(args)
    args.nproc, args.device = 64, "cuda"
    with pytest.raises(UserError, match="CUDA device"):
        resolve_nproc(args)


def test_two_gloo_ranks_train_one_student_and_resume(teacher_run, tmp_path, capfd):
    out = tmp_path / "ddp"
    args = build_parser().parse_args(student_args(teacher_run, out, "--set", "eval_episodes=0"))
    args.nproc = 2
    reports = train_distributed(args, 2)
    assert [r["rank"] for r in reports] == [0, 1]
    assert reports[0]["checksum"] == reports[1]["checksum"]
    # each rank collected its own rollouts (4 envs x horizon 8 x 2 iterations); the run counts them all
    assert [r["samples"] for r in reports] == [64, 64] and reports[0]["total_samples"] == 128
    folder = out / "student"
    assert [p.rsplit("/", 1)[-1] for p in reports[0]["checkpoints"]] == ["model_2.pt"]
    assert reports[1]["checkpoints"] == []
    assert sorted(p.name for p in folder.glob("model_*.pt")) == ["model_2.pt"]
    model, _, data = load_student(folder / "model_2.pt")
    assert data["total_samples"] == 128 and distributed.state_checksum(model) == reports[0]["checksum"]
    rows = [json.loads(line) for line in (folder / "scalars.jsonl").read_text().splitlines()]
    assert len(rows) == 2 and rows[-1]["Perf/ranks"] == 2.0  # one writer
    assert "parameters identical on all 2 ranks" in capfd.readouterr().out

    args.resume = True
    reports = train_distributed(args, 2)
    assert {r["iteration"] for r in reports} == {4} and reports[0]["checksum"] == reports[1]["checksum"]
    assert reports[0]["total_samples"] == 256 and load_student(folder / "model_4.pt")[2]["total_samples"] == 256


def test_each_rank_has_its_own_envs(teacher_run, tmp_path):
    """What makes the identical parameters above meaningful: the ranks' rollouts start from different states."""
    from robot_hoi.student.pipeline import prepare_run, student_environment

    args = build_parser().parse_args(student_args(teacher_run, tmp_path / "seeds"))
    first = []
    for rank in (0, 1):
        setup, _ = prepare_run(args, distributed.Rank(rank, 2, "cpu"))
        assert setup.env_cfg.seed == setup.teacher_env_cfg.seed + rank
        first.append(student_environment(setup, write=False).student_env.reset()["critic"])
    assert not torch.allclose(first[0], first[1])


def test_a_rank_that_refuses_its_settings_stops_the_run_with_its_message(teacher_run, tmp_path):
    from robot_hoi.student.launch import run

    args = build_parser().parse_args(student_args(teacher_run, tmp_path / "kl", "--set", "ppo.desired_kl=0.01"))
    args.nproc = 2
    with pytest.raises(UserError, match=r"rank \d: ppo.desired_kl .* each rank would adapt its own rate"):
        run(args)
    assert not list((tmp_path / "kl" / "student").glob("model_*.pt"))
