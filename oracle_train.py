"""Train the simulated teacher (the oracle) for INFORM (docs/protocol.md, "Oracles and the expert bar").

Pusher and other continuous-action tasks: SAC (CleanRL's sac_continuous_action.py) on the env reward from random
starts, step for step the SAC of `inform_sac_pusher.py --train-oracle`. The oracle written is the best periodic
evaluation's networks (as SB3's EvalCallback keeps), judged again on held-out starts; `inform_sac_pusher.py
--oracle-path` reads it with torch.load(weights_only=True). The maze (`--env-id KnoxStoneMaze-v0`, ...): `--method
value-iteration` (exact Q*, the default), `q-learning` (an imperfect teacher like the authors') or `dqn` (CleanRL's
dqn.py), saved as the 30 x 4 `q_table` that `inform_dqn_gridworld.py --oracle-path` loads.

inform_utils/ imports only the names that tests/test_surface.py declares for this script.

    python oracle_train.py --env-id Pusher-v5 --total-timesteps 200000   # into runs/{run}/oracle.pt, never oracles/
    python oracle_train.py --env-id KnoxStoneMaze-v0 --method dqn --maze-dqn-timesteps 20000
"""

import errno
import importlib.util
import io
import json
import math
import os
import random
import signal
import sys
import time
import zipfile
from dataclasses import asdict, dataclass, fields, replace
from typing import Annotated, Literal, get_type_hints

import gymnasium as gym
import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F
import tyro
from torch.utils.tensorboard import SummaryWriter

import gridworld_env
import inform_sac_pusher as isp  # Pusher's env as the core script builds it (make_env: the contact, Pusher-v4)

PUSHER_IDS = ("Pusher-v5", "Pusher-v4")
MAZE_IDS = tuple(gridworld_env.ENV_IDS)
METHODS = {"sac": ("sac",), "maze": ("value-iteration", "q-learning", "dqn")}  # SAC: Pusher or any continuous env
LOG_STD_MIN = -5.0
LOG_STD_MAX = 2.0
# Reset seeds of the evaluations, starts training never sees (it seeds its env once, then the env's RNG runs on).
# Selection uses one block every time, so its numbers compare across steps; the written oracle is judged on another.
SELECTION_EVAL_SEED = 1_000_000
FINAL_EVAL_SEED = 20_000
# the expert bar (docs/protocol.md): over 100 random starts, success >= 0.95 and, on Pusher, final distance <= 0.06
EXPERT_SUCCESS_RATE = 0.95
EXPERT_FINAL_DISTANCE = 0.06


@dataclass(frozen=True)
class Range:
    """A flag's values, beside it (tyro passes it by, check_args reads it): finite, in [low, high] or (low, high]."""

    low: float = -math.inf
    high: float = math.inf
    open_low: bool = False

    def check(self, flag: str, value) -> None:
        if value is None or (math.isfinite(value) and value <= self.high and
                             (value > self.low if self.open_low else value >= self.low)):  # fmt: skip
            return
        low = f"{'>' if self.open_low else '>='} {self.low}" if self.low > -math.inf else "finite"
        bound = f"in {'(' if self.open_low else '['}{self.low}, {self.high}]" if self.high < math.inf else low
        raise InputError(f"{flag} must be {bound}, got {value}")


POSITIVE_INT, POSITIVE, PROBABILITY = Range(1), Range(0, open_low=True), Range(0, 1)


@dataclass
class Args:
    exp_name: str = "oracle_sac"
    """the name of this experiment (its run directory's, under runs/)"""
    seed: Annotated[int, Range(0, 2**32 - 1)] = 1
    """seed of the experiment"""
    torch_deterministic: bool = True
    """if toggled, `torch.backends.cudnn.deterministic=True`"""
    cuda: bool = False
    """if toggled, cuda will be used when available"""
    save_model: bool = True
    """whether to write the oracle checkpoint to `output_path`"""
    track: bool = False
    """if toggled, mirror the TensorBoard events to Weights & Biases (`pip install wandb`; WANDB_MODE=offline works)"""
    wandb_project_name: str = "inform"
    """the Weights & Biases project"""
    wandb_entity: str | None = None
    """the Weights & Biases team or user (None: your default)"""
    num_threads: Annotated[int, POSITIVE_INT] = 1
    """number of torch CPU threads (1 keeps a second core free; more is faster and changes the numbers)"""
    bf16: bool = False
    """opt-in speed: the SAC updates' forward passes in bfloat16 (CPU autocast; changes the numbers)"""
    capture_video: bool = False
    """film the written oracle's first three held-out evaluation episodes into runs/{run}/videos/oracle.mp4"""

    # Oracle (SAC) arguments
    env_id: str = "Pusher-v5"
    """Pusher-v5, Pusher-v4 (where mujoco<3 is installed), any continuous-action Gymnasium env (SAC), or a maze id"""
    contact: Literal[isp.CONTACTS] = "mujoco-2.3"
    """Pusher's contact: mujoco-2.3 as MuJoCo 2.3 made it (contact_as_mujoco23: the arm pushes the object); gymnasium:
    as the installed MuJoCo makes it (on mujoco>=3 the arm passes through the object, Gymnasium #1576)"""
    reward_dist_weight: Annotated[float | None, POSITIVE] = None
    """the weight of the object-to-goal distance in the training env's reward (Pusher-v5's reward_dist_weight; None:
    the env's, 1): the teacher's Q then values that reward (docs/protocol.md). The evaluations that choose and judge
    the teacher run the env's own reward, so success stays a final distance below --success-distance"""
    success_distance: Annotated[float, POSITIVE] = 0.08
    """an evaluation episode succeeds if its final distance |info[success_info_key]| is below this"""
    success_info_key: str = "reward_dist"
    """the `info` entry whose absolute value at an episode's end is its final distance (Pusher's, Reacher's)"""
    success_return: Annotated[float | None, Range()] = None
    """if set, an episode succeeds if its return is at least this (and the return breaks selection's ties)"""
    total_timesteps: Annotated[int, POSITIVE_INT] = 200000
    """total environment steps of SAC training"""
    buffer_size: Annotated[int, POSITIVE_INT] = 1000000
    """the replay memory buffer size (capped at total_timesteps)"""
    gamma: Annotated[float, PROBABILITY] = 0.99
    """the discount factor gamma (SAC, and every maze method)"""
    tau: Annotated[float, Range(0, 1, open_low=True)] = 0.005
    """target smoothing coefficient"""
    batch_size: Annotated[int, POSITIVE_INT] = 256
    """the batch size of sample from the replay memory"""
    learning_starts: Annotated[int, POSITIVE_INT] = 5000
    """timestep to start learning (random actions before, or the --init-from actor's)"""
    policy_lr: Annotated[float, POSITIVE] = 3e-4
    """the learning rate of the policy network optimizer"""
    q_lr: Annotated[float, POSITIVE] = 1e-3
    """the learning rate of the Q network optimizer"""
    policy_frequency: Annotated[int, POSITIVE_INT] = 2
    """the frequency of policy and entropy updates (delayed, one update each time)"""
    hidden_size: Annotated[int, POSITIVE_INT] = 256
    """width of the two hidden layers of actor and critics"""
    autotune: bool = True
    """automatic tuning of the entropy coefficient"""
    ent_coef: Annotated[float, POSITIVE] = 0.2
    """the entropy coefficient when it is not autotuned (CleanRL's --alpha)"""
    layer_norm: bool = False
    """LayerNorm after each hidden layer of the critics (RLPD's; kept in the teacher's kwargs)"""

    # Learning from demonstrations (docs/protocol.md, "A teacher from demonstrations")
    demos: str | None = None
    """an .npz of demonstrations (`python -m inform_utils.pusher_control --save-demos`), sampled as --demo-ratio of
    every batch (RLPD, Ball et al. 2023); their steps count in --total-timesteps (the agent's own start after them)"""
    demo_ratio: Annotated[float, PROBABILITY] = 0.5
    """the share of every SAC batch drawn from --demos (RLPD's symmetric sampling: 0.5)"""
    clone_steps: Annotated[int, Range(0)] = 0
    """with --demos: before SAC, clone the successful demonstrations into the actor for this many gradient steps,
    then warm the critics on every demonstration for as many (the actor fixed); the actor acts from the first step"""

    # Evaluation, logging and checkpointing
    eval_frequency: Annotated[int, POSITIVE_INT] = 10000
    """evaluate the deterministic policy every this many steps; the best evaluation's networks are kept as best.pt"""
    eval_episodes: Annotated[int, POSITIVE_INT] = 100
    """random-start episodes per periodic evaluation (the same reset seeds every time, never used in training)"""
    final_eval_episodes: Annotated[int, POSITIVE_INT] = 100
    """random-start episodes of the final, held-out evaluation of the written oracle (other reset seeds again)"""
    log_frequency: Annotated[int, POSITIVE_INT] = 1000
    """log losses and SPS every this many steps"""
    checkpoint_frequency: Annotated[int, POSITIVE_INT] = 10000
    """write the resumable training state every this many steps"""
    stop_at_expert: bool = False
    """end training at the first periodic evaluation that meets the expert bar (EXPERT_SUCCESS_RATE, ...)"""
    snapshot_frequency: Annotated[int, POSITIVE_INT] = 50000
    """keep a copy of the oracle checkpoint (oracle_step{N}.pt in the run dir) every this many steps"""
    resume: str | None = None
    """path of a training_state.pt to continue from (same run directory, the run's own flags; --total-timesteps and
    the logging flags may change)"""
    init_from: str | None = None
    """warm start: the actor and twin critics of this SAC teacher (oracle_train.py's checkpoint, same observation and
    action sizes), acting from the first step; the entropy coefficient starts at --ent-coef"""
    output_path: str | None = None
    """where the final oracle checkpoint is written (default: the run directory's oracle.pt for SAC,
    oracles/{env_id}__{method}_oracle.pt for the maze); an existing file is replaced only with --overwrite"""
    overwrite: bool = False
    """allow --output-path to replace an existing checkpoint (a shipped teacher under oracles/, say)"""

    # Maze oracles
    method: str | None = None
    """sac (continuous envs), or value-iteration (exact Q*), q-learning or dqn (the maze); default: the first"""
    maze_episodes: Annotated[int, POSITIVE_INT] = 50
    """episodes of the maze's tabular Q-learning (--method q-learning)"""
    maze_alpha: Annotated[float, Range(0, 1, open_low=True)] = 0.2
    """step size of the maze's tabular Q-learning"""
    maze_epsilon: Annotated[float, PROBABILITY] = 0.1
    """exploration rate of the maze's tabular Q-learning"""
    maze_dqn_timesteps: Annotated[int, POSITIVE_INT] = 20000
    """environment steps of the maze DQN (--method dqn)"""
    maze_dqn_learning_rate: Annotated[float, POSITIVE] = 1e-3
    """Adam learning rate of the maze DQN"""
    maze_dqn_hidden: Annotated[int, POSITIVE_INT] = 64
    """width of the maze DQN's two hidden layers"""
    maze_dqn_buffer_size: Annotated[int, POSITIVE_INT] = 10000
    """replay memory size of the maze DQN"""
    maze_dqn_batch_size: Annotated[int, POSITIVE_INT] = 128
    """batch size of the maze DQN"""
    maze_dqn_learning_starts: Annotated[int, Range(0)] = 1000
    """environment steps before the maze DQN's first gradient step"""
    maze_dqn_train_frequency: Annotated[int, POSITIVE_INT] = 2
    """environment steps between the maze DQN's gradient steps"""
    maze_dqn_target_network_frequency: Annotated[int, POSITIVE_INT] = 100
    """environment steps between copies of the maze DQN into its target network"""
    maze_dqn_start_e: Annotated[float, PROBABILITY] = 1.0
    """starting epsilon of the maze DQN's exploration"""
    maze_dqn_end_e: Annotated[float, PROBABILITY] = 0.05
    """final epsilon of the maze DQN's exploration"""
    maze_dqn_exploration_fraction: Annotated[float, POSITIVE] = 0.5
    """fraction of --maze-dqn-timesteps over which epsilon decays from start to end"""

    def outcome(self) -> "Outcome":
        """How this run judges an episode (--success-info-key, --success-distance, --success-return)."""
        return Outcome(self.success_info_key, self.success_distance, self.success_return)


