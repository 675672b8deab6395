"""INFORM on the Knox & Stone maze: TAMER learns from a simulated teacher's yes/no feedback ("day"), then offline
IQ-Learn on the remembered transitions ("sleep") gives a far-sighted policy and a recovered reward.

Tarakli & Di Nuovo, "Learning while Sleeping" (ICDL 2024): Algorithm 1 and Fig. 3 on the 30-cell maze; what the paper
leaves open is in docs/protocol.md. Read top to bottom: Args, make_env, the network, Eq. 1-4 and the teacher, the
buffer, the day, the night, the evaluation, main; the armour (files, checks, the run's end) comes after main.
Gymnasium's toy-text tasks that carry their model (`--env-id FrozenLake-v1`, `CliffWalking-v1`, `Taxi-v4`) run from
their id alone: exact Q* by value iteration on `env.unwrapped.P`, one-hot observations, and an episode succeeds if it
ends on the task's goal (the terminal that earns its top reward); the maze's own tests are skipped there.

inform_utils/ imports only the names that tests/test_surface.py declares for this script;
inform_utils/evaluate_policy.py re-evaluates a saved network.

    python inform_dqn_gridworld.py --seed 1
    python inform_dqn_gridworld.py --teacher-noise 0.2 --teacher-delay 1 --credit-window 2   # a human-like teacher
    python inform_dqn_gridworld.py --teacher human   # teach it yourself (docs/teachers.md)
    python inform_dqn_gridworld.py --teacher browser --participant P01   # teach it through a web page
    python inform_dqn_gridworld.py --env-id FrozenLake-v1 --success-max-steps 100   # a toy-text task (slippery ice)
"""

import collections
import contextlib
import gc
import importlib.util
import itertools
import json
import math
import os
import random
import select
import signal
import sys
import tempfile
import threading
import time
import typing
import zipfile
from dataclasses import dataclass, fields, is_dataclass
from typing import Annotated, Literal

# the signals that stop a run, which then saves what finished: Ctrl-C, kill and Slurm (SIGTERM), a closed terminal
# (SIGHUP), Ctrl-\ (SIGQUIT), a cluster's CPU-time limit (SIGXCPU, before its SIGKILL) and the user signals
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT, signal.SIGXCPU, signal.SIGUSR1,
                signal.SIGUSR2)  # fmt: skip


def stopped_while_starting(signum, frame):
    """A stop before the run directory exists (torch & co. take seconds to load): one line, nothing to save."""
    with contextlib.suppress(OSError):
        os.write(2, f"interrupted ({signal.Signals(signum).name}) while starting; no run was made\n".encode())
    os._exit(128 + signum)


if __name__ == "__main__":  # before the slow imports, so that no stop ever ends in a traceback
    for sig in STOP_SIGNALS:
        if signal.getsignal(sig) is not signal.SIG_IGN:  # an ignored SIGINT (nohup, `&`) stays ignored
            signal.signal(sig, stopped_while_starting)

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
import torch.nn as nn  # noqa: E402
import torch.nn.functional as F  # noqa: E402
import typeguard  # noqa: E402
import tyro  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from torch.utils.tensorboard import SummaryWriter  # noqa: E402

try:
    import gridworld_env
except ModuleNotFoundError as e:  # a copy of this script without the maze beside it: said after parsing
    if e.name != "gridworld_env":
        raise
    gridworld_env = None

MAZE_IDS = tuple(gridworld_env.ENV_IDS) if gridworld_env else ("KnoxStoneMaze-v0",)
POLICIES = ("oracle", "tamer", "inform")
GAMMA = 0.99  # the discount of the oracle's Q* and of the sleep (non-myopic, unlike TAMER's 0)
TAU = 1.0  # soft-update rate of the sleep's target Q per step (1 copies it every step, as the authors did)
EXPLORATION_FRACTION = 0.2  # of the forward phase, over which epsilon decays from start_e to end_e
HUMAN_UPDATES_PER_ANSWER = 20  # a person teaches: H's gradient steps after each answer (Deep TAMER's remedies)
EVAL_FREQUENCY = 500  # env steps of the day, gradient steps of the night, between greedy evaluations
TOY_TEXT_MAX_STEPS = 200  # the step limit of a toy-text env registered without one (CliffWalking), as the maze's
SEED_RANGE = "[0, 4294967296)"  # what numpy's seeding takes
# the defaults that depend on who teaches: the paper's simulated teacher, or a person who answers every move
TEACHER_DEFAULTS = {
    "oracle": {"tamer_learning_starts": 1000, "start_e": 1.0, "end_e": 0.05},
    "human": {"tamer_learning_starts": 1, "start_e": 0.0, "end_e": 0.0},
    "browser": {"tamer_learning_starts": 1, "start_e": 0.0, "end_e": 0.0},
}
LOG_FREQUENCY = {"oracle": 100, "human": 1, "browser": 1}  # steps between scalar logs (a person's every answer)


class Range(str):
    """A flag's range beside the flag, as "[1, inf)" or "(0, 1]" (check_args reads it; NaN is in none)."""


DAY = "day"  # in a flag's Annotated type: the flag shapes the day (Args.day_settings: a saved day keeps it)


@dataclass
class Args:
    exp_name: str = os.path.basename(__file__)[: -len(".py")]
    """the name of this experiment (one name: runs/{env_id}__{exp_name}__{seed}__{time})"""
    seed: Annotated[int, Range(SEED_RANGE), DAY] = 1
    """seed of the experiment"""
    capture_video: bool = False
    """draw TAMER's and INFORM's final greedy episodes (plain maze, wall maze, a few start cells) as GIFs into
    runs/{run}/videos/"""
    cuda: bool = False
    """if toggled, the networks train on the GPU when one is available"""
    track: bool = False
    """mirror the TensorBoard events to Weights & Biases (CleanRL's --track; `pip install wandb`; WANDB_PROJECT,
    default inform, and WANDB_ENTITY choose where; WANDB_MODE=offline keeps the run on this machine)"""
    env_id: Annotated[str, DAY] = "KnoxStoneMaze-v0"
    """the maze (one of the ids gridworld_env registers), or a Gymnasium toy-text env with a model (FrozenLake-v1,
    CliffWalking-v1, Taxi-v4, ...)"""
    oracle_path: Annotated[str | None, DAY] = None
    """a maze teacher saved by oracle_train.py (e.g. a half-trained Q-learner) instead of exact Q*"""

    # Forward phase: TAMER (Eq. 1) with simulated feedback (Eq. 4)
    tamer_total_timesteps: Annotated[int, Range("[1, inf)"), DAY] = 10000
    """environment steps of the forward phase"""
    tamer_learning_starts: Annotated[int | None, Range("[1, inf)"), DAY] = None
    """environment steps before H is trained (None: 1000; with --teacher human 1, H learns from your first answer)"""
    tamer_batch_size: Annotated[int, Range("[1, inf)"), DAY] = 32
    """batch size of the H regression"""
    tamer_h_lr: Annotated[float, Range("(0, inf)"), DAY] = 1e-3
    """Adam learning rate of the feedback model H"""
    start_e: Annotated[float | None, Range("[0, 1]"), DAY] = None
    """starting epsilon of the exploration (None: 1; with --teacher human 0, no random moves)"""
    end_e: Annotated[float | None, Range("[0, 1]"), DAY] = None
    """final epsilon, reached after a fifth of the phase (None: 0.05; with --teacher human 0)"""
    feedback_alpha_start: Annotated[float, Range("[0, 1]"), DAY] = 0.999
    """alpha of Eq. 4 at the start of the forward phase (1 = only the oracle's best action earns +1)"""
    feedback_alpha_end: Annotated[float, Range("[0, 1]"), DAY] = 0.999
    """alpha of Eq. 4 at the end of the forward phase (alpha moves linearly: the teacher gets stricter)"""
    success_max_steps: Annotated[int, Range("[1, inf)"), DAY] = 30
    """an episode is tagged success if it reaches the goal (the terminal with the task's top reward) in fewer steps"""

    # The teacher as a person (docs/protocol.md); the defaults are the paper's perfect, instant, tireless teacher
    teacher: Annotated[Literal["oracle", "human", "browser"], DAY] = "oracle"
    """who answers: "oracle" (Eq. 4, distorted by the flags below), "human" (you, in the terminal: y, Enter, q) or
    "browser" (a person at the web page whose address the run prints: Yes, No, End the day)"""
    participant: Annotated[str | None, DAY] = None
    """--teacher browser: the person's ID, written with each answer into runs/{run}/answers.jsonl"""
    host: Annotated[str, DAY] = "127.0.0.1"
    """--teacher browser: where the page listens, HOST or HOST:PORT (0.0.0.0: other machines too; no port: any)"""
    teacher_noise: Annotated[float, Range("[0, 1]"), DAY] = 0.0
    """probability that the teacher's judgement is flipped (+1 <-> no feedback)"""
    teacher_sparsity: Annotated[float, Range("[0, 1]"), DAY] = 1.0
    """probability that a +1 judgement is actually given (otherwise no feedback)"""
    teacher_delay: Annotated[int, Range("[0, inf)"), DAY] = 0
    """env steps between a transition and the arrival of its signal (which labels the later transition)"""
    credit_window: Annotated[int, Range("[1, inf)"), DAY] = 1
    """each arriving signal labels this many most recent transitions (teacher_delay + 1 covers the right one)"""
    feedback_budget: Annotated[int | None, Range("[1, inf)"), DAY] = None
    """the teacher leaves after this many +1 signals (None: never); then TAMER stops learning"""
    budget_ends_forward_phase: Annotated[bool, DAY] = False
    """when the budget is spent, end the forward phase and sleep (otherwise keep acting, without feedback)"""

    # Sleep phase: offline IQ-Learn (Eq. 2), no environment steps
    sleep_gradient_steps: Annotated[int, Range("[1, inf)")] = 3000
    """gradient steps of the sleep phase"""
    sleep_batch_size: Annotated[int, Range("[1, inf)")] = 32
    """transitions from the success set, and as many from the whole buffer, per step"""
    sleep_q_lr: Annotated[float, Range("(0, inf)")] = 1e-3
    """Adam learning rate of the soft Q network"""
    sleep_temperature: Annotated[float, Range("(0, inf)")] = 0.1
    """temperature of the soft value V(s) = temp * logsumexp(Q(s, .) / temp)"""
    sleep_chi2_coef: Annotated[float, Range("[0, inf)")] = 0.5
    """weight of the chi-squared regulariser, 1 / (4 * 0.5) as IQ-Learn; 0 turns it off"""
    sleep_seed: Annotated[int | None, Range(SEED_RANGE)] = None
    """None: the sleep goes on with the random streams where the day left them; an integer re-seeds them before the
    sleep (several sleeps on one day)"""

    # Saved days, evaluation
    save_buffer: bool = False
    """write the day (memories, episode table, oracle, TAMER's H, random states) to runs/{run}/day.pt"""
    sleep_from: str | None = None
    """run only the night and the final tests on the day saved in this run directory (by --save-buffer); the day's
    flags (env, seed, teacher, TAMER) replace this run's"""
    eval_episodes: Annotated[int, Range("[1, inf)"), DAY] = 20
    """greedy episodes of each evaluation on a toy-text env, on fixed reset seeds (the maze's tests are one episode
    from each of their start cells)"""

    def fill_teacher_defaults(self) -> "Args":
        """The flags left at None take the default of --teacher (the simulated teacher's are the paper's)."""
        for name, value in TEACHER_DEFAULTS[self.teacher].items():
            setattr(self, name, value if getattr(self, name) is None else getattr(self, name))
        return self

    def day_settings(self) -> dict:
        """What the day runs with: every flag marked DAY, here or in a subclass (which may redefine one), kept whole."""
        hints = [typing.get_type_hints(c, include_extras=True) for c in type(self).__mro__ if is_dataclass(c)]
        marked = [f.name for f in fields(self) if any(DAY in getattr(h.get(f.name), "__metadata__", ()) for h in hints)]
        return {name: getattr(self, name) for name in marked}

    def night_settings(self) -> dict:
        """What the night's learner runs with (setting x from flag sleep_x)."""
        return {"q_lr": self.sleep_q_lr, "temperature": self.sleep_temperature, "chi2_coef": self.sleep_chi2_coef}

    def sleep_learner(self, obs_dim: int, n_actions: int, h_net: nn.Module, device) -> "Sleep":
        """The night's learner (the study module's Args returns its variants here; only its sham uses H)."""
        return Sleep(obs_dim, n_actions, device, **self.night_settings())

    def sleep_variant(self) -> str:
        """The night in a line, for summary.json: what it runs with."""
        settings = {"gradient_steps": self.sleep_gradient_steps, "batch_size": self.sleep_batch_size,
                    **self.night_settings(), "seed": self.sleep_seed}  # fmt: skip
        return " ".join(f"{k}={v}" for k, v in settings.items())


