"""Recipes: a teacher run as a file, `configs/recipes/NAME.yaml`, trained by `robot-hoi train --recipe NAME`.

A recipe holds only what differs from the defaults, or from the recipe its `base:` names:

    base:     another recipe (a name under configs/recipes/ or a YAML path); absent or null: the defaults
    data:     clip sources, as --data (files, folders, embedded:NAME; paths from the current directory)
    group:    subject | object | clip, as --group
    budget:   as --budget (30m, 3.5M, 2h,50M)
    init:     as --init: a checkpoint, or none (from scratch); absent: the shipped base policy
    preset:   fast | paper, as --preset
    rewards:  a reward set (configs/tasks/rewards/), as --rewards
    skip_gate: true to train although the reference fails the physics gate, as --skip-gate (say why beside it)
    env:      task settings, nested as in configs/tasks/interaction.yaml (what --set env.KEY=VALUE sets)
    retarget: the task's retarget settings, as its retarget: block (what --set retarget.KEY=VALUE sets)
    train:    training settings, nested as in configs/train/ppo_fast.yaml: seed, model, ppo, runner (--set KEY=VALUE)

A recipe's values override its base's (mappings key by key); the command line's flags and --set override the
recipe. The run folder records the recipe as the run used it (RECORD_FILE): its files merged, the command line
on top, no base, so `robot-hoi train --recipe RUN/recipe.yaml` trains the same again.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import yaml

from deploy.atomic import atomic_write_text
from robot_hoi.errors import UserError
from robot_hoi.paths import CONFIGS_DIR
from robot_hoi.tasks.interaction.env_cfg import LEGACY_RETARGET_KEYS
from robot_hoi.utils.config import apply_changes, merge_dicts, parse_override, read_yaml_chain

RECIPES_DIR = CONFIGS_DIR / "recipes"
RECORD_FILE = "recipe.yaml"
FLAGS = ("data", "group", "budget", "init", "preset", "rewards", "skip_gate")  # the keys that stand for train's flags
SECTIONS = ("env", "retarget", "train")  # the keys that change a config
GROUPS = ("subject", "object", "clip")

T = TypeVar("T")


@dataclass
class Recipe:
    name: str
    layers: list[tuple[Path, dict]]  # (file, its settings without base), base first

    @property
    def settings(self) -> dict:
        """The files merged: each over its base."""
        merged: dict = {}
        for _, layer in self.layers:
            merged = merge_dicts(merged, layer)
        return merged

    def apply(self, section: str, cfg: T) -> T:
        """`cfg` (the task config for "env" and "retarget", its retarget: block, the training config for "train")
        with each file's changes merged in, base first, so an unknown key or a wrong value is reported with the file
        that holds it."""
        for path, layer in self.layers:
            if layer.get(section):
                if section == "retarget":
                    cfg = apply_changes(cfg, {"retarget": layer[section]}, str(path))
                else:
                    cfg = apply_changes(cfg, layer[section], str(path), prefix=(section,))
        return cfg


def recipe_names() -> list[str]:
    return sorted(p.stem for p in RECIPES_DIR.glob("*.yaml"))


def load_recipe(name: str) -> Recipe:
    """The recipe `name` (configs/recipes/<name>.yaml or a YAML path) with its bases."""
    layers = read_yaml_chain(name, RECIPES_DIR, "recipe", {*FLAGS, *SECTIONS})
    for path, layer in layers:
        _check_layer(path, layer)
    return Recipe(name=Path(name).stem, layers=layers)


def _check_layer(path: Path, layer: dict) -> None:
    for key in ("budget", "init", "preset", "rewards"):
        if key in layer and not isinstance(layer[key], str):
            raise UserError(f"{path}: {key}: expected a string, got {layer[key]!r}")
    if "skip_gate" in layer and not isinstance(layer["skip_gate"], bool):
        raise UserError(f"{path}: skip_gate: expected true or false, got {layer['skip_gate']!r}")
    if "group" in layer and layer["group"] not in GROUPS:
        raise UserError(f"{path}: group: {layer['group']!r} is not one of {', '.join(GROUPS)}")
    data = layer.get("data")
    if "data" in layer and not (isinstance(data, list) and all(isinstance(d, str) for d in data)):
        raise UserError(f"{path}: data: expected a list of clip sources, got {data!r}")
    for section in SECTIONS:
        if section in layer and not isinstance(layer[section], dict | None):
            raise UserError(f"{path}: {section}: expected a mapping of settings, got {layer[section]!r}")
    env = layer.get("env") or {}
    if "reward_set" in env:
        raise UserError(f"{path}: env.reward_set: a recipe names its reward set as rewards: NAME")
    if "retarget" in env:
        raise UserError(f"{path}: env.retarget: a recipe's retarget settings are a section of their own, retarget:")
    for key in env:
        if key in LEGACY_RETARGET_KEYS:
            raise UserError(f"{path}: env.{key}: the retarget settings are a recipe section of their own: spell it "
                            f"retarget: {{{LEGACY_RETARGET_KEYS[key]}: ...}}")


def resolved(recipe: Recipe | None, flags: dict[str, Any], overrides: list[str]) -> dict:
    """The recipe as a run uses it: `recipe`'s files merged, `flags` (train's flags by recipe key; None: not given)
    and the --set `overrides` (env.KEY=VALUE into env, retarget.KEY=VALUE into retarget, others into train) on top."""
    out = recipe.settings if recipe is not None else {}
    out = merge_dicts(out, {k: v for k, v in flags.items() if v is not None})
    for item in overrides:
        parts, value = parse_override(item)
        section = "train"
        if parts[0] in ("env", "retarget"):
            section, parts = parts[0], parts[1:]
        for part in reversed(parts):
            value = {part: value}
        out = merge_dicts(out, {section: value})
    return {key: out[key] for key in (*FLAGS, *SECTIONS) if out.get(key) is not None}


def write_record(run_dir: Path, record: dict, recipe: Recipe | None) -> Path:
    """RECORD_FILE in `run_dir`: the resolved recipe, itself a recipe."""
    source = (f"recipe {recipe.name} ({' <- '.join(str(p) for p, _ in reversed(recipe.layers))})"
              if recipe is not None else "no recipe")
    header = (f"# The recipe this run trained with: {source} with the command line on top.\n"
              f"# `robot-hoi train --recipe {Path(run_dir) / RECORD_FILE}` trains the same again.\n")
    path = Path(run_dir) / RECORD_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, header + yaml.safe_dump(record, sort_keys=False, default_flow_style=False))
    return path
