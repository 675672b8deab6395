"""INFORM on the Knox & Stone maze: TAMER learns from a simulated teacher's yes/no feedback ("day"), then offline
IQ-Learn on the remembered transitions ("sleep") gives a far-sighted policy and a recovered reward.

Tarakli & Di Nuovo, "Learning while Sleeping" (ICDL 2024): Algorithm 1 and Fig. 3 (episode length of TAMER, INFORM
and the expert) on the 30-cell maze; what the paper leaves open is in docs/protocol.md. Read top to bottom down to
`main`: Args, the network, Eq. 1-4 and the teacher, the buffer, the day, the night, main. Everything else comes after
main.

Gymnasium's toy-text tasks that carry their model (`--env-id FrozenLake-v1`, `CliffWalking-v1`, `Taxi-v4`) run from
their id alone: exact Q* by value iteration on `env.unwrapped.P`, one-hot observations, and an episode succeeds if it
ends on the task's goal (the terminal that earns its top reward) within --success-max-steps. The maze's own tests
(the wall maze, its start cells, the reward table and the drawings) are skipped there, and the summary says so.

Imported by inform_utils/, the only names other code may use (a test holds it to them): Args, main, check_args,
StopSignals, Teacher, ReplayBuffer, greedy_actions, greedy_episode, load_q_network, maze_frames, InputError.

    python inform_dqn_gridworld.py --seed 1
    python inform_dqn_gridworld.py --teacher-noise 0.2 --teacher-delay 1 --credit-window 2   # a human-like teacher
    python inform_dqn_gridworld.py --teacher human   # teach it yourself (docs/teachers.md)
    python inform_dqn_gridworld.py --env-id FrozenLake-v1 --success-max-steps 100   # a toy-text task (slippery ice)
"""

import collections
import contextlib
import gc
import importlib.util
import json
import math
import os
import pickle
import random
import signal
import sys
import time
import zipfile
from dataclasses import asdict, dataclass, fields
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
TOY_TEXT_MAX_STEPS = 200  # the step limit of a toy-text env registered without one (CliffWalking), as the maze's
if gridworld_env:
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
    track: bool = False
    """if toggled, mirror the TensorBoard events to Weights & Biases (CleanRL's --track; needs `pip install wandb`,
    and WANDB_MODE=offline keeps the run on this machine)"""
    wandb_project_name: str = "inform"
    """the Weights & Biases project"""
    wandb_entity: str | None = None
    """the Weights & Biases team or user (None: your default)"""
    env_id: str = "KnoxStoneMaze-v0"
    """the maze to train on (one of the ids gridworld_env registers), or a Gymnasium toy-text env with a model
    (FrozenLake-v1, CliffWalking-v1, Taxi-v4, ...)"""

    # Oracle (the simulated teacher)
    oracle_gamma: float = 0.99
    """discount of the oracle's exact Q* (value iteration)"""
    oracle_path: str | None = None
    """a maze teacher saved by oracle_train.py (e.g. a half-trained Q-learner) instead of exact Q*"""

    # Forward phase: TAMER (Eq. 1) with simulated feedback (Eq. 4)
    tamer_total_timesteps: int = 10000
    """environment steps of the forward phase"""
    tamer_learning_starts: int | None = None
    """environment steps before H is trained (None: 1000; with --teacher human 1, H learns from your first answer)"""
    tamer_batch_size: int = 32
    """batch size of the H regression"""
    tamer_h_lr: float = 1e-3
    """Adam learning rate of the feedback model H"""
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
    """an episode is tagged success if it reaches the goal (the terminal that earns the task's top reward) in fewer
    than this many steps"""

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
    """the teacher leaves after this many +1 signals (None: never); then TAMER stops learning"""
    budget_ends_forward_phase: bool = False
    """when the budget is spent, end the forward phase and sleep (otherwise keep acting, without feedback)"""
    human_updates_per_answer: int = 20
    """--teacher human: H's gradient steps after each answer, each on the newest answer plus a replay of earlier ones
    (Deep TAMER's remedies), so that an answer takes effect before the next move"""

    # Sleep phase: offline IQ-Learn (Eq. 2), no environment steps
    sleep_gradient_steps: int = 3000
    """gradient steps of the sleep phase"""
    sleep_batch_size: int = 32
    """transitions from the success set, and as many from the whole buffer, per step"""
    sleep_q_lr: float = 1e-3
    """Adam learning rate of the soft Q network"""
    sleep_gamma: float = 0.99
    """discount of the sleep phase (non-myopic, unlike TAMER's 0)"""
    sleep_temperature: float = 0.1
    """temperature of the soft value V(s) = temp * logsumexp(Q(s, .) / temp)"""
    sleep_chi2_coef: float = 0.5
    """weight of the chi-squared regulariser, 1 / (4 * 0.5) as IQ-Learn; 0 turns it off"""
    tau: float = 1.0
    """soft-update rate of the sleep's target Q network per step (1 copies it every step, as the authors did)"""
    sleep_loss_rows: Literal["all", "expert"] = "all"
    """the rows of Eq. 2's value and chi-squared terms: the whole batch (the paper), or the expert rows only
    (IQ-Learn's offline recipe, its `value_expert` loss)"""
    sleep_control: Literal["none", "bc", "sham"] = "none"
    """a control in place of the sleep, same steps and batches: bc = behaviour cloning on the success set (cross-entropy
    of Q(s, .) / temperature on the expert rows); sham = TAMER's own update (H from the day's, Eq. 1 on the replay
    rows), no consolidation"""
    sleep_seed: int | None = None
    """None: the sleep goes on with the random streams where the day left them; an integer re-seeds them before the
    sleep (several sleeps on one day)"""

    # Saved days: one forward phase, many nights
    save_buffer: bool = False
    """write the day (memories, episode table, oracle, TAMER's H, random states) to runs/{run}/day.pt for
    --sleep-from"""
    sleep_from: str | None = None
    """run only the night and the final tests on the day saved in this run directory (by --save-buffer); the day's
    flags (env, seed, teacher, TAMER) replace this run's"""

    # Evaluation
    eval_frequency: int = 500
    """forward-phase environment steps between greedy evaluations"""
    sleep_eval_frequency: int = 500
    """sleep-phase gradient steps between greedy evaluations"""
    eval_episodes: int = 20
    """greedy episodes of each evaluation on a toy-text env, on fixed reset seeds (the maze's tests are one episode
    from each of their start cells)"""
    log_frequency: int | None = None
    """steps between scalar logs (losses, SPS, feedback) (None: 100; with --teacher human 1, every answer)"""
    evaluate: str | None = None
    """re-evaluate a saved tamer_h.pt or inform_q.pt, print its episode lengths as JSON, train nothing"""


# the task: the maze, or a toy-text env that carries its model (P[s][a] = [(probability, s', reward, terminated)])


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


def optimal_q(env: gym.Env, gamma: float) -> np.ndarray:
    """Exact Q* by value iteration (the "fully trained model"): the maze's own, or from a toy-text env's model, whose
    slippery moves give expected values."""
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


# ---------------------------------------------------------------------------------------------------------------------
# the network: each is rebuilt from the `kwargs` saved beside its state_dict


class QNetwork(nn.Module):
    """The 30-32-32-4 MLP of the authors, used both for TAMER's H(s, a) and for the sleep phase's soft Q(s, a)."""

    def __init__(self, obs_dim: int, n_actions: int, hidden: int = 32):
        super().__init__()
        self.network = nn.Sequential(
            nn.Linear(obs_dim, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, n_actions)
        )

    def forward(self, x):
        return self.network(x)


def soft_update(target: nn.Module, source: nn.Module, tau: float) -> None:
    with torch.no_grad():
        for param, target_param in zip(source.parameters(), target.parameters(), strict=True):
            target_param.lerp_(param, tau)


# ---------------------------------------------------------------------------------------------------------------------
# the pieces of Algorithm 1, named after the paper: Eq. 1-4 and the teacher


def linear_schedule(start: float, end: float, duration: int, t: int) -> float:
    """From `start` at t = 0 to `end` at t = duration, then constant."""
    return start + (end - start) * min(t, duration) / max(duration, 1)


def oracle_feedback(q_star_sa, q_star_best, alpha):
    # Eq. 4, sign-safe: h = 1 if Q*(s, a) >= Q*(s, a*) - (1 - alpha) |Q*(s, a*)|, else 0
    return (q_star_sa >= q_star_best - (1.0 - alpha) * abs(q_star_best)) * 1.0