def make_env(env_id: str) -> gym.Env:
    """The maze, or a toy-text env with its state as a one-hot vector (the maze's observation) and a step limit."""
    if env_id in MAZE_IDS:
        return gym.make(env_id)
    limit = None if gym.spec(env_id).max_episode_steps else TOY_TEXT_MAX_STEPS
    return OneHot(gym.make(env_id, max_episode_steps=limit))


class OneHot(gym.ObservationWrapper):
    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.observation_space = gym.spaces.Box(0.0, 1.0, (int(env.observation_space.n),), np.float32)

    def observation(self, obs):
        one_hot = np.zeros(self.observation_space.shape, np.float32)
        one_hot[int(obs)] = 1.0
        return one_hot


# ---------------------------------------------------------------------------------------------------------------------
# ALGO LOGIC: the teacher's model of the task, the network, Eq. 1-4 and the teacher


def optimal_q(env: gym.Env, gamma: float = GAMMA) -> np.ndarray:
    """Exact Q* by value iteration (the "fully trained model"): the maze's own, or from a toy-text env's model
    (P[s][a] = [(probability, s', reward, terminated)]), whose slippery moves give expected values."""
    if env.spec.id in MAZE_IDS:
        return gridworld_env.optimal_q(env.unwrapped.variant, gamma)
    model = env.unwrapped.P
    n_states, n_actions = len(model), len(model[0])
    k = max(len(outcomes) for moves in model.values() for outcomes in moves.values())
    prob, reward, going_on = (np.zeros((n_states, n_actions, k)) for _ in range(3))
    next_state = np.zeros((n_states, n_actions, k), dtype=np.int64)
    for state, moves in model.items():
        for action, outcomes in moves.items():
            for i, (p, s_next, r, terminated) in enumerate(outcomes):
                prob[state, action, i], next_state[state, action, i] = p, s_next
                reward[state, action, i], going_on[state, action, i] = r, not terminated
    q = np.zeros((n_states, n_actions))
    while True:
        q_new = (prob * (reward + gamma * going_on * q.max(1)[next_state])).sum(-1)
        if np.abs(q_new - q).max() < 1e-10:
            return q_new
        q = q_new


def top_reward(env: gym.Env) -> float:
    """The reward of the task's goal, which a success must end on: the maze pays +1 at G and nothing else; a toy-text
    env, the largest reward in its model (FrozenLake's goal, Taxi's drop-off, CliffWalking's last step)."""
    if env.spec.id in MAZE_IDS:
        return 1.0
    return max(r for moves in env.unwrapped.P.values() for outcomes in moves.values() for _, _, r, _ in outcomes)


def is_success(terminated: bool, reward: float, length: int, max_steps: int, goal_reward: float) -> bool:
    """The success tag: the goal (the terminal with the task's top reward, not FrozenLake's holes) in time."""
    return bool(terminated) and reward >= goal_reward and length < max_steps


class QNetwork(nn.Module):
    """The 30-32-32-4 MLP of the authors, for TAMER's H(s, a) and the sleep's soft Q(s, a); `kwargs` rebuild it."""

    def __init__(self, obs_dim: int, n_actions: int, hidden: int = 32):
        super().__init__()
        self.kwargs = {"obs_dim": obs_dim, "n_actions": n_actions, "hidden": hidden}
        self.network = nn.Sequential(
            nn.Linear(obs_dim, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, n_actions)
        )

    def forward(self, x):
        return self.network(x)


def linear_schedule(start: float, end: float, duration: int, t: int) -> float:
    """From `start` at t = 0 to `end` at t = duration, then constant."""
    return start + (end - start) * min(t, duration) / max(duration, 1)


def oracle_feedback(q_star_sa, q_star_best, alpha):
    # Eq. 4, sign-safe: h = 1 if Q*(s, a) >= Q*(s, a*) - (1 - alpha) |Q*(s, a*)|, else 0
    return (q_star_sa >= q_star_best - (1.0 - alpha) * abs(q_star_best)) * 1.0


class Teacher:
    """A simulated person between Eq. 4 and the learner: noisy, sparse, late and limited (paper Sec. VII's future work).
    A call hands over the perfect answer h* about buffer index `step` (Eq. 4's 0 or 1, or any value of another
    teacher) and returns the labels arriving now, {index: h}, each the answer as given (0: no feedback, no label).
    The judgement is flipped with probability `noise` (1 - h for 0 and 1, -h for any other answer); an answer is
    clicked with probability `sparsity`; a click about step t arrives at t + `delay` and labels that transition and
    the `credit_window` - 1 before it (Deep TAMER). The teacher leaves after `budget` positive signals. Its own
    generator: the defaults are the perfect teacher exactly."""

    def __init__(self, noise=0.0, sparsity=1.0, delay=0, credit_window=1, budget=None, seed=0):
        self.noise, self.sparsity, self.delay, self.credit_window = noise, sparsity, delay, credit_window
        self.budget, self.rng = budget, np.random.default_rng(seed)
        self.in_flight = collections.deque()  # clicks on their way, oldest first
        self.positives = self.perfect_positives = 0  # +1 signals delivered; +1 answers of the perfect teacher (Eq. 4)

    @property
    def gone(self) -> bool:  # the budget is spent: no more feedback from now on
        return self.budget is not None and self.positives >= self.budget

    def __call__(self, step: int, h_star: float) -> dict[int, float]:
        self.perfect_positives += int(h_star > 0)
        flip, click = self.rng.random(2)  # always two draws: the stream does not depend on the answers
        h = (1.0 - h_star if h_star in (0, 1) else -h_star) if flip < self.noise else h_star
        h = h if click < self.sparsity else 0.0
        self.in_flight.append(h)
        if len(self.in_flight) <= self.delay:
            return {}
        h = self.in_flight.popleft()
        if h == 0 or self.gone:
            return {}
        self.positives += int(h > 0)
        return dict.fromkeys(range(max(0, step - self.credit_window + 1), step + 1), float(h))


def tamer_loss(h_net, obs, actions, feedback):
    # Eq. 1: E[(H(s, a) - h)^2], gamma = 0: no bootstrapping, no target network
    return F.mse_loss(h_net(obs).gather(1, actions[:, None]).squeeze(1), feedback)


def soft_value(q, temperature: float):
    """V(s) = temp * logsumexp(Q(s, .) / temp) (discrete IQ-Learn)."""
    return temperature * torch.logsumexp(q / temperature, dim=1)


def iq_loss(q_net, target_net, obs, actions, next_obs, terminated, is_expert, gamma, temperature, chi2_coef, rows=None):
    # Eq. 2 (to minimise): y = (1 - done) gamma V_target(s');
    # L = -E_success[Q(s,a) - y] + E_all[V(s) - y] + chi2 * E_all[(Q(s,a) - y)^2]   (`rows`: of the last two terms)
    q = q_net(obs)
    q_sa = q.gather(1, actions[:, None]).squeeze(1)
    with torch.no_grad():
        y = (1.0 - terminated) * gamma * soft_value(target_net(next_obs), temperature)  # V_target of s', not of s
    v_s = soft_value(q, temperature)
    rows = slice(None) if rows is None else rows
    expert_term = -(q_sa - y)[is_expert].mean()
    value_term = (v_s - y)[rows].mean()
    chi2_term = chi2_coef * (q_sa - y)[rows].pow(2).mean()
    terms = {"iq_expert_term": expert_term, "iq_value_term": value_term, "iq_chi2_term": chi2_term}
    return sum(terms.values()), terms  # the total and its named terms: the sleep logs whatever terms come back


def recover_reward(q_sa, v_next, terminated, gamma):
    # Eq. 3: r(s, a, s') = Q(s, a) - (1 - terminated) gamma V(s')
    return q_sa - (1.0 - terminated) * gamma * v_next


def reward_table(q_net, next_cell, gamma, temperature, device):
    """Eq. 3 for every (s, a) of the maze, with s' the deterministic move: a (30, 4) table."""
    with torch.no_grad():
        q = q_net(torch.eye(gridworld_env.N_CELLS, device=device)).cpu()
    next_cell = torch.as_tensor(next_cell)
    terminated = (next_cell == gridworld_env.GOAL).float()
    return recover_reward(q, soft_value(q, temperature)[next_cell], terminated, gamma)


def greedy_actions(q_net, device, n_states: int | None = None) -> np.ndarray:
    """The greedy policy as a table: one forward pass over every state's one-hot observation (the maze's 30 cells
    unless `n_states` says otherwise)."""
    with torch.no_grad():
        return q_net(torch.eye(n_states or gridworld_env.N_CELLS, device=device)).argmax(1).cpu().numpy()


