"""INFORM on MuJoCo Pusher: SAC-style TAMER learns from a simulated teacher's yes/no feedback ("day"), then offline
IQ-Learn on the remembered transitions ("sleep") gives a far-sighted policy and a recovered reward.

Tarakli & Di Nuovo, "Learning while Sleeping" (ICDL 2024): Algorithm 1, Fig. 3 and the obstacle test (Fig. 5); what
the paper leaves open is in docs/protocol.md. Episodes start from the run's seed (the paper's protocol) unless
--random-starts. The teacher: the shipped oracles/{env_id}__sac_oracle.pt, --oracle-path, or SAC trained here
(--train-oracle). Pusher's contact is MuJoCo 2.3's (--contact, make_env). Read top to bottom: Args, make_env, the
networks, Eq. 1-4 and the teacher, the buffer, the day, the night, main; below main the evaluation protocol, then the
plumbing. Other continuous-action tasks run from their id, judged by a final distance in `info` or by --success-return.
inform_utils/ holds the sleep study's nights, re-evaluation and the web page, and imports only the names that
tests/test_surface.py declares for this script.

    python inform_sac_pusher.py --seed 1                            # Pusher-v5, the authors' budget
    python inform_sac_pusher.py --env-id Pusher-v4 --seed 1         # the paper's Pusher
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
import pathlib
import random
import re
import shutil
import signal
import sys
import tempfile
import threading
import time
import typing
import xml.etree.ElementTree as ET
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
from torch.utils.tensorboard import SummaryWriter  # noqa: E402

PUSHER_IDS = ("Pusher-v5", "Pusher-v4")  # the paper's task; any other continuous-action env id works too
CONTACTS = ("mujoco-2.3", "gymnasium")  # Pusher's object contact (make_env)
POLICIES = ("oracle", "tamer", "inform")
REPO_DIR = os.path.dirname(os.path.abspath(__file__))
# the authors' settings (docs/protocol.md), constants rather than flags: change them here
HIDDEN_SIZE = 256  # both hidden layers of every network (oracle, TAMER, INFORM)
TAU = 0.005  # soft update of target networks (the oracle's SAC and the sleep)
TAMER_POLICY_LR = 3e-4  # the TAMER actor (H's rate is --tamer-h-lr)
SLEEP_GAMMA = 0.99  # the sleep's discount: non-myopic, unlike TAMER's 0
ORACLE_SAC = {"learning_starts": 5000, "batch_size": 256, "q_lr": 1e-3, "policy_lr": 3e-4, "gamma": 0.99}
EVAL_FREQUENCY = 2000  # forward-phase env steps between evaluations of TAMER (curves like Fig. 3)
SLEEP_EVAL_FREQUENCY = 1000  # sleep gradient steps between evaluations of INFORM
PERIODIC_EVAL_EPISODES = 5  # episodes of each evaluation during the phases
METRICS = ("return", "final_distance", "success_rate")  # what a test reports of each policy
SIDE_BY_SIDE = 20  # episodes a test runs at once, on copies of its env (evaluate)
LOG_FREQUENCY = 1000  # steps between scalar logs
# the night's recipe, ours and the authors' (their test loads the 100k-step checkpoint); a preset fills in only what
# the command left unset (None)
SLEEP_PROTOCOLS = {
    "ours": dict(sleep_gradient_steps=5000, sleep_init_actor_from_tamer=True, sleep_actor_states="replay",
                 sleep_policy_frequency=1),
    "authors": dict(sleep_gradient_steps=100000, sleep_init_actor_from_tamer=False, sleep_actor_states="replay+expert",
                    sleep_policy_frequency=2),
}  # fmt: skip


@dataclass(frozen=True)
class In:
    """A flag's range, in its Annotated type; check_args refuses a value outside it (NaN too) in one line."""

    low: float
    high: float = math.inf
    ends: str = "[)"  # which ends belong to the range

    def __contains__(self, x) -> bool:
        above = x >= self.low if self.ends[0] == "[" else x > self.low
        return above and (x <= self.high if self.ends[1] == "]" else x < self.high)

    def __str__(self) -> str:
        return f"in {self.ends[0]}{self.low}, {self.high}{self.ends[1]}"


COUNT, SEED, UNIT, RATE, WEIGHT = In(1), In(0, 2**32), In(0, 1, "[]"), In(0, ends="()"), In(0)
DAY = "day"  # in a flag's Annotated type: the flag shapes the day (Args.day_settings: a saved day keeps it)


@dataclass
class Args:
    exp_name: str = os.path.basename(__file__)[: -len(".py")]
    """the name of this experiment (one plain directory name: runs/{env_id}__{exp_name}__{seed}__{time})"""
    seed: Annotated[int, SEED, DAY] = 1
    """seed of the experiment (also the reset seed of every episode under the fixed-start protocol)"""
    num_threads: Annotated[int, COUNT] = 1
    """torch CPU threads (these small networks are fastest on one)"""
    cuda: bool = False
    """if toggled, the networks train on the GPU when one is available (evaluation and the env stay on the CPU)"""
    capture_video: bool = False
    """film the final deterministic episodes, plain and with the boxes, into runs/{run}/videos/ (headless MUJOCO_GL)"""
    track: bool = False
    """mirror the TensorBoard events to Weights & Biases (`pip install wandb`; WANDB_PROJECT, WANDB_MODE=offline)"""
    env_id: Annotated[str, DAY] = "Pusher-v5"
    """Pusher-v5, Pusher-v4 (the paper's; on mujoco>=3 its model in its own class), or any continuous-action env"""
    contact: Annotated[Literal[CONTACTS], DAY] = "mujoco-2.3"
    """Pusher's contact: mujoco-2.3 as MuJoCo 2.3 made it (contact_as_mujoco23: the arm pushes the object); gymnasium:
    as the installed MuJoCo makes it (on mujoco>=3 the arm passes through the object, Gymnasium #1576)"""
    random_starts: Annotated[bool, DAY] = False
    """random initial states (the standard task) instead of the paper's fixed start (reset with the run's seed)"""
    success_distance: Annotated[float, RATE, DAY] = 0.08
    """an episode is a success if its final distance |info[success_info_key]| (Pusher: object to goal) is below this"""
    success_info_key: Annotated[str, DAY] = "reward_dist"
    """the `info` entry whose absolute value at an episode's end is its final distance (else --success-return)"""
    success_return: Annotated[float | None, In(-math.inf, math.inf, "()"), DAY] = None
    """if set, an episode is a success if its return is at least this (the final distance is then only reported)"""

    # Oracle (the simulated teacher): a SAC agent trained on the environment reward
    oracle_path: Annotated[str | None, DAY] = None
    """oracle checkpoint from oracle_train.py; default: the shipped oracles/{env_id}__sac_oracle.pt if present"""
    train_oracle: Annotated[bool, DAY] = False
    """train the SAC oracle here on the environment reward (also what happens when no checkpoint is found)"""
    oracle_total_timesteps: Annotated[int, In(ORACLE_SAC["learning_starts"] + 1), DAY] = 200000
    """environment steps of the in-script SAC oracle (from random starts; the first 5,000 random actions)"""

    # Forward phase: TAMER (Eq. 1) with simulated feedback (Eq. 4)
    tamer_total_timesteps: Annotated[int, COUNT, DAY] = 200000
    """environment steps of the forward phase (each gets one feedback signal); 200k is the authors' budget"""
    tamer_learning_starts: Annotated[int, COUNT, DAY] = 5000
    """random-action steps before H and the actor are trained"""
    tamer_batch_size: Annotated[int, COUNT, DAY] = 256
    """batch size of the H regression and the actor update"""
    tamer_h_lr: Annotated[float, RATE, DAY] = 1e-3
    """learning rate of the twin feedback models H (and of TAMER's entropy coefficient)"""
    feedback_alpha_start: Annotated[float, UNIT, DAY] = 0.99
    """alpha of Eq. 4 at the start of the forward phase (1 = only the oracle's action earns +1)"""
    feedback_alpha_end: Annotated[float, UNIT, DAY] = 0.992
    """alpha of Eq. 4 at the end of the forward phase (alpha rises linearly: the teacher gets stricter)"""

    # The teacher as a person (docs/protocol.md); the defaults are the paper's perfect, instant, tireless teacher
    teacher_noise: Annotated[float, UNIT, DAY] = 0.0
    """probability that the teacher's judgement is flipped (+1 <-> no feedback)"""
    teacher_sparsity: Annotated[float, UNIT, DAY] = 1.0
    """probability that a +1 judgement is actually given (otherwise no feedback)"""
    teacher_delay: Annotated[int, In(0), DAY] = 0
    """env steps between a transition and the arrival of its signal (which labels the later transition)"""
    credit_window: Annotated[int, COUNT, DAY] = 1
    """each arriving signal labels this many most recent transitions (teacher_delay + 1 covers the right one)"""
    feedback_budget: Annotated[int | None, COUNT, DAY] = None
    """the teacher leaves after this many +1 signals (None: never); then TAMER stops learning"""
    budget_ends_forward_phase: Annotated[bool, DAY] = False
    """when the budget is spent, end the forward phase and sleep (otherwise keep acting, without feedback)"""

    # Sleep phase: offline IQ-Learn (Eq. 2), no environment steps
    sleep_protocol: Literal["ours", "authors"] = "ours"
    """authors: their night (the actor from scratch, on replay + expert states, 2 updates every 2nd step, 100k steps);
    a preset fills in only what the command did not set"""
    sleep_gradient_steps: Annotated[int | None, COUNT] = None
    """gradient steps of the sleep (None: the protocol's, 5,000 ours: best early at the 200k forward budget)"""
    sleep_batch_size: Annotated[int, COUNT] = 256
    """transitions from the success set, and as many from the whole buffer, per step"""
    sleep_q_lr: Annotated[float, RATE] = 3e-4
    """learning rate of the soft Q network"""
    sleep_policy_lr: Annotated[float, RATE] = 5e-6
    """learning rate of the INFORM actor"""
    sleep_temperature: Annotated[float, RATE] = 0.01
    """fixed entropy temperature of V(s) = Q(s, a~pi) - temp * log pi(a|s)"""
    sleep_chi2_coef: Annotated[float, WEIGHT] = 0.5
    """weight of the chi-squared regulariser, 1 / (4 * 0.5) as IQ-Learn; 0 turns it off"""
    sleep_seed: Annotated[int | None, SEED] = None
    """re-seed the random streams before the sleep (several nights on one day); None: go on where the day left them"""

    # Saved days: one forward phase, many nights
    save_buffer: bool = False
    """write the day (memories, episode table, teacher, TAMER, random states) to runs/{run}/day.pt for --sleep-from"""
    sleep_from: str | None = None
    """run only the night and the tests on the day saved in this run directory; the day's flags replace this run's"""

    # Evaluation
    eval_episodes: Annotated[int, COUNT] = 20
    """episodes of each final evaluation (deterministic and sampled actions)"""
    obstacle_episodes: Annotated[int, In(0)] = 100
    """episodes per policy on the obstacle variant, all from the run's initial state, sampled actions"""
    obstacle_layout: Literal["bisector", "paper"] = "bisector"
    """bisector: on the bisector of the object's start and the goal, the middle box on the path; paper: the paper's"""
    authors_test_episodes: Annotated[int, In(0)] = 100
    """episodes of the authors' test: sampled actions from the run's initial state (eval/authors_test/...)"""

    def outcome(self) -> "Outcome":
        """How this run judges an episode (--success-info-key, --success-distance, --success-return)."""
        return Outcome(self.success_info_key, self.success_distance, self.success_return)

    def day_settings(self) -> dict:
        """What the day runs with: every flag marked DAY, here or in a subclass (which may redefine one), kept whole."""
        hints = [typing.get_type_hints(c, include_extras=True) for c in type(self).__mro__ if is_dataclass(c)]
        marked = [f.name for f in fields(self) if any(DAY in getattr(h.get(f.name), "__metadata__", ()) for h in hints)]
        return {name: getattr(self, name) for name in marked}

    def sleep_recipe(self) -> dict:
        """The night's settings that --sleep-protocol presets: the protocol's, under whatever the command set (a field
        that is not None; the study module's Args has more of them)."""
        recipe = SLEEP_PROTOCOLS[self.sleep_protocol]
        return {k: v if getattr(self, k, None) is None else getattr(self, k) for k, v in recipe.items()}

    def night_settings(self) -> dict:
        """What the night runs with: these flags and the --sleep-protocol preset (setting x from flag sleep_x)."""
        recipe = {k.removeprefix("sleep_"): v for k, v in self.sleep_recipe().items() if k != "sleep_gradient_steps"}
        return {"batch_size": self.sleep_batch_size, "q_lr": self.sleep_q_lr, "policy_lr": self.sleep_policy_lr,
                "temperature": self.sleep_temperature, "chi2_coef": self.sleep_chi2_coef, **recipe}  # fmt: skip

    def sleep_variant(self) -> str:
        """The night in a line, for summary.json: what it runs with."""
        settings = {"protocol": self.sleep_protocol, "gradient_steps": self.sleep_recipe()["sleep_gradient_steps"],
                    **self.night_settings(), "seed": self.sleep_seed}  # fmt: skip
        return " ".join(f"{k}={v}" for k, v in settings.items())

    def night(self, tamer_actor: "Actor", device, tamer: dict) -> "Night":
        """The night's learner (`tamer`: the day's H, its kwargs and entropy coefficient, which only the sham uses)."""
        return Night(tamer_actor, device, **self.night_settings())

    def day(self, device, space: gym.spaces.Box, obs_dim: int) -> "Day":
        """The day's learner (a page's Args give theirs: inform_utils/browser_pusher.py), as `night` is the night's."""
        return Day(self.day_settings(), device, space, obs_dim)


