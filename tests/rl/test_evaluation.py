"""The evaluation protocol: seeded start draws, both success definitions, intervals, comparisons, results tables."""

from __future__ import annotations

import json

import pytest
import torch

from robot_hoi.cli import main
from robot_hoi.errors import UserError
from robot_hoi.rl import evaluation
from robot_hoi.rl.compare import compare_records
from robot_hoi.rl.results import load_records, render

CLIP = "embedded:push"


def test_wilson_interval_matches_the_closed_form():
    assert evaluation.wilson_interval(0, 10) == pytest.approx((0.0, 0.2775), abs=1e-4)
    assert evaluation.wilson_interval(10, 10) == pytest.approx((0.7225, 1.0), abs=1e-4)
    assert evaluation.wilson_interval(5, 10) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    assert evaluation.wilson_interval(26, 32) == pytest.approx((0.6469, 0.9111), abs=1e-4)


def test_mean_interval_is_a_t_interval():
    m = evaluation.mean_interval([1.0, 2.0, 3.0, 4.0])
    # mean 2.5, sd 1.291, t(0.975, 3) = 3.182: half-width 2.054
    assert m["mean"] == 2.5 and m["lo"] == pytest.approx(0.446, abs=1e-3) and m["hi"] == pytest.approx(4.554, abs=1e-3)
    assert evaluation.mean_interval([3.0])["lo"] is None


def test_protocols_load_by_name_and_unknown_ones_are_named():
    name, randomized = evaluation.load_protocol("randomized")
    assert name == "randomized" and not randomized.deterministic and randomized.stand_yaw > 0
    assert evaluation.load_protocol("stand")[1].deterministic
    with pytest.raises(UserError, match="nope.yaml: no such evaluation protocol"):
        evaluation.load_protocol("nope")


def _starts(protocol: str, seed: int, episodes: int = 6) -> torch.Tensor:
    """Robot root xy + heading quaternion + a body joint + object pose of every env right after reset."""
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.paths import TASK_CONFIG
    from robot_hoi.tasks.interaction import factory
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg
    from robot_hoi.utils.config import load_yaml_dataclass

    cfg = evaluation.protocol_env_cfg(load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG),
                                      evaluation.load_protocol(protocol)[1], episodes, seed)
    cfg.backend, cfg.nthread = "cpu", 1
    env = factory.make_env([factory.load_source(CLIP)], cfg, load_embodiment("g1_inspire"))
    env.reset()
    lay = env.layout
    q = env.backend.qpos
    return torch.cat([q[:, 0:2], q[:, 3:7], q[:, 7:lay.robot_nq], q[:, lay.object_qpos:lay.object_qpos + 7]], 1)


@pytest.fixture(scope="module")
def randomized_starts():
    return _starts("randomized", seed=0)


def test_randomized_starts_differ_per_episode_and_replay_from_the_seed(randomized_starts):
    a = randomized_starts
    assert torch.cdist(a, a).fill_diagonal_(1.0).min() > 1e-3  # no two episodes start alike
    assert torch.equal(a, _starts("randomized", seed=0))       # the seed reproduces every draw
    assert not torch.allclose(a, _starts("randomized", seed=1))
    stand = _starts("stand", seed=0)
    assert torch.equal(stand, stand[:1].expand_as(stand))       # one start, repeated
    # the object moves by at most the protocol's draw: 2 cm in x and y about the stand protocol's
    _, p = evaluation.load_protocol("randomized")
    assert (a[:, -7:-5] - stand[:, -7:-5]).abs().max() <= p.object_xy + 1e-6
    assert (a[:, -7:-5] - stand[:, -7:-5]).abs().max() > 0.2 * p.object_xy


def _eval(folder, *extra: str) -> dict:
    out = folder / "record.json"
    assert main(["eval", "untrained", "--data", CLIP, "--episodes", "3", "--out", str(out), *extra]) == 0
    return json.loads(out.read_text())


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    """An untrained policy's record under the default protocol (shared: each evaluation retargets the clip)."""
    return _eval(tmp_path_factory.mktemp("eval"), "--label", "baseline", "--table", "baselines")


@pytest.mark.slow
def test_eval_reports_both_definitions_with_intervals_and_its_seeds(record, tmp_path):
    (clip,) = record["clips"].values()
    assert record["protocol"]["name"] == "randomized" and record["protocol"]["seed"] == 0
    assert record["protocol"]["validation_seed"] == evaluation.VALIDATION_SEED and record["label"] == "baseline"
    for definition in evaluation.DEFINITIONS:
        r = clip[definition]
        assert r["episodes"] == 3 and len(r["per_episode"]["duration_s"]) == 3
        assert r["success"]["lo"] <= r["success"]["rate"] <= r["success"]["hi"]
        assert r["duration_s"]["lo"] <= r["duration_s"]["mean"] <= r["duration_s"]["hi"]
        assert sum(r["ended_by"].values()) >= 1.0  # every episode ended by something, the clip's end included
    assert record["overall"]["ours"]["success"]["n"] == 3
    # the stand protocol: one trajectory, said so
    stand = _eval(tmp_path, "--protocol", "stand")
    durations = stand["clips"][next(iter(stand["clips"]))]["ours"]["per_episode"]["duration_s"]
    assert stand["protocol"]["deterministic"] and len(set(durations)) == 1
    from robot_hoi.rl.results import eval_rows

    assert "(one trajectory)" in eval_rows("stand", stand)[0] and "[" not in eval_rows("stand", stand)[0].split("|")[5]