def make_env(env_id: str, seed: int, reward_dist_weight: float | None = None, contact="mujoco-2.3", **render):
    """The core script's make_env: Pusher on MuJoCo 2.3's contact (or MuJoCo's own), Pusher-v4 on any MuJoCo."""
    return isp.make_env(env_id, seed, None, contact, **env_kwargs(reward_dist_weight), **render)


def env_kwargs(reward_dist_weight: float | None) -> dict:
    return {} if reward_dist_weight is None else {"reward_dist_weight": reward_dist_weight}


# ALGO LOGIC: the networks (copied verbatim from inform_sac_pusher.py, CleanRL style; a test keeps the copies alike)
class BatchedLinear(nn.Module):
    """`n` independent linear layers in one batched matmul: x [n, B, in] -> [n, B, out]."""

    def __init__(self, n: int, in_features: int, out_features: int):
        super().__init__()
        self.weight = nn.Parameter(torch.empty(n, in_features, out_features))
        self.bias = nn.Parameter(torch.empty(n, 1, out_features))
        bound = 1.0 / math.sqrt(in_features)  # nn.Linear's default init
        nn.init.uniform_(self.weight, -bound, bound)
        nn.init.uniform_(self.bias, -bound, bound)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.baddbmm(self.bias, x, self.weight)


# held source-identical in inform_sac_pusher.py and oracle_train.py (a test): a change goes into both
class QEnsemble(nn.Module):
    """`n` Q (or H) networks as one module: twin critics with n=2, the sleep critic with n=1. Returns [n, B]."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: int = 256, n: int = 2, layer_norm: bool = False):
        super().__init__()
        self.n = n
        self.fc1 = BatchedLinear(n, obs_dim + act_dim, hidden)
        self.fc2 = BatchedLinear(n, hidden, hidden)
        self.fc3 = BatchedLinear(n, hidden, 1)
        self.register_buffer("norm", torch.ones(()) if layer_norm else None)  # RLPD's LayerNorm, a saved marker

    def forward(self, obs: torch.Tensor, act: torch.Tensor) -> torch.Tensor:
        x = torch.cat([obs, act], -1).unsqueeze(0).expand(self.n, -1, -1)
        x = F.relu(self.fc1(x) if self.norm is None else F.layer_norm(self.fc1(x), self.fc1.bias.shape[-1:]))
        x = F.relu(self.fc2(x) if self.norm is None else F.layer_norm(self.fc2(x), self.fc2.bias.shape[-1:]))
        return self.fc3(x).squeeze(-1)


class Actor(nn.Module):
    """CleanRL's SAC actor: a tanh-squashed Gaussian rescaled to the action bounds."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: int = 256, action_low=None, action_high=None):
        super().__init__()
        self.fc1 = nn.Linear(obs_dim, hidden)
        self.fc2 = nn.Linear(hidden, hidden)
        self.fc_mean = nn.Linear(hidden, act_dim)
        self.fc_logstd = nn.Linear(hidden, act_dim)
        low = torch.as_tensor(action_low if action_low is not None else -np.ones(act_dim), dtype=torch.float32)
        high = torch.as_tensor(action_high if action_high is not None else np.ones(act_dim), dtype=torch.float32)
        self.register_buffer("action_scale", (high - low) / 2.0)
        self.register_buffer("action_bias", (high + low) / 2.0)

    def forward(self, obs: torch.Tensor):
        x = F.relu(self.fc1(obs))
        x = F.relu(self.fc2(x))
        log_std = torch.tanh(self.fc_logstd(x))
        return self.fc_mean(x), LOG_STD_MIN + 0.5 * (LOG_STD_MAX - LOG_STD_MIN) * (log_std + 1)

    def get_action(self, obs: torch.Tensor, generator: torch.Generator | None = None, eps: torch.Tensor | None = None):
        """(sampled action, its log-prob [B], mean action); `generator` keeps evaluation off the training RNG; `eps`:
        the Gaussian noise, drawn beforehand."""
        mean, log_std = self(obs)
        eps = torch.randn(mean.shape, generator=generator, device=mean.device) if eps is None else eps
        x_t = mean + log_std.exp() * eps
        y_t = torch.tanh(x_t)
        log_prob = -0.5 * eps.pow(2) - log_std - 0.5 * math.log(2 * math.pi)
        log_prob = log_prob - torch.log(self.action_scale * (1 - y_t.pow(2)) + 1e-6)
        mean_action = torch.tanh(mean) * self.action_scale + self.action_bias
        return y_t * self.action_scale + self.action_bias, log_prob.sum(-1), mean_action

    def log_prob(self, obs: torch.Tensor, action: torch.Tensor, per_dimension: bool = False) -> torch.Tensor:
        """log pi(a|s) of given actions [B] (the offline criterion's expert log-likelihood); [B, act_dim] per
        action dimension."""
        mean, log_std = self(obs)
        y = ((action - self.action_bias) / self.action_scale).clamp(-1 + 1e-6, 1 - 1e-6)
        z = (torch.atanh(y) - mean) / log_std.exp()
        log_prob = -0.5 * z.pow(2) - log_std - 0.5 * math.log(2 * math.pi)
        log_prob = log_prob - torch.log(self.action_scale * (1 - y.pow(2)) + 1e-6)
        return log_prob if per_dimension else log_prob.sum(-1)