# ALGO LOGIC: the teacher (docs/protocol.md). Eq. 4 says what a perfect teacher would answer; a person distorts it.
# Copy this class verbatim into both INFORM scripts (CleanRL style: repeated across files, never within one).
class Teacher:
    """A simulated person between Eq. 4 and the learner: noisy, sparse, late and limited (paper Sec. VII's future work).

    Each call hands over the perfect teacher's answer h* (0 or 1) about the transition at buffer index `step` and
    returns the labels that arrive now, {buffer index: h} (h = 1 here; a graded or negative teacher returns other
    values, and the forward phase writes whatever it gets). In order: the judgement is flipped with probability
    `noise`; a +1 is then clicked only with probability `sparsity`; a click about step t arrives at step t + `delay`
    and labels that later transition and the `credit_window` - 1 before it (Deep TAMER's remedy; a window of
    delay + 1 covers the step it was about). The teacher leaves after `budget` delivered +1 signals (None: never).
    Its randomness is its own generator, so the defaults (0, 1, 0, 1, None) reproduce the perfect teacher exactly
    and leave every other random stream untouched. Signals still on their way when the phase ends are lost.
    """

    def __init__(self, noise=0.0, sparsity=1.0, delay=0, credit_window=1, budget=None, seed=0):
        self.noise = noise
        self.sparsity = sparsity
        self.delay = delay
        self.credit_window = credit_window
        self.budget = budget
        self.rng = np.random.default_rng(seed)
        self.in_flight = collections.deque()  # clicks on their way, oldest first
        self.positives = 0  # +1 signals delivered
        self.perfect_positives = 0  # +1 answers of the perfect teacher (Eq. 4), for the record

    @classmethod
    def from_args(cls, args) -> "Teacher":
        """The person that the --teacher-* flags describe, with a generator of its own."""
        flags = ("teacher_noise", "teacher_sparsity", "teacher_delay", "credit_window", "feedback_budget")
        return cls(*(getattr(args, flag) for flag in flags), seed=args.seed + 7919)

    @property
    def gone(self) -> bool:
        """The budget is spent: no more feedback from now on."""
        return self.budget is not None and self.positives >= self.budget

    def __call__(self, step: int, h_star: float) -> dict[int, float]:
        self.perfect_positives += int(h_star > 0)
        flip, click = self.rng.random(2)  # always two draws: the stream does not depend on the answers
        h = 1.0 - h_star if flip < self.noise else h_star
        h = h if click < self.sparsity else 0.0
        self.in_flight.append(h)
        if len(self.in_flight) <= self.delay:
            return {}
        h = self.in_flight.popleft()
        if h <= 0 or self.gone:
            return {}
        self.positives += 1
        return dict.fromkeys(range(max(0, step - self.credit_window + 1), step + 1), 1.0)


def tamer_loss(h_net, obs, actions, feedback):
    # Eq. 1: E[(H(s, a) - h)^2], gamma = 0: no bootstrapping, no target network
    return F.mse_loss(h_net(obs).gather(1, actions[:, None]).squeeze(1), feedback)


def soft_value(q, temperature: float):
    """V(s) = temp * logsumexp(Q(s, .) / temp) (discrete IQ-Learn)."""
    return temperature * torch.logsumexp(q / temperature, dim=1)


# ALGO LOGIC: the sleep loss. The Pusher script's signature and return, without the actor that V(s) needs there; the
# rows of the value and chi-squared terms (IQ-Learn's offline recipe takes the expert rows only).
def iq_loss(q_net, target_net, obs, actions, next_obs, terminated, is_expert, gamma, temperature, chi2_coef, rows=None):
    # Eq. 2 (to minimise): y = (1 - done) gamma V_target(s');
    # L = -E_success[Q(s,a) - y] + E_all[V(s) - y] + chi2 * E_all[(Q(s,a) - y)^2]
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
        eye = torch.eye(n_states or gridworld_env.N_CELLS, device=device)
        return q_net(eye).argmax(1).cpu().numpy()


def is_success(terminated: bool, reward: float, length: int, max_steps: int, goal_reward: float) -> bool:
    """The success tag: the goal was reached in fewer than `max_steps` steps. The goal is the terminal that earns the
    task's top reward (the maze's G; not FrozenLake's holes, which end the episode with nothing)."""
    return bool(terminated) and reward >= goal_reward and length < max_steps


class ReplayBuffer:
    """Every forward-phase transition (s, a, s', h, terminated), preallocated, and the success tag of its episode."""

    def __init__(self, capacity: int, obs_dim: int, device: torch.device):
        self.obs = torch.zeros(capacity, obs_dim, device=device)
        self.next_obs = torch.zeros(capacity, obs_dim, device=device)
        self.actions = torch.zeros(capacity, dtype=torch.long, device=device)
        self.feedback = torch.zeros(capacity, device=device)  # h, written by the teacher when a signal arrives
        self.terminated = torch.zeros(capacity, device=device)
        self.success = torch.zeros(capacity, dtype=torch.bool, device=device)
        self.size = 0  # transitions stored (fewer than the capacity when the teacher stops early)
        self.episodes = []  # (start, end) of each episode that ended: buffer[start:end]

    def add(self, obs, action, next_obs, terminated) -> None:
        self.obs[self.size] = torch.as_tensor(obs)
        self.actions[self.size] = action
        self.next_obs[self.size] = torch.as_tensor(next_obs)
        self.terminated[self.size] = float(terminated)
        self.size += 1

    def tag_episode(self, start: int, success: bool) -> bool:
        """Tag the trajectory buffer[start:size], which just ended, as a success or a failure."""
        self.success[start : self.size] = success
        self.episodes.append((start, self.size))
        return success

    def batch(self, idx: torch.Tensor):
        return self.obs[idx], self.actions[idx], self.next_obs[idx], self.feedback[idx], self.terminated[idx]


# ---------------------------------------------------------------------------------------------------------------------
# the phases of Algorithm 1, then main


def forward_phase(args: Args, env, q_star: np.ndarray, buffer: ReplayBuffer, evaluator, writer, device):
    """The day: TAMER (Eq. 1, gamma = 0) acts on H and fits it to the teacher's yes/no feedback (Eq. 4 through the
    Teacher, or a person at the terminal); every transition is remembered, every episode tagged."""
    h_net = QNetwork(buffer.obs.shape[1], int(env.action_space.n)).to(device)
    h_optimizer = torch.optim.Adam(h_net.parameters(), lr=args.tamer_h_lr, fused=True)
    teacher = Teacher.from_args(args)
    human = (
        HumanTeacher(env.unwrapped.variant, args.success_max_steps, h_net, device) if args.teacher == "human" else None
    )
    n = args.tamer_total_timesteps
    progress = Progress("tamer", n, warmup=args.tamer_learning_starts, evaluator=evaluator)
    h_loss = torch.zeros((), device=device)
    optimum_at = None  # (step, +1 signals) at the first evaluation where TAMER's greedy path is the shortest
    evaluated_at = 0
    ep_start = ep_length = successes = 0
    ep_return = 0.0
    goal_reward = top_reward(env)
    obs, _ = env.reset(seed=args.seed)
    for step in range(n):
        StopSignals.check()  # a stop signal ends the run here, between two steps
        epsilon = linear_schedule(args.start_e, args.end_e, int(args.exploration_fraction * n), step)
        explore = random.random() < epsilon
        cell = int(obs.argmax())
        if explore:
            action = env.action_space.sample()
        else:
            with torch.no_grad():
                h_values = h_net(torch.as_tensor(obs, device=device))
            action = int(h_values.argmax()) if human is None else human.propose(h_values, cell)

        # ALGO LOGIC: the teacher watches (s, a): the perfect answer (Eq. 4), then the person's (Teacher), or yours
        taught = not teacher.gone  # after the budget is spent, TAMER has nothing to learn from
        feedback_alpha = linear_schedule(args.feedback_alpha_start, args.feedback_alpha_end, n - 1, step)
        h_star = oracle_feedback(q_star[cell, action], q_star[cell].max(), feedback_alpha) if taught else 0.0
        if human is not None and taught:
            h_star = human(cell, action, explore, step + 1, teacher.positives, h_star, successes)
            if h_star is None:  # q or the end of the input: stop teaching, the sleep starts
                break
        labels = teacher(step, h_star)  # {transition: h} that this step's arriving signal labels
        buffer.feedback[list(labels)] = torch.tensor(list(labels.values()), device=device)

        next_obs, reward, terminated, truncated, _ = env.step(action)
        buffer.add(obs, action, next_obs, terminated)
        ep_length += 1
        ep_return += float(reward)
        obs = next_obs
        if terminated or truncated:  # an episode cut off by the end of the phase stays untagged: a failure
            success = is_success(terminated, reward, ep_length, args.success_max_steps, goal_reward)
            successes += buffer.tag_episode(ep_start, success)
            writer.add_scalar("charts/episodic_return", ep_return, step + 1)
            writer.add_scalar("charts/episodic_length", ep_length, step + 1)
            ep_start = step + 1
            ep_length = 0
            ep_return = 0.0
            obs, _ = env.reset()

        # ALGO LOGIC: TAMER's update: H regresses on the feedback (Eq. 1); a person's answer gets several (below main)
        if taught and human is not None and step + 1 >= args.tamer_learning_starts:
            h_loss = human.learn(h_optimizer, buffer, args.human_updates_per_answer, args.tamer_batch_size)
        elif taught and step >= args.tamer_learning_starts and (step + 1) % args.tamer_train_frequency == 0:
            idx = torch.randint(0, buffer.size, (args.tamer_batch_size,), device=device)
            obs_b, actions_b, _, feedback_b, _ = buffer.batch(idx)
            h_loss = tamer_loss(h_net, obs_b, actions_b, feedback_b)
            h_optimizer.zero_grad()
            h_loss.backward()
            h_optimizer.step()

        # TRY NOT TO MODIFY: logging and periodic evaluation
        last_step = step == n - 1 or (teacher.gone and args.budget_ends_forward_phase)
        if (step + 1) % args.log_frequency == 0 or last_step:
            writer.add_scalar("losses/tamer_loss", h_loss.item(), step + 1)
            writer.add_scalar("feedback/positive", teacher.positives, step + 1)
            writer.add_scalar("feedback/positive_rate", teacher.positives / (step + 1), step + 1)
            writer.add_scalar("feedback/alpha", feedback_alpha, step + 1)
            writer.add_scalar("charts/epsilon", epsilon, step + 1)
            writer.add_scalar("charts/SPS", progress.sps(step + 1), step + 1)
        report = {"positives": teacher.positives}
        if (step + 1) % args.eval_frequency == 0 or last_step:
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
    if human is not None:
        human.finish(buffer.size, teacher.positives, successes)
    stats = {
        "feedback/positive": teacher.positives,
        "feedback/perfect_positive": teacher.perfect_positives,
        "feedback/steps": buffer.size,
        "feedback/positive_rate": teacher.positives / max(buffer.size, 1),
        "feedback/step_to_tamer_optimum": None if optimum_at is None else optimum_at[0],
        "feedback/positive_to_tamer_optimum": None if optimum_at is None else optimum_at[1],
    }
    if human is not None:
        stats["feedback/oracle_agreement"] = human.agreement / max(human.answers, 1)
        stats["feedback/answers"] = human.answers
        stats["feedback/answers_to_tamer_goal"] = human.answers_to_goal  # until H's greedy path from S reached G
    return h_net, stats


