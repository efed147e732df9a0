"""How good is a retarget: residuals per link group, floor penetration, joint-limit contacts, hand anchoring.

Numbers are plain floats in a JSON-ready dict (lengths in cm), so the CLI can print them or dump them.
"""

from __future__ import annotations

import numpy as np

from robot_hoi.retarget.targets import GROUPS, hand_side, link_group, to_object_frame, wxyz_to_xyzw


def _cm(x) -> float:
    return round(float(x) * 100.0, 2)


def residual_by_group(residual: np.ndarray, human_names) -> dict[str, dict[str, float]]:
    """{group: {"mean_cm", "max_cm"}} over all frames and the group's links."""
    groups = np.array([link_group(h) for h in human_names])
    out = {}
    for g in GROUPS:
        cols = groups == g
        if cols.any():
            r = residual[:, cols]
            out[g] = {"mean_cm": _cm(r.mean()), "max_cm": _cm(r.max())}
    return out


def anchored_residual(residual: np.ndarray, anchor: np.ndarray, human_names, threshold: float = 0.5) -> dict:
    """Wrist and fingertip residuals only where those links are anchored to the object (a > threshold): free
    fingertips are barely weighted (the Inspire hand is longer than a scaled human hand), held ones matter."""
    out = {}
    for g in ("wrists", "fingers"):
        cols = np.array([link_group(h) == g for h in human_names])
        held = residual[:, cols][anchor[:, cols] > threshold]
        if held.size:
            out[g] = {"mean_cm": _cm(held.mean()), "max_cm": _cm(held.max())}
    return out


def hand_surface_distance(dist: np.ndarray, human_names, side: str) -> np.ndarray:
    """(T,) closest approach of one hand (wrist or any fingertip) to the object surface."""
    cols = [i for i, h in enumerate(human_names) if hand_side(h) == side]
    return dist[:, cols].min(axis=1) if cols else np.full(dist.shape[0], np.nan)


def object_lifted(object_pos: np.ndarray, threshold: float = 0.05) -> np.ndarray:
    """(T,) bool: the object is more than `threshold` m above its first-frame height (it is being carried)."""
    return object_pos[:, 2] - object_pos[0, 2] > threshold


def build_report(result, floor_height: float = 0.0) -> dict:
    """Summary of a pipeline.RetargetResult."""
    motion, targets, ik = result.motion, result.targets, result.ik
    names = motion.human_names
    robot_dist = targets.robot_surface_distance(motion.link_pos)
    penetration = np.maximum(floor_height - ik.sole_min_z, 0.0)
    penetration = np.where(np.isfinite(penetration), penetration, 0.0)
    hits_per_joint = ik.at_limit.sum(axis=0)
    lifted = object_lifted(targets.object_pos)
    anchor = {}
    for side, hold in result.hold.items():
        robot_hand = hand_surface_distance(robot_dist, names, side)
        human_hand = hand_surface_distance(targets.human_surface_dist, names, side)
        entry = {"frames_anchored_frac": round(float(hold.mean()), 3)}
        if hold.any():
            entry["robot_surface_dist_cm_mean"] = _cm(robot_hand[hold].mean())
            entry["human_surface_dist_cm_mean"] = _cm(human_hand[hold].mean())
        if lifted.any():
            entry["robot_surface_dist_cm_max_while_lifted"] = _cm(robot_hand[lifted].max())
            entry["human_surface_dist_cm_max_while_lifted"] = _cm(human_hand[lifted].max())
        anchor[side] = entry
    return {
        "frames": motion.num_frames,
        "fps": motion.fps,
        "scale": round(motion.scale, 4),
        "ik_seconds": round(result.seconds, 3),
        "position_error": residual_by_group(motion.residual, names),
        "position_error_anchored": anchored_residual(motion.residual, motion.anchor, names),
        "feet": {
            "max_penetration_cm": _cm(penetration.max()),
            "frames_penetrating_over_5mm": int((penetration > 0.005).sum()),
        },
        "hands_below_floor": {
            "max_cm": _cm(ik.hand_floor_depth.max()),
            "frames_over_5mm": int((ik.hand_floor_depth > 0.005).sum()),
        },
        "joint_limits": {
            "frame_joint_hits": int(hits_per_joint.sum()),
            "joints": {n: int(c) for n, c in zip(ik.limited_joint_names, hits_per_joint, strict=True) if c},
        },
        "anchor": {"object_lifted_frac": round(float(lifted.mean()), 3), **anchor},
        "hands_in_object": _hands_in_object(result),
    }


def _hands_in_object(result) -> dict:
    """How deep the robot's hand geometry and the human's hand joints sit inside the object's convex hull."""
    targets, ik = result.targets, result.ik
    if targets.object_hull is None:
        return {}
    names = targets.human_names
    cols = [i for i, h in enumerate(names) if hand_side(h) is not None]
    local = to_object_frame(targets.human_pos[:, cols], targets.human_object_pos,
                            wxyz_to_xyzw(targets.object_quat_wxyz))
    human_depth = np.maximum(-targets.object_hull.signed_distance(local, within=0.0)[0].min(axis=1), 0.0)
    return {
        "robot_max_cm": _cm(ik.object_penetration.max()),
        "robot_frames_over_1cm": int((ik.object_penetration > 0.01).sum()),
        "human_max_cm": _cm(human_depth.max()),
        "human_frames_over_1cm": int((human_depth > 0.01).sum()),
    }


def format_report(report: dict) -> str:
    """Human-readable lines for the terminal."""
    lines = [f"{report['frames']} frames at {report['fps']:g} fps, scale {report['scale']}, "
             f"IK {report['ik_seconds']} s"]
    lines.append("position error (cm)   mean    max")
    for group, r in report["position_error"].items():
        lines.append(f"  {group:<18}{r['mean_cm']:7.2f}{r['max_cm']:7.2f}")
    for group, r in report.get("position_error_anchored", {}).items():
        lines.append(f"  {group + ' (anchored)':<18}{r['mean_cm']:7.2f}{r['max_cm']:7.2f}")
    feet = report["feet"]
    lines.append(f"feet: max penetration {feet['max_penetration_cm']} cm, "
                 f"{feet['frames_penetrating_over_5mm']} frames deeper than 5 mm")
    hands = report["hands_below_floor"]
    lines.append(f"hands: max {hands['max_cm']} cm below the floor, {hands['frames_over_5mm']} frames deeper than 5 mm")
    lim = report["joint_limits"]
    joints = ", ".join(f"{k} ({v})" for k, v in lim["joints"].items()) or "none"
    lines.append(f"joint limits: {lim['frame_joint_hits']} frame-joint contacts; {joints}")
    inside = report.get("hands_in_object")
    if inside:
        lines.append(f"inside the object's hull: robot arms and hands max {inside['robot_max_cm']} cm "
                     f"({inside['robot_frames_over_1cm']} frames > 1 cm); human hand joints max "
                     f"{inside['human_max_cm']} cm ({inside['human_frames_over_1cm']} frames > 1 cm)")
    anchor = report["anchor"]
    lines.append(f"object lifted in {anchor['object_lifted_frac'] * 100:.0f}% of frames")
    for side in ("left", "right"):
        if side not in anchor:
            continue
        a = anchor[side]
        text = f"  {side} hand anchored {a['frames_anchored_frac'] * 100:.0f}% of frames"
        if "robot_surface_dist_cm_mean" in a:
            text += (f"; hand-surface distance while anchored: robot {a['robot_surface_dist_cm_mean']} cm, "
                     f"human {a['human_surface_dist_cm_mean']} cm")
        lines.append(text)
    return "\n".join(lines)
