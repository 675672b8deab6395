"""INFORM on the Knox & Stone maze: TAMER from a simulated teacher's yes/no feedback ("day"), then offline
IQ-Learn on the remembered transitions ("sleep"), giving a far-sighted policy and a recovered reward.

Reproduces the gridworld experiment of Tarakli & Di Nuovo, "Learning while Sleeping" (ICDL 2024), Algorithm 1,
Fig. 3 (episode length of TAMER, INFORM and the expert). What the paper leaves open: docs/protocol.md.

    python inform_dqn_gridworld.py --seed 1
    python inform_dqn_gridworld.py --teacher-noise 0.2 --teacher-delay 1 --credit-window 2   # a human-like teacher
    python inform_dqn_gridworld.py --teacher human --tamer-learning-starts 32   # teach it yourself (docs/teachers.md)
"""

import collections
import contextlib
import gc
import json
import math
import os
import pickle
import random
import signal
import sys
import time
import zipfile
from dataclasses import asdict, dataclass
from typing import Literal


def stopped_while_starting(signum, frame):
    """A stop before the run directory exists (torch & co. take seconds to load): one line, nothing to save."""
    with contextlib.suppress(OSError):
        os.write(2, f"interrupted ({signal.Signals(signum).name}) while starting; no run was made\n".encode())
    os._exit(128 + signum)


if __name__ == "__main__":  # before the slow imports, so that no stop ever ends in a traceback
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        if signal.getsignal(sig) is not signal.SIG_IGN:  # an ignored SIGINT (nohup, `&`) stays ignored
            signal.signal(sig, stopped_while_starting)

import gymnasium as gym  # noqa: E402
import matplotlib  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
import torch.nn as nn  # noqa: E402
import torch.nn.functional as F  # noqa: E402
import tyro  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Polygon, Rectangle  # noqa: E402
from torch.utils.tensorboard import SummaryWriter  # noqa: E402

try:
    import gridworld_env
except ModuleNotFoundError as e:  # a copy of this script without the maze beside it: said after parsing, see below
    if e.name != "gridworld_env":
        raise
    gridworld_env = None

MAZE_IDS = tuple(gridworld_env.ENV_IDS) if gridworld_env else ("KnoxStoneMaze-v0",)
POLICIES = ("oracle", "tamer", "inform")
if gridworld_env:
    ALL_STARTS = tuple(cell for cell in range(gridworld_env.N_CELLS) if cell != gridworld_env.GOAL)  # the 29 others
    OPTIMUM = gridworld_env.greedy_episode_length(gridworld_env.optimal_q("plain").argmax(1))  # 19 steps from S


@dataclass
class Args:
    exp_name: str = os.path.basename(__file__)[: -len(".py")]
    """the name of this experiment"""
    seed: int = 1
    """seed of the experiment"""
    torch_deterministic: bool = True
    """if toggled, `torch.backends.cudnn.deterministic=True` and deterministic algorithms"""
    cuda: bool = False
    """if toggled, use CUDA when available (these tiny networks are faster on the CPU)"""
    num_threads: int = 1
    """torch CPU threads (one is fastest for networks this small)"""
    capture_video: bool = False
    """draw TAMER's and INFORM's final greedy episodes (plain maze, wall maze, a few start cells) as GIFs into
    runs/{run}/videos/"""
    save_model: bool = True
    """whether to save the H and Q networks and the recovered reward table into the run directory"""
    env_id: str = "KnoxStoneMaze-v0"
    """the maze to train on (one of the ids gridworld_env registers)"""

    # Oracle (the simulated teacher)
    oracle_gamma: float = 0.99
    """discount of the oracle's exact Q* (value iteration)"""
    oracle_path: str | None = None
    """a maze teacher saved by oracle_train.py (e.g. a half-trained Q-learner) instead of exact Q*"""

    # Forward phase: TAMER (Eq. 1) with simulated feedback (Eq. 4)
    tamer_total_timesteps: int = 10000
    """environment steps of the forward phase"""
    tamer_learning_rate: float = 1e-3
    """Adam learning rate of the feedback model H"""
    tamer_batch_size: int = 32
    """batch size of the H regression"""
    tamer_learning_starts: int | None = None
    """environment steps before H is trained (None: 1000; with --teacher human 1, H learns from your first answer)"""
    tamer_train_frequency: int = 1
    """environment steps between H updates"""
    start_e: float | None = None
    """starting epsilon of the epsilon-greedy exploration (None: 1; with --teacher human 0, no random moves)"""
    end_e: float | None = None
    """final epsilon (None: 0.05; with --teacher human 0)"""
    exploration_fraction: float = 0.2
    """fraction of the forward phase over which epsilon decays from start_e to end_e"""
    feedback_alpha_start: float = 0.999
    """alpha of Eq. 4 at the start of the forward phase (1 = only the oracle's best action earns +1)"""
    feedback_alpha_end: float = 0.999
    """alpha of Eq. 4 at the end of the forward phase (alpha rises linearly: the teacher gets stricter)"""
    success_max_steps: int = 30
    """an episode is tagged success if it reaches the goal in fewer than this many steps"""

    # The teacher as a person (docs/protocol.md); the defaults are the paper's perfect, instant, tireless teacher
    teacher: Literal["oracle", "human"] = "oracle"
    """who answers: "oracle" (Eq. 4, distorted by the flags below) or "human" (you, in the terminal: y, Enter, q)"""
    teacher_noise: float = 0.0
    """probability that the teacher's judgement is flipped (+1 <-> no feedback)"""
    teacher_sparsity: float = 1.0
    """probability that a +1 judgement is actually given (otherwise no feedback)"""
    teacher_delay: int = 0
    """env steps between a transition and the arrival of its signal (which labels the later transition)"""
    credit_window: int = 1
    """each arriving signal labels this many most recent transitions (teacher_delay + 1 covers the right one)"""
    feedback_budget: int | None = None
    """the teacher leaves after this many +1 signals (None: never); then H and the TAMER policy are frozen"""
    budget_ends_forward_phase: bool = False
    """when the budget is spent, end the forward phase and sleep (otherwise keep acting, without feedback)"""
    human_updates_per_answer: int = 20
    """--teacher human: H's gradient steps after each answer, each on the newest answer plus a replay of earlier ones
    (Deep TAMER's remedies), so that an answer takes effect before the next move"""

    # Sleep phase: offline IQ-Learn (Eq. 2), no environment steps
    sleep_gradient_steps: int = 3000
    """gradient steps of the sleep phase"""
    sleep_batch_size: int = 32
    """transitions drawn from the success set, and as many from the whole buffer, per step"""
    sleep_learning_rate: float = 1e-3
    """Adam learning rate of the soft Q network"""
    sleep_gamma: float = 0.99
    """discount of the sleep phase (non-myopic, unlike TAMER's 0)"""
    sleep_temperature: float = 0.1
    """temperature of the soft value V(s) = temp * logsumexp(Q(s, .) / temp)"""
    sleep_chi2_coef: float = 0.5
    """weight of the chi-squared regulariser, 1 / (4 * 0.5) as IQ-Learn; 0 turns it off"""
    sleep_tau: float = 1.0
    """soft-update rate of the target Q network per step (1 copies it every step, as the authors did)"""

    # Evaluation
    eval_frequency: int = 500
    """forward-phase environment steps between greedy evaluations"""
    sleep_eval_frequency: int = 500
    """sleep-phase gradient steps between greedy evaluations"""
    evaluate: str | None = None
    """re-evaluate a saved tamer_h.pt or inform_q.pt, print its episode lengths as JSON, train nothing"""


