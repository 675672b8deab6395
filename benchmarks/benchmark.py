"""Side-by-side speed benchmark: our scripts against a plain eager CleanRL-style reference, in one run.

For each Pusher phase (oracle SAC training, TAMER forward phase, sleep phase) it measures, interleaved over
`--repeats` rounds and reported as medians:
- ours: `inform_sac_pusher.py` run for real with small budgets (its own per-phase throughput from summary.json);
- the reference: the same loops written inside this file the simplest CleanRL way (separate Q modules, a numpy
  replay buffer copied to tensors every step, `.item()` every step, default Adam, a parameter loop for the soft
  update), with the same hyperparameters and budgets;
- the raw env step rate, and each process's peak memory.
It also times the full default gridworld pipeline. Only ratios taken in one run count: these machines are noisy.

The roofline (`--roofline`): each phase's own code (`train_oracle`, `forward_phase`, `sleep_phase`, imported from the
script) runs in this process for two budgets past learning starts, and the difference per step gives
- the FLOPs of one step, counted by `torch.utils.flop_counter.FlopCounterMode`;
- the achieved GFLOP/s (those FLOPs over the measured seconds per step; `--clock process` counts the CPU seconds this
  process got, which on a shared machine is what it ran, `wall` the elapsed ones);
- the one-thread peak at the phase's own matmul shapes: the shapes recorded by `torch.profiler` (record_shapes), each
  timed in a hot loop in the same run; peak = the step's matmul FLOPs over the time those calls take in the hot loop;
- `roofline/{phase}_fraction` = achieved / peak, and the top ops (self time) of the longer profiled run (its setup
  and random-action steps included).
`--baseline-script` measures another copy of the script (e.g. the previous commit's) side by side, interleaved, and
`--variants threads` the opt-in speed (two threads; or any boolean flag of the script) against the default,
interleaved. The baseline must have the same phase functions as the script (the night as an object, `Args.night`:
the commit that made it one on).

    python benchmarks/benchmark.py                # about 5 minutes on 2 cores
    python benchmarks/benchmark.py --repeats 1 --oracle-steps 600 --tamer-steps 600 --sleep-steps 200   # a smoke run
    git show HEAD~1:inform_sac_pusher.py > /tmp/before/inform_sac_pusher.py && ln -s $PWD/oracles /tmp/before/
    python benchmarks/benchmark.py --no-side-by-side --baseline-script /tmp/before/inform_sac_pusher.py \
        --variants threads

Writes benchmarks/results.json (keys `{phase}_ratio` = ours / reference for oracle, tamer, sleep,
`gridworld_pipeline_s`, and `roofline/...`) and prints tables.
"""

import collections
import contextlib
import glob
import importlib.util
import inspect
import io
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass

import gymnasium as gym
import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F
import tyro

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ORACLE_RANDOM_STEPS = 5000  # inform_sac_pusher.py's ORACLE_SAC["learning_starts"]: its oracle's random steps


@dataclass
class Args:
    env_id: str = "Pusher-v5"
    """the Pusher version to measure"""
    repeats: int = 3
    """interleaved rounds (ours, reference, ours, reference, ...); the table shows medians"""
    oracle_steps: int = 1500
    """SAC oracle training steps per measurement"""
    tamer_steps: int = 1500
    """TAMER forward-phase env steps per measurement"""
    sleep_steps: int = 500
    """sleep-phase gradient steps per measurement"""
    learning_starts: int = 256
    """random-action steps before updates, in both oracle and TAMER phases (small: the updates are measured)"""
    num_threads: int = 1
    """torch threads, for ours and the reference alike"""
    env_steps: int = 5000
    """steps of the raw env measurement"""
    gridworld: bool = True
    """also time the full default gridworld pipeline"""
    output: str = os.path.join(REPO, "benchmarks", "results.json")
    """where the results go"""
    reference: bool = False
    """internal: run the reference loops in this process and print their throughput as JSON"""
    side_by_side: bool = True
    """the subprocess comparison with the eager reference (and the gridworld pipeline)"""
    roofline: bool = True
    """measure each Pusher phase against the machine's own matmul peak, in this process"""
    roofline_steps: tuple[int, int] = (40, 200)
    """the two budgets (steps past learning starts; gradient steps for the sleep) whose difference is one step"""
    roofline_repeats: int = 3
    """interleaved timing rounds of the roofline (and of the baseline and variants); medians"""
    profile_steps: tuple[int, int] = (10, 40)
    """the two budgets profiled with record_shapes (the shapes per step, and the top-ops table)"""
    clock: str = "process"
    """process: CPU seconds of this process (what it ran on a shared machine); wall: elapsed seconds"""
    baseline_script: str | None = None
    """another inform_sac_pusher.py (e.g. the previous commit's, oracles/ beside it), timed interleaved with ours"""
    variants: tuple[str, ...] = ()
    """opt-in speed to time against the default, interleaved: threads (two), or any boolean flag of the script"""


# ---------------------------------------------------------------------------------------------------------------
# the reference: CleanRL's sac_continuous_action.py networks and loops, plain eager


