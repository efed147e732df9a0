"""One validation episode: deploy's runtime driving the simulated G1 + Inspire hands through one clip.

run_episode(job) builds a fresh world (one MuJoCo model per episode, from the target's MJB bytes), wires the
unchanged deploy.loop.Runtime to it (simulated clock, MuJoCo body, mocap tracker, Inspire devices speaking real
bytes), runs the runtime's whole life (WAIT_STATE -> ZERO_TORQUE -> RAMP -> HOLD -> POLICY -> DAMP), and
returns plain data: the episode's metrics, the runtime's summary and, for plots and videos, traces.
Imports neither torch nor robot_hoi.sim, so worker processes stay small.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import mujoco
import numpy as np

from deploy.loop import Runtime
from deploy.observations import ObservationBuilder
from deploy.policy import OnnxPolicy
from deploy.rotations import quat_wxyz_from_axis_angle, yaw_of_quat_wxyz
from deploy.runlog import EventLog, TickRecorder
from deploy.safety import Phase, SafetyConfig
from robot_hoi import termination
from sim2sim import metrics
from sim2sim.clock import SimClock
from sim2sim.hands import SimulatedInspireHands
from sim2sim.layout import WorldLayout
from sim2sim.monitor import EpisodeMonitor, MonitoredPolicy, ReferenceTrack, Thresholds
from sim2sim.perturbations import Perturbation
from sim2sim.scene import load_model
from sim2sim.sensors import MujocoBody, MujocoTracker
from sim2sim.targets import EvalTarget
from sim2sim.world import SimWorld

# The robot hangs in the gantry during ZERO_TORQUE and the ramp, then stands on its own in HOLD before the
# policy starts: the runtime's real phases, shortened (the policy is what is being evaluated).
SIM2SIM_SAFETY = dict(zero_torque_s=0.1, ramp_s=0.5, auto_start_after_s=0.5, damp_s=0.2)
SPAWN_NOISE_XY = 0.02  # m, uniform; training's stand starts use 0.05
KEEP_ROWS = ("phase", "cmd_hand_units", "hand_angles", "hand_forces")


@dataclass
class EpisodeJob:
    policy_path: str
    policy_label: str
    target: EvalTarget
    perturbation: Perturbation
    episode: int
    seed: int
    thresholds: Thresholds = field(default_factory=Thresholds)
    hand_transport: str = "serial"
    hand_link: str = "direct"
    tracker_rate_hz: float = 120.0
    hand_rate_hz: float = 100.0
    max_frames: int | None = None  # evaluate only the first frames of the clip
    # (object m, body m): interaction success = success within these worst errors (the task config's
    # success_max_object_error / success_max_link_error); None: not judged
    success_bounds: tuple[float, float] | None = None
    keep_traces: bool = True


class MemoryRecorder(TickRecorder):
    """deploy's tick recorder keeping the few per-tick fields the report needs, in memory."""

    def __init__(self, world=None):
        super().__init__(None)
        self.rows: list[dict] = []
        self.world = world
        self.touched_object = False  # a hand touched the object at some tick (E_o means little otherwise)

    def record(self, row) -> None:
        self.ticks += 1
        self.rows.append({k: np.asarray(row[k]) for k in KEEP_ROWS})
        if self.world is not None and not self.touched_object:
            self.touched_object = bool(self.world.hand_contact().any())


_POLICIES: dict[str, OnnxPolicy] = {}
_TRACKS: dict[tuple[str, str, int], ReferenceTrack] = {}


def _policy(path: str) -> OnnxPolicy:
    if path not in _POLICIES:
        _POLICIES[path] = OnnxPolicy(path)
    return _POLICIES[path]


def start_qpos(model, layout: WorldLayout, motion, rng: np.random.Generator) -> np.ndarray:
    """The default stand (the model's 'default' keyframe) at the reference's first root position and heading."""
    key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "default")
    qpos = np.array(model.key_qpos[key][: layout.robot_nq], dtype=np.float64)
    qpos[0:2] = motion.root_pos[0, 0:2] + rng.uniform(-SPAWN_NOISE_XY, SPAWN_NOISE_XY, 2)
    yaw = float(yaw_of_quat_wxyz(motion.root_quat_wxyz[0]))
    qpos[3:7] = quat_wxyz_from_axis_angle(np.array([0.0, 0.0, 1.0]), yaw)
    return qpos