def make_env(env_id: str, seed: int, obstacles=None, contact: str = "mujoco-2.3", **kwargs) -> gym.Env:
    """The env, or Pusher with the obstacle test's boxes at the xy `obstacles`; `kwargs` go to the env (render_mode,
    width, height: with Pusher's video camera). The boxes and the camera are built below main, as Pusher-v4 on
    mujoco>=3 (which Gymnasium refuses): its own model in its own class. Pusher's `contact`: see contact_as_mujoco23."""
    own = obstacles is not None or "render_mode" in kwargs or (env_id == "Pusher-v4" and mujoco_major() >= 3)
    env = pusher_with_boxes(env_id, obstacles, **kwargs) if env_id in PUSHER_IDS and own else gym.make(env_id, **kwargs)
    if env_id in PUSHER_IDS and contact == "mujoco-2.3" and mujoco_major() >= 3:  # mujoco<3 has it (to the last bit)
        contact_as_mujoco23(env.unwrapped.model)
    env.action_space.seed(seed)
    env.observation_space.seed(seed)
    return env


def contact_as_mujoco23(model) -> None:
    """Every body's body_invweight0, which scales how soft its contacts are, set as MuJoCo 2.3 computed it: the mean
    diagonal of J M^-1 J^T at qpos0 (armature in M), for the translation and the rotation of the body's centre of mass.
    MuJoCo >= 3 takes a body that moves only on slide joints (Pusher's object) by its mass alone: ~1e5 times softer."""
    import mujoco

    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)  # at qpos0: the mass matrix and its factorisation
    jac, solved = np.zeros((6, model.nv)), np.zeros((6, model.nv))
    for body in range(1, model.nbody):
        mujoco.mj_jacBodyCom(model, data, jac[:3], jac[3:], body)
        mujoco.mj_solveM(model, data, solved, jac)
        model.body_invweight0[body] = (jac * solved).sum(1).reshape(2, 3).mean(1)


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


# ---------------------------------------------------------------------------------------------------------------------
# ALGO LOGIC: the networks (each is rebuilt from the `kwargs` saved beside its state_dict)
LOG_STD_MIN, LOG_STD_MAX = -5.0, 2.0


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


def on_cpu(net):
    """The network, or a CPU copy of one on the GPU (evaluation runs on the CPU, as the env does)."""
    params = net.parameters() if isinstance(net, nn.Module) else ()  # anything else: as it is
    return copy.deepcopy(net).cpu() if any(p.device.type != "cpu" for p in params) else net


def soft_update(target: nn.Module, source: nn.Module, tau: float) -> None:
    with torch.no_grad():
        for param, target_param in zip(source.parameters(), target.parameters(), strict=True):
            target_param.lerp_(param, tau)


# ---------------------------------------------------------------------------------------------------------------------
# ALGO LOGIC: the pieces of Algorithm 1, named after the paper: Eq. 1-4 and the teacher


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
class Teacher:
    """A simulated person between Eq. 4 and the learner: noisy, sparse, late and limited (paper Sec. VII's future work).

    Each call hands over the perfect answer h* about the transition at buffer index `step` (Eq. 4's 0 or 1, or any
    value of another teacher) and returns the labels that arrive now, {buffer index: h}, each the answer as given (0:
    no feedback, no label). The judgement is flipped with probability `noise` (1 - h for Eq. 4's 0 and 1, -h for any
    other answer); an answer is clicked only with probability `sparsity`; a click about step t arrives at step t +
    `delay` and labels that transition and the `credit_window` - 1 before it (Deep TAMER's remedy). The teacher leaves
    after `budget` positive signals (None: never). Its own generator: the defaults (0, 1, 0, 1, None) are the perfect
    teacher and leave every other stream untouched.
    """

    def __init__(self, noise=0.0, sparsity=1.0, delay=0, credit_window=1, budget=None, seed=0):
        self.noise, self.sparsity, self.delay, self.credit_window = noise, sparsity, delay, credit_window
        self.budget, self.rng = budget, np.random.default_rng(seed)
        self.in_flight = collections.deque()  # clicks on their way, oldest first
        self.positives = self.perfect_positives = 0  # +1 signals delivered; +1 answers of the perfect teacher (Eq. 4)

    @property
    def gone(self) -> bool:  # the budget is spent: no more feedback from now on
        return self.budget is not None and self.positives >= self.budget

    def drive(self, obs: torch.Tensor) -> torch.Tensor | None:  # a person at the page may take the arm: their action
        return None

    def __call__(self, step: int, h_star: float, action=None) -> dict[int, float]:  # the action: for a person's eyes
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
        return dict.fromkeys(range(max(0, step - self.credit_window + 1), step + 1), h)


def tamer_loss(h_net: QEnsemble, obs: torch.Tensor, actions: torch.Tensor, feedback: torch.Tensor) -> torch.Tensor:
    # Eq. 1: E[(H(s, a) - h)^2], gamma = 0: no bootstrapping, no target network; summed over the twin H models
    return (h_net(obs, actions) - feedback.unsqueeze(0)).pow(2).mean(-1).sum()


def soft_value(q_net: QEnsemble, actor: Actor, obs: torch.Tensor, temperature: float, generator=None):
    """V(s) = Q(s, a~pi) - temp * log pi(a|s), one sample (continuous IQ-Learn)."""
    with torch.no_grad():
        action, log_prob, _ = actor.get_action(obs, generator)
    return q_net(obs, action).min(0).values - temperature * log_prob


# ALGO LOGIC: the sleep loss. `rows`: the rows of the value and chi-squared terms (None: all; IQ-Learn's offline
# recipe takes the expert rows only)
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


def update_actor(q_net, actor, obs, log_ent_coef, actor_optimizer, ent_coef_optimizer) -> None:
    """One SAC actor step on min_i Q_i (the oracle's critics, or TAMER's H), then one of the autotuned entropy
    coefficient exp(log_ent_coef) towards SAC's target entropy, -dim(A)."""
    q_net.requires_grad_(False)  # the gradient flows through the critic to the action, but none is kept on it
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
        self.obs, self.next_obs = (torch.zeros(capacity, obs_dim, device=device) for _ in range(2))
        self.actions = torch.zeros(capacity, act_dim, device=device)
        self.feedback, self.terminated = (torch.zeros(capacity, device=device) for _ in range(2))  # h: when it comes
        self.success = torch.zeros(capacity, dtype=torch.bool, device=device)
        self.driven = torch.zeros(capacity, dtype=torch.bool, device=device)  # a person at the page drove the arm
        self.episodes: list[tuple[int, int, float]] = []  # (first step, end step, shortfall: see Outcome)
        self.size = 0  # transitions stored (fewer than the capacity when the teacher's budget ends the day early)

    def add(self, obs, action, next_obs, terminated, driven: bool = False) -> None:
        self.obs[self.size], self.actions[self.size], self.next_obs[self.size] = obs, action, next_obs
        self.terminated[self.size], self.driven[self.size] = float(terminated), driven
        self.size += 1

    def tag_episode(self, start: int, shortfall: float, success: bool) -> None:
        """Tag the trajectory buffer[start:size], which just ended, with its Outcome."""
        self.success[start : self.size] = success
        self.episodes.append((start, self.size, shortfall))

    def successes(self) -> int:  # episodes tagged success
        return sum(bool(self.success[start]) for start, _, _ in self.episodes)

    def batch(self, idx: torch.Tensor):
        return self.obs[idx], self.actions[idx], self.next_obs[idx], self.feedback[idx], self.terminated[idx]

    def expert_indices(self, keep: torch.Tensor | None = None, fallback_fraction: float = 0.1):
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
# ALGO LOGIC: the phases of Algorithm 1


class Day:
    """The day's learner and what made it, as `Night` is the night's: TAMER's twin feedback models H (Eq. 1, gamma = 0),
    its actor trained SAC-style on H, their optimisers, and `settings` (every flag marked DAY in Args: a saved day keeps
    them whole). A change goes here: a new day flag (marked DAY, read from `settings`); `answer`, the perfect teacher's
    h* (Eq. 4's 0 or 1: any sign and size reaches H as given); `h_kwargs`, `actor_kwargs`, what H and the actor are
    built from (a saved day rebuilds them from these); `update`, TAMER's step; `teacher`, the simulated person."""

    def __init__(self, settings: dict, device, space: gym.spaces.Box | None = None, obs_dim=0, saved=None):
        """A new day for actions in `space` and `obs_dim`-d observations, or a saved day's learner (`saved`: the
        day's tamer_h and tamer_actor, each its constructor arguments and state_dict)."""
        self.settings, s = settings, settings
        if saved is None:
            shapes = {"obs_dim": obs_dim, "act_dim": space.shape[0], "hidden": HIDDEN_SIZE}
            bounds = {"action_low": torch.as_tensor(space.low), "action_high": torch.as_tensor(space.high)}
            self.h_kwargs, self.actor_kwargs = {**shapes, "n": 2}, {**shapes, **bounds}
        else:  # as that day built them
            self.h_kwargs, self.actor_kwargs = saved["tamer_h"]["kwargs"], saved["tamer_actor"]["kwargs"]
        self.h_net = QEnsemble(**self.h_kwargs).to(device)
        self.actor = Actor(**self.actor_kwargs).to(device)
        if saved is not None:
            self.h_net.load_state_dict(saved["tamer_h"]["state_dict"])
            self.actor.load_state_dict(saved["tamer_actor"]["state_dict"])
        self.h_optimizer = torch.optim.Adam(self.h_net.parameters(), lr=s["tamer_h_lr"], foreach=True)
        self.actor_optimizer = torch.optim.Adam(self.actor.parameters(), lr=TAMER_POLICY_LR, foreach=True)
        self.log_ent_coef = torch.zeros(1, device=device, requires_grad=True)  # the actor's entropy coefficient
        self.ent_coef_optimizer = torch.optim.Adam([self.log_ent_coef], lr=s["tamer_h_lr"], foreach=True)

    def teacher(self) -> Teacher:  # the simulated person, on a random stream of its own
        s = self.settings
        return Teacher(s["teacher_noise"], s["teacher_sparsity"], s["teacher_delay"], s["credit_window"],
                       s["feedback_budget"], seed=s["seed"] + 7919)  # fmt: skip

    def answer(self, q_star_sa: torch.Tensor, q_star_best: torch.Tensor, alpha: float) -> float:
        """The perfect teacher's answer h* about (s, a): Eq. 4, 1 or 0."""
        return oracle_feedback(q_star_sa, q_star_best, alpha).item()

    def update(self, buffer: ReplayBuffer, step: int) -> torch.Tensor:
        """TAMER's update: H regresses on the feedback (Eq. 1), then the actor maximises H, SAC-style; H's loss."""
        idx = torch.randint(0, step + 1, (self.settings["tamer_batch_size"],), device=buffer.obs.device)
        obs_b = buffer.obs[idx]
        h_loss = tamer_loss(self.h_net, obs_b, buffer.actions[idx], buffer.feedback[idx])
        self.h_optimizer.zero_grad(set_to_none=True)
        h_loss.backward()
        self.h_optimizer.step()
        update_actor(self.h_net, self.actor, obs_b, self.log_ent_coef, self.actor_optimizer, self.ent_coef_optimizer)
        return h_loss

    def saved(self) -> dict:  # what a saved day keeps of its learner: the settings whole, the networks rebuildable
        nets = {"tamer_h": (self.h_net, self.h_kwargs), "tamer_actor": (self.actor, self.actor_kwargs)}
        saved = {k: {"kwargs": kwargs, "state_dict": state_dict_cpu(net)} for k, (net, kwargs) in nets.items()}
        return {"day_args": {**self.settings, **DAY_CONSTANTS}, **saved}


