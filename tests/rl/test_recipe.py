"""Recipes (robot_hoi/rl/recipe.py): a run as a file with `base:` inheritance, `robot-hoi train --recipe`, the
command line on top, the resolved recipe recorded in the run folder; `--seeds` trains one run folder per seed."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from robot_hoi.cli import main
from robot_hoi.errors import UserError
from robot_hoi.paths import TASK_CONFIG
from robot_hoi.rl.config import DEFAULT_PPO_CONFIG, FAST_PPO_CONFIG, load_train_config
from robot_hoi.rl.recipe import RECORD_FILE, load_recipe, recipe_names
from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg, apply_reward_set
from robot_hoi.utils.config import load_yaml_dataclass

TINY = ["--eval-episodes", "1", "--set", "runner.progress=false", "--set", "runner.tensorboard=false",
        "--set", "env.num_envs=4", "--set", "env.nthread=1", "--set", "ppo.horizon=4", "--set", "runner.eval_interval=0",
        "--set", "model.actor_hidden_dims=[32]", "--set", "model.critic_hidden_dims=[32]"]


def _write(folder: Path, name: str, data: dict) -> Path:
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _configs(recipe):
    """The task and training configs a recipe gives (without a command line)."""
    settings = recipe.settings
    env = load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG)
    if settings.get("rewards"):
        apply_reward_set(env, settings["rewards"])
    preset = DEFAULT_PPO_CONFIG if settings.get("preset") == "paper" else FAST_PPO_CONFIG
    return recipe.apply("retarget", recipe.apply("env", env)), recipe.apply("train", load_train_config(preset))


def test_every_shipped_recipe_loads_and_applies():
    """Each configs/recipes/*.yaml names only keys the configs have (a renamed setting fails here)."""
    names = recipe_names()
    assert {"lift_place_scratch", "lift_carry", "table_drag", "base_policy", "gpu"} <= set(names)
    for name in names:
        _configs(load_recipe(name))
    table_env, _ = _configs(load_recipe("table_drag"))
    assert table_env.init.failure_weighted  # from its base
    assert (table_env.retarget.squeeze_depth, table_env.retarget.squeeze_toward, table_env.assist.anneal_samples) == \
        (0.12, "surface", 0.6e6)
    assert table_env.rewards["object_pos"].weight == 156.0  # anchor_additive_tight
    assert table_env.assist.initial_level == 1.0  # untouched settings keep the task config's


def test_bases_nest_and_merge_key_by_key(tmp_path):
    _write(tmp_path, "a", {"budget": "10m", "env": {"assist": {"anneal_samples": 1.0e6, "initial_level": 0.5}}})
    _write(tmp_path, "b", {"base": "a.yaml", "budget": "20m", "env": {"assist": {"anneal_samples": 2.0e6}},
                           "train": {"seed": 4}})
    leaf = _write(tmp_path, "c", {"base": "b.yaml", "env": {"num_envs": 8}})
    recipe = load_recipe(str(leaf))
    assert [p.name for p, _ in recipe.layers] == ["a.yaml", "b.yaml", "c.yaml"]
    assert recipe.settings == {"budget": "20m", "train": {"seed": 4},
                               "env": {"assist": {"anneal_samples": 2.0e6, "initial_level": 0.5}, "num_envs": 8}}
    env, train = _configs(recipe)
    assert (env.assist.anneal_samples, env.assist.initial_level, env.num_envs, train.seed) == (2.0e6, 0.5, 8, 4)


def test_a_base_cycle_is_refused_naming_the_file(tmp_path):
    _write(tmp_path, "a", {"base": "b.yaml"})
    _write(tmp_path, "b", {"base": "c.yaml"})
    _write(tmp_path, "c", {"base": "a.yaml"})
    with pytest.raises(UserError, match=r"c\.yaml: base 'a' makes a cycle \(a\.yaml -> b\.yaml -> c\.yaml -> a\.yaml\)"):
        load_recipe(str(tmp_path / "a.yaml"))
    _write(tmp_path, "self", {"base": "self.yaml"})
    with pytest.raises(UserError, match="self.yaml: base 'self' makes a cycle"):
        load_recipe(str(tmp_path / "self.yaml"))
    with pytest.raises(UserError, match="base 'nope': no such recipe"):
        load_recipe(str(_write(tmp_path, "d", {"base": "nope"})))


def test_unknown_keys_are_refused_naming_the_file_and_the_key(tmp_path):
    with pytest.raises(UserError, match=r"x\.yaml: unknown key\(s\) budgett"):
        load_recipe(str(_write(tmp_path, "x", {"budgett": "5m"})))
    _write(tmp_path, "base", {"env": {"assist": {"anneal_sample": 1.0}}})
    leaf = _write(tmp_path, "leaf", {"base": "base.yaml", "budget": "5m"})
    with pytest.raises(UserError, match=r"base\.yaml: unknown key 'env\.assist\.anneal_sample'"):
        _configs(load_recipe(str(leaf)))  # named in the base, which holds it
    with pytest.raises(UserError, match=r"t\.yaml: unknown key 'train\.ppo\.lr'"):
        _configs(load_recipe(str(_write(tmp_path, "t", {"train": {"ppo": {"lr": 1.0}}}))))
    with pytest.raises(UserError, match=r"g\.yaml: group: 'team' is not one of"):
        load_recipe(str(_write(tmp_path, "g", {"group": "team"})))
    with pytest.raises(UserError, match=r"s\.yaml: skip_gate: expected true or false, got 'yes please'"):
        load_recipe(str(_write(tmp_path, "s", {"skip_gate": "yes please"})))
    with pytest.raises(UserError, match=r"r\.yaml: unknown key 'retarget\.squeeze_dept'"):
        _configs(load_recipe(str(_write(tmp_path, "r", {"retarget": {"squeeze_dept": 0.1}}))))


def test_retarget_settings_are_a_section_of_their_own(tmp_path):
    """A recipe's retarget: section sets the task config's retarget: block (as --set retarget.KEY=VALUE); the
    settings under env:, flat or nested, are refused with the spelling to use."""
    _write(tmp_path, "base", {"retarget": {"squeeze_depth": 0.1, "solver": "qp"}})
    leaf = _write(tmp_path, "leaf", {"base": "base.yaml", "retarget": {"squeeze_depth": 0.2}})
    env, _ = _configs(load_recipe(str(leaf)))
    assert (env.retarget.squeeze_depth, env.retarget.solver) == (0.2, "qp")
    with pytest.raises(UserError, match=r"flat\.yaml: env\.retarget_squeeze_depth: .* retarget: \{squeeze_depth: "):
        load_recipe(str(_write(tmp_path, "flat", {"env": {"retarget_squeeze_depth": 0.1}})))
    with pytest.raises(UserError, match=r"nested\.yaml: env\.retarget: .* a section of their own, retarget:"):
        load_recipe(str(_write(tmp_path, "nested", {"env": {"retarget": {"squeeze_depth": 0.1}}})))
    with pytest.raises(UserError, match=r"retarget\.squeeze_depth must be within"):
        _configs(load_recipe(str(_write(tmp_path, "far", {"retarget": {"squeeze_depth": 1.0}}))))


def test_a_recipe_can_train_past_the_gate_and_the_command_line_still_decides(tmp_path):
    """`skip_gate: true` in a recipe stands for --skip-gate; without either the gate runs."""
    skip = _write(tmp_path, "skip", {"data": ["embedded:push"], "skip_gate": True})
    plain = _write(tmp_path, "plain", {"data": ["embedded:push"]})
    assert train_args(["train", "--recipe", str(skip)]).skip_gate is True
    assert train_args(["train", "--recipe", str(plain)]).skip_gate is False
    assert train_args(["train", "--recipe", str(plain), "--skip-gate"]).skip_gate is True
    assert train_args(["train"]).skip_gate is False


def train_args(argv: list[str]):
    """train's arguments once the recipe has filled the flags the command line left unset."""
    from robot_hoi.cli import build_parser
    from robot_hoi.commands.train import _apply_recipe_flags

    args = build_parser().parse_args(argv)
    _apply_recipe_flags(args)
    return args


class _Stop(Exception):
    pass


@pytest.mark.slow
def test_command_line_overrides_the_recipe_and_the_run_records_it(tmp_path, monkeypatch):
    """Flags and --set win over the recipe, the recipe over its base and the task config; the run folder's
    recipe.yaml holds the result and, trained again, gives the same configs."""
    jobs = []

    def capture(job, clips):
        jobs.append(job)
        raise _Stop

    monkeypatch.setattr("robot_hoi.rl.teacher_job.train_teacher_group", capture)
    _write(tmp_path, "base", {"budget": "30m", "env": {"assist": {"anneal_samples": 1.0e6, "initial_level": 0.7}},
                              "retarget": {"squeeze_depth": 0.1, "solver": "dls"},
                              "train": {"seed": 5, "ppo": {"num_epochs": 3}}})
    leaf = _write(tmp_path, "leaf", {"base": "base.yaml", "rewards": "anchor_additive_tight", "init": "none",
                                     "env": {"assist": {"anneal_samples": 2.0e6}}})
    out = tmp_path / "run"
    with pytest.raises(_Stop):
        main(["train", "--recipe", str(leaf), "--budget", "3it", "--set", "seed=7", "--out", str(out), *TINY,
              "--set", "env.assist.anneal_samples=123", "--set", "ppo.num_epochs=2", "--set", "retarget.squeeze_depth=0.06"])
    (job,) = jobs
    env, train = job.env_cfg, job.train_cfg
    assert env.assist.anneal_samples == 123.0  # --set over the recipe over its base
    assert env.assist.initial_level == 0.7  # the base's, untouched by the leaf
    assert (env.retarget.squeeze_depth, env.retarget.solver) == (0.06, "dls")  # --set over the base's
    assert env.rewards["root_pos"].weight == 44.4  # the recipe's reward set
    assert (train.seed, train.ppo.num_epochs) == (7, 2)  # --set over the base's
    assert job.budget.iterations == 3 and job.init is None  # --budget over 30m; init: none
    record = yaml.safe_load((out / RECORD_FILE).read_text())
    assert record["budget"] == "3it" and record["init"] == "none" and record["rewards"] == "anchor_additive_tight"
    assert record["env"]["assist"] == {"anneal_samples": 123, "initial_level": 0.7}
    assert record["retarget"] == {"squeeze_depth": 0.06, "solver": "dls"}
    assert record["train"]["seed"] == 7 and "base" not in record
    again = out / "again"
    with pytest.raises(_Stop):
        main(["train", "--recipe", str(out / RECORD_FILE), "--out", str(again)])
    assert jobs[1].env_cfg == env and jobs[1].train_cfg == train and jobs[1].budget == job.budget
    assert yaml.safe_load((again / RECORD_FILE).read_text()) == record


@pytest.mark.parametrize("extra, message", [
    (["--seeds", "1", "2", "--seed", "3"], None),  # argparse: not allowed with
    (["--seeds", "1", "--set", "seed=2"], "drop --set seed="),
    (["--seeds", "1", "1"], "seed 1 given more than once"),
    (["--seed", "1", "--set", "seed=2"], "give one"),
])
def test_conflicting_seeds_are_refused(tmp_path, capsys, extra, message):
    try:
        code = main(["train", "--out", str(tmp_path / "run"), "--budget", "1it", *extra])
    except SystemExit as exc:  # argparse's refusal
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert (message or "not allowed with argument") in err
    assert not (tmp_path / "run").exists()


@pytest.mark.slow
def test_seeds_train_one_run_folder_each_and_resume(tmp_path, capsys):
    """`--seeds 1 2`: two run folders, each with its checkpoint, task.json and the recipe with its seed; `--resume`
    continues a seed's folder."""
    out = tmp_path / "runs"
    assert main(["train", "--recipe", "lift_place_scratch", "--seeds", "1", "2", "--budget", "1it", "--out", str(out),
                 *TINY]) == 0
    printed = capsys.readouterr().out
    for seed in (1, 2):
        folder = out / f"seed_{seed}"
        assert f"seed {seed}: {folder}" in printed
        (group,) = [p for p in folder.iterdir() if p.is_dir()]
        assert (group / "model_1.pt").is_file() and (group / "task.json").is_file()
        record = yaml.safe_load((folder / RECORD_FILE).read_text())
        assert record["train"]["seed"] == seed and record["init"] == "none" and record["budget"] == "1it"
    assert main(["train", "--recipe", "lift_place_scratch", "--seeds", "1", "--budget", "1it", "--resume",
                 "--out", str(out), *TINY]) == 0
    (teacher,) = json.loads((out / "seed_1" / "teachers.json").read_text())["teachers"].values()
    assert teacher["resumed_from"] == 1 and teacher["iteration"] == 2