# The defaults that depend on who teaches: the paper's simulated teacher, or a person who answers every move
TEACHER_DEFAULTS = {
    "oracle": {"tamer_learning_starts": 1000, "start_e": 1.0, "end_e": 0.05},
    "human": {"tamer_learning_starts": 1, "start_e": 0.0, "end_e": 0.0},
}


def fill_teacher_defaults(args: Args) -> Args:
    """The flags left at None take the default of --teacher (the simulated teacher's are the paper's)."""
    for name, value in TEACHER_DEFAULTS[args.teacher].items():
        if getattr(args, name) is None:
            setattr(args, name, value)
    return args


class InputError(Exception):
    """Bad input from the user: a flag value, a file. Reported as one line, before anything is written."""


class Diverged(Exception):
    """The sleep loss became NaN or inf."""


def check_args(args: Args) -> None:
    """Reject bad flag values before anything is written; each message says what is wrong and how to fix it."""
    fill_teacher_defaults(args)
    if args.seed < 0:
        raise InputError(f"--seed must be >= 0 (numpy refuses negative seeds), got {args.seed}")
    positive_ints = [
        "num_threads",
        "tamer_total_timesteps",
        "tamer_batch_size",
        "tamer_train_frequency",
        "success_max_steps",
        "sleep_gradient_steps",
        "sleep_batch_size",
        "eval_frequency",
        "sleep_eval_frequency",
        "human_updates_per_answer",
    ]
    for name in positive_ints:
        if getattr(args, name) < 1:
            raise InputError(f"--{name.replace('_', '-')} must be a positive integer, got {getattr(args, name)}")
    unit_interval = ["feedback_alpha_start", "feedback_alpha_end", "start_e", "end_e", "sleep_gamma", "oracle_gamma"]
    for name in unit_interval:
        if not 0.0 <= getattr(args, name) <= 1.0:
            raise InputError(f"--{name.replace('_', '-')} must be in [0, 1], got {getattr(args, name)}")
    positive_floats = ["tamer_learning_rate", "sleep_learning_rate", "sleep_temperature", "exploration_fraction"]
    for name in positive_floats:
        if not 0.0 < getattr(args, name) < math.inf:
            raise InputError(f"--{name.replace('_', '-')} must be a finite number > 0, got {getattr(args, name)}")
    if not 0.0 < args.sleep_tau <= 1.0:
        raise InputError(f"--sleep-tau must be in (0, 1], got {args.sleep_tau}")
    if not 0.0 <= args.sleep_chi2_coef < math.inf:
        raise InputError(f"--sleep-chi2-coef must be a finite number >= 0 (0 turns it off), got {args.sleep_chi2_coef}")
    if args.oracle_gamma >= 1.0:
        raise InputError("--oracle-gamma must be below 1 for value iteration to converge")
    if args.tamer_learning_starts < 1:
        raise InputError(f"--tamer-learning-starts must be a positive integer, got {args.tamer_learning_starts}")
    if args.teacher == "oracle" and args.tamer_learning_starts < args.tamer_batch_size:
        raise InputError(
            f"--tamer-learning-starts ({args.tamer_learning_starts}) must be at least "
            f"--tamer-batch-size ({args.tamer_batch_size})"
        )
    if args.tamer_learning_starts >= args.tamer_total_timesteps:
        raise InputError(
            f"--tamer-total-timesteps ({args.tamer_total_timesteps}) must exceed "
            f"--tamer-learning-starts ({args.tamer_learning_starts}), or H is never trained"
        )
    if args.env_id not in MAZE_IDS:
        raise InputError(f"unknown --env-id {args.env_id!r}; this script trains on one of {', '.join(MAZE_IDS)}")
    for name in ("teacher_noise", "teacher_sparsity"):
        if not 0.0 <= getattr(args, name) <= 1.0:
            raise InputError(f"--{name.replace('_', '-')} is a probability, in [0, 1]; got {getattr(args, name)}")
    if args.teacher_delay < 0:
        raise InputError(f"--teacher-delay must be >= 0 env steps, got {args.teacher_delay}")
    if args.credit_window < 1:
        raise InputError(f"--credit-window must be >= 1 (1 labels only the transition a signal arrives on), "
                         f"got {args.credit_window}")  # fmt: skip
    if args.feedback_budget is not None and args.feedback_budget < 1:
        raise InputError(f"--feedback-budget must be >= 1 positive signal (or None: unlimited), "
                         f"got {args.feedback_budget}")  # fmt: skip
    distortions = {"teacher_noise": 0.0, "teacher_sparsity": 1.0, "teacher_delay": 0, "credit_window": 1}
    changed = [f"--{k.replace('_', '-')}" for k, v in distortions.items() if getattr(args, k) != v]
    if args.teacher == "human" and changed:
        raise InputError(f"--teacher human takes your answers as they are; drop {', '.join(changed)} "
                         f"(they distort the simulated teacher only)")  # fmt: skip


class QNetwork(nn.Module):
    """The 30-32-32-4 MLP of the authors, used both for TAMER's H(s, a) and for the sleep phase's soft Q(s, a)."""

    def __init__(self, obs_dim: int, n_actions: int, hidden: int = 32):
        super().__init__()
        self.network = nn.Sequential(
            nn.Linear(obs_dim, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, n_actions)
        )

    def forward(self, x):
        return self.network(x)


class ReplayBuffer:
    """Keeps every forward-phase transition (s, a, s', h, terminated) and the success tag of its episode."""

    def __init__(self, capacity: int, obs_dim: int, device: torch.device):
        self.obs = torch.zeros((capacity, obs_dim), device=device)
        self.next_obs = torch.zeros((capacity, obs_dim), device=device)
        self.actions = torch.zeros(capacity, dtype=torch.long, device=device)
        self.feedback = torch.zeros(capacity, device=device)
        self.terminated = torch.zeros(capacity, device=device)
        self.success = torch.zeros(capacity, dtype=torch.bool, device=device)
        self.size = 0

    def add(self, obs, action, next_obs, feedback, terminated):
        i = self.size
        self.obs[i] = torch.as_tensor(obs)
        self.next_obs[i] = torch.as_tensor(next_obs)
        self.actions[i], self.feedback[i], self.terminated[i] = action, feedback, float(terminated)
        self.size += 1

    def tag_episode(self, start: int, success: bool):
        """Tag the trajectory buffer[start:size], which just ended, as a success or a failure."""
        self.success[start : self.size] = success

    def batch(self, idx):
        return self.obs[idx], self.actions[idx], self.next_obs[idx], self.feedback[idx], self.terminated[idx]


def linear_schedule(start: float, end: float, duration: int, t: int) -> float:
    return start + (end - start) * min(t / duration, 1.0)


def oracle_feedback(q_star_sa, q_star_best, alpha):  # Eq. 4, sign-safe
    """h = 1 if Q*(s, a) >= Q*(s, a*) - (1 - alpha) |Q*(s, a*)|, else 0 (no feedback)."""
    return (q_star_sa >= q_star_best - (1.0 - alpha) * abs(q_star_best)) * 1.0


