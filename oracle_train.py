"""Train the simulated teacher (the oracle) for INFORM (docs/protocol.md, "Oracles and the expert bar").

Pusher: a SAC agent (Haarnoja et al. 2018, CleanRL's sac_continuous_action.py) trained on the
environment reward from random initial states, so that it is an expert from any start: step for step the SAC of
`inform_sac_pusher.py --train-oracle` (a test trains both with one seed and compares the networks). The
final checkpoint holds state_dicts only (actor and twin critics) plus the arguments to rebuild
them, the env id, the observation and action shapes, the training steps and a 100-episode
evaluation; `inform_sac_pusher.py --oracle-path` loads it with torch.load(weights_only=True).

Written for speed on a few CPU cores (LeanRL habits): twin critics are one batched module,
the replay buffer and the hot-loop tensors are preallocated, there is no .item() in the loop
and scalars are logged every `log_frequency` steps only. Training state is checkpointed
atomically every `checkpoint_frequency` steps; `--resume <run_dir>/training_state.pt`
continues an interrupted run.

Maze (`--env-id KnoxStoneMaze-v0` and the other ids of gridworld_env): `--method value-iteration`
(the default) saves the exact Q*; `--method q-learning` saves the Q-table of a tabular Q-learner
after `--maze-episodes` episodes, a less than perfect teacher like the authors' half-trained table;
`--method dqn` trains a small DQN (CleanRL's dqn.py: an MLP on the one-hot observation, replay buffer,
target network, linearly decaying epsilon-greedy, Adam) for `--maze-dqn-timesteps` env steps, another
learned teacher. Every maze checkpoint holds the 30 x 4 `q_table` (for the DQN: the network's Q over the
30 one-hot states), which `inform_dqn_gridworld.py --oracle-path` loads, plus the env id, the observation
and action shapes, the training steps and the greedy episode length; the DQN's also holds its state_dict
and the arguments to rebuild it (`MazeQNetwork(**ckpt["kwargs"])`).

Other continuous-action tasks (`--env-id Reacher-v5`) train the same SAC; an evaluation episode succeeds by its final
distance |info[--success-info-key]| below --success-distance, or by its return (--success-return), as in
inform_sac_pusher.py.

Imported by inform_utils/, the only names other code may use (a test holds it to them): Actor.

Examples:
    python oracle_train.py --env-id Pusher-v5 --seed 1 --total-timesteps 200000 \
        --output-path oracles/Pusher-v5__sac_oracle.pt
    python oracle_train.py --env-id Reacher-v5 --success-distance 0.02 --total-timesteps 100000
    python oracle_train.py --env-id KnoxStoneMaze-v0 --method q-learning --maze-episodes 50
    python oracle_train.py --env-id KnoxStoneMaze-v0 --method dqn --maze-dqn-timesteps 20000
"""

import importlib.util
import json
import math
import os
import pickle
import random
import signal
import sys
import tempfile
import time
import warnings
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import asdict, dataclass

import gymnasium as gym
import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F
import tyro
from torch.utils.tensorboard import SummaryWriter

import gridworld_env

PUSHER_IDS = ("Pusher-v5", "Pusher-v4")
MAZE_IDS = tuple(gridworld_env.ENV_IDS)
METHODS = {"sac": ("sac",), "maze": ("value-iteration", "q-learning", "dqn")}  # SAC: Pusher or any continuous env
LOG_STD_MIN = -5.0
LOG_STD_MAX = 2.0
# Reset seeds of the evaluations. Training seeds its env once (--seed, or --seed + step on --resume) and then
# draws its starts from the env's own RNG, so these fixed blocks are starts it never trains from. The periodic
# evaluation uses the same block every time, so its numbers compare across steps and choose best.pt; the final
# evaluation of the written oracle uses another block, so the choice is not judged on the starts it was chosen on.
SELECTION_EVAL_SEED = 1_000_000
# the expert bar (docs/protocol.md): over 100 random starts, success >= 0.95 and, on Pusher, final distance <= 0.06
EXPERT_SUCCESS_RATE = 0.95
EXPERT_FINAL_DISTANCE = 0.06
FINAL_EVAL_SEED = 20_000
TRAINING_STATE_KEYS = (
    "actor",
    "qf",
    "qf_target",
    "q_optimizer",
    "actor_optimizer",
    "ent_coef_optimizer",
    "log_ent_coef",
    "buf_n",
    "buf_obs",
    "buf_next_obs",
    "buf_act",
    "buf_rew",
    "buf_term",
    "global_step",
    "torch_rng",
)


