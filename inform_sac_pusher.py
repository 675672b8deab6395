"""INFORM on MuJoCo Pusher: SAC-style TAMER learns from a simulated teacher's yes/no feedback ("day"), then offline
IQ-Learn on the remembered transitions ("sleep") gives a far-sighted policy and a recovered reward.

Tarakli & Di Nuovo, "Learning while Sleeping" (ICDL 2024): Algorithm 1, Fig. 3 and the obstacle robustness test; what
the paper leaves open is in docs/protocol.md. Every episode starts from the run's seed (the paper's protocol) unless
--random-starts. The teacher is the shipped oracles/{env_id}__sac_oracle.pt (from oracle_train.py), --oracle-path, or
a SAC agent trained here (--train-oracle). Read top to bottom down to `main`: Args, the networks, Eq. 1-4 and the
teacher, the buffer, the day, the night, main. Everything else comes after main.

Other continuous-action tasks run from their id alone (`--env-id Reacher-v5`): an episode succeeds by a final
distance that the env reports in `info` (--success-info-key, --success-distance) or by its return
(--success-return). What only Pusher has (the object's path, the obstacle test, the videos' camera) is one block
below main, skipped elsewhere, and the summary says so.

Imported by inform_utils/, the only names other code may use (a test holds it to them): Args, main, evaluate,
read_checkpoint, actor_from_checkpoint, check_video, video_env, mujoco_major, InputError, Outcome, object_xy.

    python inform_sac_pusher.py --seed 1                            # Pusher-v5, the authors' budget
    python inform_sac_pusher.py --env-id Pusher-v4 --seed 1         # the paper's Pusher (needs mujoco==2.3.7)
    python inform_sac_pusher.py --env-id Reacher-v5 --success-distance 0.02 --random-starts \
        --tamer-total-timesteps 30000                               # another task, its teacher in oracles/
"""

import atexit
import collections
import contextlib
import copy
import dataclasses
import gc
import importlib.util
import json
import math
import os
import random
import shutil
import signal
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
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
import numpy as np  # noqa: E402
import torch  # noqa: E402
import torch.nn as nn  # noqa: E402
import torch.nn.functional as F  # noqa: E402
import tyro  # noqa: E402
from torch.utils.tensorboard import SummaryWriter  # noqa: E402

PUSHER_IDS = ("Pusher-v5", "Pusher-v4")  # the paper's task; any other continuous-action env id works too
POLICIES = ("oracle", "tamer", "inform")
LOG_STD_MIN = -5.0
LOG_STD_MAX = 2.0
REPO_DIR = os.path.dirname(os.path.abspath(__file__))


@dataclass
class Args:
    exp_name: str = os.path.basename(__file__)[: -len(".py")]
    """the name of this experiment"""
    seed: int = 1
    """seed of the experiment (also the reset seed of every episode under the fixed-start protocol)"""
    torch_deterministic: bool = True
    """if toggled, `torch.backends.cudnn.deterministic=True` and deterministic algorithms"""
    cuda: bool = False
    """if toggled, use CUDA when available (these small networks are fast enough on one CPU thread)"""
    num_threads: int = 1
    """torch CPU threads"""
    capture_video: bool = False
    """film the final deterministic episode of the oracle, TAMER and INFORM, plain and with the boxes, into
    runs/{run}/videos/ (headless MuJoCo: MUJOCO_GL, egl when unset and there is no display)"""
    bf16: bool = False
    """opt-in speed: the training updates' forward passes in bfloat16 (CPU autocast); the numbers change"""
    save_model: bool = True
    """whether to save the oracle (when trained here), TAMER and INFORM networks into the run directory"""
    track: bool = False
    """if toggled, mirror the TensorBoard events to Weights & Biases (CleanRL's --track; needs `pip install wandb`,
    and WANDB_MODE=offline keeps the run on this machine)"""
    wandb_project_name: str = "inform"
    """the Weights & Biases project"""
    wandb_entity: str | None = None
    """the Weights & Biases team or user (None: your default)"""
    env_id: str = "Pusher-v5"
    """Pusher-v5 (current MuJoCo), Pusher-v4 (the paper's; needs mujoco<3), or any continuous-action Gymnasium env
    (Reacher-v5, ...; the obstacle test is Pusher's and is skipped)"""
    random_starts: bool = False
    """random initial states (the standard task) instead of the paper's fixed start (reset with the run's seed)"""
    success_distance: float = 0.08
    """an episode is a success if its final distance |info[success_info_key]| (Pusher: object to goal) is below this"""
    success_info_key: str = "reward_dist"
    """the `info` entry whose absolute value at an episode's end is its final distance (Pusher's and Reacher's
    reward_dist); envs without one need --success-return"""
    success_return: float | None = None
    """if set, an episode is a success if its return is at least this (the final distance is then only reported)"""

    # Oracle (the simulated teacher): a SAC agent trained on the environment reward
    oracle_path: str | None = None
    """oracle checkpoint from oracle_train.py; default: the shipped oracles/{env_id}__sac_oracle.pt if present"""
    train_oracle: bool = False
    """train the SAC oracle here on the environment reward (also what happens when no checkpoint is found)"""
    oracle_total_timesteps: int = 200000
    """environment steps of the in-script SAC oracle"""
    oracle_random_starts: bool = True
    """train the in-script oracle from random initial states, so it is an expert from any start"""
    oracle_learning_starts: int = 5000
    """random-action steps before the oracle learns"""
    oracle_batch_size: int = 256
    """SAC batch size of the oracle"""
    oracle_q_lr: float = 1e-3
    """learning rate of the oracle's twin critics"""
    oracle_policy_lr: float = 3e-4
    """learning rate of the oracle's actor"""
    oracle_policy_frequency: int = 2
    """oracle actor and entropy updates every this many steps"""
    oracle_gamma: float = 0.99
    """discount of the oracle's SAC"""
    hidden_size: int = 256
    """width of the two hidden layers of every network (oracle, TAMER, INFORM)"""
    tau: float = 0.005
    """soft-update rate of target networks (oracle SAC and sleep phase)"""

    # Forward phase: TAMER (Eq. 1) with simulated feedback (Eq. 4)
    tamer_total_timesteps: int = 200000
    """environment steps of the forward phase (each gets one feedback signal); 200k is the authors' budget, 30000
    the quick look"""
    tamer_learning_starts: int = 5000
    """random-action steps before H and the actor are trained"""
    tamer_batch_size: int = 256
    """batch size of the H regression and the actor update"""
    tamer_h_lr: float = 1e-3
    """learning rate of the twin feedback models H (and of TAMER's entropy coefficient)"""
    tamer_policy_lr: float = 3e-4
    """learning rate of the TAMER actor"""
    tamer_policy_frequency: int = 1
    """TAMER actor and entropy updates every this many steps"""
    feedback_alpha_start: float = 0.99
    """alpha of Eq. 4 at the start of the forward phase (1 = only the oracle's action earns +1)"""
    feedback_alpha_end: float = 0.992
    """alpha of Eq. 4 at the end of the forward phase (alpha rises linearly: the teacher gets stricter)"""

    # The teacher as a person (docs/protocol.md); the defaults are the paper's perfect, instant, tireless teacher
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

    # Sleep phase: offline IQ-Learn (Eq. 2), no environment steps
    sleep_gradient_steps: int = 5000
    """gradient steps of the sleep phase; at the 200k forward budget the measured sleep curve was best early (3% below
    the oracle after 2k steps, 8% after 5k) and drifted later (38% below at 13k): docs/pusher_notes.md"""
    sleep_batch_size: int = 256
    """transitions from the success set, and as many from the whole buffer, per step"""
    sleep_q_lr: float = 3e-4
    """learning rate of the soft Q network"""
    sleep_policy_lr: float = 5e-6
    """learning rate of the INFORM actor"""
    sleep_gamma: float = 0.99
    """discount of the sleep phase (non-myopic, unlike TAMER's 0)"""
    sleep_temperature: float = 0.01
    """fixed entropy temperature of V(s) = Q(s, a~pi) - temp * log pi(a|s)"""
    sleep_chi2_coef: float = 0.5
    """weight of the chi-squared regulariser, 1 / (4 * 0.5) as IQ-Learn; 0 turns it off"""
    sleep_init_actor_from_tamer: bool = True
    """start the INFORM actor from the TAMER actor (consolidation); False starts it from scratch"""
    sleep_actor_states: Literal["replay", "replay+expert", "expert"] = "replay"
    """the states of each batch the INFORM actor is trained on: the replay rows, both halves, or the expert rows"""
    sleep_policy_frequency: int = 1
    """the INFORM actor is updated this many times every this many gradient steps (CleanRL's delayed policy update;
    the authors' sleep: 2)"""
    sleep_loss_rows: Literal["all", "expert"] = "all"
    """the rows of Eq. 2's value and chi-squared terms: the whole batch (the paper), or the expert rows only
    (IQ-Learn's offline recipe, its `value_expert` loss)"""
    sleep_twin_critics: bool = False
    """two soft Q networks, each trained on Eq. 2, their minimum in V(s) and in the actor's objective"""
    sleep_bc_coef: float = 0.0
    """a behaviour-cloning term on the INFORM actor, TD3+BC style: the Q objective divided by mean |Q|, plus this
    weight times the squared error of the mean action on the expert rows; 0 turns it off"""
    sleep_control: Literal["none", "bc", "sham"] = "none"
    """a control in place of the INFORM actor's update, same steps: bc = behaviour cloning on the success set (the
    mean action's squared error on the expert rows); sham = TAMER's own update (H on the feedback, the actor on H),
    no consolidation. The soft Q network sleeps as usual"""
    sleep_protocol: Literal["ours", "authors"] = "ours"
    """authors: the authors' sleep in one flag: the actor from scratch, on replay + expert states, 2 updates every 2nd
    step, 100k gradient steps (their test loads the 100k-step checkpoint); it sets those flags"""
    sleep_seed: int | None = None
    """None: the sleep goes on with the random streams where the day left them; an integer re-seeds them before the
    sleep (several sleeps on one day)"""
    sleep_holdout_fraction: float = 0.0
    """hold this fraction of the day's episodes out of the sleep (split by episode, fixed by the seed) and log the
    offline criterion on them every --sleep-eval-frequency steps; the checkpoint it picks is kept and tested as
    `inform_selected`. 0: no hold-out (the default)"""

    # Saved days: one forward phase, many nights
    save_buffer: bool = False
    """write the day (memories, episode table, teacher, TAMER, random states) to runs/{run}/day.pt for --sleep-from"""
    sleep_from: str | None = None
    """run only the night and the final tests on the day saved in this run directory (by --save-buffer); the day's
    flags (env, seed, teacher, TAMER) replace this run's"""

    # Evaluation
    eval_episodes: int = 20
    """episodes of each final evaluation (deterministic and sampled actions)"""
    eval_frequency: int = 2000
    """forward-phase environment steps between evaluations of TAMER (curves like Fig. 3)"""
    sleep_eval_frequency: int = 1000
    """sleep-phase gradient steps between evaluations of INFORM"""
    periodic_eval_episodes: int = 5
    """episodes of each evaluation during the phases"""
    obstacle_episodes: int = 100
    """episodes per policy on the obstacle variant, all from the run's initial state, sampled actions"""
    obstacle_layout: Literal["bisector", "paper"] = "bisector"
    """bisector: on the bisector of the object's start and the goal, the middle box on the path; paper: the paper's"""
    authors_test_episodes: int = 100
    """episodes of the authors' test: sampled actions from the run's initial state (eval/authors_test/...)"""
    log_frequency: int = 1000
    """steps between scalar logs (losses, SPS, feedback)"""
    evaluate: str | None = None
    """re-evaluate a saved tamer_actor.pt, inform_actor.pt or oracle (and the obstacle test); print JSON, no run"""


