"""Metric functions against values computed by hand on small synthetic trajectories."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2sim import metrics


def test_global_and_root_relative_mpjpe():
    ref = np.zeros((2, 3, 3))
    ref[:, 1] = [1.0, 0.0, 0.0]
    ref[:, 2] = [0.0, 1.0, 0.0]
    shifted = ref + np.array([3.0, 4.0, 0.0])  # the whole body 5 m off, same pose
    assert metrics.mpjpe_global(shifted, ref) == pytest.approx(5.0)
    assert metrics.mpjpe_root_relative(shifted, ref, root=0) == pytest.approx(0.0)
    bent = ref.copy()
    bent[:, 2] += [0.0, 0.0, 0.3]  # one of three joints 0.3 m off, root in place
    assert metrics.mpjpe_global(bent, ref) == pytest.approx(0.1)
    assert metrics.mpjpe_root_relative(bent, ref, root=0) == pytest.approx(0.1)


def test_acceleration_and_velocity_errors():
    ref = np.zeros((3, 1, 3))
    pos = np.zeros((3, 1, 3))
    pos[:, 0, 0] = [0.0, 1.0, 3.0]
    # v = [1, 2] -> mean |v - 0| = 1.5; a_1 = 3 - 2 + 0 = 1
    assert metrics.velocity_error(pos, ref) == pytest.approx(1.5)
    assert metrics.acceleration_error(pos, ref) == pytest.approx(1.0)
    bump = np.zeros((3, 2, 3))
    bump[1, 0, 2] = 1.0  # one joint of two up for one frame: a_1 = -2 for it, 0 for the other
    assert metrics.acceleration_error(bump, np.zeros_like(bump)) == pytest.approx(1.0)
    assert math.isnan(metrics.acceleration_error(pos[:2], ref[:2]))
    assert math.isnan(metrics.velocity_error(pos[:1], ref[:1]))


def test_tracking_metrics_units_and_hand_links_excluded():
    names = ["pelvis", "left_knee_link", "L_index_tip"]
    body = metrics.body_link_indices(names)
    assert body == [0, 1]
    ref = np.zeros((4, 3, 3))
    pos = ref.copy()
    pos[:, 1, 0] = 0.02  # knee 2 cm off
    pos[:, 2, 0] = 0.50  # fingertip far off: not part of E_h (InterMimic excludes hands for OMOMO)
    out = metrics.tracking_metrics(pos, ref, np.full(4, 0.03), body, root=0)
    assert out["E_h_cm"] == pytest.approx(1.0)  # mean over 2 body links of (0, 2 cm)
    assert out["E_o_cm"] == pytest.approx(3.0)
    assert out["mpjpe_g_mm"] == pytest.approx(10.0)
    assert out["mpjpe_mm"] == pytest.approx(10.0)
    assert out["e_vel_mm"] == pytest.approx(0.0)
    assert out["e_acc_mm"] == pytest.approx(0.0)
    assert out["E_h_max_cm"] == pytest.approx(1.0) and out["E_o_max_cm"] == pytest.approx(3.0)
    empty = metrics.tracking_metrics(np.zeros((0, 3, 3)), np.zeros((0, 3, 3)), np.zeros(0), body, root=0)
    assert all(math.isnan(v) for v in empty.values())


def test_object_points_rotate_and_translate():
    points = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 2.0]])
    quat_z90 = np.array([np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)])
    out = metrics.object_points_world(points, np.array([0.0, 0.0, 1.0]), quat_z90)
    np.testing.assert_allclose(out, [[0.0, 1.0, 1.0], [0.0, 0.0, 3.0]], atol=1e-12)
    batched = metrics.object_points_world(points, np.zeros((2, 3)), np.stack([quat_z90, [1.0, 0, 0, 0]]))
    assert batched.shape == (2, 2, 3)
    np.testing.assert_allclose(batched[1], points)


def test_nearest_surface_vectors_match_brute_force():
    rng = np.random.default_rng(1)
    links, points = rng.normal(size=(4, 7, 3)), rng.normal(size=(4, 50, 3))
    diff = points[:, None] - links[:, :, None]
    brute = np.take_along_axis(diff, np.linalg.norm(diff, axis=-1).argmin(-1)[..., None, None], axis=-2)[..., 0, :]
    np.testing.assert_allclose(metrics.nearest_surface_vectors(links, points), brute, atol=1e-12)


def test_interaction_weights_and_distance_error_by_hand():
    d = np.array([[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    d_hat = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    # 1/|d|^2 = [1, 0.25] -> [0.8, 0.2]; reference [1, 1] -> [0.5, 0.5]; w = [0.65, 0.35]
    np.testing.assert_allclose(metrics.interaction_weights(d, d_hat), [0.65, 0.35])
    # <w, |d|> = 0.65 + 0.7 = 1.35, <w, |d_hat|> = 1
    assert metrics.interaction_distance_error(d, d_hat) == pytest.approx(0.35)
    assert metrics.interaction_distance_error(d, d) == pytest.approx(0.0)


def test_hand_command_stats_by_hand():
    cmd = np.array([[-1] * 12, [1000] * 12, [0] * 12, [0] * 12])  # first tick: no command (-1)
    meas = np.array([[1000] * 12, [1000] * 12, [900] * 12, [100] * 12])
    force = np.array([[0] * 12, [0] * 12, [50] * 12, [300] * 12])
    s = metrics.hand_command_stats(cmd, meas, force)
    assert s["mean_command"] == pytest.approx(1000 / 3)
    assert s["command_step"] == pytest.approx(500.0)  # |0 - 1000|, |0 - 0|
    assert s["closed_fraction"] == pytest.approx(2 / 3)
    assert s["open_fraction"] == pytest.approx(1 / 3)
    assert s["tracking_error"] == pytest.approx((100 + 100) / 2)  # |1000 - 900|, |0 - 100|
    assert s["peak_force_g"] == 300
    assert s["mean_force_g"] == pytest.approx(350 / 3)
    assert math.isnan(metrics.hand_command_stats(cmd[:1], meas[:1], force[:1])["mean_command"])


def test_aggregate_and_percentiles():
    agg = metrics.aggregate([1.0, 3.0, float("nan"), None])
    assert agg == {"mean": 2.0, "std": 1.0, "min": 1.0, "max": 3.0, "n": 2}
    assert metrics.aggregate([])["mean"] is None
    p = metrics.percentiles_ms([0.001, 0.002, 0.003])
    assert p["p50"] == pytest.approx(2.0) and p["max"] == pytest.approx(3.0)


def test_same_conventions_as_training():
    """The hand-link rule and the object point subsample are training's (robot_hoi.tasks.interaction)."""
    import torch

    from robot_hoi.tasks.interaction.env import _subsample
    from robot_hoi.tasks.interaction.scene_setup import HAND_LINK_MARKERS

    assert metrics.HAND_LINK_MARKERS == HAND_LINK_MARKERS
    points = np.random.default_rng(0).normal(size=(340, 3))
    np.testing.assert_allclose(metrics.subsample_points(points, 256),
                               _subsample(torch.as_tensor(points), 256).numpy())


def test_worst_errors_skip_untracked_frames():
    """interaction success reads the worst frame after the warmup, as training does: a bad warmup frame is not it."""
    body = [0, 1]
    ref = np.zeros((4, 2, 3))
    pos = ref.copy()
    pos[0, :, 0] = 0.40  # warmup frame far off
    pos[2, :, 0] = 0.05
    obj = np.array([0.30, 0.01, 0.02, 0.04])
    tracked = np.array([False, True, True, True])
    out = metrics.tracking_metrics(pos, ref, obj, body, root=0, tracked=tracked)
    assert out["E_h_max_cm"] == pytest.approx(5.0) and out["E_o_max_cm"] == pytest.approx(4.0)
    assert metrics.tracking_metrics(pos, ref, obj, body, root=0)["E_h_max_cm"] == pytest.approx(40.0)
    none = metrics.tracking_metrics(pos, ref, obj, body, root=0, tracked=np.zeros(4, dtype=bool))
    assert math.isnan(none["E_h_max_cm"]) and math.isnan(none["E_o_max_cm"])
