"""Pusher's fingertip, driven from first principles: an operational-space controller on MuJoCo's own Jacobian, and a
scripted pushing demonstrator built on it (issues 53 and 54). Neither is a teacher: the controller turns a target in
the table's plane into the env's 7-d action (a person's take-over at the page), the demonstrator makes demonstrations.

The arm has no gravity and torque motors (tau = gear * action, action in ctrlrange = [-2, 2]). With J the 3x7 Jacobian
of the fingertip ("tips_arm", obs[14:17]), stacked with the rows that keep the fork's crossbar level (and, if asked,
across the push), M the arm's mass matrix and x the task coordinates:

    v* = clip(kp / kd * (x_target - x), max_speed)                  (task velocity wanted, PD with a speed limit)
    Lambda = (J M^-1 J^T + eps I)^-1                                 (task-space inertia)
    tau = J^T Lambda kd (v* - J qdot) + N^T M (kq (q_post - q) - dq qdot),   N = I - J^T Lambda J M^-1

the second term a posture inside the null space of the task. A joint at a limit that tau would drive further is taken
out of the task (its column of J set to zero) and held there; the rest take the task over. tau is scaled down as a
whole, never clipped joint by joint, to stay within the action limits (its direction kept). The controller reads only
the observation (obs[:7] joint angles, obs[7:14] velocities), so it serves a policy's interface too.

What limits the push on Pusher-v5 (measured; `python -m inform_utils.pusher_contact`): not the object's mass (its
slides' armature 0.04 and damping 0.5 dwarf it, and the same xml pushes fine under MuJoCo 2.3.7: this demonstrator
scores 0.80 on starts 1000-1029 with v5's xml under 2.3.7, 0.00 under 4.0.0), but MuJoCo 4's contact: it regularises the
arm-object contact by the object's body_invweight0 = 1 / mass (1.27e5; 2.3.7 counted the armature: 16.7), so R is
~6,700 (2.3.7: 1.9) and the contact holds ~0.39 N per metre of penetration. The object moves at f / 0.5, so one
capsule pushes it at <= 0.05 m/s (deeper than 7 cm the crossbar passes through it); the fork's corners, two contacts
at once, push at <= 0.08 (inner corner, as the SAC teacher does) and <= 0.10 (outer corner). A start needs 0.1-0.3 m
of push, so the push alone takes 2-6 s of the episode's 5, and this controller's approach to behind the object takes
another 1.3-2.9 s (26-58 steps; the SAC teacher touches the object at steps 10-19). This demonstrator pushes with the
crossbar's middle, one contact: 0.03-0.04 m/s. What it would take: a corner push and an approach in under a second.
MPPIDemonstrator (pusher_mpc.py, `--demonstrator mpc`) does both by sampling MPC on the true model: 0.69 on v5.

    python -m inform_utils.pusher_control --episodes 100              # the demonstrator on reset seeds 0-99
    python -m inform_utils.pusher_control --episodes 100 --demonstrator mpc   # MPC on the true model (pusher_mpc.py)
    python -m inform_utils.pusher_control --episodes 200 --demonstrator mpc --first-seed 3000000 --save-demos demos.npz
"""

import math
import os
import time
from dataclasses import dataclass
from typing import Literal

import gymnasium as gym
import mujoco
import numpy as np
import tyro

import inform_sac_pusher as isp
from inform_utils.demos import FIELDS as DEMO_FIELDS
from inform_utils.files import BadInput, Stop, atomic, check_writable, cut, run_tool
from inform_utils.pusher_mpc import MPPIDemonstrator
from inform_utils.teacher_check import pace

