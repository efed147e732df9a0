"""The ONNX policy contract: the policy file carries everything the runtime needs, nothing is copied elsewhere.

Graph
    one input  ``obs``     float32 [batch, obs_dim]
    one output ``actions`` float32 [batch, num_actions]
    Observation and action normalisation are baked into the graph: the runtime feeds raw observation terms and
    reads raw actions.

Metadata (``metadata_props``; every value is a JSON-encoded string; for the four plain-string keys a bare,
unquoted string is accepted too)
    robot_hoi.contract  "1"                    contract version this file follows
    robot_hoi.version   str                    robot-hoi version that wrote the file
    embodiment          str                    e.g. "g1_inspire"
    policy_kind         "teacher" | "student" | "untrained"
    actuator_names      [str] * A              A = 41 for g1_inspire: 29 body joints in Unitree motor order, then
                                               the left hand's 6 and the right hand's 6 channel joints
    default_pose        [float] * A            rad
    action_scale        [float] * A
    action_offset       [float] * A            joint target = offset + scale * clip(action, -action_clip, action_clip)
    action_clip         float > 0
    kp, kd              [float] * A            PD gains the policy was trained with (>= 0)
    joint_lower/upper   [float] * A            rad, lower < upper; default_pose lies inside
    effort_limit        [float] * A            N m (> 0)
    control_dt          float > 0              s, one policy step
    keyframes           [int >= 0]             reference look-ahead frames k (t + k) used by the ref_* terms
    obs_spec            [{"name", "size"}]     terms in input order; sizes sum to obs_dim (see OBS_TERMS)
    hands               {"left": [{"name", "joint", "open_rad", "closed_rad"}] * 6, "right": [...]}
                        Inspire register order; units = 1000 * (rad - closed_rad) / (open_rad - closed_rad).
                        The 12 hand joints are the last 12 actuators, left then right, in channel order.
    link_names          [str] * L              robot links/sites of the reference link positions, in order
    reference           {"file": "NAME.motion.npz", "sha256": hex} | null   sidecar next to the .onnx
    action_offset_mode  "fixed" | "reference"  optional, default "fixed". "reference": the target offset is the
                                               motion's joint_pos at the frame being stepped to, f(t + 1), instead
                                               of action_offset (the policy outputs corrections to the reference)
    warmup_frames       int >= 0               optional, default 0: the reference clock holds frame 0 for this many
                                               policy ticks (stand-and-approach warmup); f(t) = max(t - warmup, 0)
    warmup_blend        bool                   optional, default false. true ("reference" mode): during the warmup
                                               the target offset glides from default_pose (tick 0) to frame 0's
                                               joints, warmup_offset(); false: frame 0's joints from tick 0
    data                {"clips": [...], "license": str}   the clips the policy learnt; a clip with
                                               "motion": {"file", "sha256"} is a skill: that sidecar (next to the
                                               .onnx) is its reference, and `reference` names the default skill's
    tracker             ["robot"[, "object"]]  optional: the poses the policy reads from the pose tracker (mocap);
                                               [] = none, the runtime opens no tracker. Derived from obs_spec
                                               (tracked_poses); a file whose value disagrees is refused
    task                {"env": {...}} | null  optional, default null: the training task's environment config
                                               (robot_hoi's InteractionEnvCfg as a dict: object density, friction
                                               and collision shape, termination thresholds, success bounds), so a
                                               simulated validation rebuilds the world the policy learnt in. The
                                               runtime does not read it.

Observation terms (name: size with A actuators, B = A - 12 body joints, K keyframes, L links) are defined in
deploy.observations with their exact math; sizes are fixed here so a file can be checked without building them.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from deploy.embodiment import check_against_embodiment  # noqa: F401  (re-exported: callers import it from here)
from deploy.errors import ContractError
from deploy.hand_units import HAND_SIDES, INSPIRE_CHANNELS, HandChannel

CONTRACT_VERSION = "1"
POLICY_KINDS = ("teacher", "student", "untrained")
ACTION_OFFSET_MODES = ("fixed", "reference")
# The ONNX graph's one input and one output, defined here only: the export names them so, the runtime feeds them.
INPUT_NAME = "obs"
OUTPUT_NAME = "actions"
HAND_DOF = len(INSPIRE_CHANNELS)
NUM_HAND_ACTUATORS = HAND_DOF * len(HAND_SIDES)

PER_ACTUATOR_KEYS = (
    "default_pose",
    "action_scale",
    "action_offset",
    "kp",
    "kd",
    "joint_lower",
    "joint_upper",
    "effort_limit",
)
STRING_KEYS = ("robot_hoi.contract", "robot_hoi.version", "embodiment", "policy_kind")
REQUIRED_KEYS = (
    "robot_hoi.contract",
    "robot_hoi.version",
    "embodiment",
    "policy_kind",
    "actuator_names",
    *PER_ACTUATOR_KEYS,
    "action_clip",
    "control_dt",
    "keyframes",
    "obs_spec",
    "hands",
    "link_names",
    "reference",
    "data",
)


def warmup_offset(start, target, steps_done, warmup_frames):
    """The PD target offset `steps_done` steps into a warmup of `warmup_frames` steps under the warmup blend: a
    straight line from `start` (the pose the warmup began in; default_pose from the stand) at step 0 to `target`
    (frame 0's joints), reached at the warmup's end. Stepping the target to a bent-over frame 0 at once makes the
    robot lunge (on sub3_largebox_003 it knocks the box 5 cm and falls). numpy arrays or torch tensors (per-row
    `steps_done` / `warmup_frames` as (N, 1) columns)."""
    weight = steps_done / warmup_frames
    weight = weight.clamp(max=1.0) if hasattr(weight, "clamp") else min(weight, 1.0)
    return start + weight * (target - start)


@dataclass(frozen=True)
class _Dims:
    actuators: int
    body: int
    keyframes: int
    links: int


# term name -> size from the contract's dimensions. The single source of which terms exist.
OBS_TERMS: dict[str, Callable[[_Dims], int]] = {
    "projected_gravity": lambda d: 3,
    "base_ang_vel": lambda d: 3,
    "joint_pos": lambda d: d.actuators,
    "joint_vel": lambda d: d.body,
    "hand_force": lambda d: NUM_HAND_ACTUATORS,
    "last_action": lambda d: d.actuators,
    "object_pos": lambda d: 3,
    "object_rot": lambda d: 6,
    "ref_root_pos": lambda d: 3 * d.keyframes,
    "ref_root_rot": lambda d: 6 * d.keyframes,
    "ref_joint_pos": lambda d: d.actuators * d.keyframes,
    "ref_link_pos": lambda d: 3 * d.links * d.keyframes,
    "ref_object_pos": lambda d: 3 * d.keyframes,
    "ref_object_rot": lambda d: 6 * d.keyframes,
    "ref_root_local": lambda d: 9 * d.keyframes,
}
REFERENCE_TERMS = tuple(name for name in OBS_TERMS if name.startswith("ref_"))
OBJECT_TERMS = ("object_pos", "object_rot")
# Terms that read the tracked pelvis pose (its heading, or positions relative to it); the object terms read both.
# A policy without any of them needs no pose tracker (deploy.observations states each term's inputs).
PELVIS_TERMS = (*OBJECT_TERMS, "ref_root_pos", "ref_root_rot", "ref_link_pos", "ref_object_pos", "ref_object_rot")


def tracked_poses(term_names) -> tuple[str, ...]:
    """The poses a policy observing `term_names` needs from the pose tracker: (), ("robot",) or ("robot",
    "object")."""
    names = set(term_names)
    if not names & set(PELVIS_TERMS):
        return ()
    return ("robot", "object") if names & set(OBJECT_TERMS) else ("robot",)


@dataclass(frozen=True)
class ObsTermSpec:
    name: str
    size: int


@dataclass(frozen=True)
class ReferenceInfo:
    file: str
    sha256: str


@dataclass(frozen=True, eq=False)
class PolicyContract:
    source: str
    robot_hoi_version: str
    embodiment: str
    policy_kind: str
    actuator_names: tuple[str, ...]
    default_pose: np.ndarray
    action_scale: np.ndarray
    action_offset: np.ndarray
    action_clip: float
    kp: np.ndarray
    kd: np.ndarray
    joint_lower: np.ndarray
    joint_upper: np.ndarray
    effort_limit: np.ndarray
    control_dt: float
    keyframes: tuple[int, ...]
    obs_spec: tuple[ObsTermSpec, ...]
    hands: dict[str, tuple[HandChannel, ...]]
    link_names: tuple[str, ...]
    reference: ReferenceInfo | None
    data: dict = field(default_factory=dict)
    action_offset_mode: str = "fixed"
    warmup_frames: int = 0
    warmup_blend: bool = False
    task: dict | None = None
    skills: dict[str, ReferenceInfo] = field(default_factory=dict)  # clip name -> its sidecar (data.clips "motion")

    @property
    def num_actions(self) -> int:
        return len(self.actuator_names)

    @property
    def num_body(self) -> int:
        return self.num_actions - NUM_HAND_ACTUATORS

    @property
    def obs_dim(self) -> int:
        return sum(t.size for t in self.obs_spec)

    @property
    def obs_names(self) -> list[str]:
        return [t.name for t in self.obs_spec]

    @property
    def uses_reference(self) -> bool:
        return any(t.name in REFERENCE_TERMS for t in self.obs_spec)

    @property
    def uses_object(self) -> bool:
        """Whether the policy observes the tracked object (ref_object_* come from the motion, not the tracker)."""
        return any(t.name in OBJECT_TERMS for t in self.obs_spec)

    @property
    def tracked_poses(self) -> tuple[str, ...]:
        return tracked_poses(self.obs_names)

    @property
    def trained_rate_limit(self) -> float | None:
        """rad/s the policy's PD targets were limited to in training (its task's command_rate_limit), if any."""
        env = (self.task or {}).get("env", {})
        value = env.get("command_rate_limit")
        return None if value is None else float(value)

    @property
    def needs_tracker(self) -> bool:
        return bool(self.tracked_poses)

    def hand_slice(self, side: str) -> slice:
        """Actuator indices of one hand's 6 channel joints (left, then right, after the body)."""
        start = self.num_body + HAND_DOF * HAND_SIDES.index(side)
        return slice(start, start + HAND_DOF)

    @property
    def body_slice(self) -> slice:
        return slice(0, self.num_body)

    def reference_frame(self, tick: int, num_frames: int) -> int:
        """Reference frame of policy tick t: f(t) = min(max(t - warmup_frames, 0), T - 1)."""
        return min(max(int(tick) - self.warmup_frames, 0), num_frames - 1)

    def reference_offset(self, tick: int, motion_joint_pos: np.ndarray) -> np.ndarray:
        """The "reference" mode offset of policy tick t: joint_pos of frame f(t + 1), blended in from default_pose
        over the warmup when warmup_blend is set."""
        target = motion_joint_pos[self.reference_frame(tick + 1, len(motion_joint_pos))]
        if not self.warmup_blend or tick >= self.warmup_frames:
            return target
        return warmup_offset(self.default_pose, target, tick, self.warmup_frames)

    def action_to_target(self, action: np.ndarray, offset: np.ndarray | None = None) -> np.ndarray:
        """Joint targets (rad): offset + scale * clip(action, -action_clip, action_clip). `offset` is the
        reference joint_pos of frame f(t + 1) in "reference" mode (required there), else action_offset."""
        if self.action_offset_mode == "reference" and offset is None:
            raise ContractError(f"{self.source}: action_offset_mode 'reference' needs the reference joint offset")
        clipped = np.clip(np.asarray(action, dtype=np.float64), -self.action_clip, self.action_clip)
        base = self.action_offset if offset is None else np.asarray(offset, dtype=np.float64)
        return base + self.action_scale * clipped

    def reference_path(self) -> Path | None:
        if self.reference is None:
            return None
        return Path(self.source).parent / self.reference.file

    def skill_reference(self, name: str) -> tuple[Path, ReferenceInfo]:
        """The sidecar path and entry of skill `name` (a clip of data.clips with a motion)."""
        if name not in self.skills:
            known = ", ".join(self.skills) or "none (the policy has one reference)"
            raise ContractError(f"{self.source}: no skill {name!r}; its skills: {known}")
        info = self.skills[name]
        return Path(self.source).parent / info.file, info

    def to_metadata(self) -> dict[str, str]:
        """The metadata_props this contract is written as (values JSON-encoded)."""
        values = {
            "robot_hoi.contract": CONTRACT_VERSION,
            "robot_hoi.version": self.robot_hoi_version,
            "embodiment": self.embodiment,
            "policy_kind": self.policy_kind,
            "actuator_names": list(self.actuator_names),
            **{key: [float(v) for v in getattr(self, key)] for key in PER_ACTUATOR_KEYS},
            "action_clip": float(self.action_clip),
            "control_dt": float(self.control_dt),
            "keyframes": list(self.keyframes),
            "obs_spec": [{"name": t.name, "size": t.size} for t in self.obs_spec],
            "hands": {side: [c.to_dict() for c in self.hands[side]] for side in HAND_SIDES},
            "link_names": list(self.link_names),
            "reference": None if self.reference is None else vars(self.reference).copy(),
            "data": self.data,
            "action_offset_mode": self.action_offset_mode,
            "warmup_frames": int(self.warmup_frames),
            "warmup_blend": bool(self.warmup_blend),
            "tracker": list(self.tracked_poses),
        }
        if self.task is not None:
            values["task"] = self.task
        return {key: json.dumps(value) for key, value in values.items()}

    @classmethod
    def from_metadata(cls, metadata: dict[str, str], source: str = "<metadata>") -> PolicyContract:
        return _parse(metadata, source)

    @classmethod
    def from_onnx(cls, path: str | os.PathLike) -> PolicyContract:
        """Parse and validate a policy file's contract (graph inputs/outputs + metadata)."""
        from deploy.policy import open_session  # not at the top: a cycle (policy builds on this module)

        return cls.from_session(open_session(path), str(path))

    @classmethod
    def from_session(cls, session, source: str) -> PolicyContract:
        """Validate an onnxruntime session's graph signature and metadata against the contract."""
        obs_dim, num_actions = _check_signature(session, source)
        metadata = dict(session.get_modelmeta().custom_metadata_map)
        contract = _parse(metadata, source)
        if contract.obs_dim != obs_dim:
            raise ContractError(
                f"{source}: obs_spec sizes sum to {contract.obs_dim} but input '{INPUT_NAME}' has {obs_dim} columns"
            )
        if contract.num_actions != num_actions:
            raise ContractError(
                f"{source}: actuator_names has {contract.num_actions} entries but output '{OUTPUT_NAME}' has "
                f"{num_actions} columns"
            )
        return contract


