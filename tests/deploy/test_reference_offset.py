"""Policies trained with residual actions around the reference and a warmup: the contract round-trips the two
settings, the reference clock holds during warmup, and targets are offset by the reference joints of f(t + 1)."""

import dataclasses
import json

import numpy as np
import pytest

from deploy.contract import PolicyContract, ReferenceInfo
from deploy.devpolicy import make_contract, make_motion
from deploy.embodiment import load_embodiment
from deploy.errors import ContractError
from deploy.observations import ObsContext


@pytest.fixture(scope="module")
def contract():
    base = make_contract(load_embodiment("g1_inspire"), reference=ReferenceInfo("x.motion.npz", "0" * 64))
    return dataclasses.replace(base, action_offset_mode="reference", warmup_frames=15)


def test_round_trip_and_defaults(contract):
    parsed = PolicyContract.from_metadata(contract.to_metadata())
    assert parsed.action_offset_mode == "reference" and parsed.warmup_frames == 15
    legacy = {k: v for k, v in contract.to_metadata().items() if k not in ("action_offset_mode", "warmup_frames")}
    old = PolicyContract.from_metadata(legacy)
    assert old.action_offset_mode == "fixed" and old.warmup_frames == 0 and not old.warmup_blend
    blended = dataclasses.replace(contract, warmup_blend=True)
    assert PolicyContract.from_metadata(blended.to_metadata()).warmup_blend


@pytest.mark.parametrize(("key", "value"), [("action_offset_mode", "sideways"), ("warmup_frames", -1),
                                            ("warmup_frames", 1.5), ("warmup_blend", "yes")])
def test_bad_values_are_refused(contract, key, value):
    metadata = contract.to_metadata()
    metadata[key] = json.dumps(value)
    with pytest.raises(ContractError, match=key):
        PolicyContract.from_metadata(metadata)


def test_reference_mode_needs_a_motion(contract):
    metadata = contract.to_metadata()
    metadata["reference"] = "null"
    with pytest.raises(ContractError, match="action_offset_mode"):
        PolicyContract.from_metadata(metadata)


def test_clock_holds_during_warmup_then_advances(contract):
    motion = make_motion(contract, duration_s=2.0)
    assert [contract.reference_frame(t, motion.num_frames) for t in (0, 10, 15, 16, 20)] == [0, 0, 0, 1, 5]
    assert contract.reference_frame(10_000, motion.num_frames) == motion.num_frames - 1
    ctx = ObsContext(contract, motion)
    assert ctx.ref_frames(3).tolist() == [min(k, motion.num_frames - 1) for k in contract.keyframes]
    assert ctx.ref_frames(20).tolist() == [min(5 + k, motion.num_frames - 1) for k in contract.keyframes]


def test_targets_are_reference_joints_plus_scaled_action(contract):
    motion = make_motion(contract, duration_s=2.0)
    action = np.linspace(-1, 1, contract.num_actions)
    offset = motion.joint_pos[contract.reference_frame(21, motion.num_frames)]
    np.testing.assert_allclose(contract.action_to_target(action, offset), offset + contract.action_scale * action)
    with pytest.raises(ContractError, match="reference"):
        contract.action_to_target(action)


def test_warmup_blend_glides_from_the_default_pose_to_frame_0(contract):
    motion = make_motion(contract, duration_s=2.0)
    joint_pos = motion.joint_pos + 0.3  # frame 0 away from the default pose
    stepped = [contract.reference_offset(t, joint_pos) for t in (0, 7, 14, 15)]
    for offset in stepped[:3]:
        np.testing.assert_allclose(offset, joint_pos[0])  # without the blend: frame 0 from the first tick
    np.testing.assert_allclose(stepped[3], joint_pos[1])
    blend = dataclasses.replace(contract, warmup_blend=True)
    np.testing.assert_allclose(blend.reference_offset(0, joint_pos), contract.default_pose)
    halfway = contract.default_pose + 7 / 15 * (joint_pos[0] - contract.default_pose)
    np.testing.assert_allclose(blend.reference_offset(7, joint_pos), halfway)
    np.testing.assert_allclose(blend.reference_offset(15, joint_pos), joint_pos[1])  # tracking: unchanged