def forward_phase(day: Day, env, oracle_actor, oracle_qf, teacher, outcome, buffer: ReplayBuffer, evaluator, writer):
    """The day: SAC-style TAMER (`day`, Eq. 1, gamma = 0) on the teacher's feedback (Eq. 4), all remembered. The
    teacher: the simulated person (Teacher), or one with its interface (a person at a web page); with
    --budget-ends-forward-phase the day ends when the teacher's budget is spent."""
    s, n, device = day.settings, day.settings["tamer_total_timesteps"], buffer.obs.device
    print(f"[tamer] {n} env steps, feedback alpha {s['feedback_alpha_start']} -> {s['feedback_alpha_end']}", flush=True)
    progress = Progress("tamer", n, warmup=s["tamer_learning_starts"], evaluator=evaluator)
    obs, _ = env.reset(seed=s["seed"])
    obs_t = torch.as_tensor(obs, dtype=torch.float32, device=device)
    h_loss = torch.zeros((), device=device)
    ep_start, ep_length, ep_return, last_return = 0, 0, 0.0, float("nan")
    for step in range(n):
        StopSignals.check()  # a stop signal ends the run here, between two steps
        feedback_alpha = linear_schedule(s["feedback_alpha_start"], s["feedback_alpha_end"], n - 1, step)  # stricter
        if step < s["tamer_learning_starts"]:
            action_t = torch.as_tensor(env.action_space.sample(), device=device)
        else:
            with torch.no_grad():
                action_t = day.actor.get_action(obs_t.unsqueeze(0))[0][0]
        driven = teacher.drive(obs_t)  # None, or the action of a person who has taken the arm (at the web page)
        action_t = action_t if driven is None else driven

        # ALGO LOGIC: the teacher watches (s, a): the perfect answer (Eq. 4), then the person's (Teacher)
        taught = not teacher.gone  # after the budget is spent, TAMER has nothing to learn from
        with torch.no_grad():
            q_star_sa, q_star_best = oracle_q(oracle_actor, oracle_qf, obs_t, action_t)
        h_star = day.answer(q_star_sa, q_star_best, feedback_alpha) if taught else 0.0
        labels = teacher(step, h_star, action_t)  # {transition: h} that this step's arriving signal labels
        buffer.feedback[list(labels)] = torch.tensor(list(labels.values()), device=device)

        next_obs, reward, terminated, truncated, info = env.step(action_t.cpu().numpy())
        next_t = torch.as_tensor(next_obs, dtype=torch.float32, device=device)
        buffer.add(obs_t, action_t, next_t, terminated, driven is not None)
        ep_return, ep_length = ep_return + float(reward), ep_length + 1
        last_step = step == n - 1 or (teacher.gone and s["budget_ends_forward_phase"])
        if terminated or truncated or last_step:  # tag the trajectory; a cut-off last one by where it stands
            distance, success, shortfall = outcome(info, ep_return)
            buffer.tag_episode(ep_start, shortfall, success)
            charts = {"episodic_return": ep_return, "episodic_length": ep_length, "episode_success": float(success)}
            for tag, value in {**charts, **({} if math.isnan(distance) else {"final_distance": distance})}.items():
                writer.add_scalar(f"charts/{tag}", value, step + 1)
            ep_start, ep_length, ep_return, last_return = step + 1, 0, 0.0, ep_return
            next_obs, _ = env.reset(seed=None if s["random_starts"] else s["seed"])
            next_t = torch.as_tensor(next_obs, dtype=torch.float32, device=device)
        obs_t = next_t

        # ALGO LOGIC: TAMER's update: H regresses on the feedback (Eq. 1), the actor maximises H, SAC-style
        if step >= s["tamer_learning_starts"] and taught:
            h_loss = day.update(buffer, step)

        # TRY NOT TO MODIFY: the divergence check, logging and periodic evaluation
        if (step + 1) % 100 == 0 or last_step:
            check_finite({"tamer_loss": h_loss}, {}, "TAMER's feedback model H", f"env step {step + 1}", "--tamer-h-lr")
        if (step + 1) % LOG_FREQUENCY == 0 or last_step:
            logs = {"losses/tamer_loss": h_loss.item(), "losses/tamer_entropy_coef": day.log_ent_coef.exp().item(),
                    "feedback/positive": teacher.positives, "feedback/positive_rate": teacher.positives / (step + 1),
                    "feedback/alpha": feedback_alpha, "charts/SPS": progress.sps(step + 1)}  # fmt: skip
            for tag, value in logs.items():
                writer.add_scalar(tag, value, step + 1)
        report = {"return": last_return}
        if (step + 1) % EVAL_FREQUENCY == 0 or last_step:
            report["eval return"] = evaluator("tamer", day.actor, step + 1, PERIODIC_EVAL_EPISODES)["eval/tamer_return"]
        progress(step + 1, **report)
        if last_step:
            break

    positives, successes = teacher.positives, buffer.successes()
    print(f"[tamer] feedback +1 on {positives}/{buffer.size} steps ({positives / buffer.size:.1%}); "
          f"{successes}/{len(buffer.episodes)} episodes tagged success", flush=True)  # fmt: skip
    stats = {"feedback/positive": positives, "feedback/perfect_positive": teacher.perfect_positives}
    stats.update({"feedback/steps": buffer.size, "feedback/positive_rate": positives / buffer.size})
    stats["feedback/driven_steps"] = int(buffer.driven[: buffer.size].sum())  # a person's own steps (the web page)
    stats.update({"sleep/success_episodes": int(successes), "sleep/episodes": len(buffer.episodes)})
    if ((labels := buffer.feedback[: buffer.size])[labels > 0] != 1).any():  # graded answers: what counted, and how
        stats.update({"feedback/counted_as_positive": "every answer above 0, as one signal (its rate, the budget)",
                      "feedback/positive_label_mean": labels[labels > 0].mean().item()})  # fmt: skip
    return {**stats, "losses/tamer_entropy_coef": day.log_ent_coef.exp().item()}


def sleep_batch(buffer: ReplayBuffer, batch_size: int, expert_idx: torch.Tensor, replay_idx=None):
    """The sleep's batch: `batch_size` replay rows (replay_idx's; None: the whole buffer), then as many expert rows."""
    device = expert_idx.device
    replay = torch.randint(0, buffer.size if replay_idx is None else replay_idx.numel(), (batch_size,), device=device)
    replay = replay if replay_idx is None else replay_idx[replay]
    expert = expert_idx[torch.randint(0, expert_idx.numel(), (batch_size,), device=device)]
    return buffer.batch(torch.cat([replay, expert]))


class Night:
    """The night's learner: soft Q by IQ-Learn (Eq. 2) on replay rows then expert rows, the INFORM actor on Q (SAC's
    objective at a fixed temperature), the target Q following softly. The sleep study
    (inform_utils/sleep_variants_pusher.py) subclasses it: `loss`, `actor_loss` and `update_actor` are where a variant
    changes the night (calling these, so that a term added here reaches every variant), `memories` what it sleeps on."""

    n_critics = 1  # soft Q networks (twins: their minimum in V(s) and in the actor's objective)

    def __init__(self, tamer_actor: Actor, device, *, batch_size: int, q_lr: float, policy_lr: float,
                 temperature: float, chi2_coef: float, init_actor_from_tamer: bool, actor_states: str,
                 policy_frequency: int):  # fmt: skip
        obs_dim, act_dim = tamer_actor.fc1.in_features, tamer_actor.fc_mean.out_features
        self.q_net = QEnsemble(obs_dim, act_dim, HIDDEN_SIZE, n=self.n_critics).to(device)
        self.q_target = QEnsemble(obs_dim, act_dim, HIDDEN_SIZE, n=self.n_critics).to(device)
        self.q_target.load_state_dict(self.q_net.state_dict())
        scale, bias = tamer_actor.action_scale, tamer_actor.action_bias
        self.actor = Actor(obs_dim, act_dim, HIDDEN_SIZE, bias - scale, bias + scale).to(device)
        if init_actor_from_tamer:  # consolidation: the night starts from the day's actor
            self.actor.load_state_dict(tamer_actor.state_dict())
        self.q_optimizer = torch.optim.Adam(self.q_net.parameters(), lr=q_lr, foreach=True)
        self.actor_optimizer = torch.optim.Adam(self.actor.parameters(), lr=policy_lr, foreach=True)
        self.temperature, self.chi2_coef, self.frequency = temperature, chi2_coef, policy_frequency
        self.is_expert = torch.arange(2 * batch_size, device=device) >= batch_size  # replay rows, then expert rows
        rows = {"replay": ~self.is_expert, "expert": self.is_expert, "replay+expert": slice(None)}
        self.actor_rows = rows[actor_states]  # the states the actor learns on
        self.pi_loss = torch.zeros((), device=device)  # the last actor loss, for the logs
        self.selected = None  # a checkpoint picked offline ({"step", "actor"}), beside the last one: none here

    def memories(self, buffer: ReplayBuffer) -> tuple[torch.Tensor | None, torch.Tensor, int]:
        """What the night sleeps on: the replay rows' indices (None: the whole buffer), the success set's and, if it
        is empty, how many closest episodes stand in for it."""
        return None, *buffer.expert_indices()

    def loss(self, obs, actions, next_obs, feedback, terminated, **kw) -> tuple[torch.Tensor, dict]:
        """Eq. 2 on one batch, and its named terms (the logs show whatever terms come back)."""
        return iq_loss(self.q_net, self.q_target, obs, actions, next_obs, terminated, self.is_expert, SLEEP_GAMMA,
                       self.temperature, self.chi2_coef, self.actor, **kw)  # fmt: skip

    def actor_loss(self, obs, actions, feedback) -> torch.Tensor:
        return actor_loss(self.q_net, self.actor, obs[self.actor_rows], self.temperature)[0]

    def update_actor(self, batch) -> None:
        obs, actions, _, feedback, _ = batch
        self.q_net.requires_grad_(False)  # the actor's gradient flows through Q, but none is kept on it
        self.pi_loss = self.actor_loss(obs, actions, feedback)
        self.actor_optimizer.zero_grad(set_to_none=True)
        self.pi_loss.backward()
        self.q_net.requires_grad_(True)
        self.actor_optimizer.step()

    def update(self, step: int, batch) -> tuple[torch.Tensor, dict]:
        """One gradient step of Q, the actor's updates (the authors': 2 every 2nd step), the target's soft step."""
        obs, actions, next_obs, feedback, terminated = batch
        loss, terms = self.loss(obs, actions, next_obs, feedback, terminated)
        self.q_optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.q_optimizer.step()
        for _ in range(self.frequency if step % self.frequency == 0 else 0):
            self.update_actor(batch)
        soft_update(self.q_target, self.q_net, TAU)
        return loss, terms

    def evaluated(self, step: int, writer) -> dict:  # after each periodic evaluation: more to report (the study's)
        return {}

    def stats(self) -> dict:  # what the night adds to the summary
        return {}


def sleep_phase(night: Night, buffer: ReplayBuffer, steps: int, batch_size: int, evaluator, writer, device) -> dict:
    """The night: `night` learns offline on the buffer, the successful trajectories as the expert set, no environment
    steps; its stats and last losses."""
    replay_idx, expert_idx, fallback_episodes = night.memories(buffer)
    if fallback_episodes:
        closest = "the smallest final distance, or with --success-return the highest return"
        print(f"[sleep] warning: no successful episode; the {fallback_episodes} closest ({closest}) are the expert set")
    replay = buffer.size if replay_idx is None else replay_idx.numel()
    print(f"[sleep] {expert_idx.numel()} expert transitions, {replay} in the buffer", flush=True)
    stats = {"sleep/expert_transitions": int(expert_idx.numel()), "sleep/expert_fallback": int(fallback_episodes > 0)}
    losses = {}
    progress = Progress("sleep", steps, evaluator=evaluator)
    for step in range(1, steps + 1):
        StopSignals.check()
        # ALGO LOGIC: the sleep update: Q by IQ-Learn (Eq. 2), the INFORM actor on Q, the target Q follows softly
        loss, terms = night.update(step, sleep_batch(buffer, batch_size, expert_idx, replay_idx))

        # TRY NOT TO MODIFY: logging (one host sync per 100 steps to catch divergence) and periodic evaluation
        last_step = step == steps
        if step % 100 == 0 or step % LOG_FREQUENCY == 0 or last_step:
            tags = {"iq_loss": loss, **terms, "inform_actor_loss": night.pi_loss}
            losses = check_finite(tags, losses, "the sleep loss", f"gradient step {step}", SLEEP_LRS)
        if step % LOG_FREQUENCY == 0 or last_step:
            for tag, value in {**losses, "sleep/SPS": progress.sps(step)}.items():
                writer.add_scalar(tag, value, step)
        report = {"iq_loss": losses.get("losses/iq_loss")}
        if step % SLEEP_EVAL_FREQUENCY == 0 or last_step:
            report["eval return"] = evaluator("inform", night.actor, step, PERIODIC_EVAL_EPISODES)["eval/inform_return"]
            report.update(night.evaluated(step, writer))
        progress(step, **report)
    return {**stats, **night.stats(), **losses}


