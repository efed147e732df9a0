"""The reference ghost: one renderer draws it for play, retarget and sim2sim videos."""

from __future__ import annotations

import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest

NO_GL = 3
SCRIPT = """
import sys
from robot_hoi.retarget.video import choose_gl_backend
if choose_gl_backend() is None:
    sys.exit(3)
import mujoco, numpy as np
from robot_hoi.sim.video import StateRenderer, add_ghost_skeleton
xml = '''<mujoco><worldbody><light pos="0 0 3"/><geom type="plane" size="5 5 .1"/>
<body name="b"><freejoint/><geom type="box" size=".2 .2 .5" rgba=".8 .2 .2 1"/></body></worldbody></mujoco>'''
model = mujoco.MjModel.from_xml_string(xml)
q = model.qpos0.copy(); q[2] = 0.5
ghost = q.copy(); ghost[1] = 0.8
with StateRenderer(model, (160, 120), distance=3.0) as r:
    plain = r.render(q).astype(int)
    ghosted = r.render(q, ghost_qpos=ghost).astype(int)
    skeleton = r.render(q, decorate=lambda s: add_ghost_skeleton(s, np.array([[0, .8, .2], [0, .8, 1.]]), [(0, 1)]))
print(int((np.abs(ghosted - plain).sum(-1) > 30).sum()), int((np.abs(skeleton.astype(int) - plain).sum(-1) > 30).sum()))
"""


def test_ghost_is_drawn_beside_the_robot():
    done = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=300)
    if done.returncode == NO_GL:
        pytest.skip("no offscreen OpenGL backend (egl, osmesa) here")
    assert done.returncode == 0, done.stderr[-2000:]
    ghost_pixels, skeleton_pixels = map(int, done.stdout.split())
    assert ghost_pixels > 200 and skeleton_pixels > 20


def test_sim2sim_ghost_follows_the_policy_clock():
    from deploy.safety import Phase
    from sim2sim.video import reference_qpos

    frames = 10
    motion = SimpleNamespace(
        fps=50.0, num_frames=frames, root_pos=np.arange(frames)[:, None] * np.ones(3),
        root_quat_wxyz=np.tile([1.0, 0, 0, 0], (frames, 1)), joint_pos=np.arange(frames)[:, None] * np.ones(3),
        object_pos=-np.arange(frames)[:, None] * np.ones(3), object_quat_wxyz=np.tile([1.0, 0, 0, 0], (frames, 1)))
    layout = SimpleNamespace(body_qpos=np.array([7, 8]), hand_qpos=np.array([9]), object_qpos=10)
    times = np.arange(8) / 50.0
    phase = np.array([Phase.HOLD] * 2 + [Phase.POLICY] * 6)
    trace = {"qpos": np.zeros((8, 17)), "time_s": times, "phase": phase}
    ghost = reference_qpos(trace, motion, layout, warmup_frames=2)
    # ticks since the policy started: 0 0 | 0 1 2 3 4 5 -> frames after a 2-tick warmup: 0 0 0 0 0 1 2 3
    assert ghost[:, 0].tolist() == [0, 0, 0, 0, 0, 1, 2, 3]
    assert ghost[-1, 7:10].tolist() == [3, 3, 3] and ghost[-1, 10] == -3