# ALGO LOGIC: the teacher (docs/protocol.md). Eq. 4 says what a perfect teacher would answer; a person distorts it.
# Copy this class verbatim into both INFORM scripts (CleanRL style: repeated across files, never within one).
class Teacher:
    """A simulated person between Eq. 4 and the learner: noisy, sparse, late and limited (paper Sec. VII's future work).

    Each call hands over the perfect teacher's answer h* (0 or 1) about the transition at buffer index `step` and
    returns the buffer indices that receive h = 1 now. In order: the judgement is flipped with probability
    `noise`; a +1 is then clicked only with probability `sparsity`; a click about step t arrives at step t + `delay`
    and labels that later transition and the `credit_window` - 1 before it (Deep TAMER's remedy; a window of
    delay + 1 covers the step it was about). The teacher leaves after `budget` delivered +1 signals (None: never).
    Its randomness is its own generator, so the defaults (0, 1, 0, 1, None) reproduce the perfect teacher exactly
    and leave every other random stream untouched. Signals still on their way when the phase ends are lost.
    """

    def __init__(self, noise=0.0, sparsity=1.0, delay=0, credit_window=1, budget=None, seed=0):
        self.noise, self.sparsity, self.delay, self.credit_window, self.budget = (
            noise, sparsity, delay, credit_window, budget,
        )  # fmt: skip
        self.rng = np.random.default_rng(seed)
        self.in_flight = collections.deque()  # clicks on their way, oldest first
        self.positives = 0  # +1 signals delivered
        self.perfect_positives = 0  # +1 answers of the perfect teacher (Eq. 4), for the record

    @property
    def gone(self) -> bool:
        """The budget is spent: no more feedback from now on."""
        return self.budget is not None and self.positives >= self.budget

    def __call__(self, step: int, h_star: float) -> list[int]:
        self.perfect_positives += int(h_star > 0)
        flip, click = self.rng.random(2)  # always two draws: the stream does not depend on the answers
        h = 1.0 - h_star if flip < self.noise else h_star
        h = h if click < self.sparsity else 0.0
        self.in_flight.append(h)
        if len(self.in_flight) <= self.delay:
            return []
        h = self.in_flight.popleft()
        if h <= 0 or self.gone:
            return []
        self.positives += 1
        return list(range(max(0, step - self.credit_window + 1), step + 1))


def tamer_loss(h_net, obs, actions, feedback):  # Eq. 1: E[(H(s, a) - h)^2], gamma = 0, no bootstrapping
    return F.mse_loss(h_net(obs).gather(1, actions[:, None]).squeeze(1), feedback)


def soft_value(q, temperature: float):  # V(s) = temp * logsumexp(Q(s, .) / temp)
    return temperature * torch.logsumexp(q / temperature, dim=1)


def iq_loss(q_net, target_net, obs, actions, next_obs, terminated, is_expert, gamma, temperature, chi2_coef):  # Eq. 2
    """IQ-Learn's loss to minimise; `is_expert` marks the success-set rows of the batch, all rows are "all"."""
    q = q_net(obs)
    q_sa = q.gather(1, actions[:, None]).squeeze(1)
    with torch.no_grad():
        y = (1.0 - terminated) * gamma * soft_value(target_net(next_obs), temperature)  # V_target(s'), not of s
    td = q_sa - y
    expert_term = -td[is_expert].mean()
    value_term = (soft_value(q, temperature) - y).mean()
    chi2_term = chi2_coef * td.pow(2).mean()
    return expert_term + value_term + chi2_term, (expert_term, value_term, chi2_term)


def recover_reward(q_sa, v_next, terminated, gamma):  # Eq. 3: r(s, a, s') = Q(s, a) - (1 - terminated) gamma V(s')
    return q_sa - (1.0 - terminated) * gamma * v_next


def reward_table(q_net, next_cell, gamma, temperature, device):
    """Eq. 3 for every (s, a) of the maze, with s' the deterministic move: a (30, 4) table."""
    with torch.no_grad():
        q = q_net(torch.eye(gridworld_env.N_CELLS, device=device)).cpu()
    next_cell = torch.as_tensor(next_cell)
    terminated = (next_cell == gridworld_env.GOAL).float()
    return recover_reward(q, soft_value(q, temperature)[next_cell], terminated, gamma)


def greedy_actions(q_net, device) -> np.ndarray:
    """The greedy policy as a table: one forward pass over every cell's one-hot observation."""
    with torch.no_grad():
        return q_net(torch.eye(gridworld_env.N_CELLS, device=device)).argmax(1).cpu().numpy()


def is_success(terminated: bool, length: int, max_steps: int) -> bool:
    """The success tag: the goal was reached in fewer than `max_steps` steps."""
    return bool(terminated) and length < max_steps


def evaluate(env: gym.Env, policy: np.ndarray, start_cells, success_max_steps: int):
    """Run the greedy table policy once from each start cell; mean episode length and success rate."""
    lengths, successes = [], []
    for cell in start_cells:
        obs, _ = env.reset(options={"start_cell": cell})
        terminated = truncated = False
        length = 0
        while not (terminated or truncated):
            obs, _, terminated, truncated, _ = env.step(policy[int(obs.argmax())])
            length += 1
        lengths.append(length)
        successes.append(is_success(terminated, length, success_max_steps))
    return float(np.mean(lengths)), float(np.mean(successes))


class Evaluator:
    """Greedy evaluation on the plain maze, the wall maze, the start set and all 29 starts; logs eval/ tags."""

    def __init__(self, writer: SummaryWriter | None, success_max_steps: int):
        self.writer = writer
        self.success_max_steps = success_max_steps
        self.envs = {
            name: gym.make(env_id)
            for name, env_id in [
                ("plain", "KnoxStoneMaze-v0"),
                ("wall", "KnoxStoneMazeWall-v0"),
                ("start_set", "KnoxStoneMazeStartSet-v0"),
            ]
        }
        self.seconds = 0.0
        self.final = {}

    def __call__(self, name: str, policy: np.ndarray, step: int) -> dict:
        t0 = time.time()
        length, _ = evaluate(self.envs["plain"], policy, [gridworld_env.START], self.success_max_steps)
        wall_length, _ = evaluate(self.envs["wall"], policy, [gridworld_env.START], self.success_max_steps)
        set_length, set_success = evaluate(
            self.envs["start_set"], policy, gridworld_env.START_SET, self.success_max_steps
        )
        _, all_success = evaluate(self.envs["plain"], policy, ALL_STARTS, self.success_max_steps)
        metrics = {
            f"eval/{name}_episode_length": length,
            f"eval/wall/{name}_episode_length": wall_length,
            f"eval/start_set/{name}_episode_length": set_length,
            f"eval/start_set/{name}_success_rate": set_success,
            f"eval/all_starts/{name}_success_rate": all_success,
        }
        for tag, value in metrics.items():
            if self.writer is not None:
                self.writer.add_scalar(tag, value, step)
        self.final.update(metrics)
        self.seconds += time.time() - t0
        return metrics

    def close(self):
        for env in self.envs.values():
            env.close()