SLEEP_LRS = "--sleep-q-lr or --sleep-policy-lr"  # what helps a diverging night


def check_finite(tags: dict, last: dict, what: str, when: str, flag: str) -> dict:
    """{losses/tag: value} after one host sync; Diverged, naming `what` and the `flag` that helps, if any is NaN or
    inf (`last`: the last finite ones, for the message)."""
    values = torch.stack(list(tags.values())).tolist()
    if not all(map(math.isfinite, values)):
        finite = ", ".join(f"{k.split('/')[1]} {v:.4g}" for k, v in last.items()) or "none yet"
        raise Diverged(f"{what} diverged (NaN or inf) by {when}; last finite losses: {finite}; try a lower {flag}")
    return {f"losses/{tag}": value for tag, value in zip(tags, values, strict=True)}


# ---------------------------------------------------------------------------------------------------------------------
# ALGO LOGIC: the evaluation protocol (deterministic and sampled actions, the authors' test, the obstacle
# test), the oracle's own SAC, the recovered reward (Eq. 3) as an object and a Gymnasium wrapper


@torch.no_grad()
def evaluate(actor: Actor, env, episodes: int, reset_seed, deterministic: bool, generator, outcome: Outcome):
    """Run `episodes` episodes; reset_seed(ep) gives each episode's reset seed. `env`: one env, or a list of copies of
    one, which run the episodes side by side with the numbers of one env running them in turn. Returns means and
    per-episode data, each episode's observations included. On the CPU, as the env and `generator` are: a GPU actor
    is copied there."""
    envs, actor = env if isinstance(env, list) else [env], on_cpu(actor)
    rows = one_row_at_a_time(actor) if min(len(envs), episodes) > 1 else actor  # a batch of episodes will run
    stream = generator or torch.default_generator
    returns, distances, successes, trajectories = [], [], [], []
    for first in range(0, episodes, len(envs)):
        seeds, state = [reset_seed(ep) for ep in range(first, min(first + len(envs), episodes))], stream.get_state()
        ran = side_by_side(rows, envs, seeds, deterministic, generator) if len(seeds) > 1 else None
        if ran is None:  # one at a time: each episode draws its noise step by step, for as long as it runs
            stream.set_state(state)
            ran = [one_episode(actor, envs[0], seed, deterministic, generator) for seed in seeds]
        for ep_return, info, trajectory in ran:
            distance, success, _ = outcome(info, ep_return)
            returns.append(ep_return)
            distances.append(distance)
            successes.append(success)
            trajectories.append(trajectory)
    distances = np.asarray(distances)
    res = {"return": float(np.mean(returns)), "final_distance": float(distances.mean())}
    res.update({"final_distance_std": float(distances.std()), "success_rate": float(np.mean(successes))})
    return {**res, "distances": distances, "returns": np.asarray(returns), "trajectories": trajectories}


def one_episode(actor: Actor, env: gym.Env, seed: int | None, deterministic: bool, generator) -> tuple:
    """(return, last info, observations) of one episode from env.reset(seed=seed)."""
    StopSignals.check()
    obs, _ = env.reset(seed=seed)
    done, ep_return, info, trajectory = False, 0.0, {}, [obs]
    while not done:
        sampled, _, mean = actor.get_action(torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0), generator)
        obs, reward, terminated, truncated, info = env.step((mean if deterministic else sampled)[0].numpy())
        ep_return, done = ep_return + float(reward), terminated or truncated
        trajectory.append(obs)
    return ep_return, info, np.array(trajectory)


def side_by_side(rows: Actor, envs: list, seeds: list, deterministic: bool, generator) -> list | None:
    """one_episode's results for `seeds` at once, on copies of one env: one batched action a step from `rows`
    (one_row_at_a_time), the noise of the sampled actions drawn beforehand in the order one env running the episodes
    in turn draws it, so the numbers are that env's. None if an episode could end before the time limit (its draws
    are not known beforehand)."""
    horizon = envs[0].spec.max_episode_steps if envs[0].spec is not None else None
    if horizon is None or None in seeds:  # no time limit, or a reset that goes on from an env's own random state
        return None
    envs, act_dim = envs[: len(seeds)], rows.action_scale.shape[0]
    eps = torch.stack([torch.cat([torch.randn((1, act_dim), generator=generator) for _ in range(horizon)])
                       for _ in seeds])  # fmt: skip
    obs = np.stack([env.reset(seed=seed)[0] for env, seed in zip(envs, seeds, strict=True)])
    returns, infos, observations = [0.0] * len(seeds), [], [obs]
    for t in range(horizon):
        StopSignals.check()
        sampled, _, mean = rows.get_action(torch.as_tensor(obs, dtype=torch.float32), eps=eps[:, t])
        actions = (mean if deterministic else sampled).numpy()
        steps = [env.step(action) for env, action in zip(envs, actions, strict=True)]
        if any(terminated or truncated != (t == horizon - 1) for _, _, terminated, truncated, _ in steps):
            return None
        obs, infos = np.stack([step[0] for step in steps]), [step[4] for step in steps]
        returns = [ep_return + float(step[1]) for ep_return, step in zip(returns, steps, strict=True)]
        observations.append(obs)
    return list(zip(returns, infos, np.stack(observations, axis=1), strict=True))


class OneRow(nn.Module):
    """A Linear layer that computes each row of a batch as it computes a batch of one (a matmul per row, where one
    matmul on the batch sums in another order): a batch of episodes then acts as each episode would alone."""

    def __init__(self, linear: nn.Linear):
        super().__init__()
        self.linear = linear

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        n, weight, bias = x.shape[0], self.linear.weight, self.linear.bias
        return torch.baddbmm(bias.expand(n, 1, -1), x.unsqueeze(1), weight.t().expand(n, -1, -1)).squeeze(1)


def env_copies(env_id: str, seed: int, episodes: int, obstacles=None, contact="mujoco-2.3") -> list[gym.Env]:
    """Copies of one env, as many as `episodes` can use at once (evaluate runs them side by side)."""
    return [make_env(env_id, seed, obstacles, contact) for _ in range(max(1, min(episodes, SIDE_BY_SIDE)))]


def one_row_at_a_time(actor: Actor) -> Actor:
    """A copy of `actor` whose layers are OneRow."""
    rows = copy.deepcopy(actor)
    for name, layer in list(rows.named_children()):
        setattr(rows, name, OneRow(layer) if isinstance(layer, nn.Linear) else layer)
    return rows


class Evaluator:
    """Evaluates a policy on the plain env with deterministic and sampled actions; logs and keeps eval/{name}_*.
    Episodes start from the run's seed (fixed start) or from fresh seeds (`--random-starts`), the same each time."""

    def __init__(self, env_id: str, seed: int, random_starts: bool, outcome: Outcome, writer, contact="mujoco-2.3"):
        self.envs, self.contact = env_copies(env_id, seed, SIDE_BY_SIDE, contact=contact), contact
        self.writer, self.seed, self.random_starts, self.outcome = writer, seed, random_starts, outcome
        self.generator = torch.Generator().manual_seed(seed + 12345)  # sampled actions, off the training RNG
        self.seconds, self.final = 0.0, {}  # spent evaluating; the latest value of each tag

    def reset_seed(self, episode: int) -> int:
        return 1_000_000 + 1000 * self.seed + episode if self.random_starts else self.seed

    def __call__(self, name: str, actor: Actor, step: int, episodes: int) -> dict:
        t, results = time.time(), {}
        for deterministic, suffix in ((True, ""), (False, "_sampled")):
            res = evaluate(actor, self.envs, episodes, self.reset_seed, deterministic, self.generator, self.outcome)
            results.update({f"eval/{name}_{k}{suffix}": res[k] for k in METRICS})
        for tag, value in results.items() if self.writer is not None else ():
            self.writer.add_scalar(tag, value, step)
        self.final.update(results)
        self.seconds += time.time() - t
        return results

    def close(self):
        for env in self.envs:
            env.close()


def final_evaluation(buffer, q_net, policies: dict, evaluator, writer, run_dir: str, *, env_id: str, end_step: int,
                     temperature: float, eval_episodes: int, obstacle_layout: str, obstacle_episodes: int,
                     authors_test_episodes: int, capture_video: bool) -> dict:  # fmt: skip
    """After the sleep: Eq. 3 on the buffer (at the night's `temperature`), each policy's final evaluation, the
    obstacle test (Pusher only) and the authors' test (all logged at `end_step`), the obstacle files and the videos."""
    results = recovered_reward_stats(buffer, q_net, policies["inform"], temperature)
    seed, outcome, contact, boxes = evaluator.seed, evaluator.outcome, evaluator.contact, None
    print("[eval] final evaluation", flush=True)
    for name, actor in policies.items():
        evaluator(name, actor, end_step, eval_episodes)
    t = time.time()
    if obstacle_skipped(env_id, obstacle_episodes):
        results["obstacle/skipped"] = obstacle_skipped(env_id, obstacle_episodes)
    else:
        test = (env_id, seed, obstacle_layout, obstacle_episodes, outcome)
        obstacle, distances, paths = obstacle_test(*test, policies, evaluator.generator, contact)
        results.update(obstacle)
        for name, arrays in (("distances", distances), ("paths", paths)):  # whole or not at all (a full disk)
            with atomic(f"{run_dir}/obstacle_{name}.npz") as tmp, open(tmp, "wb") as f:
                np.savez(f, **arrays)
        boxes = paths["boxes"]
    if authors_test_episodes > 0:  # the authors' test: sampled actions, every episode from the run's start
        envs = env_copies(env_id, seed, authors_test_episodes, contact=contact)
        for name, actor in policies.items():
            res = evaluate(actor, envs, authors_test_episodes, lambda ep: seed, False, evaluator.generator, outcome)
            results.update({f"eval/authors_test/{name}_{k}": res[k] for k in METRICS})
        for env in envs:
            env.close()
    for tag, value in results.items():
        if tag.startswith(("eval/obstacle/", "eval/authors_test/", "obstacle/min")):
            writer.add_scalar(tag, value, end_step)
    evaluator.seconds += time.time() - t
    if capture_video:  # after every number is in: filming changes none of them
        record_videos(env_id, seed, outcome, policies, boxes, evaluator.reset_seed(0), run_dir, contact)
    return results


def recovered_reward_stats(buffer: ReplayBuffer, q_net: QEnsemble, inform_actor: Actor, temperature: float) -> dict:
    """Eq. 3 on the buffer: the mean recovered reward of success and of failure transitions, for the record."""
    reward_fn = RecoveredReward(q_net, inform_actor, SLEEP_GAMMA, temperature, samples=4)
    b = [x[: buffer.size].cpu().numpy() for x in (buffer.obs, buffer.actions, buffer.next_obs, buffer.terminated)]
    r_all, succ = reward_fn(*b), buffer.success[: buffer.size].cpu().numpy()
    mean = lambda rows: float(r_all[rows].mean()) if rows.any() else float("nan")  # noqa: E731
    return {"sleep/recovered_reward_success_mean": mean(succ), "sleep/recovered_reward_failure_mean": mean(~succ)}