class ReplayBuffer:
    """Every forward-phase transition (s, a, s', h, terminated), preallocated, and the success tag of its episode."""

    def __init__(self, capacity: int, obs_dim: int, device: torch.device):
        self.obs, self.next_obs = (torch.zeros(capacity, obs_dim, device=device) for _ in range(2))
        self.actions = torch.zeros(capacity, dtype=torch.long, device=device)
        self.feedback = torch.zeros(capacity, device=device)  # h, written by the teacher when a signal arrives
        self.terminated = torch.zeros(capacity, device=device)
        self.success = torch.zeros(capacity, dtype=torch.bool, device=device)
        self.size = 0  # transitions stored (fewer than the capacity when the teacher stops early)
        self.episodes = []  # (start, end) of each episode that ended: buffer[start:end]

    def add(self, obs, action, next_obs, terminated) -> None:
        self.obs[self.size], self.actions[self.size] = torch.as_tensor(obs), action
        self.next_obs[self.size], self.terminated[self.size] = torch.as_tensor(next_obs), float(terminated)
        self.size += 1

    def tag_episode(self, start: int, success: bool) -> bool:
        """Tag the trajectory buffer[start:size], which just ended, as a success or a failure."""
        self.success[start : self.size] = success
        self.episodes.append((start, self.size))
        return success

    def batch(self, idx: torch.Tensor):
        return self.obs[idx], self.actions[idx], self.next_obs[idx], self.feedback[idx], self.terminated[idx]


# ---------------------------------------------------------------------------------------------------------------------
# ALGO LOGIC: the day (forward phase) and the person at the terminal


class Day:
    """The day's learner and what made it, as `Sleep` is the night's: TAMER's feedback model H (Eq. 1, gamma = 0),
    its optimiser, and `settings` (every flag marked DAY in Args: a saved day keeps them whole). A change goes here:
    a new day flag (marked DAY, read from `settings`); `answer`, the perfect teacher's h* (Eq. 4's 0 or 1: any sign
    and size reaches H as given); H (QNetwork keeps its arguments, which a saved day rebuilds it from); `update`,
    TAMER's step (Eq. 1); `teacher`, the simulated person."""

    def __init__(self, settings: dict, device, obs_dim: int = 0, n_actions: int = 0, saved: dict | None = None):
        """A new day's H for `obs_dim` and `n_actions`, or a saved day's (`saved`: its kwargs and state_dict)."""
        self.settings = settings
        kwargs = {"obs_dim": obs_dim, "n_actions": n_actions} if saved is None else saved["kwargs"]
        self.h_net = QNetwork(**kwargs).to(device)  # it keeps its constructor arguments (kwargs) for a saved day
        if saved is not None:
            self.h_net.load_state_dict(saved["state_dict"])
        self.h_optimizer = torch.optim.Adam(self.h_net.parameters(), lr=settings["tamer_h_lr"], fused=True)

    def teacher(self) -> Teacher:  # the simulated person, on a random stream of its own
        s = self.settings
        return Teacher(s["teacher_noise"], s["teacher_sparsity"], s["teacher_delay"], s["credit_window"],
                       s["feedback_budget"], seed=s["seed"] + 7919)  # fmt: skip

    def answer(self, q_star_sa: float, q_star_best: float, alpha: float) -> float:
        """The perfect teacher's answer h* about (s, a): Eq. 4, 1 or 0."""
        return oracle_feedback(q_star_sa, q_star_best, alpha)

    def update(self, buffer: ReplayBuffer, idx: torch.Tensor | None = None) -> torch.Tensor:
        """TAMER's update: H regresses on the feedback (Eq. 1) of the rows `idx` (None: a random batch); H's loss."""
        n = self.settings["tamer_batch_size"]
        idx = torch.randint(0, buffer.size, (n,), device=buffer.obs.device) if idx is None else idx
        h_loss = tamer_loss(self.h_net, buffer.obs[idx], buffer.actions[idx], buffer.feedback[idx])
        self.h_optimizer.zero_grad()
        h_loss.backward()
        self.h_optimizer.step()
        return h_loss


def forward_phase(day: Day, env, q_star: np.ndarray, teacher, buffer: ReplayBuffer, evaluator, writer, page=None):
    """The day: TAMER (`day`, Eq. 1, gamma = 0) acts on H and fits it to the teacher's yes/no feedback (Eq. 4
    through the Teacher, or, by --teacher, a person at the terminal or the web page); every transition is remembered,
    every episode tagged. With --budget-ends-forward-phase the day ends when the teacher's budget is spent."""
    s, h_net, device = day.settings, day.h_net, buffer.obs.device
    human = None
    if s["teacher"] in ("human", "browser"):  # you, at the terminal or at the web page
        human = HumanTeacher(env.unwrapped.variant, s["success_max_steps"], h_net, device, page)
    n, log_every = s["tamer_total_timesteps"], LOG_FREQUENCY[s["teacher"]]
    progress = Progress("tamer", n, evaluator)
    h_loss = torch.zeros((), device=device)
    optimum_at = None  # (step, +1 signals) at the first evaluation where TAMER's greedy path is the shortest
    evaluated_at, ep_start, ep_length, successes, ep_return = 0, 0, 0, 0, 0.0
    goal_reward = top_reward(env)
    obs, _ = env.reset(seed=s["seed"])
    for step in range(n):
        StopSignals.check()  # a stop signal ends the run here, between two steps
        epsilon = linear_schedule(s["start_e"], s["end_e"], int(EXPLORATION_FRACTION * n), step)
        explore = random.random() < epsilon
        cell = int(obs.argmax())
        if explore:
            action = env.action_space.sample()
        else:
            with torch.no_grad():
                h_values = h_net(torch.as_tensor(obs, device=device))
            action = int(h_values.argmax()) if not human else human.propose(h_values, cell)

        # the teacher watches (s, a): the perfect answer (Eq. 4), then the person's (Teacher), or yours
        taught = not teacher.gone  # after the budget is spent, TAMER has nothing to learn from
        feedback_alpha = linear_schedule(s["feedback_alpha_start"], s["feedback_alpha_end"], n - 1, step)  # stricter
        h_star = day.answer(q_star[cell, action], q_star[cell].max(), feedback_alpha) if taught else 0.0
        if human and taught:
            h_star = human(cell, action, explore, step + 1, teacher.positives, h_star, successes)
            if h_star is None:  # q or the end of the input: stop teaching, the sleep starts
                break
        labels = teacher(step, h_star)  # {transition: h} that this step's arriving signal labels
        buffer.feedback[list(labels)] = torch.tensor(list(labels.values()), device=device)

        next_obs, reward, terminated, truncated, _ = env.step(action)
        buffer.add(obs, action, next_obs, terminated)
        ep_length, ep_return = ep_length + 1, ep_return + float(reward)
        obs = next_obs
        if terminated or truncated:  # an episode cut off by the end of the phase stays untagged: a failure
            successes += buffer.tag_episode(ep_start, is_success(terminated, reward, ep_length,
                                                                 s["success_max_steps"], goal_reward))  # fmt: skip
            writer.add_scalar("charts/episodic_return", ep_return, step + 1)
            writer.add_scalar("charts/episodic_length", ep_length, step + 1)
            ep_start, ep_length, ep_return = step + 1, 0, 0.0
            obs, _ = env.reset()

        # TAMER's update: H regresses on the feedback (Eq. 1); a person's answer gets several
        if taught and human and step + 1 >= s["tamer_learning_starts"]:
            h_loss = human.learn(day, buffer, HUMAN_UPDATES_PER_ANSWER, s["tamer_batch_size"])
        elif taught and step >= s["tamer_learning_starts"]:
            h_loss = day.update(buffer)

        # TRY NOT TO MODIFY: logging, the divergence check and periodic evaluation
        last_step = step == n - 1 or (teacher.gone and s["budget_ends_forward_phase"])
        if (step + 1) % log_every == 0 or last_step:
            if not math.isfinite(h_loss.item()):
                raise Diverged(f"TAMER's H diverged (its loss is NaN or inf) by env step {step + 1}; "
                               f"try a lower --tamer-h-lr (it is {s['tamer_h_lr']:g})")  # fmt: skip
            for tag, value in (("losses/tamer_loss", h_loss.item()), ("feedback/positive", teacher.positives),
                               ("feedback/positive_rate", teacher.positives / (step + 1)),
                               ("feedback/alpha", feedback_alpha), ("charts/epsilon", epsilon),
                               ("charts/SPS", progress.sps(step + 1))):  # fmt: skip
                writer.add_scalar(tag, value, step + 1)
        report = {"positives": teacher.positives}
        if (step + 1) % EVAL_FREQUENCY == 0 or last_step:
            metrics = evaluator("tamer", greedy_actions(h_net, device, buffer.obs.shape[1]), step + 1)
            evaluated_at = step + 1
            report["eval length"] = metrics["eval/tamer_episode_length"]
            if optimum_at is None and report["eval length"] == evaluator.optimum:
                optimum_at = (step + 1, teacher.positives)
        progress(step + 1, **report)
        if last_step:
            break

    if evaluated_at != buffer.size:  # the person stopped between two evaluations
        evaluator("tamer", greedy_actions(h_net, device, buffer.obs.shape[1]), buffer.size)
    at = optimum_at or (None, None)
    stats = {"feedback/positive": teacher.positives, "feedback/perfect_positive": teacher.perfect_positives,
             "feedback/steps": buffer.size, "feedback/positive_rate": teacher.positives / max(buffer.size, 1),
             "feedback/step_to_tamer_optimum": at[0], "feedback/positive_to_tamer_optimum": at[1]}  # fmt: skip
    if human:
        stats.update(human.finish(buffer.size, teacher.positives, successes))
    return stats