def run_episode(job: EpisodeJob) -> dict:
    wall0, cpu0 = time.perf_counter(), time.process_time()
    policy = _policy(job.policy_path)
    contract = policy.contract
    target = job.target
    motion = target.motion
    model = load_model(target.scene)
    layout = WorldLayout.resolve(model, contract)
    seeds = np.random.SeedSequence([job.seed, job.episode]).spawn(4)
    world = SimWorld(model, layout, job.perturbation, np.random.default_rng(seeds[0]))
    world.reset(start_qpos(model, layout, motion, np.random.default_rng(seeds[1])), motion.object_pos[0],
                motion.object_quat_wxyz[0])
    clock = SimClock(world)
    body = MujocoBody(world, contract.num_body, job.perturbation, np.random.default_rng(seeds[2]))
    tracker = MujocoTracker(world, job.perturbation, np.random.default_rng(seeds[3]), rate_hz=job.tracker_rate_hz)
    last_frame = motion.num_frames - 1 if job.max_frames is None else min(job.max_frames, motion.num_frames - 1)
    key = (target.name, motion.source, motion.num_frames)
    if key not in _TRACKS:  # a worker runs many episodes of the same clip
        _TRACKS[key] = ReferenceTrack.build(motion, target.object_points, target.hand_contact)
    ref = _TRACKS[key]
    warmup = contract.warmup_frames
    monitor = EpisodeMonitor(world, ref, job.thresholds, last_frame, keep_qpos=job.keep_traces,
                             warmup_frames=warmup)
    hands = SimulatedInspireHands(world, contract, clock, transport=job.hand_transport, link=job.hand_link,
                                   rate_hz=job.hand_rate_hz)
    try:
        body.connect()
        recorder = MemoryRecorder(world)
        safety = SafetyConfig(**SIM2SIM_SAFETY)
        runtime = Runtime(contract, MonitoredPolicy(policy, monitor), ObservationBuilder(contract, motion), body,
                          tracker, hands.hands, clock=clock, safety=safety, operator=monitor,
                          events=EventLog(clock), recorder=recorder)
        monitor.attach(runtime)
        pre_policy = safety.zero_torque_s + safety.ramp_s + safety.auto_start_after_s + 0.5
        run_wall0, run_cpu0 = time.perf_counter(), time.process_time()
        clock.mark_awake()
        summary = runtime.run(duration_s=pre_policy + (last_frame + warmup) / motion.fps + 2.0)
        run_wall, run_cpu = time.perf_counter() - run_wall0, time.process_time() - run_cpu0
    finally:
        hands.close()
    return _result(job, contract, world, clock, monitor, recorder, summary, (run_wall, run_cpu),
                   time.perf_counter() - wall0, time.process_time() - cpu0)


FALL_TILT_DEG = 60.0  # the pelvis leaning further than this from upright at the end: the robot is down
FALL_ROOT_HEIGHT_M = 0.2


def fell(qpos: np.ndarray) -> str | None:
    """'fell: ...' when the robot lies on the floor in state `qpos` (free base first), else None. Height alone
    misreads a deep squat, so tilt counts too."""
    w, x, y, z = qpos[3:7]
    up_z = 1.0 - 2.0 * (x * x + y * y)  # world z of the pelvis' z axis
    tilt = float(np.degrees(np.arccos(np.clip(up_z, -1.0, 1.0))))
    if tilt > FALL_TILT_DEG or qpos[2] < FALL_ROOT_HEIGHT_M:
        return f"fell: pelvis at {qpos[2]:.2f} m, tilted {tilt:.0f} deg at the end"
    return None


def _pushes_before_end(pushes: list, monitor: EpisodeMonitor, fps: float) -> int:
    """Pushes that landed while the episode counted (the world runs on through DAMP after it ended)."""
    if monitor.policy_started_at is None:
        return 0
    end = monitor.policy_started_at + (len(monitor.ticks) + 1) / fps
    return sum(t <= end for t, _ in pushes)


def _outcome(monitor: EpisodeMonitor, summary: dict, world=None) -> tuple[bool, str]:
    if monitor.terminations:
        down = fell(world.data.qpos) if world is not None else None
        return False, "terminated: " + ", ".join(monitor.terminations) + (f" ({down})" if down else "")
    if summary["faults"]:
        return False, "runtime fault: " + summary["faults"][0]
    if monitor.policy_started_at is None:
        return False, "policy never started: " + (summary["exit_reason"] or "?")
    if not monitor.reached_end:
        return False, "stopped before the clip ended: " + (summary["exit_reason"] or "?")
    return True, "reached the end of the clip"