LOG_STD_MIN, LOG_STD_MAX = -5, 2


class SoftQNetwork(nn.Module):
    def __init__(self, obs_dim, act_dim, hidden=256):
        super().__init__()
        self.fc1 = nn.Linear(obs_dim + act_dim, hidden)
        self.fc2 = nn.Linear(hidden, hidden)
        self.fc3 = nn.Linear(hidden, 1)

    def forward(self, x, a):
        x = torch.cat([x, a], 1)
        x = F.relu(self.fc1(x))
        x = F.relu(self.fc2(x))
        return self.fc3(x)


class Actor(nn.Module):
    def __init__(self, obs_dim, act_dim, low, high, hidden=256):
        super().__init__()
        self.fc1 = nn.Linear(obs_dim, hidden)
        self.fc2 = nn.Linear(hidden, hidden)
        self.fc_mean = nn.Linear(hidden, act_dim)
        self.fc_logstd = nn.Linear(hidden, act_dim)
        self.register_buffer("action_scale", torch.tensor((high - low) / 2.0, dtype=torch.float32))
        self.register_buffer("action_bias", torch.tensor((high + low) / 2.0, dtype=torch.float32))

    def forward(self, x):
        x = F.relu(self.fc1(x))
        x = F.relu(self.fc2(x))
        log_std = torch.tanh(self.fc_logstd(x))
        return self.fc_mean(x), LOG_STD_MIN + 0.5 * (LOG_STD_MAX - LOG_STD_MIN) * (log_std + 1)

    def get_action(self, x):
        mean, log_std = self(x)
        normal = torch.distributions.Normal(mean, log_std.exp())
        x_t = normal.rsample()
        y_t = torch.tanh(x_t)
        action = y_t * self.action_scale + self.action_bias
        log_prob = normal.log_prob(x_t) - torch.log(self.action_scale * (1 - y_t.pow(2)) + 1e-6)
        return action, log_prob.sum(1, keepdim=True), torch.tanh(mean) * self.action_scale + self.action_bias


class NumpyBuffer:
    """CleanRL-style replay: numpy arrays, each sample converted to tensors."""

    def __init__(self, n, obs_dim, act_dim):
        self.obs, self.next_obs = np.zeros((n, obs_dim), np.float32), np.zeros((n, obs_dim), np.float32)
        self.actions, self.rewards = np.zeros((n, act_dim), np.float32), np.zeros((n, 1), np.float32)
        self.dones, self.size = np.zeros((n, 1), np.float32), 0

    def add(self, obs, next_obs, action, reward, done):
        i = self.size
        self.obs[i], self.next_obs[i], self.actions[i], self.rewards[i], self.dones[i] = (
            obs,
            next_obs,
            action,
            reward,
            done,
        )
        self.size += 1

    def sample(self, batch_size, idx=None):
        idx = np.random.randint(0, self.size, batch_size) if idx is None else idx
        return [torch.tensor(x[idx]) for x in (self.obs, self.actions, self.next_obs, self.rewards, self.dones)]


def soft_update(target, source, tau):
    for param, target_param in zip(source.parameters(), target.parameters(), strict=True):
        target_param.data.copy_(tau * param.data + (1 - tau) * target_param.data)


def sac_update(batch, qf1, qf2, qf1_t, qf2_t, actor, q_opt, pi_opt, a_opt, log_alpha, target_entropy, step, gamma=0.99):
    """One CleanRL SAC update (critic every step, actor and alpha every 2nd); `.item()` as CleanRL logs."""
    obs, actions, next_obs, rewards, dones = batch
    alpha = log_alpha.exp().item()
    with torch.no_grad():
        next_a, next_logp, _ = actor.get_action(next_obs)
        min_next = torch.min(qf1_t(next_obs, next_a), qf2_t(next_obs, next_a)) - alpha * next_logp
        target = rewards.flatten() + (1 - dones.flatten()) * gamma * min_next.view(-1)
    qf_loss = F.mse_loss(qf1(obs, actions).view(-1), target) + F.mse_loss(qf2(obs, actions).view(-1), target)
    q_opt.zero_grad()
    qf_loss.backward()
    q_opt.step()
    losses = [qf_loss.item()]
    if step % 2 == 0:
        pi, logp, _ = actor.get_action(obs)
        actor_loss = (alpha * logp - torch.min(qf1(obs, pi), qf2(obs, pi))).mean()
        pi_opt.zero_grad()
        actor_loss.backward()
        pi_opt.step()
        with torch.no_grad():
            _, logp, _ = actor.get_action(obs)
        alpha_loss = (-log_alpha.exp() * (logp + target_entropy)).mean()
        a_opt.zero_grad()
        alpha_loss.backward()
        a_opt.step()
        losses += [actor_loss.item(), alpha_loss.item()]
    soft_update(qf1_t, qf1, 0.005)
    soft_update(qf2_t, qf2, 0.005)
    return losses