def sleep_phase(args: Args, buffer: ReplayBuffer, n_actions: int, evaluator, writer, device, h_net=None):
    """The night: offline IQ-Learn (Eq. 2) on the buffer, the successful trajectories as the expert set. Without a
    success there is nothing to consolidate: no INFORM policy (None). TAMER's H is needed by the sham control only."""
    expert_idx = buffer.success[: buffer.size].nonzero().squeeze(1)
    stats = {"sleep/expert_transitions": int(expert_idx.numel()), "sleep/replay_transitions": buffer.size}
    stats["sleep_skipped"] = expert_idx.numel() == 0
    if stats["sleep_skipped"]:
        how = "raise --tamer-total-timesteps"
        if args.teacher == "human":
            how = "next time keep teaching until the agent has walked from S to G in time at least once"
        print(
            f"warning: the sleep is skipped and no INFORM policy is made: no episode reached G in fewer than "
            f"{args.success_max_steps} steps, so there is nothing to consolidate; {how}",
            file=sys.stderr,
        )
        return None, stats
    q_net = QNetwork(buffer.obs.shape[1], n_actions).to(device)
    q_target = QNetwork(buffer.obs.shape[1], n_actions).to(device)
    q_target.load_state_dict(q_net.state_dict())
    q_optimizer = torch.optim.Adam(q_net.parameters(), lr=args.sleep_q_lr, fused=True)
    if args.sleep_control == "sham":  # TAMER goes on learning from its memories, at its own rate
        q_net.load_state_dict(h_net.state_dict())
        q_optimizer = torch.optim.Adam(q_net.parameters(), lr=args.tamer_h_lr, fused=True)
    batch_size = args.sleep_batch_size
    gamma = args.sleep_gamma
    temperature = args.sleep_temperature
    chi2 = args.sleep_chi2_coef
    is_expert = torch.arange(2 * batch_size, device=device) >= batch_size  # the batch: replay rows, then expert rows
    rows = is_expert if args.sleep_loss_rows == "expert" else None  # of the value and chi2 terms
    losses = {}
    progress = Progress("sleep", args.sleep_gradient_steps, evaluator=evaluator)
    for step in range(1, args.sleep_gradient_steps + 1):
        StopSignals.check()
        # ALGO LOGIC: the sleep update: Q by IQ-Learn (Eq. 2), the target Q follows softly
        replay = torch.randint(0, buffer.size, (batch_size,), device=device)
        expert = expert_idx[torch.randint(0, expert_idx.numel(), (batch_size,), device=device)]
        obs, actions, next_obs, feedback, terminated = buffer.batch(torch.cat([replay, expert]))
        if args.sleep_control == "none":
            loss, terms = iq_loss(
                q_net, q_target, obs, actions, next_obs, terminated, is_expert, gamma, temperature, chi2, rows
            )
        elif args.sleep_control == "bc":  # control: behaviour cloning on the success set, no Eq. 2
            loss = F.cross_entropy(q_net(obs[is_expert]) / temperature, actions[is_expert])
            terms = {}
        else:  # control "sham": TAMER's own update (Eq. 1) on the replay rows, no Eq. 2
            loss = tamer_loss(q_net, obs[~is_expert], actions[~is_expert], feedback[~is_expert])
            terms = {}
        q_optimizer.zero_grad()
        loss.backward()
        q_optimizer.step()
        soft_update(q_target, q_net, args.tau)

        # TRY NOT TO MODIFY: logging (one host sync per 100 steps to catch divergence) and periodic evaluation
        last_step = step == args.sleep_gradient_steps
        log_now = step % args.log_frequency == 0 or last_step
        if log_now or step % 100 == 0:
            tags = {"iq_loss" if args.sleep_control == "none" else f"{args.sleep_control}_loss": loss, **terms}
            values = torch.stack(list(tags.values())).tolist()
            if not all(map(math.isfinite, values)):
                last = ", ".join(f"{k.split('/')[1]} {v:.4g}" for k, v in losses.items())
                raise Diverged(
                    f"the sleep loss diverged (NaN or inf) by gradient step {step}; last finite losses: "
                    f"{last or 'none yet'}; try a lower --sleep-q-lr"
                )
            losses = {f"losses/{tag}": value for tag, value in zip(tags, values, strict=True)}
        if log_now:
            for tag, value in losses.items():
                writer.add_scalar(tag, value, step)
            writer.add_scalar("sleep/SPS", progress.sps(step), step)
        report = {"iq_loss": losses.get("losses/iq_loss")}
        if step % args.sleep_eval_frequency == 0 or last_step:
            metrics = evaluator("inform", greedy_actions(q_net, device, buffer.obs.shape[1]), step)
            report["eval length"] = metrics["eval/inform_episode_length"]
            if "sleep/step_to_inform_optimum" not in stats and report["eval length"] == evaluator.optimum:
                stats["sleep/step_to_inform_optimum"] = step
        progress(step, **report)
    return q_net, {**stats, **losses}