@dataclass
class Args:
    exp_name: str = "oracle_sac"
    """the name of this experiment"""
    seed: int = 1
    """seed of the experiment"""
    torch_deterministic: bool = True
    """if toggled, `torch.backends.cudnn.deterministic=True`"""
    cuda: bool = False
    """if toggled, cuda will be used when available"""
    save_model: bool = True
    """whether to write the oracle checkpoint to `output_path`"""
    track: bool = False
    """if toggled, mirror the TensorBoard events to Weights & Biases (CleanRL's --track; needs `pip install wandb`,
    and WANDB_MODE=offline keeps the run on this machine)"""
    wandb_project_name: str = "inform"
    """the Weights & Biases project"""
    wandb_entity: str | None = None
    """the Weights & Biases team or user (None: your default)"""
    num_threads: int = 1
    """number of torch CPU threads (1 keeps a second core free; more is faster and changes the numbers)"""
    bf16: bool = False
    """opt-in speed: the SAC updates' forward passes in bfloat16 (CPU autocast); the numbers change, a teacher need
    only be good (recorded in the checkpoint's args)"""
    capture_video: bool = False
    """film the written Pusher oracle's first three held-out evaluation episodes into runs/{run}/videos/oracle.mp4
    (headless MuJoCo: MUJOCO_GL, egl when unset and there is no display)"""

    # Oracle (SAC) arguments
    env_id: str = "Pusher-v5"
    """Pusher-v5, Pusher-v4 (where mujoco<3 is installed), any continuous-action Gymnasium env (SAC), or a maze id"""
    success_distance: float = 0.08
    """an evaluation episode succeeds if its final distance |info[success_info_key]| (Pusher: object to goal) is
    below this"""
    success_info_key: str = "reward_dist"
    """the `info` entry whose absolute value at an episode's end is its final distance (Pusher's, Reacher's)"""
    success_return: float | None = None
    """if set, an evaluation episode succeeds if its return is at least this (then the return breaks ties in the
    choice of the best checkpoint, not the distance)"""
    total_timesteps: int = 200000
    """total environment steps of SAC training"""
    buffer_size: int = 1000000
    """the replay memory buffer size (capped at total_timesteps)"""
    gamma: float = 0.99
    """the discount factor gamma (SAC, and every maze method)"""
    tau: float = 0.005
    """target smoothing coefficient"""
    batch_size: int = 256
    """the batch size of sample from the replay memory"""
    learning_starts: int = 5000
    """timestep to start learning (random actions before)"""
    policy_lr: float = 3e-4
    """the learning rate of the policy network optimizer"""
    q_lr: float = 1e-3
    """the learning rate of the Q network optimizer"""
    policy_frequency: int = 2
    """the frequency of policy and entropy updates (delayed, one update each time)"""
    hidden_size: int = 256
    """width of the two hidden layers of actor and critics"""
    autotune: bool = True
    """automatic tuning of the entropy coefficient"""
    ent_coef: float = 0.2
    """the entropy coefficient when it is not autotuned (CleanRL's --alpha)"""

    # Evaluation, logging and checkpointing
    eval_frequency: int = 10000
    """evaluate the deterministic policy every this many steps; the best evaluation's networks are kept as best.pt"""
    eval_episodes: int = 100
    """random-start episodes per periodic evaluation (the same reset seeds every time, never used in training)"""
    final_eval_episodes: int = 100
    """random-start episodes of the final, held-out evaluation of the written oracle (other reset seeds again)"""
    log_frequency: int = 1000
    """log losses and SPS every this many steps"""
    checkpoint_frequency: int = 10000
    """write the resumable training state every this many steps"""
    stop_at_expert: bool = False
    """end training at the first periodic evaluation that meets the expert bar (success rate >= 0.95 and, on Pusher,
    final distance <= 0.06 over its episodes); the held-out final evaluation then judges the written oracle"""
    snapshot_frequency: int = 50000
    """keep a copy of the oracle checkpoint (oracle_step{N}.pt in the run dir) every this many steps"""
    resume: str | None = None
    """path of a training_state.pt to continue from (same run directory)"""
    output_path: str | None = None
    """where the final oracle checkpoint is written (default: oracles/{env_id}__{method}_oracle.pt)"""

    # Maze oracles
    method: str | None = None
    """sac (Pusher and other continuous envs); value-iteration (exact Q*), q-learning or dqn (imperfect, learned
    teachers) on the maze; default: sac or value-iteration"""
    maze_episodes: int = 50
    """episodes of the maze's tabular Q-learning (--method q-learning)"""
    maze_alpha: float = 0.2
    """step size of the maze's tabular Q-learning"""
    maze_epsilon: float = 0.1
    """exploration rate of the maze's tabular Q-learning"""
    maze_dqn_timesteps: int = 20000
    """environment steps of the maze DQN (--method dqn)"""
    maze_dqn_learning_rate: float = 1e-3
    """Adam learning rate of the maze DQN"""
    maze_dqn_hidden: int = 64
    """width of the maze DQN's two hidden layers"""
    maze_dqn_buffer_size: int = 10000
    """replay memory size of the maze DQN"""
    maze_dqn_batch_size: int = 128
    """batch size of the maze DQN"""
    maze_dqn_learning_starts: int = 1000
    """environment steps before the maze DQN's first gradient step"""
    maze_dqn_train_frequency: int = 2
    """environment steps between the maze DQN's gradient steps"""
    maze_dqn_target_network_frequency: int = 100
    """environment steps between copies of the maze DQN into its target network"""
    maze_dqn_start_e: float = 1.0
    """starting epsilon of the maze DQN's exploration"""
    maze_dqn_end_e: float = 0.05
    """final epsilon of the maze DQN's exploration"""
    maze_dqn_exploration_fraction: float = 0.5
    """fraction of --maze-dqn-timesteps over which epsilon decays from start to end"""


class InputError(Exception):
    """Bad input from the user: a flag value, a file. Reported as one line, before anything is written."""


def check_args(args: Args) -> None:
    """What tyro cannot know: the env id, the method, ranges, files. Raises InputError."""
    if args.track and importlib.util.find_spec("wandb") is None:
        raise InputError("--track needs Weights & Biases: `pip install wandb`, or run without --track")
    if args.track and args.env_id in MAZE_IDS:
        raise InputError("--track mirrors TensorBoard events, which only the SAC training writes")
    methods = METHODS["maze" if args.env_id in MAZE_IDS else "sac"]
    if args.method is not None and args.method not in methods:
        raise InputError(f"--method {args.method} does not apply to {args.env_id}; choose one of {', '.join(methods)}")
    if not 0 <= args.seed < 2**32:
        raise InputError(f"--seed must be in [0, 2**32), got {args.seed}")
    if args.num_threads < 1 or args.hidden_size < 1:
        raise InputError(f"--num-threads ({args.num_threads}) and --hidden-size ({args.hidden_size}) must be positive")
    if not (args.policy_lr > 0.0 and args.q_lr > 0.0 and args.ent_coef > 0.0):
        raise InputError("--policy-lr, --q-lr and --ent-coef must be > 0")
    if args.output_path is not None and (not args.output_path or os.path.isdir(args.output_path)):
        raise InputError(f"--output-path {args.output_path!r} must name a file (it is empty or a directory)")
    if args.resume is not None and args.env_id in MAZE_IDS:
        raise InputError(
            "--resume continues a SAC (Pusher) run; the maze methods train in seconds and have no training state"
        )
    if args.maze_episodes < 1 or not 0.0 < args.maze_alpha <= 1.0 or not 0.0 <= args.maze_epsilon <= 1.0:
        raise InputError("--maze-episodes must be >= 1, --maze-alpha in (0, 1] and --maze-epsilon in [0, 1]")
    check_maze_dqn_args(args)
    if args.env_id == "Pusher-v4":
        import mujoco

        if int(mujoco.__version__.split(".")[0]) >= 3:
            raise InputError(
                f"Pusher-v4 needs mujoco<3 (installed: {mujoco.__version__}); use --env-id Pusher-v5 "
                "or `pip install mujoco==2.3.7` in a separate venv"
            )
    positive = ["total_timesteps", "batch_size", "eval_frequency", "eval_episodes", "final_eval_episodes"]
    positive += ["learning_starts", "log_frequency", "checkpoint_frequency", "policy_frequency", "buffer_size"]
    for name in positive:
        if getattr(args, name) <= 0:
            raise InputError(f"--{name.replace('_', '-')} must be positive (got {getattr(args, name)})")
    if args.batch_size > args.total_timesteps:
        raise InputError(f"--batch-size {args.batch_size} is larger than --total-timesteps {args.total_timesteps}")
    if not 0.0 < args.tau <= 1.0:
        raise InputError(f"--tau must be in (0, 1], got {args.tau}")
    if not 0.0 <= args.gamma <= 1.0:
        raise InputError(f"--gamma must be in [0, 1], got {args.gamma}")
    if args.resume is not None and not os.path.isfile(args.resume):
        raise InputError(f"--resume {args.resume}: no such file")
    if not args.success_distance > 0.0:
        raise InputError(f"--success-distance must be > 0, got {args.success_distance}")
    if args.env_id not in MAZE_IDS:
        check_env(args)