class HumanTeacher:
    """You as the teacher (docs/teachers.md). The maze is drawn with the agent and its move; you answer on standard
    input: y (+1), Enter (no feedback) or q (stop teaching: the sleep starts). The end of the input counts as q, so
    a pipe or a file of answers works as well as a keyboard."""

    def __init__(self, variant: str, success_max_steps: int):
        self.variant, self.next_cell = variant, gridworld_env.transition_table(variant)
        self.answers = self.agreement = 0  # answers given, and how many Eq. 4 (the oracle) would have given too
        self.refused = np.zeros((gridworld_env.N_CELLS, gridworld_env.N_ACTIONS))  # Enter answers per (cell, move)
        self.answers_to_goal = None  # answers given when the agent's own (greedy) way from S first reached G
        self.echo = not sys.stdin.isatty()  # piped answers are not echoed by a terminal: print them
        print("You are the teacher. The agent A must reach G by the shortest path (19 steps from S).\n"
              "For each move answer: y = good (+1), Enter = no feedback, q = stop teaching (the sleep starts).\n"
              "A move you answer with Enter is not proposed again in that cell while it has moves you have not "
              f"judged.\nThe sleep learns from the walks from S to G in fewer than {success_max_steps} steps: "
              "teach until there is at least one.", flush=True)  # fmt: skip

    def propose(self, h_values: torch.Tensor, cell: int) -> int:
        """The agent's move: greedy on H, but never a move you refused in this cell before the ones you have not."""
        return int(np.argmax(h_values.cpu().numpy() - 2.0 * self.refused[cell]))  # H is in about [0, 1]

    def __call__(self, cell: int, action: int, explore: bool, step: int, positives: int, h_oracle: float,
                 own_way: int, successes: int):  # fmt: skip
        """Your answer about the move `action` from `cell`: 1.0, 0.0, or None to stop teaching."""
        how = " (exploring: a random move)" if explore else ""
        how += " into a wall: it stays where it is" if self.next_cell[cell, action] == cell else ""
        way = f"reaches G in {own_way} steps" if own_way < 200 else "does not reach G yet"
        print(f"\nstep {step} | answers {self.answers} | positives given {positives} | its own way from S: {way} | "
              f"walks to G in time: {successes}\n"
              + gridworld_env.draw_maze(self.variant, agent=cell, arrows={cell: action})
              + f"the agent moves {gridworld_env.ACTION_NAMES[action]}{how}", flush=True)  # fmt: skip
        while True:
            print("good move? [y / Enter / q] ", end="", flush=True)
            line = sys.stdin.readline()
            answer = line.strip().lower() if line else "q"
            if self.echo:
                print(answer or "(Enter)", flush=True)
            if answer == "q":
                return None
            if answer in ("y", ""):
                h = float(answer == "y")
                self.answers += 1
                self.agreement += int(h == h_oracle)
                self.refused[cell, action] += 1.0 - h
                return h
            print(f"{answer!r}? type y for +1, press Enter for no feedback, or type q to stop teaching", flush=True)

    def finish(self, steps: int, positives: int, successes: int):
        then = "now the agent sleeps" if successes else "the agent did not walk from S to G in time, so it cannot sleep"
        print(f"\nthank you: {steps} steps taught, {positives} positives given ({self.agreement} of "
              f"{self.answers} answers as the oracle's, Eq. 4); {then}", flush=True)  # fmt: skip


def draw_greedy_path(policy: np.ndarray, variant: str) -> str:
    """A greedy table policy's path from S drawn on the maze, and where it ends."""
    next_cell = gridworld_env.transition_table(variant)
    cell, arrows = gridworld_env.START, {}
    while cell != gridworld_env.GOAL and cell not in arrows:  # a deterministic path either ends in G or loops
        arrows[cell] = int(policy[cell])
        cell = int(next_cell[cell, policy[cell]])
    ending = (f"reaches G in {len(arrows)} steps" if cell == gridworld_env.GOAL
              else "never reaches G: it goes round in a loop or bumps into a wall")  # fmt: skip
    return gridworld_env.draw_maze(variant, agent=gridworld_env.START, arrows=arrows) + ending