def main(args: Args, oracle_q: np.ndarray | None, stop: "StopSignals", day: dict | None = None) -> dict:
    run_name = f"{args.env_id}__{args.exp_name}__{args.seed}__{int(time.time())}"
    run_start = time.time()
    run_dir = writer = env = evaluator = None
    summary = {"time/oracle_s": 0.0, "time/tamer_s": 0.0, "time/sleep_s": 0.0}
    summary["sleep_from"] = os.path.abspath(args.sleep_from) if args.sleep_from else None  # a saved day's run
    summary["sleep_variant"] = (
        f"control={args.sleep_control} loss_rows={args.sleep_loss_rows} temperature={args.sleep_temperature} "
        f"steps={args.sleep_gradient_steps} seed={args.sleep_seed}"
    )
    status = "completed"
    failure = None
    phase = "startup"
    try:  # a stop (signal, dead reader) anywhere below finds the except that saves what finished
        run_dir = make_run_dir(run_name)  # only now: bad input has been rejected, nothing half-written is left
        print(f"run directory: {run_dir}", flush=True)
        StopSignals.check()  # a stop while starting ends here, with a summary in the run directory
        random.seed(args.seed)
        np.random.seed(args.seed)
        torch.manual_seed(args.seed)
        torch.backends.cudnn.deterministic = args.torch_deterministic
        if args.torch_deterministic:
            os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")  # CUDA matmuls refuse determinism without it
        torch.use_deterministic_algorithms(args.torch_deterministic)
        torch.set_num_threads(args.num_threads)
        device = torch.device("cuda" if torch.cuda.is_available() and args.cuda else "cpu")

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
        writer.add_text(
            "hyperparameters",
            "|param|value|\n|-|-|\n" + "\n".join(f"|{key}|{value}|" for key, value in vars(args).items()),
        )
        env = make_env(args.env_id)
        env.action_space.seed(args.seed)
        evaluator = Evaluator(args, writer)
        obs_dim = env.observation_space.shape[0]
        n_actions = int(env.action_space.n)

        if day is None:
            # ---- oracle: exact Q* by value iteration (the "fully trained model"), or a teacher from oracle_train.py
            phase = "oracle"
            t0 = time.time()
            q_star = optimal_q(env, args.oracle_gamma) if oracle_q is None else oracle_q
            summary["time/oracle_s"] = time.time() - t0
            evaluator("oracle", q_star.argmax(1), 0)

            # ---- forward phase ("day"): TAMER with simulated feedback, every transition remembered
            phase = "tamer"
            t0 = time.time() - evaluator.seconds  # the phase's clock stops during its evaluations
            buffer = ReplayBuffer(args.tamer_total_timesteps, obs_dim, device)
            h_net, stats = forward_phase(args, env, q_star, buffer, evaluator, writer, device)
            summary.update(stats)
            summary["time/tamer_s"] = time.time() - evaluator.seconds - t0
            if args.save_buffer:  # the day as it ended, for later nights (--sleep-from)
                day_stats = {**stats, "time/tamer_s": summary["time/tamer_s"]}
                save_day(f"{run_dir}/day.pt", args, buffer, h_net, q_star, day_stats)
        else:  # --sleep-from: a saved day's oracle, memories and H, its random streams where that day left them
            q_star, buffer, h_net = restore_day(day, device)
            summary.update(day["day_stats"])
        if args.save_model:
            save_network(f"{run_dir}/tamer_h.pt", h_net, env_id=args.env_id)

        # ---- sleep phase ("night"): offline IQ-Learn on the buffer, no environment steps
        phase = "sleep"
        if args.sleep_seed is not None:  # a night of its own: the random streams start afresh
            random.seed(args.sleep_seed)
            np.random.seed(args.sleep_seed)
            torch.manual_seed(args.sleep_seed)
        t0 = time.time() - evaluator.seconds
        q_net, stats = sleep_phase(args, buffer, n_actions, evaluator, writer, device, h_net)
        summary.update(stats)
        summary["time/sleep_s"] = time.time() - evaluator.seconds - t0

        # ---- the recovered reward (Eq. 3) on the maze the agent learned in, then the final evaluation
        phase = "eval"
        policies = {"oracle": q_star.argmax(1), "tamer": greedy_actions(h_net, device, obs_dim)}
        if q_net is not None:
            policies["inform"] = greedy_actions(q_net, device, obs_dim)
            extra = {"env_id": args.env_id, "gamma": args.sleep_gamma, "temperature": args.sleep_temperature}
            if args.save_model:
                save_network(f"{run_dir}/inform_q.pt", q_net, **extra)
            if args.env_id in MAZE_IDS:  # the reward table needs the maze's deterministic moves
                reward = reward_table(q_net, env.unwrapped.next_cell, args.sleep_gamma, args.sleep_temperature, device)
                figure = reward_figure(reward.numpy(), f"recovered reward, seed {args.seed}")
                writer.add_figure("sleep/recovered_reward", figure)
                if args.save_model:
                    save_atomic({"reward": reward, **extra}, f"{run_dir}/recovered_reward.pt")
        if args.env_id not in MAZE_IDS:
            summary["maze_tests/skipped"] = (
                f"the wall maze, start cells, reward table and drawings: none on {args.env_id}"
            )
        final_evaluation(args, env, policies, h_net, q_net, evaluator, run_dir, summary["feedback/steps"])
    except (KeyboardInterrupt, BrokenPipeError) as e:  # a signal, or the reader of our output died
        status = "interrupted"
        stop.broken_pipe = isinstance(e, BrokenPipeError)
    except Diverged as e:
        status = "diverged"
        summary["error"] = str(e)
    except Exception as e:  # a bug: the summary records it, then its traceback
        status = "failed"
        summary["error"] = f"{type(e).__name__}: {(str(e).strip() or '-').splitlines()[0]}"
        failure = e
    summary = end_run(args, summary, status, phase, run_dir, run_start, evaluator, (env, writer), stop)
    if failure is not None:
        raise failure
    return summary


# ---------------------------------------------------------------------------------------------------------------------
# ALGO LOGIC, below main: the evaluation protocol and the rest of the research code. The greedy tests (S, the wall
# maze, the start set, all cells), the person at the terminal (a teacher), the drawings of paths and of the reward


def final_evaluation(args: Args, env, policies: dict, h_net, q_net, evaluator, run_dir: str, forward_steps: int):
    """The greedy policies' final evaluation (INFORM's at the sleep's last step, the others at the day's), the GIFs
    with --capture-video, and for a person who taught: TAMER's and INFORM's paths from S, drawn."""
    for name, policy in policies.items():
        evaluator(name, policy, args.sleep_gradient_steps if name == "inform" else forward_steps)
    if args.capture_video:  # after the evaluation: drawing changes no number
        record_videos(run_dir, {name: policy for name, policy in policies.items() if name != "oracle"})
    if args.teacher == "human":
        variant = env.unwrapped.variant
        print("\nTAMER (what you taught), greedy from S:\n" + draw_greedy_path(policies["tamer"], variant))
        if "inform" in policies:
            print("\nINFORM (after the sleep), greedy from S:\n" + draw_greedy_path(policies["inform"], variant))


