"""A small, valid contract policy + synthetic reference motion for tests and development (no torch).

    python -m deploy.devpolicy -o policies/dev.onnx [--embodiment g1_inspire] [--keyframes 1 16]

writes `policies/dev.onnx` and its sidecar `policies/dev.motion.npz`. The graph is one linear layer,
`actions = obs @ W + b`. With `--mode follow` (default) W reads the first keyframe of `ref_joint_pos` and scales it
by 1/action_scale, so joint targets = the reference joint positions: a dry run visibly tracks the motion. With
`--mode random` W is small seeded noise (an "untrained" policy). Metadata comes from the embodiment YAML, joint
and effort limits and action_clip from its `deploy` section (or, with --urdf, the joint limits from a URDF; the
runtime refuses what is wider than the YAML's). The motion is synthetic (stand, sway, reach, close the hands, a box that
rises in front of the robot); its link positions are rough offsets, not forward kinematics.
This module needs the `onnx` package (a development dependency), unlike the rest of deploy.
"""

from __future__ import annotations

import argparse
import os
import sys
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from deploy import __version__
from deploy.atomic import atomic_write_bytes
from deploy.contract import (
    INPUT_NAME,
    NUM_HAND_ACTUATORS,
    OBS_TERMS,
    OUTPUT_NAME,
    ObsTermSpec,
    PolicyContract,
    ReferenceInfo,
    _Dims,
)
from deploy.embodiment import EmbodimentConfig, load_embodiment
from deploy.errors import DeployError
from deploy.hand_units import HAND_SIDES, channel_arrays, units_to_rad
from deploy.motion import ReferenceMotion, file_sha256
from deploy.rotations import quat_wxyz_from_axis_angle, yaw_matrix

HAND_EFFORT = 1.0  # N m, the Inspire URDF's placeholder; the hands are position-servoed by their own firmware

# Rough standing offsets from the pelvis (m) for synthetic link positions; other links sit at the pelvis.
_LINK_OFFSETS = {
    "left_hip_yaw_link": (0.0, 0.09, -0.2), "right_hip_yaw_link": (0.0, -0.09, -0.2),
    "left_knee_link": (0.02, 0.1, -0.4), "right_knee_link": (0.02, -0.1, -0.4),
    "left_ankle_roll_link": (0.0, 0.11, -0.73), "right_ankle_roll_link": (0.0, -0.11, -0.73),
    "left_toe": (0.12, 0.11, -0.77), "right_toe": (0.12, -0.11, -0.77),
    "torso_link": (0.0, 0.0, 0.05), "head": (0.0, 0.0, 0.45),
    "left_shoulder_yaw_link": (0.0, 0.18, 0.25), "right_shoulder_yaw_link": (0.0, -0.18, 0.25),
    "left_elbow_link": (0.05, 0.2, 0.05), "right_elbow_link": (0.05, -0.2, 0.05),
    "left_wrist_yaw_link": (0.25, 0.2, 0.0), "right_wrist_yaw_link": (0.25, -0.2, 0.0),
}
DEFAULT_KEYFRAMES = (1, 16)


def read_urdf_limits(path: str | os.PathLike) -> dict[str, tuple[float, float, float]]:
    """joint name -> (lower, upper, effort) from a URDF's <limit> tags (stdlib XML, no URDF library)."""
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        raise DeployError(f"{path}: cannot read URDF ({exc})") from None
    limits = {}
    for joint in root.iter("joint"):
        limit = joint.find("limit")
        if limit is not None and "lower" in limit.attrib and "upper" in limit.attrib:
            limits[joint.attrib["name"]] = (
                float(limit.attrib["lower"]),
                float(limit.attrib["upper"]),
                float(limit.attrib.get("effort", HAND_EFFORT)),
            )
    return limits


def joint_limits(emb: EmbodimentConfig, urdf: str | os.PathLike | None = None) -> tuple[np.ndarray, ...]:
    """(lower, upper, effort) per actuator: the YAML's deploy limits, or with a URDF its limits for the body and
    the span of the open/closed mapping for the hand joints."""
    hand_span = {}
    if urdf:
        table = read_urdf_limits(urdf)
        for side in HAND_SIDES:
            for ch in emb.hands[side]:
                hand_span[ch.joint] = (min(ch.open_rad, ch.closed_rad), max(ch.open_rad, ch.closed_rad), HAND_EFFORT)
    elif emb.limits is not None:
        table = emb.limits.joints
    else:
        raise DeployError(f"{emb.path}: no 'deploy' section with joint limits (or pass --urdf)")
    rows = []
    for name in emb.actuator_names:
        if name in hand_span:
            rows.append(hand_span[name])
        elif name in table:
            rows.append(table[name])
        else:
            source = urdf or f"{emb.path} deploy.joint_limits"
            raise DeployError(f"{emb.path}: actuator '{name}' has no joint limits in {source}")
    lower, upper, effort = (np.array(col, dtype=np.float64) for col in zip(*rows, strict=True))
    return lower, upper, effort