class Progress:
    """One line per ~5% of a phase: steps, SPS and ETA, plus whatever the phase reports."""

    def __init__(self, phase: str, total: int):
        self.phase, self.total, self.start = phase, total, time.time()
        self.every = max(total // 20, 1)

    def __call__(self, step: int, **info):
        if step % self.every and step != self.total:
            return
        elapsed = time.time() - self.start
        sps = step / max(elapsed, 1e-9)
        eta = (self.total - step) / max(sps, 1e-9)
        info = {k: v for k, v in info.items() if v is not None}  # a value not measured yet is not shown
        extra = "".join(f" | {k} {v:.4g}" if isinstance(v, float) else f" | {k} {v}" for k, v in info.items())
        print(
            f"[{self.phase}] {step}/{self.total} {100 * step // self.total:3d}% | {sps:,.0f} SPS | "
            f"ETA {eta:.0f}s{extra}",
            flush=True,
        )


def reward_figure(table: np.ndarray, title: str):
    """The recovered reward drawn over the maze: each free cell split into four triangles, one per action."""
    fig = Figure(figsize=(6, 6))
    ax = fig.subplots()
    visited = np.arange(gridworld_env.N_CELLS) != gridworld_env.GOAL  # the agent never acts in G (terminal)
    lim = max(float(np.abs(table[visited]).max()), 1e-8)
    cmap, norm = matplotlib.colormaps["coolwarm"], matplotlib.colors.Normalize(-lim, lim)
    # triangle corners for up, down, left, right, in (x, y) with y pointing down
    corners = {0: [(0, 0), (1, 0)], 1: [(0, 1), (1, 1)], 2: [(0, 0), (0, 1)], 3: [(1, 0), (1, 1)]}
    for cell, (r, c) in enumerate(gridworld_env.CELLS):
        if cell == gridworld_env.GOAL:
            ax.add_patch(Rectangle((c, r), 1, 1, facecolor="0.85"))
        else:
            for a, ((x1, y1), (x2, y2)) in corners.items():
                tri = [(c + 0.5, r + 0.5), (c + x1, r + y1), (c + x2, r + y2)]
                ax.add_patch(Polygon(tri, facecolor=cmap(norm(table[cell, a])), edgecolor="white", lw=0.5))
        label = "G" if cell == gridworld_env.GOAL else "S" if cell == gridworld_env.START else ""
        ax.text(c + 0.5, r + 0.5, label, ha="center", va="center", fontsize=12, weight="bold")
    for r, c in gridworld_env.BLOCKED:
        ax.add_patch(Rectangle((c, r), 1, 1, facecolor="0.25"))
    for wall in gridworld_env.PLAIN_WALLS:
        (r1, c1), (r2, c2) = sorted(wall)
        xs, ys = ([c2, c2], [r1, r1 + 1]) if r1 == r2 else ([c1, c1 + 1], [r2, r2])
        ax.plot(xs, ys, color="black", lw=3)
    ax.set(xlim=(0, gridworld_env.COLS), ylim=(gridworld_env.ROWS, 0), aspect="equal", xticks=[], yticks=[])
    ax.set_title(title)
    fig.colorbar(matplotlib.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.8, label="r(s, a, s')")
    return fig


def read_checkpoint(path: str) -> dict:
    """torch.load(path, weights_only=True), with every way it can fail turned into one InputError naming the file."""
    if not os.path.isfile(path):
        raise InputError(f"{path}: no such file")
    if not zipfile.is_zipfile(path):  # torch.save writes a zip archive; a truncated one has lost its directory
        raise InputError(f"{path}: not a torch checkpoint, or a truncated one (not a complete zip archive)")
    try:
        ckpt = torch.load(path, weights_only=True, map_location="cpu")
    except pickle.UnpicklingError as e:
        unsupported = [line.strip() for line in str(e).splitlines() if "unsupported" in line.lower()]
        raise InputError(f"{path}: refused, it holds more than tensors and plain values (it could run code): "
                         f"{(unsupported or [type(e).__name__])[0][:160]}") from None  # fmt: skip
    except Exception as e:  # a damaged archive: torch raises RuntimeError, EOFError, ...
        raise InputError(
            f"{path}: corrupt checkpoint: {(str(e).strip() or type(e).__name__).splitlines()[0][:160]}"
        ) from None
    if not isinstance(ckpt, dict):
        raise InputError(f"{path}: not a checkpoint of this project (expected a dict, found {type(ckpt).__name__})")
    return ckpt


def load_oracle(path: str, env_id: str) -> np.ndarray:
    """The maze teacher's Q table from an oracle_train.py checkpoint, checked against the env and its shapes."""
    ckpt = read_checkpoint(path)
    if "q_table" not in ckpt:
        raise InputError(f"{path}: not a maze oracle checkpoint (no 'q_table'); make one with oracle_train.py")
    if ckpt.get("env_id") != env_id:
        raise InputError(f"{path}: an oracle for {ckpt.get('env_id')!r}, not for --env-id {env_id}")
    q_table = ckpt["q_table"]
    if not isinstance(q_table, torch.Tensor) or tuple(q_table.shape) != (
        gridworld_env.N_CELLS,
        gridworld_env.N_ACTIONS,
    ):
        shape = tuple(q_table.shape) if isinstance(q_table, torch.Tensor) else type(q_table).__name__
        raise InputError(f"{path}: q_table has shape {shape}, expected ({gridworld_env.N_CELLS}, "
                         f"{gridworld_env.N_ACTIONS})")  # fmt: skip
    return q_table.double().numpy()


def load_q_network(path: str) -> QNetwork:
    """Rebuild a saved H or Q network (tamer_h.pt, inform_q.pt) from its state_dict and arguments."""
    ckpt = read_checkpoint(path)
    if "state_dict" not in ckpt or "kwargs" not in ckpt:
        raise InputError(f"{path}: not a saved network of this script (needs 'state_dict' and 'kwargs')")
    net = QNetwork(**ckpt["kwargs"])
    try:
        net.load_state_dict(ckpt["state_dict"])
    except RuntimeError as e:
        raise InputError(f"{path}: the weights do not fit the network: {str(e).splitlines()[0][:160]}") from None
    if ckpt["kwargs"].get("obs_dim") != gridworld_env.N_CELLS:
        raise InputError(f"{path}: a network for {ckpt['kwargs'].get('obs_dim')}-d observations, not the maze's 30")
    return net


def forward_phase(args, env, q_star, h_net, buffer, evaluator, writer, device) -> dict:
    """TAMER ("day"): act on H, get the teacher's feedback (Eq. 4 through Teacher, or a person), fit H by Eq. 1,
    remember and tag every transition."""
    h_optimizer = torch.optim.Adam(h_net.parameters(), lr=args.tamer_learning_rate, fused=True)
    progress = Progress("tamer", args.tamer_total_timesteps)
    teacher = Teacher(args.teacher_noise, args.teacher_sparsity, args.teacher_delay, args.credit_window,
                      args.feedback_budget, seed=args.seed + 7919)  # fmt: skip
    variant = env.unwrapped.variant
    human = HumanTeacher(variant, args.success_max_steps) if args.teacher == "human" else None
    episode_positives = episode_length = episode_start = steps_run = successes = 0
    own_way = gridworld_env.greedy_episode_length(greedy_actions(h_net, device), variant) if human else None
    optimum_at = None  # (step, +1 signals) at the first evaluation where TAMER's greedy path is the shortest
    evaluated_at = -1
    start_time = time.time()
    obs, _ = env.reset(seed=args.seed)
    for global_step in range(1, args.tamer_total_timesteps + 1):
        epsilon = linear_schedule(args.start_e, args.end_e, int(args.exploration_fraction * args.tamer_total_timesteps),
                                  global_step - 1)  # fmt: skip
        explore = random.random() < epsilon
        if explore:
            action = env.action_space.sample()
        else:
            with torch.no_grad():
                h_values = h_net(torch.as_tensor(obs, device=device))
            action = int(h_values.argmax()) if human is None else human.propose(h_values, int(obs.argmax()))

        # the teacher watches (s, a): the perfect answer (Eq. 4) or a person's; once it has left, H stays frozen
        taught = not teacher.gone
        alpha = linear_schedule(args.feedback_alpha_start, args.feedback_alpha_end, args.tamer_total_timesteps,
                                global_step - 1)  # fmt: skip
        q_star_s = q_star[int(obs.argmax())]
        h_star = oracle_feedback(q_star_s[action], q_star_s.max(), alpha)
        if human is not None and taught:
            h_star = human(int(obs.argmax()), action, explore, global_step, teacher.positives, h_star, own_way,
                           successes)  # fmt: skip
            if h_star is None:  # q or the end of the input: stop teaching, the sleep starts
                break
        next_obs, _, terminated, truncated, _ = env.step(action)
        buffer.add(obs, action, next_obs, 0.0, terminated)
        if taught:
            labelled = teacher(buffer.size - 1, h_star)
            buffer.feedback[labelled] = 1.0
            episode_positives += int(bool(labelled))
        episode_length += 1
        steps_run = global_step

        obs = next_obs
        if terminated or truncated:
            success = is_success(terminated, episode_length, args.success_max_steps)
            buffer.tag_episode(episode_start, success)
            successes += success
            writer.add_scalar("charts/episodic_return", float(terminated), global_step)
            writer.add_scalar("charts/episodic_length", episode_length, global_step)
            writer.add_scalar("feedback/positive_rate", episode_positives / episode_length, global_step)
            episode_start, episode_positives, episode_length = buffer.size, 0, 0
            obs, _ = env.reset()

        if human is not None and taught and global_step >= args.tamer_learning_starts:
            # a person: several updates per answer, on the newest answer and a replay of the earlier ones (Deep TAMER)
            for _ in range(args.human_updates_per_answer):
                replay = torch.randint(buffer.size, (args.tamer_batch_size - 1,), device=device)
                idx = torch.cat([torch.tensor([buffer.size - 1], device=device), replay])
                b_obs, b_actions, _, b_feedback, _ = buffer.batch(idx)
                loss = tamer_loss(h_net, b_obs, b_actions, b_feedback)
                h_optimizer.zero_grad()
                loss.backward()
                h_optimizer.step()
            writer.add_scalar("losses/tamer_loss", loss.item(), global_step)
            own_way = gridworld_env.greedy_episode_length(greedy_actions(h_net, device), variant)
            if own_way < 200 and human.answers_to_goal is None:
                human.answers_to_goal = human.answers
        elif taught and global_step > args.tamer_learning_starts and global_step % args.tamer_train_frequency == 0:
            idx = torch.randint(buffer.size, (args.tamer_batch_size,), device=device)
            b_obs, b_actions, _, b_feedback, _ = buffer.batch(idx)
            loss = tamer_loss(h_net, b_obs, b_actions, b_feedback)
            h_optimizer.zero_grad()
            loss.backward()
            h_optimizer.step()
            if global_step % 100 == 0:
                writer.add_scalar("losses/tamer_loss", loss.item(), global_step)

        if global_step % 100 == 0:
            writer.add_scalar("feedback/positive", teacher.positives, global_step)
            writer.add_scalar("feedback/alpha", alpha, global_step)
            writer.add_scalar("charts/epsilon", epsilon, global_step)
        if global_step % 1000 == 0:
            writer.add_scalar("charts/SPS", int(global_step / (time.time() - start_time)), global_step)
        phase_ends = teacher.gone and args.budget_ends_forward_phase
        if global_step % args.eval_frequency == 0 or global_step == args.tamer_total_timesteps or phase_ends:
            metrics, evaluated_at = evaluator("tamer", greedy_actions(h_net, device), global_step), global_step
            progress(global_step, positives=teacher.positives, eval_length=metrics["eval/tamer_episode_length"])
            if optimum_at is None and metrics["eval/tamer_episode_length"] == OPTIMUM:
                optimum_at = (global_step, teacher.positives)
        if phase_ends:
            break
    # an episode cut off by the end of the phase never reached the goal: it stays untagged (failure)
    if evaluated_at != steps_run:  # the person stopped between two evaluations
        evaluator("tamer", greedy_actions(h_net, device), steps_run)
    if human is not None:
        human.finish(steps_run, teacher.positives, successes)
    stats = {
        "feedback/positive": teacher.positives,
        "feedback/perfect_positive": teacher.perfect_positives,
        "feedback/steps": steps_run,
        "feedback/positive_rate": teacher.positives / max(steps_run, 1),
        "feedback/step_to_tamer_optimum": None if optimum_at is None else optimum_at[0],
        "feedback/positive_to_tamer_optimum": None if optimum_at is None else optimum_at[1],
    }
    if human is not None:
        stats["feedback/oracle_agreement"] = human.agreement / max(human.answers, 1)
        stats["feedback/answers"] = human.answers
        stats["feedback/answers_to_tamer_goal"] = human.answers_to_goal  # until H's greedy path from S reached G
    return stats


def sleep_phase(args, buffer, q_net, target_net, evaluator, writer, device) -> dict:
    """Offline IQ-Learn ("sleep", Eq. 2) on the buffer, successful trajectories as the expert set."""
    success_idx = buffer.success[: buffer.size].nonzero().squeeze(1)
    stats = {"sleep/expert_transitions": int(success_idx.numel()), "sleep/replay_transitions": buffer.size,
             "sleep_skipped": success_idx.numel() == 0}  # fmt: skip
    if stats["sleep_skipped"]:
        how = ("next time keep teaching until the agent has walked from S to G in fewer than "
               f"{args.success_max_steps} steps at least once" if args.teacher == "human"
               else "raise --tamer-total-timesteps")  # fmt: skip
        print(
            f"warning: the sleep is skipped and no INFORM policy is made: no episode reached G in fewer than "
            f"{args.success_max_steps} steps, so there is nothing to consolidate; {how}",
            file=sys.stderr,
        )
        return stats
    q_optimizer = torch.optim.Adam(q_net.parameters(), lr=args.sleep_learning_rate, fused=True)
    is_expert = torch.arange(2 * args.sleep_batch_size, device=device) < args.sleep_batch_size
    progress = Progress("sleep", args.sleep_gradient_steps)
    start_time = time.time()
    for sleep_step in range(1, args.sleep_gradient_steps + 1):
        expert_idx = success_idx[torch.randint(success_idx.numel(), (args.sleep_batch_size,), device=device)]
        replay_idx = torch.randint(buffer.size, (args.sleep_batch_size,), device=device)
        b_obs, b_actions, b_next_obs, _, b_terminated = buffer.batch(torch.cat([expert_idx, replay_idx]))
        loss, terms = iq_loss(q_net, target_net, b_obs, b_actions, b_next_obs, b_terminated, is_expert,
                              args.sleep_gamma, args.sleep_temperature, args.sleep_chi2_coef)  # fmt: skip
        q_optimizer.zero_grad()
        loss.backward()
        q_optimizer.step()
        with torch.no_grad():
            for param, target_param in zip(q_net.parameters(), target_net.parameters(), strict=True):
                target_param.lerp_(param, args.sleep_tau)

        if sleep_step % 100 == 0 or sleep_step == args.sleep_gradient_steps:  # one host sync per 100 steps
            values = torch.stack([loss, *terms]).tolist()
            if not all(map(np.isfinite, values)):
                last = ", ".join(f"{k.split('/')[1]} {v:.4g}" for k, v in stats.items() if k.startswith("losses/"))
                raise Diverged(f"the sleep loss diverged (NaN or inf) by gradient step {sleep_step}; last finite "
                               f"losses: {last or 'none yet'}; try a lower --sleep-learning-rate")  # fmt: skip
            names = ("losses/iq_loss", "losses/iq_expert_term", "losses/iq_value_term", "losses/iq_chi2_term")
            stats.update(zip(names, values, strict=True))
            for tag in names:
                writer.add_scalar(tag, stats[tag], sleep_step)
            writer.add_scalar("sleep/SPS", int(sleep_step / (time.time() - start_time)), sleep_step)
        if sleep_step % args.sleep_eval_frequency == 0 or sleep_step == args.sleep_gradient_steps:
            metrics = evaluator("inform", greedy_actions(q_net, device), sleep_step)
            progress(sleep_step, iq_loss=stats.get("losses/iq_loss"),  # synced every 100 steps
                     eval_length=metrics["eval/inform_episode_length"])  # fmt: skip
            if "sleep/step_to_inform_optimum" not in stats and metrics["eval/inform_episode_length"] == OPTIMUM:
                stats["sleep/step_to_inform_optimum"] = sleep_step
    return stats


def make_run_dir(run_name: str) -> str:
    """runs/{run_name}, never an existing directory: a clash gets a numeric suffix."""
    path, n = f"runs/{run_name}", 0
    while True:
        try:
            os.makedirs(path)
            return path
        except FileExistsError:
            n += 1
            path = f"runs/{run_name}_{n}"


def write_json_atomic(path: str, data: dict) -> None:
    with open(path + ".tmp", "w") as f:
        json.dump(data, f, indent=2)
    os.replace(path + ".tmp", path)


def save_network(path: str, net: nn.Module, **extra) -> None:
    """A state_dict plus what rebuilds the network; torch.load(path, weights_only=True) reads it."""
    kwargs = {
        "obs_dim": net.network[0].in_features,
        "n_actions": net.network[-1].out_features,
        "hidden": net.network[0].out_features,
    }
    torch.save({"state_dict": net.state_dict(), "kwargs": kwargs, **extra}, path)


def main(args: Args, stop: "StopSignals", oracle_q: np.ndarray | None = None) -> dict:
    run_name = f"{args.env_id}__{args.exp_name}__{args.seed}__{int(time.time())}"
    run_start = time.time()
    run_dir = writer = evaluator = env = None
    summary, status, phase = {}, "completed", "startup"
    try:
        with stop.held():  # a stop waits until the directory exists and is known, so the summary can go there
            run_dir = make_run_dir(run_name)  # only now: bad input has been rejected, nothing half-written is left
        print(f"run directory: {run_dir}", flush=True)
        random.seed(args.seed)
        np.random.seed(args.seed)
        torch.manual_seed(args.seed)
        torch.backends.cudnn.deterministic = args.torch_deterministic
        if args.torch_deterministic:
            os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")  # CUDA matmuls refuse determinism without it
        torch.use_deterministic_algorithms(args.torch_deterministic)
        torch.set_num_threads(args.num_threads)
        device = torch.device("cuda" if torch.cuda.is_available() and args.cuda else "cpu")

        env = gym.make(args.env_id)
        env.action_space.seed(args.seed)
        obs_dim, n_actions = env.observation_space.shape[0], int(env.action_space.n)

        # Oracle: exact Q* by value iteration (the "fully trained model"), or a teacher saved by oracle_train.py
        phase, t0 = "oracle", time.time()
        if oracle_q is not None:
            q_star = oracle_q  # read and checked before the run directory was made
        else:
            q_star = gridworld_env.optimal_q(env.unwrapped.variant, args.oracle_gamma)
        summary["time/oracle_s"] = time.time() - t0

        writer = HeldWriter(run_dir, stop)
        writer.add_text(
            "hyperparameters",
            "|param|value|\n|-|-|\n" + "\n".join(f"|{key}|{value}|" for key, value in vars(args).items()),
        )
        evaluator = Evaluator(writer, args.success_max_steps)

        h_net = QNetwork(obs_dim, n_actions).to(device)
        buffer = ReplayBuffer(args.tamer_total_timesteps, obs_dim, device)
        q_net = QNetwork(obs_dim, n_actions).to(device)
        target_net = QNetwork(obs_dim, n_actions).to(device)
        target_net.load_state_dict(q_net.state_dict())
        evaluator("oracle", q_star.argmax(1), 0)

        # Forward phase ("day"): TAMER with a myopic H(s, a), simulated feedback, every transition remembered
        phase, t0, eval_s0 = "tamer", time.time(), evaluator.seconds
        summary.update(forward_phase(args, env, q_star, h_net, buffer, evaluator, writer, device))
        summary["time/tamer_s"] = time.time() - t0 - (evaluator.seconds - eval_s0)
        if args.save_model:
            save_network(f"{run_dir}/tamer_h.pt", h_net, env_id=args.env_id)

        # Sleep phase: offline IQ-Learn on the buffer; no environment steps
        phase, t0, eval_s0 = "sleep", time.time(), evaluator.seconds
        summary.update(sleep_phase(args, buffer, q_net, target_net, evaluator, writer, device))
        summary["time/sleep_s"] = time.time() - t0 - (evaluator.seconds - eval_s0)
        slept = not summary["sleep_skipped"]

        # Recovered reward (Eq. 3) on the maze the agent learned in
        phase = "reward"
        if slept:
            reward = reward_table(q_net, env.unwrapped.next_cell, args.sleep_gamma, args.sleep_temperature, device)
            writer.add_figure(
                "sleep/recovered_reward", reward_figure(reward.numpy(), f"recovered reward, seed {args.seed}")
            )
        if args.save_model and slept:
            save_network(f"{run_dir}/inform_q.pt", q_net, env_id=args.env_id, gamma=args.sleep_gamma,
                         temperature=args.sleep_temperature)  # fmt: skip
            torch.save({"reward": reward, "env_id": args.env_id, "gamma": args.sleep_gamma,
                        "temperature": args.sleep_temperature}, f"{run_dir}/recovered_reward.pt")  # fmt: skip

        # Final evaluation of the three policies (INFORM's only if the sleep made one)
        phase = "eval"
        evaluator("oracle", q_star.argmax(1), summary["feedback/steps"])
        evaluator("tamer", greedy_actions(h_net, device), summary["feedback/steps"])
        if slept:
            evaluator("inform", greedy_actions(q_net, device), args.sleep_gradient_steps)
        if args.capture_video:  # after the evaluation: drawing changes no number
            policies = {"tamer": greedy_actions(h_net, device)}
            if slept:
                policies["inform"] = greedy_actions(q_net, device)
            record_videos(run_dir, policies)
        if args.teacher == "human":
            for name, net in (("TAMER (what you taught)", h_net), ("INFORM (after the sleep)", q_net))[: 1 + slept]:
                print(
                    f"\n{name}, greedy from S:\n" + draw_greedy_path(greedy_actions(net, device), env.unwrapped.variant)
                )
    except (KeyboardInterrupt, BrokenPipeError) as e:  # a signal, or the reader of our output died
        status, stop.broken_pipe = "interrupted", isinstance(e, BrokenPipeError)
    except Diverged as e:
        status = "diverged"
        summary["error"] = str(e)

    # the summary first, then the messages: no signal cuts this short (StopSignals only notes the later ones)
    stop.finished = True
    reason = stop.reason()
    if run_dir is not None:
        if evaluator is not None:
            summary.update(evaluator.final)
            summary["time/eval_s"] = evaluator.seconds
        summary.update({"wall_time_s": time.time() - run_start, "seed": args.seed, "script": os.path.basename(__file__),
                        "status": status, "args": asdict(args)})  # fmt: skip
        if status != "completed":
            summary["phase"] = phase
        if status == "interrupted":
            summary["signal"] = reason
        write_json_atomic(f"{run_dir}/summary.json", summary)
    for closing in (evaluator, env, writer):
        if closing is not None:
            closing.close()
    if status == "interrupted":
        saved = f"what finished is saved in {run_dir}" if run_dir else "no run was made"
        say(f"interrupted ({reason}) during the {phase} phase; {saved}", sys.stderr)
    elif status == "diverged":
        say(f"error: {summary['error']}", sys.stderr)
    elif "eval/inform_episode_length" in summary:
        say(" | ".join(f"{p}: {summary[f'eval/{p}_episode_length']:.0f} steps" for p in POLICIES))
    if run_dir is not None:
        say(f"{status} in {summary['wall_time_s']:.1f}s; summary: {run_dir}/summary.json")
    return summary


# ---------------------------------------------------------------------------------------------------------------
# TRY NOT TO MODIFY: how a run ends. Signals, a dead reader of our output, messages that cannot crash the exit


class StopSignals:
    """SIGINT (Ctrl-C; unless ignored: nohup, `&`), SIGTERM (kill, Slurm) and SIGHUP (a closed terminal) stop the
    run: the first one raises KeyboardInterrupt, which main catches to save what finished. Never inside a TensorBoard
    call (see `held`): an interrupt in its queue put can swallow the wake-up of the writer's flush thread, and close()
    then waits for the thread's next flush, up to 120 s. Later signals, and any after the summary, are only noted."""

    def __init__(self):
        self.received, self.holding, self.pending, self.finished, self.broken_pipe = [], 0, False, False, False
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            if signal.getsignal(sig) is not signal.SIG_IGN:
                signal.signal(sig, self.handler)

    def handler(self, signum, frame):
        self.received.append(signal.Signals(signum).name)
        if len(self.received) > 1 or self.finished:
            return
        if self.holding:
            self.pending = True
            return
        raise KeyboardInterrupt

    @contextlib.contextmanager
    def held(self):
        """A stop signal that arrives in here takes effect as soon as the block ends."""
        self.holding += 1
        try:
            yield
        finally:
            self.holding -= 1
            if self.pending and not self.holding:
                self.pending = False
                raise KeyboardInterrupt

    def reason(self) -> str:
        """What stopped the run: the first signal; else SIGPIPE if the reader of our output died, else Ctrl-C."""
        return self.received[0] if self.received else "SIGPIPE" if self.broken_pipe else "SIGINT"

    def exit_code(self, status: str) -> int:
        """128 + the signal (130 SIGINT, 143 SIGTERM, 129 SIGHUP, 141 a dead reader), as a shell reports a kill;
        a signal after the summary still says the person wanted the run to stop (a shell loop then stops too)."""
        if status == "interrupted" or self.received:
            return 128 + signal.Signals[self.reason()].value
        return {"completed": 0, "diverged": 1}[status]


class HeldWriter:
    """TensorBoard's SummaryWriter, each call inside StopSignals.held()."""

    def __init__(self, log_dir: str, stop: StopSignals):
        self.stop = stop
        with stop.held():
            self.writer = SummaryWriter(log_dir)

    def __getattr__(self, name):
        method = getattr(self.writer, name)

        def held_call(*args, **kwargs):
            with self.stop.held():
                return method(*args, **kwargs)

        return held_call


def say(text: str, file=None) -> None:
    """print, except that a dead reader (a broken pipe) is not an error: what follows goes to /dev/null."""
    file = file or sys.stdout
    try:
        print(text, file=file, flush=True)
    except OSError:  # BrokenPipeError, or a closed terminal
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), file.fileno())  # the exit's final flush then succeeds too


