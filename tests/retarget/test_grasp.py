"""Grasp planning (retarget/grasp.py, faces.py, hand_geometry.py) on a box, a table and a chair."""

from dataclasses import replace

import numpy as np
import pytest
import trimesh

from robot_hoi.data.objects import box_asset
from robot_hoi.data.synth import embedded_clip
from robot_hoi.embodiment import build_model, load_embodiment
from robot_hoi.retarget.faces import Face, object_faces
from robot_hoi.retarget.grasp import (
    Episode,
    GraspSettings,
    blend_weight,
    episode_grips,
    grip_episodes,
    squeeze_weight,
)
from robot_hoi.retarget.hand_geometry import hand_geometry
from robot_hoi.retarget.object_contact import HullPlanes
from robot_hoi.retarget.pipeline import RetargetOptions, clip_grasps, retarget_clip, robot_hand_lengths
from robot_hoi.retarget.targets import targets_from_clip

UP = np.array([0.0, 0.0, 1.0])
SINK_MM = 4.0  # the planned hand may touch the object this deep at most (its pads are placed 3 mm off)


@pytest.fixture(scope="module")
def robot():
    cfg = load_embodiment("g1_inspire")
    model = build_model(cfg)
    names, humans = list(cfg.link_map), list(cfg.link_map.values())
    return cfg, model, {side: hand_geometry(model, cfg, side, names, humans) for side in ("left", "right")}


def box(center, size) -> np.ndarray:
    return trimesh.creation.box(extents=size).vertices + np.asarray(center, dtype=float)


def hand_links(geometry, palm: np.ndarray, fingers: np.ndarray, palm_normal: np.ndarray) -> np.ndarray:
    """A human hand's link positions (wrist first), as the targets would place it: the open robot hand with its
    palm centre at `palm`, fingers along `fingers`, palm toward `palm_normal`."""
    from robot_hoi.retarget.hand_geometry import hand_rotation

    handed = np.sign(np.cross(geometry.palm_normal, geometry.thumb) @ geometry.axis)
    rotation = hand_rotation(geometry, palm_normal, handed * np.cross(fingers, palm_normal))
    links = geometry.link_local[0] @ rotation.T
    return links + palm - rotation @ geometry.palm_centre


def episode(geometries, hands: dict, up=UP, lifted=False, motion=(0.0, 0.0, 0.0), frames=10) -> Episode:
    arms = {side: hands[side][0] + np.array([-0.3, 0.1 if side == "left" else -0.1, 0.3]) for side in hands}
    return Episode(0, frames - 1, {side: np.ones(frames, dtype=bool) for side in hands}, hands, arms,
                   np.asarray(up, dtype=float), lifted, np.asarray(motion, dtype=float))


def check_grip_touches(geometries, grip, planes):
    geometry = geometries[grip.side]
    assert geometry.sink(grip.rotation, grip.wrist, planes, grip.closure) < SINK_MM / 1000
    nearest = (planes.signed_distance(geometry.at(grip.closure)[1] @ grip.rotation.T + grip.wrist)[0]
               - geometry.probe_radius).min()
    assert nearest < 0.01  # and it touches the object (within 1 cm)


def test_box_sides_are_found_and_a_cut_box_is_merged_back():
    one = object_faces([box((0, 0, 0), (0.4, 0.3, 0.3))])
    assert len(one) == 6
    halves = object_faces([box((-0.1, 0, 0), (0.2, 0.3, 0.3)), box((0.1, 0, 0), (0.2, 0.3, 0.3))])
    assert len(halves) == 6  # the cut between the halves is not a side; the halves' sides join
    front = next(f for f in halves if f.normal @ [0, 1, 0] > 0.99)
    assert np.ptp(front.corners[:, 0]) == pytest.approx(0.4, abs=1e-6)


def test_face_clamp_keeps_a_point_inside_the_margin():
    face = object_faces([box((0, 0, 0), (0.4, 0.3, 0.3))])[0]
    inside = face.clamp(face.centre + 5.0 * face.basis()[0], 0.02)
    assert abs(face.normal @ inside + face.offset) < 1e-9
    assert np.abs((inside - face.centre) @ face.basis().T).max() <= 0.2 - 0.02 + 1e-9