def reference_oracle(args: Args, env) -> float:
    """CleanRL SAC on the env reward; returns env steps per second."""
    obs_dim, act_dim = env.observation_space.shape[0], env.action_space.shape[0]
    actor = Actor(obs_dim, act_dim, env.action_space.low, env.action_space.high)
    qf1, qf2, qf1_t, qf2_t = (SoftQNetwork(obs_dim, act_dim) for _ in range(4))
    qf1_t.load_state_dict(qf1.state_dict())
    qf2_t.load_state_dict(qf2.state_dict())
    q_opt = torch.optim.Adam(list(qf1.parameters()) + list(qf2.parameters()), lr=1e-3)
    pi_opt = torch.optim.Adam(actor.parameters(), lr=3e-4)
    log_alpha = torch.zeros(1, requires_grad=True)
    a_opt = torch.optim.Adam([log_alpha], lr=1e-3)
    rb = NumpyBuffer(args.oracle_steps, obs_dim, act_dim)
    obs, _ = env.reset(seed=1)
    start = time.time()
    for step in range(args.oracle_steps):
        if step < args.learning_starts:
            action = env.action_space.sample()
        else:
            action = actor.get_action(torch.Tensor(obs).unsqueeze(0))[0].detach().numpy()[0]
        next_obs, reward, terminated, truncated, _ = env.step(action)
        rb.add(obs, next_obs, action, reward, terminated)
        obs = next_obs if not (terminated or truncated) else env.reset()[0]
        if step >= args.learning_starts:
            sac_update(rb.sample(256), qf1, qf2, qf1_t, qf2_t, actor, q_opt, pi_opt, a_opt, log_alpha, -act_dim, step)
    return args.oracle_steps / (time.time() - start)


def reference_tamer(args: Args, env) -> float:
    """TAMER with an oracle query every step, H as two separate critics regressed on h; env steps per second."""
    obs_dim, act_dim = env.observation_space.shape[0], env.action_space.shape[0]
    low, high = env.action_space.low, env.action_space.high
    oracle_actor, oracle_q1, oracle_q2 = (
        Actor(obs_dim, act_dim, low, high),
        *(SoftQNetwork(obs_dim, act_dim) for _ in range(2)),
    )
    actor = Actor(obs_dim, act_dim, low, high)
    h1, h2 = SoftQNetwork(obs_dim, act_dim), SoftQNetwork(obs_dim, act_dim)
    h_opt = torch.optim.Adam(list(h1.parameters()) + list(h2.parameters()), lr=1e-3)
    pi_opt = torch.optim.Adam(actor.parameters(), lr=3e-4)
    log_alpha = torch.zeros(1, requires_grad=True)
    a_opt = torch.optim.Adam([log_alpha], lr=1e-3)
    rb = NumpyBuffer(args.tamer_steps, obs_dim, act_dim)
    obs, _ = env.reset(seed=1)
    start = time.time()
    for step in range(args.tamer_steps):
        obs_t = torch.Tensor(obs).unsqueeze(0)
        if step < args.learning_starts:
            action = env.action_space.sample()
        else:
            action = actor.get_action(obs_t)[0].detach().numpy()[0]
        with torch.no_grad():  # the teacher: Eq. 4 with the oracle's mean action
            a_star = oracle_actor.get_action(obs_t)[2]
            a_t = torch.Tensor(action).unsqueeze(0)
            q_sa = torch.min(oracle_q1(obs_t, a_t), oracle_q2(obs_t, a_t)).item()
            q_best = torch.min(oracle_q1(obs_t, a_star), oracle_q2(obs_t, a_star)).item()
        alpha_t = 0.99 + 0.002 * step / args.tamer_steps
        h = float(q_sa >= q_best - (1 - alpha_t) * abs(q_best))
        next_obs, _, terminated, truncated, _ = env.step(action)
        rb.add(obs, next_obs, action, h, terminated)
        obs = next_obs if not (terminated or truncated) else env.reset(seed=1)[0]
        if step >= args.learning_starts:
            b_obs, b_act, _, b_h, _ = rb.sample(256)
            h_loss = F.mse_loss(h1(b_obs, b_act), b_h) + F.mse_loss(h2(b_obs, b_act), b_h)
            h_opt.zero_grad()
            h_loss.backward()
            h_opt.step()
            alpha = log_alpha.exp().item()
            pi, logp, _ = actor.get_action(b_obs)
            actor_loss = (alpha * logp - torch.min(h1(b_obs, pi), h2(b_obs, pi))).mean()
            pi_opt.zero_grad()
            actor_loss.backward()
            pi_opt.step()
            alpha_loss = (-log_alpha.exp() * (logp.detach() - act_dim)).mean()
            a_opt.zero_grad()
            alpha_loss.backward()
            a_opt.step()
            _ = (h_loss.item(), actor_loss.item(), alpha_loss.item())
    return args.tamer_steps / (time.time() - start)