ARM = 7  # the arm's joints lead qpos and qvel; the object's and the goal's slides follow
SHOULDER_XY = np.array([0.0, -0.6])  # the shoulder pan's axis in the table's plane
WORK_HEIGHT = -0.275  # the fingertip's height when pushing: the object's centre (the table at -0.325, its top -0.225)
CLEAR_HEIGHT = -0.16  # the fingertip's height when passing over the object (its crossbar 0.045 m above it)
# the posture pulled to in the null space: the shoulder's pan follows the target's bearing, the other joints stay on
# the branch that reaches the table from the shoulder's reach (0.3-0.75 m) out to the goal without meeting a limit
POSTURE = np.array([0.0, 0.9, 1.2, -1.4, 0.5, -0.4, -1.2])
PAN_OFFSET = 0.1  # radians: the pan's posture is the target's bearing plus this
UP = np.array([0.0, 0.0, 1.0])
MAX_SEED = 2**63 - 1  # the reset seeds are saved as int64
MAX_SAMPLES = 10_000  # MPPI's rollouts a step: ~2 ms of CPU each, so 10,000 are 20 s a step (and 14 MB of plans)


# ---------------------------------------------------------------------------------------------------------------------
# ALGO LOGIC: the operational-space controller
class FingertipController:
    """Joint torques (the env's action) that bring the fingertip to a point, its crossbar level; see the docstring."""

    def __init__(self, model: mujoco.MjModel, kp: float = 60.0, kd: float = 20.0, max_speed: float = 1.0,
                 posture_gain: float = 4.0, posture_damping: float = 2.0, limit_margin: float = 0.05,
                 limit_gain: float = 20.0, jacobian_gain: float = 1.0):  # fmt: skip
        self.model, self.data = model, mujoco.MjData(model)  # a scratch copy: the env's own data is never touched
        self.tip = model.body("tips_arm").id
        self.kp, self.kd, self.max_speed = kp, kd, max_speed
        self.posture_gain, self.posture_damping = posture_gain, posture_damping
        self.limit_margin, self.limit_gain = limit_margin, limit_gain
        self.jacobian_gain = jacobian_gain  # 1; 0 removes the task term (the learning-check mutation of the tests)
        self.low, self.high = model.jnt_range[:ARM].T
        self.gear = model.actuator_gear[:ARM, 0]
        self.action_low, self.action_high = model.actuator_ctrlrange[:ARM].T

    def __call__(self, obs: np.ndarray, target_xy, height: float = WORK_HEIGHT, push_direction=None) -> np.ndarray:
        """The action that drives the fingertip towards (target_xy, height); `push_direction` (a direction in the
        table's plane) also turns the fork's crossbar at right angles to it, as a push along that direction wants."""
        q, qvel = self._load(obs)
        target = np.array([target_xy[0], target_xy[1], height])
        jac, v_wanted = self._task(target, push_direction)
        tau = self._torques(jac, v_wanted, q, qvel, self._posture(target))
        action = tau / self.gear
        scale = max(1.0, float(np.max(action / np.where(action > 0, self.action_high, self.action_low))))
        return action / scale

    def _load(self, obs):
        self.data.qpos[:ARM], self.data.qvel[:ARM] = obs[:ARM], obs[ARM : 2 * ARM]
        mujoco.mj_forward(self.model, self.data)
        return self.data.qpos[:ARM].copy(), self.data.qvel[:ARM].copy()

    def _posture(self, target):
        posture = POSTURE.copy()
        bearing = np.arctan2(target[1] - SHOULDER_XY[1], target[0] - SHOULDER_XY[0])
        posture[0] = np.clip(bearing + PAN_OFFSET, self.low[0], self.high[0])
        return posture

    def _task(self, target, push_direction):
        """The task's Jacobian rows and the velocity wanted along each: the fingertip's position (3 rows), then the
        crossbar's tilt out of the table's plane (1 row), or its angle to the push's normal (2 rows)."""
        jacp, jacr = np.zeros((3, self.model.nv)), np.zeros((3, self.model.nv))
        mujoco.mj_jacBody(self.model, self.data, jacp, jacr, self.tip)
        bar = self.data.xmat[self.tip].reshape(3, 3)[:, 1]  # the crossbar's axis (the fork's local y)
        v = self.kp / self.kd * (target - self.data.xpos[self.tip])
        v *= min(1.0, self.max_speed / max(np.linalg.norm(v), 1e-12))
        if push_direction is None:  # level: d(bar . up)/dt = omega . (bar x up)
            axes, error = np.cross(bar, UP)[None], np.array([-(bar @ UP)])
        else:  # the bar along the normal n of the push (either way round): rotate by bar x n about the axes _|_ bar
            normal = np.array([-push_direction[1], push_direction[0], 0.0]) / np.linalg.norm(push_direction)
            normal *= np.sign(bar @ normal) or 1.0
            axes = np.linalg.svd(bar[None])[2][1:]  # two unit axes at right angles to the bar
            error = axes @ np.cross(bar, normal)
        jac = np.vstack([jacp[:, :ARM], axes @ jacr[:, :ARM]])
        return jac, np.concatenate([v, self.kp / self.kd * error])

    def _torques(self, jac, v_wanted, q, qvel, posture):
        """tau of the docstring, with joints at a limit (and pushed into it) taken out of the task and held."""
        m_inv = np.zeros((self.model.nv, self.model.nv))
        mujoco.mj_solveM(self.model, self.data, m_inv, np.eye(self.model.nv))  # the same call in mujoco 2.3.7 and 4
        m_inv = m_inv[:ARM, :ARM]  # the arm's block (the object and the goal are other bodies)
        mass = np.linalg.inv(m_inv)
        posture_acc = self.posture_gain * (posture - q) - self.posture_damping * qvel
        free = np.ones(ARM, bool)
        for _ in range(ARM):
            j = self.jacobian_gain * jac * free  # a locked joint's column is zero
            lam = np.linalg.inv(j @ m_inv @ j.T + 1e-3 * np.eye(len(v_wanted)))
            null = np.eye(ARM) - j.T @ lam @ j @ m_inv
            tau = j.T @ lam @ (self.kd * (v_wanted - jac @ qvel)) + free * (null.T @ mass @ posture_acc)
            acc = m_inv @ tau
            pushed = ((q > self.high - self.limit_margin) & (acc > 0)) | (
                (q < self.low + self.limit_margin) & (acc < 0)
            )
            if not (pushed & free).any():
                break
            free &= ~pushed
        edge = np.clip(q, self.low + self.limit_margin, self.high - self.limit_margin)
        hold = mass @ (self.limit_gain * (edge - q) - self.posture_damping * qvel)
        return np.where(free, tau, hold)