@pytest.mark.slow
def test_the_two_definitions_end_episodes_by_their_own_thresholds(tmp_path):
    """With our object line at 1 mm every episode ends as soon as tracking starts; InterMimic's 0.5 m line lets the
    same starts run on."""
    record = _eval(tmp_path, "--set", "env.terminations.max_mean_object_point_error=0.001")
    (clip,) = record["clips"].values()
    ours, theirs = clip["ours"], clip["intermimic"]
    assert ours["ended_by"].get("object_deviation") == 1.0
    assert theirs["ended_by"].get("object_deviation", 0.0) < 1.0
    assert ours["duration_s"]["mean"] < theirs["duration_s"]["mean"]


def _record(success: list[list[int]], share: float = 0.5) -> list[dict]:
    """One fake evaluation record per seed: one clip, the given per-episode successes."""
    records = []
    for flags in success:
        per_episode = {"success": [float(f) for f in flags], "interaction_success": [float(f) for f in flags],
                       "duration_s": [share * 4.0] * len(flags)}
        records.append({"clips": {"c": {"clip_duration_s": 4.0, "ours": {"per_episode": per_episode}}}})
    return records


def test_recipes_separate_only_with_two_seeds_apart_and_disjoint_intervals():
    good, bad = _record([[1] * 30 + [0] * 2, [1] * 31 + [0]]), _record([[1] * 8 + [0] * 24, [1] * 10 + [0] * 22])
    result = compare_records(good, bad, ("tight", "base"))["success"]
    assert result["separate"] and result["higher"] == "tight" and "tight is higher" in result["statement"]
    close = _record([[1] * 20 + [0] * 12, [1] * 12 + [0] * 20])  # seeds overlap the other recipe's
    assert not compare_records(close, bad)["success"]["separate"]
    one_seed = compare_records(good[:1], bad)["success"]
    assert not one_seed["separate"] and "fewer than 2 seeds" in one_seed["statement"]


@pytest.mark.slow
def test_results_are_generated_from_records_and_checked(record, tmp_path, capsys):
    data = tmp_path / "data"
    data.mkdir()
    (data / "untrained_push.json").write_text(json.dumps(record))
    out, readme = tmp_path / "README.md", tmp_path / "GUIDE.md"
    readme.write_text("# guide\n<!-- results: untrained_push -->\nstale\n<!-- /results -->\nafter\n")
    args = ["results", "--data", str(data), "--out", str(out), "--readme", str(readme)]
    assert main(args) == 0
    text = out.read_text()
    assert "## baselines" in text and '<a id="untrained_push"></a>baseline' in text
    guide = readme.read_text()
    assert "stale" not in guide and "| result | clip |" in guide and guide.endswith("<!-- /results -->\nafter\n")
    assert main([*args, "--check"]) == 0
    (data / "untrained_push.json").write_text(json.dumps({**record, "label": "renamed"}))
    assert main([*args, "--check"]) == 1
    readme.write_text("<!-- results: nothing_here -->\n<!-- /results -->\n")
    capsys.readouterr()
    assert main(args) == 2
    assert "names 'nothing_here', which has no record" in capsys.readouterr().err
    (data / "broken.json").write_text("{")
    with pytest.raises(UserError, match="broken.json: not valid JSON"):
        load_records(data)


def test_committed_results_are_what_their_records_give():
    from robot_hoi.commands.results import RESULTS_DIR
    from robot_hoi.paths import REPO_ROOT
    from robot_hoi.rl.results import fill_blocks

    if not (RESULTS_DIR / "data").is_dir():
        pytest.skip("no docs/results/data in this checkout")
    records = load_records(RESULTS_DIR / "data")
    assert (RESULTS_DIR / "README.md").read_text() == render(records)
    readme = (REPO_ROOT / "README.md").read_text()
    assert readme == fill_blocks(readme, records)


def test_model_selection_validates_under_the_training_randomization():
    import yaml

    from robot_hoi.paths import CONFIGS_DIR, TASK_CONFIG
    from robot_hoi.rl.evaluation import selection_env_cfg, validation_label
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg, RandomizationCfg
    from robot_hoi.utils.config import apply_overrides, load_yaml_dataclass

    task = load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG)
    assert not task.randomization.is_on()
    plain = selection_env_cfg(task, episodes=8, seed=100_000)
    assert plain.randomization == RandomizationCfg() and plain.num_envs == 8 and not plain.assist.enabled
    assert validation_label(task) == {}

    hardware = yaml.safe_load((CONFIGS_DIR / "recipes" / "hardware.yaml").read_text())["env"]["randomization"]
    trained = apply_overrides(task, [f"randomization.{k}={v}" for k, v in hardware.items()], "--set")
    assert trained.randomization.is_on()
    picked = selection_env_cfg(trained, episodes=8, seed=100_000)
    assert tuple(picked.randomization.object_mass_scale) == (0.5, 2.0)
    assert picked.randomization.push_velocity == 0.6 and not picked.assist.enabled
    assert validation_label(trained) == {"validation": "training randomization"}
    # a neutral range given as a YAML list is still off
    assert not RandomizationCfg(object_mass_scale=[1.0, 1.0]).is_on()