def soft_update(target: nn.Module, source: nn.Module, tau: float) -> None:
    with torch.no_grad():
        for param, target_param in zip(source.parameters(), target.parameters(), strict=True):
            target_param.lerp_(param, tau)


class ReplayBuffer:
    """Preallocated float32 transitions in a ring (SAC's, and the maze DQN's); `n` counts every one added."""

    FIELDS = ("obs", "next_obs", "act", "rew", "term")

    def __init__(self, size: int, obs_dim: int, act_dim: int, device: torch.device):
        self.size, self.n, self.device = size, 0, device
        shapes = {"obs": (obs_dim,), "next_obs": (obs_dim,), "act": (act_dim,), "rew": (), "term": ()}
        self.data = {name: torch.zeros(size, *shapes[name], device=device) for name in self.FIELDS}

    def add(self, obs: torch.Tensor, next_obs: torch.Tensor, action, reward: float, terminated: bool) -> None:
        values = (obs, next_obs, torch.as_tensor(action, device=self.device), float(reward), float(terminated))
        for name, value in zip(self.FIELDS, values, strict=True):
            self.data[name][self.n % self.size] = value
        self.n += 1

    @classmethod
    def of(cls, data: dict, device: torch.device) -> "ReplayBuffer":
        """A full buffer holding the given transitions (FIELDS, as tensors), the demonstrations'."""
        rb = cls(len(data["rew"]), data["obs"].shape[1], data["act"].shape[1], device)
        rb.data, rb.n = {name: data[name].to(device) for name in cls.FIELDS}, len(data["rew"])
        return rb

    def sample(self, batch_size: int) -> tuple[torch.Tensor, ...]:
        idx = torch.randint(0, min(self.n, self.size), (batch_size,), device=self.device)
        return tuple(self.data[name][idx] for name in self.FIELDS)


# ALGO LOGIC: SAC (Haarnoja et al. 2018; CleanRL's sac_continuous_action.py), as inform_sac_pusher.py's train_oracle
class SAC:
    """The actor, the twin critics and their target, the entropy coefficient exp(log_ent_coef), their optimizers."""

    MODULES = ("actor", "qf", "qf_target", "q_optimizer", "actor_optimizer", "ent_coef_optimizer")

    def __init__(self, obs_dim, act_dim, low, high, hidden, policy_lr, q_lr, ent_coef, autotune, device, warm=False,
                 layer_norm=False):  # fmt: skip
        self.obs_dim, self.act_dim, self.low, self.high, self.hidden = obs_dim, act_dim, low, high, hidden
        self.actor = Actor(obs_dim, act_dim, hidden, low, high).to(device)
        self.qf = QEnsemble(obs_dim, act_dim, hidden, n=2, layer_norm=layer_norm).to(device)
        self.qf_target = QEnsemble(obs_dim, act_dim, hidden, n=2, layer_norm=layer_norm).to(device)
        self.qf_target.load_state_dict(self.qf.state_dict())
        self.q_optimizer = torch.optim.Adam(self.qf.parameters(), lr=q_lr)
        self.actor_optimizer = torch.optim.Adam(self.actor.parameters(), lr=policy_lr)
        self.log_ent_coef = torch.zeros(1, device=device, requires_grad=True)
        self.ent_coef_optimizer = torch.optim.Adam([self.log_ent_coef], lr=q_lr)
        self.target_entropy, self.autotune = -float(act_dim), autotune
        if not autotune or warm:  # autotuned from scratch, it starts at 1; a warm start's at ent_coef
            self.log_ent_coef.data.fill_(math.log(ent_coef))
        self.losses = dict.fromkeys(("qf_loss", "actor_loss", "ent_coef_loss"), torch.zeros((), device=device))

    def update(self, batch, gamma: float, tau: float, update_actor: bool, amp) -> None:
        """One gradient step of the critics; of the actor and the entropy coefficient if `update_actor` (delayed)."""
        b_obs, b_next, b_act, b_rew, b_term = batch
        ent_coef = self.log_ent_coef.detach().exp()
        with amp, torch.no_grad():
            next_act, next_logp, _ = self.actor.get_action(b_next)
            min_q_next = self.qf_target(b_next, next_act).min(0).values - ent_coef * next_logp
            target_q = b_rew + (1.0 - b_term) * gamma * min_q_next
        with amp:
            qf_loss = (self.qf(b_obs, b_act) - target_q.unsqueeze(0)).pow(2).mean(-1).sum()  # summed over the twins
        self.q_optimizer.zero_grad(set_to_none=True)
        qf_loss.backward()
        self.q_optimizer.step()
        self.losses["qf_loss"] = qf_loss
        if update_actor:
            with amp:
                pi, logp, _ = self.actor.get_action(b_obs)
                actor_loss = (ent_coef * logp - self.qf(b_obs, pi).min(0).values).mean()
            self.actor_optimizer.zero_grad(set_to_none=True)
            actor_loss.backward()
            self.actor_optimizer.step()
            self.qf.zero_grad(set_to_none=True)  # the actor loss left gradients on the critic
            self.losses["actor_loss"] = actor_loss
            if self.autotune:
                ent_coef_loss = (-self.log_ent_coef.exp() * (logp.detach() + self.target_entropy)).mean()
                self.ent_coef_optimizer.zero_grad(set_to_none=True)
                ent_coef_loss.backward()
                self.ent_coef_optimizer.step()
                self.losses["ent_coef_loss"] = ent_coef_loss
        soft_update(self.qf_target, self.qf, tau)

    def warm_start(self, teacher: dict) -> None:
        """--init-from: the actor and the twin critics (their target too) of a teacher's checkpoint."""
        self.actor.load_state_dict(teacher["actor_state_dict"])
        self.qf.load_state_dict(teacher["qf_state_dict"])
        self.qf_target.load_state_dict(teacher["qf_state_dict"])


# ALGO LOGIC: the evaluation that chooses the oracle. Outcome is copied verbatim from inform_sac_pusher.py
@dataclass(frozen=True)
class Outcome:
    """How an episode is judged, in the day's success tags and in every test: its final distance |info[info_key]| at
    the end (Pusher: object to goal; NaN if the env reports no such entry), and its success: that distance below
    `distance`, or, with `min_return`, the episode's return at least that. The shortfall ranks episodes for the
    fallback expert set (lower is better): the distance, or minus the return."""

    info_key: str = "reward_dist"
    distance: float = 0.08
    min_return: float | None = None

    def __call__(self, info: dict, ep_return: float) -> tuple[float, bool, float]:
        """(final distance, success, shortfall) of an episode that ended with `info` after earning `ep_return`."""
        distance = abs(float(info[self.info_key])) if self.info_key in info else math.nan
        if self.min_return is None:
            return distance, bool(distance < self.distance), distance
        return distance, ep_return >= self.min_return, -ep_return