def reference_sleep(args: Args, env) -> float:
    """Continuous IQ-Learn (Eq. 2) on a filled buffer: one critic, its target, an actor; gradient steps per second."""
    obs_dim, act_dim = env.observation_space.shape[0], env.action_space.shape[0]
    rb = NumpyBuffer(10000, obs_dim, act_dim)
    rb.obs[:], rb.next_obs[:] = np.random.randn(2, 10000, obs_dim)
    rb.actions[:], rb.size = np.random.uniform(-2, 2, (10000, act_dim)), 10000
    actor = Actor(obs_dim, act_dim, env.action_space.low, env.action_space.high)
    q, q_t = SoftQNetwork(obs_dim, act_dim), SoftQNetwork(obs_dim, act_dim)
    q_t.load_state_dict(q.state_dict())
    q_opt, pi_opt = torch.optim.Adam(q.parameters(), lr=3e-4), torch.optim.Adam(actor.parameters(), lr=5e-6)
    temp, gamma = 0.01, 0.99
    start = time.time()
    for _ in range(args.sleep_steps):
        expert = rb.sample(256, np.random.randint(0, 5000, 256))
        replay = rb.sample(256)
        obs, actions, next_obs, _, dones = (torch.cat([e, r]) for e, r in zip(expert, replay, strict=True))
        with torch.no_grad():
            next_a, next_logp, _ = actor.get_action(next_obs)
            y = (1 - dones) * gamma * (q_t(next_obs, next_a) - temp * next_logp)
            a, logp, _ = actor.get_action(obs)
        v = q(obs, a) - temp * logp
        q_sa = q(obs, actions)
        loss = -(q_sa - y)[:256].mean() + (v - y).mean() + 0.5 * (q_sa - y).pow(2).mean()
        q_opt.zero_grad()
        loss.backward()
        q_opt.step()
        pi, logp, _ = actor.get_action(replay[0])
        actor_loss = (temp * logp - q(replay[0], pi)).mean()
        pi_opt.zero_grad()
        actor_loss.backward()
        pi_opt.step()
        soft_update(q_t, q, 0.005)
        _ = (loss.item(), actor_loss.item())
    return args.sleep_steps / (time.time() - start)


# ---------------------------------------------------------------------------------------------------------------
# the roofline: the script's own phase code, in this process, against the matmul peak at its own shapes


MATMULS = ("aten::mm", "aten::addmm", "aten::bmm", "aten::baddbmm")


def load_script(path: str, name: str):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class NullWriter:
    def add_scalar(self, *args, **kwargs):
        pass


class NullEvaluator:
    """The phases' periodic evaluation, skipped: it is not a training step."""

    seconds = 0.0  # spent evaluating (the phases' progress lines leave it out of their clock)

    def __call__(self, name, actor, step, episodes):
        return {f"eval/{name}_return": float("nan")}


def day(module, day_args, env, oracle_actor, oracle_qf, buffer, cpu) -> None:
    """The script's forward phase with the flags `day_args`: called as the script takes it (since the reading-path
    refactor, the values it uses; before it, all of Args), so that a benchmark can time an older revision too."""
    if "args" in inspect.signature(module.forward_phase).parameters:
        module.forward_phase(day_args, env, oracle_actor, oracle_qf, buffer, NullEvaluator(), NullWriter(), cpu)
        return
    if hasattr(module, "Day"):  # since the day's learner and settings became one object
        day = module.Day(day_args.day_settings(), cpu, env.action_space, buffer.obs.shape[1])
        outcome = module.Outcome(day_args.success_info_key, day_args.success_distance, day_args.success_return)
        module.forward_phase(day, env, oracle_actor, oracle_qf, day.teacher(), outcome, buffer, NullEvaluator(),
                             NullWriter())  # fmt: skip
        return
    a = day_args
    teacher = module.Teacher(a.teacher_noise, a.teacher_sparsity, a.teacher_delay, a.credit_window, a.feedback_budget,
                             seed=a.seed + 7919)  # fmt: skip
    outcome = module.Outcome(a.success_info_key, a.success_distance, a.success_return)
    module.forward_phase(env, oracle_actor, oracle_qf, teacher, outcome, buffer, NullEvaluator(), NullWriter(), cpu,
                         seed=a.seed, random_starts=a.random_starts, total_timesteps=a.tamer_total_timesteps,
                         learning_starts=a.tamer_learning_starts, batch_size=a.tamer_batch_size, h_lr=a.tamer_h_lr,
                         alpha_start=a.feedback_alpha_start, alpha_end=a.feedback_alpha_end,
                         budget_ends=a.budget_ends_forward_phase)  # fmt: skip