def evaluate_saved(path: str, success_max_steps: int) -> dict:
    """Re-evaluate a saved tamer_h.pt or inform_q.pt: its greedy policy on the plain and wall mazes, the start set."""
    evaluator = Evaluator(None, success_max_steps)
    metrics = evaluator("policy", greedy_actions(load_q_network(path), torch.device("cpu")), 0)
    evaluator.close()
    return metrics


# --capture-video: the greedy episodes drawn as the recovered-reward figure draws the maze, written as GIFs by Pillow
VIDEO_START_CELLS = (7, 12, 17, 22)  # every third cell of the authors' start set (gridworld_env.START_SET)
VIDEO_MAZES = {"plain": "KnoxStoneMaze-v0", "wall": "KnoxStoneMazeWall-v0"}


def greedy_episode(policy: np.ndarray, variant: str, start: int) -> tuple[list[int], int, bool]:
    """One greedy episode in the registered maze, as `evaluate` runs it: the cells to draw (the start, then each
    step's, up to G or the first cell seen before: a deterministic policy then loops until the time limit), the
    episode length, and whether G was reached."""
    env = gym.make(VIDEO_MAZES[variant])
    obs, _ = env.reset(options={"start_cell": start})
    cells, length, terminated, truncated = [start], 0, False, False
    while not (terminated or truncated):
        obs, _, terminated, truncated, info = env.step(policy[int(obs.argmax())])
        length += 1
        if cells[-1] != gridworld_env.GOAL and cells.count(cells[-1]) == 1:  # no loop yet: draw this step too
            cells.append(info["cell"])
    env.close()
    return cells, length, bool(terminated)