@torch.inference_mode()
def evaluate(actor: Actor, env: gym.Env, episodes: int, seed: int, device: torch.device, outcome: Outcome) -> dict:
    """Deterministic (mean-action) episodes from the random starts of reset seeds seed, seed + 1, ...: return, final
    distance, success. The unused sample has its own generator, so evaluating never moves the training RNG."""
    generator = torch.Generator(device=device).manual_seed(seed)
    returns, distances, successes = [], [], []
    for ep in range(episodes):
        Stop.check()
        obs, _ = env.reset(seed=seed + ep)
        done, ep_return, info = False, 0.0, {}
        while not done:
            obs_t = torch.as_tensor(obs, dtype=torch.float32, device=device).unsqueeze(0)
            obs, reward, terminated, truncated, info = env.step(actor.get_action(obs_t, generator)[2][0].cpu().numpy())
            ep_return, done = ep_return + float(reward), terminated or truncated
        distance, success, _ = outcome(info, ep_return)
        returns.append(ep_return)
        distances.append(distance)
        successes.append(success)
    env.close()
    return {"return": float(np.mean(returns)), "return_std": float(np.std(returns)),
            "final_distance": float(np.mean(distances)), "success_rate": float(np.mean(successes)),
            "episodes": episodes}  # fmt: skip


class Selection:
    """The best periodic evaluation so far (SB3's EvalCallback): by success rate, then the final distance (smaller
    is better) or, when success is by return, the return. Its networks are best.pt (a resumed run goes on from it);
    every evaluation is logged, and a row of eval_curve.csv."""

    def __init__(self, run_dir: str, outcome: Outcome):
        self.run_dir, self.path = run_dir, os.path.join(run_dir, "best.pt")
        self.by_return = outcome.min_return is not None
        self.key, self.step = (-1.0, -math.inf), None
        if os.path.isfile(self.path):
            best = torch.load(self.path, weights_only=True, map_location="cpu")
            self.key, self.step = self.rank(best["evaluation"]), best["training_steps"]

    def rank(self, evaluation: dict) -> tuple[float, float]:
        return evaluation["success_rate"], evaluation["return"] if self.by_return else -evaluation["final_distance"]

    def tie(self) -> float:  # the best's return, or its final distance
        return self.key[1] if self.by_return else -self.key[1]

    def offer(self, evaluation: dict, step: int, save, writer: SummaryWriter) -> None:
        if self.rank(evaluation) > self.key:
            self.key, self.step = self.rank(evaluation), step
            save(step, {**evaluation, "reset_seed": SELECTION_EVAL_SEED}, self.path)
        for name in ("return", "final_distance", "success_rate"):
            writer.add_scalar(f"eval/oracle_{name}", evaluation[name], step)
        writer.add_scalar("eval/best_success_rate", self.key[0], step)
        writer.add_scalar("eval/best_return" if self.by_return else "eval/best_final_distance", self.tie(), step)
        with open(os.path.join(self.run_dir, "eval_curve.csv"), "a") as f:
            f.write("step,success_rate,final_distance,return\n" if f.tell() == 0 else "")
            f.write(f"{step},{evaluation['success_rate']},{evaluation['final_distance']},{evaluation['return']}\n")


