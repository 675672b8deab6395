"""Tabular agents on the wall maze, trained with INFORM's recovered reward or with the environment's own reward.

Reproduces the reward experiment of Tarakli & Di Nuovo, "Learning while Sleeping" (ICDL 2024), Fig. 6 (Sec. VI-C;
see docs/protocol.md). INFORM learns a soft Q network on the plain maze (inform_dqn_gridworld.py saves it as
inform_q.pt). Its recovered reward (Eq. 3), r(s, a, s') = Q(s, a) - (1 - terminated) gamma V(s'), is evaluated on
the transition the agent actually makes on the wall maze, which INFORM never saw, and trains fresh tabular agents
there, next to agents trained on the environment reward (+1 at G). The TAMER network of the same gridworld run is
evaluated on the wall maze, untrained there, as the baseline.

    python inform_dqn_gridworld.py --seed 1
    python q_learning_recovered_reward.py --reward-path runs/KnoxStoneMaze-v0__inform_dqn_gridworld__1__<t>

Two tabular updates (`--bootstrap`), named for what they are:
- `sampled` (default, the authors' update as docs/protocol.md describes it): target r + gamma Q(s', a') with a'
  drawn epsilon-greedily from Q(s', .), a SARSA-like target. a' is drawn for the target only; the action taken at
  s' is drawn again (SARSA proper would take a'). Its fixed point is the epsilon-greedy policy's own values.
- `max` (textbook Q-learning): target r + gamma max_a' Q(s', a').

Two recovered rewards (`--reward-source`):
- `network` (default): Eq. 3 from the saved INFORM network with the run's sleep gamma and temperature, s' being the
  wall maze's next state (a blocked move gives s' = s).
- `table`: the 30 x 4 table the gridworld run saved, computed with the *plain* maze's s' and applied whatever s'
  the wall maze gives. It pays for moves the new wall blocks; kept only as a labelled variant.

Several gridworld runs can be given at once (`--reward-path A B C`): every run trains `--num-seeds` agents, the
env-reward arm trains the same number of agents on the same seeds, so both arms have the same n.
"""

import contextlib
import gc
import json
import os
import signal
import sys
import time
import warnings
import zipfile
from dataclasses import asdict, dataclass
from typing import Literal

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
import tyro  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from torch.utils.tensorboard import SummaryWriter  # noqa: E402

try:
    import gridworld_env
except ModuleNotFoundError as e:  # a copy of this script without the maze beside it: said after parsing, see below
    if e.name != "gridworld_env":
        raise
    gridworld_env = None

BOOTSTRAP_RULES = {
    "sampled": "sampled bootstrap (SARSA-like): target r + gamma Q(s', a'), a' epsilon-greedy from Q(s', .)",
    "max": "max bootstrap (textbook Q-learning): target r + gamma max_a' Q(s', a')",
}
REWARD_NAMES = {
    "recovered_network": "recovered reward, INFORM network on the wall maze's s' (Eq. 3)",
    "recovered_table": "recovered reward, 30x4 table with the plain maze's s' (variant)",
    "env": "environment reward (+1 at G)",
}


@dataclass
class Args:
    exp_name: str = os.path.basename(__file__)[: -len(".py")]
    """the name of this experiment"""
    seed: int = 1
    """seed of the first agent; agent j of gridworld run i uses seed + i * num_seeds + j (the same in both arms)"""
    num_threads: int = 1
    """torch CPU threads (torch only evaluates the 30-cell networks once)"""
    env_id: str = "KnoxStoneMazeWall-v0"
    """the maze the tabular agents train on"""

    # Reward source
    reward_source: Literal["network", "table"] = "network"
    """network: Eq. 3 from inform_q.pt on the transition actually made; table: recovered_reward.pt (plain maze's s')"""
    reward_path: tuple[str, ...] | None = None
    """gridworld run directories (or their inform_q.pt / recovered_reward.pt); default: the newest run under runs/"""
    runs_dir: str = "runs"
    """where to look for gridworld runs when --reward-path is not given"""

    # Tabular agents
    bootstrap: Literal["sampled", "max"] = "sampled"
    """sampled: bootstrap on an epsilon-greedy sampled a' (the authors' SARSA-like update); max: Q-learning"""
    num_episodes: int = 300
    """training episodes per agent"""
    num_seeds: int = 5
    """agents per gridworld run and arm"""
    alpha: float = 0.2
    """step size of the tabular update"""
    gamma: float = 0.99
    """discount of the tabular agents"""
    epsilon: float = 0.05
    """probability of a uniformly random action (fixed, no decay); also the sampled bootstrap's epsilon"""

    # Reporting
    final_window: int = 10
    """final_episode_length is the mean training episode length over this many last episodes"""
    stability_window: int = 100
    """greedy_optimal_fraction is the fraction of this many last episodes after which the greedy policy is optimal"""
    grid_points: int = 200
    """points of the common env-step grid the per-agent curves are interpolated to (mean curve and fig6.png)"""


# ALGO LOGIC: the recovered reward (Eq. 3) ---------------------------------------------------------------------------
class QNetwork(nn.Module):
    """The 30-32-32-4 MLP of inform_dqn_gridworld.py, rebuilt here to load its saved networks (H and soft Q)."""

    def __init__(self, obs_dim: int, n_actions: int, hidden: int = 32):
        super().__init__()
        self.network = nn.Sequential(
            nn.Linear(obs_dim, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, n_actions)
        )

    def forward(self, x):
        return self.network(x)


