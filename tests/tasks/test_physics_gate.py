"""The physics gate: a reference that keeps its object passes, one whose object must drop fails, and says where."""

import pytest
import torch

from robot_hoi.data.objects import box_asset
from robot_hoi.embodiment import load_embodiment
from robot_hoi.tasks.interaction.env import InteractionEnv
from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg
from robot_hoi.tasks.interaction.feasibility import (
    format_table,
    format_verdict,
    gate_config,
    held_segments,
    replay,
)
from robot_hoi.tasks.interaction.reference import ReferenceMotion, nearest_surface_vectors
from robot_hoi.tasks.interaction.scene_setup import InteractionScene
from robot_hoi.utils.torch_rot import quat_apply

FRAMES = 30


@pytest.fixture(scope="module")
def scene():
    return InteractionScene(load_embodiment("g1_inspire"), box_asset((0.4, 0.4, 0.3)))


def reference(scene, object_z: float, held: slice | None) -> ReferenceMotion:
    """The robot standing still (its own FK as link targets), a box 0.6 m in front at height object_z, both hands
    required to touch it over the frames `held`."""
    lay = scene.layout
    robot_qpos = scene.default_robot_qpos()
    obj = torch.tensor([[0.6, 0.0, object_z, 1.0, 0.0, 0.0, 0.0]])
    backend = scene.make_backend(1, nthread=1)
    backend.set_state(torch.arange(1), torch.cat([robot_qpos, obj], 1).double(),
                      torch.zeros(1, scene.model.nv, dtype=torch.float64))
    sens = backend.sensordata.float()
    link_pos = sens[:, lay.link_pos].reshape(1, -1, 3).repeat(FRAMES, 1, 1)
    points = torch.as_tensor(scene.object_asset.sample_points, dtype=torch.float32)
    points_world = quat_apply(obj[:, None, 3:7], points[None]) + obj[:, None, :3]
    contact = torch.zeros(FRAMES, 2, dtype=torch.bool)
    if held is not None:
        contact[held] = True
    return ReferenceMotion(
        fps=30.0, link_pos=link_pos, link_quat_wxyz=sens[:, lay.link_quat].reshape(1, -1, 4).repeat(FRAMES, 1, 1),
        robot_qpos=robot_qpos.repeat(FRAMES, 1), robot_qvel=torch.zeros(FRAMES, lay.robot_nv),
        joint_pos=torch.as_tensor(scene.embodiment.default_pos, dtype=torch.float32).repeat(FRAMES, 1),
        object_pos=obj[:, :3].repeat(FRAMES, 1), object_quat_wxyz=obj[:, 3:].repeat(FRAMES, 1),
        object_lin_vel=torch.zeros(FRAMES, 3), object_ang_vel=torch.zeros(FRAMES, 3), hand_contact=contact,
        object_points=points, d_hat=nearest_surface_vectors(link_pos, points_world.repeat(FRAMES, 1, 1)), name="box")


def gate_env(scene, ref) -> InteractionEnv:
    cfg = InteractionEnvCfg(nthread=1)
    cfg.terminations.max_mean_object_point_error = 0.12  # the task config's line
    return InteractionEnv(gate_config(cfg), scene, [ref])


def test_held_segments_per_hand():
    need = torch.zeros(12, 2, dtype=torch.bool)
    need[2:5, 0] = need[7:12, 0] = need[3:9, 1] = True
    assert held_segments(need) == [{"hand": "left", "frames": [2, 4]}, {"hand": "right", "frames": [3, 8]},
                                   {"hand": "left", "frames": [7, 11]}]


def test_a_box_resting_on_the_floor_passes(scene):
    gate = replay(gate_env(scene, reference(scene, 0.15, None)))
    assert gate["verdict"] == "PASS" and gate["failure"] is None and gate["completed"]
    assert gate["start_frame"] == 0 and gate["frames"] == FRAMES - 1 and gate["object_error_max_cm"] < 1.0
    assert format_verdict(gate).startswith("PASS")


def test_a_box_nobody_holds_in_the_air_drops_and_fails_in_its_held_segment(scene):
    """The reference says both hands hold the box 1 m up from frame 12 on; the standing robot's hands are nowhere
    near it, so it falls (0.12 m of mean point error takes ~5 frames of free fall)."""
    gate = replay(gate_env(scene, reference(scene, 1.0, slice(12, FRAMES))), lead_frames=4)
    assert gate["verdict"] == "FAIL" and not gate["completed"]
    assert gate["start_frame"] == 8 and gate["first_held_frame"] == 12
    failure = gate["failure"]
    assert failure["reason"] == "object_deviation" and 10 <= failure["frame"] <= 16
    assert failure["object_error_cm"] > 12.0
    if failure["frame"] >= 12:
        assert failure["segment"] in ("left 12-29", "right 12-29")
    text = format_verdict(gate)
    assert text.startswith("FAIL: object_deviation at frame") and "cm" in text


def test_the_folder_table_has_one_row_per_clip_and_counts_passes():
    passed = {"verdict": "PASS", "failure": None, "segments": [{"hand": "left", "frames": [1, 5]}]}
    failed = {"verdict": "FAIL", "segments": [], "failure": {"frame": 40, "reason": "contact_lost", "hand": "left",
                                                              "segment": "left 20-60", "object_error_cm": 3.0}}
    table = format_table([{"clip": "a", "frames": 100, "gate": passed, "retarget_s": 1.0, "gate_s": 2.0},
                          {"clip": "b", "frames": 200, "gate": failed, "retarget_s": 3.0, "gate_s": 4.0},
                          {"clip": "c.pt", "error": "c.pt: not a clip"}]).splitlines()
    assert table[0].split()[:2] == ["clip", "frames"] and len(table) == 5
    assert table[1].split()[:4] == ["a", "100", "1", "PASS"]
    assert "contact_lost @ 40 (left 20-60)" in table[2] and "ERROR" in table[3]
    assert table[-1] == "1 of 3 clips pass the physics gate"


def test_the_gate_judges_the_object_and_contacts_not_a_tightened_body_line():
    """A task that tightens its body line (a test's 1 mm link error) still gates on the object line and the held
    contacts alone."""
    from robot_hoi.paths import TASK_CONFIG
    from robot_hoi.tasks.interaction.env_cfg import InteractionEnvCfg
    from robot_hoi.tasks.interaction.feasibility import gate_config
    from robot_hoi.utils.config import load_yaml_dataclass

    cfg = load_yaml_dataclass(InteractionEnvCfg, TASK_CONFIG, ["terminations.max_mean_link_error=0.001"])
    gate = gate_config(cfg).terminations
    assert gate.max_mean_link_error == float("inf") and gate.max_interaction_distance_error == float("inf")
    assert gate.min_root_height == float("-inf")
    assert gate.max_mean_object_point_error == cfg.terminations.max_mean_object_point_error
    assert gate.max_contact_loss_frames == cfg.terminations.max_contact_loss_frames
    assert cfg.terminations.max_mean_link_error == 0.001  # the task's own config is untouched