def train_sac(args: Args, resume_state: dict | None = None) -> None:
    """SAC on the env reward, with periodic evaluations choosing the checkpoint, training states and --resume."""
    torch.set_num_threads(args.num_threads)
    device = torch.device("cuda" if torch.cuda.is_available() and args.cuda else "cpu")
    random.seed(args.seed)
    np.random.seed(args.seed)
    torch.manual_seed(args.seed)
    torch.backends.cudnn.deterministic = args.torch_deterministic
    torch.use_deterministic_algorithms(args.torch_deterministic)

    env = make_env(args.env_id, args.seed, args.reward_dist_weight, args.contact)
    obs_dim, act_dim = int(np.prod(env.observation_space.shape)), int(np.prod(env.action_space.shape))
    acts_first = args.init_from is not None or args.clone_steps > 0  # the actor acts from the first step
    sac = SAC(obs_dim, act_dim, env.action_space.low, env.action_space.high, args.hidden_size, args.policy_lr,
              args.q_lr, args.ent_coef, args.autotune, device, warm=acts_first, layer_norm=args.layer_norm)  # fmt: skip
    if args.init_from is not None and args.resume is None:
        sac.warm_start(read_teacher(args.init_from, obs_dim, act_dim, args.hidden_size, args.layer_norm))
    amp = torch.autocast(device.type, dtype=torch.bfloat16, enabled=args.bf16)  # --bf16; off, it changes nothing
    rb = ReplayBuffer(min(args.buffer_size, args.total_timesteps), obs_dim, act_dim, device)
    demo_rb = clone_rb = None
    demo_id = {}
    if args.demos is not None:  # read by a helper module, imported under its flag only
        from inform_utils.demos import pretrain, read_demos

        demos = read_demos(args.demos, env, args, resume_state, InputError)
        demo_rb, clone_rb = ReplayBuffer.of(demos["all"], device), ReplayBuffer.of(demos["success"], device)
        demo_id = {"demos_sha256": demos["sha256"]}
    start_step = demo_rb.n if demo_rb is not None else 0  # the demonstrator's steps count in the budget
    if args.resume is not None:
        run_dir = os.path.dirname(os.path.abspath(args.resume))
        start_step = load_training_state(resume_state, sac, rb, args)
        np.random.seed(args.seed + start_step)
        env.action_space.seed(args.seed + start_step)
        print(f"resumed from {args.resume} at step {start_step}", flush=True)
    else:
        if args.clone_steps:  # the actor cloned from the successful demonstrations, then the critics warmed on all
            pretrain(sac, clone_rb, demo_rb, args, amp, Stop.check)  # a stop here leaves no folder: nothing to keep
        run_dir = new_run_dir(args)
    output_path = args.output_path or os.path.join(run_dir, "oracle.pt")
    writer = open_writer(args, run_dir)
    print(f"run directory: {run_dir}", flush=True)
    state_path = os.path.join(run_dir, "training_state.pt")

    def save_oracle(step: int, evaluation: dict, path: str) -> None:
        atomic_save(oracle_checkpoint(sac, args, step, evaluation), path)

    outcome = args.outcome()  # judged on the env's own reward: info["reward_dist"] is weighted
    selection = Selection(run_dir, outcome)
    obs, _ = env.reset(seed=args.seed + start_step)  # random starts: seed once, then the env RNG runs on
    obs_t = torch.as_tensor(obs, dtype=torch.float32, device=device)
    ep_return, ep_length, last_eval = 0.0, 0, {}
    t0 = t_last = time.time()
    step_last = trained = start_step  # trained: env steps so far (fewer than --total-timesteps after --stop-at-expert)
    report_every = max(1, (args.total_timesteps - start_step) // 20)
    for global_step in range(start_step, args.total_timesteps):
        Stop.check()
        if global_step < args.learning_starts and not acts_first:
            action = env.action_space.sample()
        else:
            with torch.no_grad():
                action = sac.actor.get_action(obs_t.unsqueeze(0))[0][0].cpu().numpy()
        next_obs, reward, terminated, truncated, info = env.step(action)
        next_obs_t = torch.as_tensor(next_obs, dtype=torch.float32, device=device)
        rb.add(obs_t, next_obs_t, action, reward, terminated)
        ep_return, ep_length = ep_return + float(reward), ep_length + 1
        if terminated or truncated:
            writer.add_scalar("charts/episodic_return", ep_return, global_step)
            writer.add_scalar("charts/episodic_length", ep_length, global_step)
            if not math.isnan(distance := outcome(info, ep_return)[0] / (args.reward_dist_weight or 1.0)):
                writer.add_scalar("charts/final_distance", distance, global_step)
            ep_return, ep_length = 0.0, 0
            next_obs_t = torch.as_tensor(env.reset()[0], dtype=torch.float32, device=device)
        obs_t = next_obs_t

        # ALGO LOGIC: one SAC update per env step, the actor's delayed; with --demos, --demo-ratio of the batch theirs
        if global_step >= args.learning_starts:
            batch = rb.sample(args.batch_size - (k := round(args.batch_size * args.demo_ratio) if demo_rb else 0))
            batch = tuple(torch.cat(pair) for pair in zip(demo_rb.sample(k), batch, strict=True)) if k else batch
            sac.update(batch, args.gamma, args.tau, global_step % args.policy_frequency == 0, amp)

        # TRY NOT TO MODIFY: logging, the evaluation that chooses the checkpoint, training states
        step = trained = global_step + 1
        if step % args.log_frequency == 0:
            for name, loss in sac.losses.items():
                writer.add_scalar(f"losses/{name}", loss.item(), step)
            writer.add_scalar("losses/ent_coef", sac.log_ent_coef.exp().item(), step)
            writer.add_scalar("charts/SPS", (step - step_last) / max(time.time() - t_last, 1e-9), step)
        if evaluated := step % args.eval_frequency == 0 or step == args.total_timesteps:
            last_eval = evaluate(sac.actor, make_env(args.env_id, args.seed, contact=args.contact), args.eval_episodes,
                                 SELECTION_EVAL_SEED, device, outcome)  # fmt: skip
            selection.offer(last_eval, step, save_oracle, writer)
        if step % report_every == 0 or evaluated:
            print_progress(step, start_step, args.total_timesteps, t0, last_eval, selection)
        if step % args.checkpoint_frequency == 0 or step == args.total_timesteps:
            save_training_state(state_path, sac, rb, step, args, **demo_id)
            save_oracle(step, last_eval, os.path.join(run_dir, "oracle_latest.pt"))
            if step % args.snapshot_frequency == 0:  # kept, so the teacher can be chosen by a longer evaluation later
                save_oracle(step, last_eval, os.path.join(run_dir, f"oracle_step{step:07d}.pt"))
        t_last, step_last = (time.time(), step) if step % args.log_frequency == 0 else (t_last, step_last)
        if args.stop_at_expert and evaluated and last_eval["success_rate"] >= EXPERT_SUCCESS_RATE and (
            args.env_id not in PUSHER_IDS or last_eval["final_distance"] <= EXPERT_FINAL_DISTANCE):  # fmt: skip
            print(f"[oracle] step {step}: the evaluation meets the expert bar (--stop-at-expert), training ends")
            save_training_state(state_path, sac, rb, step, args, **demo_id)
            break
    env.close()
    write_oracle(args, sac, selection, run_dir, output_path, device, trained, time.time() - t0)
    writer.close()


def write_oracle(args: Args, sac: SAC, selection: Selection, run_dir: str, output_path: str, device, trained: int,
                 train_time: float) -> None:  # fmt: skip
    """The best evaluation's networks (the last ones stay in oracle_latest.pt), judged again on held-out starts."""
    best = torch.load(selection.path, weights_only=True, map_location="cpu")
    sac.actor.load_state_dict(best["actor_state_dict"])
    sac.qf.load_state_dict(best["qf_state_dict"])
    final = evaluate(sac.actor, make_env(args.env_id, args.seed, contact=args.contact), args.final_eval_episodes,
                     FINAL_EVAL_SEED, device, args.outcome())  # fmt: skip
    chosen = best["evaluation"]
    print(f"[oracle] best evaluation at step {best['training_steps']}: success rate {chosen['success_rate']:.2f}, "
          f"final distance {chosen['final_distance']:.4f} over {chosen['episodes']:.0f} episodes; held-out eval over "
          f"{args.final_eval_episodes} other starts: return {final['return']:.2f} +- {final['return_std']:.2f} | "
          f"final distance {final['final_distance']:.4f} | success rate {final['success_rate']:.2f} | train time "
          f"{train_time:.0f}s (this session)", flush=True)  # fmt: skip
    if args.save_model:
        ckpt = oracle_checkpoint(sac, args, best["training_steps"], final)
        ckpt.update(train_time_s_this_session=float(train_time), selection_evaluation=chosen, total_timesteps=trained)
        os.makedirs(os.path.dirname(os.path.abspath(output_path)), exist_ok=True)
        atomic_save(ckpt, output_path)
        report = {"eval": final, "selection_eval": chosen, "steps": best["training_steps"], "train_time_s": train_time}
        atomic_write(os.path.join(run_dir, "oracle_eval.json"), json.dumps({**report, "args": asdict(args)}, indent=1))
        print(f"oracle written to {output_path}", flush=True)
    if args.capture_video:
        record_teacher(args, sac.actor, run_dir, device)


# ALGO LOGIC: the maze's teachers
def maze_q_learning(env: gym.Env, args: Args) -> tuple[np.ndarray, int]:
    """Tabular Q-learning on the maze's own reward; ties broken at random. Returns (Q table, env steps)."""
    rng = np.random.default_rng(args.seed)
    q = np.zeros((gridworld_env.N_CELLS, gridworld_env.N_ACTIONS))
    steps = 0
    obs, _ = env.reset(seed=args.seed)
    for _ in range(args.maze_episodes):
        Stop.check()
        s, done = int(obs.argmax()), False
        while not done:
            best = np.flatnonzero(q[s] == q[s].max())
            explore = rng.random() < args.maze_epsilon
            a = int(rng.integers(gridworld_env.N_ACTIONS)) if explore else int(rng.choice(best))
            obs, reward, terminated, truncated, _ = env.step(a)
            s_next = int(obs.argmax())
            q[s, a] += args.maze_alpha * (reward + args.gamma * (1.0 - terminated) * q[s_next].max() - q[s, a])
            s, done, steps = s_next, terminated or truncated, steps + 1
        obs, _ = env.reset()
    return q, steps


class MazeQNetwork(nn.Module):
    """CleanRL dqn.py's Q network, sized for the maze: one-hot observation -> one Q value per action."""

    def __init__(self, obs_dim: int, n_actions: int, hidden: int = 64):
        super().__init__()
        self.network = nn.Sequential(
            nn.Linear(obs_dim, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, n_actions)
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.network(x)


def maze_dqn(env: gym.Env, args: Args) -> MazeQNetwork:
    """DQN (CleanRL's dqn.py) on the maze's own reward for --maze-dqn-timesteps steps; truncation bootstraps."""
    torch.set_num_threads(args.num_threads)
    random.seed(args.seed)
    np.random.seed(args.seed)
    torch.manual_seed(args.seed)
    eye = torch.eye(gridworld_env.N_CELLS)  # the one-hot observation of cell s is eye[s]
    q_network = MazeQNetwork(gridworld_env.N_CELLS, gridworld_env.N_ACTIONS, args.maze_dqn_hidden)
    target_network = MazeQNetwork(gridworld_env.N_CELLS, gridworld_env.N_ACTIONS, args.maze_dqn_hidden)
    target_network.load_state_dict(q_network.state_dict())
    optimizer = torch.optim.Adam(q_network.parameters(), lr=args.maze_dqn_learning_rate, fused=True)
    rb = ReplayBuffer(min(args.maze_dqn_buffer_size, args.maze_dqn_timesteps), gridworld_env.N_CELLS, 1, eye.device)
    rng = np.random.default_rng(args.seed)
    env.action_space.seed(args.seed)
    s = int(env.reset(seed=args.seed)[0].argmax())
    decay_steps = max(1, int(args.maze_dqn_exploration_fraction * args.maze_dqn_timesteps))
    for global_step in range(args.maze_dqn_timesteps):
        Stop.check()
        fraction = min(global_step / decay_steps, 1.0)  # epsilon decays linearly from start_e to end_e
        if rng.random() < args.maze_dqn_start_e + (args.maze_dqn_end_e - args.maze_dqn_start_e) * fraction:
            action = int(env.action_space.sample())
        else:
            with torch.no_grad():
                action = int(q_network(eye[s]).argmax())
        obs, reward, terminated, truncated, _ = env.step(action)
        rb.add(eye[s], eye[int(obs.argmax())], action, reward, terminated)
        s = int(obs.argmax()) if not (terminated or truncated) else int(env.reset()[0].argmax())
        if global_step >= args.maze_dqn_learning_starts and global_step % args.maze_dqn_train_frequency == 0:
            b_obs, b_next, b_act, b_rew, b_term = rb.sample(args.maze_dqn_batch_size)
            with torch.no_grad():
                td_target = b_rew + args.gamma * target_network(b_next).max(1).values * (1.0 - b_term)
            loss = F.mse_loss(td_target, q_network(b_obs).gather(1, b_act.long()).squeeze(1))
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
        if global_step % args.maze_dqn_target_network_frequency == 0:
            target_network.load_state_dict(q_network.state_dict())
    return q_network


def train_maze(args: Args) -> None:
    """A maze teacher: exact Q* by value iteration, a tabular Q-learner's table or a DQN's Q over the 30 cells;
    saved as a 30 x 4 q_table (and, for the DQN, the network's state_dict with the kwargs to rebuild it)."""
    env = gym.make(args.env_id)
    variant, start, extra = env.unwrapped.variant, time.time(), {}
    if args.method == "q-learning":
        q, steps = maze_q_learning(env, args)
    elif args.method == "dqn":
        q_network, steps = maze_dqn(env, args), args.maze_dqn_timesteps
        with torch.no_grad():  # the network's Q over every one-hot state: row s = Q(one_hot(s), .)
            q = q_network(torch.eye(gridworld_env.N_CELLS)).double().numpy()
        extra["kwargs"] = {"obs_dim": gridworld_env.N_CELLS, "n_actions": gridworld_env.N_ACTIONS,
                           "hidden": args.maze_dqn_hidden}  # fmt: skip
        extra["state_dict"] = {k: v.detach().cpu().clone() for k, v in q_network.state_dict().items()}
    else:
        q, steps = gridworld_env.optimal_q(variant, args.gamma), 0
    env.close()
    length = gridworld_env.greedy_episode_length(q.argmax(1), variant)
    print(f"[oracle] {args.method} on {args.env_id}: {steps} env steps, greedy episode length {length} "
          f"({time.time() - start:.1f}s)", flush=True)  # fmt: skip
    if args.save_model:  # discrete: act_shape is the number of actions, the q_table's columns
        ckpt = {"algorithm": args.method, "env_id": args.env_id, "obs_shape": [gridworld_env.N_CELLS],
                "act_shape": [gridworld_env.N_ACTIONS], "n_actions": gridworld_env.N_ACTIONS,
                "q_table": torch.tensor(q), "gamma": args.gamma, "training_steps": steps, "training_seed": args.seed,
                "evaluation": {"episode_length": float(length)}, **extra}  # fmt: skip
        os.makedirs(os.path.dirname(os.path.abspath(args.output_path)), exist_ok=True)
        atomic_save(ckpt, args.output_path)
        print(f"oracle written to {args.output_path}", flush=True)


def main() -> None:
    # Ctrl-C, SIGTERM (Slurm's cancel and time limit, kill), SIGHUP (a closed terminal), Ctrl-\ (SIGQUIT), a CPU-time
    # limit (SIGXCPU) and SIGUSR1/2 stop training: recorded here, acted on by Stop.check() at the next loop head. An
    # ignored signal stays ignored (nohup, `&`).
    stops = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT, signal.SIGXCPU, signal.SIGUSR1,
             signal.SIGUSR2)  # fmt: skip
    for sig in stops:
        if signal.getsignal(sig) is not signal.SIG_IGN:
            signal.signal(sig, lambda signum, frame: Stop.signals.append(signal.Signals(signum).name))
    args = tyro.cli(Args)
    is_sac = args.env_id not in MAZE_IDS
    try:
        check_args(args)
        state = read_training_state(args.resume) if args.resume is not None else None
        if state is not None and "args" in state:  # the run goes on with its own flags
            args = resumed_args(args.resume, state["args"])
            check_args(args)
        if args.capture_video:
            check_video(args.env_id)
        args.method = args.method or ("sac" if is_sac else "value-iteration")
        if is_sac:
            train_sac(args, state)
        else:
            args.output_path = args.output_path or maze_output_path(args)
            train_maze(args)
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    except OSError as e:  # a full or read-only disk: one line, what could not be written; nothing partial is left
        if e.errno not in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EACCES):
            raise
        resume = f"; {resumable()}" if is_sac else ""
        print(f"failed: cannot write {e.filename}: {e.strerror}; no partial file is left{resume}", file=sys.stderr)
        sys.exit(1)
    except KeyboardInterrupt:  # nothing half-written: every file is saved atomically
        Stop.raised = True
        print(f"interrupted ({(Stop.signals or ['SIGINT'])[0]}); no oracle checkpoint was written; {resumable()}",
              file=sys.stderr)  # fmt: skip
    if Stop.signals and not Stop.raised:  # after the last loop: the oracle is complete, and the caller asked to stop
        print(f"{Stop.signals[0]} received after training finished; the oracle checkpoint is complete", file=sys.stderr)
    if Stop.signals or Stop.raised:
        sys.exit(128 + signal.Signals[(Stop.signals or ["SIGINT"])[0]].value)  # 130 SIGINT, 143 SIGTERM, 129 SIGHUP