def evaluate(policy: np.ndarray, env: gym.Env, resets: list[dict], success_max_steps: int):
    """Run the greedy table policy once from each reset (the keyword arguments of env.reset: a maze's start cell, a
    toy-text env's seed); mean episode length and success rate."""
    lengths = []
    successes = []
    goal_reward = top_reward(env)
    for reset in resets:
        obs, _ = env.reset(**reset)
        terminated = truncated = False
        length = 0
        reward = 0.0
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
    --eval-episodes fixed reset seeds; logs eval/ tags. `optimum` is the shortest mean length a greedy policy can
    have there (the maze's 19 steps; on a toy-text env, exact Q*'s)."""

    def __init__(self, args: Args, writer: SummaryWriter | None):
        self.writer = writer
        self.success_max_steps = args.success_max_steps
        self.maze = args.env_id in MAZE_IDS
        if self.maze:
            self.envs = {
                name: gym.make(env_id)
                for name, env_id in [
                    ("plain", "KnoxStoneMaze-v0"),
                    ("wall", "KnoxStoneMazeWall-v0"),
                    ("start_set", "KnoxStoneMazeStartSet-v0"),
                ]
            }
            self.optimum = OPTIMUM
        else:
            self.envs = {"plain": make_env(args.env_id)}
            self.resets = [{"seed": 1_000_000 + 1000 * args.seed + ep} for ep in range(args.eval_episodes)]
            q_star = optimal_q(self.envs["plain"], args.oracle_gamma)
            self.optimum = evaluate(q_star.argmax(1), self.envs["plain"], self.resets, self.success_max_steps)[0]
        self.seconds = 0.0
        self.final = {}

    def __call__(self, name: str, policy: np.ndarray, step: int) -> dict:
        t0 = time.time()
        if self.maze:
            length, _ = evaluate(policy, self.envs["plain"], start_cells(gridworld_env.START), self.success_max_steps)
            wall_length, _ = evaluate(
                policy, self.envs["wall"], start_cells(gridworld_env.START), self.success_max_steps
            )
            set_length, set_success = evaluate(
                policy, self.envs["start_set"], start_cells(*gridworld_env.START_SET), self.success_max_steps
            )
            _, all_success = evaluate(
                policy, self.envs["plain"], start_cells(*gridworld_env.ANY_START), self.success_max_steps
            )
            metrics = {
                f"eval/{name}_episode_length": length,
                f"eval/wall/{name}_episode_length": wall_length,
                f"eval/start_set/{name}_episode_length": set_length,
                f"eval/start_set/{name}_success_rate": set_success,
                f"eval/all_starts/{name}_success_rate": all_success,
            }
        else:
            length, success = evaluate(policy, self.envs["plain"], self.resets, self.success_max_steps)
            metrics = {f"eval/{name}_episode_length": length, f"eval/{name}_success_rate": success}
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

    def __init__(self, variant: str, success_max_steps: int, h_net: QNetwork, device: torch.device):
        self.variant = variant
        self.h_net = h_net
        self.device = device
        self.own_way = self.greedy_length()  # the length of the agent's own (greedy) way from S; 200: it never ends
        self.next_cell = gridworld_env.transition_table(variant)
        self.answers = self.agreement = 0  # answers given, and how many Eq. 4 (the oracle) would have given too
        self.refused = np.zeros((gridworld_env.N_CELLS, gridworld_env.N_ACTIONS))  # Enter answers per (cell, move)
        self.answers_to_goal = None  # answers given when the agent's own (greedy) way from S first reached G
        self.echo = not sys.stdin.isatty()  # piped answers are not echoed by a terminal: print them
        print(
            "You are the teacher. The agent A must reach G by the shortest path (19 steps from S).\n"
            "For each move answer: y = good (+1), Enter = no feedback, q = stop teaching (the sleep starts).\n"
            "A move you answer with Enter is not proposed again in that cell while it has moves you have not "
            f"judged.\nThe sleep learns from the walks from S to G in fewer than {success_max_steps} steps: "
            "teach until there is at least one.",
            flush=True,
        )

    def propose(self, h_values: torch.Tensor, cell: int) -> int:
        """The agent's move: greedy on H, but never a move you refused in this cell before the ones you have not."""
        return int(np.argmax(h_values.cpu().numpy() - 2.0 * self.refused[cell]))  # H is in about [0, 1]

    def __call__(
        self,
        cell: int,
        action: int,
        explore: bool,
        step: int,
        positives: int,
        h_oracle: float,
        successes: int,
    ):
        """Your answer about the move `action` from `cell`: 1.0, 0.0, or None to stop teaching."""
        how = " (exploring: a random move)" if explore else ""
        how += " into a wall: it stays where it is" if self.next_cell[cell, action] == cell else ""
        way = f"reaches G in {self.own_way} steps" if self.own_way < 200 else "does not reach G yet"
        print(
            f"\nstep {step} | answers {self.answers} | positives given {positives} | its own way from S: {way} | "
            f"walks to G in time: {successes}\n"
            + gridworld_env.draw_maze(self.variant, agent=cell, arrows={cell: action})
            + f"the agent moves {gridworld_env.ACTION_NAMES[action]}{how}",
            flush=True,
        )
        while True:
            print("good move? [y / Enter / q] ", end="", flush=True)
            with StopSignals.waiting():  # Ctrl-C while you think stops the run at once
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

    def greedy_length(self) -> int:
        return gridworld_env.greedy_episode_length(greedy_actions(self.h_net, self.device), self.variant)

    def learn(self, h_optimizer, buffer: ReplayBuffer, updates: int, batch_size: int) -> torch.Tensor:
        """TAMER's update (Eq. 1) after your answer: several gradient steps, each on the newest answer and a replay of
        the earlier ones (Deep TAMER's remedies), so that the answer takes effect before the next move."""
        for _ in range(updates):
            replay = torch.randint(0, buffer.size, (batch_size - 1,), device=self.device)
            newest = torch.tensor([buffer.size - 1], device=self.device)
            obs_b, actions_b, _, feedback_b, _ = buffer.batch(torch.cat([newest, replay]))
            h_loss = tamer_loss(self.h_net, obs_b, actions_b, feedback_b)
            h_optimizer.zero_grad()
            h_loss.backward()
            h_optimizer.step()
        self.own_way = self.greedy_length()
        if self.own_way < 200 and self.answers_to_goal is None:
            self.answers_to_goal = self.answers
        return h_loss

    def finish(self, steps: int, positives: int, successes: int):
        then = "now the agent sleeps" if successes else "the agent did not walk from S to G in time, so it cannot sleep"
        print(
            f"\nthank you: {steps} steps taught, {positives} positives given ({self.agreement} of "
            f"{self.answers} answers as the oracle's, Eq. 4); {then}",
            flush=True,
        )


def draw_greedy_path(policy: np.ndarray, variant: str) -> str:
    """A greedy table policy's path from S drawn on the maze, and where it ends."""
    next_cell = gridworld_env.transition_table(variant)
    cell = gridworld_env.START
    arrows = {}
    while cell != gridworld_env.GOAL and cell not in arrows:  # a deterministic path either ends in G or loops
        arrows[cell] = int(policy[cell])
        cell = int(next_cell[cell, policy[cell]])
    ending = (
        f"reaches G in {len(arrows)} steps"
        if cell == gridworld_env.GOAL
        else "never reaches G: it goes round in a loop or bumps into a wall"
    )
    return gridworld_env.draw_maze(variant, agent=gridworld_env.START, arrows=arrows) + ending


def reward_figure(table: np.ndarray, title: str):
    """The recovered reward drawn over the maze: each free cell split into four triangles, one per action."""
    fig = Figure(figsize=(6, 6))
    ax = fig.subplots()
    visited = np.arange(gridworld_env.N_CELLS) != gridworld_env.GOAL  # the agent never acts in G (terminal)
    lim = max(float(np.abs(table[visited]).max()), 1e-8)
    cmap = matplotlib.colormaps["coolwarm"]
    norm = matplotlib.colors.Normalize(-lim, lim)
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


# ---------------------------------------------------------------------------------------------------------------------
# TRY NOT TO MODIFY: plumbing. Progress lines, checkpoints, saved days, input checks, signals and the run's end,
# --evaluate, videos


