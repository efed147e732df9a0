"""EmbodimentConfig loading, validation errors, Inspire unit mapping and link_map resolution."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from robot_hoi.embodiment import build_model, load_embodiment
from robot_hoi.embodiment.config import EMBODIMENTS_DIR
from robot_hoi.embodiment.links import LinkIndex, resolve_link_map, resolve_links
from robot_hoi.errors import UserError


@pytest.fixture(scope="module")
def cfg():
    return load_embodiment("g1_inspire")


@pytest.fixture()
def raw():
    return yaml.safe_load((EMBODIMENTS_DIR / "g1_inspire.yaml").read_text())


def _write(tmp_path: Path, data) -> Path:
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_loads_by_name_and_by_path(cfg):
    same = load_embodiment(str(EMBODIMENTS_DIR / "g1_inspire.yaml"))
    assert same == cfg
    assert cfg.physics_dt == pytest.approx(cfg.control_dt / 7)
    assert cfg.kp.shape == cfg.kd.shape == cfg.default_pos.shape == cfg.action_scale.shape == (41,)
    assert cfg.kp[0] == 100 and cfg.default_pos[3] == pytest.approx(0.3)
    assert list(cfg.hand_actuator_indices("left")) == list(range(29, 35))
    assert list(cfg.hand_actuator_indices("right")) == list(range(35, 41))


def test_overrides(cfg):
    changed = load_embodiment("g1_inspire", overrides=["decimation=4", "self_collision=true"])
    assert changed.decimation == 4 and changed.self_collision is True
    assert changed.physics_dt == pytest.approx(cfg.control_dt / 4)
    with pytest.raises(UserError, match="unknown key"):
        load_embodiment("g1_inspire", overrides=["decimaton=4"])


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d.__setitem__("colour", "red"), "unknown key"),
        (lambda d: d["actuators"][0].__setitem__("name", "left_hip_pitch"), "actuator not in the model"),
        (lambda d: d["actuators"][0].__setitem__("kp", "stiff"), "expected a number"),
        (lambda d: d["actuators"].append(dict(d["actuators"][0])), "listed twice"),
        (lambda d: d["actuators"].pop(3), "without an actuator entry: left_knee_joint"),
        (lambda d: d["actuators"][29].__setitem__("name", "L_pinky_intermediate_joint"), "passive joint"),
        (lambda d: d["actuators"][3].__setitem__("default", 3.5), "outside the joint range"),
        (lambda d: d["hands"]["left"]["channels"].reverse(), "in that order"),
        (lambda d: d["link_map"].__setitem__("nose", "Head"), "no body or site"),
        (lambda d: d.__setitem__("decimation", 0), "decimation must be >= 1"),
        (lambda d: d.pop("control_dt"), "missing required key 'control_dt'"),
    ],
)
def test_bad_configs_name_the_file_and_the_problem(tmp_path, raw, edit, message):
    edit(raw)
    path = _write(tmp_path, raw)
    with pytest.raises(UserError, match=message) as info:
        load_embodiment(str(path))
    assert str(path) in str(info.value)


def test_unknown_name_and_bad_yaml(tmp_path):
    with pytest.raises(UserError, match="unknown embodiment 'g2'.*g1_inspire"):
        load_embodiment("g2")
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: [unclosed\n")
    with pytest.raises(UserError, match="not valid YAML"):
        load_embodiment(str(bad))
    with pytest.raises(UserError, match="not found"):
        load_embodiment(str(tmp_path / "missing.yaml"))


def test_inspire_units_round_trip(cfg):
    closed = cfg.units_to_rad("left", np.zeros(6))
    opened = cfg.units_to_rad("left", np.full(6, 1000))
    np.testing.assert_allclose(closed, [1.7, 1.7, 1.7, 1.7, 0.5, 1.3])
    np.testing.assert_allclose(opened, [0.0, 0.0, 0.0, 0.0, 0.0, -0.1])
    units = np.array([[0, 250, 500, 750, 1000, 333], [1000, 0, 10, 990, 500, 500]], dtype=float)
    np.testing.assert_allclose(cfg.rad_to_units("right", cfg.units_to_rad("right", units)), units, atol=1e-9)
    # beyond the channel's range: clipped to 0..1000
    np.testing.assert_allclose(cfg.rad_to_units("left", [2.0, -0.5, 0.85, 0.85, 0.25, 0.6]),
                               [0, 1000, 500, 500, 500, 500])
    with pytest.raises(UserError, match="no hand 'middle'"):
        cfg.rad_to_units("middle", np.zeros(6))


def test_link_map_resolves_to_bodies_and_sites(cfg):
    import mujoco

    model = build_model(cfg)
    refs = resolve_link_map(model, cfg)
    assert list(refs) == list(cfg.link_map)
    assert refs["pelvis"].kind == "body" and refs["L_index_tip"].kind == "site" and refs["head"].kind == "site"
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    mujoco.mj_kinematics(model, data)
    index = LinkIndex.from_refs(refs)
    pos = index.positions(data)
    assert pos.shape == (len(cfg.link_map), 3)
    np.testing.assert_allclose(pos[index.names.index("pelvis")], [0, 0, cfg.spawn_height])
    head, toe = pos[index.names.index("head")], pos[index.names.index("left_toe")]
    assert abs(head[2] - cfg.robot_height) < 0.03 and abs(toe[2]) < 2e-3  # standing on the floor
    with pytest.raises(UserError, match="neither a body nor a site"):
        resolve_links(model, ["tail"])