def phase_runner(module, args: Args, phase: str, flags: dict):
    """run(steps): the script's `phase` code for `steps` steps past learning starts, output swallowed."""
    cpu = torch.device("cpu")
    # the phases' evaluations (every EVAL_FREQUENCY / SLEEP_EVAL_FREQUENCY steps) go to NullEvaluator: no episodes
    common = dict(env_id=args.env_id, tamer_learning_starts=args.learning_starts, **flags)
    oracle_ckpt = torch.load(os.path.join(os.path.dirname(module.__file__), "oracles", f"{args.env_id}__sac_oracle.pt"),
                             weights_only=True)  # fmt: skip
    oracle_actor, oracle_qf = module.oracle_from_checkpoint(oracle_ckpt, cpu)
    for p in (*oracle_actor.parameters(), *oracle_qf.parameters()):
        p.requires_grad_(False)
    obs_dim, act_dim = oracle_actor.fc1.in_features, oracle_actor.fc_mean.out_features
    memory = []  # the sleep's buffer: one short forward phase of the oracle's teaching, made once

    def run(steps: int):
        torch.manual_seed(1)
        with contextlib.redirect_stdout(io.StringIO()):
            if phase == "oracle":  # the script's SAC starts learning after its own fixed random steps
                n = module.ORACLE_SAC["learning_starts"] + steps
                module.train_oracle(args.env_id, 1, n, module.Outcome(), NullWriter(), cpu)
            elif phase == "tamer":
                n = args.learning_starts + steps
                buffer = module.ReplayBuffer(n, obs_dim, act_dim, cpu)
                day(module, module.Args(**common, tamer_total_timesteps=n), module.make_env(args.env_id, 1),
                    oracle_actor, oracle_qf, buffer, cpu)  # fmt: skip
            else:
                if not memory:
                    n = 2000  # random actions only (learning starts = the budget - 1): cheap to make
                    memory.append(module.ReplayBuffer(n, obs_dim, act_dim, cpu))
                    random_day = module.Args(**{**common, "tamer_learning_starts": n - 1}, tamer_total_timesteps=n)
                    day(module, random_day, module.make_env(args.env_id, 1), oracle_actor, oracle_qf, memory[0], cpu)
                    memory[0].success[:200] |= not memory[0].success.any()  # an expert set, whatever the luck
                night_args = module.Args(**common, sleep_gradient_steps=steps)
                night = night_args.night(oracle_actor, cpu, tamer={})
                module.sleep_phase(night, memory[0], steps, night_args.sleep_batch_size, NullEvaluator(), NullWriter(),
                                   cpu)  # fmt: skip

    return run


def clock(kind: str) -> float:
    return time.process_time() if kind == "process" else time.perf_counter()


def seconds_per_step(run, steps: tuple[int, int], kind: str) -> float:
    """The difference of two budgets' times per step: setup, learning starts and the last evaluation cancel."""
    times = []
    for n in steps:
        t = clock(kind)
        run(n)
        times.append(clock(kind) - t)
    return (times[1] - times[0]) / (steps[1] - steps[0])


def flops_per_step(run, steps: tuple[int, int]) -> float:
    from torch.utils.flop_counter import FlopCounterMode

    total = []
    for n in steps:
        counter = FlopCounterMode(display=False)
        with counter:
            run(n)
        total.append(counter.get_total_flops())
    return (total[1] - total[0]) / (steps[1] - steps[0])


def matmul_flops(name: str, shapes: list) -> int:
    a, b = (shapes[1], shapes[2]) if name in ("aten::addmm", "aten::baddbmm") else (shapes[0], shapes[1])
    return 2 * math.prod(a) * b[-1]  # [(batch,) m, k] @ [(batch,) k, n]


def profile_phase(run, steps: tuple[int, int]):
    """(matmul calls per step by (op, input shapes), the top ops per step of the longer run's profile)."""
    from torch.profiler import ProfilerActivity, profile

    counts, tables = [], []
    for n in steps:
        with profile(activities=[ProfilerActivity.CPU], record_shapes=True) as prof:
            run(n)
        c = collections.Counter()
        for e in prof.events():
            if e.name in MATMULS:
                c[(e.name, tuple(tuple(s) for s in e.input_shapes[:3]))] += 1
        counts.append(c)
        tables.append(prof.key_averages())
    per_step = {k: (counts[1][k] - counts[0][k]) / (steps[1] - steps[0]) for k in counts[1]}
    total = sum(e.self_cpu_time_total for e in tables[1])
    top = sorted(tables[1], key=lambda e: -e.self_cpu_time_total)[:10]
    top_ops = [{"op": e.key, "self_cpu_share": e.self_cpu_time_total / total, "calls": e.count} for e in top]
    return {k: v for k, v in per_step.items() if v > 0}, top_ops


def hot_loop_seconds(name: str, shapes: list, kind: str, budget: float = 0.05) -> float:
    """Seconds per call of one matmul at these shapes, in a hot loop (best of 3 timed loops)."""
    op = getattr(torch.ops.aten, name.split("::")[1])
    tensors = [torch.randn(s) for s in shapes[: 3 if name in ("aten::addmm", "aten::baddbmm") else 2]]
    for _ in range(3):
        op(*tensors)
    reps, best = 8, math.inf
    while True:
        t = clock(kind)
        for _ in range(reps):
            op(*tensors)
        elapsed = clock(kind) - t
        if elapsed > budget:
            break
        reps *= 4
    for _ in range(3):
        t = clock(kind)
        for _ in range(reps):
            op(*tensors)
        best = min(best, (clock(kind) - t) / reps)
    return best