def arm_reach(model: mujoco.MjModel, height: float = WORK_HEIGHT) -> tuple[np.ndarray, float]:
    """(the shoulder pan's axis in the table's plane, how far from it the fingertip reaches at `height`): the arm
    stretched from the shoulder's lift joint (qpos 0 holds it straight and level), plus the lift's offset from the pan's
    axis. The controller brings the fingertip within millimetres of a target on this circle (0.767 m on Pusher v4 and
    v5) and stops a few centimetres short of one beyond it, above the table."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)  # at qpos 0
    pan, lift = (data.xanchor[model.joint(name).id] for name in ("r_shoulder_pan_joint", "r_shoulder_lift_joint"))
    arm = np.linalg.norm(data.xpos[model.body("tips_arm").id] - lift)
    return pan[:2].copy(), float(np.linalg.norm((lift - pan)[:2]) + math.sqrt(arm**2 - (lift[2] - height) ** 2))


class PersonHand:
    """A person's hand on the arm at the page (browser_pusher's --drive-by): the action that takes their target, in
    the table's plane, to the fingertip (FingertipController), or with drive_by "object" to the object (MPPI on the
    env's own model and state, pushing it there: shared autonomy). `take()` at each take and each episode's start under
    one: the planner starts afresh."""

    def __init__(self, env: gym.Env, drive_by: str = "fingertip", seed: int | None = None):
        self.drive_by = drive_by
        if drive_by == "fingertip":
            self.controller = FingertipController(env.unwrapped.model)
        else:
            self.planner = MPPIDemonstrator(env)
            self.planner.reset(seed)

    def take(self) -> None:
        if self.drive_by == "object":  # the last plan was made for a state the agent has since moved on from
            self.planner.replan()

    def __call__(self, obs: np.ndarray, target) -> np.ndarray:
        return self.controller(obs, target) if self.drive_by == "fingertip" else self.planner(goal=target)


# ---------------------------------------------------------------------------------------------------------------------
# ALGO LOGIC: the pushing demonstrator
class PushingDemonstrator:
    """A scripted push from the observation (object obs[17:20], goal obs[20:23], fingertip obs[14:17]): to a point
    `standoff` behind the object on the goal's line (round its side first if the fingertip is ahead of it), then along
    the line, the target `lead` ahead of the contact point and re-aimed at every step; round again whenever the
    fingertip leaves the line. It holds still once the object is within `done` of the goal."""

    CONTACT = 0.07  # object's radius 0.05 + the crossbar's 0.02: the fingertip's distance behind the object's centre
    CLEARANCE = 0.18  # sideways from the object's centre when going round it (the crossbar's half-length 0.12 + 0.06)

    def __init__(self, model: mujoco.MjModel, standoff: float = 0.15, lead: float = 0.08, done: float = 0.01,
                 max_lateral: float = 0.05, max_speed: float = 0.5):  # fmt: skip
        self.controller = FingertipController(model, max_speed=max_speed)
        self.standoff, self.lead, self.done, self.max_lateral = standoff, lead, done, max_lateral
        self.pushing = False

    def reset(self, seed: int | None = None) -> None:  # the seed is MPPIDemonstrator's; nothing here is random
        self.pushing = False

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        tip, obj, goal = obs[14:17], obs[17:19], obs[20:22]
        distance = np.linalg.norm(goal - obj)
        u = (goal - obj) / max(distance, 1e-9)
        n = np.array([-u[1], u[0]])
        along, lateral = (tip[:2] - obj) @ u, (tip[:2] - obj) @ n
        behind = obj - self.standoff * u
        if self.pushing and (abs(lateral) > self.max_lateral or along > 0.0):
            self.pushing = False  # off the line, or beside the object: round again
        if not self.pushing and np.linalg.norm(tip[:2] - behind) < 0.03 and tip[2] < WORK_HEIGHT + 0.03:
            self.pushing = True
        if self.pushing:
            step = 0.0 if distance < self.done else min(self.lead, distance)
            target = obj + (step - self.CONTACT) * u
        elif along > -self.standoff + 0.03 and abs(lateral) < self.CLEARANCE:  # ahead of the object: round its side
            target = behind + (np.sign(lateral) or 1.0) * self.CLEARANCE * n
        else:
            target = behind
        return self.controller(obs, target, WORK_HEIGHT, push_direction=u)


def run_episode(env: gym.Env, demonstrator: PushingDemonstrator | MPPIDemonstrator, seed: int,
                record: dict | None = None, path: list | None = None) -> tuple[float, float]:  # fmt: skip
    """(final object-to-goal distance, return) of one episode from reset(seed); the demonstrator is reset with the
    same seed (MPPIDemonstrator seeds its sampler from it). `record`: lists per DEMO_FIELDS, each step appended;
    `path`: the object's distance to the goal in the table's plane appended before each step and after the last."""
    obs, _ = env.reset(seed=seed)
    demonstrator.reset(seed)
    ep_return, done, info = 0.0, False, {}
    while True:
        Stop.check()  # a stop signal ends the run between two steps (pusher_control's command line)
        if path is not None:  # as teacher_check.final_distance measures it (the goal, fixed, at obs[20:22])
            path.append(float(np.linalg.norm(isp.object_xy(obs) - obs[20:22])))
        if done:
            break
        action = demonstrator(obs)
        next_obs, reward, terminated, truncated, info = env.step(action)
        if record is not None:  # the reward's terms too, so a teacher can re-weight them (--reward-dist-weight)
            row = (obs, action, next_obs, reward, terminated, *(info.get(k, np.nan) for k in DEMO_FIELDS[5:]))
            for name, value in zip(DEMO_FIELDS, row, strict=True):
                record[name].append(value)
        obs, ep_return, done = next_obs, ep_return + float(reward), terminated or truncated
    return abs(float(info["reward_dist"])), ep_return


def save_demos(path: str, record: dict, env_id: str, demonstrator: str, seeds, distances, success_distance,
               contact: str | None) -> None:  # fmt: skip
    """The demonstrations as one .npz of plain arrays (np.load(..., allow_pickle=False) reads it): DEMO_FIELDS per
    step (float32), per episode its reset seed, final distance and success; written whole or not at all (its folder
    made if need be), never with NaN or inf in a step (BadInput: what a teacher would refuse to read)."""
    arrays = {name: np.asarray(values, dtype=np.float32) for name, values in record.items()}
    if not all(np.isfinite(arrays[name]).all() for name in DEMO_FIELDS[:5]):  # demos.py's check of a step
        raise BadInput(f"--save-demos {path}: the demonstrator's steps hold NaN or inf (its actions diverged); "
                       "nothing was written")  # fmt: skip
    episodes = {"episode_seed": np.asarray(seeds, dtype=np.int64), "episode_distance": np.asarray(distances),
                "episode_success": np.asarray(distances) < success_distance}  # fmt: skip
    meta = {"env_id": np.str_(env_id), "demonstrator": np.str_(demonstrator), "contact": np.str_(contact)}
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with atomic(path, "wb") as f:
        np.savez_compressed(f, **arrays, **episodes, **meta)


@dataclass
class Args:
    env_id: str = "Pusher-v5"
    """the Gymnasium env (Pusher-v4 on mujoco>=3: its model in its own class, as inform_sac_pusher.py builds it)"""
    contact: Literal[isp.CONTACTS] = "mujoco-2.3"
    """Pusher's contact (inform_sac_pusher.py --contact); the MPC plans on the env's own model, so on it too"""
    episodes: int = 100
    """episodes, from reset seeds first_seed .. first_seed + episodes - 1"""
    first_seed: int = 0
    """the first reset seed (0-99 evaluate; 1000-1099 were the tuning starts)"""
    success_distance: float = 0.08
    """the Outcome's success: final |reward_dist| below this (inform_sac_pusher.Outcome)"""
    demonstrator: Literal["scripted", "mpc"] = "scripted"
    """scripted: PushingDemonstrator (this module); mpc: MPPIDemonstrator (inform_utils/pusher_mpc.py)"""
    mpc_ctrl_weight: float = 0.01
    """the MPC's weight on the torques' squares, against the object distance's 10 (the env's reward weighs them a
    tenth of the distance: 1.0 here); only with --demonstrator mpc"""
    mpc_samples: int = 40
    """action sequences the MPC tries at every step (its CPU grows with them: 160 cost 3.9x, 28 s an episode); only with
    --demonstrator mpc"""
    save_demos: str | None = None
    """write every step of the episodes to this .npz (new file) for a teacher to learn from (oracle_train.py
    --demos); pick reset seeds no evaluation uses (e.g. --first-seed 3000000)"""