class Progress:
    """One line per ~5% of a phase: steps, SPS and ETA, plus whatever the phase reports. The clock stops while the
    `evaluator` runs. The first line comes early (`warmup` + 500 steps), and the ETA counts only the steps after
    `warmup` (random-action steps before learning starts are much faster than the rest)."""

    def __init__(self, phase: str, total: int, warmup: int = 0, evaluator=None):
        self.phase = phase
        self.total = total
        self.every = max(total // 20, 1)
        self.warmup = min(warmup, total)
        self.early = min(warmup + 500, total)
        self.evaluator = evaluator
        self.start = self.clock()
        self.warm_start = None

    def clock(self) -> float:
        """Seconds, without those spent in evaluations."""
        return time.time() - (self.evaluator.seconds if self.evaluator is not None else 0.0)

    def sps(self, step: int) -> float:
        return step / max(self.clock() - self.start, 1e-9)

    def __call__(self, step: int, **info):
        if step == self.warmup:
            self.warm_start = self.clock()
        if step % self.every == 0 or step == self.total or step == self.early:
            sps = self.sps(step)
            rate = sps
            if self.warm_start is not None and step > self.warmup:
                rate = (step - self.warmup) / max(self.clock() - self.warm_start, 1e-9)
            eta = (self.total - step) / max(rate, 1e-9)
            info = {k: v for k, v in info.items() if v is not None and v == v}  # not measured yet: not shown (nan)
            extra = "".join(f" | {k} {v:.4g}" if isinstance(v, float) else f" | {k} {v}" for k, v in info.items())
            print(
                f"[{self.phase}] {step}/{self.total} {100 * step // self.total}% | {sps:,.0f} SPS | "
                f"ETA {int(eta // 60)}m{int(eta % 60):02d}s{extra}",
                flush=True,
            )


def read_checkpoint(path: str, flag: str, env_id: str | None) -> dict:
    """The checkpoint `flag` names (--oracle-path, --evaluate, --sleep-from), read with torch.load(weights_only=True):
    tensors and plain values only, never code; if it names an env, that must be `env_id` (None: any). Every way it
    can fail is one InputError naming the flag and the file."""
    where = f"{flag} {path}"
    if not os.path.isfile(path):
        raise InputError(f"{where}: no such file")
    if not zipfile.is_zipfile(path):  # torch.save writes a zip archive; a truncated one has lost its directory
        raise InputError(f"{where}: not a torch checkpoint, or a truncated one (not a complete zip archive)")
    try:
        ckpt = torch.load(path, weights_only=True, map_location="cpu")
    except pickle.UnpicklingError as e:
        unsupported = [line.strip() for line in str(e).splitlines() if "unsupported" in line.lower()]
        raise InputError(
            f"{where}: refused, it holds more than tensors and plain values (it could run code): "
            f"{(unsupported or [type(e).__name__])[0][:160]}"
        ) from None
    except Exception as e:  # a damaged archive: torch raises RuntimeError, EOFError, ...
        raise InputError(
            f"{where}: corrupt checkpoint: {(str(e).strip() or type(e).__name__).splitlines()[0][:160]}"
        ) from None
    if not isinstance(ckpt, dict):
        raise InputError(f"{where}: not a checkpoint of this project (expected a dict, found {type(ckpt).__name__})")
    if env_id is not None and "env_id" in ckpt and ckpt["env_id"] != env_id:
        raise InputError(f"{where}: made for {ckpt['env_id']!r}, not for --env-id {env_id}")
    return ckpt


def load_oracle(path: str, env_id: str) -> np.ndarray:
    """The maze teacher's Q table from an oracle_train.py checkpoint, checked against the env and its shapes."""
    ckpt = read_checkpoint(path, "--oracle-path", None)  # what it is, then which maze (below)
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
        raise InputError(
            f"{path}: q_table has shape {shape}, expected ({gridworld_env.N_CELLS}, {gridworld_env.N_ACTIONS})"
        )
    return q_table.double().numpy()


def load_q_network(path: str, n_states: int = 30, flag: str = "--evaluate") -> QNetwork:
    """Rebuild a saved H or Q network (tamer_h.pt, inform_q.pt) from its state_dict and arguments; it must read
    `n_states`-d one-hot observations (the maze's 30 cells by default)."""
    ckpt = read_checkpoint(path, flag, None)
    if "state_dict" not in ckpt or "kwargs" not in ckpt:
        raise InputError(f"{path}: not a saved network of this script (needs 'state_dict' and 'kwargs')")
    net = QNetwork(**ckpt["kwargs"])
    try:
        net.load_state_dict(ckpt["state_dict"])
    except RuntimeError as e:
        raise InputError(f"{path}: the weights do not fit the network: {str(e).splitlines()[0][:160]}") from None
    if ckpt["kwargs"].get("obs_dim") != n_states:
        raise InputError(f"{path}: a network for {ckpt['kwargs'].get('obs_dim')}-d observations, not {n_states}-d")
    return net


def save_atomic(obj: dict, path: str) -> None:
    """torch.save to a temporary file, then rename: an interrupted save never leaves a half-written checkpoint."""
    torch.save(obj, path + ".tmp")
    os.replace(path + ".tmp", path)


def save_network(path: str, net: nn.Module, **extra) -> None:
    """A state_dict plus what rebuilds the network; torch.load(path, weights_only=True) reads it."""
    save_atomic({"state_dict": net.state_dict(), "kwargs": network_kwargs(net), **extra}, path)


def network_kwargs(net: nn.Module) -> dict:
    """QNetwork's arguments that rebuild `net`."""
    return {
        "obs_dim": net.network[0].in_features,
        "n_actions": net.network[-1].out_features,
        "hidden": net.network[0].out_features,
    }


# Saved days (--save-buffer, --sleep-from): one forward phase, many nights. day.pt holds only tensors and plain values
DAY_FORMAT = "inform-day-1"
DAY_ARGS = (  # the flags that shape the day: what the oracle, forward_phase, the Teacher and the evaluation read
    "env_id",
    "seed",
    "oracle_gamma",
    "oracle_path",
    "tamer_total_timesteps",
    "tamer_learning_starts",
    "tamer_batch_size",
    "tamer_h_lr",
    "tamer_train_frequency",
    "start_e",
    "end_e",
    "exploration_fraction",
    "feedback_alpha_start",
    "feedback_alpha_end",
    "success_max_steps",
    "teacher",
    "teacher_noise",
    "teacher_sparsity",
    "teacher_delay",
    "credit_window",
    "feedback_budget",
    "budget_ends_forward_phase",
    "human_updates_per_answer",
    "eval_frequency",
    "eval_episodes",
)
DAY_TENSORS = ("obs", "actions", "next_obs", "feedback", "terminated", "success")  # the buffer, one row a transition
EPISODE_TABLE = ("episode_start", "episode_end", "episode_length", "episode_success", "episode_ended")


def save_day(path: str, args: Args, buffer: ReplayBuffer, h_net: QNetwork, q_star: np.ndarray, day_stats: dict):
    """The day as it ended: the buffer cut to its size, the episode table (buffer[start:end], one row an episode; the
    last row, ended False, is the episode cut off by the end of the phase), the oracle's Q table, TAMER's H, the
    day's stats and flags, and the random states that the sleep goes on from. Written to a temporary name, renamed."""
    n = buffer.size
    rows = [(start, end, True) for start, end in buffer.episodes]  # (start, end, ended)
    last_end = rows[-1][1] if rows else 0
    if last_end < n:
        rows.append((last_end, n, False))
    start = torch.tensor([row[0] for row in rows], dtype=torch.int64)
    end = torch.tensor([row[1] for row in rows], dtype=torch.int64)
    np_state = np.random.get_state()
    version, internal, gauss = random.getstate()
    day = {
        "format": DAY_FORMAT,
        "script": os.path.basename(__file__),
        "env_id": args.env_id,
        "seed": args.seed,
        "day_args": {name: getattr(args, name) for name in DAY_ARGS},
        **{name: getattr(buffer, name)[:n].to("cpu", copy=True) for name in DAY_TENSORS},  # a copy: not the capacity
        "episode_start": start,
        "episode_end": end,
        "episode_length": end - start,
        "episode_success": buffer.success[:n].cpu()[start],
        "episode_ended": torch.tensor([row[2] for row in rows], dtype=torch.bool),
        "h_net": {"state_dict": {k: v.cpu() for k, v in h_net.state_dict().items()}, "kwargs": network_kwargs(h_net)},
        "q_star": torch.tensor(q_star),
        "rng": {  # the sleep and the final tests draw from torch's only; numpy's and python's are kept all the same
            "torch": torch.get_rng_state(),
            "torch_cuda": torch.cuda.get_rng_state_all() if buffer.obs.is_cuda else None,
            "numpy": [np_state[0], torch.from_numpy(np_state[1].astype(np.int64)), *np_state[2:]],
            "python": [version, list(internal), gauss],
        },
        "day_stats": day_stats,
    }
    save_atomic(day, path)


def load_day(run_dir: str, args: Args) -> dict:
    """RUN_DIR/day.pt, checked, as torch.load(weights_only=True) reads it; its day flags replace those of `args` (one
    line says so). Raises InputError before anything is written."""
    path = os.path.join(run_dir, "day.pt")
    if not os.path.isdir(run_dir):
        raise InputError(f"--sleep-from {run_dir}: no such directory")
    if not os.path.exists(path):
        raise InputError(f"--sleep-from {run_dir}: no day.pt in it (a run saves its day with --save-buffer)")
    day = read_checkpoint(path, "--sleep-from", None)
    if day.get("format") != DAY_FORMAT:
        raise InputError(f"{path}: not a saved day of this script (format {day.get('format')!r}, not {DAY_FORMAT!r})")
    try:
        check_env(str(day.get("env_id")))
    except InputError as e:
        raise InputError(f"{path}: a day on a task this script cannot run: {e}") from None
    n_states, n_actions = env_shape(day["env_id"])
    required = ("day_args", *DAY_TENSORS, *EPISODE_TABLE, "h_net", "q_star", "rng", "day_stats")
    missing = [key for key in required if key not in day]
    missing += [f"day_args.{name}" for name in DAY_ARGS if name not in day.get("day_args", {})]
    if missing:
        raise InputError(f"{path}: an incomplete saved day, no {', '.join(missing)}")
    n = day["obs"].shape[0] if isinstance(day["obs"], torch.Tensor) else -1
    episodes = day["episode_start"].shape[0] if isinstance(day["episode_start"], torch.Tensor) else -1
    shapes = {name: (n,) for name in DAY_TENSORS} | {name: (episodes,) for name in EPISODE_TABLE}
    shapes |= {"obs": (n, n_states), "next_obs": (n, n_states)}
    shapes["q_star"] = (n_states, n_actions)
    for name, shape in shapes.items():
        found = tuple(day[name].shape) if isinstance(day[name], torch.Tensor) else type(day[name]).__name__
        if found != shape:
            raise InputError(f"{path}: {name} has shape {found}, expected {shape}")
    stats = day["day_stats"]
    if not isinstance(stats, dict) or stats.get("feedback/steps") != n:
        raise InputError(f"{path}: its day_stats do not describe its {n} transitions (no feedback/steps = {n})")
    if not all(v is None or isinstance(v, bool | int | float | str) for v in stats.values()):
        raise InputError(f"{path}: its day_stats hold more than plain numbers")
    try:
        QNetwork(**day["h_net"]["kwargs"]).load_state_dict(day["h_net"]["state_dict"])
        if day["h_net"]["kwargs"]["obs_dim"] != n_states:
            raise ValueError(f"H is a network for {day['h_net']['kwargs']['obs_dim']}-d observations, not {n_states}-d")
        torch.Generator().set_state(day["rng"]["torch"])
        np.random.RandomState().set_state(numpy_state(day["rng"]))
        random.Random().setstate(python_state(day["rng"]))
    except Exception as e:  # a damaged network or random state: KeyError, TypeError, ValueError, RuntimeError
        raise InputError(f"{path}: a damaged saved day: {(str(e) or type(e).__name__).splitlines()[0][:160]}") from None
    for name in DAY_ARGS:
        setattr(args, name, day["day_args"][name])
    try:
        check_args(args)
    except (InputError, TypeError) as e:  # TypeError: a flag of the wrong type
        raise InputError(f"{path}: its day flags are not valid: {e}") from None
    print(
        f"[day] sleeping on {run_dir}'s day ({args.env_id}, seed {args.seed}, {n} steps); "
        "its day flags replace this run's",
        flush=True,
    )
    return day


def restore_day(day: dict, device: torch.device) -> tuple[np.ndarray, ReplayBuffer, QNetwork]:
    """The oracle's Q table, the buffer and H of a day from load_day; then (last: building H draws from torch) the
    random states as the day left them."""
    buffer = ReplayBuffer(day["obs"].shape[0], day["obs"].shape[1], device)
    for name in DAY_TENSORS:
        getattr(buffer, name).copy_(day[name])
    buffer.size = day["obs"].shape[0]
    ended = day["episode_ended"].tolist()
    starts, ends = day["episode_start"].tolist(), day["episode_end"].tolist()
    buffer.episodes = [(start, end) for start, end, done in zip(starts, ends, ended, strict=True) if done]
    h_net = QNetwork(**day["h_net"]["kwargs"]).to(device)
    h_net.load_state_dict(day["h_net"]["state_dict"])
    torch.set_rng_state(day["rng"]["torch"])
    if day["rng"].get("torch_cuda") is not None and device.type == "cuda":
        torch.cuda.set_rng_state_all(day["rng"]["torch_cuda"])
    np.random.set_state(numpy_state(day["rng"]))
    random.setstate(python_state(day["rng"]))
    return day["q_star"].double().numpy(), buffer, h_net


def numpy_state(rng: dict) -> tuple:
    """np.random.set_state's tuple from a saved day's list."""
    name, keys, pos, has_gauss, cached_gaussian = rng["numpy"]
    return name, keys.numpy().astype(np.uint32), int(pos), int(has_gauss), float(cached_gaussian)


def python_state(rng: dict) -> tuple:
    """random.setstate's tuple from a saved day's list."""
    version, internal, gauss = rng["python"]
    return version, tuple(internal), gauss


# The defaults that depend on who teaches: the paper's simulated teacher, or a person who answers every move
TEACHER_DEFAULTS = {
    "oracle": {"tamer_learning_starts": 1000, "start_e": 1.0, "end_e": 0.05, "log_frequency": 100},
    "human": {"tamer_learning_starts": 1, "start_e": 0.0, "end_e": 0.0, "log_frequency": 1},
}


def fill_teacher_defaults(args: Args) -> Args:
    """The flags left at None take the default of --teacher (the simulated teacher's are the paper's)."""
    for name, value in TEACHER_DEFAULTS[args.teacher].items():
        if getattr(args, name) is None:
            setattr(args, name, value)
    return args


class InputError(Exception):
    """Bad input from the user: a flag value, a file. Reported as one line, before anything is written."""


# The range of every flag that has one (InputError outside it). A flag not listed has none, so a new flag is never
# refused for its default. Counts start at 1 unless 0 means something.
RANGES = {
    **dict.fromkeys(
        (
            "num_threads",
            "tamer_total_timesteps",
            "tamer_learning_starts",
            "tamer_batch_size",
            "tamer_train_frequency",
            "success_max_steps",
            "credit_window",
            "feedback_budget",
            "human_updates_per_answer",
            "sleep_gradient_steps",
            "sleep_batch_size",
            "eval_frequency",
            "sleep_eval_frequency",
            "eval_episodes",
            "log_frequency",
        ),
        "[1, inf)",
    ),
    **dict.fromkeys(("seed", "teacher_delay", "sleep_seed"), "[0, inf)"),
    **dict.fromkeys(
        (
            "tamer_h_lr",
            "exploration_fraction",
            "sleep_q_lr",
            "sleep_temperature",
        ),
        "(0, inf)",
    ),
    "sleep_chi2_coef": "[0, inf)",
    "tau": "(0, 1]",
    **dict.fromkeys(
        (
            "feedback_alpha_start",
            "feedback_alpha_end",
            "start_e",
            "end_e",
            "sleep_gamma",
            "oracle_gamma",
            "teacher_noise",
            "teacher_sparsity",
        ),
        "[0, 1]",
    ),
}


def in_range(value: float, interval: str) -> bool:
    """Whether `value` lies in an interval written as "[0, 1]", "(0, inf)", ...; NaN never does."""
    low, high = (float(bound) for bound in interval[1:-1].split(", "))
    above = value >= low if interval[0] == "[" else value > low
    below = value <= high if interval[-1] == "]" else value < high
    return above and below


def check_args(args: Args) -> None:
    """What tyro cannot know: ranges, the env id, flags that exclude each other. Raises InputError."""
    if args.track and importlib.util.find_spec("wandb") is None:
        raise InputError("--track needs Weights & Biases: `pip install wandb`, or run without --track")
    fill_teacher_defaults(args)
    for f in fields(args):
        value = getattr(args, f.name)
        interval = RANGES.get(f.name)
        if interval is not None and value is not None and not in_range(value, interval):
            flag = "--" + f.name.replace("_", "-")
            counts = isinstance(value, int) and interval.endswith(", inf)")  # "[1, inf)": must be >= 1
            must = f"be >= {interval[1:-6]}" if counts else f"be in {interval}"
            raise InputError(f"{flag} must {must}, got {value}")
    check_env(args.env_id)
    if args.env_id not in MAZE_IDS:
        maze_only = {"--teacher human": args.teacher == "human", "--capture-video": args.capture_video}
        maze_only["--oracle-path"] = args.oracle_path is not None
        used = [flag for flag, on in maze_only.items() if on]
        if used:
            raise InputError(f"{', '.join(used)}: the maze's only (exact Q* teaches on {args.env_id}); drop it")
    if args.oracle_gamma >= 1.0:
        raise InputError("--oracle-gamma must be below 1 for value iteration to converge")
    if args.teacher == "oracle" and args.tamer_learning_starts < args.tamer_batch_size:
        raise InputError(
            f"--tamer-learning-starts ({args.tamer_learning_starts}) must be at least "
            f"--tamer-batch-size ({args.tamer_batch_size})"
        )
    if args.tamer_learning_starts >= args.tamer_total_timesteps:
        raise InputError(
            f"--tamer-learning-starts ({args.tamer_learning_starts}) must be below "
            f"--tamer-total-timesteps ({args.tamer_total_timesteps}), or H is never trained"
        )
    if args.save_buffer and args.sleep_from:
        raise InputError("--save-buffer saves a run's own day; a --sleep-from run has none (it sleeps on another's)")
    distortions = {"teacher_noise": 0.0, "teacher_sparsity": 1.0, "teacher_delay": 0, "credit_window": 1}
    changed = [f"--{k.replace('_', '-')}" for k, v in distortions.items() if getattr(args, k) != v]
    if args.teacher == "human" and changed:
        raise InputError(
            f"--teacher human takes your answers as they are; drop {', '.join(changed)} "
            "(they distort the simulated teacher only)"
        )


def check_env(env_id: str) -> None:
    """--env-id: a maze, or a Gymnasium env with discrete states and actions and a model (env.unwrapped.P)."""
    if env_id in MAZE_IDS:
        return
    try:
        env = gym.make(env_id)
    except Exception as e:  # unknown id, a missing extra, ...
        first = (str(e).strip() or type(e).__name__).splitlines()[0][:160]
        raise InputError(
            f"--env-id {env_id}: Gymnasium cannot make it ({first}); mazes: {', '.join(MAZE_IDS)}"
        ) from None
    discrete = isinstance(env.observation_space, gym.spaces.Discrete) and isinstance(
        env.action_space, gym.spaces.Discrete
    )
    has_model = isinstance(getattr(env.unwrapped, "P", None), dict)
    env.close()
    if not (discrete and has_model):
        raise InputError(
            f"--env-id {env_id}: this script needs discrete states and actions and the env's model (env.unwrapped.P, "
            "as FrozenLake-v1, CliffWalking-v1 and Taxi-v4 have); continuous tasks run in inform_sac_pusher.py"
        )


def env_shape(env_id: str) -> tuple[int, int]:  # (states, actions)
    env = make_env(env_id)
    shape = env.observation_space.shape[0], int(env.action_space.n)
    env.close()
    return shape


class Diverged(Exception):
    """The sleep loss became NaN or inf."""


class StopSignals:
    """SIGINT (Ctrl-C; unless ignored: nohup, `&`), SIGTERM (kill, Slurm) and SIGHUP (a closed terminal) stop the
    run. The handler only records the signal. `StopSignals.check()`, at the head of every loop, then raises
    KeyboardInterrupt in our own code, never inside a library call (one raised inside TensorBoard's queue put could
    leave close() waiting up to 120 s), and main catches it to save what finished. Only a wait for a person's answer
    (`waiting()`: the maze's person at the terminal), which may never come, is interrupted at once. Signals after the
    first, and any after the summary, are only noted."""

    current = None  # the run's StopSignals, which check() and waiting() read

    def __init__(self):
        self.received = []
        self.raised = False
        self.waiting_for_input = False
        self.finished = False
        self.broken_pipe = False
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            if signal.getsignal(sig) is not signal.SIG_IGN:
                signal.signal(sig, self.handler)
        StopSignals.current = self

    def handler(self, signum, frame):
        self.received.append(signal.Signals(signum).name)
        if self.waiting_for_input:
            StopSignals.check()

    @classmethod
    def check(cls) -> None:
        """KeyboardInterrupt if a stop signal came (once: main then saves what finished, and says so)."""
        stop = cls.current
        if stop is not None and stop.received and not (stop.raised or stop.finished):
            stop.raised = True
            raise KeyboardInterrupt

    @classmethod
    @contextlib.contextmanager
    def waiting(cls):
        """A wait for a person: a stop signal that comes before it or during it raises at once."""
        stop = cls.current
        if stop is None:  # none installed (the script imported, not run): a plain wait
            yield
            return
        stop.waiting_for_input = True
        try:
            cls.check()
            yield
        finally:
            stop.waiting_for_input = False

    def reason(self) -> str:
        """What stopped the run: the first signal; else SIGPIPE if the reader of our output died, else Ctrl-C."""
        return self.received[0] if self.received else "SIGPIPE" if self.broken_pipe else "SIGINT"

    def exit_code(self, status: str) -> int:
        """128 + the signal (130 SIGINT, 143 SIGTERM, 129 SIGHUP, 141 a dead reader), as a shell reports a kill;
        a signal after the summary still says the person wanted the run to stop (a shell loop then stops too)."""
        if status == "interrupted" or self.received:
            return 128 + signal.Signals[self.reason()].value
        return {"completed": 0, "diverged": 1}[status]


def say(text: str, file=None) -> None:
    """print, except that a dead reader (a broken pipe) is not an error: what follows goes to /dev/null."""
    file = file or sys.stdout
    try:
        print(text, file=file, flush=True)
    except OSError:  # BrokenPipeError, or a closed terminal
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), file.fileno())  # the exit's final flush then succeeds too


