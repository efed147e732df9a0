"""Configuration of the interaction-imitation environment (InterMimic Sec. 3.1-3.2, supp. D-F).

Mapped from configs/tasks/interaction.yaml. The rewards come from a reward set (configs/tasks/rewards/<name>.yaml:
the aggregation and the terms; `reward_set` in the task config, or `--rewards NAME`); without one they are
InterMimic's as written (intermimic_paper: supp. F's lambdas, exp(-sum_i lambda_i * E_i), supp. D.5). A reward term
set to `null` is disabled.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import ClassVar

from robot_hoi.errors import UserError
from robot_hoi.paths import CONFIGS_DIR
from robot_hoi.termination import Thresholds
from robot_hoi.utils.config import load_dataclass, merge_dicts, read_yaml_chain


@dataclass
class RewardTermCfg:
    func: str                      # name in mdp.rewards.REWARD_TERMS
    weight: float                  # lambda of exp(-lambda * E)
    params: dict[str, float | bool] = field(default_factory=dict)
    scale: float = 1.0             # the term's share in the "sum" aggregation (ignored by "product")
    kind: str = "exp"              # "exp": exp(-lambda * E) | "penalty": -lambda * E added to the reward as it is


PAPER_REWARD_SET = "intermimic_paper"


def _default_rewards() -> dict[str, RewardTermCfg | None]:
    return load_reward_set(PAPER_REWARD_SET)[1]


# Early termination (supp. E.1) + interaction early termination (Sec. 3.2): one definition, shared with sim2sim.
TerminationCfg = Thresholds


@dataclass
class PsiCfg:
    """Physical State Initialization (supp. E.2)."""

    enabled: bool = True
    buffer_size: int = 4096
    update_probability: float = 0.005   # sparse: chance per finished rollout to write into the buffer
    return_threshold: float = 0.0       # admitted above the running mean return by this many std deviations
    sample_probability: float = 0.5     # share of non-stand resets drawn from the buffer once it has states


@dataclass
class InitCfg:
    stand_start_probability: float = 0.3   # start at clip frame 0 from the default stand (with warmup)
    spawn_noise_xy: float = 0.05           # m, stand start placement noise (uniform +-)
    # Further stand-start draws (0: off, no draw made). Evaluation's randomized protocol (configs/eval/) sets them.
    spawn_noise_yaw: float = 0.0           # rad, uniform +- on the stand's heading
    stand_joint_noise: float = 0.0         # rad, normal std on the stand's actuated body joints
    object_noise_xy: float = 0.0           # m, uniform +- on the object's start position
    object_noise_yaw: float = 0.0          # rad, uniform +- on the object's start heading (about world z)
    joint_noise: float = 0.05              # rad, reference-state initialisation noise
    start_range: tuple[float, float] = (0.0, 1.0)  # clip fraction from which reference starts are drawn
    # Failure-weighted starts: reference starts drawn per clip segment in proportion to (1 + terminations seen in
    # that segment), so training spends its samples where episodes end (BeyondMimic's adaptive sampling).
    failure_weighted: bool = False
    failure_segments: int = 20
    # Samples over which a counted termination loses half its weight (0: counts never fade). Without fading, early
    # failures (e.g. a walk-up that is long since learnt) keep their weight for the whole run. Not yet measured in a
    # learning run: the default keeps today's measured behaviour.
    failure_half_life_samples: float = 0.0
    # A reference state holds the object with no grip force (the hands rest ~1 cm off the hull; the grasp squeeze
    # is in the PD targets only): the squeeze slams the hands shut and squirts the object out. After a reference
    # start the object is held at its reference pose while the grasp loads, the hold fading linearly to none over
    # this many frames (0: off). Stand and PSI starts never settle.
    grip_settle_frames: int = 0


@dataclass
class AssistCfg:
    """Assist wrenches (curriculum, mdp/assist.py): PD pulls on the pelvis and the object toward the reference,
    annealed linearly from initial_level to 0 over anneal_samples training samples. Gains are per unit level."""

    enabled: bool = False
    initial_level: float = 1.0
    anneal_samples: float = 3.0e6
    root_kp: float = 2000.0      # N/m
    root_kd: float = 100.0       # N s/m
    root_kp_rot: float = 60.0    # N m/rad
    root_kd_rot: float = 4.0     # N m s/rad (held for a control step: 10 makes the pelvis yaw ring, measured)
    object_kp: float = 300.0
    object_kd: float = 20.0
    object_kp_rot: float = 5.0
    object_kd_rot: float = 0.3
    object_gravity_share: float = 0.5  # of the object's weight carried by the assist at full level
    # Share of episodes that get the assist at all (drawn per episode, not observed by the policy): the others
    # train the policy to balance on its own from the start. With every episode assisted the policy learned to
    # lean on the pelvis wrench and its unassisted eval duration fell from 2.4 s to 0.8 s (measured, lift_place).
    assisted_share: float = 0.5
    # Metres added to terminations.max_mean_object_point_error at full level, annealed with the level (0 = off): a
    # policy that loses the object early keeps its episode (and the object reward's gradient) through the
    # interaction, and the line tightens to the evaluated one as the assist fades. Every training episode, assisted
    # or not; never in evaluation (the assist is off there).
    object_termination_margin: float = 0.0


@dataclass
class RandomizationCfg:
    """Per-episode domain randomisation in training (evaluation uses the same keys to test one setting).

    Every value is drawn per environment at its reset from the env's generator (mdp/randomization.py); a range
    at its neutral value is off and makes no draw, so a config without it trains exactly as before. Ranges are
    uniform unless said otherwise. configs/recipes/hardware.yaml turns on what a policy for the robot needs."""

    # Object mass x scale, drawn log-uniform per episode on a 2 % grid (inertia scaled alike). (1, 1) = off.
    # A policy trained at exactly the clip's mass drops the box at x0.5 and at x2 (sim2sim robust suite).
    object_mass_scale: tuple[float, float] = (1.0, 1.0)
    # x the object's sliding friction (every contact it makes: its geoms have priority). Real boxes are
    # cardboard, plastic, wood; sim2sim checks x0.5 and x1.5.
    object_friction_scale: tuple[float, float] = (1.0, 1.0)
    # x the floor's and the robot's sliding friction (a foot-floor contact takes the larger of the two, so both
    # scale): floors differ from lab to lab (BeyondMimic trains 0.3-1.6).
    floor_friction_scale: tuple[float, float] = (1.0, 1.0)
    # x the body motors' PD stiffness and damping (position actuators' gains; the Inspire hands run their own
    # loop): the G1's drivers do not apply exactly the commanded kp/kd; sim2sim checks x0.7 and x1.3.
    kp_scale: tuple[float, float] = (1.0, 1.0)
    kd_scale: tuple[float, float] = (1.0, 1.0)
    # s: each PD target reaches the motors this late (rounded to physics steps, 4.8 ms on the G1): DDS and the
    # motor drivers add latency on the robot; sim2sim checks 20 ms.
    actuator_delay_s: tuple[float, float] = (0.0, 0.0)
    # m/s: a push adds a uniform draw in [-v, v] to the pelvis's x and y velocity, every push_interval_s (drawn
    # per push); 0 = no pushes. People and cables bump the robot (BeyondMimic pushes every 1-3 s).
    push_velocity: float = 0.0
    push_interval_s: tuple[float, float] = (1.0, 3.0)
    # m, half-widths per axis (x, y, z) of a uniform offset of the torso's centre of mass: battery, cabling and
    # payload move it on real robots (BeyondMimic: 2.5 / 5 / 5 cm).
    torso_com_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    # Observation noise (normal std, drawn every step) on the deployable (student) observation only, whose terms
    # model the robot's sensors; the teachers' privileged observation stays exact (their actions are the
    # student's labels). Defaults of the hardware recipe = sim2sim's sensor_noise condition.
    joint_pos_noise: float = 0.0    # rad, encoders (joint_pos)
    joint_vel_noise: float = 0.0    # rad/s (joint_vel)
    imu_rot_noise: float = 0.0      # rad, IMU orientation (projected_gravity)
    gyro_noise: float = 0.0         # rad/s (base_ang_vel)
    tracker_pos_noise: float = 0.0  # m, mocap positions (object_pos and every ref_* position relative to the pelvis)
    tracker_rot_noise: float = 0.0  # rad, mocap orientations (object_rot, ref_root_rot, ref_object_rot)

    def is_on(self) -> bool:
        """Whether any range or noise is away from its neutral (off) value."""
        neutral = RandomizationCfg()
        return any(_values(getattr(self, f.name)) != _values(getattr(neutral, f.name)) for f in fields(self))


def _values(value):
    return tuple(value) if isinstance(value, (list, tuple)) else value


@dataclass
class RetargetCfg:
    """How the task's references are retargeted: the task config's `retarget:` block, `--set retarget.KEY=VALUE` on
    every command that retargets (train, retarget, eval). factory.retarget_options maps it onto the retarget's
    RetargetOptions; None: the retarget's own default. Each is recorded in the cached reference: a cache made with
    another value is an error, not silently reused."""

    # settings that are gone, and why (a saved run holding one at its neutral value still loads: saved_env_cfg)
    REMOVED_KEYS: ClassVar[dict[str, str]] = {
        "fingertip_underside_reach": "it did not help the table teacher (docs/experiments/omomo_table_sub2_largetable"
                                     ".md), and the grasp's hook closes the fingers under a tabletop (retarget.grasp)",
    }

    # the IK: "dls" (damped least squares + repairs) | "qp" (constrained QP, retarget/qp.py); None: the retarget's dls
    solver: str | None = None
    # hands in held segments: the human's placement (False) or grasps planned for the Inspire hand (True,
    # retarget/grasp.py: opposing faces, pushes); None: the retarget's default
    grasp: bool | None = None
    # the leg PD targets also carry the torques that hold the body on its feet in contact. The root-held,
    # zero-residual replay of OMOMO sub8_largebox_000 (bend over to push a floor box) then reaches the box (hands
    # 2-3 cm from it at frame 13, pelvis within 1 cm) instead of hanging 20-25 cm off (pelvis 9.5 cm low); the
    # shipped base policy was trained without it
    leg_loads: bool = False
    # ... and the torques that drive the reference's motion and cancel the servos' damping along it (inverse
    # dynamics; retarget ExecutableSettings.compensate_dynamics)
    dynamics: bool = False
    # fraction of the fingers' open->closed stroke while a hand holds (None: the retarget's GraspRule default, 0.6)
    finger_closure: float | None = None
    # where a holding hand's PD targets squeeze: "other_hand" | "surface" (into the nearest face: pushes; retarget
    # ExecutableSettings.squeeze_toward; None: the retarget's "other_hand")
    squeeze_toward: str | None = None
    # m the holding hands' PD targets go past the surface (retarget ExecutableSettings.squeeze_depth; None: the
    # retarget's 0.06)
    squeeze_depth: float | None = None
    # anchor weights (links that follow the object): "distance" (from the distance to the object) | "contact" (the
    # clip's per-body contact labels where it has them; retarget TargetMapping.anchor_mode); None: the retarget's
    # "distance"
    anchor_mode: str | None = None

    def __post_init__(self) -> None:
        """Each value checked as the user spells its key (the retarget's modules, which import MuJoCo, load only for
        a value given: `robot-hoi --help` imports this module)."""
        if self.solver is not None:
            from robot_hoi.retarget.ik import IK_SOLVERS

            if self.solver not in IK_SOLVERS:
                raise UserError(f"retarget.solver must be one of {', '.join(IK_SOLVERS)}, got {self.solver!r}")
        if self.finger_closure is not None:
            from robot_hoi.retarget.hands import check_closure

            check_closure(self.finger_closure, "retarget.finger_closure")
        if self.squeeze_toward is not None:
            from robot_hoi.retarget.executable import check_squeeze_toward

            check_squeeze_toward(self.squeeze_toward, "retarget.squeeze_toward")
        if self.squeeze_depth is not None:
            from robot_hoi.retarget.executable import check_squeeze_depth

            check_squeeze_depth(self.squeeze_depth, "retarget.squeeze_depth")
        if self.anchor_mode is not None:
            from robot_hoi.retarget.targets import ANCHOR_MODES

            if self.anchor_mode not in ANCHOR_MODES:
                raise UserError(f"retarget.anchor_mode must be one of {', '.join(ANCHOR_MODES)}, "
                                f"got {self.anchor_mode!r}")


# Runs saved before the retarget: block (task.json, an exported policy's metadata) hold its settings as flat task
# keys: saved_env_cfg moves them into the block; a config or --set of the user's that spells them so is an error
# naming the new spelling.
LEGACY_RETARGET_KEYS = {f"retarget_{name}": name for name in (
    "leg_loads", "dynamics", "finger_closure", "squeeze_toward", "squeeze_depth", "fingertip_underside_reach",
    "solver", "grasp")}


@dataclass
class InteractionEnvCfg:
    # keys that moved (utils.config names their new spelling when a config still holds them)
    MOVED_KEYS: ClassVar[dict[str, str]] = {old: f"retarget.{new}" for old, new in LEGACY_RETARGET_KEYS.items()}

    embodiment: str = "g1_inspire"
    num_envs: int = 256
    backend: str = "auto"
    sim_device: str | None = None           # warp backend device ("cuda:1", "cpu"); None = cuda:0 if present, else cpu
    nthread: int | None = None
    seed: int = 0
    keyframes: tuple[int, ...] = (1, 16)    # teacher keyframes K (Sec. 4)
    teacher_obs: str = "compact"            # "compact" (~400: pelvis, joints, hands, object) | "full" (Eq. 1, ~1750)
    student_keyframes: tuple[int, ...] = (1, 2, 4, 16)  # student keyframes K (Sec. 4)
    # The deployable observation (deploy/observations.py terms, in this order); empty = no "student" group.
    student_obs_terms: tuple[str, ...] = ()
    warmup_frames: int = 15                 # stand-and-approach frames (supp. F)
    warmup_blend: bool = False              # the warmup's PD offset glides from the start pose to frame 0's joints
                                            # (deploy.contract.warmup_offset) instead of stepping there at once
    max_episode_frames: int = 300           # supp. Table C
    reference_links: str = "ik"             # "ik" (robot-reachable link targets) | "scaled_human" (pure InterMimic)
    retarget: RetargetCfg = field(default_factory=RetargetCfg)  # how the references are retargeted
    # what the object collides as: "hull" (its convex hull; checkpoints without the key) | "decomposed" (its convex
    # pieces, ObjectAsset.convex_parts: a hand reaches under a table's top). The retarget keeps the hands out of
    # the same shape; recorded in the cached retarget like the retarget: block
    object_collision: str = "hull"
    object_density: float = 25.0            # kg/m^3 of the hull (InterMimic's G1 setting); a known mass wins
    object_friction: float = 0.9            # supp. Table A
    object_torsional_friction: float = 0.0  # m; > 0: the object's contacts resist turning about their normal
    object_surface_points: int = 256        # samples for d_t
    # MuJoCo's friction model for every contact: "pyramidal" | "elliptic" cones, and impratio (frictional-to-normal
    # impedance ratio; > 1 makes friction stiffer, MuJoCo applies it to elliptic cones). Chosen by the physics gate
    friction_cone: str = "pyramidal"
    impratio: float = 1.0
    self_collision: bool = False
    action_clip: float = 4.0
    # rad/s: each step's PD targets move at most this far from the last step's, as the robot runtime shapes them
    # (deploy.safety.TargetShaper, SafetyConfig.max_target_rate). None: off (teachers); students train with the
    # runtime's limit (student.task.student_env_cfg)
    command_rate_limit: float | None = None
    # PD target = offset + action_scale * action. "reference": offset = the retargeted reference joints of the frame
    # being stepped to (the policy learns corrections; the runtime reads them from the motion sidecar);
    # "default": offset = the default pose (InterMimic's absolute targets).
    action_offset: str = "reference"
    # A reward set's name (or YAML path): on loading it replaces reward_mode and rewards and is cleared, so the
    # saved config (task.json) holds the terms themselves and `--set env.rewards.<term>...` overrides stick.
    reward_set: str | None = None
    reward_mode: str = "product"            # "product": exp(-sum lambda E) (InterMimic) | "sum": weighted sum of exps
    rewards: dict[str, RewardTermCfg | None] = field(default_factory=_default_rewards)
    terminations: TerminationCfg = field(default_factory=TerminationCfg)
    init: InitCfg = field(default_factory=InitCfg)
    psi: PsiCfg = field(default_factory=PsiCfg)
    assist: AssistCfg = field(default_factory=AssistCfg)
    randomization: RandomizationCfg = field(default_factory=RandomizationCfg)
    success_min_frames_fraction: float = 0.95  # success = tracked to (almost) the end without termination
    # interaction_success: a success (above) that also tracked the interaction: at no tracked step did the object's
    # mean surface-point error or the body's mean link error exceed these (m). The terminations (0.5 m, InterMimic)
    # let a policy "succeed" that never lifts the box: measured on lift_place, success 1.0 with the box held on the
    # floor 21 cm below the reference's lift.
    success_max_object_error: float = 0.10
    success_max_link_error: float = 0.15

    def __post_init__(self) -> None:
        # not at the top: data.objects imports trimesh and scipy (~0.7 s), and `robot-hoi --help` imports this module
        from robot_hoi.data.objects import check_object_collision

        check_object_collision(self.object_collision, ValueError)  # the config loader names the file
        if self.friction_cone not in ("pyramidal", "elliptic"):
            raise ValueError(f"friction_cone must be pyramidal or elliptic, not {self.friction_cone!r}")
        if not self.impratio >= 1.0:
            raise ValueError(f"impratio must be >= 1, got {self.impratio}")
        if self.reward_set:
            apply_reward_set(self, self.reward_set)
            self.reward_set = None


def saved_env_cfg(data: dict, source: str) -> InteractionEnvCfg:
    """The task config a run saved (task.json, an exported policy's metadata 'task'); `source` names it in errors.
    Runs saved before the retarget: block hold its settings as flat keys retarget_*: they move into the block."""
    data = dict(data)
    block = dict(data.get("retarget") or {})
    for old, new in LEGACY_RETARGET_KEYS.items():
        if old in data:
            block[new] = data.pop(old)
    for name in RetargetCfg.REMOVED_KEYS:  # saved at its neutral value (None or 0): the behaviour is today's
        if name in block and not block[name]:
            del block[name]
    if block:
        data["retarget"] = block
    return load_dataclass(InteractionEnvCfg, data, source)


def split_overrides(overrides: list[str], bare: bool = False) -> tuple[list[str], list[str]]:
    """`--set` values split into (the task config's, the others): env.KEY=VALUE gives KEY=VALUE, and
    retarget.KEY=VALUE (the retarget: block) stays as it is; `bare`: KEY=VALUE without a prefix is the task
    config's too (eval's --set). A retarget setting spelled otherwise (env.retarget.KEY, env.retarget_KEY) is an
    error naming its one spelling."""
    task: list[str] = []
    others: list[str] = []
    for item in overrides:
        key, _, value = item.partition("=")
        key = key.strip()
        name = key[len("env."):] if key.startswith("env.") else key
        head = name.partition(".")[0]
        if name in LEGACY_RETARGET_KEYS or (head == "retarget" and name != key):
            new = LEGACY_RETARGET_KEYS.get(name) or name.partition(".")[2] or "KEY"
            raise UserError(f"--set {item}: the retarget settings are the task config's retarget: block, spelled "
                            f"--set retarget.{new}={value or 'VALUE'}")
        if head == "retarget" or key.startswith("env.") or bare:
            task.append(f"{name}={value}" if name != key else item)
        else:
            others.append(item)
    return task, others


def reward_set_names() -> list[str]:
    return sorted(p.stem for p in (CONFIGS_DIR / "tasks" / "rewards").glob("*.yaml"))


def load_reward_set(name: str) -> tuple[str, dict[str, RewardTermCfg | None]]:
    """(reward_mode, rewards) of configs/tasks/rewards/<name>.yaml or of a YAML path. A set may name another as
    its `base:` and hold only what differs: a term's fields merge into the base's term, `null` disables it."""
    chain = read_yaml_chain(name, CONFIGS_DIR / "tasks" / "rewards", "reward set", {"reward_mode", "rewards"})
    data: dict = {}
    for path, layer in chain:
        if not isinstance(layer.get("rewards", {}), dict):
            raise UserError(f"{path}: rewards: expected a mapping of terms")
        data = merge_dicts(data, layer)
    path = chain[-1][0]
    if "rewards" not in data:
        raise UserError(f"{path}: a reward set needs rewards (its own or its base's)")
    rewards = {k: None if v is None else load_dataclass(RewardTermCfg, v, f"{path} rewards.{k}")
               for k, v in data["rewards"].items()}
    return data.get("reward_mode", "product"), rewards


def apply_reward_set(cfg: InteractionEnvCfg, name: str) -> None:
    """Replace the reward terms and aggregation of `cfg` with those of the reward set `name`."""
    cfg.reward_mode, cfg.rewards = load_reward_set(name)
