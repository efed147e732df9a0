"""One termination implementation (robot_hoi/termination.py) for the training env (torch) and sim2sim (numpy).

Regression tests of issue 14 item 3: sim2sim's contact-lost check had no contact tolerance, unlike training
(the logic existed twice and had drifted). Both tests fail on the code before ab16be1: the monitor test by
terminating with "contact_lost" (old monitor: need & ~touching, no distance), the parity test because
robot_hoi.termination did not exist.
"""

from __future__ import annotations

from types import SimpleNamespace

import mujoco
import numpy as np
import pytest
import torch

LINKS = ["pelvis", "left_wrist_yaw_link", "L_index_tip", "right_wrist_yaw_link", "R_index_tip"]


class _World:
    """What EpisodeMonitor.on_policy_step reads of a SimWorld: a floating base at 0.8 m, five links, a flat object
    face (a 1 cm grid on x = 0, |y|, |z| <= 5 cm) at the origin, and no touch sensor reporting contact."""

    def __init__(self, links: np.ndarray):
        self.model = mujoco.MjModel.from_xml_string(
            "<mujoco><worldbody><body><freejoint/><geom size='0.1'/></body></worldbody></mujoco>")
        self.data = mujoco.MjData(self.model)
        self.data.qpos[2] = 0.8
        self.layout = SimpleNamespace(links=SimpleNamespace(names=LINKS))
        self.links = links
        self.t, self.pd_ticks, self.torque_saturated_updates, self.gantry_on = 0.0, 0, 0, False

    def link_positions(self):
        return self.links.copy()

    def object_frame(self):
        return np.zeros(3), np.eye(3)

    def hand_contact(self):
        return np.zeros(2, dtype=bool)


def _face_points() -> np.ndarray:
    grid = np.round(np.arange(-0.05, 0.0501, 0.01), 3)
    return np.array([(0.0, y, z) for y in grid for z in grid])


def _hand_links(left_wrist_gap: float) -> np.ndarray:
    return np.array([[-0.5, 0.0, 0.0], [-left_wrist_gap, 0.0, 0.0], [-0.12, 0.03, 0.0],
                     [-0.3, -0.3, 0.0], [-0.3, -0.35, 0.0]])


def _run_monitor(left_wrist_gap: float, ticks: int, max_frames: int = 3, ref_wrist_gap: float | None = None,
                 **thresholds):
    """EpisodeMonitor over `ticks` policy steps, the left hand required to touch, its wrist `left_wrist_gap` in
    front of the face; the reference's wrist `ref_wrist_gap` in front of it (default: the robot exactly on its
    reference). Returns the monitor."""
    from sim2sim.monitor import EpisodeMonitor, ReferenceTrack, Thresholds

    links = _hand_links(left_wrist_gap)
    ref_links = _hand_links(left_wrist_gap if ref_wrist_gap is None else ref_wrist_gap)
    frames = ticks + 1
    motion = SimpleNamespace(link_pos=np.repeat(ref_links[None], frames, 0),
                             object_pos=np.zeros((frames, 3)),
                             object_quat_wxyz=np.repeat(np.array([[1.0, 0.0, 0.0, 0.0]]), frames, 0))
    need = np.zeros((frames, 2), dtype=bool)
    need[:, 0] = True
    ref = ReferenceTrack.build(motion, _face_points(), need)
    monitor = EpisodeMonitor(_World(links), ref, Thresholds(max_contact_loss_frames=max_frames, **thresholds),
                             last_frame=frames + 10, keep_qpos=False)
    for tick in range(1, ticks + 1):
        monitor.on_policy_step(tick)
    return monitor


def test_sim2sim_contact_check_honours_the_tolerance():
    """A required hand 1 cm off the object surface keeps its contact (training's contact_tolerance, 2 cm); 5 cm off
    it is lost after max_contact_loss_frames + 1 policy steps, as in training.

    Old: sim2sim counted every step without touch as a miss: the 1 cm hand ended the episode after 4 steps."""
    near = _run_monitor(0.01, ticks=10)
    assert not near.finished and near.terminations == []
    assert near.contact_loss.tolist() == [0, 0]
    far = _run_monitor(0.05, ticks=10, ref_wrist_gap=0.01)
    assert far.terminations == ["contact_lost"]
    assert far.ticks[-1] == 4  # counts 1, 2, 3, 4 > 3


def test_contact_tolerance_counts_from_the_reference_hand():
    """Where the reference's own hand links sit 6 cm off the surface (an Inspire hand on a table's edge: its links
    are not where the human's joints were), a robot tracking it exactly keeps the contact, 1 cm further too; 3 cm
    further (beyond the 2 cm tolerance) it is lost. Measured from the surface alone (the old rule, still
    selectable), the robot on its reference lost the contact after max_contact_loss_frames + 1 steps."""
    assert _run_monitor(0.06, ticks=10).terminations == []
    assert _run_monitor(0.07, ticks=10, ref_wrist_gap=0.06).terminations == []
    assert _run_monitor(0.09, ticks=10, ref_wrist_gap=0.06).terminations == ["contact_lost"]
    old_rule = _run_monitor(0.06, ticks=10, contact_from_reference=False)
    assert old_rule.terminations == ["contact_lost"] and old_rule.ticks[-1] == 4


