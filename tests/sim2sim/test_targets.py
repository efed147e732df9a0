"""Evaluation targets: the policy's sidecar and a clip retargeted here describe the same reference; the object
and the per-frame hand-contact labels come from the clip; bad inputs are user errors."""

from __future__ import annotations

import numpy as np
import pytest

from robot_hoi.errors import UserError
from sim2sim.targets import clip_targets, policy_targets


def test_clip_retargeted_here_equals_the_exported_sidecar(contract, target):
    (again,) = clip_targets(contract, ["embedded:lift_place"], "g1_inspire", True)
    assert again.name == target.name
    for key in ("joint_pos", "root_pos", "root_quat_wxyz", "link_pos", "object_pos", "object_quat_wxyz"):
        np.testing.assert_allclose(getattr(again.motion, key), getattr(target.motion, key), atol=1e-5, err_msg=key)
    np.testing.assert_array_equal(again.hand_contact, target.hand_contact)
    assert target.hand_contact.shape == (target.motion.num_frames, 2) and target.hand_contact.any()
    assert target.object_points.shape == (256, 3)  # training's object_surface_points
    assert target.object_mass_kg == pytest.approx(2.0) and target.license  # the lift_place box


def test_missing_inputs_are_user_errors(contract, tmp_path):
    with pytest.raises(UserError, match="no such clip"):
        clip_targets(contract, [str(tmp_path / "nope.pt")], "g1_inspire", True)
    with pytest.raises(Exception, match="motion file not found"):
        policy_targets(contract, str(tmp_path / "nope.motion.npz"), "g1_inspire", True)


def _object_friction(target) -> float:
    import mujoco

    from sim2sim.scene import load_model

    model = load_model(target.scene)
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "object")
    return float(model.geom_friction[np.flatnonzero(model.geom_bodyid == body)[0], 0])


def test_the_world_is_rebuilt_from_the_task_the_policy_recorded(contract, exported_policy):
    """The exported file records its training task; sim2sim builds the object and the episode rules from it, not
    from today's configs/tasks/interaction.yaml (a file without the record falls back to the YAML)."""
    import dataclasses
    import json

    from deploy.contract import PolicyContract
    from sim2sim.targets import task_config

    yaml_cfg = task_config()
    assert contract.task is not None
    assert json.loads(json.dumps(dataclasses.asdict(task_config(contract)))) == contract.task["env"]
    metadata = contract.to_metadata()
    edited = json.loads(metadata["task"])
    edited["env"]["object_friction"] = 0.37
    edited["env"]["terminations"]["max_contact_loss_frames"] += 5
    trained = PolicyContract.from_metadata(dict(metadata, task=json.dumps(edited)), str(exported_policy))
    cfg = task_config(trained)
    assert cfg.object_friction == 0.37 != yaml_cfg.object_friction
    assert cfg.terminations.max_contact_loss_frames == yaml_cfg.terminations.max_contact_loss_frames + 5
    assert _object_friction(policy_targets(trained, None, "g1_inspire", True)[0]) == pytest.approx(0.37)
    assert _object_friction(clip_targets(trained, ["embedded:lift_place"], "g1_inspire", True)[0]) == \
        pytest.approx(0.37)

    flat = json.loads(metadata["task"])  # exported before the retarget: block: its settings were flat env keys
    block = flat["env"].pop("retarget")
    flat["env"].update({f"retarget_{k}": v for k, v in block.items() if k != "anchor_mode"}, retarget_squeeze_depth=0.12)
    before_block = task_config(PolicyContract.from_metadata(dict(metadata, task=json.dumps(flat)), str(exported_policy)))
    recorded = task_config(contract)
    assert recorded.retarget.squeeze_depth != 0.12
    assert before_block == dataclasses.replace(recorded, retarget=dataclasses.replace(recorded.retarget,
                                                                                      squeeze_depth=0.12))

    older = {k: v for k, v in metadata.items() if k != "task"}  # exported before the task was recorded
    assert dataclasses.asdict(task_config(PolicyContract.from_metadata(older, str(exported_policy)))) == \
        dataclasses.asdict(yaml_cfg)