def test_box_lift_grips_opposite_faces_over_the_centre_of_mass(robot):
    _, _, geometries = robot
    pieces = [box((0, 0, 0.2), (0.4, 0.4, 0.4))]
    faces, planes, com = object_faces(pieces), HullPlanes.from_pieces(pieces), np.array([0.0, 0.0, 0.2])
    # the human's hands on adjacent faces: left on the back, right on the right side, both high
    hands = {"left": hand_links(geometries["left"], np.array([-0.2, 0.1, 0.32]), np.array([0.0, 0.0, -1.0]),
                                np.array([1.0, 0.0, 0.0])),
             "right": hand_links(geometries["right"], np.array([0.05, -0.2, 0.3]), np.array([0.0, 0.0, -1.0]),
                                 np.array([0.0, 1.0, 0.0]))}
    settings = GraspSettings()
    grips = {g.side: g for g in episode_grips(episode(geometries, hands, lifted=True), faces, planes, com,
                                              geometries, settings)}
    assert set(grips) == {"left", "right"} and {g.kind for g in grips.values()} == {"claw"}
    left, right = grips["left"], grips["right"]
    assert left.face.normal @ right.face.normal < -0.99  # opposite faces
    axis = left.face.normal
    middle = 0.5 * (left.point + right.point) - com
    across = middle - (middle @ axis) * axis - (middle @ UP) * UP
    assert np.linalg.norm(across) <= settings.beside_m + 1e-6  # the grasp axis passes over the centre of mass
    assert middle @ UP >= settings.hang_m - 1e-6  # the object hangs below the grasp axis
    for grip in grips.values():
        palm = grip.rotation @ geometries[grip.side].palm_normal
        assert palm @ grip.face.normal < -0.99  # palm into its face
        assert np.allclose(grip.into, -grip.face.normal)
        check_grip_touches(geometries, grip, planes)
        check_every_finger_reaches_for_the_face(geometries[grip.side], grip, planes, settings)


def test_a_low_grip_moves_up_so_the_object_hangs_below_the_grasp_axis(robot):
    """Hands below the centre of mass would balance the box on the grasp axis: the axis moves up to hang_m above
    it, and beside it by at most beside_m."""
    _, _, geometries = robot
    pieces = [box((0, 0, 0.2), (0.4, 0.4, 0.4))]
    faces, planes, com = object_faces(pieces), HullPlanes.from_pieces(pieces), np.array([0.0, 0.0, 0.2])
    hands = {side: hand_links(geometries[side], np.array([0.08, y, 0.1]), np.array([0.0, 0.0, -1.0]),
                              np.array([0.0, -np.sign(y), 0.0])) for side, y in (("left", 0.2), ("right", -0.2))}
    settings = GraspSettings()
    grips = episode_grips(episode(geometries, hands, lifted=True), faces, planes, com, geometries, settings)
    assert {g.kind for g in grips} == {"claw"} and len(grips) == 2
    middle = 0.5 * (grips[0].point + grips[1].point) - com
    assert middle @ UP == pytest.approx(settings.hang_m, abs=1e-6)
    assert np.linalg.norm(middle - (middle @ UP) * UP - (middle @ grips[0].face.normal) * grips[0].face.normal) \
        <= settings.beside_m + 1e-6


def check_every_finger_reaches_for_the_face(geometry, grip, planes, settings):
    """The longest finger's pad lies the claw's gap off the face and every other finger closes on its own until
    its pad is as near the face as it gets (one closure for all left only the middle finger's pad near it: the
    pads then sit on one line and the object pivots about it)."""
    fingers = np.unique(geometry.probe_channel[geometry.probe_channel >= 0])
    assert len(fingers) == 4

    def gaps(closure):
        world = geometry.at(closure)[1] @ grip.rotation.T + grip.wrist
        gap = planes.signed_distance(world)[0] - geometry.probe_radius
        return np.array([gap[geometry.probe_channel == k].min() for k in fingers])

    own, shared = gaps(grip.closure), gaps(settings.closure)
    assert own.min() == pytest.approx(settings.palm_gap_m, abs=1e-3)
    assert (own <= shared + 1e-6).all()
    assert (own < shared - 2e-4).sum() >= 2  # the shorter fingers moved nearer
    for k, channel in enumerate(fingers):  # and none could get nearer at another closure up to max_closure
        for c in np.linspace(settings.closure, settings.max_closure, 13):
            closure = grip.closure.copy()
            closure[channel] = c
            assert gaps(closure)[k] >= own[k] - 1e-3