def test_termination_functions_agree_on_numpy_and_torch():
    """Every robot_hoi.termination function, on the same random inputs as float64 numpy arrays and torch tensors,
    gives the same values (the env calls them on tensors, sim2sim on arrays)."""
    from robot_hoi import termination as T

    rng = np.random.default_rng(0)
    n, links, points = 7, 27, 40
    link_pos = rng.normal(size=(n, links, 3))
    ref_link_pos = link_pos + 0.3 * rng.normal(size=(n, links, 3))
    pts, ref_pts = rng.normal(size=(n, points, 3)), rng.normal(size=(n, points, 3))
    d, d_hat = rng.normal(size=(n, links, 3)), rng.normal(size=(n, links, 3))
    d[0, 3] = 0.0  # a link exactly on the surface: the 1e-4 floor of w_d
    count = rng.integers(0, 5, size=(n, 2))
    need, touching = rng.random((n, 2)) < 0.7, rng.random((n, 2)) < 0.3
    nearest = rng.uniform(0.0, 0.05, size=(n, 2))
    root_height = rng.uniform(0.0, 1.0, size=n)
    th = T.Thresholds(max_mean_link_error=0.45, max_contact_loss_frames=3)

    def both(fn, *args, **kw):
        a = fn(*args, **kw)
        b = fn(*[torch.as_tensor(x) if isinstance(x, np.ndarray) else x for x in args], **kw)
        if isinstance(a, dict):
            assert a.keys() == b.keys()
            for key in a:
                np.testing.assert_array_equal(np.asarray(a[key]), b[key].numpy(), err_msg=key)
        else:
            np.testing.assert_allclose(np.asarray(a), b.numpy(), rtol=1e-12, atol=1e-12)
        return a

    w = both(T.interaction_weights, d, d_hat)
    np.testing.assert_allclose(w.sum(-1), 1.0)
    link_err = both(T.mean_link_error, link_pos, ref_link_pos)
    obj_err = both(T.mean_object_point_error, pts, ref_pts)
    inter_err = both(T.interaction_distance_error, w, d, d_hat)
    both(T.norm, d)
    surface_rule = T.Thresholds(contact_tolerance=0.02, contact_from_reference=False)
    loss = both(T.contact_loss_count, count, need, touching, nearest, surface_rule, rng.uniform(0.0, 0.05, (n, 2)))
    assert loss.dtype.kind == "i"
    np.testing.assert_array_equal(loss, np.where(need & ~touching & (nearest >= 0.02), count + 1, 0))
    ref_nearest = rng.uniform(0.0, 0.05, size=(n, 2))
    relative = both(T.contact_loss_count, count, need, touching, nearest, T.Thresholds(contact_tolerance=0.02),
                    ref_nearest)
    np.testing.assert_array_equal(relative, np.where(need & ~touching & (nearest >= ref_nearest + 0.02), count + 1, 0))
    reasons = both(T.reasons, th, link_err, root_height, obj_err, inter_err, loss)
    assert reasons["contact_lost"].tolist() == (loss.max(-1) > 3).tolist()
    # one env at a time, as sim2sim calls it (scalars and a (2,) count)
    for i in range(n):
        one = T.reasons(th, np.float64(link_err[i]), root_height[i], np.float64(obj_err[i]),
                        np.float64(inter_err[i]), loss[i])
        assert {k: bool(v) for k, v in one.items()} == {k: bool(v[i]) for k, v in reasons.items()}


def test_env_and_sim2sim_share_the_thresholds():
    """The env's TerminationCfg is the sim2sim monitor's Thresholds (one definition, with contact_tolerance)."""
    from robot_hoi.tasks.interaction.env_cfg import TerminationCfg
    from sim2sim.monitor import Thresholds

    assert TerminationCfg is Thresholds
    assert Thresholds().contact_tolerance == pytest.approx(0.02)


@pytest.fixture
def root_too_high():
    """A new condition, registered as a user adds one: one function (and, in each test, one config entry)."""
    from robot_hoi import termination as T

    @T.condition
    def root_too_high(m: T.Measured, max_root_height: float):
        return m.root_height > max_root_height

    yield {"root_too_high": {"max_root_height": 0.5}}  # the config entry: the pelvis stands at ~0.79 m
    del T.CONDITIONS["root_too_high"]


def test_a_new_condition_is_one_function_and_one_config_entry(root_too_high):
    """Registered and given its entry in `terminations.conditions`, a new condition ends the env's episodes under
    its name and sim2sim's monitor's alike; without the entry it is off. Bad entries are refused by name."""
    from robot_hoi.data.objects import box_asset
    from robot_hoi.embodiment import load_embodiment
    from robot_hoi.tasks.interaction.scene_setup import InteractionScene
    from robot_hoi.termination import Thresholds

    from .tasks.test_bookkeeping import make_env

    scene = InteractionScene(load_embodiment("g1_inspire"), box_asset((0.4, 0.4, 0.3)))
    for entry in ({}, root_too_high):
        env = make_env(scene, terminations={"conditions": entry})
        _, _, terminated, _, extras = env.step(torch.zeros(env.num_envs, env.num_actions))
        assert terminated.all() == bool(entry) and ("ended_by/root_too_high" in extras["episode"]) == bool(entry)
        if entry:
            assert extras["episode"]["ended_by/root_too_high"].tolist() == [1.0, 1.0]
            assert extras["episode"]["ended_by/link_deviation"].tolist() == [0.0, 0.0]
    assert _run_monitor(0.01, ticks=3).terminations == []
    stopped = _run_monitor(0.01, ticks=3, conditions=root_too_high)
    assert stopped.terminations == ["root_too_high"] and stopped.ticks == [1]
    with pytest.raises(ValueError, match="conditions.root_too_hi: no such termination condition"):
        Thresholds(conditions={"root_too_hi": {"max_root_height": 0.5}})
    with pytest.raises(ValueError, match="conditions.root_too_high: parameters max_root_height; unknown height; "
                                         "missing max_root_height"):
        Thresholds(conditions={"root_too_high": {"height": 0.5}})