def make_contract(
    emb: EmbodimentConfig,
    *,
    source: str = "<devpolicy>",
    keyframes: Sequence[int] = DEFAULT_KEYFRAMES,
    obs_terms: Sequence[str] | None = None,
    reference: ReferenceInfo | None = None,
    urdf: str | os.PathLike | None = None,
    action_clip: float | None = None,
    policy_kind: str = "untrained",
) -> PolicyContract:
    """A contract whose metadata comes from the embodiment YAML (+ joint limits); action_clip defaults to the
    YAML's deploy.action_clip (4 without one)."""
    lower, upper, effort = joint_limits(emb, urdf)
    if action_clip is None:
        action_clip = emb.limits.action_clip if emb.limits is not None else 4.0
    link_names = tuple(emb.link_map)
    dims = _Dims(len(emb.actuators), len(emb.actuators) - NUM_HAND_ACTUATORS, len(keyframes), len(link_names))
    names = list(obs_terms) if obs_terms is not None else list(OBS_TERMS)
    unknown = [n for n in names if n not in OBS_TERMS]
    if unknown:
        raise DeployError(f"unknown observation term(s) {unknown}; known: {', '.join(OBS_TERMS)}")
    default = np.array([a.default for a in emb.actuators])
    return PolicyContract(
        source=source,
        robot_hoi_version=__version__,
        embodiment=emb.name,
        policy_kind=policy_kind,
        actuator_names=tuple(emb.actuator_names),
        default_pose=default,
        action_scale=np.array([a.action_scale for a in emb.actuators]),
        action_offset=default.copy(),
        action_clip=float(action_clip),
        kp=np.array([a.kp for a in emb.actuators]),
        kd=np.array([a.kd for a in emb.actuators]),
        joint_lower=lower,
        joint_upper=upper,
        effort_limit=effort,
        control_dt=emb.control_dt,
        keyframes=tuple(int(k) for k in keyframes),
        obs_spec=tuple(ObsTermSpec(n, OBS_TERMS[n](dims)) for n in names),
        hands=dict(emb.hands),
        link_names=link_names,
        reference=reference,
        data={"clips": ["synthetic:deploy.devpolicy"], "license": "CC0-1.0 (synthetic development motion)"},
    )


def make_motion(contract: PolicyContract, duration_s: float = 4.0) -> ReferenceMotion:
    """Synthetic reference: sway, arm reach, hands close then hold, a box lifted in front of the pelvis."""
    fps = 1.0 / contract.control_dt
    num = max(2, int(round(duration_s * fps)))
    t = np.arange(num) / fps
    phase = np.clip(t / max(t[-1], 1e-9), 0.0, 1.0)
    names = list(contract.actuator_names)
    q = np.tile(contract.default_pose, (num, 1))

    def add(joint: str, values: np.ndarray) -> None:
        if joint in names:
            q[:, names.index(joint)] += values

    for side, sign in (("left", 1.0), ("right", -1.0)):
        add(f"{side}_shoulder_pitch_joint", -0.5 * np.sin(np.pi * phase))
        add(f"{side}_elbow_joint", -0.4 * np.sin(np.pi * phase))
        add(f"{side}_shoulder_roll_joint", sign * 0.1 * np.sin(2 * np.pi * phase))
    add("waist_yaw_joint", 0.15 * np.sin(2 * np.pi * phase))
    grasp = np.clip((phase - 0.2) / 0.3, 0.0, 1.0)[:, None]  # default pose -> 30 % open, then hold
    for side in HAND_SIDES:
        open_rad, closed_rad = channel_arrays(contract.hands[side])
        hand = contract.hand_slice(side)
        grasped = units_to_rad(np.full(len(open_rad), 300.0), open_rad, closed_rad)
        q[:, hand] = contract.default_pose[hand] + grasp * (grasped - contract.default_pose[hand])
    q = np.clip(q, contract.joint_lower, contract.joint_upper)

    yaw = 0.2 * np.sin(2 * np.pi * phase)
    root_pos = np.stack([0.3 * phase, np.zeros(num), np.full(num, 0.793)], axis=1)
    root_quat = quat_wxyz_from_axis_angle(np.array([0.0, 0.0, 1.0]), yaw)
    heading = yaw_matrix(yaw)
    offsets = np.array([_LINK_OFFSETS.get(name, (0.0, 0.0, 0.0)) for name in contract.link_names]).reshape(-1, 3)
    link_pos = root_pos[:, None, :] + np.einsum("tij,lj->tli", heading, offsets)
    lift = 0.25 * np.clip((phase - 0.5) / 0.3, 0.0, 1.0)
    object_pos = root_pos + heading @ np.array([0.45, 0.0, 0.0]) + np.stack([0 * t, 0 * t, lift - 0.05], axis=1)
    return ReferenceMotion(
        fps=fps,
        joint_pos=q,
        root_pos=root_pos,
        root_quat_wxyz=root_quat,
        link_pos=link_pos,
        object_pos=object_pos,
        object_quat_wxyz=root_quat.copy(),
        source="<devpolicy>",
    )