def _check_signature(session, source: str) -> tuple[int, int]:
    inputs = session.get_inputs()
    outputs = session.get_outputs()
    if [i.name for i in inputs] != [INPUT_NAME]:
        raise ContractError(f"{source}: expected exactly one input named '{INPUT_NAME}', got {[i.name for i in inputs]}")
    by_name = {o.name: o for o in outputs}
    if OUTPUT_NAME not in by_name:
        raise ContractError(f"{source}: no output named '{OUTPUT_NAME}' (outputs: {list(by_name)})")
    if len(outputs) != 1:  # extra heads (value, std, ...) mean the wrong graph was exported
        raise ContractError(f"{source}: expected exactly one output '{OUTPUT_NAME}', got {list(by_name)}")
    dims = []
    for arg, kind in ((inputs[0], "input"), (by_name[OUTPUT_NAME], "output")):
        if arg.type != "tensor(float)":
            raise ContractError(f"{source}: {kind} '{arg.name}' must be float32, got {arg.type}")
        if len(arg.shape) != 2:
            raise ContractError(f"{source}: {kind} '{arg.name}' must have rank 2 [batch, n], got shape {arg.shape}")
        width = arg.shape[1]
        if not isinstance(width, int) or width <= 0:
            raise ContractError(f"{source}: {kind} '{arg.name}' needs a fixed second dimension, got {width!r}")
        dims.append(width)
    return dims[0], dims[1]