def check_env(args: Args) -> None:
    """--env-id for SAC: a Gymnasium env with a flat observation and continuous actions, whose episodes can be judged
    (one random step shows whether `info` has --success-info-key). Raises InputError."""
    try:
        env = gym.make(args.env_id)
    except Exception as e:  # unknown id, a missing extra (box2d, ...), a version that needs other packages
        first = (str(e).strip() or type(e).__name__).splitlines()[0][:160]
        mazes = ", ".join(MAZE_IDS)
        raise InputError(f"--env-id {args.env_id}: Gymnasium cannot make it ({first}); mazes: {mazes}") from None
    try:
        obs_space, act_space = env.observation_space, env.action_space
        if not isinstance(act_space, gym.spaces.Box):
            raise InputError(
                f"--env-id {args.env_id}: its actions are {type(act_space).__name__}, not continuous (Box)"
            )
        if not isinstance(obs_space, gym.spaces.Box) or len(obs_space.shape) != 1:
            raise InputError(f"--env-id {args.env_id}: needs a flat Box observation, not {obs_space}")
        if args.success_return is None:
            env.reset(seed=0)
            info = env.step(act_space.sample())[4]
            if args.success_info_key not in info:
                keys = ", ".join(sorted(info)) or "none"
                raise InputError(
                    f"--env-id {args.env_id}: its info has no {args.success_info_key!r} to measure a final distance "
                    f"(it has: {keys}); pass --success-info-key KEY, or --success-return R to judge episodes by return"
                )
    finally:
        env.close()


def check_maze_dqn_args(args: Args) -> None:
    """The --maze-dqn-* flags; raises InputError."""
    for name in ("timesteps", "hidden", "buffer_size", "batch_size", "train_frequency", "target_network_frequency"):
        value = getattr(args, f"maze_dqn_{name}")
        if value < 1:
            raise InputError(f"--maze-dqn-{name.replace('_', '-')} must be a positive integer (got {value})")
    if args.maze_dqn_learning_starts < 0:
        raise InputError(f"--maze-dqn-learning-starts must be >= 0 (got {args.maze_dqn_learning_starts})")
    if not args.maze_dqn_learning_rate > 0.0 or not args.maze_dqn_exploration_fraction > 0.0:
        raise InputError("--maze-dqn-learning-rate and --maze-dqn-exploration-fraction must be > 0")
    if not 0.0 <= args.maze_dqn_end_e <= 1.0 or not 0.0 <= args.maze_dqn_start_e <= 1.0:
        raise InputError("--maze-dqn-start-e and --maze-dqn-end-e must be in [0, 1]")
    if args.maze_dqn_batch_size > args.maze_dqn_timesteps:
        raise InputError(
            f"--maze-dqn-batch-size {args.maze_dqn_batch_size} is larger than --maze-dqn-timesteps "
            f"{args.maze_dqn_timesteps}"
        )
    if args.maze_dqn_learning_starts >= args.maze_dqn_timesteps:
        raise InputError(
            f"--maze-dqn-learning-starts ({args.maze_dqn_learning_starts}) must be below "
            f"--maze-dqn-timesteps ({args.maze_dqn_timesteps}), or the DQN never learns"
        )


def make_env(env_id: str, seed: int) -> gym.Env:
    env = gym.make(env_id)
    env.action_space.seed(seed)
    env.observation_space.seed(seed)
    return env


# The networks and the soft update are copied verbatim from inform_sac_pusher.py (CleanRL style: repeated across
# files); tests/test_pusher.py checks that the copies agree and that both scripts train the same oracle.
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