def make_demonstrator(args: Args, env: gym.Env) -> PushingDemonstrator | MPPIDemonstrator:
    if args.demonstrator == "mpc":
        return MPPIDemonstrator(env, samples=args.mpc_samples, w_ctrl=args.mpc_ctrl_weight)
    return PushingDemonstrator(env.unwrapped.model)


def check_args(args: Args) -> None:
    """Before the first episode: the env, every flag's range and where the demonstrations go; BadInput, one line."""
    if args.env_id not in isp.PUSHER_IDS:
        raise BadInput(f"--env-id {cut(args.env_id, 80)}: the demonstrators push Pusher's object; pass one of "
                       f"{', '.join(isp.PUSHER_IDS)}")  # fmt: skip
    if args.episodes < 1:
        raise BadInput(f"--episodes must be >= 1, got {args.episodes}")
    last = MAX_SEED - args.episodes + 1  # the last first seed whose episodes' seeds all fit
    if not 0 <= args.first_seed <= last:
        raise BadInput(f"--first-seed {args.first_seed}: the reset seeds lie in 0 .. 2**63 - 1 (saved as int64); with "
                       f"--episodes {args.episodes} the first is at most {last}")  # fmt: skip
    if not 0 < args.success_distance < math.inf:
        raise BadInput(f"--success-distance must be a distance above 0 (metres), got {args.success_distance}")
    mpc_only = {"mpc_ctrl_weight": "weighs the MPC's torques", "mpc_samples": "sets the MPC's rollouts"}
    for field, what in mpc_only.items():
        if args.demonstrator != "mpc" and getattr(args, field) != getattr(Args, field):
            raise BadInput(f"--{field.replace('_', '-')} {what}: it needs --demonstrator mpc")
    if not 0 <= args.mpc_ctrl_weight < math.inf:
        raise BadInput(f"--mpc-ctrl-weight {args.mpc_ctrl_weight}: a price of torque is 0 or more, and finite")
    if not 2 <= args.mpc_samples <= MAX_SAMPLES:
        raise BadInput(f"--mpc-samples {args.mpc_samples}: MPPI averages 2 or more action sequences, at most "
                       f"{MAX_SAMPLES:,} here (each costs ~2 ms of CPU a step)")  # fmt: skip
    if args.save_demos is not None:
        if os.path.lexists(args.save_demos) or not args.save_demos.endswith(".npz"):
            raise BadInput(f"--save-demos {cut(args.save_demos, 200)}: name a new file ending in .npz (it exists, or "
                           "is no .npz)")  # fmt: skip
        check_writable(os.path.dirname(args.save_demos) or ".", "--save-demos")