def soft_value(q: torch.Tensor, temperature: float) -> torch.Tensor:  # V(s) = temp * logsumexp(Q(s, .) / temp)
    return temperature * torch.logsumexp(q / temperature, dim=-1)


def recovered_reward(q_net, obs, actions, next_obs, terminated, gamma: float, temperature: float) -> torch.Tensor:
    """Eq. 3 on a batch of transitions: r(s, a, s') = Q(s, a) - (1 - terminated) gamma V(s')."""
    with torch.no_grad():
        q_sa = q_net(obs).gather(-1, actions[..., None]).squeeze(-1)
        return q_sa - (1.0 - terminated) * gamma * soft_value(q_net(next_obs), temperature)


def transition_reward_table(q_net, next_cell: np.ndarray, gamma: float, temperature: float) -> np.ndarray:
    """Eq. 3 for every (s, a) with s' = next_cell[s, a]. The maze is deterministic, so r(s, a, s') of the transition
    the agent makes is this table's entry: it is computed once instead of at every step (the training loop checks
    that the s' it sees is the one used here)."""
    n_cells, n_actions = next_cell.shape
    eye = torch.eye(n_cells)
    obs = eye.repeat_interleave(n_actions, 0)
    actions = torch.arange(n_actions).repeat(n_cells)
    s_next = torch.as_tensor(next_cell.reshape(-1))
    terminated = (s_next == gridworld_env.GOAL).float()
    r = recovered_reward(q_net, obs, actions, eye[s_next], terminated, gamma, temperature)
    return r.double().numpy().reshape(n_cells, n_actions)


# ALGO LOGIC: the tabular agents -------------------------------------------------------------------------------------
def epsilon_greedy(q_s: np.ndarray, epsilon: float, rng: np.random.Generator) -> int:
    """A random action with probability epsilon, else a greedy one with ties broken uniformly at random."""
    if rng.random() < epsilon:
        return int(rng.integers(len(q_s)))
    best = np.flatnonzero(q_s == q_s.max())
    return int(best[rng.integers(len(best))]) if len(best) > 1 else int(best[0])


def td_target(q, r, s_next, terminated, bootstrap: str, gamma: float, epsilon: float, rng) -> float:
    """The tabular target: no bootstrap past G; else on a sampled epsilon-greedy a' ("sampled") or the max ("max")."""
    if terminated:
        return r
    if bootstrap == "sampled":
        return r + gamma * q[s_next, epsilon_greedy(q[s_next], epsilon, rng)]
    return r + gamma * q[s_next].max()


def train_agent(env: gym.Env, reward: dict | None, args: Args, seed: int, variant: str) -> dict:
    """One tabular agent for args.num_episodes episodes; reward None means the environment's reward.

    `reward` holds a (30, 4) "table" and, for the network source, the "next_cell" the table was computed with.
    Returns per episode the training length, the cumulative env steps at its end, and the greedy policy's length
    on `variant` evaluated after it.
    """
    rng = np.random.default_rng(seed)
    q = np.zeros((gridworld_env.N_CELLS, gridworld_env.N_ACTIONS))
    lengths = []
    steps_at_end = []
    greedy_lengths = []
    total_steps = 0
    obs, _ = env.reset(seed=seed)
    for _ in range(args.num_episodes):
        StopSignals.check()  # a stop signal ends the run here, between two episodes
        s = int(obs.argmax())
        length = 0
        terminated = False
        truncated = False
        while not (terminated or truncated):
            a = epsilon_greedy(q[s], args.epsilon, rng)
            obs, env_reward, terminated, truncated, _ = env.step(a)
            s_next = int(obs.argmax())
            if reward is None:
                r = env_reward
            else:  # the recovered reward replaces the env's
                r = reward["table"][s, a]
                if reward.get("next_cell") is not None and reward["next_cell"][s, a] != s_next:
                    raise RuntimeError(f"the reward of ({s}, {a}) was computed for s' {reward['next_cell'][s, a]}")
            target = td_target(q, r, s_next, terminated, args.bootstrap, args.gamma, args.epsilon, rng)
            q[s, a] += args.alpha * (target - q[s, a])  # truncation at 200 steps still bootstraps
            s = s_next
            length += 1
        total_steps += length
        lengths.append(length)
        steps_at_end.append(total_steps)
        greedy_lengths.append(gridworld_env.greedy_episode_length(q.argmax(1), variant))
        obs, _ = env.reset()
    return {"lengths": np.array(lengths), "steps": np.array(steps_at_end), "greedy": np.array(greedy_lengths), "q": q}


# Metrics ------------------------------------------------------------------------------------------------------------
def first_optimum(run: dict, optimum: int) -> tuple[float, float]:
    """(env steps, episodes) until the end of the first training episode that took `optimum` steps."""
    hits = np.flatnonzero(run["lengths"] == optimum)
    return (float(run["steps"][hits[0]]), float(hits[0] + 1)) if len(hits) else (float("nan"), float("nan"))


def stays_at_optimum(run: dict, optimum: int) -> tuple[float, float]:
    """(env steps, episodes) until the greedy policy is at the optimum and stays there to the last episode."""
    at_optimum = run["greedy"] == optimum
    if not at_optimum[-1]:
        return float("nan"), float("nan")
    off = np.flatnonzero(~at_optimum)
    first = 0 if len(off) == 0 else off[-1] + 1  # first episode of the final streak at the optimum
    return float(run["steps"][first]), float(first + 1)