def measure_roofline(args: Args, module) -> dict:
    """Per phase: FLOPs per step, seconds per step (median of interleaved rounds), peak at the phase's shapes."""
    runs = {phase: phase_runner(module, args, phase, {}) for phase in ("oracle", "tamer", "sleep")}
    out = {}
    for phase, run in runs.items():
        run(args.roofline_steps[0])  # warm: first-call costs, the sleep's buffer
        print(f"roofline: {phase}: FLOPs and shapes", flush=True)
        shapes, top_ops = profile_phase(run, args.profile_steps)
        out[phase] = {"flops_per_step": flops_per_step(run, args.roofline_steps), "shapes": shapes,
                      "top_ops": top_ops, "seconds_per_step": []}  # fmt: skip
    for r in range(args.roofline_repeats):
        for phase, run in runs.items():
            print(f"roofline round {r + 1}/{args.roofline_repeats}: {phase}", flush=True)
            out[phase]["seconds_per_step"].append(seconds_per_step(run, args.roofline_steps, args.clock))
    results = {}
    for phase, m in out.items():
        hot = {k: hot_loop_seconds(k[0], k[1], args.clock) for k in m["shapes"]}
        mm_flops = sum(matmul_flops(k[0], k[1]) * c for k, c in m["shapes"].items())
        peak_seconds = sum(hot[k] * c for k, c in m["shapes"].items())
        step_s = statistics.median(m["seconds_per_step"])
        achieved, peak = m["flops_per_step"] / step_s / 1e9, mm_flops / peak_seconds / 1e9
        results.update({
            f"roofline/{phase}_flops_per_step": m["flops_per_step"],
            f"roofline/{phase}_matmul_flops_per_step": mm_flops,
            f"roofline/{phase}_seconds_per_step": step_s, f"roofline/{phase}_steps_per_s": 1 / step_s,
            f"roofline/{phase}_achieved_gflops": achieved, f"roofline/{phase}_peak_gflops": peak,
            f"roofline/{phase}_fraction": achieved / peak, f"roofline/{phase}_peak_seconds_per_step": peak_seconds,
            f"roofline/{phase}_shapes": [{"op": k[0], "shapes": k[1], "calls_per_step": c,
                                          "hot_loop_gflops": matmul_flops(*k) / hot[k] / 1e9}
                                         for k, c in sorted(m["shapes"].items(), key=lambda kv: -kv[1] * hot[kv[0]])],
            f"roofline/{phase}_top_ops": m["top_ops"], f"roofline/{phase}_rounds_s": m["seconds_per_step"],
        })  # fmt: skip
    return results


def measure_side_by_side(args: Args, sides: dict, kind: str) -> dict:
    """Seconds per step (clock `kind`) of each side (name -> (module, flags, threads)) per phase, interleaved rounds;
    returns {phase/name: median seconds per step, phase/name_rounds: all}."""
    times = {(name, phase): [] for name in sides for phase in ("oracle", "tamer", "sleep")}
    runners = {}
    for name, (module, flags, threads) in sides.items():
        torch.set_num_threads(threads)
        for phase in ("oracle", "tamer", "sleep"):
            runners[(name, phase)] = phase_runner(module, args, phase, flags)
            runners[(name, phase)](args.roofline_steps[0])  # warm (and compile, where asked)
    for r in range(args.roofline_repeats):
        for phase in ("oracle", "tamer", "sleep"):
            for name, (_, _, threads) in sides.items():
                print(f"side by side round {r + 1}/{args.roofline_repeats}: {phase} {name}", flush=True)
                torch.set_num_threads(threads)
                times[(name, phase)].append(seconds_per_step(runners[(name, phase)], args.roofline_steps, kind))
    torch.set_num_threads(args.num_threads)
    out = {}
    for (name, phase), t in times.items():
        out[f"{phase}/{name}"], out[f"{phase}/{name}_rounds"] = statistics.median(t), t
    return out


def print_side_by_side(res: dict, sides: list[str], title: str) -> dict:
    """A table of steps per second and ratios to the first side; returns the ratios."""
    ratios = {}
    print(f"\n{title}\n| phase | " + " | ".join(sides) + " |\n|" + " --- |" * (len(sides) + 1))
    for phase in ("oracle", "tamer", "sleep"):
        cells = []
        for name in sides:
            ratios[f"{phase}/{name}"] = res[f"{phase}/{sides[0]}"] / res[f"{phase}/{name}"]
            cells.append(f"{1 / res[f'{phase}/{name}']:.1f}/s ({ratios[f'{phase}/{name}']:.2f}x)")
        print(f"| {phase} | " + " | ".join(cells) + " |")
    return ratios


def print_roofline(res: dict, title: str) -> None:
    print(f"\n{title}\n| phase | FLOPs/step | achieved GFLOP/s | peak GFLOP/s at its shapes | fraction |")
    print("| --- | --- | --- | --- | --- |")
    for phase in ("oracle", "tamer", "sleep"):
        keys = ("flops_per_step", "achieved_gflops", "peak_gflops", "fraction")
        flops, achieved, peak, fraction = (res[f"roofline/{phase}_{k}"] for k in keys)
        print(f"| {phase} | {flops / 1e6:.0f} M | {achieved:.1f} | {peak:.1f} | {fraction:.2f} |")
    for phase in ("oracle", "tamer", "sleep"):
        ops = ", ".join(f"{o['op']} {100 * o['self_cpu_share']:.0f}%" for o in res[f"roofline/{phase}_top_ops"][:8])
        print(f"top ops, {phase}: {ops}")


