"""Control-level embodiment config (configs/embodiments/<name>.yaml) as dataclasses, checked against the robot.

`load_embodiment("g1_inspire")` reads the YAML strictly (unknown keys, wrong types and missing keys are
UserErrors naming the file) and then checks it against the physical description in g1_spec: every actuated
joint has exactly one actuator, defaults lie inside the joint ranges, hand channels drive actuated joints and
every link_map entry is a body or a site of the model.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from robot_hoi.embodiment.g1_spec import g1_inspire
from robot_hoi.embodiment.spec_types import RobotDescription
from robot_hoi.errors import UserError
from robot_hoi.paths import CONFIGS_DIR
from robot_hoi.utils.config import apply_overrides, load_dataclass

EMBODIMENTS_DIR = CONFIGS_DIR / "embodiments"
HAND_SIDES = ("left", "right")
INSPIRE_CHANNELS = ("pinky", "ring", "middle", "index", "thumb_bend", "thumb_rotate")
UNITS_OPEN = 1000.0


@dataclass(frozen=True)
class ActuatorCfg:
    """One position actuator, in policy/action order: target = default + action_scale * action."""

    name: str  # the joint it drives (MuJoCo actuator has the same name)
    kp: float  # N·m/rad
    kd: float  # N·m·s/rad
    default: float  # rad
    action_scale: float  # rad per unit action


@dataclass(frozen=True)
class HandChannelCfg:
    """One Inspire channel (0..1000 units, 1000 = open) driving one actuated joint linearly."""

    name: str
    joint: str
    open_rad: float
    closed_rad: float


@dataclass(frozen=True)
class HandCfg:
    channels: tuple[HandChannelCfg, ...]


@dataclass(frozen=True)
class EmbodimentConfig:
    name: str
    robot_height: float  # m, for human -> robot scaling
    control_dt: float  # s, policy period
    decimation: int  # physics steps per control step
    self_collision: bool
    spawn_height: float  # m, pelvis height of the default stand (feet on the floor)
    actuators: tuple[ActuatorCfg, ...]
    hands: dict[str, HandCfg]
    link_map: dict[str, str]  # robot body or site -> human body name
    deploy: dict[str, Any] | None = None  # the robot runtime's own limits, read by deploy/embodiment.py only

    @property
    def physics_dt(self) -> float:
        return self.control_dt / self.decimation

    @property
    def actuator_names(self) -> tuple[str, ...]:
        return tuple(a.name for a in self.actuators)

    @property
    def kp(self) -> np.ndarray:
        return np.array([a.kp for a in self.actuators], dtype=np.float64)

    @property
    def kd(self) -> np.ndarray:
        return np.array([a.kd for a in self.actuators], dtype=np.float64)

    @property
    def default_pos(self) -> np.ndarray:
        return np.array([a.default for a in self.actuators], dtype=np.float64)

    @property
    def action_scale(self) -> np.ndarray:
        return np.array([a.action_scale for a in self.actuators], dtype=np.float64)

    def description(self) -> RobotDescription:
        """The physical robot this config drives."""
        return robot_description(self.name)

    def hand_actuator_indices(self, hand: str) -> np.ndarray:
        """Indices into the actuator order of `hand`'s channels, in channel (register) order."""
        index = {n: i for i, n in enumerate(self.actuator_names)}
        return np.array([index[c.joint] for c in self._hand(hand).channels], dtype=np.int64)

    def rad_to_units(self, hand: str, rad) -> np.ndarray:
        """Joint radians (..., 6 channels) -> Inspire units 0..1000 (1000 = open), float, clipped to 0..1000.

        The hardware takes integers; rounding belongs to the code that writes the register.
        """
        open_rad, closed_rad = self._channel_arrays(hand)
        units = UNITS_OPEN * (np.asarray(rad, dtype=np.float64) - closed_rad) / (open_rad - closed_rad)
        return np.clip(units, 0.0, UNITS_OPEN)

    def units_to_rad(self, hand: str, units) -> np.ndarray:
        """Inspire units (..., 6 channels; clipped to 0..1000) -> joint radians."""
        open_rad, closed_rad = self._channel_arrays(hand)
        frac = np.clip(np.asarray(units, dtype=np.float64), 0.0, UNITS_OPEN) / UNITS_OPEN
        return closed_rad + frac * (open_rad - closed_rad)

    def _hand(self, hand: str) -> HandCfg:
        if hand not in self.hands:
            raise UserError(f"embodiment {self.name}: no hand {hand!r} (hands: {', '.join(self.hands)})")
        return self.hands[hand]

    def _channel_arrays(self, hand: str) -> tuple[np.ndarray, np.ndarray]:
        channels = self._hand(hand).channels
        return (
            np.array([c.open_rad for c in channels], dtype=np.float64),
            np.array([c.closed_rad for c in channels], dtype=np.float64),
        )