def agent_metrics(run: dict, optimum: int, final_window: int, stability_window: int) -> dict:
    steps_first, episodes_first = first_optimum(run, optimum)
    steps_stay, episodes_stay = stays_at_optimum(run, optimum)
    return {
        "steps_to_first_optimum": steps_first,
        "episodes_to_first_optimum": episodes_first,
        "steps_to_stay_optimum": steps_stay,
        "episodes_to_stay_optimum": episodes_stay,
        "auc": float(run["lengths"].sum()),  # area under the length-per-episode curve = the env steps used
        "final_episode_length": float(run["lengths"][-final_window:].mean()),
        "final_greedy_episode_length": float(run["greedy"][-1]),
        "greedy_optimal_fraction": float((run["greedy"][-stability_window:] == optimum).mean()),
    }


def censored_median(values: np.ndarray) -> float:
    """Median over all agents, one that never reached counting as later than any that did (inf if over half never)."""
    return float(np.median(np.where(np.isfinite(values), values, np.inf)))


# Diagnosis: what the reward makes optimal on the wall maze -------------------------------------------------------
def value_iteration(reward, next_cell, gamma: float, epsilon: float = 0.0, tol: float = 1e-10) -> np.ndarray:
    """Fixed point of Q(s, a) = r(s, a) + gamma (1 - [s' = G]) E_{a' ~ pi(s')} Q(s', a'), with pi greedy (epsilon 0:
    the max bootstrap's fixed point) or epsilon-greedy (the sampled bootstrap's, ties aside)."""
    not_done = (next_cell != gridworld_env.GOAL).astype(np.float64)
    q = np.zeros_like(reward, dtype=np.float64)
    while True:
        v = (1.0 - epsilon) * q.max(axis=1) + epsilon * q.mean(axis=1)
        new_q = reward + gamma * not_done * v[next_cell]
        if np.abs(new_q - q).max() < tol:
            return new_q
        q = new_q


def shortest_path_return(reward, next_cell, gamma: float, start: int, horizon: int = 200) -> tuple[float, int]:
    """The best discounted return from `start` among the paths that enter G in the fewest steps, and that number."""
    w = np.full(gridworld_env.N_CELLS, -np.inf)  # w[s]: best return from s entering G in exactly k steps
    for k in range(1, horizon + 1):
        w_next = w[next_cell]
        cont = np.where(next_cell == gridworld_env.GOAL, 0.0, np.where(np.isfinite(w_next), gamma * w_next, -np.inf))
        w = np.where(np.isin(next_cell, [gridworld_env.GOAL]) | np.isfinite(w_next), reward + cont, -np.inf).max(1)
        if np.isfinite(w[start]):
            return float(w[start]), k
    return float("nan"), -1


def greedy_path(policy: np.ndarray, next_cell: np.ndarray, max_steps: int = 200) -> list[int]:
    """The cells a table policy visits from S until G, or until a cell repeats (a deterministic policy then loops)."""
    path = [gridworld_env.START]
    while len(path) <= max_steps and path[-1] != gridworld_env.GOAL:
        path.append(int(next_cell[path[-1], policy[path[-1]]]))
        if path[-1] in path[:-1]:
            break
    return path


def diagnose(reward: np.ndarray, variant: str, gamma: float, epsilon: float) -> dict:
    """What each update's fixed point does under this reward on this maze: its greedy path from S, and, when that
    path loops, what the loop is worth (staying in it forever) against the shortest way from the loop to G."""
    next_cell = gridworld_env.transition_table(variant)
    out = {}
    q = {}
    for name, eps in (("max", 0.0), ("sampled", epsilon)):
        q[name] = value_iteration(reward, next_cell, gamma, eps)
        policy = q[name].argmax(1)
        path = greedy_path(policy, next_cell)
        out[f"{name}/episode_length"] = gridworld_env.greedy_episode_length(policy, variant)
        out[f"{name}/path"] = path
        out[f"{name}/loop"] = loop = path[path.index(path[-1]) : -1] if path[-1] != gridworld_env.GOAL else []
        if loop:  # the loop's discounted reward per round, repeated forever from its first cell
            per_round = sum(gamma**i * reward[c, policy[c]] for i, c in enumerate(loop))
            out[f"{name}/loop_worth"] = float(per_round / (1.0 - gamma ** len(loop)))
            ret, steps = shortest_path_return(reward, next_cell, gamma, loop[0])
            out[f"{name}/loop_to_goal_return"] = ret
            out[f"{name}/loop_to_goal_steps"] = steps
    if out["max/loop"]:  # at the max policy's loop: staying against setting off on the shortest way to G
        cell = out["max/loop"][0]
        stay = int(q["max"][cell].argmax())
        go = int(gridworld_env.optimal_q(variant, gamma)[cell].argmax())
        for name in q:
            out[f"{name}/q_stay_in_max_loop"] = float(q[name][cell, stay])
            out[f"{name}/q_leave_max_loop_for_goal"] = float(q[name][cell, go])
    out["shortest_path/return"], out["shortest_path/steps"] = shortest_path_return(
        reward, next_cell, gamma, gridworld_env.START
    )
    out["max/v_start"] = float(value_iteration(reward, next_cell, gamma)[gridworld_env.START].max())
    return out


