"""Read an embodiment's control config (configs/embodiments/<name>.yaml) with pyyaml.

The runtime only needs the control-level facts: actuator order, gains, default pose, action scale, control_dt,
the Inspire hand mapping and the link map. The YAML is the same file training reads; deploy parses it itself
because it must not import robot_hoi.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from deploy.errors import DeployError
from deploy.hand_units import HAND_SIDES, INSPIRE_CHANNELS, HandChannel

# Next to the repository's configs when run from a checkout; DEPLOY_CONFIG_DIR overrides (robot without a checkout).
_REPO_CONFIGS = Path(__file__).resolve().parents[1] / "configs" / "embodiments"


@dataclass(frozen=True)
class ActuatorConfig:
    name: str
    kp: float
    kd: float
    default: float
    action_scale: float


@dataclass(frozen=True)
class EmbodimentConfig:
    name: str
    path: Path
    control_dt: float
    actuators: tuple[ActuatorConfig, ...]
    hands: dict[str, tuple[HandChannel, ...]]
    link_map: dict[str, str] = field(default_factory=dict)

    @property
    def actuator_names(self) -> list[str]:
        return [a.name for a in self.actuators]


def embodiment_search_dirs() -> list[Path]:
    dirs = []
    if os.environ.get("DEPLOY_CONFIG_DIR"):
        dirs.append(Path(os.environ["DEPLOY_CONFIG_DIR"]))
    dirs.append(_REPO_CONFIGS)
    return dirs


def resolve_embodiment_path(name_or_path: str | os.PathLike) -> Path:
    """An existing YAML path as given, else `<name>.yaml` in DEPLOY_CONFIG_DIR or the repository's configs."""
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
    )
