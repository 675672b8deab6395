"""Pusher's demonstrator by sampling model-predictive control on the true model (MPPI; issue 54). It reads the
simulator's state (the env's own MjData: qpos and qvel, the object's velocity too, which the observation lacks) and
plans on the env's own model; it is a demonstrator, never a teacher.

At every env step, from the env's state s, K action sequences of H steps are tried on a scratch MjData:

    U^k = clip(U + E^k, -2, 2),   E^k smooth: Gaussian at `knots` evenly spaced knots, linear in between,
                                  std sigma (the first half of the samples) or small * sigma (the second); E^0 = 0

each rolled out with mj_step, frame_skip substeps per action as the env steps, and scored by Pusher's own terms
(o_h the object, x_h the fingertip, g the goal after step h):

    C^k = sum_h w_dist |o_h - g| + w_near |x_h - o_h| + w_ctrl |u_h|^2

Then MPPI's average with the cost's spread as its temperature's unit,

    w_k = exp(-(C^k - min C) / (temperature * std C)) / Z,    U <- sum_k w_k U^k,

the env gets U_0, and U is shifted by one step (its last action repeated) to warm-start the next step. The sampler is
seeded from the episode's reset seed, so an episode is the same on every run.

What it does that the scripted PushingDemonstrator cannot (pusher_control.py's docstring: MuJoCo 4's soft contact
caps a one-capsule push near 0.05 m/s, a corner of the fork reaches 0.08-0.10): the rollouts run on the same soft
contact, so the push it keeps is one that moves the object, and w_dist, weighted far above Pusher's own 1, prefers the
faster one. It touches the object at steps 13-25 and pushes with the fork's inner corner (the crossbar and a prong at
once) at 0.055 m/s on average, up to 0.097 (starts 1000-1009). Measured on reset seeds 0-99 (docs/results.md, round
four): Pusher-v5 success 0.69, final distance 0.076 m, return -47.1 (tuned on 1000-1029: 0.53); Pusher-v4 under
MuJoCo 2.3.7, untuned, 0.99, 0.052 m. 7.2 s of CPU an episode (72 ms a step) on one thread. With 160 samples
(`--mpc-samples 160`): Pusher-v5 0.88, 0.059 m, 28 s of CPU an episode.

    python -m inform_utils.pusher_control --episodes 100 --demonstrator mpc     # on reset seeds 0-99
"""

import gymnasium as gym
import mujoco
import numpy as np

ACTION_LIMIT = 2.0  # Pusher's ctrlrange, every joint (checked against the model in __init__)


# ---------------------------------------------------------------------------------------------------------------------
# ALGO LOGIC: the rollouts' cost and MPPI's update
class MPPIDemonstrator:
    """MPPI on Pusher's true model; see the module's docstring for the equations."""

    def __init__(self, env: gym.Env, horizon: int = 25, samples: int = 40, knots: int = 4, sigma: float = 1.0,
                 small: float = 0.3, temperature: float = 0.2, w_dist: float = 10.0, w_near: float = 0.5,
                 w_ctrl: float = 0.01):  # fmt: skip
        sim = env.unwrapped
        self.model, self.env_data = sim.model, sim.data
        self.data = mujoco.MjData(self.model)  # the rollouts' scratch copy: the env's own data is only read
        self.frame_skip = sim.frame_skip
        self.nu = self.model.nu
        assert np.allclose(self.model.actuator_ctrlrange, [-ACTION_LIMIT, ACTION_LIMIT]), "Pusher's ctrlrange changed"
        self.tip, self.object, self.goal = (self.model.body(name).id for name in ("tips_arm", "object", "goal"))
        self.horizon, self.samples, self.knots = horizon, samples, knots
        self.sigma, self.small, self.temperature = sigma, small, temperature
        self.w_dist, self.w_near, self.w_ctrl = w_dist, w_near, w_ctrl  # w_dist 0: the tests' mutation
        self.reset(0)

    def reset(self, seed: int | None = None) -> None:
        self.rng = np.random.default_rng(seed)
        self.replan()

    def replan(self) -> None:
        """Forget the plan (all zeros): for a start from a state the last plan did not lead to."""
        self.plan = np.zeros((self.horizon, self.nu))

    def __call__(self, obs: np.ndarray | None = None, goal=None) -> np.ndarray:
        """The action at the env's current state (obs is not read: the state is the simulator's), towards the goal's
        body, or `goal` ((x, y) in the table's plane, at the goal's height) in its place."""
        candidates = np.clip(self.plan + self._noise(), -ACTION_LIMIT, ACTION_LIMIT)
        costs = np.array([self.cost(actions, goal) for actions in candidates])
        weights = np.exp(-(costs - costs.min()) / (self.temperature * costs.std() + 1e-12))
        self.plan = np.tensordot(weights / weights.sum(), candidates, axes=1)
        action = self.plan[0].copy()
        self.plan = np.concatenate([self.plan[1:], self.plan[-1:]])
        return action

    def _noise(self) -> np.ndarray:
        """E: (samples, horizon, nu), linear between Gaussian knots; the second half scaled by `small`, E^0 = 0."""
        at_knots = self.rng.normal(0.0, self.sigma, (self.samples, self.knots, self.nu))
        at_knots[self.samples // 2 :] *= self.small
        at_knots[0] = 0.0
        position = np.linspace(0.0, self.knots - 1, self.horizon)  # each step's place among the knots
        left = np.minimum(position.astype(int), self.knots - 2)
        frac = (position - left)[None, :, None]
        return (1 - frac) * at_knots[:, left] + frac * at_knots[:, left + 1]

    def cost(self, actions: np.ndarray, goal=None) -> float:
        """C of one action sequence, rolled out from the env's current state (g: `goal` in the goal's place)."""
        data, src = self.data, self.env_data
        data.time = src.time
        data.qpos[:], data.qvel[:], data.qacc_warmstart[:] = src.qpos, src.qvel, src.qacc_warmstart
        tips, objects = np.empty((len(actions), 3)), np.empty((len(actions), 3))
        for h, action in enumerate(actions):
            data.ctrl[:] = action
            mujoco.mj_step(self.model, data, self.frame_skip)
            tips[h], objects[h] = data.xpos[self.tip], data.xpos[self.object]
        g = data.xpos[self.goal].copy()
        if goal is not None:
            g[:2] = goal
        dist = np.linalg.norm(objects - g, axis=1)
        near = np.linalg.norm(tips - objects, axis=1)
        return float(self.w_dist * dist.sum() + self.w_near * near.sum() + self.w_ctrl * np.square(actions).sum())
