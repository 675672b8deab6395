"""Side-by-side speed benchmark: our scripts against a plain eager CleanRL-style reference, in one run.

For each Pusher phase (oracle SAC training, TAMER forward phase, sleep phase) it measures, interleaved over
`--repeats` rounds and reported as medians:
- ours: `inform_sac_pusher.py` run for real with small budgets (its own per-phase throughput from summary.json);
- the reference: the same loops written inside this file the simplest CleanRL way (separate Q modules, a numpy
  replay buffer copied to tensors every step, `.item()` every step, default Adam, a parameter loop for the soft
  update), with the same hyperparameters and budgets;
- the raw env step rate, and each process's peak memory.
It also times the full default gridworld pipeline. Only ratios taken in one run count: these machines are noisy.

    python benchmarks/benchmark.py                # about 5 minutes on 2 cores
    python benchmarks/benchmark.py --repeats 1 --oracle-steps 600 --tamer-steps 600 --sleep-steps 200   # a smoke run

Writes benchmarks/results.json (keys `{phase}_ratio` = ours / reference for oracle, tamer, sleep, and
`gridworld_pipeline_s`) and prints a table.
"""

import glob
import json
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
    cmd = [sys.executable, os.path.join(REPO, "inform_sac_pusher.py"), "--env-id", args.env_id, "--train-oracle",
           "--exp-name", "bench", "--num-threads", str(args.num_threads), "--no-save-model",
           "--oracle-total-timesteps", str(args.oracle_steps), "--oracle-learning-starts", str(args.learning_starts),
           "--tamer-total-timesteps", str(args.tamer_steps), "--tamer-learning-starts", str(args.learning_starts),
           "--sleep-gradient-steps", str(args.sleep_steps), "--eval-episodes", "1", "--periodic-eval-episodes", "1",
           "--obstacle-episodes", "1", "--eval-frequency", str(10 * args.tamer_steps),
           "--sleep-eval-frequency", str(10 * args.sleep_steps)]  # fmt: skip
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
    with open(args.output + ".tmp", "w") as f:
        json.dump(results, f, indent=2)
    os.replace(args.output + ".tmp", args.output)
    print(f"written to {args.output}")
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