# TRY NOT TO MODIFY: the flags' checks, stops, files, logging and videos
class InputError(Exception):
    """Bad input from the user: a flag value, a file. Reported as one line, before anything is written."""


def check_args(args: Args) -> None:
    """What tyro cannot know: each flag's Range, the env id, the method, files, the run's name. Raises InputError."""
    for name, hint in get_type_hints(Args, include_extras=True).items():
        for rule in getattr(hint, "__metadata__", ()):
            rule.check(f"--{name.replace('_', '-')}", getattr(args, name))
    maze = args.env_id in MAZE_IDS
    if args.track and importlib.util.find_spec("wandb") is None:
        raise InputError("--track needs Weights & Biases: `pip install wandb`, or run without --track")
    if args.track and maze:
        raise InputError("--track mirrors TensorBoard events, which only the SAC training writes")
    if args.method is not None and args.method not in (methods := METHODS["maze" if maze else "sac"]):
        raise InputError(f"--method {args.method} does not apply to {args.env_id}; choose one of {', '.join(methods)}")
    if args.output_path is not None and (not args.output_path or os.path.isdir(args.output_path)):
        raise InputError(f"--output-path {args.output_path!r} must name a file (it is empty or a directory)")
    output_path = args.output_path or (maze_output_path(args) if maze else None)
    if output_path is not None and os.path.lexists(output_path):
        if not os.path.isfile(output_path) or os.path.islink(output_path):
            raise InputError(f"--output-path {output_path} exists and is not a regular file; name another path")
        if not args.overwrite:
            raise InputError(f"--output-path {output_path} exists; name another path, or pass --overwrite to replace "
                             "it (a shipped teacher is replaced only on purpose)")  # fmt: skip
    for flag, path in (("init-from", args.init_from), ("resume", args.resume), ("demos", args.demos)):
        if path is not None and (maze or not os.path.isfile(path)):  # SAC's files: the maze's teachers have none
            why = "a directory, not a file" if os.path.isdir(path) else "no such file"
            raise InputError(f"--{flag} {path}: " + ("the maze trains no SAC to read it" if maze else why))
    if args.clone_steps and (args.demos is None or args.init_from is not None):
        raise InputError("--clone-steps clones demonstrations into a new actor: it needs --demos, not --init-from")
    if args.demos is None and args.demo_ratio != Args.demo_ratio:  # else recorded as a share of batches no one drew
        raise InputError(f"--demo-ratio {args.demo_ratio} is the share of --demos in each batch: it needs --demos")
    if args.batch_size > args.total_timesteps:
        raise InputError(f"--batch-size {args.batch_size} is larger than --total-timesteps {args.total_timesteps}")
    if args.maze_dqn_batch_size > args.maze_dqn_timesteps:
        raise InputError(f"--maze-dqn-batch-size {args.maze_dqn_batch_size} is larger than --maze-dqn-timesteps "
                         f"{args.maze_dqn_timesteps}")  # fmt: skip
    if args.maze_dqn_learning_starts >= args.maze_dqn_timesteps:
        raise InputError(f"--maze-dqn-learning-starts {args.maze_dqn_learning_starts} leaves no step of "
                         f"--maze-dqn-timesteps {args.maze_dqn_timesteps} to learn in")  # fmt: skip
    if len(run_name(args).encode()) > 240:  # 255 bytes a file name, less a suffix; first: a name echoed below is short
        raise InputError(f"--exp-name is too long: the run directory's name would be {len(run_name(args))} characters")
    if not args.exp_name or any(c in args.exp_name for c in "/\\") or not args.exp_name.isprintable() or \
            args.exp_name in (".", ".."):  # fmt: skip
        raise InputError(f"--exp-name {args.exp_name!r} must name one directory under runs/ (no '/', not '..')")
    if not maze:
        check_env(args)