# Main ---------------------------------------------------------------------------------------------------------------
def run_arm(args, arm: str, reward_by_run: list, seeds: list, variant: str, optimum: int, runs: list, writer) -> None:
    """Train every agent of one arm; finished agents are appended to `runs` (so an interrupt keeps them)."""
    for i, (reward, seed) in enumerate(zip(reward_by_run, seeds, strict=True)):
        env = gym.make(args.env_id)
        t0 = time.time()
        run = train_agent(env, reward, args, seed, variant)
        env.close()
        run["seconds"] = time.time() - t0
        runs.append(run)
        m = agent_metrics(run, optimum, args.final_window, args.stability_window)
        for length, greedy, step in zip(run["lengths"], run["greedy"], run["steps"], strict=True):
            writer.add_scalar(f"{arm}/seed_{seed}/episode_length", length, step)
            writer.add_scalar(f"{arm}/seed_{seed}/greedy_episode_length", greedy, step)
        print(
            f"[{arm}] agent {i + 1}/{len(seeds)} (seed {seed}): {int(run['steps'][-1]):,} env steps | "
            f"first {optimum}-step episode at {m['steps_to_first_optimum']:,.0f} | "
            f"stays at {optimum} from {m['steps_to_stay_optimum']:,.0f} | greedy {int(run['greedy'][-1])} | "
            f"{run['seconds']:.1f}s",
            flush=True,
        )