def make_env(env_id: str, seed: int, obstacles=None, **render) -> gym.Env:
    """The env, or Pusher with the robustness test's boxes at the xy `obstacles`; `render` (--capture-video:
    render_mode, width, height) adds Pusher's videos' camera (other envs film with their own). The boxes and the
    camera are built below main."""
    if (obstacles is None and not render) or env_id not in PUSHER_IDS:
        env = gym.make(env_id, **render)
    else:
        env = pusher_with_boxes(env_id, obstacles, **render)
    env.action_space.seed(seed)
    env.observation_space.seed(seed)
    return env


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


# ---------------------------------------------------------------------------------------------------------------------
# networks: each is rebuilt from the `kwargs` saved beside its state_dict


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


# ---------------------------------------------------------------------------------------------------------------------
# the pieces of Algorithm 1, named after the paper: Eq. 1-4 and the teacher


def linear_schedule(start: float, end: float, duration: int, t: int) -> float:
    """From `start` at t = 0 to `end` at t = duration, then constant."""
    return start + (end - start) * min(t, duration) / max(duration, 1)


def oracle_feedback(q_star_sa: torch.Tensor, q_star_best: torch.Tensor, alpha: float) -> torch.Tensor:
    # Eq. 4, sign-safe: h = 1 if Q*(s, a) >= Q*(s, a*) - (1 - alpha) |Q*(s, a*)|, else 0
    return (q_star_sa >= q_star_best - (1.0 - alpha) * q_star_best.abs()).float()


def oracle_q(oracle_actor: Actor, oracle_qf: QEnsemble, obs: torch.Tensor, action: torch.Tensor):
    """Q*(s, a) of the learner's action and Q*(s, a*) of the oracle's mean action a* (min of the twin critics)."""
    _, _, a_star = oracle_actor.get_action(obs.unsqueeze(0))  # it draws a sample too: part of the seeded stream
    q_star = oracle_qf(obs.expand(2, -1), torch.stack([action, a_star[0]])).min(0).values
    return q_star[0], q_star[1]


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


def tamer_loss(h_net: QEnsemble, obs: torch.Tensor, actions: torch.Tensor, feedback: torch.Tensor) -> torch.Tensor:
    # Eq. 1: E[(H(s, a) - h)^2], gamma = 0: no bootstrapping, no target network; summed over the twin H models
    return (h_net(obs, actions) - feedback.unsqueeze(0)).pow(2).mean(-1).sum()


def soft_value(q_net: QEnsemble, actor: Actor, obs: torch.Tensor, temperature: float, generator=None):
    """V(s) = Q(s, a~pi) - temp * log pi(a|s), one sample (continuous IQ-Learn)."""
    with torch.no_grad():
        action, log_prob, _ = actor.get_action(obs, generator)
    return q_net(obs, action).min(0).values - temperature * log_prob


# ALGO LOGIC: the sleep loss. The maze script's signature and return, plus the actor that V(s) needs here, and the
# rows of the value and chi-squared terms (IQ-Learn's offline recipe takes the expert rows only).
def iq_loss(
    q_net, target_net, obs, actions, next_obs, terminated, is_expert, gamma, temperature, chi2_coef, actor, rows=None
):
    # Eq. 2 (to minimise): y = (1 - done) gamma V_target(s');
    # L = -E_success[Q(s,a) - y] + E_all[V(s) - y] + chi2 * E_all[(Q(s,a) - y)^2]
    # each of the n soft Q networks (twins: n = 2) is trained on it; V(s) takes their minimum
    rows = slice(None) if rows is None else rows
    q_sa = q_net(obs, actions)
    with torch.no_grad():
        y = (1.0 - terminated) * gamma * soft_value(target_net, actor, next_obs, temperature)
    v_s = soft_value(q_net, actor, obs, temperature)
    expert_term = -(q_sa - y)[:, is_expert].mean(-1).sum()
    value_term = (v_s - y)[rows].mean()
    chi2_term = chi2_coef * (q_sa - y)[:, rows].pow(2).mean(-1).sum()
    terms = {"iq_expert_term": expert_term, "iq_value_term": value_term, "iq_chi2_term": chi2_term}
    return sum(terms.values()), terms  # the total and its named terms: the sleep logs whatever terms come back


def recover_reward(q_sa: torch.Tensor, v_next: torch.Tensor, terminated: torch.Tensor, gamma: float) -> torch.Tensor:
    # Eq. 3: r(s, a, s') = Q(s, a) - (1 - terminated) gamma V(s')
    return q_sa - (1.0 - terminated) * gamma * v_next


def actor_loss(q_net: QEnsemble, actor: Actor, obs: torch.Tensor, temperature: torch.Tensor | float):
    """SAC-style actor objective, to minimise: E[temp * log pi(a|s) - min_i Q_i(s, a~pi)]; also returns log pi."""
    action, log_prob, _ = actor.get_action(obs)
    return (temperature * log_prob - q_net(obs, action).min(0).values).mean(), log_prob


def update_actor(q_net, actor, obs, log_ent_coef, actor_optimizer, ent_coef_optimizer, bf16: bool = False) -> None:
    """One SAC actor step on min_i Q_i (the oracle's critics, or TAMER's H), then one of the autotuned entropy
    coefficient exp(log_ent_coef) towards SAC's target entropy, -dim(A)."""
    q_net.requires_grad_(False)  # the gradient flows through the critic to the action, but none is kept on it
    with torch.autocast(obs.device.type, dtype=torch.bfloat16, enabled=bf16):
        pi_loss, logp = actor_loss(q_net, actor, obs, log_ent_coef.detach().exp())
    actor_optimizer.zero_grad(set_to_none=True)
    pi_loss.backward()
    q_net.requires_grad_(True)
    actor_optimizer.step()
    target_entropy = -float(actor.fc_mean.out_features)
    ent_coef_loss = (-log_ent_coef.exp() * (logp.detach() + target_entropy)).mean()
    ent_coef_optimizer.zero_grad(set_to_none=True)
    ent_coef_loss.backward()
    ent_coef_optimizer.step()


class ReplayBuffer:
    """Every forward-phase transition (s, a, s', h, terminated), preallocated, and the success tag of its episode."""

    def __init__(self, capacity: int, obs_dim: int, act_dim: int, device: torch.device):
        self.obs = torch.zeros(capacity, obs_dim, device=device)
        self.next_obs = torch.zeros(capacity, obs_dim, device=device)
        self.actions = torch.zeros(capacity, act_dim, device=device)
        self.feedback = torch.zeros(capacity, device=device)  # h, written by the teacher when a signal arrives
        self.terminated = torch.zeros(capacity, device=device)
        self.success = torch.zeros(capacity, dtype=torch.bool, device=device)
        self.episodes: list[tuple[int, int, float]] = []  # (first step, end step, shortfall: see Outcome)
        self.size = 0  # transitions stored (fewer than the capacity when the teacher's budget ends the day early)

    def add(self, obs, action, next_obs, terminated) -> None:
        self.obs[self.size] = obs
        self.actions[self.size] = action
        self.next_obs[self.size] = next_obs
        self.terminated[self.size] = float(terminated)
        self.size += 1

    def tag_episode(self, start: int, shortfall: float, success: bool) -> None:
        """Tag the trajectory buffer[start:size], which just ended, with its Outcome."""
        self.success[start : self.size] = success
        self.episodes.append((start, self.size, shortfall))

    def successes(self) -> int:  # episodes tagged success
        return sum(bool(self.success[start]) for start, _, _ in self.episodes)

    def batch(self, idx: torch.Tensor):
        return self.obs[idx], self.actions[idx], self.next_obs[idx], self.feedback[idx], self.terminated[idx]

    def expert_indices(
        self, keep: torch.Tensor | None = None, fallback_fraction: float = 0.1
    ) -> tuple[torch.Tensor, int]:
        """The success set's transitions and 0; with no success, the transitions of the episodes with the smallest
        shortfall (ended closest to the goal) and how many episodes those are. Only transitions in `keep` (a mask;
        None: all) count: a held-out episode is never an expert."""
        keep = torch.ones(self.size, dtype=torch.bool, device=self.success.device) if keep is None else keep
        idx = (self.success[: self.size] & keep).nonzero().squeeze(-1)
        if idx.numel() > 0:
            return idx, 0
        episodes = [e for e in self.episodes if keep[e[0]]]
        k = max(1, int(len(episodes) * fallback_fraction))
        closest = sorted(episodes, key=lambda e: e[2])[:k]
        return torch.cat([torch.arange(s, e, device=self.success.device) for s, e, _ in closest]), k


# ---------------------------------------------------------------------------------------------------------------------
# the phases of Algorithm 1, then main