def check_env(args: Args) -> None:
    """--env-id for SAC: a Gymnasium env with a flat observation and continuous actions, whose episodes can be judged
    (one random step shows whether `info` has --success-info-key). Raises InputError."""
    try:
        env = make_env(args.env_id, args.seed, contact=args.contact)
    except Exception as e:  # unknown id, a missing extra (box2d, ...), a version that needs other packages
        first = (str(e).strip() or type(e).__name__).splitlines()[0][:160]
        raise InputError(f"--env-id {args.env_id}: Gymnasium cannot make it ({first}); mazes: {', '.join(MAZE_IDS)}"
                         ) from None  # fmt: skip
    obs_space, act_space = env.observation_space, env.action_space
    if args.reward_dist_weight is not None:
        try:
            make_env(args.env_id, args.seed, args.reward_dist_weight).close()
        except TypeError:
            raise InputError(f"--reward-dist-weight: {args.env_id} has no reward_dist_weight (Pusher-v5 has)") from None
    if not isinstance(act_space, gym.spaces.Box):
        raise InputError(f"--env-id {args.env_id}: its actions are {type(act_space).__name__}, not continuous (Box)")
    if not isinstance(obs_space, gym.spaces.Box) or len(obs_space.shape) != 1:
        raise InputError(f"--env-id {args.env_id}: needs a flat Box observation, not {obs_space}")
    env.reset(seed=0)
    info = env.step(act_space.sample())[4]
    env.close()
    if args.success_return is None and args.success_info_key not in info:
        raise InputError(f"--env-id {args.env_id}: its info has no {args.success_info_key!r} for a final distance "
                         f"(it has: {', '.join(sorted(info)) or 'none'}); pass --success-info-key KEY, or "
                         "--success-return R to judge episodes by return")  # fmt: skip


class Stop:
    """The stop signals received (main's handler only records them); check() acts on them once, at a loop's head: in
    our own code, never inside a library call (TensorBoard's writer, a checkpoint being written)."""

    signals, raised, state = [], False, None  # state: the newest training_state.pt saved or resumed from

    @classmethod
    def check(cls) -> None:
        if cls.signals and not cls.raised:
            cls.raised = True
            raise KeyboardInterrupt


def resumable() -> str:  # what a stopped run can go on from, named: a training state only if one exists
    return f"--resume {Stop.state} continues from it" if Stop.state else "no training state was saved to resume from"


def atomic_save(obj, path: str) -> None:
    with io.BytesIO() as buffer:  # serialized in memory first, so that a full disk is an OSError of the write
        torch.save(obj, buffer)
        atomic_write(path, buffer.getvalue())


def atomic_write(path: str, data: bytes | str) -> None:
    """data to path.tmp, then renamed; if that fails, path.tmp is removed and the OSError names path."""
    try:
        with open(path + ".tmp", "wb") as f:
            f.write(data.encode() if isinstance(data, str) else data)
        os.replace(path + ".tmp", path)
    except OSError as e:
        if os.path.exists(path + ".tmp"):
            os.remove(path + ".tmp")
        raise OSError(e.errno, e.strerror, path) from None


def oracle_checkpoint(sac: SAC, args: Args, step: int, evaluation: dict) -> dict:
    """The deployable oracle: state_dicts plus everything needed to rebuild and check them, and the opt-in speed flags
    it was trained with (they change the numbers)."""
    return {"algorithm": "sac", "env_id": args.env_id, "obs_shape": [sac.obs_dim], "act_shape": [sac.act_dim],
            "kwargs": {"obs_dim": sac.obs_dim, "act_dim": sac.act_dim, "hidden": sac.hidden,
                       **({"layer_norm": True} if sac.qf.norm is not None else {})},  # fmt: skip
            "action_low": torch.as_tensor(sac.low, dtype=torch.float32),
            "action_high": torch.as_tensor(sac.high, dtype=torch.float32),
            "actor_state_dict": {k: v.detach().cpu().clone() for k, v in sac.actor.state_dict().items()},
            "qf_state_dict": {k: v.detach().cpu().clone() for k, v in sac.qf.state_dict().items()},
            "training_steps": int(step), "training_seed": args.seed, "random_starts": True,
            "bf16": bool(args.bf16), "num_threads": int(args.num_threads),
            "reward_dist_weight": args.reward_dist_weight, "contact": isp.contact_of(args.env_id, args.contact),
            "evaluation": {k: float(v) for k, v in evaluation.items()}}  # fmt: skip


def maze_output_path(args: Args) -> str:
    return os.path.join("oracles", f"{args.env_id}__{args.method or 'value-iteration'}_oracle.pt")


# what --resume lets change; every other flag is the run's own (a different value is refused)
RESUME_MAY_CHANGE = ("resume", "total_timesteps", "num_threads", "cuda", "output_path", "overwrite", "stop_at_expert",
                     "log_frequency", "checkpoint_frequency", "snapshot_frequency", "final_eval_episodes",
                     "capture_video", "track", "wandb_project_name", "wandb_entity")  # fmt: skip


def resumed_args(path: str, saved: dict) -> Args:
    """The flags of the run being resumed, with what this command line sets of RESUME_MAY_CHANGE; InputError for a
    flag that would change the run (a learning rate, the seed, the env)."""
    names = [f.name for f in fields(Args)]
    original = Args(**{k: v for k, v in saved.items() if k in names})
    args = tyro.cli(Args, default=replace(original, resume=path))
    changed = [n for n in names if n not in RESUME_MAY_CHANGE and getattr(args, n) != getattr(original, n)]
    if changed:
        flag = changed[0]
        raise InputError(f"--resume {path}: --{flag.replace('_', '-')} {getattr(args, flag)} differs from the run's "
                         f"{getattr(original, flag)}; a resumed run keeps its flags (drop it, or start a new run)"
                         )  # fmt: skip
    return args


def save_training_state(path: str, sac: SAC, rb: ReplayBuffer, step: int, args: Args, **extra) -> None:
    """What --resume needs: networks, optimizers, the replay buffer, the RNG, the flags, `extra` (the demos' digest)."""
    state = {key: getattr(sac, key).state_dict() for key in SAC.MODULES}
    state.update({f"buf_{name}": buf[: min(rb.n, rb.size)].clone() for name, buf in rb.data.items()})
    state.update(log_ent_coef=sac.log_ent_coef.detach().clone(), buf_n=rb.n, global_step=step,
                 torch_rng=torch.get_rng_state(), args=asdict(args), **extra)  # fmt: skip
    atomic_save(state, path)
    Stop.state = path


def read_training_state(path: str) -> dict:
    """torch.load(path, weights_only=True) of a training_state.pt; every way it can fail is one InputError."""
    state = load_checked(path, f"--resume {path}")
    keys = (*SAC.MODULES, "log_ent_coef", "buf_n", *(f"buf_{f}" for f in ReplayBuffer.FIELDS), "global_step")
    if not isinstance(state, dict) or any(key not in state for key in (*keys, "torch_rng")):
        raise InputError(f"--resume {path}: not a training_state.pt of oracle_train.py")
    Stop.state = path
    return state