def main(args: Args, sources: list[dict], stop: "StopSignals | None" = None) -> dict:
    run_name = f"{args.env_id}__{args.exp_name}__{args.seed}__{int(time.time())}"
    run_start = time.time()
    torch.set_num_threads(args.num_threads)
    variant = gym.make(args.env_id).unwrapped.variant
    optimum = gridworld_env.greedy_episode_length(gridworld_env.optimal_q(variant, args.gamma).argmax(1), variant)
    seeds = [args.seed + i * args.num_seeds + j for i in range(len(sources)) for j in range(args.num_seeds)]

    # The recovered reward of each gridworld run on this maze (read by resolve_sources), TAMER, the diagnosis
    reward_by_agent = [source["reward"] for source in sources for _ in range(args.num_seeds)]
    tamer_lengths = [
        None if s["tamer_policy"] is None else gridworld_env.greedy_episode_length(s["tamer_policy"], variant)
        for s in sources
    ]
    diagnoses = [diagnose(source["reward"]["table"], variant, args.gamma, args.epsilon) for source in sources]
    arms = {
        f"{args.bootstrap}_bootstrap/recovered_{args.reward_source}": reward_by_agent,
        f"{args.bootstrap}_bootstrap/env": [None] * len(seeds),
    }

    stop = stop or StopSignals()  # SIGINT, SIGTERM (Slurm, kill), SIGHUP stop the run as Ctrl-C does
    run_dir = writer = None
    runs = {arm: [] for arm in arms}
    times = {}
    arm = next(iter(arms))
    try:
        run_dir = make_run_dir(run_name)  # only now: every input has been read and checked
        writer = SummaryWriter(run_dir)
        writer.add_text(
            "hyperparameters",
            "|param|value|\n|-|-|\n" + "\n".join(f"|{key}|{value}|" for key, value in vars(args).items()),
        )
        print(f"run directory: {run_dir}", flush=True)
        print(f"optimum on {args.env_id}: {optimum} steps; update: {BOOTSTRAP_RULES[args.bootstrap]}", flush=True)
        for source, tamer, diag in zip(sources, tamer_lengths, diagnoses, strict=True):
            print(f"{source['path']}: TAMER's greedy policy on {args.env_id}: {tamer} steps", flush=True)
            print(f"  value iteration on the recovered reward: {diagnosis_report(diag)}", flush=True)
        for arm, reward in arms.items():
            run_arm(args, arm, reward, seeds, variant, optimum, runs[arm], writer)
            times[f"time/{arm}_s"] = sum(run["seconds"] for run in runs[arm])
    except (KeyboardInterrupt, BrokenPipeError) as e:  # a signal, or the reader of our output died
        # what finished is kept: the summary (first) records the agents done per arm and no figure is drawn
        stop.finished = True
        stop.broken_pipe = isinstance(e, BrokenPipeError)
        name = stop.reason()
        summary = {
            **{f"{a}/agents_done": len(runs[a]) for a in arms},
            "wall_time_s": time.time() - run_start,
            "seed": args.seed,
            "script": os.path.basename(__file__),
            "status": "interrupted",
            "phase": arm,
            "signal": name,
            "args": asdict(args),
        }
        if run_dir is not None:
            write_json_atomic(f"{run_dir}/summary.json", summary)
        if writer is not None:
            writer.close()
        say(
            f"interrupted ({name}) during {arm}; "
            + (f"the summary in {run_dir} says what finished" if run_dir else "no run was made"),
            sys.stderr,
        )
        stop.restore()
        return summary
    except OSError as e:  # a read-only or full disk: one line, exit 1
        if writer is not None:
            writer.close()
        say(f"error: cannot write {e.filename or 'runs/'}: {e.strerror or e}; this run has no record", sys.stderr)
        stop.restore()
        return {"status": "failed", "error": f"{type(e).__name__}: {e}"}
    stop.finished = True  # from here on a signal is only noted: the results below take seconds, then the exit says it

    summary = {
        "optimum_episode_length": optimum,
        "reward_source": args.reward_source,
        "bootstrap": args.bootstrap,
        "bootstrap_rule": BOOTSTRAP_RULES[args.bootstrap],
        "arms": list(arms),
        "seeds": seeds,
        "num_agents": len(seeds),
    }
    tamer_key = "eval/wall/tamer_episode_length" if variant == "wall" else "eval/tamer_episode_length"
    summary[f"{tamer_key}_per_run"] = tamer_lengths
    known = [t for t in tamer_lengths if t is not None]
    summary[tamer_key] = float(np.mean(known)) if known else None
    summary["tamer/n_reached"] = sum(t == optimum for t in known) if known else None
    for arm in arms:
        per_agent = [agent_metrics(run, optimum, args.final_window, args.stability_window) for run in runs[arm]]
        for metric in per_agent[0]:
            values = np.array([m[metric] for m in per_agent])
            reached = values[np.isfinite(values)]
            summary[f"{arm}/{metric}_per_agent"] = [nan_to_none(v) for v in values]
            summary[f"{arm}/{metric}_median"] = nan_to_none(censored_median(values))
            summary[f"{arm}/{metric}_mean"] = nan_to_none(reached.mean()) if len(reached) else None
            if metric.startswith(("steps_", "episodes_")):
                summary[f"{arm}/{metric}_min"] = nan_to_none(reached.min()) if len(reached) else None
                summary[f"{arm}/{metric}_max"] = nan_to_none(reached.max()) if len(reached) else None
        summary[f"{arm}/n_first_optimum"] = int(np.isfinite([m["steps_to_first_optimum"] for m in per_agent]).sum())
        summary[f"{arm}/n_stay_optimum"] = int(np.isfinite([m["steps_to_stay_optimum"] for m in per_agent]).sum())
        summary[f"{arm}/n_agents"] = len(per_agent)
    for key, value in summary.items():
        if isinstance(value, int | float) and not isinstance(value, bool):
            writer.add_scalar(key, value, 0)
    for key in sorted({k for d in diagnoses for k in d}):
        summary[f"diagnosis/{key}_per_run"] = [d.get(key) for d in diagnoses]

    # Curves on a common env-step grid per arm: the mean to TensorBoard, every agent to agents.npz, a figure
    curves = {}
    for arm in arms:
        grid = np.linspace(0, max(int(run["steps"][-1]) for run in runs[arm]), args.grid_points + 1)[1:]
        curves[arm] = (grid, interpolate_curves(runs[arm], grid))
        for step, mean in zip(grid, curves[arm][1].mean(0), strict=True):
            writer.add_scalar(f"{arm}/episode_length", mean, int(step))
    fields = ("lengths", "steps", "greedy")
    agents = {f"{arm}/{k}": np.stack([run[k] for run in runs[arm]]) for arm in arms for k in fields}
    tamer_label = "TAMER's greedy policy, untrained on the wall" if variant == "wall" else "TAMER's greedy policy"
    title = f"{args.env_id}: {len(seeds)} agents per arm, {args.num_episodes} episodes each"
    figure = fig6(curves, optimum, summary[tamer_key], title, tamer_label)

    summary.update(
        {
            "reward/paths": [os.path.abspath(s["path"]) for s in sources],
            "reward/tamer_paths": [
                os.path.abspath(s["tamer_path"]) if s["tamer_policy"] is not None else None for s in sources
            ],
            "reward/sleep_gamma_per_run": [s["meta"].get("gamma") for s in sources],
            "reward/temperature_per_run": [s["meta"].get("temperature") for s in sources],
            **times,
            "wall_time_s": time.time() - run_start,
            "seed": args.seed,
            "script": os.path.basename(__file__),
            "status": "completed",
            "args": asdict(args),
        }
    )
    try:  # the results, then the summary that says they are complete; a full disk leaves none of them
        with open(f"{run_dir}/agents.npz.tmp", "wb") as f:
            np.savez(f, **agents)
        os.replace(f"{run_dir}/agents.npz.tmp", f"{run_dir}/agents.npz")
        figure.savefig(f"{run_dir}/fig6.tmp.png", dpi=120)
        os.replace(f"{run_dir}/fig6.tmp.png", f"{run_dir}/fig6.png")
        write_json_atomic(f"{run_dir}/summary.json", summary)
    except OSError as e:
        for name in ("agents.npz", "agents.npz.tmp", "fig6.png", "fig6.tmp.png", "summary.json.tmp"):
            with contextlib.suppress(FileNotFoundError):
                os.remove(f"{run_dir}/{name}")
        writer.close()
        say(f"error: cannot write {e.filename or run_dir}: {e.strerror or e}; this run has no record (its "
            f"agents.npz and figure removed)", sys.stderr)  # fmt: skip
        stop.restore()
        return {**summary, "status": "unrecorded"}
    writer.close()
    for arm in arms:
        say(f"{arm} ({len(seeds)} agents): " + arm_report(summary, arm, optimum))
    say(f"done in {summary['wall_time_s']:.1f}s; summary: {run_dir}/summary.json, figure: {run_dir}/fig6.png")
    stop.restore()
    return summary


# Helpers: reading inputs, output files, the figure ---------------------------------------------------------------
def arm_report(summary: dict, arm: str, optimum: int) -> str:
    def steps(metric):
        median = summary[f"{arm}/{metric}_median"]
        if summary[f"{arm}/{metric}_min"] is None:
            return "never"
        lo = summary[f"{arm}/{metric}_min"]
        hi = summary[f"{arm}/{metric}_max"]
        return f"median {'never' if median is None else f'{median:,.0f}'} (reached {lo:,.0f}-{hi:,.0f})"

    return (
        f"first {optimum}-step episode: {summary[f'{arm}/n_first_optimum']} agents, "
        f"{steps('steps_to_first_optimum')} env steps | stays at {optimum}: {summary[f'{arm}/n_stay_optimum']} "
        f"agents, {steps('steps_to_stay_optimum')} env steps | "
        f"greedy at {optimum} after {summary[f'{arm}/greedy_optimal_fraction_mean']:.0%} of the last "
        f"{min(summary['args']['stability_window'], summary['args']['num_episodes'])} episodes | "
        f"final episode length {summary[f'{arm}/final_episode_length_mean']:.1f}"
    )