def follow_weights(contract: PolicyContract) -> tuple[np.ndarray, np.ndarray]:
    """W, b so that target = reference joint position of the first keyframe (zeros without ref_joint_pos)."""
    weights = np.zeros((contract.obs_dim, contract.num_actions), dtype=np.float32)
    bias = np.zeros(contract.num_actions, dtype=np.float32)
    start = 0
    for term in contract.obs_spec:
        if term.name == "ref_joint_pos":
            rows = np.arange(start, start + contract.num_actions)
            # obs = ref_q - default; target = offset + scale * a  =>  a = (obs + default - offset) / scale
            weights[rows, np.arange(contract.num_actions)] = 1.0 / contract.action_scale
            bias[:] = (contract.default_pose - contract.action_offset) / contract.action_scale
        start += term.size
    return weights, bias


def onnx_bytes(
    metadata: dict[str, str],
    weights: np.ndarray,
    bias: np.ndarray,
    *,
    input_name: str = INPUT_NAME,
    output_name: str = OUTPUT_NAME,
) -> bytes:
    """A linear ONNX graph `output = input @ W + b` with the given metadata_props (onnx.helper only)."""
    from onnx import TensorProto, helper, numpy_helper

    obs_dim, num_actions = weights.shape
    graph = helper.make_graph(
        [
            helper.make_node("MatMul", [input_name, "W"], ["hidden"]),
            helper.make_node("Add", ["hidden", "b"], [output_name]),
        ],
        "robot_hoi_dev_policy",
        [helper.make_tensor_value_info(input_name, TensorProto.FLOAT, ["batch", obs_dim])],
        [helper.make_tensor_value_info(output_name, TensorProto.FLOAT, ["batch", num_actions])],
        initializer=[
            numpy_helper.from_array(weights.astype(np.float32), "W"),
            numpy_helper.from_array(bias.astype(np.float32), "b"),
        ],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], producer_name="deploy.devpolicy")
    model.ir_version = 8  # readable by older onnxruntime builds on the robot
    helper.set_model_props(model, metadata)
    return model.SerializeToString()


def build_dev_policy(
    out: str | os.PathLike,
    *,
    embodiment: str | os.PathLike = "g1_inspire",
    keyframes: Sequence[int] = DEFAULT_KEYFRAMES,
    obs_terms: Sequence[str] | None = None,
    mode: str = "follow",
    seed: int = 0,
    duration_s: float = 4.0,
    with_reference: bool = True,
    urdf: str | os.PathLike | None = None,
) -> Path:
    """Write OUT.onnx (+ OUT.motion.npz when with_reference); returns the .onnx path."""
    out = Path(out)
    emb = load_embodiment(embodiment)
    contract = make_contract(emb, source=str(out), keyframes=keyframes, obs_terms=obs_terms, urdf=urdf)
    reference = None
    if with_reference:
        motion_path = out.with_name(out.name.removesuffix(".onnx") + ".motion.npz")
        make_motion(contract, duration_s).save(motion_path)
        reference = ReferenceInfo(file=motion_path.name, sha256=file_sha256(motion_path))
        contract = make_contract(
            emb, source=str(out), keyframes=keyframes, obs_terms=obs_terms, urdf=urdf, reference=reference
        )
    if mode == "follow":
        weights, bias = follow_weights(contract)
    elif mode == "random":
        rng = np.random.default_rng(seed)
        weights = (0.01 * rng.standard_normal((contract.obs_dim, contract.num_actions))).astype(np.float32)
        bias = np.zeros(contract.num_actions, dtype=np.float32)
    else:
        raise DeployError(f"devpolicy mode must be 'follow' or 'random', got {mode!r}")
    atomic_write_bytes(out, onnx_bytes(contract.to_metadata(), weights, bias))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m deploy.devpolicy", description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", required=True, help="output .onnx path (sidecar NAME.motion.npz next to it)")
    parser.add_argument("--embodiment", default="g1_inspire", help="embodiment name or YAML path")
    parser.add_argument("--keyframes", type=int, nargs="+", default=list(DEFAULT_KEYFRAMES))
    parser.add_argument("--obs", nargs="+", default=None, metavar="TERM", help="observation terms (default: all)")
    parser.add_argument("--mode", choices=("follow", "random"), default="follow")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--duration", type=float, default=4.0, help="synthetic motion length, s")
    parser.add_argument("--no-reference", action="store_true", help="write no motion sidecar (reference: null)")
    parser.add_argument("--urdf", default=None, help="read joint limits from this URDF instead of the embodiment YAML")
    args = parser.parse_args(argv)
    try:
        path = build_dev_policy(
            args.output,
            embodiment=args.embodiment,
            keyframes=args.keyframes,
            obs_terms=args.obs,
            mode=args.mode,
            seed=args.seed,
            duration_s=args.duration,
            with_reference=not args.no_reference,
            urdf=args.urdf,
        )
    except DeployError as exc:
        print(f"devpolicy: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
