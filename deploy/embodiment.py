"""Read an embodiment's control config (configs/embodiments/<name>.yaml) with pyyaml.

The runtime only needs the control-level facts: actuator order, gains, default pose, action scale, control_dt,
the Inspire hand mapping, the link map, and the `deploy` section training ignores: joint and effort limits, the
largest action_clip and the hands' FORCE_SET/SPEED_SET, which the runtime enforces whatever a policy file says.
The YAML is the same file training reads; deploy parses it itself because it must not import robot_hoi.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import yaml

from deploy.errors import ContractError, DeployError
from deploy.hand_units import HAND_SIDES, INSPIRE_CHANNELS, HandChannel
from deploy.hands.tables import REGISTERS

if TYPE_CHECKING:
    from deploy.contract import PolicyContract

# The `mode_machine` each embodiment's robot reports in LowState (Unitree's G1 description table: 4 = 23-DoF,
# 5 = 29-DoF rev 1.0 with or without Inspire hands, 6 = 29-DoF waist locked). Kept here, not in the YAML, because
# training reads the same YAML and refuses keys it does not know.
MODE_MACHINE = {"g1_inspire": 5}
MODE_MACHINE_NAMES = {4: "G1 23-DoF rev 1.0", 5: "G1 29-DoF rev 1.0", 6: "G1 29-DoF waist locked rev 1.0"}

# The shipped YAMLs: inside the package in an installed wheel (either distribution's setup.py maps them in as
# deploy/embodiments), else the checkout's configs/embodiments. DEPLOY_CONFIG_DIR is searched first.
_PACKAGE = Path(__file__).resolve().parent
_SHIPPED_CONFIGS = (_PACKAGE / "embodiments" if (_PACKAGE / "embodiments").is_dir()
                    else _PACKAGE.parent / "configs" / "embodiments")


@dataclass(frozen=True)
class ActuatorConfig:
    name: str
    kp: float
    kd: float
    default: float
    action_scale: float


@dataclass(frozen=True)
class DeployLimits:
    """The YAML's `deploy` section: what the runtime enforces whatever a policy file says."""

    joints: dict[str, tuple[float, float, float]]  # actuator -> (lower rad, upper rad, effort N m)
    action_clip: float
    hand_force_set: int  # FORCE_SET, g at the fingertip
    hand_speed_set: int  # SPEED_SET, 0..1000


@dataclass(frozen=True)
class EmbodimentConfig:
    name: str
    path: Path
    control_dt: float
    actuators: tuple[ActuatorConfig, ...]
    hands: dict[str, tuple[HandChannel, ...]]
    link_map: dict[str, str] = field(default_factory=dict)
    limits: DeployLimits | None = None  # None: the YAML has no deploy section (check_against_embodiment refuses)

    @property
    def actuator_names(self) -> list[str]:
        return [a.name for a in self.actuators]

    @property
    def mode_machine(self) -> int | None:
        """The mode_machine the robot must report (None: this embodiment has no known value; not checked)."""
        return MODE_MACHINE.get(self.name)


def embodiment_search_dirs() -> list[Path]:
    dirs = []
    if os.environ.get("DEPLOY_CONFIG_DIR"):
        dirs.append(Path(os.environ["DEPLOY_CONFIG_DIR"]))
    dirs.append(_SHIPPED_CONFIGS)
    return dirs


def resolve_embodiment_path(name_or_path: str | os.PathLike) -> Path:
    """An existing YAML path as given, else `<name>.yaml` in DEPLOY_CONFIG_DIR or the shipped configs."""
    candidate = Path(name_or_path)
    if candidate.suffix in (".yaml", ".yml") or candidate.exists():
        if not candidate.is_file():
            raise DeployError(f"{candidate}: embodiment config not found")
        return candidate
    for folder in embodiment_search_dirs():
        path = folder / f"{name_or_path}.yaml"
        if path.is_file():
            return path
    searched = ", ".join(str(d) for d in embodiment_search_dirs())
    raise DeployError(f"embodiment '{name_or_path}': no {name_or_path}.yaml in {searched} (set DEPLOY_CONFIG_DIR)")