# ---------------------------------------------------------------------------------------------------------------
# measuring


def run_measured(cmd: list[str], cwd: str) -> tuple[int, float, str]:
    """Run a command; (exit code, peak resident memory in MB of that process, stdout)."""
    with tempfile.TemporaryFile("w+") as out:
        proc = subprocess.Popen(cmd, cwd=cwd, stdout=out, stderr=subprocess.STDOUT, text=True)
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        return proc.returncode, usage.ru_maxrss / 1024, out.read()


def measure_ours(args: Args, workdir: str) -> dict:
    """One real, small inform_sac_pusher.py run that trains its oracle in-script; its own per-phase throughput."""
    # the script's oracle takes its 5,000 random steps first (ORACLE_SAC, no longer a flag): it gets as many update
    # steps as the reference's, and its steps/s counts the random ones too. The periodic evaluations (fixed now) are
    # off the phases' clocks.
    oracle_steps = ORACLE_RANDOM_STEPS + args.oracle_steps - args.learning_starts
    cmd = [sys.executable, os.path.join(REPO, "inform_sac_pusher.py"), "--env-id", args.env_id, "--train-oracle",
           "--exp-name", "bench", "--num-threads", str(args.num_threads), "--oracle-total-timesteps", str(oracle_steps),
           "--tamer-total-timesteps", str(args.tamer_steps), "--tamer-learning-starts", str(args.learning_starts),
           "--sleep-gradient-steps", str(args.sleep_steps), "--eval-episodes", "1",
           "--obstacle-episodes", "1"]  # fmt: skip
    code, peak_mb, out = run_measured(cmd, workdir)
    runs = sorted(glob.glob(os.path.join(workdir, "runs", "*__bench__*", "summary.json")), key=os.path.getmtime)
    if code != 0 or not runs:
        raise RuntimeError(f"inform_sac_pusher.py failed (exit {code}):\n{out[-2000:]}")
    with open(runs[-1]) as f:
        summary = json.load(f)
    return {"oracle": summary["sps/oracle"], "tamer": summary["sps/tamer"], "sleep": summary["sps/sleep"],
            "peak_mb": peak_mb}  # fmt: skip


def measure_reference(args: Args, workdir: str) -> dict:
    cmd = [sys.executable, os.path.abspath(__file__), "--reference", "--env-id", args.env_id,
           "--oracle-steps", str(args.oracle_steps), "--tamer-steps", str(args.tamer_steps),
           "--sleep-steps", str(args.sleep_steps), "--learning-starts", str(args.learning_starts),
           "--num-threads", str(args.num_threads), "--env-steps", str(args.env_steps)]  # fmt: skip
    code, peak_mb, out = run_measured(cmd, workdir)
    if code != 0:
        raise RuntimeError(f"the reference failed (exit {code}):\n{out[-2000:]}")
    return {**json.loads(out.strip().splitlines()[-1]), "peak_mb": peak_mb}


def raw_env_sps(env, steps: int) -> float:
    env.reset(seed=0)
    start = time.time()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    return steps / (time.time() - start)


def measure_gridworld(workdir: str) -> float:
    code, _, out = run_measured([sys.executable, os.path.join(REPO, "inform_dqn_gridworld.py"), "--exp-name", "bench"],
                                workdir)  # fmt: skip
    runs = sorted(glob.glob(os.path.join(workdir, "runs", "*__bench__*", "summary.json")), key=os.path.getmtime)
    if code != 0 or not runs:
        raise RuntimeError(f"inform_dqn_gridworld.py failed (exit {code}):\n{out[-2000:]}")
    with open(runs[-1]) as f:
        return json.load(f)["wall_time_s"]


def main(args: Args) -> dict:
    results = {}
    if os.path.isfile(args.output):  # what this run does not measure again stays as it was
        with open(args.output) as f:
            results = json.load(f)
    if args.side_by_side:
        results.update(main_side_by_side(args))
    if args.roofline or args.baseline_script or args.variants:
        results.update(main_roofline(args))
    with open(args.output + ".tmp", "w") as f:
        json.dump(results, f, indent=2)
    os.replace(args.output + ".tmp", args.output)
    print(f"written to {args.output}")
    return results