def test_table_drag_hooks_the_fingers_under_the_near_edge(robot, table_object):
    _, _, geometries = robot
    pieces = table_object.collision_pieces("decomposed")
    faces, planes = object_faces(pieces), HullPlanes.from_pieces(pieces)
    com = np.array([0.0, 0.0, 0.3])
    # the human at -y pulls the table toward itself, both hands on the top's near edge
    hands = {side: hand_links(geometries[side], np.array([x, -0.31, 0.47]), np.array([0.0, 0.6, -0.8]),
                              np.array([0.0, 0.0, -1.0])) for side, x in (("left", -0.12), ("right", 0.12))}
    grips = episode_grips(episode(geometries, hands, motion=(0.0, -1.0, 0.0)), faces, planes, com, geometries,
                          GraspSettings())
    assert {g.side for g in grips} == {"left", "right"} and {g.kind for g in grips} == {"hook"}
    for grip in grips:
        geometry = geometries[grip.side]
        assert grip.face.normal @ [0.0, -1.0, 0.0] > 0.99  # the top's near edge
        assert (grip.rotation @ geometry.axis) @ UP < -0.99  # fingers pointing down past it
        tips = geometry.at(grip.closure)[1][geometry.finger] @ grip.rotation.T + grip.wrist
        under = (tips[:, 2] < 0.40) & (tips[:, 1] > -0.30)
        assert under.any()  # curled under the top
        assert grip.into @ [0.0, -1.0, 0.0] > 0.5 and grip.into @ UP > 0.5  # pulls toward the human and lifts
        check_grip_touches(geometries, grip, planes)


def test_push_puts_the_palms_on_the_top_with_the_wrists_at_the_rear_edge(robot):
    _, _, geometries = robot
    pieces = [box((0, 0, 0.15), (0.4, 0.4, 0.3))]
    faces, planes, com = object_faces(pieces), HullPlanes.from_pieces(pieces), np.array([0.0, 0.0, 0.15])
    hands = {side: hand_links(geometries[side], np.array([-0.12, y, 0.33]), np.array([1.0, 0.0, 0.0]),
                              np.array([0.0, 0.0, -1.0])) for side, y in (("left", 0.1), ("right", -0.1))}
    grips = episode_grips(episode(geometries, hands, motion=(1.0, 0.0, 0.0)), faces, planes, com, geometries,
                          GraspSettings())
    assert {g.kind for g in grips} == {"push"} and len(grips) == 2
    for grip in grips:
        geometry = geometries[grip.side]
        assert grip.face.normal @ UP > 0.99
        assert (grip.rotation @ geometry.palm_normal) @ UP < -0.99  # palm down on the top
        assert (grip.rotation @ geometry.axis) @ [1.0, 0.0, 0.0] > 0.99  # fingers ahead
        assert grip.wrist[0] < -0.2  # the wrist behind the rear edge
        assert grip.into[0] > 0.9  # pushes ahead
        check_grip_touches(geometries, grip, planes)
    lateral = sorted(g.point[1] for g in grips)
    assert lateral[1] - lateral[0] >= 0.12 and abs(sum(lateral)) < 1e-6  # either side of the centre of mass