def forward_phase(args: Args, env, oracle_actor, oracle_qf, buffer: ReplayBuffer, evaluator, writer, device):
    """The day: SAC-style TAMER (Eq. 1, gamma = 0) on the teacher's yes/no feedback (Eq. 4), all remembered."""
    obs_dim = buffer.obs.shape[1]
    act_dim = buffer.actions.shape[1]
    h_net = QEnsemble(obs_dim, act_dim, args.hidden_size, n=2).to(device)
    tamer_actor = Actor(obs_dim, act_dim, args.hidden_size, env.action_space.low, env.action_space.high).to(device)
    amp = torch.autocast(device.type, dtype=torch.bfloat16, enabled=args.bf16)  # --bf16; off, it changes nothing
    h_optimizer = torch.optim.Adam(h_net.parameters(), lr=args.tamer_h_lr, foreach=True)
    actor_optimizer = torch.optim.Adam(tamer_actor.parameters(), lr=args.tamer_policy_lr, foreach=True)
    log_ent_coef = torch.zeros(1, device=device, requires_grad=True)  # the actor's entropy coefficient, autotuned
    ent_coef_optimizer = torch.optim.Adam([log_ent_coef], lr=args.tamer_h_lr, foreach=True)
    teacher = Teacher.from_args(args)
    outcome = Outcome.from_args(args)
    n = args.tamer_total_timesteps
    print(f"[tamer] {n} env steps, feedback alpha {args.feedback_alpha_start} -> {args.feedback_alpha_end}", flush=True)
    progress = Progress("tamer", n, warmup=args.tamer_learning_starts, evaluator=evaluator)
    reset_seed = None if args.random_starts else args.seed
    obs, _ = env.reset(seed=args.seed)
    obs_t = torch.as_tensor(obs, dtype=torch.float32, device=device)
    h_loss = torch.zeros((), device=device)
    ep_start = ep_length = 0
    ep_return = 0.0
    last_return = float("nan")
    for step in range(n):
        StopSignals.check()  # a stop signal ends the run here, between two steps
        # the teacher gets stricter: alpha rises linearly over the phase
        feedback_alpha = linear_schedule(args.feedback_alpha_start, args.feedback_alpha_end, n - 1, step)
        if step < args.tamer_learning_starts:
            action_t = torch.as_tensor(env.action_space.sample(), device=device)
        else:
            with torch.no_grad():
                action_t = tamer_actor.get_action(obs_t.unsqueeze(0))[0][0]

        # ALGO LOGIC: the teacher watches (s, a): the perfect answer (Eq. 4), then the person's (Teacher)
        taught = not teacher.gone  # after the budget is spent, TAMER has nothing to learn from
        with torch.no_grad():
            q_star_sa, q_star_best = oracle_q(oracle_actor, oracle_qf, obs_t, action_t)
        h_star = oracle_feedback(q_star_sa, q_star_best, feedback_alpha).item() if taught else 0.0
        labels = teacher(step, h_star)  # {transition: h} that this step's arriving signal labels
        buffer.feedback[list(labels)] = torch.tensor(list(labels.values()), device=device)

        next_obs, reward, terminated, truncated, info = env.step(action_t.cpu().numpy())
        next_t = torch.as_tensor(next_obs, dtype=torch.float32, device=device)
        buffer.add(obs_t, action_t, next_t, terminated)
        ep_return += float(reward)
        ep_length += 1
        last_step = step == n - 1 or (teacher.gone and args.budget_ends_forward_phase)
        if terminated or truncated or last_step:  # tag the trajectory; a cut-off last one by where it stands
            distance, success, shortfall = outcome(info, ep_return)
            buffer.tag_episode(ep_start, shortfall, success)
            writer.add_scalar("charts/episodic_return", ep_return, step + 1)
            writer.add_scalar("charts/episodic_length", ep_length, step + 1)
            if not math.isnan(distance):
                writer.add_scalar("charts/final_distance", distance, step + 1)
            writer.add_scalar("charts/episode_success", float(success), step + 1)
            last_return = ep_return
            ep_start = step + 1
            ep_return = 0.0
            ep_length = 0
            next_obs, _ = env.reset(seed=reset_seed)
            next_t = torch.as_tensor(next_obs, dtype=torch.float32, device=device)
        obs_t = next_t

        # ALGO LOGIC: TAMER's update: H regresses on the feedback (Eq. 1), the actor maximises H, SAC-style
        if step >= args.tamer_learning_starts and taught:
            idx = torch.randint(0, step + 1, (args.tamer_batch_size,), device=device)
            obs_b = buffer.obs[idx]
            with amp:
                h_loss = tamer_loss(h_net, obs_b, buffer.actions[idx], buffer.feedback[idx])
            h_optimizer.zero_grad(set_to_none=True)
            h_loss.backward()
            h_optimizer.step()
            if step % args.tamer_policy_frequency == 0:
                update_actor(h_net, tamer_actor, obs_b, log_ent_coef, actor_optimizer, ent_coef_optimizer, args.bf16)

        # TRY NOT TO MODIFY: logging and periodic evaluation
        if (step + 1) % args.log_frequency == 0 or last_step:
            writer.add_scalar("losses/tamer_loss", h_loss.item(), step + 1)
            writer.add_scalar("losses/tamer_entropy_coef", log_ent_coef.exp().item(), step + 1)
            writer.add_scalar("feedback/positive", teacher.positives, step + 1)
            writer.add_scalar("feedback/positive_rate", teacher.positives / (step + 1), step + 1)
            writer.add_scalar("feedback/alpha", feedback_alpha, step + 1)
            writer.add_scalar("charts/SPS", progress.sps(step + 1), step + 1)
        report = {"return": last_return}
        if (step + 1) % args.eval_frequency == 0 or last_step:
            metrics = evaluator("tamer", tamer_actor, step + 1, args.periodic_eval_episodes)
            report["eval return"] = metrics["eval/tamer_return"]
        progress(step + 1, **report)
        if last_step:
            break

    successes = buffer.successes()
    print(
        f"[tamer] feedback +1 on {teacher.positives}/{buffer.size} steps ({teacher.positives / buffer.size:.1%}); "
        f"{successes}/{len(buffer.episodes)} episodes tagged success",
        flush=True,
    )
    stats = {
        "feedback/positive": teacher.positives,
        "feedback/perfect_positive": teacher.perfect_positives,
        "feedback/steps": buffer.size,
        "feedback/positive_rate": teacher.positives / buffer.size,
        "sleep/success_episodes": int(successes),
        "sleep/episodes": len(buffer.episodes),
        "losses/tamer_entropy_coef": log_ent_coef.exp().item(),
    }
    return h_net, tamer_actor, stats


def sleep_phase(
    args: Args, buffer: ReplayBuffer, tamer_actor: Actor, evaluator, writer, device, h_net=None, ent_coef=1.0
):
    """The night: offline IQ-Learn (Eq. 2) on the buffer, the successful trajectories as the expert set. TAMER's H and
    entropy coefficient at the day's end are needed only by the sham control. Returns the soft Q, the INFORM actor,
    the stats and, with a hold-out, the checkpoint the offline criterion picked (else None)."""
    held = held_out(args, buffer, device)  # --sleep-holdout-fraction: episodes the sleep never sees
    keep = torch.ones(buffer.size, dtype=torch.bool, device=device)
    if held is not None:
        keep[held] = False
    replay_idx = keep.nonzero().squeeze(-1)
    expert_idx, fallback_episodes = buffer.expert_indices(keep)
    if fallback_episodes:
        print(
            f"[sleep] warning: no successful episode; using the {fallback_episodes} episodes that came closest "
            "(the smallest final distance, or with --success-return the highest return) as the expert set",
            flush=True,
        )
    print(f"[sleep] {expert_idx.numel()} expert transitions, {replay_idx.numel()} in the buffer", flush=True)
    obs_dim = buffer.obs.shape[1]
    act_dim = buffer.actions.shape[1]
    n_critics = 2 if args.sleep_twin_critics else 1
    q_net = QEnsemble(obs_dim, act_dim, args.hidden_size, n=n_critics).to(device)
    q_target = QEnsemble(obs_dim, act_dim, args.hidden_size, n=n_critics).to(device)
    q_target.load_state_dict(q_net.state_dict())
    low = tamer_actor.action_bias - tamer_actor.action_scale
    high = tamer_actor.action_bias + tamer_actor.action_scale
    inform_actor = Actor(obs_dim, act_dim, args.hidden_size, low, high).to(device)
    if args.sleep_init_actor_from_tamer or args.sleep_control == "sham":
        inform_actor.load_state_dict(tamer_actor.state_dict())
    amp = torch.autocast(device.type, dtype=torch.bfloat16, enabled=args.bf16)  # --bf16; off, it changes nothing
    q_optimizer = torch.optim.Adam(q_net.parameters(), lr=args.sleep_q_lr, foreach=True)
    policy_lr = args.tamer_policy_lr if args.sleep_control == "sham" else args.sleep_policy_lr
    inform_optimizer = torch.optim.Adam(inform_actor.parameters(), lr=policy_lr, foreach=True)
    if args.sleep_control == "sham":  # TAMER goes on learning from its memories: H and the actor, TAMER's rates
        sham_h = QEnsemble(obs_dim, act_dim, args.hidden_size, n=2).to(device)
        sham_h.load_state_dict(h_net.state_dict())
        sham_h_optimizer = torch.optim.Adam(sham_h.parameters(), lr=args.tamer_h_lr, foreach=True)
        log_ent_coef = torch.full((1,), math.log(ent_coef), device=device, requires_grad=True)
        ent_coef_optimizer = torch.optim.Adam([log_ent_coef], lr=args.tamer_h_lr, foreach=True)
    batch_size = args.sleep_batch_size
    gamma = args.sleep_gamma
    temp = args.sleep_temperature
    chi2 = args.sleep_chi2_coef
    is_expert = torch.arange(2 * batch_size, device=device) >= batch_size  # the batch: replay rows, then expert rows
    rows = is_expert if args.sleep_loss_rows == "expert" else None  # of the value and chi2 terms
    actor_rows = {"replay": ~is_expert, "expert": is_expert, "replay+expert": slice(None)}[args.sleep_actor_states]
    stats = {"sleep/expert_transitions": int(expert_idx.numel()), "sleep/expert_fallback": int(fallback_episodes > 0)}
    losses = {}
    criterion = OfflineCriterion(args, buffer, held, writer) if held is not None else None
    pi_loss = torch.zeros((), device=device)
    progress = Progress("sleep", args.sleep_gradient_steps, evaluator=evaluator)
    for step in range(1, args.sleep_gradient_steps + 1):
        StopSignals.check()
        # ALGO LOGIC: the sleep update: Q by IQ-Learn (Eq. 2), the INFORM actor on Q, the target Q follows softly
        replay = replay_idx[torch.randint(0, replay_idx.numel(), (batch_size,), device=device)]
        expert = expert_idx[torch.randint(0, expert_idx.numel(), (batch_size,), device=device)]
        obs, actions, next_obs, feedback, terminated = buffer.batch(torch.cat([replay, expert]))
        with amp:
            loss, terms = iq_loss(
                q_net, q_target, obs, actions, next_obs, terminated, is_expert, gamma, temp, chi2, inform_actor, rows
            )
        q_optimizer.zero_grad(set_to_none=True)
        loss.backward()
        q_optimizer.step()
        for _ in range(args.sleep_policy_frequency if step % args.sleep_policy_frequency == 0 else 0):
            if args.sleep_control == "sham":  # control: TAMER's own update (Eq. 1, then its actor on H), no Q
                with amp:
                    pi_loss = tamer_loss(sham_h, obs[~is_expert], actions[~is_expert], feedback[~is_expert])
                sham_h_optimizer.zero_grad(set_to_none=True)
                pi_loss.backward()
                sham_h_optimizer.step()
                update_actor(
                    sham_h, inform_actor, obs[~is_expert], log_ent_coef, inform_optimizer, ent_coef_optimizer, args.bf16
                )
                continue
            q_net.requires_grad_(False)  # the actor's gradient flows through Q, but none is kept on it
            with amp:
                if args.sleep_control == "bc":  # control: behaviour cloning on the success set, no Q
                    pi_loss = (inform_actor.get_action(obs[is_expert])[2] - actions[is_expert]).pow(2).mean()
                else:
                    pi_loss, _ = actor_loss(q_net, inform_actor, obs[actor_rows], temp)
                if args.sleep_bc_coef > 0:  # TD3+BC: the Q objective made scale-free, plus cloning the experts
                    pi_loss = (
                        pi_loss / q_net(obs, actions).abs().mean().detach()
                        + args.sleep_bc_coef
                        * (inform_actor.get_action(obs[is_expert])[2] - actions[is_expert]).pow(2).mean()
                    )
            inform_optimizer.zero_grad(set_to_none=True)
            pi_loss.backward()
            q_net.requires_grad_(True)
            inform_optimizer.step()
        soft_update(q_target, q_net, args.tau)

        # TRY NOT TO MODIFY: logging (one host sync per 100 steps to catch divergence) and periodic evaluation
        last_step = step == args.sleep_gradient_steps
        log_now = step % args.log_frequency == 0 or last_step
        if log_now or step % 100 == 0:
            tags = {"iq_loss": loss, **terms, "inform_actor_loss": pi_loss}
            values = torch.stack(list(tags.values())).tolist()
            if not all(map(math.isfinite, values)):
                last = ", ".join(f"{k.split('/')[1]} {v:.4g}" for k, v in losses.items())
                raise Diverged(
                    f"the sleep loss diverged (NaN or inf) by gradient step {step}; last finite losses: "
                    f"{last or 'none yet'}; try a lower --sleep-q-lr or --sleep-policy-lr"
                )
            losses = {f"losses/{tag}": value for tag, value in zip(tags, values, strict=True)}
        if log_now:
            for tag, value in losses.items():
                writer.add_scalar(tag, value, step)
            writer.add_scalar("sleep/SPS", progress.sps(step), step)
        report = {"iq_loss": losses.get("losses/iq_loss")}
        if step % args.sleep_eval_frequency == 0 or last_step:
            metrics = evaluator("inform", inform_actor, step, args.periodic_eval_episodes)
            report["eval return"] = metrics["eval/inform_return"]
            if criterion is not None:  # no environment: the held-out episodes only
                report["criterion"] = criterion(step, q_net, q_target, inform_actor)
        progress(step, **report)
    selected = None
    if criterion is not None:
        stats.update(criterion.stats())
        selected = criterion.selected
    return q_net, inform_actor, {**stats, **losses}, selected