def maze_frames(cells: list[int], variant: str, title: str, length: int, reached: bool) -> list[np.ndarray]:
    """RGB frames of the agent walking `cells` (its path so far as a line); the last frame says how it ended."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = Figure(figsize=(3.2, 3.4), dpi=80)
    canvas, ax = FigureCanvasAgg(fig), fig.subplots()
    fig.subplots_adjust(0.02, 0.02, 0.98, 0.86)
    for r, c in gridworld_env.CELLS:
        ax.add_patch(Rectangle((c, r), 1, 1, facecolor="white", edgecolor="0.85"))
    for r, c in gridworld_env.BLOCKED:
        ax.add_patch(Rectangle((c, r), 1, 1, facecolor="0.25"))
    for wall in gridworld_env.VARIANT_WALLS[variant]:
        (r1, c1), (r2, c2) = sorted(wall)
        xs, ys = ([c2, c2], [r1, r1 + 1]) if r1 == r2 else ([c1, c1 + 1], [r2, r2])
        ax.plot(xs, ys, color="black", lw=3)
    for cell, label in ((gridworld_env.START, "S"), (gridworld_env.GOAL, "G")):
        r, c = gridworld_env.CELLS[cell]
        ax.text(c + 0.5, r + 0.5, label, ha="center", va="center", fontsize=12, weight="bold", color="0.55")
    ax.set(xlim=(0, gridworld_env.COLS), ylim=(gridworld_env.ROWS, 0), aspect="equal", xticks=[], yticks=[])
    (path,) = ax.plot([], [], color="tab:blue", lw=2, alpha=0.6)
    (agent,) = ax.plot([], [], "o", color="tab:red", ms=14)
    heading = ax.set_title("", fontsize=9)
    frames = []
    for t in range(len(cells)):
        xs = [gridworld_env.CELLS[cell][1] + 0.5 for cell in cells[: t + 1]]
        ys = [gridworld_env.CELLS[cell][0] + 0.5 for cell in cells[: t + 1]]
        path.set_data(xs, ys)
        agent.set_data(xs[-1:], ys[-1:])
        ending = f"reaches G in {length} steps" if reached else f"loops: never reaches G ({length} steps)"
        heading.set_text(f"{title}\n" + (ending if t == len(cells) - 1 else f"step {t}"))
        canvas.draw()
        frames.append(np.asarray(canvas.buffer_rgba())[..., :3].copy())
    return frames


def write_gif(path: str, frames: list[np.ndarray], durations_ms: list[int]) -> None:
    """An endlessly looping GIF, written to a temporary name and renamed."""
    from PIL import Image

    images = [Image.fromarray(frame) for frame in frames]
    images[0].save(path + ".tmp", format="GIF", save_all=True, append_images=images[1:], loop=0,
                   duration=durations_ms)  # fmt: skip
    os.replace(path + ".tmp", path)


def record_videos(run_dir: str, policies: dict[str, np.ndarray]) -> dict:
    """--capture-video: each greedy table policy from S on the plain and the wall maze, and from VIDEO_START_CELLS on
    the plain maze one after the other, as videos/{policy}_{plain,wall,starts}.gif; videos/videos.json says how
    each episode ended."""
    os.makedirs(f"{run_dir}/videos", exist_ok=True)
    record, t0 = {}, time.time()
    for name, policy in policies.items():
        episodes = [("plain", "plain", gridworld_env.START), ("wall", "wall", gridworld_env.START)]
        episodes += [("starts", "plain", start) for start in VIDEO_START_CELLS]
        frames = {}
        for clip, variant, start in episodes:
            cells, length, reached = greedy_episode(policy, variant, start)
            maze = "wall maze" if variant == "wall" else "maze"
            title = f"{name.upper()}, {maze}, from {'S' if start == gridworld_env.START else f'cell {start}'}"
            episode = maze_frames(cells, variant, title, length, reached)
            frames.setdefault(clip, []).extend((frame, 1500 if t == len(episode) - 1 else 250)
                                               for t, frame in enumerate(episode))  # the end is held  # fmt: skip
            record[f"{name}_{clip}_{start}"] = {"file": f"{name}_{clip}.gif", "variant": variant, "start_cell": start,
                                                "episode_length": length, "reached_goal": reached,
                                                "frames": len(cells)}  # fmt: skip
        for clip, timed in frames.items():
            write_gif(f"{run_dir}/videos/{name}_{clip}.gif", [f for f, _ in timed], [ms for _, ms in timed])
    write_json_atomic(f"{run_dir}/videos/videos.json", record)
    print(f"[video] {len(record)} greedy episodes drawn in {time.time() - t0:.1f}s: {run_dir}/videos/", flush=True)
    return record


if __name__ == "__main__":
    try:
        args = tyro.cli(Args)  # a malformed flag: tyro's own message, exit 2
        if gridworld_env is None:
            raise InputError("gridworld_env.py (the maze) is not importable: copy it next to this script, or run "
                             "from the repo")  # fmt: skip
        check_args(args)
        if args.evaluate:
            print(json.dumps(evaluate_saved(args.evaluate, args.success_max_steps), indent=2))
            sys.exit(0)
        oracle_q = load_oracle(args.oracle_path, args.env_id) if args.oracle_path else None
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    stop = StopSignals()
    summary = main(args, stop, oracle_q)
    gc.freeze()  # the interpreter's last collections over torch's objects take seconds on a busy machine; skip them
    sys.exit(stop.exit_code(summary.get("status", "interrupted")))