def test_chair_lift_grips_the_seat_edges(robot):
    _, _, geometries = robot
    seat = box((0, 0, 0.45), (0.44, 0.44, 0.05))
    legs = [box((x, y, 0.21), (0.04, 0.04, 0.42)) for x in (-0.2, 0.2) for y in (-0.2, 0.2)]
    back = box((0.2, 0, 0.7), (0.04, 0.44, 0.46))
    pieces = [seat, *legs, back]
    faces, planes = object_faces(pieces), HullPlanes.from_pieces(pieces)
    com = np.array([0.03, 0.0, 0.4])
    hands = {side: hand_links(geometries[side], np.array([-0.05, y, 0.5]), np.array([0.3, 0.0, -1.0]),
                              np.array([0.0, -np.sign(y), 0.0])) for side, y in (("left", 0.24), ("right", -0.24))}
    grips = {g.side: g for g in episode_grips(episode(geometries, hands, lifted=True), faces, planes, com,
                                              geometries, GraspSettings())}
    assert set(grips) == {"left", "right"}
    assert grips["left"].face.normal @ [0.0, 1.0, 0.0] > 0.99 and grips["right"].face.normal @ [0, -1.0, 0] > 0.99
    for grip in grips.values():
        check_grip_touches(geometries, grip, planes)


def test_one_hand_lift_keeps_the_human_placement(robot):
    _, _, geometries = robot
    pieces = [box((0, 0, 0.2), (0.3, 0.3, 0.4))]
    hand = {"right": hand_links(geometries["right"], np.array([0.0, -0.17, 0.3]), np.array([1.0, 0.0, 0.0]),
                                np.array([0.0, 1.0, 0.0]))}
    assert episode_grips(episode(geometries, hand, lifted=True), object_faces(pieces), HullPlanes.from_pieces(pieces),
                         np.array([0.0, 0.0, 0.2]), geometries, GraspSettings()) == []


def test_weights_ease_in_before_and_squeeze_only_inside_the_held_frames():
    held = np.zeros(30, dtype=bool)
    held[10:20] = True
    blend = blend_weight(held, 5)
    assert (blend[10:20] == 1).all() and blend[4] == 0 and 0 < blend[7] < 1 and blend[26] == 0
    assert (np.diff(blend[4:11]) >= 0).all()
    squeeze = squeeze_weight(held, 3)
    assert (squeeze[:10] == 0).all() and (squeeze[20:] == 0).all()
    assert squeeze[10] == pytest.approx(0.25) and squeeze[15] == 1.0
    assert grip_episodes(np.stack([held, np.roll(held, 3)], 1)) == [(10, 22, ("left", "right"))]


def test_grasp_replaces_the_hands_in_the_retarget(robot):
    cfg, model, _ = robot
    clip = embedded_clip("lift_place")
    options = replace(RetargetOptions(), grasp_plan=GraspSettings(enabled=True, object_density=25.0))
    targets = targets_from_clip(clip, cfg, mapping=options.mapping, hand_length=robot_hand_lengths(model, cfg.link_map))
    plan = clip_grasps(model, cfg, clip, targets, options)
    assert {g.kind for g in plan.grips} == {"claw"}
    motion = retarget_clip(clip, cfg, model, options=options).motion
    assert motion.meta["grasp_plan"]["enabled"]
    names = list(motion.link_names)
    held = np.flatnonzero(plan.hold("left"))
    cols = [names.index(n) for n in plan.links["left"]]
    to_plan = np.linalg.norm(motion.link_pos[held][:, cols] - plan.link_pos["left"][held], axis=-1).mean(0)
    to_human = np.linalg.norm(motion.link_pos[held][:, cols] - targets.pos[held][:, cols], axis=-1).mean(0)
    assert to_plan[1:].max() < 0.02  # the fingertips reach the grip
    assert to_plan.mean() < 0.5 * to_human.mean()  # the hand left the human's placement for it
    index = motion.actuator_names.index("L_index_proximal_joint")
    pressed = np.flatnonzero(plan.squeeze["left"] >= 1.0)
    qadr = model.jnt_qposadr[model.actuator_trnid[index, 0]]
    assert (motion.joint_pos[pressed, index] - motion.qpos[pressed, qadr] > 0.2).all()  # the fingers press on


def test_face_of_a_box_asset_matches_its_size():
    asset = box_asset((0.4, 0.3, 0.2))
    faces = object_faces([asset.hull_vertices()])
    assert sorted(round(float(abs(f.offset)), 3) for f in faces) == [0.1, 0.1, 0.15, 0.15, 0.2, 0.2]
    assert all(isinstance(f, Face) for f in faces)