# the oracle: SAC on the environment reward (oracle_train.py runs the same SAC; a test keeps the two identical)
def train_oracle(env_id: str, seed: int, n: int, outcome: Outcome, writer, device: torch.device, contact="mujoco-2.3"):
    """SAC on the environment reward (CleanRL's, with the twin critics as one module), from random starts: the
    simulated teacher. Returns the actor, the twin critics and the steps per second."""
    sac, env = ORACLE_SAC, make_env(env_id, seed, contact=contact)
    obs_dim, act_dim = int(np.prod(env.observation_space.shape)), int(np.prod(env.action_space.shape))
    actor = Actor(obs_dim, act_dim, HIDDEN_SIZE, env.action_space.low, env.action_space.high).to(device)
    qf = QEnsemble(obs_dim, act_dim, HIDDEN_SIZE, n=2).to(device)
    qf_target = QEnsemble(obs_dim, act_dim, HIDDEN_SIZE, n=2).to(device)
    qf_target.load_state_dict(qf.state_dict())
    q_optimizer = torch.optim.Adam(qf.parameters(), lr=sac["q_lr"], foreach=True)
    actor_optimizer = torch.optim.Adam(actor.parameters(), lr=sac["policy_lr"], foreach=True)
    log_ent_coef = torch.zeros(1, device=device, requires_grad=True)  # SAC's entropy coefficient, autotuned
    ent_coef_optimizer = torch.optim.Adam([log_ent_coef], lr=sac["q_lr"], foreach=True)
    b_obs, b_next = torch.zeros(n, obs_dim, device=device), torch.zeros(n, obs_dim, device=device)
    b_act, b_rew = torch.zeros(n, act_dim, device=device), torch.zeros(n, device=device)
    b_term = torch.zeros(n, device=device)
    progress = Progress("oracle", n, warmup=sac["learning_starts"])
    obs, _ = env.reset(seed=seed)
    obs_t = torch.as_tensor(obs, dtype=torch.float32, device=device)
    ep_return, last_return = 0.0, float("nan")
    for step in range(n):
        StopSignals.check()
        if step < sac["learning_starts"]:
            action = env.action_space.sample()
        else:
            with torch.no_grad():
                action = actor.get_action(obs_t.unsqueeze(0))[0][0].cpu().numpy()
        next_obs, reward, terminated, truncated, info = env.step(action)
        next_t = torch.as_tensor(next_obs, dtype=torch.float32, device=device)
        b_obs[step], b_next[step], b_act[step] = obs_t, next_t, torch.as_tensor(action)
        b_rew[step], b_term[step] = float(reward), float(terminated)
        ep_return += float(reward)
        if terminated or truncated:
            writer.add_scalar("oracle/episodic_return", ep_return, step)
            distance = outcome(info, ep_return)[0]
            if not math.isnan(distance):
                writer.add_scalar("oracle/final_distance", distance, step)
            ep_return, last_return = 0.0, ep_return
            next_obs, _ = env.reset()  # random starts: an expert from any start
            next_t = torch.as_tensor(next_obs, dtype=torch.float32, device=device)
        obs_t = next_t
        if step >= sac["learning_starts"]:
            idx = torch.randint(0, step + 1, (sac["batch_size"],), device=device)
            obs_b, next_b = b_obs[idx], b_next[idx]
            with torch.no_grad():
                next_a, next_logp, _ = actor.get_action(next_b)
                v_next = qf_target(next_b, next_a).min(0).values - log_ent_coef.detach().exp() * next_logp
                target = b_rew[idx] + (1.0 - b_term[idx]) * sac["gamma"] * v_next
            q_loss = (qf(obs_b, b_act[idx]) - target.unsqueeze(0)).pow(2).mean(-1).sum()
            q_optimizer.zero_grad(set_to_none=True)
            q_loss.backward()
            q_optimizer.step()
            if step % 2 == 0:  # the actor and entropy updates every second step
                update_actor(qf, actor, obs_b, log_ent_coef, actor_optimizer, ent_coef_optimizer)
            soft_update(qf_target, qf, TAU)
            if (step + 1) % LOG_FREQUENCY == 0:
                writer.add_scalar("oracle/qf_loss", q_loss.item(), step + 1)
                writer.add_scalar("oracle/SPS", progress.sps(step + 1), step + 1)
        progress(step + 1, **{"return": last_return})
    env.close()
    return actor, qf, n / max(time.time() - progress.start, 1e-9)


class RecoveredReward:
    """The reward INFORM recovers (Eq. 3), imitation-style: reward(obs, action, next_obs, terminated) -> array.
    V(s') is averaged over `samples` actions drawn with a fixed generator, so the reward is deterministic. On the CPU
    (copies of networks trained on the GPU). inform_utils/recovered_reward.py loads it from a run and wraps an env
    with it, so that any Gymnasium agent trains on it."""

    def __init__(self, q_net: QEnsemble, actor: Actor, gamma: float, temperature: float, samples: int = 16):
        self.q_net, self.actor, self.gamma, self.temperature = on_cpu(q_net), on_cpu(actor), gamma, temperature
        self.samples = samples

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
        )
        return recover_reward(self.q_net(obs_t, act_t).min(0).values, v_next.mean(0), term_t, self.gamma).numpy()


# ALGO LOGIC, Pusher only: the obstacle test (Fig. 5) and its boxes: three 3 cm cubes on the table (docs/protocol.md),
# the paper's positions (layout "paper") or the paper's spacing on the bisector of the object's start and the goal
OBSTACLE_POSITIONS = ((0.32, -0.20), (0.35, -0.23), (0.38, -0.26))
OBSTACLE_SPACING, OBSTACLE_HALF_SIZE, OBSTACLE_Z = 0.0424, 0.015, -0.325
OBSTACLE_LAYOUTS = ("bisector", "paper")


def object_xy(obs: np.ndarray) -> np.ndarray:  # the object's xy in Pusher's observation (also along a trajectory)
    return obs[..., 17:19]


def obstacle_skipped(env_id: str, episodes: int) -> str | None:  # why the obstacle test does not run (None: it does)
    if env_id not in PUSHER_IDS:
        return f"the obstacle test is Pusher's; {env_id} has none"
    return "--obstacle-episodes 0" if episodes == 0 else None


def obstacle_test(env_id, seed, layout, episodes, outcome, policies: dict, generator, contact="mujoco-2.3"):
    """Each policy on the obstacle variant, every episode from the run's initial state, sampled actions. Returns the
    metrics, the final distances, and the object's xy path of one deterministic episode per policy with and without
    the boxes (Fig. 5a)."""
    start, goal = start_and_goal(env_id, seed)
    boxes = obstacle_positions(layout, start, goal)
    results = {"obstacle/box_positions": boxes.round(4).tolist()}
    results["obstacle/min_box_distance_to_path"] = min(distance_to_segment(b, start, goal) for b in boxes)
    distances, paths = {}, {"boxes": boxes, "start": start, "goal": goal}
    envs = env_copies(env_id, seed, episodes, boxes, contact)
    plain, at_start = make_env(env_id, seed, contact=contact), lambda episode: seed
    for name, actor in policies.items():
        res = evaluate(actor, envs, episodes, at_start, False, generator, outcome)
        det = evaluate(actor, envs[0], 1, at_start, True, generator, outcome)
        det_plain = evaluate(actor, plain, 1, at_start, True, torch.Generator(), outcome)
        paths[f"{name}_obstacle"] = object_xy(det["trajectories"][0])
        paths[f"{name}_plain"] = object_xy(det_plain["trajectories"][0])
        distances[name] = res["distances"]
        for key in ("final_distance", "final_distance_std", "success_rate", "return"):
            results[f"eval/obstacle/{name}_{key}"] = res[key]
        results[f"eval/obstacle/{name}_final_distance_deterministic"] = det["final_distance"]
    for env in (*envs, plain):
        env.close()
    return results, distances, paths


def start_and_goal(env_id: str, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The object's and the goal's xy after a reset with `seed` (obs[17:19] and obs[20:22])."""
    with make_env(env_id, seed) as env:
        obs, _ = env.reset(seed=seed)
    return object_xy(obs).copy(), obs[20:22].copy()


def obstacle_positions(layout: str, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """The three box centres (3 x 2): the paper's coordinates, or the middle box at the midpoint of the object's start
    and the goal and the other two OBSTACLE_SPACING either side of it along the perpendicular bisector."""
    if layout == "paper":
        return np.array(OBSTACLE_POSITIONS)
    middle, along = (start + goal) / 2, (goal - start) / np.linalg.norm(goal - start)
    across = np.array([-along[1], along[0]])
    return np.stack([middle - OBSTACLE_SPACING * across, middle, middle + OBSTACLE_SPACING * across])


def distance_to_segment(point: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    t = np.clip(np.dot(point - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
    return float(np.linalg.norm(point - (a + t * (b - a))))


def obstacle_xml(env_id: str, positions, camera: bool = False) -> str:
    """Pusher's own model (never modified) plus the boxes (and the videos' camera), written to a file that outlives
    the env's construction (EzPickle re-creates the env from it); returns its path."""
    import gymnasium.envs.mujoco as gym_mujoco

    name = "pusher_v5.xml" if env_id == "Pusher-v5" else "pusher.xml"
    tree = ET.parse(os.path.join(os.path.dirname(gym_mujoco.__file__), "assets", name))
    world, h = tree.getroot().find("worldbody"), OBSTACLE_HALF_SIZE
    for i, (x, y) in enumerate(() if positions is None else positions):
        box = {"name": f"obstacle_{i}", "type": "box", "size": f"{h} {h} {h}", "pos": f"{x:.6f} {y:.6f} {OBSTACLE_Z}"}
        ET.SubElement(world, "geom", {**box, "contype": "1", "conaffinity": "1", "rgba": "0.2 0.2 0.8 1"})
    if camera:  # the videos' camera: VIDEO_CAMERA's distance from its lookat, seen from +x (image up is -x); no
        # shadows: they triple the time of a frame in software OpenGL
        (x, y, z), d, el = VIDEO_CAMERA["lookat"], VIDEO_CAMERA["distance"], math.radians(VIDEO_CAMERA["elevation"])
        pos = f"{x + d * math.cos(el):.4f} {y} {z - d * math.sin(el):.4f}"
        xyaxes = f"0 1 0 {math.sin(el):.4f} 0 {math.cos(el):.4f}"
        ET.SubElement(world, "camera", {"name": "inform_video", "mode": "fixed", "pos": pos, "xyaxes": xyaxes})
        ET.SubElement(ET.SubElement(tree.getroot(), "visual"), "quality", {"shadowsize": "0"})
    if not _OBSTACLE_DIR:  # one temporary directory per process, removed at exit
        _OBSTACLE_DIR.append(tempfile.mkdtemp(prefix="inform_pusher_obstacle_"))
        atexit.register(shutil.rmtree, _OBSTACLE_DIR[0], True)
    fd, path = tempfile.mkstemp(prefix=f"{env_id.lower().replace('-', '_')}_", suffix=".xml", dir=_OBSTACLE_DIR[0])
    os.close(fd)
    tree.write(path)
    return path


def pusher_with_boxes(env_id: str, obstacles, **render) -> gym.Env:
    """Pusher's own model plus the boxes at the xy `obstacles` (None: none) and, with `render`, the videos' camera."""
    camera = "render_mode" in render
    render = {**render, "camera_name": "inform_video"} if camera else render
    xml = obstacle_xml(env_id, obstacles, camera)
    if env_id == "Pusher-v5":
        return gym.make(env_id, xml_file=xml, **render)
    from gymnasium.envs.mujoco.mujoco_env import MujocoEnv  # Pusher-v4 has no xml_file: its class, another model
    from gymnasium.envs.mujoco.pusher_v4 import PusherEnv

    class PusherObstacleV4(PusherEnv):
        def __init__(self, **kwargs):
            gym.utils.EzPickle.__init__(self, **kwargs)
            space = gym.spaces.Box(-np.inf, np.inf, (23,), np.float64)
            MujocoEnv.__init__(self, xml, 5, observation_space=space, **kwargs)

    return gym.make(dataclasses.replace(gym.spec(env_id), entry_point=PusherObstacleV4), **render)  # v4's spec too


_OBSTACLE_DIR: list[str] = []


# ---------------------------------------------------------------------------------------------------------------------
# ALGO LOGIC: main, Algorithm 1 in the order it runs: the oracle, the day, the night, Eq. 3 and the tests