def _parse(metadata: dict[str, str], source: str) -> PolicyContract:
    def fail(key: str, problem: str) -> ContractError:
        return ContractError(f"{source}: metadata '{key}' {problem}")

    missing = [key for key in REQUIRED_KEYS if key not in metadata]
    if missing:
        raise ContractError(f"{source}: missing metadata key(s) {', '.join(repr(k) for k in missing)}")
    values = {}
    for key in REQUIRED_KEYS:
        try:
            values[key] = json.loads(metadata[key])
        except (TypeError, json.JSONDecodeError):
            if key in STRING_KEYS and isinstance(metadata[key], str):
                values[key] = metadata[key]  # a bare string is unambiguous for these keys; accept it
                continue
            raise fail(key, f"is not valid JSON: {metadata[key]!r:.80}") from None

    if str(values["robot_hoi.contract"]) != CONTRACT_VERSION:
        raise fail("robot_hoi.contract", f"is {values['robot_hoi.contract']!r}; this runtime reads version {CONTRACT_VERSION}")
    for key in ("robot_hoi.version", "embodiment"):
        if not isinstance(values[key], str) or not values[key]:
            raise fail(key, "must be a non-empty string")
    if values["policy_kind"] not in POLICY_KINDS:
        raise fail("policy_kind", f"must be one of {POLICY_KINDS}, got {values['policy_kind']!r}")

    names = values["actuator_names"]
    if not isinstance(names, list) or not names or not all(isinstance(n, str) and n for n in names):
        raise fail("actuator_names", "must be a non-empty list of strings")
    if len(set(names)) != len(names):
        raise fail("actuator_names", "has duplicate names")
    if len(names) <= NUM_HAND_ACTUATORS:
        raise fail("actuator_names", f"has {len(names)} entries; need body joints plus {NUM_HAND_ACTUATORS} hand joints")
    num = len(names)

    arrays = {}
    for key in PER_ACTUATOR_KEYS:
        arrays[key] = _float_list(values[key], num, key, fail)
    if np.any(arrays["joint_lower"] >= arrays["joint_upper"]):
        bad = names[int(np.argmax(arrays["joint_lower"] >= arrays["joint_upper"]))]
        raise fail("joint_lower", f"is not below joint_upper for '{bad}'")
    outside = (arrays["default_pose"] < arrays["joint_lower"]) | (arrays["default_pose"] > arrays["joint_upper"])
    if np.any(outside):
        raise fail("default_pose", f"lies outside the joint limits for '{names[int(np.argmax(outside))]}'")
    for key in ("kp", "kd"):
        if np.any(arrays[key] < 0):
            raise fail(key, f"is negative for '{names[int(np.argmax(arrays[key] < 0))]}'")
    if np.any(arrays["effort_limit"] <= 0):
        raise fail("effort_limit", f"must be > 0 (see '{names[int(np.argmax(arrays['effort_limit'] <= 0))]}')")

    action_clip = _positive_float(values["action_clip"], "action_clip", fail)
    control_dt = _positive_float(values["control_dt"], "control_dt", fail)

    keyframes = values["keyframes"]
    if not isinstance(keyframes, list) or not all(isinstance(k, int) and not isinstance(k, bool) for k in keyframes):
        raise fail("keyframes", "must be a list of integers")
    if any(k < 0 for k in keyframes) or len(set(keyframes)) != len(keyframes):
        raise fail("keyframes", f"must be distinct non-negative frame offsets, got {keyframes}")

    link_names = values["link_names"]
    if not isinstance(link_names, list) or not all(isinstance(n, str) and n for n in link_names):
        raise fail("link_names", "must be a list of strings")

    hands = _parse_hands(values["hands"], names, fail)
    dims = _Dims(actuators=num, body=num - NUM_HAND_ACTUATORS, keyframes=len(keyframes), links=len(link_names))
    obs_spec = _parse_obs_spec(values["obs_spec"], dims, fail)
    if any(t.name in REFERENCE_TERMS for t in obs_spec) and not keyframes:
        raise fail("keyframes", "is empty but obs_spec uses reference terms")
    if any(t.name == "ref_link_pos" for t in obs_spec) and not link_names:
        raise fail("link_names", "is empty but obs_spec uses ref_link_pos")

    reference = values["reference"]
    if reference is not None:
        reference = _reference_info(reference, lambda problem: fail("reference", problem))
    data = values["data"]
    if not isinstance(data, dict) or not isinstance(data.get("clips"), list) or not isinstance(data.get("license"), str):
        raise fail("data", "must be {'clips': [...], 'license': str}")
    skills = {}
    for i, clip in enumerate(data["clips"]):
        if isinstance(clip, dict) and clip.get("motion") is not None:
            if not isinstance(clip.get("name"), str) or not clip["name"]:
                raise fail("data", f"clip {i} has a motion but no name")
            skills[clip["name"]] = _reference_info(clip["motion"],
                                                   lambda problem, i=i: fail("data", f"clip {i} motion {problem}"))

    offset_mode = _optional_json(metadata, "action_offset_mode", "fixed", fail)
    if offset_mode not in ACTION_OFFSET_MODES:
        raise fail("action_offset_mode", f"must be one of {ACTION_OFFSET_MODES}, got {offset_mode!r}")
    if offset_mode == "reference" and reference is None:
        raise fail("action_offset_mode", "is 'reference' but the policy names no reference motion")
    warmup = _optional_json(metadata, "warmup_frames", 0, fail)
    if isinstance(warmup, bool) or not isinstance(warmup, int) or warmup < 0:
        raise fail("warmup_frames", f"must be an integer >= 0, got {warmup!r}")
    blend = _optional_json(metadata, "warmup_blend", False, fail)
    if not isinstance(blend, bool):
        raise fail("warmup_blend", f"must be true or false, got {blend!r}")
    tracker = _optional_json(metadata, "tracker", None, fail)
    needed = list(tracked_poses(t.name for t in obs_spec))
    if tracker is not None and tracker != needed:
        raise fail("tracker", f"says the policy reads {tracker} from the pose tracker, its obs_spec reads {needed}")
    task = _optional_json(metadata, "task", None, fail)
    if task is not None and not (isinstance(task, dict) and isinstance(task.get("env"), dict)):
        raise fail("task", "must be null or {'env': {...}} (the training task's environment config)")
    return PolicyContract(
        task=task,
        action_offset_mode=offset_mode,
        warmup_frames=warmup,
        warmup_blend=blend,
        source=source,
        robot_hoi_version=values["robot_hoi.version"],
        embodiment=values["embodiment"],
        policy_kind=values["policy_kind"],
        actuator_names=tuple(names),
        action_clip=action_clip,
        control_dt=control_dt,
        keyframes=tuple(keyframes),
        obs_spec=obs_spec,
        hands=hands,
        link_names=tuple(link_names),
        reference=reference,
        data=data,
        skills=skills,
        **arrays,
    )