class HumanTeacher:
    """You as the teacher (docs/teachers.md). The maze is drawn with the agent and its move; you answer on standard
    input: y (+1), Enter (no feedback) or q (stop teaching: the sleep starts). The end of the input counts as q, so
    a pipe or a file of answers works as well as a keyboard. With a `page` (browser_teacher.BrowserTeacher) you answer
    on the web page instead: Yes (+1), No (no feedback), no answer (space: the move goes by unjudged), End the day."""

    def __init__(self, variant: str, success_max_steps: int, h_net: QNetwork, device: torch.device, page=None):
        self.variant, self.h_net, self.device, self.page = variant, h_net, device, page
        self.own_way = self.greedy_length()  # the length of the agent's own (greedy) way from S; 200: it never ends
        self.next_cell = gridworld_env.transition_table(variant)
        self.answers = self.agreement = 0  # answers given, and how many Eq. 4 (the oracle) would have given too
        self.refused = np.zeros((gridworld_env.N_CELLS, gridworld_env.N_ACTIONS))  # Enter answers per (cell, move)
        self.answers_to_goal = None  # answers given when the agent's own (greedy) way from S first reached G
        self.echo = page is None and not sys.stdin.isatty()  # piped answers are not echoed by a terminal: print them
        self.unread = b""  # input read but not yet answered (a pipe can bring several answers at once)
        if page is not None:
            return
        say("You are the teacher. The agent A must reach G by the shortest path (19 steps from S).\nFor each move "
            "answer: y = good (+1), Enter = no feedback, q = stop teaching (the sleep starts).\nA move you answer "
            "with Enter is not proposed again in that cell while it has moves you have not judged.\nThe sleep learns "
            f"from the walks from S to G in fewer than {success_max_steps} steps: teach one.")  # fmt: skip

    def propose(self, h_values: torch.Tensor, cell: int) -> int:
        """The agent's move: greedy on H, but never a move you refused in this cell before the ones you have not."""
        return int(np.argmax(h_values.cpu().numpy() - 2.0 * self.refused[cell]))  # H is in about [0, 1]

    def __call__(self, cell, action, explore, step, positives, h_oracle, successes) -> float | None:
        """Your answer about the move `action` from `cell`: 1.0, 0.0, or None to stop teaching."""
        how = " (exploring: a random move)" if explore else ""
        how += " into a wall: it stays where it is" if self.next_cell[cell, action] == cell else ""
        way = f"reaches G in {self.own_way} steps" if self.own_way < 200 else "does not reach G yet"
        maze = gridworld_env.draw_maze(self.variant, agent=cell, arrows={cell: action})
        move = gridworld_env.ACTION_NAMES[action]
        if self.page is not None:
            return self.ask_page(cell, action, step, maze, f"{move}{how}", way, positives, successes, h_oracle)
        say(f"\nstep {step} | answers {self.answers} | positives given {positives} | its own way from S: {way} | "
            f"walks to G in time: {successes}\n{maze}the agent moves {move}{how}")  # fmt: skip
        while True:
            print("good move? [y / Enter / q] ", end="", flush=True)
            with StopSignals.waiting():  # Ctrl-C while you think stops the run at once
                line = self.read_line()
            answer = line.strip().lower() if line else "q"
            if self.echo:
                say(answer or "(Enter)")
            if answer == "q":
                return None
            if answer in ("y", ""):
                return self.counted(cell, action, float(answer == "y"), h_oracle)
            say(f"{answer!r}? type y for +1, press Enter for no feedback, or type q to stop teaching")

    def read_line(self) -> str:
        """The next line of standard input ('' at its end), waited for in short slices: a stop signal is seen within
        them even if the kernel handed it to another of our threads, which would not wake a blocking read."""
        try:
            fd = sys.stdin.fileno()
        except (AttributeError, OSError, ValueError):  # a stream with no descriptor (a test's, an embedding app's)
            return sys.stdin.readline()
        while b"\n" not in self.unread:
            StopSignals.check()
            if select.select([fd], [], [], 0.25)[0]:
                chunk = os.read(fd, 4096)
                if not chunk:  # the end of the input
                    break
                self.unread += chunk
        line, newline, self.unread = self.unread.partition(b"\n")
        return (line + newline).decode(errors="replace")

    def ask_page(self, cell, action, step, maze, move, way, positives, successes, h_oracle) -> float | None:
        """The move on the web page; None once the day is over (End the day, or the page closed)."""
        info = {"step": step, "answers": self.answers, "positives given": positives, "the agent moves": move,
                "its own way from S": way, "walks to G in time": successes}  # fmt: skip
        with StopSignals.waiting():  # Ctrl-C while the person thinks stops the run at once
            h = self.page.ask(step, gridworld_env.ACTION_NAMES[action], state_text=maze, info=info)
        if self.page.ended is not None:
            return None
        if h is None:
            return 0.0  # no answer: the move goes by without feedback and is not counted as an answer
        return self.counted(cell, action, h, h_oracle)

    def counted(self, cell: int, action: int, h: float, h_oracle: float) -> float:
        """An answer h (1.0 or 0.0), counted: as the oracle's or not, and a refused move not proposed again first."""
        self.answers += 1
        self.agreement += int(h == h_oracle)
        self.refused[cell, action] += 1.0 - h
        return h

    def greedy_length(self) -> int:
        return gridworld_env.greedy_episode_length(greedy_actions(self.h_net, self.device), self.variant)

    def learn(self, day: "Day", buffer: ReplayBuffer, updates: int, batch_size: int) -> torch.Tensor:
        """TAMER's update (Eq. 1) after your answer: several gradient steps, each on the newest answer and a replay of
        the earlier ones (Deep TAMER's remedies), so that the answer takes effect before the next move."""
        for _ in range(updates):
            replay = torch.randint(0, buffer.size, (batch_size - 1,), device=self.device)
            newest = torch.tensor([buffer.size - 1], device=self.device)
            h_loss = day.update(buffer, torch.cat([newest, replay]))
        self.own_way = self.greedy_length()
        if self.own_way < 200 and self.answers_to_goal is None:
            self.answers_to_goal = self.answers
        return h_loss

    def finish(self, steps: int, positives: int, successes: int) -> dict:
        then = "now the agent sleeps" if successes else "the agent did not walk from S to G in time, so it cannot sleep"
        say(f"\nthank you: {steps} steps taught, {positives} positives given ({self.agreement} of {self.answers} "
            f"answers as the oracle's, Eq. 4); {then}")  # fmt: skip
        return {"feedback/oracle_agreement": self.agreement / max(self.answers, 1), "feedback/answers": self.answers,
                "feedback/answers_to_tamer_goal": self.answers_to_goal}  # fmt: skip


# ---------------------------------------------------------------------------------------------------------------------
# ALGO LOGIC: the night (sleep phase): the sleep loss and its update


class Sleep:
    """The night's learner: soft Q by IQ-Learn (Eq. 2) on replay rows, then expert rows; its target follows softly.
    The study module (inform_utils/sleep_variants_maze.py) subclasses it for its controls and loss rows: `loss` is
    where a variant changes the night."""

    tag = "iq_loss"  # the loss's name in the logs

    def __init__(self, obs_dim: int, n_actions: int, device, *, q_lr: float, temperature: float, chi2_coef: float):
        self.q_net = QNetwork(obs_dim, n_actions).to(device)
        self.q_target = QNetwork(obs_dim, n_actions).to(device)
        self.q_target.load_state_dict(self.q_net.state_dict())
        self.optimizer = torch.optim.Adam(self.q_net.parameters(), lr=q_lr, fused=True)
        self.gamma, self.temperature, self.chi2_coef = GAMMA, temperature, chi2_coef

    def loss(self, obs, actions, next_obs, feedback, terminated, is_expert, **kw):
        """The loss of one batch and its named terms (a variant calls this, so that a term added here reaches it)."""
        return iq_loss(self.q_net, self.q_target, obs, actions, next_obs, terminated, is_expert, self.gamma,
                       self.temperature, self.chi2_coef, **kw)  # fmt: skip

    def update(self, batch, is_expert) -> tuple[torch.Tensor, dict]:
        loss, terms = self.loss(*batch, is_expert)
        self.optimizer.zero_grad()
        loss.backward()
        self.optimizer.step()
        with torch.no_grad():  # the target Q follows softly (TAU 1: a copy)
            for param, target_param in zip(self.q_net.parameters(), self.q_target.parameters(), strict=True):
                target_param.lerp_(param, TAU)
        return loss, terms


def sleep_phase(learner: Sleep, buffer: ReplayBuffer, expert_idx, steps: int, batch_size: int, evaluator, writer,
                device) -> dict:  # fmt: skip
    """The night: offline IQ-Learn (Eq. 2) on the buffer, the successful trajectories (`expert_idx`) as the expert
    set, no environment steps."""
    stats, losses = {}, {}
    is_expert = torch.arange(2 * batch_size, device=device) >= batch_size  # the batch: replay rows, then expert rows
    progress = Progress("sleep", steps, evaluator)
    for step in range(1, steps + 1):
        StopSignals.check()
        replay = torch.randint(0, buffer.size, (batch_size,), device=device)
        expert = expert_idx[torch.randint(0, expert_idx.numel(), (batch_size,), device=device)]
        loss, terms = learner.update(buffer.batch(torch.cat([replay, expert])), is_expert)

        # TRY NOT TO MODIFY: logging (one host sync per 100 steps to catch divergence) and periodic evaluation
        last_step = step == steps
        if step % LOG_FREQUENCY["oracle"] == 0 or last_step:
            tags = {learner.tag: loss, **terms}
            values = torch.stack(list(tags.values())).tolist()
            if not all(map(math.isfinite, values)):
                last = ", ".join(f"{k.split('/')[1]} {v:.4g}" for k, v in losses.items())
                raise Diverged(f"the sleep loss diverged (NaN or inf) by gradient step {step}; last finite losses: "
                               f"{last or 'none yet'}; try a lower --sleep-q-lr")  # fmt: skip
            losses = {f"losses/{tag}": value for tag, value in zip(tags, values, strict=True)}
            for tag, value in {**losses, "sleep/SPS": progress.sps(step)}.items():
                writer.add_scalar(tag, value, step)
        report = {"iq_loss": losses.get("losses/iq_loss")}
        if step % EVAL_FREQUENCY == 0 or last_step:
            metrics = evaluator("inform", greedy_actions(learner.q_net, device, buffer.obs.shape[1]), step)
            report["eval length"] = metrics["eval/inform_episode_length"]
            if "sleep/step_to_inform_optimum" not in stats and report["eval length"] == evaluator.optimum:
                stats["sleep/step_to_inform_optimum"] = step
        progress(step, **report)
    return {**stats, **losses}


# ---------------------------------------------------------------------------------------------------------------------
# ALGO LOGIC: the evaluation protocol: greedy from S, on the wall maze, from the start set and from all 29 cells


def evaluate(policy: np.ndarray, env: gym.Env, resets: list[dict], success_max_steps: int):
    """Run the greedy table policy once from each reset (the keyword arguments of env.reset: a maze's start cell, a
    toy-text env's seed); mean episode length and success rate."""
    lengths, successes = [], []
    goal_reward = top_reward(env)
    for reset in resets:
        StopSignals.check()  # a long test (--eval-episodes 100000) stops within an episode
        obs, _ = env.reset(**reset)
        terminated = truncated = False
        length, reward = 0, 0.0
        while not (terminated or truncated):
            obs, reward, terminated, truncated, _ = env.step(policy[int(obs.argmax())])
            length += 1
        lengths.append(length)
        successes.append(is_success(terminated, reward, length, success_max_steps, goal_reward))
    return float(np.mean(lengths)), float(np.mean(successes))