def main_roofline(args: Args) -> dict:
    torch.set_num_threads(args.num_threads)
    ours = load_script(os.path.join(REPO, "inform_sac_pusher.py"), "inform_sac_pusher_ours")
    machine = f"{platform.machine()}, {os.cpu_count()} cores, torch {torch.__version__}, {args.num_threads} thread(s)"
    meta = "roofline" if args.roofline else "variants"  # the run's conditions go beside what it measured
    res = {f"{meta}/args": asdict(args), f"{meta}/clock": args.clock, f"{meta}/load_average_start": os.getloadavg(),
           f"{meta}/machine": machine, f"{meta}/date": time.strftime("%Y-%m-%d %H:%M")}  # fmt: skip
    if args.roofline:
        res.update(measure_roofline(args, ours))
        print_roofline(res, f"roofline ({args.clock} clock), ours")
    if args.baseline_script:
        base = load_script(os.path.abspath(args.baseline_script), "inform_sac_pusher_baseline")
        if args.roofline:
            before = measure_roofline(args, base)
            res.update({k.replace("roofline/", "roofline_baseline/"): v for k, v in before.items()})
            print_roofline(before, f"roofline ({args.clock} clock), baseline {args.baseline_script}")
        sides = {"baseline": (base, {}, args.num_threads), "ours": (ours, {}, args.num_threads)}
        times = measure_side_by_side(args, sides, args.clock)
        ratios = print_side_by_side(times, list(sides), f"ours against the baseline, interleaved ({args.clock} clock)")
        res.update({f"baseline/{k}": v for k, v in {**times, **ratios}.items()})
        res.update({f"baseline/{p}_speedup": ratios[f"{p}/ours"] for p in ("oracle", "tamer", "sleep")})
    flags = [f for f in args.variants if f != "threads"]
    if flags:
        sides = {"default": (ours, {}, 1), **{f: (ours, {f: True}, 1) for f in flags}}
        times = measure_side_by_side(args, sides, args.clock)
        ratios = print_side_by_side(times, list(sides), f"opt-in flags against the default, interleaved ({args.clock})")
        res.update({f"variants/{k}": v for k, v in {**times, **ratios}.items()})
    if "threads" in args.variants:
        sides = {"1_thread": (ours, {}, 1), "2_threads": (ours, {}, 2)}
        times = measure_side_by_side(args, sides, "wall")
        ratios = print_side_by_side(times, list(sides), "two threads against one, interleaved (wall clock)")
        res.update({f"threads/{k}": v for k, v in {**times, **ratios}.items()})
    res[f"{meta}/load_average_end"] = os.getloadavg()
    return res


def main_side_by_side(args: Args) -> dict:
    rounds = {"ours": [], "reference": [], "gridworld_pipeline_s": []}
    with tempfile.TemporaryDirectory() as workdir:
        for r in range(args.repeats):
            print(f"round {r + 1}/{args.repeats}: ours", flush=True)
            rounds["ours"].append(measure_ours(args, workdir))
            print(f"round {r + 1}/{args.repeats}: reference", flush=True)
            rounds["reference"].append(measure_reference(args, workdir))
            if args.gridworld:
                print(f"round {r + 1}/{args.repeats}: gridworld pipeline", flush=True)
                rounds["gridworld_pipeline_s"].append(measure_gridworld(workdir))

    def median(side, key):
        return statistics.median(x[key] for x in rounds[side])

    machine = f"{platform.machine()}, {os.cpu_count()} cores, torch {torch.__version__}, {args.num_threads} thread(s)"
    results = {"machine": machine, "args": asdict(args), "rounds": rounds}
    rows = []
    for phase, unit in (("oracle", "env steps/s"), ("tamer", "env steps/s"), ("sleep", "gradient steps/s")):
        ours, ref = median("ours", phase), median("reference", phase)
        results[f"{phase}_ratio"] = ours / ref
        results[f"{phase}_ours"], results[f"{phase}_reference"] = ours, ref
        rows.append((phase, unit, f"{ours:.0f}", f"{ref:.0f}", f"{ours / ref:.2f}x"))
    results["raw_env_sps"] = median("reference", "raw_env")
    results["peak_mb_ours"], results["peak_mb_reference"] = median("ours", "peak_mb"), median("reference", "peak_mb")
    if args.gridworld:
        results["gridworld_pipeline_s"] = statistics.median(rounds["gridworld_pipeline_s"])

    print(f"\n{results['machine']}, median of {args.repeats} interleaved rounds")
    print("| phase | unit | ours | eager reference | ratio |\n| --- | --- | --- | --- | --- |")
    for row in rows:
        print("| " + " | ".join(row) + " |")
    print(f"| raw env ({args.env_id}) | env steps/s | {results['raw_env_sps']:.0f} | | |")
    print(f"| peak memory | MB | {results['peak_mb_ours']:.0f} | {results['peak_mb_reference']:.0f} | |")
    if args.gridworld:
        print(f"| gridworld default pipeline | s | {results['gridworld_pipeline_s']:.1f} | | |")
    return results


if __name__ == "__main__":
    args = tyro.cli(Args)
    torch.set_num_threads(args.num_threads)
    if args.reference:
        torch.manual_seed(1)
        np.random.seed(1)
        env = gym.make(args.env_id)
        env.action_space.seed(1)
        print(json.dumps({"raw_env": raw_env_sps(env, args.env_steps), "oracle": reference_oracle(args, env),
                          "tamer": reference_tamer(args, env), "sleep": reference_sleep(args, env)}))  # fmt: skip
    else:
        if min(args.repeats, args.oracle_steps, args.tamer_steps, args.sleep_steps) < 1 or not (
            256 <= args.learning_starts < min(args.oracle_steps, args.tamer_steps)
        ):
            print(
                "error: budgets must be positive and 256 <= --learning-starts < the env-step budgets", file=sys.stderr
            )
            sys.exit(2)
        main(args)
