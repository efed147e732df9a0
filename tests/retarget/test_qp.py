"""The QP retarget (retarget/qp.py): hard limits, no penetration, stance feet fixed, speed-limited continuity."""

from dataclasses import replace

import mujoco
import numpy as np
import pytest

from robot_hoi.data.synth import embedded_clip
from robot_hoi.embodiment import build_model, load_embodiment
from robot_hoi.retarget.kinematics import joint_ids
from robot_hoi.retarget.object_contact import HullPlanes
from robot_hoi.retarget.pipeline import RetargetOptions, retarget_clip
from robot_hoi.retarget.qp import interaction_mesh


@pytest.fixture(scope="module")
def robot():
    cfg = load_embodiment("g1_inspire")
    return cfg, build_model(cfg)


def qp_retarget(robot, clip):
    cfg, model = robot
    options = RetargetOptions()
    options = replace(options, ik=replace(options.ik, solver="qp"),
                      mapping=replace(options.mapping, object_collision="decomposed"))
    return retarget_clip(clip, cfg, model, options=options)


@pytest.fixture(scope="module")
def grip(robot):
    """lift_place from the reach to the lift: the hands close on the box and carry it up."""
    return qp_retarget(robot, embedded_clip("lift_place").select_frames(np.arange(40, 100)))


@pytest.fixture(scope="module")
def walk(robot):
    return qp_retarget(robot, embedded_clip("walk:0").select_frames(np.arange(0, 75)))


def body_joint_qadr(robot):
    cfg, model = robot
    fingers = {c.joint for hand in cfg.hands.values() for c in hand.channels}
    return model.jnt_qposadr[joint_ids(model, [n for n in cfg.actuator_names if n not in fingers])]


def test_joint_limits_are_never_crossed(robot, grip):
    model = robot[1]
    limited = np.flatnonzero(model.jnt_limited & (model.jnt_type == mujoco.mjtJoint.mjJNT_HINGE))
    q = grip.motion.qpos[:, model.jnt_qposadr[limited]]
    assert (q >= model.jnt_range[limited, 0] - 1e-9).all() and (q <= model.jnt_range[limited, 1] + 1e-9).all()


def test_no_penetration_of_the_object_or_the_floor_beyond_1mm(grip, walk):
    for result in (grip, walk):
        assert result.ik.object_penetration.max() <= 0.001
        assert result.ik.sole_min_z.min() >= -0.001
        assert result.ik.hand_floor_depth.max() <= 0.001
    assert grip.motion.meta["qp_fallbacks"] == 0


def test_the_track_is_continuous_at_the_speed_limit(robot, grip, walk):
    """No joint moves faster than max_joint_speed, and no smoothing pass was needed for it."""
    limit = RetargetOptions().qp.max_joint_speed / 30.0
    for result in (grip, walk):
        steps = np.abs(np.diff(result.motion.qpos[:, body_joint_qadr(robot)], axis=0))
        assert steps.max() <= limit + 1e-6
        root_steps = np.linalg.norm(np.diff(result.motion.qpos[:, :3], axis=0), axis=1)
        assert root_steps.max() < 0.05  # m per frame: no jumps of the floating base either


def test_stance_feet_stay_where_they_landed(robot, walk):
    """Over each planted stretch of the walk, each foot moves at most ~1 mm (the QP's foot tolerance)."""
    from robot_hoi.retarget.pipeline import _stance

    model = robot[1]
    data = mujoco.MjData(model)
    stance = _stance(_solver_of(robot), walk.targets, [n for n in walk.targets.link_names if "ankle" in n or "toe" in n],
                     RetargetOptions().mapping)
    assert any(down.sum() > 10 for down in stance.values())
    for body, down in stance.items():
        pos = np.empty((len(down), 3))
        for t, q in enumerate(walk.motion.qpos):
            data.qpos[:] = q
            mujoco.mj_kinematics(model, data)
            pos[t] = data.xpos[body]
        flags = np.concatenate([[False], down, [False]])
        starts, ends = np.flatnonzero(~flags[:-1] & flags[1:]), np.flatnonzero(flags[:-1] & ~flags[1:])
        for a, b in zip(starts, ends, strict=True):
            if b - a > 1:
                assert np.abs(pos[a:b] - pos[a]).max() <= 0.0015


def _solver_of(robot):
    """An IKSolver with the pipeline's foot links (only its point bodies are read)."""
    from robot_hoi.retarget.ik import IKSolver

    cfg, model = robot
    return IKSolver(model, list(cfg.link_map))


def _every_plane(planes, points, within=None):
    """HullPlanes.signed_distance by its definition: every point against every plane of every piece, no broad
    phase (`within` ignored)."""
    values = np.asarray(points) @ planes.normals.T + planes.offsets
    bounds = (*planes.piece_starts, len(planes.normals))
    dist = np.stack([values[..., a:b].max(-1) for a, b in zip(bounds[:-1], bounds[1:], strict=True)], -1)
    face = np.stack([values[..., a:b].argmax(-1) + a for a, b in zip(bounds[:-1], bounds[1:], strict=True)], -1)
    piece = dist.argmin(-1)[..., None]
    return np.take_along_axis(dist, piece, -1)[..., 0], np.take_along_axis(face, piece, -1)[..., 0]


def test_the_fast_distances_give_the_track_of_the_exhaustive_ones(robot, grip, monkeypatch):
    """The broad phase and the vectorised distances change no row of any QP: the same joint track."""
    monkeypatch.setattr(HullPlanes, "signed_distance", _every_plane)
    slow = qp_retarget(robot, embedded_clip("lift_place").select_frames(np.arange(40, 100)))
    np.testing.assert_allclose(grip.motion.qpos, slow.motion.qpos, rtol=0, atol=1e-9)


def test_the_fast_distances_on_an_object_of_several_pieces(robot, shared, monkeypatch):
    """As above on a box CoACD cuts in two (OMOMO's largebox), the reach and the grip; the constraints hold."""
    from robot_hoi.data.clip import load_clip

    path = shared / "reference" / "motions" / "clips" / "sub8_largebox_000.pt"
    if not path.is_file():
        pytest.skip(f"{path} is absent")
    clip = load_clip(path).select_frames(np.arange(0, 50))
    fast = qp_retarget(robot, clip)
    assert len(fast.targets.object_hull.piece_starts) > 1
    assert fast.ik.object_penetration.max() <= 0.001 and fast.ik.sole_min_z.min() >= -0.001
    monkeypatch.setattr(HullPlanes, "signed_distance", _every_plane)
    slow = qp_retarget(robot, clip)
    np.testing.assert_allclose(fast.motion.qpos, slow.motion.qpos, rtol=0, atol=1e-9)


def test_the_interaction_mesh_laplacian():
    """Each keypoint row is the keypoint minus the mean of its Delaunay neighbours; rows sum to 0 over keypoints
    only where every neighbour is a keypoint (translation of the keypoints alone is free there)."""
    rng = np.random.default_rng(0)
    keypoints, obj = rng.normal(size=(6, 3)), rng.normal(size=(10, 3)) + 3.0
    mesh = interaction_mesh(keypoints, obj)
    assert mesh.shape[1] == 6 and mesh.shape[0] >= 6
    assert np.allclose(np.diag(mesh[:6]), 1.0)
    assert (mesh[:6][~np.eye(6, dtype=bool)] <= 0).all()
    assert interaction_mesh(keypoints[:3], None).shape == (0, 3)  # no tetrahedra from three points