def start_cells(*cells: int) -> list[dict]:  # a maze's resets from these start cells
    return [{"options": {"start_cell": cell}} for cell in cells]


class Evaluator:
    """Greedy evaluation on the plain maze, the wall maze, the start set and all 29 starts, or on a toy-text env from
    `eval_episodes` fixed reset seeds; logs eval/ tags. `optimum` is the shortest mean length a greedy policy can
    have there (the maze's 19 steps; on a toy-text env, exact Q*'s)."""

    def __init__(self, env_id: str, success_max_steps: int, eval_episodes: int, seed: int, writer=None):
        self.writer, self.success_max_steps, self.maze = writer, success_max_steps, env_id in MAZE_IDS
        self.seconds, self.final = 0.0, {}
        if self.maze:
            self.envs = {name: gym.make(f"KnoxStoneMaze{suffix}-v0") for name, suffix in
                         (("plain", ""), ("wall", "Wall"), ("start_set", "StartSet"))}  # fmt: skip
            self.tests = {  # tag: (maze, its start cells, what is measured)
                "eval/{}_episode_length": ("plain", (gridworld_env.START,), 0),
                "eval/wall/{}_episode_length": ("wall", (gridworld_env.START,), 0),
                "eval/start_set/{}_episode_length": ("start_set", gridworld_env.START_SET, 0),
                "eval/start_set/{}_success_rate": ("start_set", gridworld_env.START_SET, 1),
                "eval/all_starts/{}_success_rate": ("plain", gridworld_env.ANY_START, 1),
            }
            self.optimum = gridworld_env.greedy_episode_length(gridworld_env.optimal_q("plain").argmax(1))  # 19 steps
        else:
            self.envs = {"plain": make_env(env_id)}
            resets = [{"seed": 1_000_000 + 1000 * seed + ep} for ep in range(eval_episodes)]
            self.tests = {"eval/{}_episode_length": ("plain", resets, 0), "eval/{}_success_rate": ("plain", resets, 1)}
            self.optimum = evaluate(optimal_q(self.envs["plain"]).argmax(1), self.envs["plain"], resets,
                                    success_max_steps)[0]  # fmt: skip

    def __call__(self, name: str, policy: np.ndarray, step: int) -> dict:
        t0, results, metrics = time.time(), {}, {}
        for tag, (maze, starts, which) in self.tests.items():
            if (maze, id(starts)) not in results:  # one set of episodes gives the length and the success rate
                resets = start_cells(*starts) if self.maze else starts
                results[maze, id(starts)] = evaluate(policy, self.envs[maze], resets, self.success_max_steps)
            metrics[tag.format(name)] = results[maze, id(starts)][which]
        for tag, value in metrics.items() if self.writer is not None else ():
            self.writer.add_scalar(tag, value, step)
        self.final.update(metrics)
        self.seconds += time.time() - t0
        return metrics

    def close(self):
        for env in self.envs.values():
            env.close()


# ---------------------------------------------------------------------------------------------------------------------
# main: Algorithm 1 in the paper's order


def main(args: Args, oracle_q: np.ndarray | None, stop: "StopSignals", saved: dict | None = None) -> dict:
    run_start, run_dir, writer, env, evaluator, page = time.time(), None, None, None, None, None
    summary = {"time/oracle_s": 0.0, "time/tamer_s": 0.0, "time/sleep_s": 0.0}
    summary["sleep_from"] = os.path.abspath(args.sleep_from) if args.sleep_from else None  # a saved day's run
    summary["sleep_variant"] = args.sleep_variant()
    status, failure, phase = "completed", None, "startup"
    try:  # a stop (signal, dead reader) anywhere below finds the except that saves what finished
        run_dir = make_run_dir(f"{args.env_id}__{args.exp_name}__{args.seed}__{int(time.time())}")  # input checked
        say(f"run directory: {run_dir}")
        StopSignals.check()  # a stop while starting ends here, with a summary in the run directory
        seed_everything(args.seed)
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")  # CUDA matmuls refuse determinism without it
        torch.use_deterministic_algorithms(True)
        torch.set_num_threads(1)  # one thread is fastest for networks this small
        device = torch.device("cuda" if torch.cuda.is_available() and args.cuda else "cpu")
        if args.track:  # Weights & Biases mirrors the TensorBoard events (CleanRL's --track); before the writer
            import wandb

            wandb.init(project=os.environ.get("WANDB_PROJECT", "inform"), sync_tensorboard=True, config=vars(args),
                       name=os.path.basename(run_dir), dir=run_dir, save_code=True)  # fmt: skip
        writer = SummaryWriter(run_dir)
        table = "\n".join(f"|{key}|{value}|" for key, value in vars(args).items())
        writer.add_text("hyperparameters", "|param|value|\n|-|-|\n" + table)
        env = make_env(args.env_id)
        env.action_space.seed(args.seed)
        evaluator = Evaluator(args.env_id, args.success_max_steps, args.eval_episodes, args.seed, writer)
        obs_dim, n_actions = env.observation_space.shape[0], int(env.action_space.n)

        if saved is None:
            # ---- the oracle: exact Q* by value iteration (the "fully trained model"), or a teacher from a file
            phase, t0 = "oracle", time.time()
            q_star = optimal_q(env) if oracle_q is None else oracle_q
            summary["time/oracle_s"] = time.time() - t0
            evaluator("oracle", q_star.argmax(1), 0)

            # ---- forward phase ("day"): TAMER with the teacher's feedback, every transition remembered and tagged
            phase, t0 = "tamer", time.time() - evaluator.seconds  # the phase's clock stops during its evaluations
            buffer = ReplayBuffer(args.tamer_total_timesteps, obs_dim, device)
            page = open_page(run_dir, args.host, args.participant) if args.teacher == "browser" else None
            day = Day(args.day_settings(), device, obs_dim, n_actions)  # the day's learner and settings
            stats = forward_phase(day, env, q_star, day.teacher(), buffer, evaluator, writer, page)
            summary.update(stats)
            summary["time/tamer_s"] = time.time() - evaluator.seconds - t0
            if args.save_buffer:  # the day as it ended, for later nights (--sleep-from)
                save_day(f"{run_dir}/day.pt", day, buffer, q_star, {**stats, "time/tamer_s": summary["time/tamer_s"]})
        else:  # --sleep-from: a saved day's oracle, memories and H, its random streams where that day left them
            q_star, buffer, day = restore_day(saved, device)
            summary.update(saved["day_stats"], day_settings=saved["day_args"], tamer_h_kwargs=day.h_net.kwargs)
        h_net = day.h_net
        save_network(f"{run_dir}/tamer_h.pt", h_net, env_id=args.env_id)

        # ---- sleep phase ("night"): offline IQ-Learn on the success set and the whole buffer
        phase, t0 = "sleep", time.time() - evaluator.seconds
        if args.sleep_seed is not None:  # a night of its own: the random streams start afresh
            seed_everything(args.sleep_seed)
        expert_idx = buffer.success[: buffer.size].nonzero().squeeze(1)
        summary.update({"sleep/expert_transitions": int(expert_idx.numel()), "sleep/replay_transitions": buffer.size,
                        "sleep_skipped": expert_idx.numel() == 0})  # fmt: skip
        q_net = None
        if summary["sleep_skipped"]:  # no success: nothing to consolidate, no INFORM policy
            how = ("next time keep teaching until the agent has walked from S to G in time at least once"
                   if args.teacher in ("human", "browser") else "raise --tamer-total-timesteps")  # fmt: skip
            say(f"warning: the sleep is skipped and no INFORM policy is made: no episode reached G in fewer than "
                f"{args.success_max_steps} steps, so there is nothing to consolidate; {how}", sys.stderr)  # fmt: skip
        else:
            learner = args.sleep_learner(obs_dim, n_actions, h_net, device)
            summary.update(sleep_phase(learner, buffer, expert_idx, args.sleep_gradient_steps, args.sleep_batch_size,
                                       evaluator, writer, device))  # fmt: skip
            q_net = learner.q_net
        summary["time/sleep_s"] = time.time() - evaluator.seconds - t0

        # ---- the recovered reward (Eq. 3) on the maze the agent learned in, then the final evaluation
        phase = "eval"
        policies = {"oracle": q_star.argmax(1), "tamer": greedy_actions(h_net, device, obs_dim)}
        if q_net is not None:
            policies["inform"] = greedy_actions(q_net, device, obs_dim)
            extra = {"env_id": args.env_id, "gamma": GAMMA, "temperature": args.sleep_temperature}
            save_network(f"{run_dir}/inform_q.pt", q_net, **extra)
            if args.env_id in MAZE_IDS:  # the reward table needs the maze's deterministic moves
                reward = reward_table(q_net, env.unwrapped.next_cell, GAMMA, args.sleep_temperature, device)
                figure = reward_figure(reward.numpy(), f"recovered reward, seed {args.seed}")
                writer.add_figure("sleep/recovered_reward", figure)
                save_atomic({"reward": reward, **extra}, f"{run_dir}/recovered_reward.pt")
        if args.env_id not in MAZE_IDS:
            summary["maze_tests/skipped"] = f"the wall maze, start cells, reward table, drawings: none on {args.env_id}"
        for name, policy in policies.items():  # INFORM's at the sleep's last step, the others at the day's
            evaluator(name, policy, args.sleep_gradient_steps if name == "inform" else summary["feedback/steps"])
        if args.capture_video:  # after the evaluation: drawing changes no number
            record_videos(run_dir, {name: policy for name, policy in policies.items() if name != "oracle"})
        if args.teacher in ("human", "browser"):
            variant = env.unwrapped.variant
            drawn = [f"{title}, greedy from S:\n" + gridworld_env.draw_greedy_path(policies[name], variant)
                     for name, title in (("tamer", "TAMER (what you taught)"), ("inform", "INFORM (after the sleep)"))
                     if name in policies]  # fmt: skip
            say("\n" + "\n\n".join(drawn))
            if page is not None:
                page.show_outcome("\n\n".join(drawn))
        writer.flush()  # the events whole before the summary says completed (an error in TensorBoard's thread: here)
    except (KeyboardInterrupt, BrokenPipeError) as e:  # a signal, or the reader of our output died
        status, stop.broken_pipe = "interrupted", isinstance(e, BrokenPipeError)
    except Diverged as e:
        status, summary["error"] = "diverged", str(e)
    except Exception as e:  # a full disk (OSError: one line), or a bug (in the summary, then its traceback)
        status, summary["error"] = "failed", f"{type(e).__name__}: {(str(e).strip() or '-').splitlines()[0]}"
        failure = None if isinstance(e, OSError) else e
    if status != "completed" and phase in ("oracle", "tamer", "sleep"):  # how long the cut phase ran
        summary[f"time/{phase}_s"] = time.time() - evaluator.seconds - t0
    summary = end_run(summary, status, phase, run_dir, run_start, evaluator, (env, writer, page), stop, args.seed,
                      vars(args))  # fmt: skip
    if failure is not None:
        raise failure
    return summary