def main(args: Args, oracle_ckpt: dict | None, stop: "StopSignals", day: dict | None = None) -> dict:
    run_name = f"{args.env_id}__{args.exp_name}__{args.seed}__{int(time.time())}"
    run_start = time.time()
    run_dir = writer = env = evaluator = None
    summary = {"time/oracle_s": 0.0, "time/tamer_s": 0.0, "time/sleep_s": 0.0}
    oracle_ckpt = day["oracle"] if day is not None else oracle_ckpt  # --sleep-from: the saved day's teacher
    summary["oracle_path"] = oracle_ckpt["path"] if oracle_ckpt is not None else None
    summary["sleep_from"] = os.path.abspath(args.sleep_from) if day is not None else None
    summary["sleep_variant"] = sleep_variant(args)
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
        env = make_env(args.env_id, args.seed)
        evaluator = Evaluator(args, writer)
        obs_dim = int(np.prod(env.observation_space.shape))
        act_dim = int(np.prod(env.action_space.shape))

        # ---- oracle: the simulated teacher (docs/protocol.md, "Oracles and the expert bar")
        phase = "oracle"
        t0 = time.time()
        if oracle_ckpt is not None:
            oracle_actor, oracle_qf = oracle_from_checkpoint(oracle_ckpt, device)
            steps = oracle_ckpt.get("training_steps", "?")
            print(f"[oracle] loaded {oracle_ckpt['path']} ({steps} SAC steps)", flush=True)
        else:
            print(f"[oracle] training SAC on the env reward for {args.oracle_total_timesteps} steps", flush=True)
            oracle_actor, oracle_qf, summary["sps/oracle"] = train_oracle(args, writer, device)
            if args.save_model:
                save_oracle(f"{run_dir}/oracle.pt", args, oracle_actor, oracle_qf, env.action_space)
        oracle_actor.requires_grad_(False)
        oracle_qf.requires_grad_(False)
        summary["time/oracle_s"] = time.time() - t0
        evaluator("oracle", oracle_actor, 0, args.periodic_eval_episodes)

        # ---- forward phase ("day"): TAMER with simulated feedback, every transition remembered
        phase = "tamer"
        t0 = time.time() - evaluator.seconds  # the phase's clock stops during its evaluations
        buffer = ReplayBuffer(args.tamer_total_timesteps, obs_dim, act_dim, device)
        if day is None:
            h_net, tamer_actor, stats = forward_phase(
                args, env, oracle_actor, oracle_qf, buffer, evaluator, writer, device
            )
        else:  # --sleep-from: the saved day's memories and TAMER, and the random streams where the day left them
            h_net, tamer_actor, stats = restore_day(day, buffer, evaluator, device)
        summary["time/tamer_s"] = time.time() - evaluator.seconds - t0
        summary["sps/tamer"] = stats["feedback/steps"] / max(summary["time/tamer_s"], 1e-9)
        summary.update(stats)  # a saved day's stats bring the day's own time
        if args.save_model:
            save_actor(f"{run_dir}/tamer_actor.pt", tamer_actor, env_id=args.env_id)
            save_critic(f"{run_dir}/tamer_h.pt", h_net, obs_dim, act_dim, env_id=args.env_id)
        if args.save_buffer:
            day_networks = (oracle_ckpt, oracle_actor, oracle_qf, h_net, tamer_actor)
            day_stats = {**stats, "time/tamer_s": summary["time/tamer_s"], "sps/tamer": summary["sps/tamer"]}
            save_day(f"{run_dir}/day.pt", args, buffer, day_networks, day_stats, evaluator)

        # ---- sleep phase ("night"): offline IQ-Learn on the buffer, no environment steps
        phase = "sleep"
        t0 = time.time() - evaluator.seconds
        if args.sleep_seed is not None:  # another night on the same day
            torch.manual_seed(args.sleep_seed)
        q_net, inform_actor, stats, selected = sleep_phase(
            args, buffer, tamer_actor, evaluator, writer, device, h_net, stats["losses/tamer_entropy_coef"]
        )
        summary.update(stats)
        summary["time/sleep_s"] = time.time() - evaluator.seconds - t0
        summary["sps/sleep"] = args.sleep_gradient_steps / max(summary["time/sleep_s"], 1e-9)
        if args.save_model:
            save_actor(f"{run_dir}/inform_actor.pt", inform_actor, env_id=args.env_id)
            extra = {"gamma": args.sleep_gamma, "temperature": args.sleep_temperature}
            save_critic(f"{run_dir}/inform_critic.pt", q_net, obs_dim, act_dim, env_id=args.env_id, **extra)
            if selected is not None:  # the checkpoint the offline criterion picked, beside the last one
                save_actor(f"{run_dir}/inform_selected_actor.pt", selected["actor"], env_id=args.env_id)

        # ---- the recovered reward (Eq. 3), then the final evaluation and the obstacle robustness test
        phase = "eval"
        policies = {"oracle": oracle_actor, "tamer": tamer_actor, "inform": inform_actor}
        if selected is not None:
            policies["inform_selected"] = selected["actor"]
        summary.update(final_evaluation(args, buffer, q_net, policies, evaluator, writer, run_dir))
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
# ALGO LOGIC, below main: the evaluation protocol and the rest of the research code. The tests (deterministic and
# sampled, the authors'), the offline checkpoint choice, the oracle's own SAC, the recovered reward (Eq. 3) as an
# object and a Gymnasium wrapper; then Pusher's own pieces (the obstacle test and its model)


@torch.no_grad()
def evaluate(actor: Actor, env: gym.Env, episodes: int, reset_seed, deterministic: bool, generator, outcome: Outcome):
    """Run `episodes` episodes; reset_seed(ep) gives each episode's reset seed. Returns means and per-episode data,
    each episode's observations included."""
    returns = []
    distances = []
    successes = []
    trajectories = []
    for ep in range(episodes):
        StopSignals.check()
        obs, _ = env.reset(seed=reset_seed(ep))
        done = False
        ep_return = 0.0
        info = {}
        trajectory = [obs]
        while not done:
            sampled, _, mean = actor.get_action(torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0), generator)
            obs, reward, terminated, truncated, info = env.step((mean if deterministic else sampled)[0].numpy())
            ep_return = ep_return + float(reward)
            done = terminated or truncated
            trajectory.append(obs)
        distance, success, _ = outcome(info, ep_return)
        returns.append(ep_return)
        distances.append(distance)
        successes.append(success)
        trajectories.append(np.array(trajectory))
    distances = np.asarray(distances)
    return {
        "return": float(np.mean(returns)),
        "final_distance": float(distances.mean()),
        "final_distance_std": float(distances.std()),
        "success_rate": float(np.mean(successes)),
        "distances": distances,
        "returns": np.asarray(returns),
        "trajectories": trajectories,
    }


class Evaluator:
    """Evaluates a policy on the plain env with deterministic and sampled actions; logs and keeps eval/{name}_*.
    Episodes start from the run's seed (fixed start) or from fresh seeds (`--random-starts`), the same each time."""

    def __init__(self, args: Args, writer: SummaryWriter | None):
        self.env = make_env(args.env_id, args.seed)
        self.generator = torch.Generator().manual_seed(args.seed + 12345)  # sampled actions, off the training RNG
        self.writer = writer
        self.seed = args.seed
        self.random_starts = args.random_starts
        self.outcome = Outcome.from_args(args)
        self.seconds = 0.0  # spent evaluating
        self.final = {}  # the latest value of each tag

    def reset_seed(self, episode: int) -> int:
        return 1_000_000 + 1000 * self.seed + episode if self.random_starts else self.seed

    def __call__(self, name: str, actor: Actor, step: int, episodes: int) -> dict:
        t = time.time()
        results = {}
        for deterministic, suffix in ((True, ""), (False, "_sampled")):
            res = evaluate(actor, self.env, episodes, self.reset_seed, deterministic, self.generator, self.outcome)
            results.update({f"eval/{name}_{k}{suffix}": res[k] for k in ("return", "final_distance", "success_rate")})
        if self.writer is not None:
            for tag, value in results.items():
                self.writer.add_scalar(tag, value, step)
        self.final.update(results)
        self.seconds += time.time() - t
        return results

    def close(self):
        self.env.close()


def final_evaluation(args: Args, buffer, q_net, policies: dict, evaluator, writer, run_dir: str) -> dict:
    """After the sleep: Eq. 3 on the buffer, each policy's final evaluation, the obstacle test (Pusher only) and the
    authors' test (all logged at the run's last step), the obstacle files and, with --capture-video, the videos."""
    results = recovered_reward_stats(args, buffer, q_net, policies["inform"])
    end_step = args.tamer_total_timesteps + args.sleep_gradient_steps
    print("[eval] final evaluation", flush=True)
    for name, actor in policies.items():
        evaluator(name, actor, end_step, args.eval_episodes)
    t = time.time()
    boxes = None
    skipped = obstacle_skipped(args)
    if skipped:
        results["obstacle/skipped"] = skipped
    else:
        obstacle, distances, paths = obstacle_test(args, policies, evaluator.generator)
        results.update(obstacle)
        np.savez(f"{run_dir}/obstacle_distances.npz", **distances)
        np.savez(f"{run_dir}/obstacle_paths.npz", **paths)
        boxes = paths["boxes"]
    if args.authors_test_episodes > 0:
        results.update(authors_test(args, policies, evaluator.generator))
    for tag, value in results.items():
        if tag.startswith(("eval/obstacle/", "eval/authors_test/", "obstacle/min")):
            writer.add_scalar(tag, value, end_step)
    evaluator.seconds += time.time() - t
    if args.capture_video:  # after every number is in: filming changes none of them
        record_videos(args, policies, boxes, evaluator.reset_seed(0), run_dir)
    return results


def recovered_reward_stats(args: Args, buffer: ReplayBuffer, q_net: QEnsemble, inform_actor: Actor) -> dict:
    """Eq. 3 on the buffer: the mean recovered reward of success and of failure transitions, for the record."""
    reward_fn = RecoveredReward(q_net, inform_actor, args.sleep_gamma, args.sleep_temperature, samples=4)
    b = [x[: buffer.size].cpu().numpy() for x in (buffer.obs, buffer.actions, buffer.next_obs, buffer.terminated)]
    r_all = reward_fn(*b)
    succ = buffer.success[: buffer.size].cpu().numpy()
    return {
        "sleep/recovered_reward_success_mean": float(r_all[succ].mean()) if succ.any() else float("nan"),
        "sleep/recovered_reward_failure_mean": float(r_all[~succ].mean()) if (~succ).any() else float("nan"),
    }


