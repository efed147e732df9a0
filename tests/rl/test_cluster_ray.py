"""`robot-hoi train --cluster ray` on a local 2-CPU Ray instance: two teachers gathered into the run folder, a
pre-empted teacher resumed from its checkpoint, and workers without shared storage shipping their results back.
Tiny budgets (a few iterations of 4 envs); the Ray instance is shared by the module."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest

from robot_hoi.cli import main
from robot_hoi.rl.cluster import (
    INCOMING_DIRNAME,
    STAGING_DIRNAME,
    TOKEN_FILE,
    FolderSync,
    pack_folder,
    unpack_into,
)
from robot_hoi.rl.teacher_job import PREEMPT_HOOK_ENV

pytestmark = pytest.mark.slow  # Ray clusters (about 80 s)

ray = pytest.importorskip("ray")

LIFT, PUSH = "synth_lift_carry_seed0", "synth_push_seed0"
EVAL_FIELDS = {"episodes", "success_rate", "duration_s", "E_h_cm", "E_o_cm", "return", "clip_duration_s"}
TINY = ["--set", "env.num_envs=4", "--set", "runner.save_interval=2", "--set", "runner.tensorboard=false",
        "--eval-episodes", "2"]


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, logging_level=logging.WARNING, log_to_driver=False)
    yield
    ray.shutdown()


def _train(out: Path, *extra: str, data=("embedded:lift_carry", "embedded:push")) -> int:
    return main(["train", "--cluster", "ray", "--data", *data, "--group", "clip", "--out", str(out), *TINY,
                 "--skip-gate", *extra])  # the mechanics of distributed training, not the references


def _steps(group_dir: Path) -> list[int]:
    return [json.loads(line)["step"] for line in (group_dir / "scalars.jsonl").read_text().splitlines()]


def test_two_teachers_and_a_preempted_one_resumes(local_ray, tmp_path, monkeypatch):
    markers = tmp_path / "markers"
    markers.mkdir()
    (markers / f"{PUSH}.preempted").write_text("already fired\n")  # only the lift teacher gets pre-empted
    monkeypatch.setenv(PREEMPT_HOOK_ENV, str(markers))
    out = tmp_path / "run"

    assert _train(out, "--budget", "6it", "--max-retries", "2") == 0  # 3 iterations per teacher

    report = json.loads((out / "teachers.json").read_text())
    assert report["failures"] == {} and set(report["teachers"]) == {LIFT, PUSH}
    for group in (LIFT, PUSH):
        folder = out / group
        assert (folder / "model_3.pt").is_file() and (folder / "task.json").is_file()
        evaluation = json.loads((folder / "eval.json").read_text())
        assert evaluation["group"] == group and evaluation["checkpoint"] == "model_3.pt"
        assert evaluation["iteration"] == 3 and set(evaluation["clips"]) == {group}
        assert EVAL_FIELDS <= set(evaluation["clips"][group])
        assert evaluation["clips"][group]["episodes"] == 2
        assert 0.0 <= evaluation["mean"]["success_rate"] <= 1.0 and evaluation["mean"]["E_h_cm"] > 0.0
        assert report["teachers"][group]["storage"] == "shared"
    # the killed task ran again and continued from model_2.pt: iterations 1, 2 | 3, not 1, 2 | 1, 2, 3
    assert "iteration 2" in (markers / f"{LIFT}.preempted").read_text()
    assert report["teachers"][LIFT]["resumed_from"] == 2 and report["teachers"][LIFT]["iterations"] == 1
    assert _steps(out / LIFT) == [1, 2, 3]
    assert report["teachers"][PUSH]["resumed_from"] is None and _steps(out / PUSH) == [1, 2, 3]
    assert not (out / TOKEN_FILE).exists()


def test_workers_without_shared_storage_ship_results_back(local_ray, tmp_path, monkeypatch):
    monkeypatch.delenv(PREEMPT_HOOK_ENV, raising=False)
    out = tmp_path / "driver"  # forced --storage local: the worker trains in its own temp folder instead

    assert _train(out, "--budget", "2it", "--storage", "local", data=("embedded:push",)) == 0
    summary = json.loads((out / "teachers.json").read_text())["teachers"][PUSH]
    assert summary["storage"] == "local" and STAGING_DIRNAME in Path(summary["run_dir"]).parts
    assert not Path(summary["run_dir"]).is_relative_to(out)
    folder = out / PUSH
    assert (folder / "model_2.pt").is_file() and (folder / "eval.json").is_file()
    assert (folder / "job_state.json").is_file() and _steps(folder) == [1, 2]
    assert not (folder / "references").exists()  # the retarget cache stays behind
    assert not Path(summary["run_dir"]).parent.exists()  # the worker cleaned its staging folder up
    assert not (out / INCOMING_DIRNAME).exists()

    # --resume sends the driver's copy to the worker, which continues from it
    assert _train(out, "--budget", "2it", "--storage", "local", "--resume", data=("embedded:push",)) == 0
    summary = json.loads((out / "teachers.json").read_text())["teachers"][PUSH]
    assert summary["resumed_from"] == 2 and summary["iteration"] == 4
    assert (folder / "model_4.pt").is_file() and _steps(folder) == [1, 2, 3, 4]
    assert json.loads((folder / "eval.json").read_text())["checkpoint"] == "model_4.pt"


def test_a_retry_that_lost_its_disk_resumes_from_the_drivers_mirror(local_ray, tmp_path, monkeypatch):
    markers = tmp_path / "markers"
    markers.mkdir()
    (markers / "lose_disk").write_text("the pre-empted node's staging folder goes with it\n")
    monkeypatch.setenv(PREEMPT_HOOK_ENV, str(markers))
    out = tmp_path / "driver"

    assert _train(out, "--budget", "3it", "--storage", "local", "--max-retries", "1",
                  data=("embedded:push",)) == 0

    assert "iteration 2" in (markers / f"{PUSH}.preempted").read_text()
    summary = json.loads((out / "teachers.json").read_text())["teachers"][PUSH]
    assert summary["storage"] == "local" and summary["resumed_from"] == 2 and summary["iterations"] == 1
    folder = out / PUSH
    assert (folder / "model_3.pt").is_file() and _steps(folder) == [1, 2, 3]
    assert json.loads((folder / "eval.json").read_text())["checkpoint"] == "model_3.pt"
    assert not Path(summary["run_dir"]).parent.exists() and not (out / INCOMING_DIRNAME).exists()


def test_folder_sync_pushes_only_changes_and_the_driver_drops_pruned_files(tmp_path):
    worker, driver = tmp_path / "worker", tmp_path / "run" / "group"
    worker.mkdir()
    pushed: list[list[str]] = []

    def push(archive: bytes, present: list[str]) -> None:
        import io
        import tarfile

        with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
            pushed.append(sorted(tar.getnames()))
        unpack_into(archive, driver, present=set(present))

    sync = FolderSync(worker, push)
    (worker / "model_2.pt").write_bytes(b"two")
    (worker / "scalars.jsonl").write_text("a\n")
    sync()
    (worker / "model_4.pt").write_bytes(b"four")
    with open(worker / "scalars.jsonl", "a") as f:
        f.write("bb\n")  # grows: its size changes even where mtime has a coarse clock
    sync()
    (worker / "model_2.pt").unlink()  # pruned (keep_last)
    sync()

    assert pushed == [["model_2.pt", "scalars.jsonl"], ["model_4.pt", "scalars.jsonl"], []]
    assert sorted(p.name for p in driver.iterdir()) == ["model_4.pt", "scalars.jsonl"]
    assert (driver / "scalars.jsonl").read_text() == "a\nbb\n"


def test_teacher_larger_than_the_cluster_is_a_user_error(local_ray, tmp_path, capsys):
    assert _train(tmp_path / "run", "--budget", "2it", "--cpus-per-teacher", "8") == 2
    assert "8 CPU" in capsys.readouterr().err


def test_unpack_mirrors_the_worker_folder_and_keeps_references(tmp_path):
    worker = tmp_path / "worker"
    (worker / "references").mkdir(parents=True)
    (worker / "references" / "clip.npz").write_bytes(b"worker cache")
    (worker / "model_4.pt").write_bytes(b"new")
    (worker / ".model_5.pt.tmp").write_bytes(b"half written")
    (worker / "sub").mkdir()
    (worker / "sub" / "a.txt").write_text("nested")
    driver = tmp_path / "run" / "group"
    (driver / "references").mkdir(parents=True)
    (driver / "references" / "clip.npz").write_bytes(b"driver cache")
    (driver / "model_1.pt").write_bytes(b"pruned on the worker")
    (driver / "model_4.pt").write_bytes(b"old")

    unpack_into(pack_folder(worker), driver)

    files = sorted(p.relative_to(driver).as_posix() for p in driver.rglob("*") if p.is_file())
    assert files == ["model_4.pt", "references/clip.npz", "sub/a.txt"]
    assert (driver / "model_4.pt").read_bytes() == b"new"
    assert (driver / "references" / "clip.npz").read_bytes() == b"driver cache"
    assert not (tmp_path / "run" / INCOMING_DIRNAME).exists()