def _descriptions() -> dict[str, Callable[[], RobotDescription]]:
    return {"g1_inspire": g1_inspire}


@functools.cache
def robot_description(name: str) -> RobotDescription:
    """The (immutable) physical description registered under `name`."""
    known = _descriptions()
    if name not in known:
        raise UserError(f"no physical robot description named {name!r} (known: {', '.join(sorted(known))})")
    return known[name]()


def available_embodiments() -> list[str]:
    return sorted(p.stem for p in EMBODIMENTS_DIR.glob("*.yaml"))


def resolve_embodiment_path(name_or_path: str | os.PathLike) -> Path:
    """A YAML path as given, or a name looked up as configs/embodiments/<name>.yaml."""
    text = str(name_or_path)
    candidate = Path(text)
    if candidate.suffix in (".yaml", ".yml") or os.sep in text or candidate.exists():
        if not candidate.is_file():
            raise UserError(f"{candidate}: embodiment config not found")
        return candidate
    path = EMBODIMENTS_DIR / f"{text}.yaml"
    if not path.is_file():
        raise UserError(f"unknown embodiment {text!r} (available: {', '.join(available_embodiments()) or 'none'})")
    return path


def load_embodiment(name_or_path: str | os.PathLike, overrides: Sequence[str] = ()) -> EmbodimentConfig:
    """Read and check an embodiment config; `overrides` are "dotted.key=value" strings (e.g. "decimation=4")."""
    path = resolve_embodiment_path(name_or_path)
    try:
        raw = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise UserError(f"{path}: not valid YAML ({exc})") from None
    if not isinstance(raw, dict):
        raise UserError(f"{path}: expected a mapping at the top level")
    cfg = load_dataclass(EmbodimentConfig, raw, str(path))
    if overrides:
        cfg = apply_overrides(cfg, list(overrides), source=str(path))
    validate_embodiment(cfg, str(path))
    return cfg


def validate_embodiment(cfg: EmbodimentConfig, source: str = "embodiment") -> None:
    """Raise UserError (naming `source`) if `cfg` does not fit its robot description."""

    def fail(message: str) -> None:
        raise UserError(f"{source}: {message}")

    for key in ("robot_height", "control_dt", "spawn_height"):
        value = getattr(cfg, key)
        if not (math.isfinite(value) and value > 0):
            fail(f"{key} must be a positive number, got {value}")
    if cfg.decimation < 1:
        fail(f"decimation must be >= 1, got {cfg.decimation}")
    desc = robot_description(cfg.name)
    joints = {j.name: j for j in desc.joints}
    names = cfg.actuator_names
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        fail(f"actuators listed twice: {', '.join(duplicates)}")
    for i, act in enumerate(cfg.actuators):
        where = f"actuators[{i}] ({act.name})"
        if act.name not in joints:
            fail(f"{where}: actuator not in the model (no joint of that name in {desc.name})")
        joint = joints[act.name]
        if joint.mimic is not None:
            fail(f"{where}: {act.name} is a passive joint coupled to {joint.mimic.joint}; it cannot be actuated")
        for key in ("kp", "kd", "default", "action_scale"):
            if not math.isfinite(getattr(act, key)):
                fail(f"{where}: {key} must be finite")
        if act.kp < 0 or act.kd < 0:
            fail(f"{where}: kp and kd must be >= 0")
        if act.action_scale <= 0:
            fail(f"{where}: action_scale must be > 0")
        lo, hi = joint.range
        if not lo <= act.default <= hi:
            fail(f"{where}: default {act.default} is outside the joint range [{lo}, {hi}]")
    missing = [j.name for j in desc.actuated_joints if j.name not in names]
    if missing:
        fail(f"actuated joints without an actuator entry: {', '.join(missing)}")
    if set(cfg.hands) != set(HAND_SIDES):
        fail(f"hands must be exactly {', '.join(HAND_SIDES)}, got {', '.join(cfg.hands) or 'none'}")
    for side, hand in cfg.hands.items():
        got = tuple(c.name for c in hand.channels)
        if got != INSPIRE_CHANNELS:
            fail(f"hands.{side}.channels must be {', '.join(INSPIRE_CHANNELS)} in that order, got {', '.join(got)}")
        for ch in hand.channels:
            if ch.joint not in names:
                fail(f"hands.{side}.{ch.name}: joint {ch.joint!r} is not an actuator")
            if ch.open_rad == ch.closed_rad:
                fail(f"hands.{side}.{ch.name}: open_rad equals closed_rad")
    known_links = {b.name for b in desc.bodies} | set(desc.site_names)
    unknown_links = [k for k in cfg.link_map if k not in known_links]
    if unknown_links:
        fail(f"link_map names no body or site of the model: {', '.join(unknown_links)}")