def held_out(args: Args, buffer: ReplayBuffer, device) -> torch.Tensor | None:
    """The transitions of --sleep-holdout-fraction of the day's episodes, drawn by the seed (None: no hold-out)."""
    if args.sleep_holdout_fraction == 0:
        return None
    n = len(buffer.episodes)
    k = min(n - 1, max(1, round(args.sleep_holdout_fraction * n)))
    chosen = torch.randperm(n, generator=torch.Generator().manual_seed(args.seed + 15)).tolist()[:k]
    return torch.cat([torch.arange(*buffer.episodes[i][:2], device=device) for i in sorted(chosen)])


def auc(scores: torch.Tensor, positive: torch.Tensor) -> float:
    """The probability that a positive scores above a negative, ties counted half (Mann-Whitney U); NaN without both."""
    from scipy.stats import rankdata

    n_pos = int(positive.sum())
    n_neg = positive.numel() - n_pos
    if n_pos == 0 or n_neg == 0:
        return float("nan")
    ranks = rankdata(scores.float().cpu().numpy())
    return float((ranks[positive.cpu().numpy()].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


class OfflineCriterion:
    """Choosing the sleep's checkpoint without the environment: on the held-out episodes, every evaluation of the sleep
    logs the expert log-likelihood (mean log pi(a|s) of the held-out success transitions), the IQ-Learn terms, the drift
    of Q(s, a~pi) and the AUC with which the recovered reward (Eq. 3) separates success from failure transitions. The
    criterion, fixed before any test return was seen: the highest expert log-likelihood picks the checkpoint."""

    def __init__(self, args: Args, buffer: ReplayBuffer, held: torch.Tensor, writer):
        self.args = args
        self.writer = writer
        self.batch = buffer.batch(held)
        self.success = buffer.success[held]
        starts = torch.tensor([start for start, _, _ in buffer.episodes], device=held.device)
        self.episodes = int(torch.isin(starts, held).sum())
        self.best = -math.inf
        self.selected = None  # {"step", "actor"} of the best checkpoint so far
        self.last = {}
        self.q_pi_previous = None

    @torch.no_grad()
    def __call__(self, step: int, q_net: QEnsemble, q_target: QEnsemble, actor: Actor) -> float:
        args = self.args
        obs, actions, next_obs, _, terminated = self.batch
        cuda = obs.device.type == "cuda"
        with torch.random.fork_rng(devices=[torch.cuda.current_device()] if cuda else []):  # the sleep's RNG untouched
            expert = self.success.nonzero().squeeze(-1)
            loglik = actor.log_prob(obs[expert], actions[expert]).mean().item() if expert.numel() else float("nan")
            rows = self.success if args.sleep_loss_rows == "expert" else None
            gamma = args.sleep_gamma
            temp = args.sleep_temperature
            chi2 = args.sleep_chi2_coef
            loss, terms = iq_loss(
                q_net, q_target, obs, actions, next_obs, terminated, self.success, gamma, temp, chi2, actor, rows
            )
            q_pi = q_net(obs, actor.get_action(obs)[0]).min(0).values.mean().item()
            v_next = soft_value(q_net, actor, next_obs, temp)
            reward = recover_reward(q_net(obs, actions).min(0).values, v_next, terminated, gamma)
        values = {
            "holdout/expert_loglik": loglik,
            "holdout/iq_loss": loss.item(),
            **{f"holdout/{name}": term.item() for name, term in terms.items()},
            "holdout/q_pi": q_pi,
            "holdout/reward_auc": auc(reward, self.success),
        }
        if self.q_pi_previous is not None:  # per 1,000 gradient steps
            values["holdout/q_pi_drift"] = (q_pi - self.q_pi_previous[1]) * 1000 / (step - self.q_pi_previous[0])
        self.q_pi_previous = (step, q_pi)
        for tag, value in values.items():
            self.writer.add_scalar(tag, value, step)
        self.last = values
        if math.isfinite(loglik) and loglik > self.best:
            self.best = loglik
            self.selected = {"step": step, "actor": copy.deepcopy(actor)}
        return loglik

    def stats(self) -> dict:
        return {
            **self.last,
            "holdout/episodes": self.episodes,
            "holdout/transitions": int(self.success.numel()),
            "holdout/success_transitions": int(self.success.sum()),
            "holdout/selected_step": self.selected["step"] if self.selected else None,
            "holdout/selected_expert_loglik": self.best if self.selected else None,
        }


def authors_test(args: Args, policies: dict, generator: torch.Generator) -> dict:
    """The authors' test: sampled actions, every episode from the run's initial state, on the plain env."""
    env = make_env(args.env_id, args.seed)
    outcome = Outcome.from_args(args)
    results = {}
    for name, actor in policies.items():
        res = evaluate(actor, env, args.authors_test_episodes, lambda ep: args.seed, False, generator, outcome)
        for key in ("return", "final_distance", "success_rate"):
            results[f"eval/authors_test/{name}_{key}"] = res[key]
    env.close()
    return results


# the oracle: SAC on the environment reward (oracle_train.py runs the same SAC; a test keeps the two identical)
def train_oracle(args: Args, writer: SummaryWriter, device: torch.device):
    """SAC on the environment reward (CleanRL's, with the twin critics as one module): the simulated teacher."""
    env = make_env(args.env_id, args.seed)
    obs_dim = int(np.prod(env.observation_space.shape))
    act_dim = int(np.prod(env.action_space.shape))
    actor = Actor(obs_dim, act_dim, args.hidden_size, env.action_space.low, env.action_space.high).to(device)
    qf = QEnsemble(obs_dim, act_dim, args.hidden_size, n=2).to(device)
    qf_target = QEnsemble(obs_dim, act_dim, args.hidden_size, n=2).to(device)
    qf_target.load_state_dict(qf.state_dict())
    amp = torch.autocast(device.type, dtype=torch.bfloat16, enabled=args.bf16)  # --bf16; off, it changes nothing
    q_optimizer = torch.optim.Adam(qf.parameters(), lr=args.oracle_q_lr, foreach=True)
    actor_optimizer = torch.optim.Adam(actor.parameters(), lr=args.oracle_policy_lr, foreach=True)
    log_ent_coef = torch.zeros(1, device=device, requires_grad=True)  # SAC's entropy coefficient, autotuned
    ent_coef_optimizer = torch.optim.Adam([log_ent_coef], lr=args.oracle_q_lr, foreach=True)
    n = args.oracle_total_timesteps
    b_obs = torch.zeros(n, obs_dim, device=device)
    b_next = torch.zeros(n, obs_dim, device=device)
    b_act = torch.zeros(n, act_dim, device=device)
    b_rew = torch.zeros(n, device=device)
    b_term = torch.zeros(n)
    progress = Progress("oracle", n, warmup=args.oracle_learning_starts)
    reset_seed = None if args.oracle_random_starts else args.seed
    obs, _ = env.reset(seed=args.seed)
    obs_t = torch.as_tensor(obs, dtype=torch.float32, device=device)
    ep_return = 0.0
    last_return = float("nan")
    outcome = Outcome.from_args(args)
    for step in range(n):
        StopSignals.check()
        if step < args.oracle_learning_starts:
            action = env.action_space.sample()
        else:
            with torch.no_grad():
                action = actor.get_action(obs_t.unsqueeze(0))[0][0].cpu().numpy()
        next_obs, reward, terminated, truncated, info = env.step(action)
        next_t = torch.as_tensor(next_obs, dtype=torch.float32, device=device)
        b_obs[step] = obs_t
        b_next[step] = next_t
        b_act[step] = torch.as_tensor(action)
        b_rew[step] = float(reward)
        b_term[step] = float(terminated)
        ep_return += float(reward)
        if terminated or truncated:
            writer.add_scalar("oracle/episodic_return", ep_return, step)
            distance = outcome(info, ep_return)[0]
            if not math.isnan(distance):
                writer.add_scalar("oracle/final_distance", distance, step)
            last_return = ep_return
            ep_return = 0.0
            next_obs, _ = env.reset(seed=reset_seed)
            next_t = torch.as_tensor(next_obs, dtype=torch.float32, device=device)
        obs_t = next_t
        if step >= args.oracle_learning_starts:
            idx = torch.randint(0, step + 1, (args.oracle_batch_size,), device=device)
            obs_b = b_obs[idx]
            next_b = b_next[idx]
            with amp, torch.no_grad():
                next_a, next_logp, _ = actor.get_action(next_b)
                v_next = qf_target(next_b, next_a).min(0).values - log_ent_coef.detach().exp() * next_logp
                target = b_rew[idx] + (1.0 - b_term[idx]) * args.oracle_gamma * v_next
            with amp:
                q_loss = (qf(obs_b, b_act[idx]) - target.unsqueeze(0)).pow(2).mean(-1).sum()
            q_optimizer.zero_grad(set_to_none=True)
            q_loss.backward()
            q_optimizer.step()
            if step % args.oracle_policy_frequency == 0:
                update_actor(qf, actor, obs_b, log_ent_coef, actor_optimizer, ent_coef_optimizer, args.bf16)
            soft_update(qf_target, qf, args.tau)
            if (step + 1) % args.log_frequency == 0:
                writer.add_scalar("oracle/qf_loss", q_loss.item(), step + 1)
                writer.add_scalar("oracle/SPS", progress.sps(step + 1), step + 1)
        progress(step + 1, **{"return": last_return})
    env.close()
    return actor, qf, n / max(time.time() - progress.start, 1e-9)


class RecoveredReward:
    """The reward INFORM recovers (Eq. 3), imitation-style: reward(obs, action, next_obs, terminated) -> array.
    V(s') is averaged over `samples` actions drawn with a fixed generator, so the reward is deterministic."""

    def __init__(self, q_net: QEnsemble, actor: Actor, gamma: float, temperature: float, samples: int = 16):
        self.q_net = q_net
        self.actor = actor
        self.gamma = gamma
        self.temperature = temperature
        self.samples = samples

    @classmethod
    def load(cls, run_dir: str, samples: int = 16) -> "RecoveredReward":  # from a run's inform_critic.pt and actor
        critic = torch.load(os.path.join(run_dir, "inform_critic.pt"), weights_only=True)
        q_net = QEnsemble(**critic["kwargs"])
        q_net.load_state_dict(critic["state_dict"])
        actor = actor_from_checkpoint(torch.load(os.path.join(run_dir, "inform_actor.pt"), weights_only=True))
        return cls(q_net, actor, critic["gamma"], critic["temperature"], samples)

    @torch.no_grad()
    def __call__(self, obs, action, next_obs, terminated) -> np.ndarray:
        obs_t = torch.as_tensor(np.asarray(obs), dtype=torch.float32)
        obs_t = obs_t if obs_t.ndim == 2 else obs_t.unsqueeze(0)
        act_t = torch.as_tensor(np.asarray(action), dtype=torch.float32).reshape(obs_t.shape[0], -1)
        next_t = torch.as_tensor(np.asarray(next_obs), dtype=torch.float32).reshape(obs_t.shape)
        term_t = torch.as_tensor(np.asarray(terminated), dtype=torch.float32).reshape(-1)
        g = torch.Generator().manual_seed(0)
        v_next = torch.stack(
            [soft_value(self.q_net, self.actor, next_t, self.temperature, g) for _ in range(self.samples)]
        ).mean(0)
        return recover_reward(self.q_net(obs_t, act_t).min(0).values, v_next, term_t, self.gamma).numpy()


class RecoveredRewardWrapper(gym.Wrapper):
    """Any Gymnasium agent trains on the recovered reward; the env's own goes to info['env_reward']."""

    def __init__(self, env: gym.Env, reward_fn: RecoveredReward):
        super().__init__(env)
        self.reward_fn = reward_fn
        self._obs = None

    def reset(self, **kwargs):
        self._obs, info = self.env.reset(**kwargs)
        return self._obs, info

    def step(self, action):
        next_obs, reward, terminated, truncated, info = self.env.step(action)
        new_reward = float(self.reward_fn(self._obs, action, next_obs, terminated)[0])
        self._obs = next_obs
        return next_obs, new_reward, terminated, truncated, {**info, "env_reward": reward}


# ---------------------------------------------------------------------------------------------------------------------
# PUSHER ONLY: the object's and the goal's coordinates, the obstacle test and its model, the videos' camera. On any
# other --env-id the obstacle test is skipped (the summary says so) and videos use the env's own camera.


def object_xy(obs: np.ndarray) -> np.ndarray:  # the object's xy in Pusher's observation (also along a trajectory)
    return obs[..., 17:19]


def obstacle_skipped(args: Args) -> str | None:
    """Why the obstacle test does not run, or None when it does."""
    if args.env_id not in PUSHER_IDS:
        return f"the obstacle test is Pusher's; {args.env_id} has none"
    if args.obstacle_episodes == 0:
        return "--obstacle-episodes 0"
    return None


def obstacle_test(args: Args, policies: dict, generator: torch.Generator) -> tuple[dict, dict, dict]:
    """The robustness test: each policy on the obstacle variant, every episode from the run's initial state, sampled
    actions. Returns the metrics, the final distances, and the object's xy path of one deterministic episode per
    policy with and without the boxes (Fig. 5a)."""
    start, goal = start_and_goal(args.env_id, args.seed)
    boxes = obstacle_positions(args.obstacle_layout, start, goal)
    results = {
        "obstacle/box_positions": boxes.round(4).tolist(),
        "obstacle/min_box_distance_to_path": min(distance_to_segment(b, start, goal) for b in boxes),
    }
    distances = {}
    paths = {"boxes": boxes, "start": start, "goal": goal}
    env = make_env(args.env_id, args.seed, obstacles=boxes)
    plain = make_env(args.env_id, args.seed)
    at_start = lambda episode: args.seed  # noqa: E731
    outcome = Outcome.from_args(args)
    for name, actor in policies.items():
        res = evaluate(actor, env, args.obstacle_episodes, at_start, False, generator, outcome)
        det = evaluate(actor, env, 1, at_start, True, generator, outcome)
        det_plain = evaluate(actor, plain, 1, at_start, True, torch.Generator(), outcome)
        paths[f"{name}_obstacle"] = object_xy(det["trajectories"][0])
        paths[f"{name}_plain"] = object_xy(det_plain["trajectories"][0])
        distances[name] = res["distances"]
        for key in ("final_distance", "final_distance_std", "success_rate", "return"):
            results[f"eval/obstacle/{name}_{key}"] = res[key]
        results[f"eval/obstacle/{name}_final_distance_deterministic"] = det["final_distance"]
    env.close()
    plain.close()
    return results, distances, paths


# the robustness test's three 3 cm cubes on the table (docs/protocol.md): the paper's positions (layout "paper"), the
# paper's distance between neighbouring boxes (kept by layout "bisector"), their half-size and height
OBSTACLE_POSITIONS = ((0.32, -0.20), (0.35, -0.23), (0.38, -0.26))
OBSTACLE_SPACING = 0.0424
OBSTACLE_HALF_SIZE = 0.015
OBSTACLE_Z = -0.325
OBSTACLE_LAYOUTS = ("bisector", "paper")


def pusher_with_boxes(env_id: str, obstacles, **render) -> gym.Env:
    """Pusher's own model plus the boxes at the xy `obstacles` (None: none) and, with `render`, the videos' camera."""
    if render:
        render = {**render, "camera_name": "inform_video"}
    xml = obstacle_xml(env_id, obstacles, camera=bool(render))
    if env_id == "Pusher-v5":
        return gym.make(env_id, xml_file=xml, **render)
    # Pusher-v4 has no xml_file argument: the same class, with the model file swapped at construction
    from gymnasium.envs.mujoco.mujoco_env import MujocoEnv
    from gymnasium.envs.mujoco.pusher_v4 import PusherEnv

    space = gym.spaces.Box(-np.inf, np.inf, (23,), np.float64)

    class PusherObstacleV4(PusherEnv):
        def __init__(self, **kwargs):
            gym.utils.EzPickle.__init__(self, **kwargs)
            MujocoEnv.__init__(self, xml, 5, observation_space=space, **kwargs)

    return gym.wrappers.TimeLimit(PusherObstacleV4(**render), max_episode_steps=100)


_OBSTACLE_DIR: list[str] = []  # one temporary directory per process, removed at exit


def obstacle_xml(env_id: str, positions, camera: bool = False) -> str:
    """Pusher's own model (never modified) plus the boxes (and the videos' camera), written to a file that outlives
    the env's construction (EzPickle re-creates the env from it); returns its path."""
    import gymnasium.envs.mujoco as gym_mujoco

    name = "pusher_v5.xml" if env_id == "Pusher-v5" else "pusher.xml"
    tree = ET.parse(os.path.join(os.path.dirname(gym_mujoco.__file__), "assets", name))
    h = OBSTACLE_HALF_SIZE
    for i, (x, y) in enumerate(() if positions is None else positions):
        ET.SubElement(
            tree.getroot().find("worldbody"),
            "geom",
            {
                "name": f"obstacle_{i}",
                "type": "box",
                "size": f"{h} {h} {h}",
                "pos": f"{x:.6f} {y:.6f} {OBSTACLE_Z}",
                "contype": "1",
                "conaffinity": "1",
                "rgba": "0.2 0.2 0.8 1",
            },
        )
    if camera:  # the videos' camera, and no shadows: they triple the time of a frame in software OpenGL
        ET.SubElement(tree.getroot().find("worldbody"), "camera", video_camera())
        ET.SubElement(ET.SubElement(tree.getroot(), "visual"), "quality", {"shadowsize": "0"})
    if not _OBSTACLE_DIR:
        _OBSTACLE_DIR.append(tempfile.mkdtemp(prefix="inform_pusher_obstacle_"))
        atexit.register(shutil.rmtree, _OBSTACLE_DIR[0], True)
    fd, path = tempfile.mkstemp(
        prefix=f"{env_id.lower().replace('-', '_')}_obstacle_", suffix=".xml", dir=_OBSTACLE_DIR[0]
    )
    os.close(fd)
    tree.write(path)
    return path


def start_and_goal(env_id: str, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The object's and the goal's xy after a reset with `seed` (obs[17:19] and obs[20:22])."""
    env = gym.make(env_id)
    obs, _ = env.reset(seed=seed)
    env.close()
    return object_xy(obs).copy(), obs[20:22].copy()


def obstacle_positions(layout: str, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """The three box centres (3 x 2): the paper's coordinates, or the middle box at the midpoint of the object's start
    and the goal and the other two OBSTACLE_SPACING either side of it along the perpendicular bisector."""
    if layout == "paper":
        return np.array(OBSTACLE_POSITIONS)
    middle = (start + goal) / 2
    along = (goal - start) / np.linalg.norm(goal - start)
    across = np.array([-along[1], along[0]])
    return np.stack([middle - OBSTACLE_SPACING * across, middle, middle + OBSTACLE_SPACING * across])


def distance_to_segment(point: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    t = np.clip(np.dot(point - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
    return float(np.linalg.norm(point - (a + t * (b - a))))


# the videos' camera (--capture-video): a fixed camera added to the model (mujoco 2.3.7 cannot set a free camera's
# lookat) looks down on the table from behind the goal: arm, object (white), goal (red), boxes (blue)
VIDEO_CAMERA = {"lookat": (0.42, -0.2, -0.3), "distance": 1.0, "elevation": -75.0}  # metres, degrees


def video_camera() -> dict:
    """The camera's MJCF attributes: VIDEO_CAMERA's distance from its lookat, seen from +x (image up is -x)."""
    x, y, z = VIDEO_CAMERA["lookat"]
    d = VIDEO_CAMERA["distance"]
    el = math.radians(VIDEO_CAMERA["elevation"])
    pos = f"{x + d * math.cos(el):.4f} {y} {z - d * math.sin(el):.4f}"
    xyaxes = f"0 1 0 {math.sin(el):.4f} 0 {math.cos(el):.4f}"
    return {"name": "inform_video", "mode": "fixed", "pos": pos, "xyaxes": xyaxes}


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


def env_shapes(env_id: str) -> tuple[int, int]:
    env = gym.make(env_id)
    shapes = int(np.prod(env.observation_space.shape)), int(np.prod(env.action_space.shape))
    env.close()
    return shapes


def read_checkpoint(path: str, flag: str, env_id: str) -> dict:
    """An oracle (--oracle-path) or a saved actor (--evaluate: tamer_actor.pt, inform_actor.pt or an oracle) that fits
    env_id, read with torch.load(weights_only=True): tensors and plain values only, never code. InputError otherwise."""
    if not os.path.isfile(path):
        hint = " (train one with oracle_train.py)" if flag == "--oracle-path" else ""
        raise InputError(f"{flag} {path}: no such file{hint}")
    try:
        ckpt = torch.load(path, weights_only=True, map_location="cpu")
    except Exception as e:
        message = f"cannot be read as a weights-only torch checkpoint ({type(e).__name__})"
        raise InputError(f"{flag} {path}: {message}") from None
    oracle = flag == "--oracle-path"
    networks = (
        ("actor_state_dict", "qf_state_dict")
        if oracle
        else ("actor_state_dict" if "actor_state_dict" in ckpt else "state_dict",)
    )
    required = ("env_id", "kwargs", *networks, "action_low", "action_high")
    if not isinstance(ckpt, dict) or any(k not in ckpt for k in required) or not isinstance(ckpt["kwargs"], dict):
        raise InputError(
            f"{flag} {path}: not an {'oracle' if oracle else 'actor'} checkpoint (needs keys {', '.join(required)})"
        )
    if ckpt["env_id"] != env_id:
        raise InputError(f"{flag} {path}: trained on {ckpt['env_id']}, not {env_id}; pass --env-id")
    kw = ckpt["kwargs"]
    obs_dim, act_dim = env_shapes(env_id)
    if (kw.get("obs_dim"), kw.get("act_dim")) != (obs_dim, act_dim):
        raise InputError(
            f"{flag} {path}: shapes obs {kw.get('obs_dim')} act {kw.get('act_dim')} do not match "
            f"{env_id} (obs {obs_dim}, act {act_dim})"
        )
    try:
        oracle_from_checkpoint(ckpt, torch.device("cpu")) if oracle else actor_from_checkpoint(ckpt)
    except Exception as e:
        raise InputError(
            f"{flag} {path}: the networks do not load ({type(e).__name__}: {' '.join(str(e).split())[:100]})"
        ) from None
    return ckpt


def oracle_from_checkpoint(ckpt: dict, device: torch.device) -> tuple[Actor, QEnsemble]:
    kw = ckpt["kwargs"]
    actor = Actor(kw["obs_dim"], kw["act_dim"], kw["hidden"], ckpt["action_low"], ckpt["action_high"]).to(device)
    actor.load_state_dict(ckpt["actor_state_dict"])
    qf = QEnsemble(kw["obs_dim"], kw["act_dim"], kw["hidden"], n=2).to(device)
    qf.load_state_dict(ckpt["qf_state_dict"])
    return actor, qf


def actor_from_checkpoint(ckpt: dict) -> Actor:  # a saved actor, or an oracle's
    kw = ckpt["kwargs"]
    actor = Actor(kw["obs_dim"], kw["act_dim"], kw["hidden"], ckpt["action_low"], ckpt["action_high"])
    actor.load_state_dict(ckpt["actor_state_dict" if "actor_state_dict" in ckpt else "state_dict"])
    return actor


def shipped_oracle_paths(env_id: str) -> list[str]:
    """Where the shipped teacher may be: beside the script (a clone) and under the working directory (a copy)."""
    name = os.path.join("oracles", f"{env_id}__sac_oracle.pt")
    return list(dict.fromkeys([os.path.join(REPO_DIR, name), os.path.abspath(name)]))


def load_oracle(args: Args) -> dict | None:
    """The oracle checkpoint to use (--oracle-path, else the shipped one), or None to train one here."""
    path = args.oracle_path
    if path is None and not args.train_oracle:
        path = next((p for p in shipped_oracle_paths(args.env_id) if os.path.isfile(p)), None)
        if path is None:  # a copied script: say so before an hour of training starts
            print(
                f"[oracle] no shipped teacher found (looked for {' and '.join(shipped_oracle_paths(args.env_id))}); "
                f"training one here for {args.oracle_total_timesteps} env steps, about "
                f"{args.oracle_total_timesteps / 100 / 60:.0f} min on one core at ~100 steps/s. To skip this, pass "
                "--oracle-path PATH (a checkpoint of oracle_train.py, e.g. the repo's oracles/), or --train-oracle "
                "to silence this note",
                file=sys.stderr,
                flush=True,
            )
    if path is not None:
        return {**read_checkpoint(path, "--oracle-path", args.env_id), "path": path}
    if args.oracle_batch_size > args.oracle_total_timesteps:
        raise InputError(
            f"--oracle-batch-size ({args.oracle_batch_size}) exceeds --oracle-total-timesteps "
            f"({args.oracle_total_timesteps})"
        )
    if args.oracle_learning_starts >= args.oracle_total_timesteps:
        raise InputError(
            f"--oracle-learning-starts ({args.oracle_learning_starts}) must be below "
            f"--oracle-total-timesteps ({args.oracle_total_timesteps})"
        )
    return None


def save_atomic(obj: dict, path: str) -> None:
    """torch.save to a temporary file, then rename: an interrupted save never leaves a half-written checkpoint."""
    torch.save(obj, path + ".tmp")
    os.replace(path + ".tmp", path)


def state_dict_cpu(net: nn.Module) -> dict:
    return {k: v.detach().cpu().clone() for k, v in net.state_dict().items()}


def save_actor(path: str, actor: Actor, **extra) -> None:
    kwargs = {"obs_dim": actor.fc1.in_features, "act_dim": actor.fc_mean.out_features, "hidden": actor.fc1.out_features}
    low = (actor.action_bias - actor.action_scale).cpu()
    high = (actor.action_bias + actor.action_scale).cpu()
    save_atomic(
        {"state_dict": state_dict_cpu(actor), "kwargs": kwargs, "action_low": low, "action_high": high, **extra}, path
    )


def save_critic(path: str, q_net: QEnsemble, obs_dim: int, act_dim: int, **extra) -> None:
    kwargs = {"obs_dim": obs_dim, "act_dim": act_dim, "hidden": q_net.fc1.weight.shape[2], "n": q_net.n}
    save_atomic({"state_dict": state_dict_cpu(q_net), "kwargs": kwargs, **extra}, path)


def save_oracle(path: str, args: Args, actor: Actor, qf: QEnsemble, action_space: gym.spaces.Box) -> None:
    save_atomic(oracle_checkpoint(args, actor, qf, action_space.low, action_space.high), path)


def oracle_checkpoint(args: Args, actor: Actor, qf: QEnsemble, action_low, action_high) -> dict:
    """oracle_train.py's format, so --oracle-path loads either."""
    obs_dim = actor.fc1.in_features
    act_dim = actor.fc_mean.out_features
    return {
        "algorithm": "sac",
        "env_id": args.env_id,
        "obs_shape": [obs_dim],
        "act_shape": [act_dim],
        "kwargs": {"obs_dim": obs_dim, "act_dim": act_dim, "hidden": args.hidden_size},
        "action_low": torch.as_tensor(action_low),
        "action_high": torch.as_tensor(action_high),
        "actor_state_dict": state_dict_cpu(actor),
        "qf_state_dict": state_dict_cpu(qf),
        "training_steps": args.oracle_total_timesteps,
        "training_seed": args.seed,
        "random_starts": args.oracle_random_starts,
    }


# saved days (--save-buffer, --sleep-from): a day is deterministic, so it is saved once and slept on many times
DAY_FORMAT = "inform-day-2"
DAY_FIELDS = ("env_id", "seed", "random_starts", "train_oracle", "hidden_size", "eval_frequency", "credit_window")
DAY_FIELDS += ("budget_ends_forward_phase", "success_distance", "success_info_key", "success_return")
DAY_PREFIXES = ("oracle_", "tamer_", "feedback_", "teacher_")
DAY_TENSORS = ("obs", "actions", "next_obs", "feedback", "terminated", "success")


def day_fields(args: Args) -> dict:
    """The flags that shape the day: the env, the seed, the teacher and TAMER."""
    return {
        f.name: getattr(args, f.name) for f in fields(args) if f.name in DAY_FIELDS or f.name.startswith(DAY_PREFIXES)
    }


def save_day(path: str, args: Args, buffer: ReplayBuffer, networks: tuple, stats: dict, evaluator) -> None:
    """The day as plain tensors and values (torch.load(weights_only=True) reads it): the memories, the episode table,
    the teacher, TAMER's H and actor, the day's stats and the random states the night goes on from."""
    oracle_ckpt, oracle_actor, oracle_qf, h_net, tamer_actor = networks
    if oracle_ckpt is None:  # trained here: the same format as oracle_train.py's
        low = tamer_actor.action_bias - tamer_actor.action_scale
        high = tamer_actor.action_bias + tamer_actor.action_scale
        oracle_ckpt = oracle_checkpoint(args, oracle_actor, oracle_qf, low.cpu(), high.cpu())
    n = buffer.size
    day = {key: getattr(buffer, key)[:n].cpu().clone() for key in DAY_TENSORS}
    starts, ends, shortfalls = zip(*buffer.episodes, strict=True)
    day.update(
        format=DAY_FORMAT,
        script=os.path.basename(__file__),
        env_id=args.env_id,
        seed=args.seed,
        day_args=day_fields(args),
        day_stats=stats,
        episode_start=torch.tensor(starts, dtype=torch.int64),
        episode_end=torch.tensor(ends, dtype=torch.int64),
        episode_shortfall=torch.tensor(shortfalls, dtype=torch.float64),  # the final distance, or minus the return
        episode_success=buffer.success[list(starts)].cpu(),
        oracle={k: v for k, v in oracle_ckpt.items() if k != "path"},
        oracle_path=oracle_ckpt.get("path"),
        tamer_h={"state_dict": state_dict_cpu(h_net), "n": h_net.n},
        tamer_actor={"state_dict": state_dict_cpu(tamer_actor)},
        torch_rng=torch.get_rng_state(),
        cuda_rng=torch.cuda.get_rng_state() if buffer.obs.is_cuda else None,
        evaluator_rng=evaluator.generator.get_state(),
    )
    save_atomic(day, path)


def load_day(run_dir: str) -> dict:
    """--sleep-from: RUN_DIR/day.pt, read with weights_only=True and checked; InputError otherwise."""
    path = os.path.join(run_dir, "day.pt")
    if not os.path.isfile(path):
        raise InputError(f"--sleep-from {run_dir}: no day.pt there (make one with --save-buffer)")
    try:
        day = torch.load(path, weights_only=True, map_location="cpu")
    except Exception as e:
        raise InputError(f"--sleep-from {path}: not a readable weights-only day ({type(e).__name__})") from None
    if isinstance(day, dict) and day.get("format") == "inform-day-1" and "episode_final_distance" in day:
        # saved before other tasks: Pusher's final distances, and episodes judged by Outcome's defaults
        day["episode_shortfall"] = day.pop("episode_final_distance")
        day["day_args"] = {"success_info_key": "reward_dist", "success_return": None, **day["day_args"]}
        day["format"] = DAY_FORMAT
    if not isinstance(day, dict) or day.get("format") != DAY_FORMAT or day.get("script") != os.path.basename(__file__):
        raise InputError(f"--sleep-from {path}: not a day saved by this script's --save-buffer ({DAY_FORMAT})")
    if day["env_id"] == "Pusher-v4" and mujoco_major() >= 3:
        raise InputError(f"--sleep-from {path}: the day is on Pusher-v4, which needs mujoco<3 (a separate venv)")
    day["oracle"]["path"] = day["oracle_path"] or f"the oracle saved in {path}"
    return day


def restore_day(day: dict, buffer: ReplayBuffer, evaluator, device) -> tuple:
    """The saved day back in place of the forward phase: the buffer, TAMER's H and actor, the day's stats, and last
    the random states (building networks draws from them)."""
    n = day["obs"].shape[0]
    for key in DAY_TENSORS:
        getattr(buffer, key)[:n] = day[key].to(device)
    buffer.size = n
    table = (day["episode_start"], day["episode_end"], day["episode_shortfall"])
    buffer.episodes = list(zip(*(column.tolist() for column in table), strict=True))
    obs_dim = buffer.obs.shape[1]
    act_dim = buffer.actions.shape[1]
    o = day["oracle"]
    hidden = day["day_args"]["hidden_size"]
    h_net = QEnsemble(obs_dim, act_dim, hidden, day["tamer_h"]["n"])
    h_net.load_state_dict(day["tamer_h"]["state_dict"])
    tamer_actor = Actor(obs_dim, act_dim, hidden, o["action_low"], o["action_high"])
    tamer_actor.load_state_dict(day["tamer_actor"]["state_dict"])
    torch.set_rng_state(day["torch_rng"])
    if day["cuda_rng"] is not None and device.type == "cuda":
        torch.cuda.set_rng_state(day["cuda_rng"])
    evaluator.generator.set_state(day["evaluator_rng"])
    print(f"[day] {n} transitions, {len(buffer.episodes)} episodes from the saved day", flush=True)
    return h_net.to(device), tamer_actor.to(device), dict(day["day_stats"])


def sleep_variant(args: Args) -> str:
    """The sleep's settings in one line, for summary.json and the study's tables."""
    start = "tamer" if args.sleep_init_actor_from_tamer else "scratch"
    parts = [f"protocol={args.sleep_protocol}", f"control={args.sleep_control}", f"actor_start={start}"]
    parts += [f"actor_states={args.sleep_actor_states}", f"policy_frequency={args.sleep_policy_frequency}"]
    parts += [f"loss_rows={args.sleep_loss_rows}", f"twin_critics={args.sleep_twin_critics}"]
    parts += [f"bc_coef={args.sleep_bc_coef}", f"temperature={args.sleep_temperature}"]
    parts += [f"steps={args.sleep_gradient_steps}", f"seed={args.sleep_seed}"]
    parts += [f"holdout_fraction={args.sleep_holdout_fraction}"]
    return " ".join(parts)


def apply_sleep_protocol(args: Args) -> Args:
    """--sleep-protocol authors: the authors' sleep (a fresh actor on replay + expert states, two updates every second
    step, tested at 100k gradient steps; their lr 5e-6, temperature 0.01, one critic and chi2 0.5 are our defaults)."""
    if args.sleep_protocol != "authors":
        return args
    authors = {
        "sleep_init_actor_from_tamer": False,
        "sleep_actor_states": "replay+expert",
        "sleep_policy_frequency": 2,
        "sleep_gradient_steps": 100000,
    }
    print(f"[sleep] --sleep-protocol authors sets {' '.join(f'{k}={v}' for k, v in authors.items())}", flush=True)
    return dataclasses.replace(args, **authors)


class InputError(Exception):
    """Bad input from the user: a flag value, a file. Reported as one line, before anything is written."""


# The range of every flag that has one (InputError outside it). A flag not listed has none, so a new flag is never
# refused for its default. Counts start at 1 unless 0 means something.
RANGES = {
    **dict.fromkeys(
        (
            "num_threads",
            "oracle_total_timesteps",
            "oracle_learning_starts",
            "oracle_batch_size",
            "oracle_policy_frequency",
            "hidden_size",
            "tamer_total_timesteps",
            "tamer_learning_starts",
            "tamer_batch_size",
            "tamer_policy_frequency",
            "credit_window",
            "feedback_budget",
            "sleep_gradient_steps",
            "sleep_batch_size",
            "sleep_policy_frequency",
            "eval_episodes",
            "eval_frequency",
            "sleep_eval_frequency",
            "periodic_eval_episodes",
            "log_frequency",
        ),
        "[1, inf)",
    ),
    **dict.fromkeys(("seed", "teacher_delay", "sleep_seed", "obstacle_episodes", "authors_test_episodes"), "[0, inf)"),
    **dict.fromkeys(
        (
            "success_distance",
            "oracle_q_lr",
            "oracle_policy_lr",
            "tamer_h_lr",
            "tamer_policy_lr",
            "sleep_q_lr",
            "sleep_policy_lr",
            "sleep_temperature",
        ),
        "(0, inf)",
    ),
    **dict.fromkeys(
        (
            "sleep_chi2_coef",
            "sleep_bc_coef",
        ),
        "[0, inf)",
    ),
    "tau": "(0, 1]",
    **dict.fromkeys(
        (
            "feedback_alpha_start",
            "feedback_alpha_end",
            "sleep_gamma",
            "oracle_gamma",
            "teacher_noise",
            "teacher_sparsity",
            "sleep_holdout_fraction",
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
    """What tyro cannot know: the env id, ranges, flags that exclude each other. Raises InputError."""
    if args.track and importlib.util.find_spec("wandb") is None:
        raise InputError("--track needs Weights & Biases: `pip install wandb`, or run without --track")
    if args.env_id == "Pusher-v4" and mujoco_major() >= 3:
        raise InputError(
            "Pusher-v4 needs mujoco<3 (Gymnasium issue 950); use --env-id Pusher-v5, or run in a "
            "separate venv with `pip install mujoco==2.3.7`"
        )
    for f in fields(args):
        value = getattr(args, f.name)
        interval = RANGES.get(f.name)
        if interval is not None and value is not None and not in_range(value, interval):
            flag = "--" + f.name.replace("_", "-")
            counts = isinstance(value, int) and interval.endswith(", inf)")  # "[1, inf)": must be >= 1
            must = f"be >= {interval[1:-6]}" if counts else f"be in {interval}"
            raise InputError(f"{flag} must {must}, got {value}")
    check_env(args)
    if args.tamer_learning_starts >= args.tamer_total_timesteps:
        raise InputError(
            f"--tamer-learning-starts ({args.tamer_learning_starts}) must be below "
            f"--tamer-total-timesteps ({args.tamer_total_timesteps}), or H is never trained"
        )
    if max(args.tamer_batch_size, args.sleep_batch_size) > args.tamer_total_timesteps:
        raise InputError(
            f"--tamer-batch-size ({args.tamer_batch_size}) and --sleep-batch-size "
            f"({args.sleep_batch_size}) must not exceed --tamer-total-timesteps "
            f"({args.tamer_total_timesteps}), the size of the buffer"
        )
    if args.oracle_path is not None and args.train_oracle:
        raise InputError("--oracle-path and --train-oracle exclude each other; pass one of them")
    if args.sleep_from is not None and args.save_buffer:
        raise InputError("--save-buffer and --sleep-from exclude each other: a night on a saved day saves no new day")
    if args.sleep_holdout_fraction >= 1:
        raise InputError(f"--sleep-holdout-fraction must be below 1, got {args.sleep_holdout_fraction}")


def check_env(args: Args) -> None:
    """--env-id: a Gymnasium env with a flat observation and continuous actions, whose episodes can be judged (one
    random step shows whether `info` has --success-info-key). Raises InputError."""
    try:
        env = gym.make(args.env_id)
    except Exception as e:  # unknown id, a missing extra (box2d, ...), a version that needs other packages
        first = (str(e).strip() or type(e).__name__).splitlines()[0][:160]
        raise InputError(f"--env-id {args.env_id}: Gymnasium cannot make it ({first})") from None
    try:
        obs_space, act_space = env.observation_space, env.action_space
        if not isinstance(act_space, gym.spaces.Box):
            raise InputError(
                f"--env-id {args.env_id}: its actions are {type(act_space).__name__}, not continuous (Box); "
                "discrete tasks run in inform_dqn_gridworld.py"
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


def mujoco_major() -> int:
    import mujoco

    return int(mujoco.__version__.split(".")[0])


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
        for p in POLICIES:
            e = {k[len("eval/") :].replace(p, "@"): v for k, v in summary.items() if k.startswith("eval/")}
            obstacle = (
                f" | obstacle distance {e['obstacle/@_final_distance']:.3f} +- {e['obstacle/@_final_distance_std']:.3f}"
                if "obstacle/@_final_distance" in e
                else ""
            )
            say(
                f"{p:>6}: return {e['@_return']:.2f} (sampled {e['@_return_sampled']:.2f}) | final distance "
                f"{e['@_final_distance']:.3f} | success {e['@_success_rate']:.2f}{obstacle}"
            )
        say(" | ".join(f"{k} {v:.0f}" for k, v in summary.items() if k.startswith(("time/", "sps/"))))
    say(f"{summary['status']} in {summary['wall_time_s']:.1f}s; summary: {run_dir}/summary.json")


def evaluate_saved(args: Args) -> dict:
    """--evaluate: a saved policy under the final evaluation's protocol (--eval-episodes, deterministic and sampled
    actions, the run's start or random starts) and the obstacle test; writes nothing."""
    torch.manual_seed(args.seed)
    torch.set_num_threads(args.num_threads)
    actor = actor_from_checkpoint(read_checkpoint(args.evaluate, "--evaluate", args.env_id))
    evaluator = Evaluator(args, writer=None)
    metrics = evaluator("policy", actor, 0, args.eval_episodes)
    skipped = obstacle_skipped(args)
    if skipped:
        obstacle = {"obstacle/skipped": skipped}
    else:
        obstacle, _, _ = obstacle_test(args, {"policy": actor}, evaluator.generator)
    evaluator.close()
    return {**metrics, **obstacle}


# --capture-video: headless MuJoCo frames (MUJOCO_GL, as MuJoCo documents it) written as mp4 by imageio-ffmpeg, the
# ffmpeg that Gymnasium's RecordVideo reaches through moviepy. Pusher films with a fixed
# camera of its own (the Pusher block above); other envs with their default one.
VIDEO_SIZE = 480  # pixels, square; a multiple of 16, as H.264 wants


def check_video(env_id: str) -> None:
    """Before anything is written: pick the headless GL backend (egl when MUJOCO_GL is unset and there is no display),
    render one frame, and find ffmpeg. InputError, one line, if either is missing."""
    import warnings

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
            env = make_env(env_id, 0, render_mode="rgb_array", width=16, height=16)
            env.reset(seed=0)
            frame = env.render()
            env.close()
    except Exception as e:
        raise InputError(
            f"--capture-video: MuJoCo cannot render with MUJOCO_GL={os.environ.get('MUJOCO_GL')} "
            f"({type(e).__name__}); install EGL (Debian: apt-get install libegl1 libegl-mesa0) or "
            "OSMesa (apt-get install libosmesa6, then MUJOCO_GL=osmesa)"
        ) from None
    if not isinstance(frame, np.ndarray) or frame.shape != (16, 16, 3):
        raise InputError(f"--capture-video: MuJoCo rendered no image with MUJOCO_GL={os.environ.get('MUJOCO_GL')}")


def video_env(env_id: str, seed: int, obstacles=None, size: int = VIDEO_SIZE) -> gym.Env:
    """The evaluation env, rendering every reset and step into a list (Gymnasium's RenderCollection)."""
    return gym.wrappers.RenderCollection(
        make_env(env_id, seed, obstacles, render_mode="rgb_array", width=size, height=size)
    )


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


def record_videos(args: Args, policies: dict, boxes: np.ndarray | None, reset_seed: int, run_dir: str) -> dict:
    """--capture-video: each policy's deterministic episode as the final evaluation runs it (from `reset_seed`) and,
    when the obstacle test ran (`boxes`), as it runs it (the run's start, the boxes), by the same `evaluate`, with a
    generator of its own so no other random stream moves. Writes videos/{policy}[_obstacle].mp4 and
    videos/videos.json (frames, final distance and reset seed of each)."""
    os.makedirs(f"{run_dir}/videos", exist_ok=True)
    record = {}
    t = time.time()
    outcome = Outcome.from_args(args)
    films = [("", None, reset_seed)] + ([("_obstacle", boxes, args.seed)] if boxes is not None else [])
    for suffix, obstacles, seed in films:
        env = video_env(args.env_id, args.seed, obstacles)
        for name, actor in policies.items():
            res = evaluate(actor, env, 1, lambda ep, s=seed: s, True, torch.Generator(), outcome)
            frames = env.render()
            write_video(f"{run_dir}/videos/{name}{suffix}.mp4", frames, env.metadata["render_fps"])
            record[f"{name}{suffix}"] = {
                "file": f"{name}{suffix}.mp4",
                "frames": len(frames),
                "size": list(frames[0].shape),
                "final_distance": res["final_distance"],
                "reset_seed": seed,
            }
        env.close()
    write_json_atomic(f"{run_dir}/videos/videos.json", record)
    print(f"[video] {len(record)} episodes filmed in {time.time() - t:.1f}s: {run_dir}/videos/", flush=True)
    return record


if __name__ == "__main__":
    args = tyro.cli(Args)  # a malformed flag: tyro's own message, exit 2
    day = None
    try:
        args = apply_sleep_protocol(args)
        if args.sleep_from is not None:  # the day's flags replace this run's: its numbers are the day's
            day = load_day(args.sleep_from)
            args = dataclasses.replace(args, **day["day_args"])
            print(
                f"[day] sleeping on the day saved in {args.sleep_from} ({args.env_id}, seed {args.seed}, "
                f"{day['obs'].shape[0]} steps); its day flags replace this run's",
                flush=True,
            )
        check_args(args)
        if args.capture_video:
            check_video(args.env_id)
        if args.evaluate is not None:  # writes nothing: a stop meanwhile ends it with one line (see the top)
            print(json.dumps(evaluate_saved(args), indent=2))
            sys.exit(0)
        oracle_ckpt = load_oracle(args) if day is None else None
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    stop = StopSignals()
    summary = main(args, oracle_ckpt, stop, day)
    gc.freeze()  # the interpreter's last collections over torch's objects take seconds on a busy machine; skip them
    sys.exit(stop.exit_code(summary["status"]))