class QEnsemble(nn.Module):
    """`n` Q (or H) networks as one module: twin critics with n=2, the sleep critic with n=1. Returns [n, B]."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: int = 256, n: int = 2):
        super().__init__()
        self.n = n
        self.fc1 = BatchedLinear(n, obs_dim + act_dim, hidden)
        self.fc2 = BatchedLinear(n, hidden, hidden)
        self.fc3 = BatchedLinear(n, hidden, 1)

    def forward(self, obs: torch.Tensor, act: torch.Tensor) -> torch.Tensor:
        x = torch.cat([obs, act], -1).unsqueeze(0).expand(self.n, -1, -1)
        x = F.relu(self.fc1(x))
        x = F.relu(self.fc2(x))
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

    def get_action(self, obs: torch.Tensor, generator: torch.Generator | None = None):
        """(sampled action, its log-prob [B], mean action); `generator` keeps evaluation off the training RNG."""
        mean, log_std = self(obs)
        eps = torch.randn(mean.shape, generator=generator, device=mean.device)
        x_t = mean + log_std.exp() * eps
        y_t = torch.tanh(x_t)
        log_prob = -0.5 * eps.pow(2) - log_std - 0.5 * math.log(2 * math.pi)
        log_prob = log_prob - torch.log(self.action_scale * (1 - y_t.pow(2)) + 1e-6)
        mean_action = torch.tanh(mean) * self.action_scale + self.action_bias
        return y_t * self.action_scale + self.action_bias, log_prob.sum(-1), mean_action

    def log_prob(self, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """log pi(a|s) of given actions [B] (the offline criterion's expert log-likelihood)."""
        mean, log_std = self(obs)
        y = ((action - self.action_bias) / self.action_scale).clamp(-1 + 1e-6, 1 - 1e-6)
        z = (torch.atanh(y) - mean) / log_std.exp()
        log_prob = -0.5 * z.pow(2) - log_std - 0.5 * math.log(2 * math.pi)
        return (log_prob - torch.log(self.action_scale * (1 - y.pow(2)) + 1e-6)).sum(-1)


def soft_update(target: nn.Module, source: nn.Module, tau: float) -> None:
    with torch.no_grad():
        for param, target_param in zip(source.parameters(), target.parameters(), strict=True):
            target_param.lerp_(param, tau)


# How an episode is judged: copied verbatim from inform_sac_pusher.py (a test keeps the copies identical)
@dataclass(frozen=True)
class Outcome:
    """How an episode is judged, in the day's success tags and in every test: its final distance |info[info_key]| at
    the end (Pusher: object to goal; NaN if the env reports no such entry), and its success: that distance below
    `distance`, or, with `min_return`, the episode's return at least that. The shortfall ranks episodes for the
    fallback expert set (lower is better): the distance, or minus the return."""

    info_key: str = "reward_dist"
    distance: float = 0.08
    min_return: float | None = None

    @classmethod
    def from_args(cls, args: Args) -> "Outcome":
        return cls(args.success_info_key, args.success_distance, args.success_return)

    def __call__(self, info: dict, ep_return: float) -> tuple[float, bool, float]:
        """(final distance, success, shortfall) of an episode that ended with `info` after earning `ep_return`."""
        distance = abs(float(info[self.info_key])) if self.info_key in info else math.nan
        if self.min_return is None:
            return distance, bool(distance < self.distance), distance
        return distance, ep_return >= self.min_return, -ep_return


def selection_key(evaluation: dict, outcome: Outcome) -> tuple[float, float]:
    """What makes one evaluation better than another (SB3's EvalCallback keeps the best): the success rate, then the
    final distance (smaller is better) or, when success is by return, the return."""
    tie = evaluation["return"] if outcome.min_return is not None else -evaluation["final_distance"]
    return evaluation["success_rate"], tie


class Stop:
    """The stop signals received (main's handler only records them) and whether stop_check() has acted on them."""

    signals = []
    raised = False


def stop_check() -> None:
    """KeyboardInterrupt if a stop signal came (once), at the head of every loop: in our own code, never inside a
    library call (TensorBoard's writer, a checkpoint being written)."""
    if Stop.signals and not Stop.raised:
        Stop.raised = True
        raise KeyboardInterrupt


@torch.inference_mode()
def evaluate(actor: Actor, env_id: str, episodes: int, seed: int, device: torch.device, outcome: Outcome) -> dict:
    """Deterministic (mean-action) episodes from random starts: return, final distance, success. The unused sample
    comes from its own generator, so evaluating never moves the training RNG."""
    env = gym.make(env_id)
    generator = torch.Generator(device=device).manual_seed(seed)
    returns = []
    distances = []
    successes = []
    for ep in range(episodes):
        stop_check()
        obs, _ = env.reset(seed=seed + ep)
        done = False
        ep_return = 0.0
        info = {}
        while not done:
            obs_t = torch.as_tensor(obs, dtype=torch.float32, device=device).unsqueeze(0)
            _, _, action = actor.get_action(obs_t, generator)
            obs, reward, terminated, truncated, info = env.step(action[0].cpu().numpy())
            ep_return += float(reward)
            done = terminated or truncated
        distance, success, _ = outcome(info, ep_return)
        returns.append(ep_return)
        distances.append(distance)
        successes.append(success)
    env.close()
    distances = np.asarray(distances)
    return {
        "return": float(np.mean(returns)),
        "return_std": float(np.std(returns)),
        "final_distance": float(distances.mean()),
        "success_rate": float(np.mean(successes)),
        "episodes": episodes,
    }


def atomic_save(obj, path: str) -> None:
    tmp = path + ".tmp"
    torch.save(obj, tmp)
    os.replace(tmp, path)


def oracle_checkpoint(actor, qf, args: Args, obs_dim, act_dim, action_low, action_high, step, evaluation) -> dict:
    """The deployable oracle: state_dicts plus everything needed to rebuild and check them."""
    return {
        "algorithm": "sac",
        "env_id": args.env_id,
        "obs_shape": [obs_dim],
        "act_shape": [act_dim],
        "kwargs": {"obs_dim": obs_dim, "act_dim": act_dim, "hidden": args.hidden_size},
        "action_low": torch.as_tensor(action_low, dtype=torch.float32),
        "action_high": torch.as_tensor(action_high, dtype=torch.float32),
        "actor_state_dict": {k: v.detach().cpu().clone() for k, v in actor.state_dict().items()},
        "qf_state_dict": {k: v.detach().cpu().clone() for k, v in qf.state_dict().items()},
        "training_steps": int(step),
        "training_seed": args.seed,
        "random_starts": True,
        "bf16": bool(args.bf16),  # the opt-in speed flags it was trained with (they change the numbers)
        "num_threads": int(args.num_threads),
        "evaluation": {k: float(v) for k, v in evaluation.items()},
    }


def read_training_state(path: str) -> dict:
    """torch.load(path, weights_only=True) of a training_state.pt; every way it can fail is one InputError."""
    if not zipfile.is_zipfile(path):  # torch.save writes a zip archive; a truncated one has lost its directory
        raise InputError(f"--resume {path}: not a torch checkpoint, or a truncated one (not a complete zip archive)")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            state = torch.load(path, weights_only=True, map_location="cpu")
    except pickle.UnpicklingError as e:
        unsupported = [line.strip() for line in str(e).splitlines() if "unsupported" in line.lower()]
        raise InputError(
            f"--resume {path}: refused, it holds more than tensors and plain values (it could run "
            f"code): {(unsupported or [type(e).__name__])[0][:160]}"
        ) from None
    except Exception as e:  # a damaged archive: torch raises RuntimeError, EOFError, ...
        first = (str(e).strip() or type(e).__name__).splitlines()[0][:160]
        raise InputError(f"--resume {path}: corrupt checkpoint: {first}") from None
    for old, new in (("a_optimizer", "ent_coef_optimizer"), ("log_alpha", "log_ent_coef")):  # an older state's names
        if isinstance(state, dict) and old in state:
            state[new] = state.pop(old)
    missing = [k for k in TRAINING_STATE_KEYS if not isinstance(state, dict) or k not in state]
    if missing:
        more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        raise InputError(
            f"--resume {path}: not a training_state.pt of oracle_train.py (missing {', '.join(missing[:3])}{more})"
        )
    return state


def new_run_dir(args: Args) -> str:
    run_name = f"{args.env_id}__{args.exp_name}__{args.seed}__{int(time.time())}"
    run_dir = os.path.join("runs", run_name)
    suffix = 0
    while os.path.exists(run_dir):
        suffix += 1
        run_dir = os.path.join("runs", f"{run_name}_{suffix}")
    os.makedirs(run_dir)
    return run_dir


def train_sac(args: Args, resume_state: dict | None = None) -> None:
    """SAC on the env reward (CleanRL's sac_continuous_action.py), step for step the SAC of inform_sac_pusher.py
    --train-oracle (a test trains both and compares the networks), plus checkpoints, snapshots and --resume."""
    torch.set_num_threads(args.num_threads)
    device = torch.device("cuda" if torch.cuda.is_available() and args.cuda else "cpu")
    random.seed(args.seed)
    np.random.seed(args.seed)
    torch.manual_seed(args.seed)
    torch.backends.cudnn.deterministic = args.torch_deterministic
    torch.use_deterministic_algorithms(args.torch_deterministic)

    env = make_env(args.env_id, args.seed)
    obs_dim = int(np.prod(env.observation_space.shape))
    act_dim = int(np.prod(env.action_space.shape))
    low = env.action_space.low
    high = env.action_space.high

    actor = Actor(obs_dim, act_dim, args.hidden_size, low, high).to(device)
    qf = QEnsemble(obs_dim, act_dim, args.hidden_size, n=2).to(device)
    qf_target = QEnsemble(obs_dim, act_dim, args.hidden_size, n=2).to(device)
    qf_target.load_state_dict(qf.state_dict())
    amp = torch.autocast(device.type, dtype=torch.bfloat16, enabled=args.bf16)  # --bf16; off, it changes nothing
    q_optimizer = torch.optim.Adam(qf.parameters(), lr=args.q_lr)
    actor_optimizer = torch.optim.Adam(actor.parameters(), lr=args.policy_lr)
    target_entropy = -float(act_dim)
    log_ent_coef = torch.zeros(1, device=device, requires_grad=True)  # SAC's entropy coefficient, exp(log_ent_coef)
    ent_coef_optimizer = torch.optim.Adam([log_ent_coef], lr=args.q_lr)
    if not args.autotune:
        log_ent_coef.data.fill_(math.log(args.ent_coef))

    # preallocated replay buffer (float32; Pusher never terminates but the flag is kept)
    size = min(args.buffer_size, args.total_timesteps)
    buf_obs = torch.zeros(size, obs_dim, device=device)
    buf_next_obs = torch.zeros(size, obs_dim, device=device)
    buf_act = torch.zeros(size, act_dim, device=device)
    buf_rew = torch.zeros(size, device=device)
    buf_term = torch.zeros(size, device=device)
    buffers = {
        "buf_obs": buf_obs,
        "buf_next_obs": buf_next_obs,
        "buf_act": buf_act,
        "buf_rew": buf_rew,
        "buf_term": buf_term,
    }
    modules = {
        "actor": actor,
        "qf": qf,
        "qf_target": qf_target,
        "q_optimizer": q_optimizer,
        "actor_optimizer": actor_optimizer,
        "ent_coef_optimizer": ent_coef_optimizer,
    }
    buf_n = start_step = 0
    if args.resume is not None:
        run_dir = os.path.dirname(os.path.abspath(args.resume))
        try:
            for key, module in modules.items():
                module.load_state_dict(resume_state[key])
            log_ent_coef.data.copy_(resume_state["log_ent_coef"])
            buf_n = int(resume_state["buf_n"])
            for key, buf in buffers.items():
                buf[: min(buf_n, size)] = resume_state[key][: min(buf_n, size)]
            start_step = int(resume_state["global_step"])
            torch.set_rng_state(resume_state["torch_rng"])
        except (RuntimeError, ValueError, TypeError, KeyError, IndexError) as e:  # nothing is written before this
            first = (str(e).strip() or type(e).__name__).splitlines()[0][:160]
            raise InputError(f"--resume {args.resume}: does not fit this run ({type(e).__name__}: {first})") from None
        np.random.seed(args.seed + start_step)
        env.action_space.seed(args.seed + start_step)
        print(f"resumed from {args.resume} at step {start_step}", flush=True)
    else:
        run_dir = new_run_dir(args)
    if args.track:  # Weights & Biases mirrors the TensorBoard events (CleanRL's --track); before the writer
        import wandb

        wandb.init(
            project=args.wandb_project_name,
            entity=args.wandb_entity,
            sync_tensorboard=True,
            config=vars(args),
            name=os.path.basename(run_dir),
            dir=run_dir,
            save_code=True,
        )
    writer = SummaryWriter(run_dir)
    if args.resume is None:
        writer.add_text(
            "hyperparameters",
            "|param|value|\n|-|-|\n" + "\n".join(f"|{key}|{value}|" for key, value in vars(args).items()),
        )
    print(f"run directory: {run_dir}", flush=True)

    def save_training_state(global_step: int) -> None:
        n = min(buf_n, size)
        state = {key: module.state_dict() for key, module in modules.items()}
        state.update({key: buf[:n].clone() for key, buf in buffers.items()})
        state.update(
            log_ent_coef=log_ent_coef.detach().clone(),
            buf_n=buf_n,
            global_step=global_step,
            torch_rng=torch.get_rng_state(),
        )
        atomic_save(state, os.path.join(run_dir, "training_state.pt"))

    def save_oracle(step: int, evaluation: dict, path: str) -> None:
        atomic_save(oracle_checkpoint(actor, qf, args, obs_dim, act_dim, low, high, step, evaluation), path)

    # the best evaluation so far (SB3's EvalCallback): success rate first, then final distance; a resumed run goes on
    # from the best.pt in its run directory
    outcome = Outcome.from_args(args)
    best_path = os.path.join(run_dir, "best.pt")
    best_key = (-1.0, -math.inf)
    best_step = None
    if os.path.isfile(best_path):
        best = torch.load(best_path, weights_only=True, map_location="cpu")
        best_key = selection_key(best["evaluation"], outcome)
        best_step = best["training_steps"]

    obs, _ = env.reset(seed=args.seed + start_step)  # random starts: seed once, then the env RNG runs on
    obs_t = torch.as_tensor(obs, dtype=torch.float32, device=device)
    ep_return = 0.0
    ep_length = 0
    t0 = time.time()
    t_last = time.time()
    step_last = start_step
    qf_loss = actor_loss = ent_coef_loss = torch.zeros((), device=device)
    last_eval = {}
    expert_reached = False
    trained = start_step  # env steps trained so far (fewer than --total-timesteps after --stop-at-expert)
    report_every = max(1, (args.total_timesteps - start_step) // 20)
    for global_step in range(start_step, args.total_timesteps):
        stop_check()
        if global_step < args.learning_starts:
            action = env.action_space.sample()
        else:
            with torch.no_grad():
                action_t, _, _ = actor.get_action(obs_t.unsqueeze(0))
            action = action_t[0].cpu().numpy()
        next_obs, reward, terminated, truncated, info = env.step(action)
        next_obs_t = torch.as_tensor(next_obs, dtype=torch.float32, device=device)
        i = buf_n % size
        buf_obs[i] = obs_t
        buf_next_obs[i] = next_obs_t
        buf_act[i] = torch.as_tensor(action, device=device)
        buf_rew[i] = float(reward)
        buf_term[i] = float(terminated)
        buf_n += 1
        ep_return = ep_return + float(reward)
        ep_length = ep_length + 1
        if terminated or truncated:
            writer.add_scalar("charts/episodic_return", ep_return, global_step)
            writer.add_scalar("charts/episodic_length", ep_length, global_step)
            distance = outcome(info, ep_return)[0]
            if not math.isnan(distance):
                writer.add_scalar("charts/final_distance", distance, global_step)
            ep_return = 0.0
            ep_length = 0
            next_obs, _ = env.reset()
            next_obs_t = torch.as_tensor(next_obs, dtype=torch.float32, device=device)
        obs_t = next_obs_t

        # ALGO LOGIC: one SAC update per env step, as inform_sac_pusher.py's train_oracle
        if global_step >= args.learning_starts:
            idx = torch.randint(0, min(buf_n, size), (args.batch_size,), device=device)
            b_obs = buf_obs[idx]
            b_next = buf_next_obs[idx]
            b_act = buf_act[idx]
            b_rew = buf_rew[idx]
            b_term = buf_term[idx]
            ent_coef = log_ent_coef.detach().exp()
            with amp, torch.no_grad():
                next_act, next_logp, _ = actor.get_action(b_next)
                min_q_next = qf_target(b_next, next_act).min(0).values - ent_coef * next_logp
                target_q = b_rew + (1.0 - b_term) * args.gamma * min_q_next
            with amp:
                qf_loss = (qf(b_obs, b_act) - target_q.unsqueeze(0)).pow(2).mean(-1).sum()  # summed over the twins
            q_optimizer.zero_grad(set_to_none=True)
            qf_loss.backward()
            q_optimizer.step()

            if global_step % args.policy_frequency == 0:
                with amp:
                    pi, logp, _ = actor.get_action(b_obs)
                    actor_loss = (ent_coef * logp - qf(b_obs, pi).min(0).values).mean()
                actor_optimizer.zero_grad(set_to_none=True)
                actor_loss.backward()
                actor_optimizer.step()
                qf.zero_grad(set_to_none=True)  # the actor loss left gradients on the critic
                if args.autotune:
                    ent_coef_loss = (-log_ent_coef.exp() * (logp.detach() + target_entropy)).mean()
                    ent_coef_optimizer.zero_grad(set_to_none=True)
                    ent_coef_loss.backward()
                    ent_coef_optimizer.step()
            soft_update(qf_target, qf, args.tau)

        # TRY NOT TO MODIFY: logging, evaluation, checkpoints
        step = global_step + 1
        if step % args.log_frequency == 0:
            sps = (step - step_last) / max(time.time() - t_last, 1e-9)
            writer.add_scalar("losses/qf_loss", qf_loss.item(), step)
            writer.add_scalar("losses/actor_loss", actor_loss.item(), step)
            writer.add_scalar("losses/ent_coef", log_ent_coef.exp().item(), step)
            writer.add_scalar("losses/ent_coef_loss", ent_coef_loss.item(), step)
            writer.add_scalar("charts/SPS", sps, step)
        if step % args.eval_frequency == 0 or step == args.total_timesteps:
            last_eval = evaluate(actor, args.env_id, args.eval_episodes, SELECTION_EVAL_SEED, device, outcome)
            writer.add_scalar("eval/oracle_return", last_eval["return"], step)
            writer.add_scalar("eval/oracle_final_distance", last_eval["final_distance"], step)
            writer.add_scalar("eval/oracle_success_rate", last_eval["success_rate"], step)
            if selection_key(last_eval, outcome) > best_key:
                best_key = selection_key(last_eval, outcome)
                best_step = step
                save_oracle(step, {**last_eval, "reset_seed": SELECTION_EVAL_SEED}, best_path)
            writer.add_scalar("eval/best_success_rate", best_key[0], step)
            writer.add_scalar("eval/best_return" if outcome.min_return is not None else "eval/best_final_distance",
                              best_key[1] if outcome.min_return is not None else -best_key[1], step)  # fmt: skip
            with open(os.path.join(run_dir, "eval_curve.csv"), "a") as f:  # the selection curve, one row per evaluation
                if f.tell() == 0:
                    f.write("step,success_rate,final_distance,return\n")
                f.write(f"{step},{last_eval['success_rate']},{last_eval['final_distance']},{last_eval['return']}\n")
            expert_reached = args.stop_at_expert and (
                last_eval["success_rate"] >= EXPERT_SUCCESS_RATE
                and (args.env_id not in PUSHER_IDS or last_eval["final_distance"] <= EXPERT_FINAL_DISTANCE)
            )
        if step % report_every == 0 or step % args.eval_frequency == 0 or step == args.total_timesteps:
            sps = (step - start_step) / max(time.time() - t0, 1e-9)
            eta = (args.total_timesteps - step) / max(sps, 1e-9)
            ev = ""
            best_tie = best_key[1] if outcome.min_return is not None else -best_key[1]  # its return, or distance
            if last_eval:
                ev = (
                    f" | eval return {last_eval['return']:.1f} dist {last_eval['final_distance']:.3f} success "
                    f"{last_eval['success_rate']:.2f} | best {best_key[0]:.2f} / {best_tie:.3f} at {best_step}"
                )
            print(
                f"[oracle] {step}/{args.total_timesteps} {100 * step // args.total_timesteps}% | {sps:.0f} SPS"
                f" | ETA {int(eta // 60)}m{int(eta % 60):02d}s{ev}",
                flush=True,
            )
        if step % args.checkpoint_frequency == 0 or step == args.total_timesteps:
            save_training_state(step)
            save_oracle(step, last_eval or {}, os.path.join(run_dir, "oracle_latest.pt"))
            if step % args.snapshot_frequency == 0:  # kept, so the teacher can be chosen by a longer evaluation later
                save_oracle(step, last_eval or {}, os.path.join(run_dir, f"oracle_step{step:07d}.pt"))
        t_last, step_last = (time.time(), step) if step % args.log_frequency == 0 else (t_last, step_last)
        trained = step
        if expert_reached:
            print(
                f"[oracle] step {step}: the evaluation meets the expert bar (--stop-at-expert), training ends",
                flush=True,
            )
            save_training_state(step)
            break

    train_time = time.time() - t0
    env.close()
    # the oracle written is the best evaluation's networks (the last ones stay in oracle_latest.pt), judged again on
    # held-out starts
    best = torch.load(best_path, weights_only=True, map_location="cpu")
    actor.load_state_dict(best["actor_state_dict"])
    qf.load_state_dict(best["qf_state_dict"])
    final_eval = evaluate(actor, args.env_id, args.final_eval_episodes, FINAL_EVAL_SEED, device, outcome)
    print(
        f"[oracle] best evaluation at step {best['training_steps']}: success rate "
        f"{best['evaluation']['success_rate']:.2f}, final distance {best['evaluation']['final_distance']:.4f} over "
        f"{best['evaluation']['episodes']:.0f} episodes; held-out eval over {args.final_eval_episodes} other starts: "
        f"return {final_eval['return']:.2f} +- {final_eval['return_std']:.2f} | final distance "
        f"{final_eval['final_distance']:.4f} | success rate {final_eval['success_rate']:.2f} | train time "
        f"{train_time:.0f}s (this session)",
        flush=True,
    )
    steps = best["training_steps"]
    if args.save_model:
        ckpt = oracle_checkpoint(actor, qf, args, obs_dim, act_dim, low, high, steps, final_eval)
        ckpt["train_time_s_this_session"] = float(train_time)
        ckpt["selection_evaluation"] = best["evaluation"]
        ckpt["total_timesteps"] = trained
        os.makedirs(os.path.dirname(os.path.abspath(args.output_path)), exist_ok=True)
        atomic_save(ckpt, args.output_path)
        with open(os.path.join(run_dir, "oracle_eval.json"), "w") as f:
            json.dump(
                {
                    "eval": final_eval,
                    "selection_eval": best["evaluation"],
                    "steps": steps,
                    "train_time_s": train_time,
                    "args": asdict(args),
                },
                f,
                indent=1,
            )
        print(f"oracle written to {args.output_path}", flush=True)
    if args.capture_video:
        record_teacher(args, actor, run_dir, device)
    writer.close()


def maze_q_learning(env: gym.Env, args: Args) -> tuple[np.ndarray, int]:
    """Tabular Q-learning on the maze's own reward; ties broken at random. Returns (Q table, env steps)."""
    rng = np.random.default_rng(args.seed)
    q = np.zeros((gridworld_env.N_CELLS, gridworld_env.N_ACTIONS))
    steps = 0
    obs, _ = env.reset(seed=args.seed)
    for _ in range(args.maze_episodes):
        stop_check()
        s = int(obs.argmax())
        done = False
        while not done:
            best = np.flatnonzero(q[s] == q[s].max())
            a = (
                int(rng.integers(gridworld_env.N_ACTIONS))
                if rng.random() < args.maze_epsilon
                else int(rng.choice(best))
            )
            obs, reward, terminated, truncated, _ = env.step(a)
            s_next = int(obs.argmax())
            q[s, a] += args.maze_alpha * (reward + args.gamma * (1.0 - terminated) * q[s_next].max() - q[s, a])
            s = s_next
            done = terminated or truncated
            steps = steps + 1
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


def maze_q_table(q_network: MazeQNetwork) -> np.ndarray:
    """The network's Q over every one-hot state: a (30, 4) table, row s = Q(one_hot(s), .)."""
    with torch.no_grad():
        return q_network(torch.eye(gridworld_env.N_CELLS)).double().numpy()


def linear_schedule(start_e: float, end_e: float, duration: int, t: int) -> float:
    return start_e + (end_e - start_e) * min(t / duration, 1.0)


def maze_dqn(env: gym.Env, args: Args) -> tuple[MazeQNetwork, int]:
    """DQN (CleanRL's dqn.py) on the maze's own reward; truncation bootstraps. Returns (Q network, env steps)."""
    torch.set_num_threads(args.num_threads)
    random.seed(args.seed)
    np.random.seed(args.seed)
    torch.manual_seed(args.seed)
    obs_dim = gridworld_env.N_CELLS
    n_actions = gridworld_env.N_ACTIONS
    q_network = MazeQNetwork(obs_dim, n_actions, args.maze_dqn_hidden)
    target_network = MazeQNetwork(obs_dim, n_actions, args.maze_dqn_hidden)
    target_network.load_state_dict(q_network.state_dict())
    optimizer = torch.optim.Adam(q_network.parameters(), lr=args.maze_dqn_learning_rate, fused=True)
    size = min(args.maze_dqn_buffer_size, args.maze_dqn_timesteps)
    # one-hot observations are stored as cell indices; torch.eye turns a batch back into observations
    buf_s = torch.zeros(size, dtype=torch.long)
    buf_a = torch.zeros(size, dtype=torch.long)
    buf_r = torch.zeros(size)
    buf_s_next = torch.zeros(size, dtype=torch.long)
    buf_term = torch.zeros(size)
    eye = torch.eye(obs_dim)
    rng = np.random.default_rng(args.seed)
    env.action_space.seed(args.seed)
    obs, _ = env.reset(seed=args.seed)
    s = int(obs.argmax())
    decay_steps = max(1, int(args.maze_dqn_exploration_fraction * args.maze_dqn_timesteps))
    for global_step in range(args.maze_dqn_timesteps):
        stop_check()
        epsilon = linear_schedule(args.maze_dqn_start_e, args.maze_dqn_end_e, decay_steps, global_step)
        if rng.random() < epsilon:
            action = int(env.action_space.sample())
        else:
            with torch.no_grad():
                action = int(q_network(eye[s]).argmax())
        obs, reward, terminated, truncated, _ = env.step(action)
        s_next = int(obs.argmax())
        i = global_step % size
        buf_s[i] = s
        buf_a[i] = action
        buf_r[i] = float(reward)
        buf_s_next[i] = s_next
        buf_term[i] = float(terminated)
        s = s_next
        if terminated or truncated:
            obs, _ = env.reset()
            s = int(obs.argmax())

        if global_step >= args.maze_dqn_learning_starts and global_step % args.maze_dqn_train_frequency == 0:
            idx = torch.randint(min(global_step + 1, size), (args.maze_dqn_batch_size,))
            with torch.no_grad():
                target_max = target_network(eye[buf_s_next[idx]]).max(1).values
                td_target = buf_r[idx] + args.gamma * target_max * (1.0 - buf_term[idx])
            old_val = q_network(eye[buf_s[idx]]).gather(1, buf_a[idx, None]).squeeze(1)
            loss = F.mse_loss(td_target, old_val)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
        if global_step % args.maze_dqn_target_network_frequency == 0:
            target_network.load_state_dict(q_network.state_dict())
    return q_network, args.maze_dqn_timesteps


def train_maze(args: Args) -> None:
    """A maze teacher: exact Q* by value iteration, a tabular Q-learner's table or a DQN's Q over the 30 cells;
    saved as a 30 x 4 q_table (and, for the DQN, the network's state_dict with the kwargs to rebuild it)."""
    env = gym.make(args.env_id)
    variant = env.unwrapped.variant
    start = time.time()
    extra = {}
    if args.method == "q-learning":
        q, steps = maze_q_learning(env, args)
    elif args.method == "dqn":
        q_network, steps = maze_dqn(env, args)
        q = maze_q_table(q_network)
        extra = {
            "kwargs": {
                "obs_dim": gridworld_env.N_CELLS,
                "n_actions": gridworld_env.N_ACTIONS,
                "hidden": args.maze_dqn_hidden,
            },
            "state_dict": {k: v.detach().cpu().clone() for k, v in q_network.state_dict().items()},
        }
    else:
        q = gridworld_env.optimal_q(variant, args.gamma)
        steps = 0
    env.close()
    length = gridworld_env.greedy_episode_length(q.argmax(1), variant)
    ckpt = {
        "algorithm": args.method,
        "env_id": args.env_id,
        "obs_shape": [gridworld_env.N_CELLS],
        "act_shape": [gridworld_env.N_ACTIONS],  # discrete: one Q value per action, the q_table's columns
        "n_actions": gridworld_env.N_ACTIONS,
        "q_table": torch.tensor(q),
        "gamma": args.gamma,
        "training_steps": steps,
        "training_seed": args.seed,
        "evaluation": {"episode_length": float(length)},
        **extra,
    }
    print(
        f"[oracle] {args.method} on {args.env_id}: {steps} env steps, greedy episode length {length} "
        f"({time.time() - start:.1f}s)",
        flush=True,
    )
    if args.save_model:
        os.makedirs(os.path.dirname(os.path.abspath(args.output_path)), exist_ok=True)
        atomic_save(ckpt, args.output_path)
        print(f"oracle written to {args.output_path}", flush=True)


# --capture-video: as inform_sac_pusher.py films its policies (video_camera and write_video are copied verbatim; a test
# keeps them identical): headless MuJoCo (MUJOCO_GL), a fixed camera added to the model, mp4 by imageio-ffmpeg.
VIDEO_CAMERA = {"lookat": (0.42, -0.2, -0.3), "distance": 1.0, "elevation": -75.0}  # metres, degrees
VIDEO_SIZE = 480  # pixels, square; a multiple of 16, as H.264 wants
VIDEO_EPISODES = 3


def video_camera() -> dict:
    """The camera's MJCF attributes: VIDEO_CAMERA's distance from its lookat, seen from +x (image up is -x)."""
    x, y, z = VIDEO_CAMERA["lookat"]
    d = VIDEO_CAMERA["distance"]
    el = math.radians(VIDEO_CAMERA["elevation"])
    pos = f"{x + d * math.cos(el):.4f} {y} {z - d * math.sin(el):.4f}"
    xyaxes = f"0 1 0 {math.sin(el):.4f} 0 {math.cos(el):.4f}"
    return {"name": "inform_video", "mode": "fixed", "pos": pos, "xyaxes": xyaxes}


def video_env(env_id: str, size: int = VIDEO_SIZE) -> gym.Env:
    """Pusher from its own model plus the videos' camera (and no shadows: they triple the time of a frame in software
    OpenGL), or another env with its own camera, rendering every reset and step into a list (Gymnasium's
    RenderCollection)."""
    import gymnasium.envs.mujoco as gym_mujoco

    if env_id not in PUSHER_IDS:
        return gym.wrappers.RenderCollection(gym.make(env_id, render_mode="rgb_array", width=size, height=size))

    name = "pusher_v5.xml" if env_id == "Pusher-v5" else "pusher.xml"
    tree = ET.parse(os.path.join(os.path.dirname(gym_mujoco.__file__), "assets", name))
    ET.SubElement(tree.getroot().find("worldbody"), "camera", video_camera())
    ET.SubElement(ET.SubElement(tree.getroot(), "visual"), "quality", {"shadowsize": "0"})
    render = {"render_mode": "rgb_array", "width": size, "height": size, "camera_name": "inform_video"}
    with tempfile.TemporaryDirectory(prefix="oracle_video_") as tmp:  # MuJoCo reads the model once, at construction
        xml = os.path.join(tmp, name)
        tree.write(xml)
        if env_id == "Pusher-v5":
            env = gym.make(env_id, xml_file=xml, **render)
        else:  # Pusher-v4 has no xml_file argument: same class, model file swapped at construction
            from gymnasium.envs.mujoco.mujoco_env import MujocoEnv
            from gymnasium.envs.mujoco.pusher_v4 import PusherEnv

            class PusherVideoV4(PusherEnv):
                def __init__(self, **kwargs):
                    space = gym.spaces.Box(-np.inf, np.inf, (23,), np.float64)
                    MujocoEnv.__init__(self, xml, 5, observation_space=space, **kwargs)

            env = gym.wrappers.TimeLimit(PusherVideoV4(**render), max_episode_steps=100)
    return gym.wrappers.RenderCollection(env)


def check_video(env_id: str) -> None:
    """Before anything is written: pick the headless GL backend (egl when MUJOCO_GL is unset and there is no display),
    render one frame, and find ffmpeg. InputError, one line, if either is missing."""
    if env_id in MAZE_IDS:
        raise InputError(
            f"--capture-video films a SAC teacher; the maze's are drawn by inform_dqn_gridworld.py "
            f"--capture-video, not for {env_id}"
        )
    if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        os.environ["MUJOCO_GL"] = "egl"
    try:
        import imageio_ffmpeg

        imageio_ffmpeg.get_ffmpeg_exe()
    except Exception as e:
        raise InputError(
            f"--capture-video writes mp4 with imageio-ffmpeg, which is missing ({type(e).__name__}): "
            "pip install imageio-ffmpeg==0.8.1"
        ) from None
    try:
        with warnings.catch_warnings():  # a failing backend warns before it raises: one line is enough
            warnings.simplefilter("ignore")
            env = video_env(env_id, size=16)
            env.reset(seed=0)
            frame = env.render()[-1]
            env.close()
    except Exception as e:
        raise InputError(
            f"--capture-video: MuJoCo cannot render with MUJOCO_GL={os.environ.get('MUJOCO_GL')} "
            f"({type(e).__name__}); install EGL (Debian: apt-get install libegl1 libegl-mesa0) or "
            "OSMesa (apt-get install libosmesa6, then MUJOCO_GL=osmesa)"
        ) from None
    if not isinstance(frame, np.ndarray) or frame.shape != (16, 16, 3):
        raise InputError(f"--capture-video: MuJoCo rendered no image with MUJOCO_GL={os.environ.get('MUJOCO_GL')}")


def write_video(path: str, frames: list[np.ndarray], fps: float) -> None:
    """H.264 mp4, written to a temporary name and renamed: an interrupted write leaves no half-written video."""
    import imageio_ffmpeg

    tmp = path[: -len(".mp4")] + ".tmp.mp4"  # ffmpeg reads the container from the extension
    try:
        writer = imageio_ffmpeg.write_frames(
            tmp,
            frames[0].shape[1::-1],
            fps=fps,
            codec="libx264",
            quality=6,
            macro_block_size=16,
            ffmpeg_log_level="error",
        )
        writer.send(None)
        for frame in frames:
            writer.send(np.ascontiguousarray(frame))
        writer.close()
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


@torch.inference_mode()
def record_teacher(args: Args, actor: Actor, run_dir: str, device: torch.device) -> dict:
    """--capture-video: the written oracle's first VIDEO_EPISODES held-out evaluation episodes, deterministic and from
    the reset seeds `evaluate` gives them, back to back in videos/oracle.mp4; videos/videos.json has each episode's
    reset seed, frames and final distance."""
    os.makedirs(os.path.join(run_dir, "videos"), exist_ok=True)
    env = video_env(args.env_id)
    outcome = Outcome.from_args(args)
    generator = torch.Generator(device=device).manual_seed(FINAL_EVAL_SEED)
    frames = []
    record = {}
    t0 = time.time()
    for ep in range(VIDEO_EPISODES):
        stop_check()
        obs, _ = env.reset(seed=FINAL_EVAL_SEED + ep)
        done = False
        info = {}
        ep_return = 0.0
        while not done:
            _, _, action = actor.get_action(
                torch.as_tensor(obs, dtype=torch.float32, device=device).unsqueeze(0), generator
            )
            obs, reward, terminated, truncated, info = env.step(action[0].cpu().numpy())
            ep_return += float(reward)
            done = terminated or truncated
        episode = env.render()
        frames += episode
        record[f"episode_{ep}"] = {
            "reset_seed": FINAL_EVAL_SEED + ep,
            "frames": len(episode),
            "final_distance": outcome(info, ep_return)[0],
        }
    write_video(os.path.join(run_dir, "videos", "oracle.mp4"), frames, env.metadata["render_fps"])
    env.close()
    with open(os.path.join(run_dir, "videos", "videos.json"), "w") as f:
        json.dump({"file": "oracle.mp4", "size": list(frames[0].shape), "episodes": record}, f, indent=1)
    print(
        f"[video] {VIDEO_EPISODES} episodes of the oracle filmed in {time.time() - t0:.1f}s: "
        f"{os.path.join(run_dir, 'videos', 'oracle.mp4')}",
        flush=True,
    )
    return record


def main() -> None:
    # Ctrl-C, SIGTERM (Slurm's cancel and time limit, kill) and SIGHUP (a closed terminal) stop training: recorded
    # here, acted on by stop_check() at the next loop head. An ignored signal stays ignored (nohup, `&`).
    def stop(signum, frame):
        Stop.signals.append(signal.Signals(signum).name)

    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        if signal.getsignal(sig) is not signal.SIG_IGN:
            signal.signal(sig, stop)
    args = tyro.cli(Args)
    try:
        check_args(args)
        is_sac = args.env_id not in MAZE_IDS
        if args.capture_video:
            check_video(args.env_id)
        args.method = args.method or ("sac" if is_sac else "value-iteration")
        args.output_path = args.output_path or os.path.join("oracles", f"{args.env_id}__{args.method}_oracle.pt")
        if is_sac:
            train_sac(args, read_training_state(args.resume) if args.resume is not None else None)
        else:
            train_maze(args)
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        # nothing half-written: every file is saved atomically; SAC's state is saved every --checkpoint-frequency steps
        reason = (Stop.signals or ["SIGINT"])[0]
        print(
            f"interrupted ({reason}); no oracle checkpoint was written. SAC training continues "
            "from its last saved state with --resume <run dir>/training_state.pt",
            file=sys.stderr,
        )
        sys.exit(128 + signal.Signals[reason].value)  # 130 SIGINT, 143 SIGTERM, 129 SIGHUP
    if Stop.signals:  # after the last loop: the oracle is complete, and the caller (a shell loop too) asked to stop
        print(f"{Stop.signals[0]} received after training finished; the oracle checkpoint is complete", file=sys.stderr)
        sys.exit(128 + signal.Signals[Stop.signals[0]].value)


if __name__ == "__main__":
    main()