def diagnosis_report(d: dict) -> str:
    text = f"max bootstrap's fixed point {d['max/episode_length']} steps (V(S) {d['max/v_start']:.3f}"
    if d["max/loop"]:
        cell = d["max/loop"][0]
        text += (
            f"; it loops at {d['max/loop']}, worth {d['max/loop_worth']:.3f} forever against "
            f"{d['max/loop_to_goal_return']:.3f} for the {d['max/loop_to_goal_steps']} steps from {cell} to G"
        )
    text += f"), sampled bootstrap's {d['sampled/episode_length']} steps"
    if d["max/loop"]:
        text += (
            f" (at {cell}: Q(stay) {d['sampled/q_stay_in_max_loop']:.3f}, Q(set off for G) "
            f"{d['sampled/q_leave_max_loop_for_goal']:.3f}; under the max {d['max/q_stay_in_max_loop']:.3f} and "
            f"{d['max/q_leave_max_loop_for_goal']:.3f})"
        )
    return text + f"; the shortest path S to G is worth {d['shortest_path/return']:.3f}"


def nan_to_none(x: float):
    return None if not np.isfinite(x) else float(x)


def interpolate_curves(runs: list[dict], grid: np.ndarray) -> np.ndarray:
    """Each agent's episode length (at the env step its episode ended) on a common step grid; (agents, points).

    np.interp holds the first episode's length before it ends and the last one's after the agent's budget ran out.
    """
    return np.stack([np.interp(grid, run["steps"], run["lengths"]) for run in runs])


def arm_label(arm: str) -> str:
    bootstrap, reward = arm.split("/")
    return f"{REWARD_NAMES[reward]}; {BOOTSTRAP_RULES[bootstrap.removesuffix('_bootstrap')].split(':')[0]}"


def fig6(curves: dict, optimum: int, tamer_length: float | None, title: str, tamer_label: str) -> Figure:
    """Paper Fig. 6: mean and spread (+-1 std and min-max bands) over agents of episode length against env steps."""
    fig = Figure(figsize=(8, 5.5), layout="constrained")
    ax = fig.subplots()
    for (arm, (grid, values)), colour in zip(curves.items(), ("tab:blue", "tab:orange"), strict=False):
        mean = values.mean(0)
        std = values.std(0)
        ax.plot(grid, mean, color=colour, label=f"{arm_label(arm)} (mean, n={len(values)})")
        ax.fill_between(grid, values.min(0), values.max(0), color=colour, alpha=0.12, lw=0)
        ax.fill_between(grid, np.maximum(mean - std, 0), mean + std, color=colour, alpha=0.25, lw=0)
    ax.axhline(optimum, color="black", ls="--", lw=1, label=f"optimum ({optimum})")
    if tamer_length is not None:
        ax.axhline(tamer_length, color="tab:red", ls=":", lw=1.5, label=f"{tamer_label} ({tamer_length:g})")
    ax.set(xlabel="environment steps", ylabel="training episode length", ylim=(0, 210))
    ax.set_title(f"{title}\nline: mean over agents; bands: +-1 std (dark), min-max (light)", fontsize=10)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=1, fontsize=8)
    ax.grid(alpha=0.3)
    return fig


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
    try:
        with open(path + ".tmp", "w") as f:
            json.dump(data, f, indent=2)
        os.replace(path + ".tmp", path)
    except OSError as e:  # no partial file; the error names the file
        with contextlib.suppress(FileNotFoundError):
            os.remove(path + ".tmp")
        raise OSError(e.errno, e.strerror, path) from None