def load_checked(path: str, where: str):
    """torch.load(path, weights_only=True) after check_crc; InputError, one line, for a pickle that could run code."""
    check_crc(path, where)
    try:
        return torch.load(path, weights_only=True, map_location="cpu")
    except Exception as e:
        raise InputError(f"{where}: refused: not a weights-only torch checkpoint ({type(e).__name__})") from None


def check_crc(path: str, where: str) -> None:
    """torch.save writes a zip archive with a CRC-32 per member, which torch.load never checks: a flipped bit would be
    used. InputError, one line, for an archive that is truncated or whose bytes changed since it was saved."""
    try:
        with zipfile.ZipFile(path) as archive:
            damaged = archive.testzip()
    except OSError as e:  # unreadable (permission denied): said so, not taken for a damaged archive
        raise InputError(f"{where}: cannot read it ({e.strerror or e})") from None
    except Exception as e:  # a damaged archive fails in many ways (BadZipFile, EOFError, a garbled name)
        raise InputError(f"{where}: not a complete torch checkpoint, or a damaged one ({e})") from None
    if damaged is not None:
        raise InputError(f"{where}: damaged since it was saved ({damaged} fails its CRC-32 check); make it again")


def read_teacher(path: str, obs_dim: int, act_dim: int, hidden: int, layer_norm: bool) -> dict:
    """--init-from: a SAC teacher's checkpoint (torch.load(weights_only=True)) that fits this env and --hidden-size."""
    teacher = load_checked(path, f"--init-from {path}")
    if not isinstance(teacher, dict) or teacher.get("algorithm") != "sac" or "actor_state_dict" not in teacher:
        raise InputError(f"--init-from {path}: not a SAC teacher of oracle_train.py")
    kwargs = teacher.get("kwargs", {})
    if (kwargs.get("obs_dim"), kwargs.get("act_dim")) != (obs_dim, act_dim) or kwargs.get("hidden") != hidden:
        raise InputError(f"--init-from {path}: its networks are {kwargs} (from {teacher.get('env_id')}); this run's "
                         f"are obs_dim {obs_dim}, act_dim {act_dim}, hidden {hidden} (--hidden-size)")  # fmt: skip
    if kwargs.get("layer_norm", False) != layer_norm:
        raise InputError(f"--init-from {path}: its critics are {'with' if not layer_norm else 'without'} LayerNorm; "
                         f"pass {'--layer-norm' if not layer_norm else '--no-layer-norm'}")  # fmt: skip
    return teacher


def load_training_state(state: dict, sac: SAC, rb: ReplayBuffer, args: Args) -> int:
    """Networks, optimizers, replay buffer and torch RNG from read_training_state's dict; returns its step."""
    try:
        for key in SAC.MODULES:
            getattr(sac, key).load_state_dict(state[key])
        sac.log_ent_coef.data.copy_(state["log_ent_coef"])
        rb.n = int(state["buf_n"])
        for name, buf in rb.data.items():
            buf[: min(rb.n, rb.size)] = state[f"buf_{name}"][: min(rb.n, rb.size)]
        torch.set_rng_state(state["torch_rng"])
    except (RuntimeError, ValueError, TypeError, KeyError, IndexError) as e:  # nothing is written before this
        first = (str(e).strip() or type(e).__name__).splitlines()[0][:160]
        raise InputError(f"--resume {args.resume}: does not fit this run ({type(e).__name__}: {first})") from None
    if args.seed + int(state["global_step"]) >= 2**32:  # numpy's seeds are below 2**32
        raise InputError(f"--resume: the run goes on with numpy's seed --seed + {state['global_step']}, over 2**32")
    return int(state["global_step"])


def run_name(args: Args) -> str:
    return f"{args.env_id}__{args.exp_name}__{args.seed}__{int(time.time())}"


def new_run_dir(args: Args) -> str:
    """runs/{run_name}, never an existing directory (a suffix _1, _2, ... when one run started in the same second)."""
    run_dir, suffix = os.path.join("runs", run_name(args)), 0
    while os.path.exists(run_dir):
        suffix += 1
        run_dir = os.path.join("runs", f"{run_name(args)}_{suffix}")
    os.makedirs(run_dir)
    return run_dir


def open_writer(args: Args, run_dir: str) -> SummaryWriter:
    """TensorBoard's writer (and the hyperparameter table, once per run); with --track, Weights & Biases first."""
    if args.track:
        import wandb

        wandb.init(project=args.wandb_project_name, entity=args.wandb_entity, sync_tensorboard=True, config=vars(args),
                   name=os.path.basename(run_dir), dir=run_dir, save_code=True)  # fmt: skip
    writer = SummaryWriter(run_dir)
    if args.resume is None:
        table = "\n".join(f"|{key}|{value}|" for key, value in vars(args).items())
        writer.add_text("hyperparameters", "|param|value|\n|-|-|\n" + table)
    return writer


def print_progress(step: int, start_step: int, total: int, t0: float, evaluation: dict, selection: Selection) -> None:
    sps = (step - start_step) / max(time.time() - t0, 1e-9)
    eta = (total - step) / max(sps, 1e-9)
    ev = (f" | eval return {evaluation['return']:.1f} dist {evaluation['final_distance']:.3f} success "
          f"{evaluation['success_rate']:.2f} | best {selection.key[0]:.2f} / {selection.tie():.3f} at "
          f"{selection.step}") if evaluation else ""  # fmt: skip
    print(f"[oracle] {step}/{total} {100 * step // total}% | {sps:.0f} SPS | ETA {int(eta // 60)}m{int(eta % 60):02d}s"
          f"{ev}", flush=True)  # fmt: skip


# --capture-video: the oracle's episodes rendered headless (MUJOCO_GL) by Gymnasium's RenderCollection, Pusher seen
# from above (make_env's camera: inform_sac_pusher.py's), mp4 by imageio-ffmpeg
VIDEO_SIZE = 480  # pixels, square; a multiple of 16, as H.264 wants
VIDEO_EPISODES = 3


def video_env(env_id: str, size: int = VIDEO_SIZE, contact: str = "mujoco-2.3") -> gym.Env:
    """The env, rendering every reset and step into one list (Pusher from above, no shadows: the core script's)."""
    env = make_env(env_id, 0, contact=contact, render_mode="rgb_array", width=size, height=size)
    return gym.wrappers.RenderCollection(env, reset_clean=False)


def check_video(env_id: str) -> None:
    """Before anything is written: MuJoCo renders headless here and mp4 can be written (inform_utils/videos.py,
    imported only under --capture-video); InputError, one line, if not."""
    if env_id in MAZE_IDS:
        raise InputError(f"--capture-video films a SAC teacher; inform_dqn_gridworld.py draws the maze's, not {env_id}")
    from inform_utils import videos

    if (problem := videos.gl_problem(lambda: video_env(env_id, size=16))) is not None:
        raise InputError(problem)


def record_teacher(args: Args, actor: Actor, run_dir: str, device: torch.device) -> None:
    """The oracle's first VIDEO_EPISODES held-out evaluation episodes, back to back in videos/oracle.mp4, and their
    evaluation (the held-out one's on its first episodes) in videos/videos.json."""
    os.makedirs(os.path.join(run_dir, "videos"), exist_ok=True)
    env, t0 = video_env(args.env_id, contact=args.contact), time.time()
    evaluation = evaluate(actor, env, VIDEO_EPISODES, FINAL_EVAL_SEED, device, args.outcome())
    frames = env.render()
    from inform_utils.videos import write_video  # checked by check_video

    write_video(path := os.path.join(run_dir, "videos", "oracle.mp4"), frames, env.metadata["render_fps"])
    record = {"file": "oracle.mp4", "size": list(frames[0].shape), "frames": len(frames), "evaluation": evaluation}
    atomic_write(os.path.join(run_dir, "videos", "videos.json"),
                 json.dumps({**record, "first_reset_seed": FINAL_EVAL_SEED}, indent=1))  # fmt: skip
    print(f"[video] {VIDEO_EPISODES} episodes of the oracle filmed in {time.time() - t0:.1f}s: {path}", flush=True)


if __name__ == "__main__":
    main()