def _reference_info(value, fail) -> ReferenceInfo:
    """A sidecar entry {"file": bare name next to the policy, "sha256": 64 hex}; `fail(problem)` makes the error."""
    if not isinstance(value, dict) or not isinstance(value.get("file"), str) or not value["file"]:
        raise fail("must be null or {'file': str, 'sha256': str}")
    if Path(value["file"]).name != value["file"]:
        raise fail(f"file must be a bare file name next to the policy, got {value['file']!r}")
    sha = value.get("sha256")
    if not isinstance(sha, str) or len(sha) != 64 or any(c not in "0123456789abcdef" for c in sha.lower()):
        raise fail("sha256 must be 64 hex characters")
    return ReferenceInfo(file=value["file"], sha256=sha.lower())


def _optional_json(metadata: dict[str, str], key: str, default, fail):
    if key not in metadata:
        return default
    try:
        return json.loads(metadata[key])
    except (TypeError, json.JSONDecodeError):
        raise fail(key, f"is not valid JSON: {metadata[key]!r:.80}") from None


def _float_list(value, length: int, key: str, fail) -> np.ndarray:
    if not isinstance(value, list) or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
        raise fail(key, "must be a list of numbers")
    if len(value) != length:
        raise fail(key, f"has {len(value)} entries, expected {length} (one per actuator)")
    array = np.asarray(value, dtype=np.float64)
    if not np.all(np.isfinite(array)):
        raise fail(key, f"has a non-finite value at index {int(np.argmax(~np.isfinite(array)))}")
    return array