def main(args: Args, oracle_ckpt, stop: "StopSignals", saved=None, make_teacher=None) -> dict:
    """oracle -> day (the forward phase) -> night (`args.night`, the study's Args give theirs) -> Eq. 3 and the tests.
    `make_teacher(args, env, run_dir)`: the day's teacher in place of the simulated one (a person at a web page)."""
    args = dataclasses.replace(args, **{k: v for k, v in args.sleep_recipe().items() if hasattr(args, k)})  # as ran
    run_start, run_dir, writer, env, evaluator = time.time(), None, None, None, None
    oracle_ckpt = saved["oracle"] if saved is not None else oracle_ckpt  # --sleep-from: the saved day's teacher
    summary = {"time/oracle_s": 0.0, "time/tamer_s": 0.0, "time/sleep_s": 0.0}
    summary["oracle_path"] = oracle_ckpt["path"] if oracle_ckpt is not None else None
    summary["sleep_from"] = os.path.abspath(args.sleep_from) if saved is not None else None
    summary["sleep_variant"] = args.sleep_variant()
    status, failure, phase = "completed", None, "startup"
    try:  # a stop (signal, dead reader) anywhere below finds the except that saves what finished
        run_dir = make_run_dir(f"{args.env_id}__{args.exp_name}__{args.seed}__{int(time.time())}")
        if contact := contact_of(args.env_id, args.contact):  # Pusher's contact, the run's first line
            why = "the arm pushes the object" if contact == CONTACTS[0] else "on mujoco>=3 the arm passes through it"
            print(f"[env] {args.env_id}, the {contact} contact ({why}; --contact {'|'.join(CONTACTS)})", flush=True)
        summary["contact"] = contact
        print(f"run directory: {run_dir}", flush=True)  # only now: bad input was refused, nothing half-written is left
        mujoco_log_in(run_dir)
        StopSignals.check()  # a stop while starting ends here, with a summary in the run directory
        random.seed(args.seed)
        np.random.seed(args.seed)
        torch.manual_seed(args.seed)
        torch.backends.cudnn.deterministic = True
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")  # CUDA matmuls refuse determinism without it
        torch.use_deterministic_algorithms(True)
        torch.set_num_threads(args.num_threads)
        device = torch.device("cuda" if torch.cuda.is_available() and args.cuda else "cpu")
        if args.track:  # Weights & Biases mirrors the TensorBoard events (CleanRL's --track); before the writer
            import wandb

            wandb.init(project=os.environ.get("WANDB_PROJECT", "inform"), sync_tensorboard=True, config=vars(args),
                       name=os.path.basename(run_dir), dir=run_dir, save_code=True)  # fmt: skip
        writer = SummaryWriter(run_dir)
        table = "\n".join(f"|{k}|{v}|" for k, v in vars(args).items())
        writer.add_text("hyperparameters", "|param|value|\n|-|-|\n" + table)
        env, outcome = make_env(args.env_id, args.seed, contact=args.contact), args.outcome()  # how episodes are judged
        evaluator = Evaluator(args.env_id, args.seed, args.random_starts, outcome, writer, args.contact)
        obs_dim, act_dim = int(np.prod(env.observation_space.shape)), int(np.prod(env.action_space.shape))

        # ---- oracle: the simulated teacher (docs/protocol.md, "Oracles and the expert bar")
        phase, t0 = "oracle", time.time()
        if oracle_ckpt is not None:
            oracle_actor, oracle_qf = oracle_from_checkpoint(oracle_ckpt, device)
            print(f"[oracle] loaded {oracle_ckpt['path']} ({oracle_ckpt.get('training_steps', '?')} SAC steps)")
        else:
            print(f"[oracle] training SAC on the env reward for {args.oracle_total_timesteps} steps", flush=True)
            oracle_actor, oracle_qf, summary["sps/oracle"] = train_oracle(
                args.env_id, args.seed, args.oracle_total_timesteps, outcome, writer, device, args.contact
            )
            oracle_ckpt = oracle_checkpoint(oracle_actor, oracle_qf, args.env_id, args.oracle_total_timesteps,
                                            args.seed, contact_of(args.env_id, args.contact))  # fmt: skip
            save_atomic(oracle_ckpt, f"{run_dir}/oracle.pt")  # and the saved day's teacher
        oracle_actor.requires_grad_(False), oracle_qf.requires_grad_(False)
        summary["time/oracle_s"] = time.time() - t0
        evaluator("oracle", oracle_actor, 0, PERIODIC_EVAL_EPISODES)

        # ---- forward phase ("day"): TAMER with simulated feedback, every transition remembered
        phase, t0 = "tamer", time.time() - evaluator.seconds  # the phase's clock stops during its evaluations
        buffer = ReplayBuffer(args.tamer_total_timesteps, obs_dim, act_dim, device)
        if saved is None:  # the day's learner (Day), taught by a person (make_teacher) or by Eq. 4 through Teacher
            day = args.day(device, env.action_space, obs_dim)
            teacher = make_teacher(args, env, run_dir) if make_teacher is not None else day.teacher()
            stats = forward_phase(day, env, oracle_actor, oracle_qf, teacher, outcome, buffer, evaluator, writer)
        else:  # --sleep-from: the saved day's memories and TAMER, and the random streams where the day left them
            day, stats = restore_day(saved, buffer, evaluator, device)
            summary.update(day_settings=saved["day_args"], tamer_h_kwargs=day.h_kwargs)  # whole, as the day saved them
        summary["time/tamer_s"] = time.time() - evaluator.seconds - t0
        summary["sps/tamer"] = stats["feedback/steps"] / max(summary["time/tamer_s"], 1e-9)
        summary.update(stats)  # a saved day's stats bring the day's own time
        save_actor(f"{run_dir}/tamer_actor.pt", day.actor, env_id=args.env_id)
        save_critic(f"{run_dir}/tamer_h.pt", day.h_net, day.h_kwargs, env_id=args.env_id)
        if args.save_buffer:
            day_stats = {**stats, "time/tamer_s": summary["time/tamer_s"], "sps/tamer": summary["sps/tamer"]}
            save_day(f"{run_dir}/day.pt", day, buffer, oracle_ckpt, day_stats, evaluator.generator)

        # ---- sleep phase ("night"): offline IQ-Learn on the buffer, no environment steps
        phase, t0 = "sleep", time.time() - evaluator.seconds
        if args.sleep_seed is not None:  # another night on the same day
            torch.manual_seed(args.sleep_seed)
        tamer = {"h_net": day.h_net, "h_kwargs": day.h_kwargs, "day_settings": day.settings}  # the day's H and flags
        night = args.night(day.actor, device, tamer={**tamer, "ent_coef": stats["losses/tamer_entropy_coef"]})
        summary.update(sleep_phase(night, buffer, args.sleep_gradient_steps, args.sleep_batch_size, evaluator, writer,
                                   device))  # fmt: skip
        q_net, inform_actor, selected = night.q_net, night.actor, night.selected
        summary["time/sleep_s"] = time.time() - evaluator.seconds - t0
        summary["sps/sleep"] = args.sleep_gradient_steps / max(summary["time/sleep_s"], 1e-9)
        save_actor(f"{run_dir}/inform_actor.pt", inform_actor, env_id=args.env_id)
        extra = {"env_id": args.env_id, "gamma": SLEEP_GAMMA, "temperature": args.sleep_temperature}
        save_critic(f"{run_dir}/inform_critic.pt", q_net, {"obs_dim": obs_dim, "act_dim": act_dim}, **extra)
        policies = {"oracle": oracle_actor, "tamer": day.actor, "inform": inform_actor}
        if selected is not None:  # the checkpoint picked offline, beside the last one
            save_actor(f"{run_dir}/inform_selected_actor.pt", selected["actor"], env_id=args.env_id)
            policies["inform_selected"] = selected["actor"]

        # ---- the recovered reward (Eq. 3), then the final evaluation and the obstacle robustness test
        phase = "eval"
        summary.update(final_evaluation(
            buffer, q_net, policies, evaluator, writer, run_dir, env_id=args.env_id, eval_episodes=args.eval_episodes,
            end_step=args.tamer_total_timesteps + args.sleep_gradient_steps, temperature=args.sleep_temperature,
            obstacle_layout=args.obstacle_layout, obstacle_episodes=args.obstacle_episodes,
            authors_test_episodes=args.authors_test_episodes, capture_video=args.capture_video))  # fmt: skip
        writer.flush()  # the events whole before the summary says completed (an error in TensorBoard's thread: here)
    except (KeyboardInterrupt, BrokenPipeError) as e:  # a signal, or the reader of our output died
        status, stop.broken_pipe = "interrupted", isinstance(e, BrokenPipeError)
    except Diverged as e:
        status, summary["error"] = "diverged", str(e)
    except Exception as e:  # the summary records it; a bug then gets its traceback, a full disk its one line
        status, summary["error"] = "failed", f"{type(e).__name__}: {(str(e).strip() or '-').splitlines()[0]}"
        failure = None if isinstance(e, OSError) else e
    if status != "completed" and phase in ("oracle", "tamer", "sleep"):  # how long the cut phase ran
        summary[f"time/{phase}_s"] = time.time() - evaluator.seconds - t0
    summary = end_run(summary, status, phase, run_dir, run_start, evaluator, (env, writer), stop, args.seed, vars(args))
    if failure is not None:
        raise failure
    return summary


# ---------------------------------------------------------------------------------------------------------------------
# TRY NOT TO MODIFY: plumbing. The videos, progress lines, checkpoints, saved days, input checks, the command line


# the videos' camera (--capture-video): a fixed camera added to the model (mujoco 2.3.7 cannot set a free camera's
# lookat) looks down on the table from behind the goal: arm, object (white), goal (red), boxes (blue)
VIDEO_CAMERA = {"lookat": (0.42, -0.2, -0.3), "distance": 1.0, "elevation": -75.0}  # metres, degrees
VIDEO_SIZE = 480  # pixels, square; a multiple of 16, as H.264 wants


GL_HINT = "install EGL (Debian: apt-get install libegl1 libegl-mesa0) or OSMesa (libosmesa6, MUJOCO_GL=osmesa)"


def check_video(env_id: str) -> None:
    """--capture-video, before anything is written: MuJoCo renders headless here and mp4 can be written (InputError,
    one line, if not). Its plumbing is inform_utils/videos.py, imported only under this flag."""
    small = {"render_mode": "rgb_array", "width": 16, "height": 16}
    if (problem := videos().gl_problem(lambda: make_env(env_id, 0, **small))) is not None:
        raise InputError(problem)


def videos():  # --capture-video's plumbing, beside this script in the repository
    try:
        from inform_utils import videos
    except ModuleNotFoundError:
        raise InputError("--capture-video needs the repository's inform_utils/videos.py beside this script") from None
    return videos


def video_env(env_id: str, seed: int, obstacles=None, size: int = VIDEO_SIZE, contact="mujoco-2.3") -> gym.Env:
    """The evaluation env, rendering every reset and step into a list (Gymnasium's RenderCollection)."""
    env = make_env(env_id, seed, obstacles, contact, render_mode="rgb_array", width=size, height=size)
    return gym.wrappers.RenderCollection(env)


def record_videos(env_id, seed, outcome, policies: dict, boxes, reset_seed: int, run_dir: str, contact) -> None:
    """--capture-video: each policy's deterministic episode as the final evaluation runs it (from `reset_seed`) and,
    with the boxes, as the obstacle test does, by the same `evaluate` with a generator of its own. Writes
    videos/{policy}[_obstacle].mp4 and videos/videos.json (frames, final distance, reset seed)."""
    os.makedirs(f"{run_dir}/videos", exist_ok=True)
    record, t = {}, time.time()
    films = [("", None, reset_seed)] + ([("_obstacle", boxes, seed)] if boxes is not None else [])
    for suffix, obstacles, start in films:
        env = video_env(env_id, seed, obstacles, contact=contact)
        for name, actor in policies.items():
            res = evaluate(actor, env, 1, lambda ep, s=start: s, True, torch.Generator(), outcome)
            frames, key = env.render(), f"{name}{suffix}"
            videos().write_video(f"{run_dir}/videos/{key}.mp4", frames, env.metadata["render_fps"])
            record[key] = {"file": f"{key}.mp4", "frames": len(frames), "size": list(frames[0].shape)}
            record[key].update({"final_distance": res["final_distance"], "reset_seed": start})
        env.close()
    write_json_atomic(f"{run_dir}/videos/videos.json", record)
    print(f"[video] {len(record)} episodes filmed in {time.time() - t:.1f}s: {run_dir}/videos/", flush=True)