def check_args(args: Args) -> None:
    """Reject bad flag values before anything is read or written; each message says what is wrong."""
    for name in ("num_threads", "num_episodes", "num_seeds", "final_window", "stability_window", "grid_points"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be a positive integer, got {getattr(args, name)}")
    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    name = args.exp_name
    if not name or name in (".", "..") or not name.isprintable() or any(c in name for c in "/\\") or len(name) > 150:
        raise ValueError(f"--exp-name {name[:160]!r}: a run name must be one short directory name inside runs/")
    if not 0.0 < args.alpha <= 1.0:
        raise ValueError(f"--alpha must be in (0, 1], got {args.alpha}")
    if not 0.0 <= args.gamma < 1.0:
        raise ValueError(f"--gamma must be in [0, 1), got {args.gamma}")
    if not 0.0 <= args.epsilon <= 1.0:
        raise ValueError(f"--epsilon must be in [0, 1], got {args.epsilon}")
    if args.env_id not in ("KnoxStoneMazeWall-v0", "KnoxStoneMaze-v0"):
        raise ValueError(f"--env-id must be KnoxStoneMazeWall-v0 or KnoxStoneMaze-v0, got {args.env_id!r}")


def one_line(e: Exception) -> str:
    lines = str(e).strip().splitlines()
    return f"{type(e).__name__}: {lines[0][:200]}" if lines else type(e).__name__


FILES = {"network": "inform_q.pt", "table": "recovered_reward.pt"}


def find_newest_run(runs_dir: str, filename: str) -> str:
    """The gridworld run directory under runs_dir with the newest `filename` (by file time)."""
    candidates = []
    if os.path.isdir(runs_dir):
        for name in os.listdir(runs_dir):
            path = os.path.join(runs_dir, name, filename)
            if os.path.isfile(path):
                candidates.append((os.path.getmtime(path), os.path.dirname(path)))
    if not candidates:
        raise ValueError(
            f"no --reward-path given and no {runs_dir}/*/{filename} found; "
            "run inform_dqn_gridworld.py first or pass --reward-path"
        )
    return max(candidates)[1]


def load_checkpoint(path: str, what: str) -> dict:
    if not os.path.isfile(path):
        raise ValueError(f"{what} {path} does not exist")
    if not zipfile.is_zipfile(path):  # torch.save writes a zip archive; a truncated one has lost its directory
        raise ValueError(f"cannot read {what} {path} as a torch checkpoint (not a complete zip archive)")
    try:  # torch.load checks no CRC: a flipped bit would be used
        with zipfile.ZipFile(path) as archive:
            damaged = archive.testzip()
    except Exception as e:  # a damaged archive fails in many ways (BadZipFile, EOFError, a garbled name)
        damaged = f"its archive: {e}"
    if damaged is not None:
        raise ValueError(f"{what} {path} is damaged since it was saved ({damaged} fails its CRC-32 check)")
    try:
        with warnings.catch_warnings():  # a foreign pickle warns before it fails; the error line says enough
            warnings.simplefilter("ignore")
            ckpt = torch.load(path, weights_only=True, map_location="cpu")
    except Exception as e:  # a corrupt or foreign file raises many kinds of errors; one line names it
        raise ValueError(f"cannot read {what} {path} as a torch checkpoint ({one_line(e)})") from None
    if not isinstance(ckpt, dict):
        raise ValueError(f"{path} is not a {what} checkpoint: expected a dict, found {type(ckpt).__name__}")
    return ckpt


def check_plain_maze(ckpt: dict, path: str, what: str) -> None:
    """The reward must come from INFORM on the plain maze: the experiment transfers it to the wall maze."""
    env_id = ckpt.get("env_id")
    if env_id not in gridworld_env.ENV_IDS:
        raise ValueError(
            f"{path}: a {what} for {env_id!r}, not for one of the mazes ({', '.join(gridworld_env.ENV_IDS)})"
        )
    if gridworld_env.ENV_IDS[env_id].get("variant") != "plain":
        raise ValueError(f"{path}: a {what} learnt on {env_id}; the reward experiment needs one from the plain maze")


def load_inform_network(path: str) -> tuple[QNetwork, dict]:
    """The saved INFORM soft Q network and the sleep phase's gamma and temperature that define its reward (Eq. 3)."""
    ckpt = load_checkpoint(path, "INFORM network")
    if not isinstance(ckpt.get("state_dict"), dict) or not isinstance(ckpt.get("kwargs"), dict):
        raise ValueError(f"{path} is not a saved network: needs 'state_dict' and 'kwargs' (keys: {sorted(ckpt)})")
    check_plain_maze(ckpt, path, "network")
    dims = (ckpt["kwargs"].get("obs_dim"), ckpt["kwargs"].get("n_actions"))
    if dims != (gridworld_env.N_CELLS, gridworld_env.N_ACTIONS):
        raise ValueError(f"{path}: a network for obs {dims[0]}, actions {dims[1]}, not the maze's 30 cells x 4 moves")
    meta = {k: ckpt.get(k) for k in ("env_id", "gamma", "temperature")}
    gamma = meta["gamma"]
    temperature = meta["temperature"]
    if not isinstance(gamma, float | int) or not 0.0 <= gamma < 1.0:
        raise ValueError(f"{path}: needs the sleep phase's 'gamma' in [0, 1) to recover the reward, found {gamma!r}")
    if not isinstance(temperature, float | int) or not 0.0 < temperature < float("inf"):
        raise ValueError(
            f"{path}: needs the sleep phase's 'temperature' > 0 to recover the reward, found {temperature!r}"
        )
    try:
        net = QNetwork(**ckpt["kwargs"])
        net.load_state_dict(ckpt["state_dict"])
    except Exception as e:
        raise ValueError(f"cannot rebuild the INFORM network from {path} ({one_line(e)})") from None
    return net, meta


def load_reward_table(path: str) -> tuple[np.ndarray, dict]:
    """The (30, 4) table r(s, a) a gridworld run saved (plain maze's s'), and its metadata."""
    ckpt = load_checkpoint(path, "reward table")
    reward = ckpt.get("reward")
    if not isinstance(reward, torch.Tensor):
        raise ValueError(f"{path} is not a recovered-reward checkpoint: no 'reward' tensor (keys: {sorted(ckpt)})")
    expected = (gridworld_env.N_CELLS, gridworld_env.N_ACTIONS)
    if tuple(reward.shape) != expected:
        raise ValueError(f"reward table in {path} has shape {tuple(reward.shape)}, expected {expected}")
    if "env_id" in ckpt:
        check_plain_maze(ckpt, path, "reward table")
    meta = {k: v for k, v in ckpt.items() if k != "reward" and isinstance(v, str | int | float)}
    return reward.double().numpy(), meta


def load_tamer(path: str) -> np.ndarray:
    """The greedy policy table (one action per cell) of a saved TAMER network H(s, a)."""
    ckpt = load_checkpoint(path, "TAMER network")
    try:
        net = QNetwork(**ckpt["kwargs"])
        net.load_state_dict(ckpt["state_dict"])
        with torch.no_grad():
            return net(torch.eye(gridworld_env.N_CELLS)).argmax(1).numpy()
    except Exception as e:
        raise ValueError(f"cannot rebuild the TAMER network from {path} ({one_line(e)})") from None


def resolve_sources(args: Args) -> list[dict]:
    """Find and read every input before anything is written: per gridworld run, its reward and TAMER's network."""
    filename = FILES[args.reward_source]
    paths = args.reward_path
    if not paths:
        paths = (find_newest_run(args.runs_dir, filename),)
        print(f"gridworld run: {paths[0]} (the newest with a {filename} under {args.runs_dir}/)", flush=True)
    next_cell = gridworld_env.transition_table(gym.make(args.env_id).unwrapped.variant)
    sources, seen = [], set()
    for given in paths:
        path = os.path.join(given, filename) if os.path.isdir(given) else given
        if os.path.realpath(path) in seen:
            raise ValueError(f"--reward-path names {path} twice: each run's reward counts once (n is the runs given)")
        seen.add(os.path.realpath(path))
        source = {"path": path, "network": None, "table": None}
        if args.reward_source == "network":
            source["network"], source["meta"] = load_inform_network(path)
        else:
            source["table"], source["meta"] = load_reward_table(path)
            if not np.isfinite(source["table"]).all():
                raise ValueError(f"reward table in {path} contains NaN or inf")
        source["reward"] = reward_for(source, args.reward_source, next_cell)
        source["tamer_path"] = os.path.join(os.path.dirname(path), "tamer_h.pt")
        has_tamer = os.path.isfile(source["tamer_path"])
        source["tamer_policy"] = load_tamer(source["tamer_path"]) if has_tamer else None
        sources.append(source)
    return sources


def reward_for(source: dict, reward_source: str, next_cell: np.ndarray) -> dict:
    """The reward the agents train on: Eq. 3 on this maze's s' (network), or the saved plain-maze table."""
    if reward_source == "table":
        return {"table": source["table"], "next_cell": None}
    meta = source["meta"]
    table = transition_reward_table(source["network"], next_cell, float(meta["gamma"]), float(meta["temperature"]))
    if not np.isfinite(table).all():
        raise ValueError(f"the recovered reward of {source['path']} contains NaN or inf")
    return {"table": table, "next_cell": next_cell}


# How a run ends: signals, a dead reader of our output, messages that cannot crash the exit ---------------------------
class StopSignals:
    """SIGINT (Ctrl-C; unless ignored: nohup, `&`), SIGTERM (kill, Slurm) and SIGHUP (a closed terminal) stop the
    run. The handler only records the signal. `StopSignals.check()`, at the head of every agent's episodes, then raises
    KeyboardInterrupt in our own code, never inside a library call (one raised inside TensorBoard's queue put could
    leave close() waiting up to 120 s), and main catches it to save what finished. Signals after the first, and any
    after the summary, are only noted."""

    current = None  # the run's StopSignals, which check() reads

    def __init__(self):
        self.received = []
        self.raised = False
        self.finished = False
        self.broken_pipe = False
        self.previous = {}
        for sig in STOP_SIGNALS:
            if signal.getsignal(sig) is not signal.SIG_IGN:
                self.previous[sig] = signal.signal(sig, self.handler)
        StopSignals.current = self

    def restore(self):
        """The handlers from before (main also runs inside other programs, e.g. the tests)."""
        for sig, handler in self.previous.items():
            signal.signal(sig, handler)

    def handler(self, signum, frame):
        self.received.append(signal.Signals(signum).name)

    @classmethod
    def check(cls) -> None:
        """KeyboardInterrupt if a stop signal came (once: main then saves what finished, and says so)."""
        stop = cls.current
        if stop is not None and stop.received and not (stop.raised or stop.finished):
            stop.raised = True
            raise KeyboardInterrupt

    def reason(self) -> str:
        """What stopped the run: the first signal; else SIGPIPE if the reader of our output died, else Ctrl-C."""
        return self.received[0] if self.received else "SIGPIPE" if self.broken_pipe else "SIGINT"

    def exit_code(self, status: str) -> int:
        """128 + the signal (130 SIGINT, 143 SIGTERM, 129 SIGHUP, 141 a dead reader), as a shell reports a kill;
        a signal after the summary still says the person wanted the run to stop (a shell loop then stops too)."""
        if status == "interrupted" or self.received:
            return 128 + signal.Signals[self.reason()].value
        return 0 if status == "completed" else 1  # failed, or unrecorded (no summary.json)


def say(text: str, file=None) -> None:
    """print, except that a dead reader (a broken pipe) is not an error: what follows goes to /dev/null."""
    file = file or sys.stdout
    try:
        print(text, file=file, flush=True)
    except OSError:  # BrokenPipeError, or a closed terminal
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), file.fileno())  # the exit's final flush then succeeds too


if __name__ == "__main__":
    try:
        args = tyro.cli(Args)  # a malformed flag: tyro's own message, exit 2
        if gridworld_env is None:
            raise ValueError(
                "gridworld_env.py (the maze) is not importable: copy it next to this script, or run from the repo"
            )
        check_args(args)
        sources = resolve_sources(args)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    stop = StopSignals()
    summary = main(args, sources, stop)
    gc.freeze()  # the interpreter's last collections over torch's objects take seconds on a busy machine; skip them
    sys.exit(stop.exit_code(summary["status"]))