def _positive_float(value, key: str, fail) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise fail(key, f"must be a number, got {value!r}")
    if not math.isfinite(value) or value <= 0:
        raise fail(key, f"must be finite and > 0, got {value!r}")
    return float(value)


def _parse_hands(value, names: list[str], fail) -> dict[str, tuple[HandChannel, ...]]:
    if not isinstance(value, dict) or set(value) != set(HAND_SIDES):
        raise fail("hands", f"must map exactly {list(HAND_SIDES)} to channel lists")
    hands = {}
    num_body = len(names) - NUM_HAND_ACTUATORS
    for s, side in enumerate(HAND_SIDES):
        channels_raw = value[side]
        if not isinstance(channels_raw, list) or len(channels_raw) != HAND_DOF:
            raise fail("hands", f"'{side}' must list {HAND_DOF} channels")
        channels = []
        for i, ch in enumerate(channels_raw):
            where = f"{side}[{i}]"
            if not isinstance(ch, dict) or not {"name", "joint", "open_rad", "closed_rad"} <= set(ch):
                raise fail("hands", f"{where} needs name, joint, open_rad, closed_rad")
            for key in ("open_rad", "closed_rad"):
                v = ch[key]
                if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                    raise fail("hands", f"{where}.{key} must be a finite number")
            if ch["open_rad"] == ch["closed_rad"]:
                raise fail("hands", f"{where} has open_rad == closed_rad")
            if ch["name"] != INSPIRE_CHANNELS[i]:
                raise fail("hands", f"{where} is '{ch['name']}', expected '{INSPIRE_CHANNELS[i]}' (Inspire register order)")
            expected_joint = names[num_body + s * HAND_DOF + i]
            if ch["joint"] != expected_joint:
                raise fail(
                    "hands",
                    f"{where} joint '{ch['joint']}' must be actuator {num_body + s * HAND_DOF + i} ('{expected_joint}')",
                )
            channels.append(HandChannel(ch["name"], ch["joint"], float(ch["open_rad"]), float(ch["closed_rad"])))
        hands[side] = tuple(channels)
    return hands