def cli(args: Args) -> int:
    """The command line after tyro (a malformed flag: tyro's own message, exit 2): check, load what the flags name,
    run; the exit code. The study module passes its own Args (a subclass with the study's flags)."""
    try:
        if gridworld_env is None:
            raise InputError("gridworld_env.py (the maze) is not importable: copy it next to this script")
        check_args(args)
        oracle_q = saved = None
        if args.sleep_from:  # a saved day: no oracle, no forward phase; its day flags replace these
            saved = load_day(args.sleep_from, type(args))
            flags = {f.name for f in fields(args)}
            for name in flags & set(saved["day_args"]):
                setattr(args, name, saved["day_args"][name])
            try:
                check_args(args)
            except (InputError, TypeError) as e:  # TypeError: a flag of the wrong type
                raise InputError(f"{args.sleep_from}/day.pt: its day flags are not valid: {e}") from None
            say(f"[day] sleeping on {args.sleep_from}'s day ({args.env_id}, seed {args.seed}, {saved['obs'].shape[0]} "
                "steps); its day flags replace these")  # fmt: skip
            if unknown := {k: v for k, v in saved["day_args"].items() if k not in flags}:  # a copy's: kept, said
                say(f"[day] the day's settings unknown to this script, kept in summary.json: {cut(unknown, 200)}")
        elif args.oracle_path:
            oracle_q = load_oracle(args.oracle_path, args.env_id)
        check_writable("runs")
    except InputError as e:
        say(f"error: {e}", sys.stderr)
        return 2
    # TensorBoard's writer thread on a full disk: no traceback from it; main hears its error at its next write
    threading.excepthook = lambda h: "tensorboard" in type(h.thread).__module__ or threading.__excepthook__(h)
    stop = StopSignals()
    summary = main(args, oracle_q, stop, saved)
    gc.freeze()  # the interpreter's last collections over torch's objects take seconds on a busy machine; skip them
    return stop.exit_code(summary.get("status", "interrupted"))


# ---------------------------------------------------------------------------------------------------------------------
# TRY NOT TO MODIFY: the armour. Logging, drawings and videos, checkpoints and saved days, input checks


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


class Progress:
    """One line per 5% of a phase: steps, SPS (the clock stops while the `evaluator` runs), ETA and a report."""

    def __init__(self, phase: str, total: int, evaluator):
        self.phase, self.total, self.every, self.evaluator = phase, total, max(total // 20, 1), evaluator
        self.start = time.time() - evaluator.seconds

    def sps(self, step: int) -> float:
        return step / max(time.time() - self.evaluator.seconds - self.start, 1e-9)

    def __call__(self, step: int, **report):
        if step % self.every == 0 or step == self.total:
            sps, shown = self.sps(step), "".join(f" | {k} {v:.4g}" if isinstance(v, float) else f" | {k} {v}"
                                                 for k, v in report.items() if v is not None)  # fmt: skip
            eta = (self.total - step) / max(sps, 1e-9)
            # print, not say: with a dead reader (`| head`) the run stops here, saving what finished (exit 141)
            print(f"[{self.phase}] {step}/{self.total} {100 * step // self.total}% | {sps:,.0f} SPS | "
                  f"ETA {int(eta // 60)}m{int(eta % 60):02d}s{shown}", flush=True)  # fmt: skip


def print_results(summary: dict, run_dir: str) -> None:
    toy = summary["args"]["env_id"] not in MAZE_IDS  # the maze: one episode from S; a toy-text env: the mean
    results = [f"{p}: {summary[f'eval/{p}_episode_length']:.{int(toy)}f} steps"
               + (f", success {summary[f'eval/{p}_success_rate']:.2f}" if toy else "")
               for p in POLICIES if f"eval/{p}_episode_length" in summary]  # fmt: skip
    if summary["status"] == "completed":
        say(" | ".join(results) + ("" if toy else " (optimum: 19)"))
    say(f"{summary['status']} in {summary['wall_time_s']:.1f}s; summary: {run_dir}/summary.json")


def reward_figure(table: np.ndarray, title: str) -> Figure:
    """The recovered reward over the maze, one panel per action (blocked cells and G, where nothing is done, blank)."""
    grid = np.full((gridworld_env.N_ACTIONS, gridworld_env.ROWS, gridworld_env.COLS), np.nan)
    for cell, (r, c) in enumerate(gridworld_env.CELLS):
        grid[:, r, c] = np.nan if cell == gridworld_env.GOAL else table[cell]
    lim = max(float(np.nanmax(np.abs(grid))), 1e-8)
    fig = Figure(figsize=(7, 6))
    for ax, action, image in zip(fig.subplots(2, 2).flat, gridworld_env.ACTION_NAMES, grid, strict=True):
        shown = ax.imshow(image, cmap="coolwarm", vmin=-lim, vmax=lim)
        ax.set(title=f"{action} from each cell", xticks=[], yticks=[])
    fig.suptitle(title)
    fig.colorbar(shown, ax=fig.axes, label="r(s, a, s')")
    return fig


VIDEO_START_CELLS = (7, 12, 17, 22)  # every third cell of the authors' start set (gridworld_env.START_SET)


def record_videos(run_dir: str, policies: dict[str, np.ndarray]) -> dict:
    """--capture-video: each greedy table policy from S on the plain and the wall maze, and from VIDEO_START_CELLS on
    the plain maze one after the other, as videos/{policy}_{plain,wall,starts}.gif: the maze's rgb_array frames,
    collected by Gymnasium's RenderCollection; videos/videos.json says how each episode ended."""
    from PIL import Image

    os.makedirs(f"{run_dir}/videos", exist_ok=True)
    record, t0, start = {}, time.time(), (gridworld_env.START,)
    clips = (("plain", "", start), ("wall", "Wall", start), ("starts", "", VIDEO_START_CELLS))
    for (name, policy), (clip, maze, starts) in itertools.product(policies.items(), clips):
        env = gym.wrappers.RenderCollection(gym.make(f"KnoxStoneMaze{maze}-v0", render_mode="rgb_array"))
        frames = []
        for start in starts:
            length, reached = evaluate(policy, env, start_cells(start), math.inf)  # G reached, in any time
            frames += env.render()  # the episode's frames, from the reset on
            record[f"{name}_{clip}_{start}"] = {"file": f"{name}_{clip}.gif", "variant": maze.lower() or "plain",
                                                "start_cell": start, "episode_length": int(length),
                                                "reached_goal": bool(reached), "frames": int(length) + 1}  # fmt: skip
        env.close()
        images = [Image.fromarray(frame) for frame in frames]
        with atomic(f"{run_dir}/videos/{name}_{clip}.gif") as tmp:
            images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:], loop=0, duration=250)
    write_json_atomic(f"{run_dir}/videos/videos.json", record)
    say(f"[video] {len(record)} greedy episodes drawn in {time.time() - t0:.1f}s: {run_dir}/videos/")
    return record


def read_checkpoint(path: str, flag: str) -> dict:
    """The checkpoint `flag` names, read with torch.load(weights_only=True): tensors and plain values only, never code.
    Every way it can fail is one InputError naming the flag and the file."""
    if not os.path.isfile(path):
        raise InputError(f"{flag} {path}: no such file")
    if not os.access(path, os.R_OK):  # zipfile.is_zipfile, below, would take it for a truncated archive
        raise InputError(f"{flag} {path}: cannot read it (Permission denied)")
    if not zipfile.is_zipfile(path):  # torch.save writes a zip archive; a truncated one has lost its directory
        raise InputError(f"{flag} {path}: not a torch checkpoint, or a truncated one (not a complete zip archive)")
    check_crc(path, f"{flag} {path}")
    try:
        ckpt = torch.load(path, weights_only=True, map_location="cpu")
    except Exception as e:  # code in the pickle (UnpicklingError), or a damaged archive (RuntimeError, EOFError, ...)
        lines = (str(e).strip() or type(e).__name__).splitlines()
        code = [line.strip() for line in lines if "unsupported" in line.lower()]
        what = "refused, it holds more than tensors and plain values (it could run code)" if code else "corrupt"
        raise InputError(f"{flag} {path}: {what}: {(code or lines)[0][:160]}") from None
    if not isinstance(ckpt, dict):
        raise InputError(f"{flag} {path}: not a checkpoint of this project (expected a dict, not "
                         f"{type(ckpt).__name__})")  # fmt: skip
    return ckpt


def load_oracle(path: str, env_id: str) -> np.ndarray:
    """The maze teacher's Q table from an oracle_train.py checkpoint, checked against the env, its shape and values."""
    ckpt = read_checkpoint(path, "--oracle-path")
    if "q_table" not in ckpt:
        raise InputError(f"{path}: not a maze oracle checkpoint (no 'q_table'); make one with oracle_train.py")
    if ckpt.get("env_id") != env_id:
        raise InputError(f"{path}: an oracle for {ckpt.get('env_id')!r}, not for --env-id {env_id}")
    q_table, shape = ckpt["q_table"], (gridworld_env.N_CELLS, gridworld_env.N_ACTIONS)
    if not isinstance(q_table, torch.Tensor) or tuple(q_table.shape) != shape:
        found = tuple(q_table.shape) if isinstance(q_table, torch.Tensor) else type(q_table).__name__
        raise InputError(f"{path}: q_table has shape {found}, expected {shape}")
    if not torch.isfinite(q_table).all():
        raise InputError(f"{path}: its q_table holds NaN or inf; train the oracle again (oracle_train.py)")
    return q_table.double().numpy()


def save_network(path: str, net: QNetwork, **extra) -> None:
    save_atomic({"state_dict": net.state_dict(), "kwargs": net.kwargs, **extra}, path)


# Saved days (--save-buffer, --sleep-from): one forward phase, many nights
DAY_FORMAT = "inform-day-1"
DAY_ARGS = tuple(Args().day_settings())  # the flags that shape a day (marked DAY): a saved day records them
DAY_TENSORS = ("obs", "actions", "next_obs", "feedback", "terminated", "success")  # the buffer, one row a transition
EPISODE_TABLE = ("episode_start", "episode_end", "episode_length", "episode_success", "episode_ended")


