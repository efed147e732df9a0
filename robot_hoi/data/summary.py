"""What `robot-hoi data inspect` reports about a clip: a JSON-ready dict and its one-screen text form."""

from __future__ import annotations

import numpy as np

from robot_hoi.data.clip import HOIClip
from robot_hoi.data.contacts import ContactParams
from robot_hoi.data.objects import to_world
from robot_hoi.data.segments import mask_segments

LIFT_THRESHOLD_M = ContactParams().ground_tolerance_m  # lowest object point above this: off the floor


def _segments(mask: np.ndarray, fps: float) -> list[dict]:
    return [
        {"start_frame": a, "end_frame": b, "start_s": round(a / fps, 3), "end_s": round((b + 1) / fps, 3)}
        for a, b in mask_segments(mask)
    ]


def object_heights(clip: HOIClip) -> np.ndarray:
    """(T,) height (m) of the object's lowest point; without a mesh, its origin's rise above frame 0."""
    if clip.object is not None:
        return to_world(clip.object.hull_vertices(), clip.object_pos, clip.object_quat_xyzw)[..., 2].min(
            axis=1
        )
    return clip.object_pos[:, 2] - clip.object_pos[0, 2]


def lift_summary(clip: HOIClip) -> dict:
    low = object_heights(clip)
    peak = int(np.argmax(low))
    lifted = low > LIFT_THRESHOLD_M
    return {
        "measured": "lowest mesh point" if clip.object is not None else "object origin rise (no mesh)",
        "max_height_m": round(float(low[peak]), 3),
        "peak_time_s": round(peak / clip.fps, 3),
        "lifted": bool(lifted.any()),
        "lifted_segments": _segments(lifted, clip.fps),
        "object_travel_m": round(float(np.linalg.norm(clip.object_pos[-1, :2] - clip.object_pos[0, :2])), 3),
    }


def clip_summary(clip: HOIClip, path: str | None = None) -> dict:
    stored = clip.contact.astype(bool)
    obj = clip.object
    return {
        "file": path,
        "name": clip.name,
        "fps": clip.fps,
        "frames": clip.num_frames,
        "duration_s": round(clip.duration, 3),
        "subject": clip.subject,
        "subject_height_m": clip.subject_height_m,
        "height_source": clip.height_source,
        "object": {
            "name": clip.object_name,
            "loaded": obj is not None,
            "mesh_file": obj.mesh_file if obj is not None else None,
            "origin": obj.origin if obj is not None else None,
            "extents_m": [round(float(v), 3) for v in obj.extents] if obj is not None else None,
            "sample_points": int(len(obj.sample_points)) if obj is not None else 0,
            "mass_kg": obj.mass_kg if obj is not None else None,
        },
        "contact": {
            "stored_frames": int(stored.sum()),
            "inferred_frames": int(clip.inferred_contact.sum()),
            # None when nothing was inferred: matching "no contact" frames alone would read as agreement
            "agreement": round(float(np.mean(stored == clip.inferred_contact)), 3)
            if clip.inferred_contact.any() else None,
            "stored_segments": _segments(stored, clip.fps),
            "inferred_segments": _segments(clip.inferred_contact, clip.fps),
        },
        "lift": lift_summary(clip),
        "problems": list(clip.problems),
        "source": clip.source,
        "license": clip.license,
    }


def _fmt_segments(segments: list[dict]) -> str:
    if not segments:
        return "none"
    return ", ".join(
        f"{s['start_s']:.2f}-{s['end_s']:.2f} s (frames {s['start_frame']}-{s['end_frame']})"
        for s in segments
    )


def _agreement(contact: dict, obj: dict) -> str:
    if contact["agreement"] is not None:
        return f"agree on {100 * contact['agreement']:.0f} % of frames"
    return "no object, nothing inferred" if not obj["loaded"] else "no contact inferred, nothing to compare"


def format_summary(report: dict) -> str:
    obj, contact, lift = report["object"], report["contact"], report["lift"]
    height = "unknown" if report["subject_height_m"] is None else f"{report['subject_height_m']:.3f} m"
    extents = "x".join(f"{v:.2f}" for v in obj["extents_m"]) + " m" if obj["extents_m"] else "mesh not loaded"
    lines = [
        f"clip      {report['name']}" + (f"  ({report['file']})" if report["file"] else ""),
        f"frames    {report['frames']} at {report['fps']:g} fps = {report['duration_s']:.2f} s",
        f"subject   {report['subject'] or 'unknown'}, height {height} ({report['height_source']})",
        f"object    {obj['name'] or 'unknown'}: {extents}, {obj['sample_points']} sample points",
        f"          from {obj['origin'] or 'nothing (no object)'}",
        f"contact   stored:   {_fmt_segments(contact['stored_segments'])}",
        f"          inferred: {_fmt_segments(contact['inferred_segments'])}  ({_agreement(contact, obj)})",
        f"lift      max {lift['max_height_m']:.2f} m at {lift['peak_time_s']:.2f} s ({lift['measured']}); "
        f"off the floor: {_fmt_segments(lift['lifted_segments'])}; moved {lift['object_travel_m']:.2f} m",
        f"license   {report['license']}",
    ]
    problems = report["problems"]
    lines.append("problems  " + ("none" if not problems else problems[0]))
    lines += [f"          {p}" for p in problems[1:]]
    return "\n".join(lines)