def make_run_dir(run_name: str) -> str:
    """runs/{run_name}, never an existing directory: a clash gets a numeric suffix."""
    path = f"runs/{run_name}"
    n = 0
    while True:
        try:
            os.makedirs(path)
            return path
        except FileExistsError:
            n += 1
            path = f"runs/{run_name}_{n}"


def write_json_atomic(path: str, data: dict) -> None:
    # strict JSON: a metric that does not exist in this run (e.g. no success episodes) is null, not NaN
    data = {k: None if isinstance(v, float) and not math.isfinite(v) else v for k, v in data.items()}
    with open(path + ".tmp", "w") as f:
        json.dump(data, f, indent=2, allow_nan=False)
    os.replace(path + ".tmp", path)


def end_run(args, summary, status, phase, run_dir, run_start, evaluator, closing, stop) -> dict:
    """The summary first, then the messages: no signal cuts this short (StopSignals only notes the later ones)."""
    stop.finished = True
    if run_dir is not None:
        summary = {
            **(evaluator.final if evaluator else {}),
            **summary,
            "time/eval_s": evaluator.seconds if evaluator else 0.0,
            "wall_time_s": time.time() - run_start,
            "seed": args.seed,
            "script": os.path.basename(__file__),
            "status": status,
            "args": asdict(args),
        }
        if status != "completed":
            summary["phase"] = phase
        if status == "interrupted":
            summary["signal"] = stop.reason()
        write_json_atomic(f"{run_dir}/summary.json", summary)
    for thing in (*closing, evaluator):
        if thing is not None:
            thing.close()
    if status == "interrupted":
        saved = f"what finished is saved in {run_dir}" if run_dir else "no run was made"
        say(f"interrupted ({stop.reason()}) during the {phase} phase; {saved}", sys.stderr)
    elif status == "diverged":
        say(f"error: {summary['error']}", sys.stderr)
    if run_dir is not None:
        print_results(summary, run_dir)
    summary.setdefault("status", status)
    return summary