class Progress:
    """One line per ~5% of a phase: steps, SPS, ETA and what the phase reports (the first line early, at `warmup` +
    500 steps; the ETA from the steps after `warmup`). The clock stops while the `evaluator` runs."""

    def __init__(self, phase: str, total: int, warmup: int = 0, evaluator=None):
        self.phase, self.total, self.every, self.evaluator = phase, total, max(total // 20, 1), evaluator
        self.warmup, self.early, self.warm_start = min(warmup, total), min(warmup + 500, total), None
        self.start = self.clock()

    def clock(self) -> float:  # seconds, without those spent in evaluations
        return time.time() - (self.evaluator.seconds if self.evaluator is not None else 0.0)

    def sps(self, step: int) -> float:
        return step / max(self.clock() - self.start, 1e-9)

    def __call__(self, step: int, **info):
        self.warm_start = self.clock() if step == self.warmup else self.warm_start
        if step % self.every == 0 or step in (self.total, self.early):
            sps = rate = self.sps(step)
            if self.warm_start is not None and step > self.warmup:
                rate = (step - self.warmup) / max(self.clock() - self.warm_start, 1e-9)
            eta = (self.total - step) / max(rate, 1e-9)
            shown = {k: v for k, v in info.items() if v is not None and v == v}  # not measured yet: not shown
            extra = "".join(f" | {k} {v:.4g}" if isinstance(v, float) else f" | {k} {v}" for k, v in shown.items())
            head = f"[{self.phase}] {step}/{self.total} {100 * step // self.total}% | {sps:,.0f} SPS"
            print(f"{head} | ETA {int(eta // 60)}m{int(eta % 60):02d}s{extra}", flush=True)


def env_shapes(env_id: str) -> tuple[int, int]:
    with make_env(env_id, 0) as env:
        return int(np.prod(env.observation_space.shape)), int(np.prod(env.action_space.shape))


def read_checkpoint(path: str, flag: str, env_id: str) -> dict:
    """An oracle (--oracle-path) or a saved actor (tamer_actor.pt, inform_actor.pt or an oracle, for
    inform_utils/evaluate_policy.py) that fits env_id, read with torch.load(weights_only=True): tensors and plain
    values only, never code. InputError otherwise."""
    oracle, where = flag == "--oracle-path", f"{flag} {path}"
    if not os.path.isfile(path):
        raise InputError(f"{where}: no such file" + (" (train one with oracle_train.py)" if oracle else ""))
    check_crc(path, where)
    try:
        ckpt = torch.load(path, weights_only=True, map_location="cpu")
    except Exception as e:
        raise InputError(f"{where}: cannot be read as a weights-only torch checkpoint ({type(e).__name__})") from None
    nets = ["actor_state_dict", "qf_state_dict"] if oracle else ["actor_state_dict"]
    nets = ["state_dict"] if not oracle and isinstance(ckpt, dict) and "actor_state_dict" not in ckpt else nets
    required = ("env_id", "kwargs", *nets, "action_low", "action_high")
    if not isinstance(ckpt, dict) or any(k not in ckpt for k in required) or not isinstance(ckpt["kwargs"], dict):
        raise InputError(f"{where}: not an {'oracle' if oracle else 'actor'} checkpoint (needs {', '.join(required)})")
    if ckpt["env_id"] != env_id:
        raise InputError(f"{where}: trained on {ckpt['env_id']}, not {env_id}; pass --env-id")
    shapes, (obs_dim, act_dim) = (ckpt["kwargs"].get("obs_dim"), ckpt["kwargs"].get("act_dim")), env_shapes(env_id)
    if shapes != (obs_dim, act_dim):
        raise InputError(f"{where}: shapes obs {shapes[0]} act {shapes[1]} do not match {env_id} (obs {obs_dim}, "
                         f"act {act_dim})")  # fmt: skip
    try:
        nets = oracle_from_checkpoint(ckpt, torch.device("cpu")) if oracle else (actor_from_checkpoint(ckpt),)
    except Exception as e:
        why = " ".join(str(e).split())[:80]
        raise InputError(f"{where}: the networks do not load ({type(e).__name__}: {why})") from None
    if not all(torch.isfinite(p).all() for net in nets for p in net.state_dict().values()):
        raise InputError(f"{where}: its networks hold NaN or inf")
    return ckpt


def oracle_from_checkpoint(ckpt: dict, device: torch.device) -> tuple[Actor, QEnsemble]:
    actor, kw = actor_from_checkpoint(ckpt).to(device), ckpt["kwargs"]
    qf = QEnsemble(kw["obs_dim"], kw["act_dim"], kw["hidden"], n=2, layer_norm=kw.get("layer_norm", False)).to(device)
    qf.load_state_dict(ckpt["qf_state_dict"])
    return actor, qf


def actor_from_checkpoint(ckpt: dict) -> Actor:  # a saved actor, or an oracle's
    kw = ckpt["kwargs"]
    actor = Actor(kw["obs_dim"], kw["act_dim"], kw["hidden"], ckpt["action_low"], ckpt["action_high"])
    actor.load_state_dict(ckpt["actor_state_dict" if "actor_state_dict" in ckpt else "state_dict"])
    return actor


def load_oracle(env_id: str, contact: str, path: str | None, train: bool, train_steps: int) -> dict | None:
    """The oracle checkpoint to use (`path`, else the shipped one of the run's `contact`), or None to train one here
    (`train`, or no shipped one found: then for `train_steps`)."""
    gymnasium = contact_of(env_id, contact) == CONTACTS[1]
    name = os.path.join("oracles", f"{env_id}__sac_oracle{'_gymnasium_contact' if gymnasium else ''}.pt")
    if path is None and not train:  # oracles/ beside the script, in the cwd, then above either
        script_up, cwd_up = ([d, *map(str, pathlib.PurePath(d).parents)] for d in (REPO_DIR, os.getcwd()))  # and up
        places = list(dict.fromkeys(os.path.join(d, name) for d in [script_up[0], cwd_up[0], *script_up, *cwd_up]))
        path = next((p for p in places if os.path.isfile(p)), None)
        if path is None:  # a copied script far from the repository: say so before an hour of training starts
            hint = "pass --oracle-path PATH (a checkpoint of oracle_train.py, as in oracles/), or --train-oracle"
            say(f"[oracle] no shipped teacher found (looked for {name} beside the script, in the working directory and "
                f"in every directory above them: {', '.join(places)}); training one here for "
                f"{train_steps} env steps (~100 steps/s on one core). To skip this, {hint}",
                sys.stderr)  # fmt: skip
    if path is not None:
        check_contact(ckpt := read_checkpoint(path, "--oracle-path", env_id), env_id, contact, f"--oracle-path {path}")
        return {**ckpt, "path": path}


def state_dict_cpu(net: nn.Module) -> dict:
    return {k: v.detach().cpu().clone() for k, v in net.state_dict().items()}


def save_actor(path: str, actor: Actor, **extra) -> None:
    kwargs = {"obs_dim": actor.fc1.in_features, "act_dim": actor.fc_mean.out_features, "hidden": actor.fc1.out_features}
    low, high = (actor.action_bias - actor.action_scale).cpu(), (actor.action_bias + actor.action_scale).cpu()
    ckpt = {"state_dict": state_dict_cpu(actor), "kwargs": kwargs, "action_low": low, "action_high": high}
    save_atomic({**ckpt, **extra}, path)


def save_critic(path: str, q_net: QEnsemble, kwargs: dict, **extra) -> None:  # kwargs: what rebuilds it, whole
    shape = {"hidden": q_net.fc1.weight.shape[2], "n": q_net.n, "layer_norm": q_net.norm is not None}
    save_atomic({"state_dict": state_dict_cpu(q_net), "kwargs": {**shape, **kwargs}, **extra}, path)


def oracle_checkpoint(actor: Actor, qf: QEnsemble, env_id: str, steps: int, seed: int, contact) -> dict:
    obs_dim, act_dim = actor.fc1.in_features, actor.fc_mean.out_features
    ckpt = {"algorithm": "sac", "env_id": env_id, "obs_shape": [obs_dim], "act_shape": [act_dim]}
    ckpt["kwargs"] = {"obs_dim": obs_dim, "act_dim": act_dim, "hidden": HIDDEN_SIZE}
    ckpt["action_low"] = (actor.action_bias - actor.action_scale).cpu()
    ckpt["action_high"] = (actor.action_bias + actor.action_scale).cpu()
    ckpt.update(actor_state_dict=state_dict_cpu(actor), qf_state_dict=state_dict_cpu(qf), random_starts=True)
    return {**ckpt, "training_steps": steps, "training_seed": seed, "contact": contact}


# saved days (--save-buffer, --sleep-from): a day is deterministic, so it is saved once and slept on many times
DAY_FORMAT = "inform-day-2"
DAY_ARGS = tuple(Args().day_settings())  # the flags that shape a day (marked DAY): a saved day records them
DAY_TENSORS = ("obs", "actions", "next_obs", "feedback", "terminated", "success", "driven")
# what shaped a day and is a constant now, under the flag names that days record it by
DAY_CONSTANTS = {"hidden_size": HIDDEN_SIZE, "eval_frequency": EVAL_FREQUENCY, "tamer_policy_lr": TAMER_POLICY_LR}
DAY_CONSTANTS["tamer_policy_frequency"] = 1


def save_day(path, day: Day, buffer: ReplayBuffer, oracle_ckpt, stats, generator) -> None:
    """The day as plain tensors and values (torch.load(weights_only=True) reads it): the memories, the episode table,
    the day's learner (Day.saved: its settings whole, H and the actor with their constructor arguments), the
    teacher, the day's stats and the random states the night goes on from."""
    record = {key: getattr(buffer, key)[: buffer.size].cpu().clone() for key in DAY_TENSORS}
    starts, ends, shortfalls = zip(*buffer.episodes, strict=True)
    record.update(day.saved(), format=DAY_FORMAT, script=os.path.basename(__file__), env_id=day.settings["env_id"])
    record.update(seed=day.settings["seed"], day_stats=stats, episode_success=buffer.success[list(starts)])
    record.update(episode_start=torch.tensor(starts), episode_end=torch.tensor(ends))
    record["episode_shortfall"] = torch.tensor(shortfalls, dtype=torch.float64)  # the distance, or minus the return
    record.update(oracle={k: v for k, v in oracle_ckpt.items() if k != "path"}, oracle_path=oracle_ckpt.get("path"))
    record.update(torch_rng=torch.get_rng_state(), cuda_rng=torch.cuda.get_rng_state() if buffer.obs.is_cuda else None)
    save_atomic({**record, "evaluator_rng": generator.get_state()}, path)


def load_day(run_dir: str, args_type: type = Args) -> dict:
    """--sleep-from: RUN_DIR/day.pt, read with weights_only=True and checked: its memories (check_day), and its
    learner rebuilt from what the day saved (Day, as "learner"), with finite networks; InputError otherwise. The
    day's settings stay whole in "day_args", known to `args_type` or not, each a JSON value (of its flag's type)."""
    path = os.path.join(run_dir, "day.pt")
    if not os.path.isfile(path):
        raise InputError(f"--sleep-from {run_dir}: no day.pt there (make one with --save-buffer)")
    check_crc(path, f"--sleep-from {path}")
    try:
        day = torch.load(path, weights_only=True, map_location="cpu")
    except Exception as e:
        raise InputError(f"--sleep-from {path}: not a readable weights-only day ({type(e).__name__})") from None
    if isinstance(day, dict) and day.get("format") == "inform-day-1" and "episode_final_distance" in day:
        # saved before other tasks: Pusher's final distances, and episodes judged by Outcome's defaults
        day["episode_shortfall"], day["format"] = day.pop("episode_final_distance"), DAY_FORMAT
        day["day_args"] = {"success_info_key": "reward_dist", "success_return": None, **day["day_args"]}
    if not isinstance(day, dict) or day.get("format") != DAY_FORMAT:  # this script's or a copy's, under any name
        raise InputError(f"--sleep-from {path}: not a day saved by this script's --save-buffer ({DAY_FORMAT})")
    for part, hints in (("day_args", typing.get_type_hints(args_type, include_extras=True)), ("day_stats", {})):
        check_settings(day.get(part), hints, f"--sleep-from {path}: {part}")  # they go into summary.json
    ran = {k: day["day_args"].get(k, v) for k, v in DAY_CONSTANTS.items()}
    if ran != DAY_CONSTANTS:
        raise InputError(f"--sleep-from {path}: the day ran with {ran}, this script has {DAY_CONSTANTS}")
    day.setdefault("driven", torch.zeros(len(day.get("obs", ())), dtype=torch.bool))  # saved before a person drove
    check_day(day, path)
    day["oracle"]["path"] = day["oracle_path"] or f"the oracle saved in {path}"
    if "kwargs" not in day["tamer_h"]:  # saved before days kept their networks' arguments: today's (checked above)
        shapes = {"obs_dim": day["obs"].shape[1], "act_dim": day["actions"].shape[1], "hidden": HIDDEN_SIZE}
        day["tamer_h"]["kwargs"] = {**shapes, "n": day["tamer_h"].pop("n")}
        day["tamer_actor"]["kwargs"] = {**shapes, **{k: day["oracle"][k] for k in ("action_low", "action_high")}}
    try:
        check_settings(day["tamer_h"]["kwargs"], typing.get_type_hints(QEnsemble.__init__), f"{path}: tamer_h kwargs")
        learner = day["learner"] = Day(day["day_args"], torch.device("cpu"), saved=day)
    except (TypeError, RuntimeError, KeyError) as e:  # networks built, or settings kept, by another script
        why = " ".join(str(e).split())[:200]
        raise InputError(f"--sleep-from {path}: this script cannot rebuild the day's TAMER ({type(e).__name__}: "
                         f"{why}); sleep on it with the script that made it") from None  # fmt: skip
    if not all(torch.isfinite(t).all() for net in (learner.h_net, learner.actor) for t in net.state_dict().values()):
        raise InputError(f"--sleep-from {path}: the day's TAMER networks hold NaN or inf")
    return day


def check_day(day: dict, path: str) -> None:
    """A day as --save-buffer writes it: tensors of shapes that fit its env, finite values, 0/1 terminal flags, and
    episodes that tile the buffer. InputError, naming the first part that is not."""
    try:
        n, (obs_dim, act_dim), table = day["obs"].shape[0], env_shapes(day["env_id"]), day["episode_start"].shape
        starts, ends, term = day["episode_start"], day["episode_end"], day["terminated"]
        shapes = {"obs": (n, obs_dim), "next_obs": (n, obs_dim), "actions": (n, act_dim), "episode_end": table}
        shapes.update(dict.fromkeys(("feedback", "terminated", "success", "driven"), (n,)), episode_shortfall=table)
        checks = {"shapes": all(day[k].shape == shape for k, shape in shapes.items()) and len(table) == 1}
        checks["values"] = all(torch.isfinite(day[k]).all() for k in ("obs", "next_obs", "actions", "feedback"))
        checks["terminated flags"] = bool(((term == 0) | (term == 1)).all())
        tiled = starts[0] == 0 and ends[-1] == n and torch.equal(starts[1:], ends[:-1]) and bool((starts < ends).all())
        checks["episode table"] = bool(day["episode_success"].shape == table and tiled)
    except (KeyError, AttributeError, TypeError, IndexError, RuntimeError, ValueError) as e:
        raise InputError(f"--sleep-from {path}: not a day as --save-buffer writes it ({type(e).__name__})") from None
    if bad := [what for what, ok in checks.items() if not ok]:
        raise InputError(f"--sleep-from {path}: the day's {bad[0]} are not what --save-buffer writes")


def restore_day(saved: dict, buffer: ReplayBuffer, evaluator, device) -> tuple["Day", dict]:
    """The saved day back in place of the forward phase: the buffer, the day's learner (load_day rebuilt it), the
    day's stats, and the random states where the day left them."""
    n, day = saved["obs"].shape[0], saved["learner"]
    for key in DAY_TENSORS:
        getattr(buffer, key)[:n] = saved[key].to(device)
    table = (saved["episode_start"].tolist(), saved["episode_end"].tolist(), saved["episode_shortfall"].tolist())
    buffer.size, buffer.episodes = n, list(zip(*table, strict=True))
    day.h_net.to(device), day.actor.to(device)
    torch.set_rng_state(saved["torch_rng"])
    if saved.get("cuda_rng") is not None and device.type == "cuda":
        torch.cuda.set_rng_state(saved["cuda_rng"])
    evaluator.generator.set_state(saved["evaluator_rng"])
    print(f"[day] {n} transitions, {len(buffer.episodes)} episodes from the saved day", flush=True)
    return day, dict(saved["day_stats"])


def check_args(args: Args) -> None:
    """What tyro cannot know: ranges (declared beside each flag), the run name, the env id, flags that exclude each
    other. Raises InputError."""
    hints = typing.get_type_hints(type(args), include_extras=True)
    for f in fields(args):
        value = getattr(args, f.name)
        spec = next((m for m in getattr(hints[f.name], "__metadata__", ()) if isinstance(m, In)), None)
        if spec is not None and value is not None and value not in spec:  # a count: ">= 1"; a float: its interval
            bound = f" and < {spec.high}" if spec.high < math.inf else ""
            must = f">= {spec.low}{bound}" if isinstance(value, int) else spec
            raise InputError(f"--{f.name.replace('_', '-')} must be {must}, got {value}")
    check_run_name(args.env_id, args.exp_name, args.seed)
    if args.num_threads > (cpus := os.cpu_count() or 1):  # torch segfaults on absurd counts
        raise InputError(f"--num-threads {args.num_threads} is more than this machine's {cpus} CPUs")
    if args.track and importlib.util.find_spec("wandb") is None:
        raise InputError("--track needs Weights & Biases: `pip install wandb`, or run without --track")
    check_env(args)
    steps = f"--tamer-total-timesteps ({args.tamer_total_timesteps})"
    if args.tamer_learning_starts >= args.tamer_total_timesteps:
        raise InputError(f"--tamer-learning-starts ({args.tamer_learning_starts}) must be below {steps}")
    if max(args.tamer_batch_size, args.sleep_batch_size) > args.tamer_total_timesteps:
        batches = f"--tamer-batch-size ({args.tamer_batch_size}) and --sleep-batch-size ({args.sleep_batch_size})"
        raise InputError(f"{batches} must not exceed {steps}, the size of the buffer")
    if args.oracle_path is not None and args.train_oracle:
        raise InputError("--oracle-path and --train-oracle exclude each other; pass one of them")
    if args.sleep_from is not None and args.save_buffer:
        raise InputError("--save-buffer and --sleep-from exclude each other: a night on a saved day saves no new day")


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


def check_env(args: Args) -> None:
    """--env-id: a Gymnasium env with a flat observation and continuous actions, whose episodes can be judged (one
    random step shows whether `info` has --success-info-key). Raises InputError."""
    try:
        env = make_env(args.env_id, args.seed)
    except Exception as e:  # unknown id, a missing extra (box2d, ...), a version that needs other packages
        first = (str(e).strip() or type(e).__name__).splitlines()[0][:160]
        if os.environ.get("MUJOCO_GL") and re.search(r"\bgl[A-Z]|OSMesa|EGL|GLFW|MUJOCO_GL", str(e)):  # GL, not the id
            raise InputError(f"MUJOCO_GL={os.environ['MUJOCO_GL']}: MuJoCo cannot load that GL backend ({first}); "
                             f"{GL_HINT}, or unset MUJOCO_GL") from None  # fmt: skip
        raise InputError(f"--env-id {args.env_id}: Gymnasium cannot make it ({first})") from None
    try:
        obs_space, act_space, key = env.observation_space, env.action_space, args.success_info_key
        if not isinstance(act_space, gym.spaces.Box):
            raise InputError(f"--env-id {args.env_id}: its actions are {type(act_space).__name__}, not continuous "
                             "(Box); discrete tasks run in inform_dqn_gridworld.py")  # fmt: skip
        if not isinstance(obs_space, gym.spaces.Box) or len(obs_space.shape) != 1:
            raise InputError(f"--env-id {args.env_id}: needs a flat Box observation, not {obs_space}")
        if args.success_return is None:
            env.reset(seed=0)
            info = env.step(act_space.sample())[4]
            if key not in info:
                has = f"it has: {', '.join(sorted(info)) or 'none'}"
                hint = "pass --success-info-key KEY, or --success-return R to judge episodes by return"
                raise InputError(f"--env-id {args.env_id}: its info has no {key!r} for a final distance ({has}); "
                                 f"{hint}")  # fmt: skip
    finally:
        env.close()


def mujoco_log_in(run_dir: str) -> None:
    """MuJoCo's warnings (an unstable simulation, say) into run_dir/MUJOCO_LOG.TXT: left to itself, MuJoCo prints them
    and writes MUJOCO_LOG.TXT into the working directory, outside the run. The run's error line says what failed."""
    import mujoco

    def warning(message: str) -> None:
        with open(os.path.join(run_dir, "MUJOCO_LOG.TXT"), "a") as f:
            f.write(message.rstrip() + "\n")

    if hasattr(mujoco, "set_mju_user_warning"):  # an older MuJoCo: its default stays
        mujoco.set_mju_user_warning(warning)


def mujoco_major() -> int:
    return int(importlib.import_module("mujoco").__version__.split(".")[0])


def contact_of(env_id: str, contact: str) -> str | None:
    """The contact a run has, as recorded: none off Pusher; MuJoCo 2.3's under mujoco<3, where Gymnasium's is it."""
    return None if env_id not in PUSHER_IDS else "mujoco-2.3" if mujoco_major() < 3 else contact


def made_under(record: dict, env_id: str) -> str | None:  # before the setting: Pusher-v4 on 2.3.7, Pusher-v5 on 4
    return record.get("contact", {"Pusher-v4": CONTACTS[0], "Pusher-v5": CONTACTS[1]}.get(env_id))


def check_contact(record: dict, env_id: str, contact: str, where: str) -> None:
    """A teacher or a saved day runs only under the contact it was made under: InputError, one line, if not."""
    ours, theirs = contact_of(env_id, contact), made_under(record, env_id)
    if None not in (theirs, ours) and theirs != ours:
        raise InputError(f"{where}: made under the {theirs} contact, and this run's is {ours}; pass --contact "
                         f"{theirs}, or a teacher or day made under {ours}")  # fmt: skip


def print_results(summary: dict, run_dir: str) -> None:
    for p in POLICIES if summary["status"] == "completed" else ():
        e = {k[len("eval/") :].replace(p, "@"): v for k, v in summary.items() if k.startswith("eval/")}
        obstacle, std = e.get("obstacle/@_final_distance"), e.get("obstacle/@_final_distance_std")
        obstacle = "" if obstacle is None else f" | obstacle distance {obstacle:.3f} +- {std:.3f}"
        say(f"{p:>6}: return {e['@_return']:.2f} (sampled {e['@_return_sampled']:.2f}) | final distance "
            f"{e['@_final_distance']:.3f} | success {e['@_success_rate']:.2f}{obstacle}")  # fmt: skip
    if summary["status"] == "completed":
        say(" | ".join(f"{k} {v:.0f}" for k, v in summary.items() if k.startswith(("time/", "sps/"))))
    say(f"{summary['status']} in {summary['wall_time_s']:.1f}s; summary: {run_dir}/summary.json")


def cli(args: Args, make_teacher=None) -> int:
    """The command line after tyro: a saved day, the checks, then the run; returns the exit code. The study
    module (inform_utils/sleep_variants_pusher.py) runs it with its own Args (and their night), the web page
    (inform_utils/browser_pusher.py) with its own Args and `make_teacher`."""
    saved = oracle_ckpt = None  # a saved day brings its own teacher
    try:
        if args.sleep_from is not None:  # the day's flags replace this run's: its numbers are the day's
            saved = load_day(args.sleep_from, type(args))
            flags = {f.name for f in fields(args)}  # but the contact: a day under another one is refused, below
            args = dataclasses.replace(args, **{k: v for k, v in saved["day_args"].items() if k in flags - {"contact"}})
            check_contact(saved["day_args"], args.env_id, args.contact, f"--sleep-from {args.sleep_from}")
            print(f"[day] sleeping on the day saved in {args.sleep_from} ({args.env_id}, seed {args.seed}, "
                  f"{saved['obs'].shape[0]} steps); its day flags replace this run's", flush=True)  # fmt: skip
            if unknown := {k: v for k, v in saved["day_args"].items() if k not in {*flags, *DAY_CONSTANTS}}:
                say(f"[day] the day's settings unknown to this script, kept in summary.json: {cut(unknown, 200)}")
        check_args(args)
        if contact_of(args.env_id, args.contact):  # under mujoco<3 Gymnasium's contact is 2.3's: recorded as what runs
            args = dataclasses.replace(args, contact=contact_of(args.env_id, args.contact))
        if args.capture_video:
            check_video(args.env_id)
        if saved is None:
            teacher = args.oracle_path, args.train_oracle, args.oracle_total_timesteps
            oracle_ckpt = load_oracle(args.env_id, args.contact, *teacher)
        check_writable("runs")
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    # TensorBoard's writer thread on a full disk: no traceback from it; main hears its error at its next write
    threading.excepthook = lambda h: "tensorboard" in type(h.thread).__module__ or threading.__excepthook__(h)
    stop = StopSignals()
    summary = main(args, oracle_ckpt, stop, saved, make_teacher)
    gc.freeze()  # the interpreter's last collections over torch's objects take seconds on a busy machine; skip them
    return stop.exit_code(summary["status"])


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
    sys.exit(cli(tyro.cli(Args)))  # a malformed flag: tyro's own message, exit 2