def _parse_obs_spec(value, dims: _Dims, fail) -> tuple[ObsTermSpec, ...]:
    if not isinstance(value, list) or not value:
        raise fail("obs_spec", "must be a non-empty list of {'name', 'size'}")
    spec = []
    for i, term in enumerate(value):
        if not isinstance(term, dict) or not isinstance(term.get("name"), str) or "size" not in term:
            raise fail("obs_spec", f"entry {i} must be {{'name': str, 'size': int}}")
        name, size = term["name"], term["size"]
        if name not in OBS_TERMS and name.startswith("teacher."):
            raise fail("obs_spec", f"entry {i} is the privileged simulation term '{name}': a teacher policy cannot "
                                   "run on the robot (deploy a distilled student)")
        if name not in OBS_TERMS:
            raise fail("obs_spec", f"entry {i} names unknown observation term '{name}' (known: {', '.join(OBS_TERMS)})")
        if not isinstance(size, int) or isinstance(size, bool):
            raise fail("obs_spec", f"term '{name}' size must be an integer")
        expected = OBS_TERMS[name](dims)
        if size != expected:
            raise fail("obs_spec", f"term '{name}' has size {size}, expected {expected} for this contract")
        spec.append(ObsTermSpec(name, size))
    names = [t.name for t in spec]
    if len(set(names)) != len(names):
        raise fail("obs_spec", "lists a term twice")
    return tuple(spec)