def print_results(summary: dict, run_dir: str) -> None:
    if summary["status"] == "completed":
        lengths = {p: summary.get(f"eval/{p}_episode_length") for p in POLICIES}  # no INFORM if the sleep was skipped
        if summary["args"]["env_id"] in MAZE_IDS:
            say(
                " | ".join(f"{p}: {v:.0f} steps" for p, v in lengths.items() if v is not None)
                + f" (optimum: {OPTIMUM})"
            )
        else:  # a toy-text env: the mean over the evaluation's episodes
            say(" | ".join(f"{p}: {v:.1f} steps, success {summary[f'eval/{p}_success_rate']:.2f}"
                           for p, v in lengths.items() if v is not None))  # fmt: skip
    say(f"{summary['status']} in {summary['wall_time_s']:.1f}s; summary: {run_dir}/summary.json")


def evaluate_saved(args: Args) -> dict:
    """--evaluate: a saved tamer_h.pt or inform_q.pt, its greedy policy on the plain and wall mazes, the start set."""
    evaluator = Evaluator(args, writer=None)
    n_states = evaluator.envs["plain"].observation_space.shape[0]
    policy = greedy_actions(load_q_network(args.evaluate, n_states), torch.device("cpu"), n_states)
    metrics = evaluator("policy", policy, 0)
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
    cells = [start]
    length = 0
    terminated = False
    truncated = False
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
    canvas = FigureCanvasAgg(fig)
    ax = fig.subplots()
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
    images[0].save(path + ".tmp", format="GIF", save_all=True, append_images=images[1:], loop=0, duration=durations_ms)
    os.replace(path + ".tmp", path)


def record_videos(run_dir: str, policies: dict[str, np.ndarray]) -> dict:
    """--capture-video: each greedy table policy from S on the plain and the wall maze, and from VIDEO_START_CELLS on
    the plain maze one after the other, as videos/{policy}_{plain,wall,starts}.gif; videos/videos.json says how
    each episode ended."""
    os.makedirs(f"{run_dir}/videos", exist_ok=True)
    record = {}
    t0 = time.time()
    for name, policy in policies.items():
        episodes = [("plain", "plain", gridworld_env.START), ("wall", "wall", gridworld_env.START)]
        episodes += [("starts", "plain", start) for start in VIDEO_START_CELLS]
        frames = {}
        for clip, variant, start in episodes:
            cells, length, reached = greedy_episode(policy, variant, start)
            maze = "wall maze" if variant == "wall" else "maze"
            title = f"{name.upper()}, {maze}, from {'S' if start == gridworld_env.START else f'cell {start}'}"
            episode = maze_frames(cells, variant, title, length, reached)
            frames.setdefault(clip, []).extend(
                (frame, 1500 if t == len(episode) - 1 else 250) for t, frame in enumerate(episode)
            )  # the end is held
            record[f"{name}_{clip}_{start}"] = {
                "file": f"{name}_{clip}.gif",
                "variant": variant,
                "start_cell": start,
                "episode_length": length,
                "reached_goal": reached,
                "frames": len(cells),
            }
        for clip, timed in frames.items():
            write_gif(f"{run_dir}/videos/{name}_{clip}.gif", [f for f, _ in timed], [ms for _, ms in timed])
    write_json_atomic(f"{run_dir}/videos/videos.json", record)
    print(f"[video] {len(record)} greedy episodes drawn in {time.time() - t0:.1f}s: {run_dir}/videos/", flush=True)
    return record


if __name__ == "__main__":
    try:
        args = tyro.cli(Args)  # a malformed flag: tyro's own message, exit 2
        if gridworld_env is None:
            raise InputError(
                "gridworld_env.py (the maze) is not importable: copy it next to this script, or run from the repo"
            )
        check_args(args)
        if args.evaluate:
            print(json.dumps(evaluate_saved(args), indent=2))
            sys.exit(0)
        oracle_q = day = None
        if args.sleep_from:  # a saved day: no oracle, no forward phase; its day flags replace these
            day = load_day(args.sleep_from, args)
        elif args.oracle_path:
            oracle_q = load_oracle(args.oracle_path, args.env_id)
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    stop = StopSignals()
    summary = main(args, oracle_q, stop, day)
    gc.freeze()  # the interpreter's last collections over torch's objects take seconds on a busy machine; skip them
    sys.exit(stop.exit_code(summary.get("status", "interrupted")))