def _result(job, contract, world, clock, monitor, recorder, summary, run_time, wall, cpu) -> dict:
    run_wall, run_cpu = run_time
    target = job.target
    motion = target.motion
    success, outcome = _outcome(monitor, summary, world)
    frames = np.asarray(monitor.frames, dtype=int)
    link_pos = np.asarray(monitor.link_pos).reshape(-1, len(contract.link_names), 3)
    link_names = list(contract.link_names)
    body_links = metrics.body_link_indices(link_names)
    root = link_names.index("pelvis") if "pelvis" in link_names else body_links[0]
    tracked = np.asarray(monitor.ticks, dtype=int) > contract.warmup_frames  # training's E_h/E_o skip the warmup
    tracking = metrics.tracking_metrics(link_pos, motion.link_pos[frames], np.asarray(monitor.object_error),
                                        body_links, root, tracked)
    interaction_success = None
    if job.success_bounds is not None:
        interaction_success = bool(success and termination.interaction_tracked(
            tracking["E_o_max_cm"] / 100, tracking["E_h_max_cm"] / 100, *job.success_bounds))
    rows = recorder.rows
    policy_rows = [r for r in rows if int(r["phase"]) == Phase.POLICY]
    def stack(key: str) -> np.ndarray:  # (policy ticks, 12); empty when the policy never ran
        return np.array([r[key] for r in policy_rows]).reshape(-1, 12)

    hand = metrics.hand_command_stats(stack("cmd_hand_units"), stack("hand_angles"), stack("hand_forces"))
    n = min(len(rows), len(clock.tick_wall_s))
    policy_tick_wall = [clock.tick_wall_s[i] for i in range(n) if int(rows[i]["phase"]) == Phase.POLICY]
    sim_s = world.t
    result = {
        "policy": job.policy_label,
        "clip": target.name,
        "perturbation": job.perturbation.name,
        "episode": job.episode,
        "seed": job.seed,
        "success": success,
        "interaction_success": interaction_success,
        "outcome": outcome,
        "terminations": list(monitor.terminations),
        "duration_s": float(len(monitor.ticks) / motion.fps),
        "evaluated_frames": len(monitor.ticks),
        "target_frames": int(monitor.last_frame),
        **tracking,
        "hand": {**hand, "bus": summary["hands"]},
        "runtime": {k: summary[k] for k in ("exit_reason", "final_phase", "faults", "ticks", "policy_steps",
                                            "phase_time_s", "overruns", "missed_deadlines", "lateness_ms",
                                            "period_error_ms", "clamped_ticks", "rate_limited_ticks",
                                            "body_send_errors")},
        "timing": {
            "policy_tick_wall_ms": metrics.percentiles_ms(policy_tick_wall),
            "sim_s": sim_s,
            "run_wall_s": run_wall,
            "run_cpu_s": run_cpu,
            "episode_wall_s": wall,
            "episode_cpu_s": cpu,
            "physics_wall_s": clock.physics_wall_s,
            "realtime_factor": sim_s / run_wall if run_wall > 0 else None,
            "pd_updates": world.pd_ticks,
            "torque_saturated_fraction": monitor.policy_torque_saturation(),
        },
        "pushes": world.pushes,
        "pushes_in_episode": _pushes_before_end(world.pushes, monitor, motion.fps),
        "object_touched": recorder.touched_object,
        "fell": fell(world.data.qpos) is not None,
    }
    if job.keep_traces:
        result["trace"] = {
            "frame_time_s": np.asarray(monitor.ticks, dtype=float) / motion.fps,
            "link_error_m": np.asarray(monitor.link_error),
            "object_error_m": np.asarray(monitor.object_error),
            "interaction_error_m": np.asarray(monitor.interaction_error),
            "hand_command": stack("cmd_hand_units").astype(np.int16),
            "hand_measured": stack("hand_angles").astype(np.int16),
            "hand_force_g": stack("hand_forces").astype(np.int32),
            "tick_wall_s": np.asarray(policy_tick_wall),
            "time_s": np.asarray(monitor.time_trace),
            "phase": np.asarray(monitor.phase_trace, dtype=np.int8),
            "qpos": np.asarray(monitor.qpos_trace, dtype=np.float32),
        }
    return result
