"""Training progress off a terminal: plain, flushed, periodic lines with the numbers a log reader needs."""

from __future__ import annotations

import io
import subprocess
import sys

import pytest

from robot_hoi.rl.progress import PlainProgress, progress_text, training_progress


class _Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def test_plain_lines_are_periodic(monkeypatch):
    clock = _Clock()
    monkeypatch.setattr("robot_hoi.rl.progress.time.monotonic", clock)
    out = io.StringIO()
    with PlainProgress(interval_s=30.0, stream=out) as progress:
        task = progress.add_task("start", total=100)
        for second in range(0, 95, 5):
            clock.now = float(second)
            progress.update(task, completed=second, description=f"it {second}")
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("[  0%] 0:00:00 it 0")
    assert [line.split()[-1] for line in lines] == ["0", "30", "60", "90"]  # every 30 s and the last state


def test_not_a_terminal_means_plain_lines():
    assert isinstance(training_progress(True, io.StringIO()), PlainProgress)


def test_text_names_throughput_return_length_and_metrics():
    text = progress_text(7, 1234.0, {"Train/mean_return": 12.5, "Train/mean_episode_length": 88.0,
                                     "Metrics/success": 0.25, "Metrics/E_h_cm": 9.87, "Metrics/E_o_cm": 3.2,
                                     "Eval/success_rate": 0.5})
    assert text == ("it 7 | 1,234 samples/s | return 12.5 | ep len 88 | success 0.25 | E_h 9.9 cm | E_o 3.2 cm | "
                    "success_rate 0.5")


@pytest.mark.slow
def test_runner_under_a_pipe_prints_progress_lines(tmp_path):
    """What nohup or a batch system sees: the real runner with its stdout redirected to a file."""
    script = (
        "from robot_hoi.rl.budget import Budget\n"
        "import torch; torch.set_num_threads(1)\n"
        "from robot_hoi.rl.config import FAST_PPO_CONFIG, load_train_config\n"
        "from robot_hoi.rl.dummy_env import ReachEnv\n"
        "from robot_hoi.rl.runner import OnPolicyRunner\n"
        "cfg = load_train_config(FAST_PPO_CONFIG, ['ppo.horizon=8', 'runner.tensorboard=false'])\n"
        "OnPolicyRunner(ReachEnv(num_envs=4, max_episode_length=4), cfg, None).learn(Budget(iterations=3))\n"
    )
    log = tmp_path / "train.log"
    with log.open("w") as f:
        subprocess.run([sys.executable, "-c", script], stdout=f, stderr=subprocess.STDOUT, check=True, timeout=120)
    lines = [line for line in log.read_text().splitlines() if line.startswith("[")]
    assert lines and "it 1 |" in lines[0] and "samples/s" in lines[0] and "it 3 |" in lines[-1]
