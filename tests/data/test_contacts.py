import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robot_hoi.data.contacts import ContactParams, infer_contacts, label_contacts
from robot_hoi.data.layout import BODY_INDEX, L_HAND, R_HAND
from robot_hoi.data.objects import box_asset

FPS = 30.0
T = 60
t = np.arange(T) / FPS
BOX = box_asset((0.4, 0.4, 0.3))
IDENTITY = np.tile([0.0, 0.0, 0.0, 1.0], (T, 1))


def _far_human(near_point=None):
    """Everything 5 m away; optionally the left middle fingertip at `near_point` (T, 3)."""
    pos = np.tile(np.array([5.0, 5.0, 1.0]), (T, 52, 1)) + np.arange(52)[None, :, None] * 0.01
    pos[:, BODY_INDEX["L_Ankle"], 2] = 0.08
    pos[:, BODY_INDEX["L_Toe"], 2] = 0.03
    if near_point is not None:
        pos[:, BODY_INDEX["L_Middle3"]] = near_point
    return pos


def _track(z, x=None):
    x = np.zeros(T) if x is None else x
    return np.stack([x, np.zeros(T), z], axis=1)


def test_free_fall_needs_no_human_force():
    # sinking at a tenth of g is not free fall: someone lowers the box
    est = infer_contacts(_far_human(), BOX, _track(3.0 - 0.5 * 0.981 * t**2), IDENTITY, FPS)
    assert est.airborne.all() and est.force.all()
    est = infer_contacts(_far_human(), BOX, _track(5.0 - 0.5 * 9.81 * t**2), IDENTITY, FPS)
    falling = t < 0.9  # (the parabola would cross the floor later)
    assert est.airborne[falling].all() and not est.force[falling].any() and not est.contact.any()


def test_box_held_in_the_air_is_a_contact_only_with_a_body_nearby():
    far = infer_contacts(_far_human(), BOX, _track(np.full(T, 1.0)), IDENTITY, FPS)
    assert far.force.all() and not far.contact.any()
    assert "no body within" in far.problems[0]
    touching = np.tile([0.0, 0.2 + 0.008 + 0.01, 1.0], (T, 1))  # 1 cm off the +y face, plus finger radius
    near = infer_contacts(_far_human(touching), BOX, _track(np.full(T, 1.0)), IDENTITY, FPS)
    assert near.contact.all() and near.problems == []
    assert (near.body_contact[:, list(L_HAND)] == 1).all()  # the whole hand is one contact unit
    assert (near.body_contact[:, list(R_HAND)] == -1).all()
    assert (near.body_contact[:, BODY_INDEX["Head"]] == -1).all()
    assert (near.body_contact[:, BODY_INDEX["L_Ankle"]] == 0).all()  # foot on the floor: neutral
    np.testing.assert_allclose(near.threshold, ContactParams().touch_distance)


def test_floor_sliding_is_pushed_unless_it_decelerates_by_friction():
    z = np.full(T, 0.15)
    pushed = infer_contacts(_far_human(), BOX, _track(z, 0.5 * t), IDENTITY, FPS)
    assert not pushed.airborne.any() and pushed.force.all()
    params = ContactParams(friction_coefficient=0.2)
    decel = 0.2 * 9.81
    v0 = 1.5
    stop = v0 / decel
    x = np.where(t < stop, v0 * t - 0.5 * decel * t**2, v0 * stop - 0.5 * decel * stop**2)
    coasting = infer_contacts(_far_human(), BOX, _track(z, x), IDENTITY, FPS, params)
    middle = (t > 0.15) & (t < stop - 0.15)
    assert middle.sum() >= 10 and not coasting.force[middle].any()
    assert not coasting.force[t > stop + 0.2].any()  # at rest


def test_turning_on_the_floor_is_a_force():
    quat = Rotation.from_rotvec(np.outer(1.0 * t, [0.0, 0.0, 1.0])).as_quat()
    est = infer_contacts(_far_human(), BOX, _track(np.full(T, 0.15)), quat, FPS)
    assert est.force.all()


def test_label_rule_matches_the_stored_labels_definition():
    touching = np.tile([0.0, 0.2 + 0.008 + 0.005, 0.15], (T, 1))
    flag, body = label_contacts(_far_human(touching), BOX, _track(np.full(T, 0.15)), IDENTITY, FPS)
    assert flag.all() and (body[:, list(L_HAND)] == 1).all() and (body[:, BODY_INDEX["Head"]] == -1).all()
    flag, body = label_contacts(_far_human(), BOX, _track(np.full(T, 0.15)), IDENTITY, FPS)
    assert not flag.any()
    assert flag.dtype == np.int8 and body.dtype == np.int8


@pytest.mark.parametrize("kind", ["lift_carry", "push"])
def test_synthetic_clips_stored_and_inferred_agree(kind, lift_clip, push_clip):
    clip = lift_clip if kind == "lift_carry" else push_clip
    assert clip.contact.any()
    assert np.mean(clip.contact.astype(bool) == clip.inferred_contact) > 0.97