def save_day(path: str, day: Day, buffer: ReplayBuffer, q_star: np.ndarray, day_stats: dict):
    """The day as it ended: the buffer cut to its size, the episode table (buffer[start:end], one row an episode; the
    last row, ended False, is the episode cut off by the end of the phase), the oracle's Q table, the day's learner
    (its settings whole, H with its constructor arguments), the day's stats, and the random states that the sleep
    goes on from."""
    n, rows = buffer.size, [(start, end, True) for start, end in buffer.episodes]
    if (rows[-1][1] if rows else 0) < n:
        rows.append((rows[-1][1] if rows else 0, n, False))
    columns = list(zip(*rows, strict=True)) or [(), (), ()]  # no step at all: a person who answered q at once
    start, end, ended = (torch.tensor(column, dtype=torch.int64) for column in columns)
    np_state, (version, internal, gauss) = np.random.get_state(), random.getstate()
    save_atomic({
        "format": DAY_FORMAT, "script": os.path.basename(__file__), "env_id": day.settings["env_id"],
        "seed": day.settings["seed"], "day_args": day.settings,
        **{name: getattr(buffer, name)[:n].to("cpu", copy=True) for name in DAY_TENSORS},  # a copy: not the capacity
        "episode_start": start, "episode_end": end, "episode_length": end - start,
        "episode_success": buffer.success[:n].cpu()[start], "episode_ended": ended.bool(),
        "h_net": {"state_dict": day.h_net.state_dict(), "kwargs": day.h_net.kwargs}, "q_star": torch.tensor(q_star),
        "rng": {"torch": torch.get_rng_state(), "python": [version, list(internal), gauss],
                "torch_cuda": torch.cuda.get_rng_state() if buffer.obs.is_cuda else None,
                "numpy": [np_state[0], torch.from_numpy(np_state[1].astype(np.int64)), *np_state[2:]]},
        "day_stats": day_stats,
    }, path)  # fmt: skip


def set_rng_state(rng: dict) -> None:
    """The random streams as a saved day left them."""
    torch.set_rng_state(rng["torch"])
    if rng.get("torch_cuda") is not None and torch.cuda.is_available():
        torch.cuda.set_rng_state(rng["torch_cuda"])
    name, keys, pos, has_gauss, cached_gaussian = rng["numpy"]
    np.random.set_state((name, keys.numpy().astype(np.uint32), int(pos), int(has_gauss), float(cached_gaussian)))
    version, internal, gauss = rng["python"]
    random.setstate((version, tuple(internal), gauss))


def load_day(run_dir: str, args_type: type = Args) -> dict:
    """RUN_DIR/day.pt, checked (keys, shapes, index and value ranges, its settings and stats as JSON values, a flag of
    `args_type` of its type; its flags as this run's when they replace them). InputError before anything is written."""
    path = os.path.join(run_dir, "day.pt")
    if not os.path.isdir(run_dir):
        raise InputError(f"--sleep-from {run_dir}: no such directory")
    if not os.path.exists(path):
        raise InputError(f"--sleep-from {run_dir}: no day.pt in it (a run saves its day with --save-buffer)")
    day = read_checkpoint(path, "--sleep-from")
    if day.get("format") != DAY_FORMAT:
        raise InputError(f"{path}: not a saved day of this script (format {day.get('format')!r}, not {DAY_FORMAT!r})")
    for part, hints in (("day_args", typing.get_type_hints(args_type, include_extras=True)), ("day_stats", {})):
        check_settings(day.get(part, {}), hints, f"{path}: {part}")  # they go into summary.json
    missing = [k for k in ("env_id", "day_args", *DAY_TENSORS, *EPISODE_TABLE, "h_net", "q_star", "rng", "day_stats")
               if k not in day] + [f"day_args.{k}" for k in DAY_ARGS if k not in day.get("day_args", {})]  # fmt: skip
    if missing:
        raise InputError(f"{path}: an incomplete saved day, no {', '.join(missing)}")
    try:
        check_env(str(day["env_id"]))
    except InputError as e:
        raise InputError(f"{path}: a day on a task this script cannot run: {e}") from None
    env = make_env(day["env_id"])
    n_states, n_actions = env.observation_space.shape[0], int(env.action_space.n)
    env.close()
    n, rows = (len(day[k]) if isinstance(day[k], torch.Tensor) else -1 for k in ("obs", "episode_start"))
    shapes = {name: (n,) for name in DAY_TENSORS} | {name: (rows,) for name in EPISODE_TABLE}
    shapes |= {"obs": (n, n_states), "next_obs": (n, n_states), "q_star": (n_states, n_actions)}
    for name, shape in shapes.items():
        found = tuple(day[name].shape) if isinstance(day[name], torch.Tensor) else type(day[name]).__name__
        if found != shape:
            raise InputError(f"{path}: {name} has shape {found}, expected {shape}")
    start, end, one_hot = day["episode_start"], day["episode_end"], torch.eye(n_states)
    ranges = {  # what a forward phase can have written; anything else is a damaged or tampered day
        "episode_start, episode_end": (rows == n == 0) or (rows > 0 and start[0] == 0 and end[-1] == n
        and bool((start <= end).all()) and torch.equal(start[1:], end[:-1])
        and torch.equal(day["episode_length"], end - start)),
        "actions": bool(((day["actions"] >= 0) & (day["actions"] < n_actions)).all()),
        "feedback": bool(((day["feedback"] >= -1) & (day["feedback"] <= 1)).all()),  # h in [-1, 1]
        "terminated": bool(((day["terminated"] == 0) | (day["terminated"] == 1)).all()),
        "obs, next_obs": all(bool((one_hot[x.argmax(1)] == x).all()) for x in (day["obs"], day["next_obs"])),
        "q_star": bool(torch.isfinite(day["q_star"]).all()),
        "day_stats": isinstance(day["day_stats"], dict) and day["day_stats"].get("feedback/steps") == n,
    }  # fmt: skip
    if not all(ranges.values()):
        raise InputError(f"{path}: a damaged or tampered day: {', '.join(k for k, ok in ranges.items() if not ok)} "
                         f"out of range")  # fmt: skip
    try:  # the day's learner, rebuilt from what the day saved (another script's H is refused here, by name)
        check_settings(day["h_net"]["kwargs"], typing.get_type_hints(QNetwork.__init__), f"{path}: h_net kwargs")
        day["learner"] = Day(day["day_args"], torch.device("cpu"), saved=day["h_net"])
        if day["h_net"]["kwargs"]["obs_dim"] != n_states:
            raise ValueError(f"H is a network for {day['h_net']['kwargs']['obs_dim']}-d observations, not {n_states}-d")
        set_rng_state(day["rng"])  # tried here; main seeds, then restore_day sets them again
    except Exception as e:  # a damaged network or random state: KeyError, TypeError, ValueError, RuntimeError
        raise InputError(f"{path}: a damaged saved day, or one this script cannot rebuild (sleep on it with the script "
                         f"that made it): {(str(e) or type(e).__name__).splitlines()[0][:160]}") from None  # fmt: skip
    if not all(torch.isfinite(t).all() for t in day["learner"].h_net.state_dict().values()):
        raise InputError(f"{path}: the day's H holds NaN or inf")
    return day


def restore_day(saved: dict, device: torch.device) -> tuple[np.ndarray, ReplayBuffer, Day]:
    """The oracle's Q table, the buffer and the day's learner (load_day rebuilt it) of a saved day; then the random
    states as the day left them."""
    buffer = ReplayBuffer(saved["obs"].shape[0], saved["obs"].shape[1], device)
    for name in DAY_TENSORS:
        getattr(buffer, name).copy_(saved[name])
    buffer.size = saved["obs"].shape[0]
    rows = zip(*(saved[k].tolist() for k in ("episode_start", "episode_end", "episode_ended")), strict=True)
    buffer.episodes = [(start, end) for start, end, ended in rows if ended]
    saved["learner"].h_net.to(device)
    set_rng_state(saved["rng"])
    return saved["q_star"].double().numpy(), buffer, saved["learner"]


def check_args(args: Args) -> None:
    """Every flag against the range declared beside it, then what a range cannot say. Raises InputError."""
    if args.track and importlib.util.find_spec("wandb") is None:
        raise InputError("--track needs Weights & Biases: `pip install wandb`, or run without --track")
    args.fill_teacher_defaults()
    hints = typing.get_type_hints(type(args), include_extras=True)
    for f in fields(args):
        value, interval = getattr(args, f.name), next(iter(getattr(hints[f.name], "__metadata__", ())), None)
        if isinstance(interval, Range) and value is not None:
            (low, high), (left, right) = (float(x) for x in interval[1:-1].split(", ")), (interval[0], interval[-1])
            above, below = value >= low if left == "[" else value > low, value <= high if right == "]" else value < high
            if not (above and below):  # NaN is neither
                must = f"be in {interval}"
                if isinstance(value, int) and left == "[":  # a count or a seed: "must be >= 1"
                    must = f"be >= {low:g}" + (f" and below {high:.0f}" if high < math.inf else "")
                raise InputError(f"--{f.name.replace('_', '-')} must {must}, got {value}")
    check_run_name(args.env_id, args.exp_name, args.seed)
    check_env(args.env_id)
    maze_only = {f"--teacher {args.teacher}": args.teacher != "oracle", "--capture-video": args.capture_video,
                 "--oracle-path": args.oracle_path is not None}  # fmt: skip
    if args.env_id not in MAZE_IDS and any(maze_only.values()):
        used = ", ".join(flag for flag, on in maze_only.items() if on)
        raise InputError(f"{used}: the maze's only (exact Q* teaches on {args.env_id}); drop it")
    if args.teacher == "oracle" and args.tamer_learning_starts < args.tamer_batch_size:
        raise InputError(f"--tamer-learning-starts ({args.tamer_learning_starts}) must be at least "
                         f"--tamer-batch-size ({args.tamer_batch_size})")  # fmt: skip
    if args.tamer_learning_starts >= args.tamer_total_timesteps:
        raise InputError(f"--tamer-learning-starts ({args.tamer_learning_starts}) must be below "
                         f"--tamer-total-timesteps ({args.tamer_total_timesteps}), or H is never trained")  # fmt: skip
    if args.save_buffer and args.sleep_from:
        raise InputError("--save-buffer saves a run's own day; a --sleep-from run has none (it sleeps on another's)")
    distortions = {"teacher_noise": 0.0, "teacher_sparsity": 1.0, "teacher_delay": 0, "credit_window": 1}
    changed = [f"--{k.replace('_', '-')}" for k, v in distortions.items() if getattr(args, k) != v]
    if args.teacher != "oracle" and changed:
        raise InputError(f"--teacher {args.teacher} takes the answers as they are; drop {', '.join(changed)} "
                         "(they distort the simulated teacher only)")  # fmt: skip
    page_flags = [f for f, default in (("--participant", None), ("--host", "127.0.0.1"))
                  if getattr(args, f[2:]) != default]  # fmt: skip
    if args.teacher != "browser" and page_flags:
        raise InputError(f"{', '.join(page_flags)}: the web page's (--teacher browser); drop it, or add that")
    if args.teacher == "browser" and not args.sleep_from:
        if importlib.util.find_spec("browser_teacher") is None:
            raise InputError("--teacher browser needs browser_teacher.py (the web page) beside this script")
        import browser_teacher

        try:  # the page's address is free and ours to take, said before the run starts (nothing is written)
            browser_teacher.check_address(*browser_teacher.host_and_port(args.host))
        except ValueError as e:
            raise InputError(str(e)) from None
    if args.teacher == "human" and not args.sleep_from and (sys.stdin is None or sys.stdin.closed):
        raise InputError("--teacher human reads your answers from standard input, which is closed; "
                         "run it in a terminal, or pipe the answers in")  # fmt: skip