def _number(path: Path, where: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise DeployError(f"{path}: {where} must be a finite number, got {value!r}")
    return float(value)


def load_embodiment(name_or_path: str | os.PathLike) -> EmbodimentConfig:
    path = resolve_embodiment_path(name_or_path)
    try:
        raw = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise DeployError(f"{path}: not valid YAML ({exc})") from None
    if not isinstance(raw, dict):
        raise DeployError(f"{path}: expected a mapping at the top level")
    for key in ("name", "control_dt", "actuators", "hands"):
        if key not in raw:
            raise DeployError(f"{path}: missing key '{key}'")
    control_dt = _number(path, "control_dt", raw["control_dt"])
    if control_dt <= 0:
        raise DeployError(f"{path}: control_dt must be > 0, got {control_dt}")

    if not isinstance(raw["actuators"], list) or not raw["actuators"]:
        raise DeployError(f"{path}: 'actuators' must be a non-empty list")
    actuators = []
    for i, entry in enumerate(raw["actuators"]):
        if not isinstance(entry, dict) or "name" not in entry:
            raise DeployError(f"{path}: actuators[{i}] must be a mapping with a 'name'")
        values = {}
        for key in ("kp", "kd", "default", "action_scale"):
            if key not in entry:
                raise DeployError(f"{path}: actuators[{i}] ({entry['name']}) is missing '{key}'")
            values[key] = _number(path, f"actuators[{i}].{key}", entry[key])
        actuators.append(ActuatorConfig(name=str(entry["name"]), **values))
    names = [a.name for a in actuators]
    if len(set(names)) != len(names):
        raise DeployError(f"{path}: actuator names are not unique")

    hands_raw = raw["hands"]
    if not isinstance(hands_raw, dict):
        raise DeployError(f"{path}: 'hands' must be a mapping with 'left' and 'right'")
    hands = {}
    for side in HAND_SIDES:
        channels_raw = (hands_raw.get(side) or {}).get("channels") if isinstance(hands_raw.get(side), dict) else None
        if not isinstance(channels_raw, list) or len(channels_raw) != len(INSPIRE_CHANNELS):
            raise DeployError(f"{path}: hands.{side}.channels must list {len(INSPIRE_CHANNELS)} Inspire channels")
        channels = []
        for i, ch in enumerate(channels_raw):
            where = f"hands.{side}.channels[{i}]"
            if not isinstance(ch, dict) or not {"name", "joint", "open_rad", "closed_rad"} <= set(ch):
                raise DeployError(f"{path}: {where} needs name, joint, open_rad, closed_rad")
            channel = HandChannel(
                name=str(ch["name"]),
                joint=str(ch["joint"]),
                open_rad=_number(path, f"{where}.open_rad", ch["open_rad"]),
                closed_rad=_number(path, f"{where}.closed_rad", ch["closed_rad"]),
            )
            if channel.joint not in names:
                raise DeployError(f"{path}: {where} joint '{channel.joint}' is not an actuator")
            if channel.open_rad == channel.closed_rad:
                raise DeployError(f"{path}: {where} open_rad equals closed_rad")
            channels.append(channel)
        hands[side] = tuple(channels)
    link_map = raw.get("link_map") or {}
    if not isinstance(link_map, dict):
        raise DeployError(f"{path}: 'link_map' must be a mapping")
    return EmbodimentConfig(
        name=str(raw["name"]),
        path=path,
        control_dt=control_dt,
        actuators=tuple(actuators),
        hands=hands,
        link_map={str(k): str(v) for k, v in link_map.items()},
        limits=None if raw.get("deploy") is None else _deploy_limits(path, raw["deploy"], names),
    )


def _deploy_limits(path: Path, raw, names: list[str]) -> DeployLimits:
    if not isinstance(raw, dict) or not isinstance(raw.get("joint_limits"), dict):
        raise DeployError(f"{path}: 'deploy' must be a mapping with 'joint_limits' (actuator: [lower, upper, effort])")
    joints = {}
    for name, entry in raw["joint_limits"].items():
        where = f"deploy.joint_limits.{name}"
        if name not in names:
            raise DeployError(f"{path}: {where} is not an actuator")
        if not isinstance(entry, list) or len(entry) != 3:
            raise DeployError(f"{path}: {where} must be [lower rad, upper rad, effort N m]")
        lower, upper, effort = (_number(path, where, v) for v in entry)
        if not lower < upper or effort <= 0:
            raise DeployError(f"{path}: {where} needs lower < upper and effort > 0, got {entry}")
        joints[name] = (lower, upper, effort)
    action_clip = _number(path, "deploy.action_clip", raw.get("action_clip"))
    if action_clip <= 0:
        raise DeployError(f"{path}: deploy.action_clip must be > 0, got {action_clip}")
    hand = {}
    for key, register in (("hand_force_set", "FORCE_SET"), ("hand_speed_set", "SPEED_SET")):
        value, reg = raw.get(key), REGISTERS[register]
        if isinstance(value, bool) or not isinstance(value, int) or not reg.low <= value <= reg.high:
            raise DeployError(f"{path}: deploy.{key} must be an integer in {reg.low}..{reg.high} ({register}), "
                              f"got {value!r}")
        hand[key] = value
    return DeployLimits(joints=joints, action_clip=action_clip, **hand)


# How far the policy's gains and default pose may sit from the embodiment YAML (JSON and float32 round trips
# stay far inside these; a retuned gain or a shifted default pose does not).
GAIN_RTOL = 1e-3
GAIN_ATOL = 1e-6
DEFAULT_POSE_ATOL_RAD = 1e-3


LIMIT_ATOL = 1e-6  # a file's limit may pass the config's by float noise, no more
MAX_PROBLEMS_SHOWN = 8


def check_against_embodiment(contract: PolicyContract, embodiment_yaml_path: str | os.PathLike) -> None:
    """Refuse a policy trained for another robot layout: actuator names/order, control_dt, hand mapping, and
    (when the order matches) each actuator's kp, kd and default pose within GAIN_RTOL/GAIN_ATOL and
    DEFAULT_POSE_ATOL_RAD. The deploy side owns the limits: a file whose joint or effort limits are wider than
    the YAML's `deploy` section, whose action_clip is larger, or whose action_scale or (fixed) action_offset
    differ from the actuators, is refused too. Passing, every limit the runtime takes from the file lies within
    the deploy side's."""
    emb = load_embodiment(embodiment_yaml_path)
    problems = []
    if contract.embodiment != emb.name:
        problems.append(f"embodiment is '{contract.embodiment}' but the config is '{emb.name}'")
    if list(contract.actuator_names) != emb.actuator_names:
        if len(contract.actuator_names) != len(emb.actuator_names):
            problems.append(f"{len(contract.actuator_names)} actuators vs {len(emb.actuator_names)} in the config")
        else:
            i = next(i for i, (a, b) in enumerate(zip(contract.actuator_names, emb.actuator_names, strict=True)) if a != b)
            problems.append(f"actuator {i} is '{contract.actuator_names[i]}' but the config has '{emb.actuator_names[i]}'")
    else:
        problems.extend(_actuator_mismatches(contract, emb))
        problems.extend(_limit_mismatches(contract, emb))
    if not math.isclose(contract.control_dt, emb.control_dt, rel_tol=1e-6, abs_tol=1e-9):
        problems.append(f"control_dt {contract.control_dt} s vs {emb.control_dt} s in the config")
    for side in HAND_SIDES:
        for ours, theirs in zip(contract.hands[side], emb.hands[side], strict=True):
            if ours.name != theirs.name or ours.joint != theirs.joint:
                problems.append(f"hand {side} channel '{ours.name}'/{ours.joint} vs '{theirs.name}'/{theirs.joint}")
            elif not (math.isclose(ours.open_rad, theirs.open_rad, abs_tol=1e-9)
                      and math.isclose(ours.closed_rad, theirs.closed_rad, abs_tol=1e-9)):
                problems.append(
                    f"hand {side} '{ours.name}' maps open/closed {ours.open_rad}/{ours.closed_rad} rad vs "
                    f"{theirs.open_rad}/{theirs.closed_rad} in the config"
                )
    if problems:
        shown = problems[:MAX_PROBLEMS_SHOWN]
        more = f"; and {len(problems) - len(shown)} more" if len(problems) > len(shown) else ""
        raise ContractError(f"{contract.source} does not match {emb.path}: " + "; ".join(shown) + more)


def _actuator_mismatches(contract: PolicyContract, emb: EmbodimentConfig) -> list[str]:
    """'left_knee_joint kp 120 vs 150 in the config' for every gain or default pose beyond its tolerance."""
    problems = []
    for i, act in enumerate(emb.actuators):
        for key, ours, theirs in (("kp", contract.kp[i], act.kp), ("kd", contract.kd[i], act.kd)):
            if not math.isclose(ours, theirs, rel_tol=GAIN_RTOL, abs_tol=GAIN_ATOL):
                problems.append(f"{act.name} {key} {ours:g} vs {theirs:g} in the config")
        if abs(contract.default_pose[i] - act.default) > DEFAULT_POSE_ATOL_RAD:
            problems.append(f"{act.name} default pose {contract.default_pose[i]:.4f} vs {act.default:.4f} rad "
                            "in the config")
    return problems


def _limit_mismatches(contract: PolicyContract, emb: EmbodimentConfig) -> list[str]:
    """'effort_limit left_knee_joint 1e+06 N m is above the config's 139 (and 40 more joints)': per field, the
    first joint the file widens and how many more."""
    limits = emb.limits
    if limits is None:
        return ["the config has no 'deploy' section (joint limits, effort limits, action_clip): the runtime takes "
                "no limits from a policy file alone"]
    found: dict[str, list[str]] = {}
    for i, act in enumerate(emb.actuators):
        name = act.name
        if name not in limits.joints:
            found.setdefault("missing", []).append(f"no deploy.joint_limits entry for {name} in the config")
            continue
        lower, upper, effort = limits.joints[name]
        checks = (
            ("joint_lower", contract.joint_lower[i] < lower - LIMIT_ATOL,
             f"{contract.joint_lower[i]:.6g} rad is below the config's {lower:.6g}"),
            ("joint_upper", contract.joint_upper[i] > upper + LIMIT_ATOL,
             f"{contract.joint_upper[i]:.6g} rad is above the config's {upper:.6g}"),
            ("effort_limit", contract.effort_limit[i] > effort + LIMIT_ATOL,
             f"{contract.effort_limit[i]:g} N m is above the config's {effort:g}"),
            ("action_scale", not math.isclose(contract.action_scale[i], act.action_scale, rel_tol=GAIN_RTOL,
                                              abs_tol=GAIN_ATOL),
             f"{contract.action_scale[i]:g} vs {act.action_scale:g} in the config"),
            ("action_offset", abs(contract.action_offset[i] - act.default) > DEFAULT_POSE_ATOL_RAD,
             f"{contract.action_offset[i]:.4f} rad vs {act.default:.4f} (default pose) in the config"),
        )
        for key, wrong, text in checks:
            if wrong:
                found.setdefault(key, []).append(f"{key} {name} {text}")
    problems = [items[0] + (f" (and {len(items) - 1} more joints)" if len(items) > 1 else "")
                for items in found.values()]
    if contract.action_clip > limits.action_clip + LIMIT_ATOL:
        problems.append(f"action_clip {contract.action_clip:g} is above the config's {limits.action_clip:g}")
    return problems