def main(args: Args) -> None:
    check_args(args)
    env = isp.make_env(args.env_id, 0, contact=args.contact)
    demonstrator = make_demonstrator(args, env)
    demonstrator_name = "scripted"
    if args.demonstrator == "mpc":
        demonstrator_name = f"mpc ({args.mpc_samples} samples, torques weighed {args.mpc_ctrl_weight:g})"
    seeds = range(args.first_seed, args.first_seed + args.episodes)
    cpu = time.process_time()
    record = {name: [] for name in DEMO_FIELDS} if args.save_demos else None
    paths = [[] for _ in seeds]
    results = np.array(
        [run_episode(env, demonstrator, seed, record, path) for seed, path in zip(seeds, paths, strict=True)]
    )
    cpu = time.process_time() - cpu
    dt = env.unwrapped.dt
    env.close()
    distances, returns = results[:, 0], results[:, 1]
    succeeded = distances < args.success_distance
    print(f"success {succeeded.mean():.2f}, final distance {distances.mean():.3f} m, "
          f"return {returns.mean():.1f} over {args.episodes} random starts (reset seeds {seeds[0]}-{seeds[-1]}) "
          f"on {args.env_id}, the {demonstrator_name} demonstrator "
          f"({cpu / args.episodes:.2f} s of CPU an episode)")  # fmt: skip
    failed = [(seed, round(float(d), 3)) for seed, d, ok in zip(seeds, distances, succeeded, strict=True) if not ok]
    if failed:
        print(f"failed (seed, final distance): {failed}")
    for outcome, ended in (("successes", succeeded), ("failures", ~succeeded)):
        speeds = pace(np.array(paths)[ended], dt)  # teacher_check's measure of the push, for a teacher beside it
        if speeds is not None:
            print(f"pace of the {speeds['episodes']} {outcome}: the object closes on the goal at "
                  f"{speeds['peak_closing_speed']:.3f} m/s at its fastest, {speeds['last_closing_speed']:.3f} at "
                  f"the end; {speeds['still_closing']:.2f} still closing")  # fmt: skip
    if record is not None:
        contact = isp.contact_of(args.env_id, args.contact)
        save_demos(args.save_demos, record, args.env_id, demonstrator_name, seeds, distances, args.success_distance,
                   contact)  # fmt: skip
        print(f"{len(record['rew'])} steps of {args.episodes} episodes written to {args.save_demos}")


if __name__ == "__main__":
    run_tool(main, tyro.cli(Args), stops=True)