def open_page(run_dir: str, address: str, participant: str | None):
    """--teacher browser: the web page the person teaches at, served at --host `address` (browser_teacher.py,
    imported only here)."""
    import browser_teacher

    host, port = browser_teacher.host_and_port(address)
    return browser_teacher.BrowserTeacher(run_dir, "maze", host, port, participant=participant)


def check_writable(directory: str) -> None:
    """A read-only or full disk is said before the run starts (64 kB written, then removed): nothing is left."""
    made = not os.path.isdir(directory)
    try:
        os.makedirs(directory, exist_ok=True)
        with tempfile.TemporaryFile(dir=directory) as f:
            f.write(bytes(65536))
            f.flush()
            os.fsync(f.fileno())
    except OSError as e:
        raise InputError(f"cannot write into {os.path.abspath(directory)}: {e.strerror or e}") from None
    finally:
        if made:  # main makes it again
            with contextlib.suppress(OSError):
                os.rmdir(directory)


def check_env(env_id: str) -> None:
    """--env-id: a maze, or a Gymnasium env with discrete states and actions and a model (env.unwrapped.P)."""
    if env_id in MAZE_IDS:
        return
    try:
        env = gym.make(env_id)
    except Exception as e:  # unknown id, a missing extra, ...
        first = (str(e).strip() or type(e).__name__).splitlines()[0][:160]
        raise InputError(f"--env-id {env_id}: Gymnasium cannot make it ({first}); mazes: "
                         f"{', '.join(MAZE_IDS)}") from None  # fmt: skip
    spaces = (env.observation_space, env.action_space)
    ok = all(isinstance(s, gym.spaces.Discrete) for s in spaces) and isinstance(getattr(env.unwrapped, "P", None), dict)
    env.close()
    if not ok:
        raise InputError(f"--env-id {env_id}: this script needs discrete states and actions and the env's model "
                         "(env.unwrapped.P, as FrozenLake-v1, CliffWalking-v1 and Taxi-v4 have); continuous tasks "
                         "run in inform_sac_pusher.py")  # fmt: skip


# --- shared plumbing: the same in inform_dqn_gridworld.py ---
class InputError(Exception):
    """Bad input (a flag, a file): one `error:` line and exit 2, before anything is written."""


class Diverged(Exception):
    """A loss became NaN or inf; the message names the phase and the flag that helps."""


class StopSignals:
    """SIGINT (unless ignored: nohup, `&`), SIGTERM and SIGHUP stop the run. The handler only records the signal;
    `StopSignals.check()`, at the head of every loop, raises KeyboardInterrupt in our own code (never inside a library
    call) and main saves what finished. Only a wait for a person (`waiting()`) is interrupted at once. Signals after
    the first, and any after the summary, are only noted."""

    current = None  # the run's StopSignals, which check() and waiting() read

    def __init__(self):
        self.received, self.raised, self.finished = [], False, False
        self.waiting_for_input = self.broken_pipe = False
        for sig in STOP_SIGNALS:
            if signal.getsignal(sig) is not signal.SIG_IGN:
                signal.signal(sig, self.handler)
        StopSignals.current = self

    def handler(self, signum, frame):
        self.received.append(signal.Signals(signum).name)
        if self.waiting_for_input:
            StopSignals.check()

    @classmethod
    def check(cls) -> None:  # KeyboardInterrupt if a stop signal came (once: main then saves what finished)
        stop = cls.current
        if stop is not None and stop.received and not (stop.raised or stop.finished):
            stop.raised = True
            raise KeyboardInterrupt

    @classmethod
    @contextlib.contextmanager
    def waiting(cls):  # a wait for a person: a stop signal before it or during it raises at once
        stop = cls.current or cls.__new__(cls)  # none installed (the script imported, not run): a plain wait
        stop.waiting_for_input = True
        try:
            cls.check()
            yield
        finally:
            stop.waiting_for_input = False

    def reason(self) -> str:  # the first signal; else SIGPIPE if the reader of our output died, else Ctrl-C
        return self.received[0] if self.received else "SIGPIPE" if self.broken_pipe else "SIGINT"

    def exit_code(self, status: str) -> int:  # 128 + the signal, as a shell reports a kill (even after the summary)
        if status == "interrupted" or self.received:
            return 128 + signal.Signals[self.reason()].value
        return 0 if status == "completed" else 1


def say(text: str, file=None) -> None:  # print; a dead reader (a broken pipe) is no error: the rest goes to /dev/null
    file = file or sys.stdout
    try:
        print(text, file=file, flush=True)
    except OSError:  # BrokenPipeError, or a closed terminal
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), file.fileno())  # the exit's final flush then succeeds too


def check_run_name(env_id: str, exp_name: str, seed: int) -> None:  # one plain, short directory name inside runs/
    name = f"{env_id}__{exp_name}__{seed}__{int(time.time())}_99.tmp"  # the longest a run's files get
    plain = exp_name.isprintable() and not any(c in name for c in "/\\")  # no newline, no separator, no NUL
    if not exp_name or exp_name in (".", "..") or not plain or len(name.encode()) > 255:
        raise InputError(f"--exp-name {exp_name[:60]!r}{'...' * (len(exp_name) > 60)}: not one folder name in runs/")


def make_run_dir(run_name: str) -> str:  # runs/{run_name}, never an existing directory: a clash gets a suffix
    for n in range(100):
        path = f"runs/{run_name}" + (f"_{n}" if n else "")
        with contextlib.suppress(FileExistsError):
            os.makedirs(path)
            return path
    raise FileExistsError(f"runs/{run_name}: 100 runs of this name in the same second")


@contextlib.contextmanager
def atomic(path: str):
    """A temporary name for `path`, renamed once written; a failed write leaves no partial file (the summary may need
    its space)."""
    tmp = path + ".tmp"
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.remove(tmp)


def save_atomic(obj: dict, path: str) -> None:
    with atomic(path) as tmp, open(tmp, "wb") as f:  # our own file object: closed for sure, its space freed
        try:
            torch.save(obj, f)
        except RuntimeError as e:  # torch reports a failed write (a full disk) so: an OSError, as open() would
            raise OSError(f"{path}: {' '.join(str(e).split())[-120:]}") from None


def write_json_atomic(path: str, data: dict) -> None:
    with atomic(path) as tmp, open(tmp, "w") as f:
        json.dump(strict_json(data), f, indent=2, allow_nan=False)


def end_run(summary, status, phase, run_dir, run_start, evaluator, closing, stop, seed: int, flags: dict) -> dict:
    """The summary (with the run's `flags`; a run that did not complete keeps its mid-run checks under their own
    name) first, then the messages: no signal cuts this short (StopSignals only notes the later ones)."""
    stop.finished = True
    if run_dir is not None:
        final = {"time/eval_s": evaluator.seconds if evaluator else 0.0, "wall_time_s": time.time() - run_start}
        final.update(seed=seed, script=os.path.basename(__file__), status=status, args=flags)
        tests = evaluator.final if evaluator else {}
        tests = tests if status == "completed" else {f"eval/last_check/{k[5:]}": v for k, v in tests.items()}
        summary = {**tests, **summary, **final}
        summary.update({"phase": phase} if status != "completed" else {})
        summary.update({"signal": stop.reason()} if status == "interrupted" else {})
        try:
            write_json_atomic(f"{run_dir}/summary.json", summary)
        except OSError as e:  # a run without its record must not look completed to a caller: exit 1
            say(f"error: {run_dir}/summary.json not written ({e.strerror or e}); this run has no record", sys.stderr)
            status = summary["status"] = "unrecorded"
    for thing in (thing for thing in (*closing, evaluator) if thing is not None):
        with contextlib.suppress(OSError):  # TensorBoard on a full disk: a completed run's main flushed it first
            thing.close()
    if status == "interrupted":
        saved = f"what finished is saved in {run_dir}" if run_dir else "no run was made"
        say(f"interrupted ({stop.reason()}) during the {phase} phase; {saved}", sys.stderr)
    elif status in ("diverged", "failed"):
        say(f"error: {summary.get('error')}", sys.stderr)
    if run_dir is not None and status != "unrecorded":
        print_results(summary, run_dir)
    summary.setdefault("status", status)
    if status == "interrupted" and getattr(sys.modules.get("wandb"), "run", None) is not None:
        sys.stdout.flush(), sys.stderr.flush()  # --track: wandb's exit would wait ~10 s for its upload; a stop must not
        os._exit(stop.exit_code(status))
    return summary


# --- end of shared plumbing ---


def check_settings(values, hints: dict, where: str) -> None:
    """What a saved day brings into summary.json, checked as it is read: a dict of JSON values, a known flag's (in
    `hints`, Args' type hints) of its type too (typeguard's check); InputError naming the first that is not."""
    if not isinstance(values, dict):
        raise InputError(f"{where} is {cut(values)}, not a dict")
    for name, value in values.items():
        try:  # TypeError: a tensor, bytes, a key that is no string; ValueError: a loop
            json.dumps({name: value})
            typeguard.check_type(value, hints.get(name, typing.Any))
        except (TypeError, ValueError, RecursionError):
            raise InputError(f"{where}[{cut(name)}] is {cut(value)}, not a JSON value") from None
        except typeguard.TypeCheckError as e:  # in its words, on one line
            why = " ".join(str(e).split())[:160]
            raise InputError(f"{where}[{cut(name)}] is {cut(value)}, not of its flag's type: {why}") from None


def cut(value, n: int = 80) -> str:  # a value in a message: one line, a long one cut short
    text = " ".join(repr(value).split())
    return text if len(text) <= n else f"{text[:n]}... ({len(text):,} characters)"


def strict_json(value):  # NaN and inf as null, at any depth (a metric this run does not have, e.g. no successes)
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: strict_json(v) for k, v in value.items()}
    return [strict_json(v) for v in value] if isinstance(value, list | tuple) else value


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


if __name__ == "__main__":
    sys.exit(cli(tyro.cli(Args)))
