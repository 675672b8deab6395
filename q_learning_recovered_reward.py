"""Tabular Q-learning on the wall maze with INFORM's recovered reward against the environment's own reward.

Reproduces the reward experiment of Tarakli & Di Nuovo, "Learning while Sleeping" (ICDL 2024), Fig. 6 (SPEC.md
sections 6, 7 and 9): the reward r(s, a) that INFORM recovered on the plain maze (Eq. 3, saved by
inform_dqn_gridworld.py) trains fresh Q-learning agents on the wall variant, which the recovered reward never saw,
next to agents trained on the environment reward (+1 at G). The TAMER network of the same gridworld run is
evaluated on the wall maze, untrained there, as the baseline.

    python inform_dqn_gridworld.py --seed 1
    python q_learning_recovered_reward.py --reward-path runs/KnoxStoneMaze-v0__inform_dqn_gridworld__1__<t>

Choices the paper leaves open, fixed here:
- The recovered reward replaces the environment's reward: a step (s, a) earns table[s, a] whatever s' the wall
  maze gives. The table was computed with the plain maze's s' (so the two moves the new walls block, 10 down and
  18 up, keep the reward of a move that now bumps). Entering G terminates, as in the environment; the table's
  entry for that step is Q(s, a) (Eq. 3 with terminated = 1) and Q-learning does not bootstrap past it.
  Truncation at 200 steps (the registered TimeLimit) does bootstrap.
- Q starts at zero. Ties in the behaviour policy's argmax are broken uniformly at random with the run's seeded
  rng (argmax-first would always pick "up" in unvisited cells). The greedy policy that is evaluated after each
  episode takes the first maximal action, so the evaluation consumes no randomness.
- A seed whose greedy policy is not at the optimum from some episode to the last is "not reached": it counts in
  `n_reached`, and `steps_to_optimum` / `episodes_to_optimum` are averaged over the seeds that reached it
  (null when none did). No censored value is imputed.
"""

import contextlib
import io
import json
import os
import sys
import time
import warnings
from dataclasses import asdict, dataclass

import gymnasium as gym
import numpy as np
import torch
import torch.nn as nn
import tyro
from matplotlib.figure import Figure
from torch.utils.tensorboard import SummaryWriter

import gridworld_env

ARMS = ("recovered", "env")
METRICS = ("steps_to_optimum", "episodes_to_optimum", "auc", "final_episode_length")


@dataclass
class Args:
    exp_name: str = os.path.basename(__file__)[: -len(".py")]
    """the name of this experiment"""
    seed: int = 1
    """seed of the first Q-learning run; the others use seed + 1, ..., seed + num_seeds - 1 (the same in both arms)"""
    num_threads: int = 1
    """torch CPU threads (torch only loads the checkpoints and runs the 30-cell TAMER network once)"""
    env_id: str = "KnoxStoneMazeWall-v0"
    """the maze the Q-learning agents train on"""

    # Reward source
    reward_path: str | None = None
    """recovered_reward.pt (or the gridworld run directory holding it); default: the newest such file under runs/"""
    runs_dir: str = "runs"
    """where to look for gridworld runs when --reward-path is not given"""

    # Q-learning
    num_episodes: int = 300
    """training episodes per seed and arm"""
    num_seeds: int = 5
    """independent Q-learning runs per arm"""
    alpha: float = 0.2
    """Q-learning step size"""
    gamma: float = 0.99
    """Q-learning discount"""
    epsilon: float = 0.05
    """probability of a uniformly random action (fixed, no decay)"""

    # Reporting
    dense_threshold: float = 1e-3
    """a recovered reward entry counts as non-zero ("dense") when |r(s, a)| exceeds this"""
    final_window: int = 10
    """final_episode_length is the mean training episode length over this many last episodes"""
    grid_points: int = 200
    """points of the common env-step grid the per-seed curves are interpolated to (mean curve and fig6.png)"""


def check_args(args: Args) -> None:
    """Reject bad flag values before anything is read or written; each message says what is wrong."""
    for name in ("num_threads", "num_episodes", "num_seeds", "final_window", "grid_points"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be a positive integer, got {getattr(args, name)}")
    if not 0.0 < args.alpha <= 1.0:
        raise ValueError(f"--alpha must be in (0, 1], got {args.alpha}")
    if not 0.0 <= args.gamma < 1.0:
        raise ValueError(f"--gamma must be in [0, 1), got {args.gamma}")
    if not 0.0 <= args.epsilon <= 1.0:
        raise ValueError(f"--epsilon must be in [0, 1], got {args.epsilon}")
    if args.dense_threshold < 0.0:
        raise ValueError(f"--dense-threshold must be >= 0, got {args.dense_threshold}")
    if args.env_id not in ("KnoxStoneMazeWall-v0", "KnoxStoneMaze-v0"):
        raise ValueError(f"--env-id must be KnoxStoneMazeWall-v0 or KnoxStoneMaze-v0, got {args.env_id!r}")


class QNetwork(nn.Module):
    """The 30-32-32-4 MLP of inform_dqn_gridworld.py, rebuilt here to load the saved TAMER network H(s, a)."""

    def __init__(self, obs_dim: int, n_actions: int, hidden: int = 32):
        super().__init__()
        self.network = nn.Sequential(
            nn.Linear(obs_dim, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, n_actions)
        )

    def forward(self, x):
        return self.network(x)


def one_line(e: Exception) -> str:
    lines = str(e).strip().splitlines()
    return f"{type(e).__name__}: {lines[0][:200]}" if lines else type(e).__name__


def find_newest_reward(runs_dir: str) -> str:
    """The recovered_reward.pt of the newest run (by file time) under runs_dir."""
    candidates = []
    if os.path.isdir(runs_dir):
        for name in os.listdir(runs_dir):
            path = os.path.join(runs_dir, name, "recovered_reward.pt")
            if os.path.isfile(path):
                candidates.append((os.path.getmtime(path), path))
    if not candidates:
        raise ValueError(
            f"no --reward-path given and no {runs_dir}/*/recovered_reward.pt found; "
            "run inform_dqn_gridworld.py first or pass --reward-path"
        )
    return max(candidates)[1]


def load_checkpoint(path: str, what: str) -> dict:
    try:
        with warnings.catch_warnings():  # a foreign pickle warns before it fails; the error line says enough
            warnings.simplefilter("ignore")
            ckpt = torch.load(path, weights_only=True, map_location="cpu")
    except Exception as e:  # a corrupt or foreign file raises many kinds of errors; one line names it
        raise ValueError(f"cannot read {what} {path} as a torch checkpoint ({one_line(e)})") from None
    if not isinstance(ckpt, dict):
        raise ValueError(f"{path} is not a {what} checkpoint: expected a dict, found {type(ckpt).__name__}")
    return ckpt


def load_reward_table(path: str) -> tuple[np.ndarray, dict]:
    """The (30, 4) table r(s, a) a gridworld run saved, and its metadata (env_id, gamma, temperature)."""
    if os.path.isdir(path):
        path = os.path.join(path, "recovered_reward.pt")
    if not os.path.isfile(path):
        raise ValueError(f"reward table {path} does not exist")
    ckpt = load_checkpoint(path, "reward table")
    reward = ckpt.get("reward")
    if not isinstance(reward, torch.Tensor):
        raise ValueError(f"{path} is not a recovered-reward checkpoint: no 'reward' tensor (keys: {sorted(ckpt)})")
    expected = (gridworld_env.N_CELLS, gridworld_env.N_ACTIONS)
    if tuple(reward.shape) != expected:
        raise ValueError(f"reward table in {path} has shape {tuple(reward.shape)}, expected {expected}")
    table = reward.double().numpy()
    if not np.isfinite(table).all():
        raise ValueError(f"reward table in {path} contains NaN or inf")
    meta = {k: v for k, v in ckpt.items() if k != "reward" and isinstance(v, str | int | float)}
    return table, meta


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


def resolve_source(args: Args) -> dict:
    """Find and read every input before anything is written: the reward table and, if present, TAMER's network."""
    if args.reward_path is None:
        path = find_newest_reward(args.runs_dir)
        print(f"reward table: {path} (the newest gridworld run with a table under {args.runs_dir}/)", flush=True)
    else:
        path = args.reward_path
    table, meta = load_reward_table(path)
    path = os.path.join(path, "recovered_reward.pt") if os.path.isdir(path) else path
    tamer_path = os.path.join(os.path.dirname(path), "tamer_h.pt")
    tamer_policy = load_tamer(tamer_path) if os.path.isfile(tamer_path) else None
    return {"path": path, "table": table, "meta": meta, "tamer_path": tamer_path, "tamer_policy": tamer_policy}


def value_iteration(reward: np.ndarray, next_cell: np.ndarray, gamma: float, tol: float = 1e-10) -> np.ndarray:
    """Q(s, a) = r(s, a) + gamma (1 - [s' = G]) max_a' Q(s', a') for a reward table on a maze's deterministic moves."""
    not_done = (next_cell != gridworld_env.GOAL).astype(np.float64)
    q = np.zeros_like(reward, dtype=np.float64)
    while True:
        new_q = reward + gamma * not_done * q.max(axis=1)[next_cell]
        if np.abs(new_q - q).max() < tol:
            return new_q
        q = new_q


def reward_shape_report(table: np.ndarray, gamma: float, threshold: float) -> dict:
    """How dense the recovered reward is and how far its optimal policy agrees with the true one, per maze.

    Agreement: the fraction of states from which G is reachable (V* > 0; G itself excluded) where the greedy
    action of value iteration on the recovered reward is one of the true optimal actions (Q* ties count as a match).
    """
    non_goal = np.arange(gridworld_env.N_CELLS) != gridworld_env.GOAL  # G is terminal: its row is never used
    report = {
        "reward/density": float((np.abs(table[non_goal]) > threshold).mean()),
        "reward/density_threshold": threshold,
        "reward/positive_fraction": float((table[non_goal] > threshold).mean()),
    }
    for variant in ("plain", "wall"):
        next_cell = gridworld_env.transition_table(variant)
        q_star = gridworld_env.optimal_q(variant, gamma)
        policy = value_iteration(table, next_cell, gamma).argmax(1)
        reachable = (q_star.max(1) > 0) & non_goal
        cells = np.flatnonzero(reachable)
        match = q_star[cells, policy[cells]] >= q_star[cells].max(1) - 1e-9
        self_loop = (next_cell == np.arange(gridworld_env.N_CELLS)[:, None]) & non_goal[:, None]
        report[f"reward/{variant}/policy_agreement"] = float(match.mean())
        report[f"reward/{variant}/agreement_states"] = int(len(cells))
        report[f"reward/{variant}/vi_episode_length"] = gridworld_env.greedy_episode_length(policy, variant)
        report[f"reward/{variant}/positive_self_loops"] = int((self_loop & (table > threshold)).sum())
    return report


def greedy_path(policy: np.ndarray, variant: str, max_steps: int = 40) -> list[int]:
    """The cells a table policy visits from S (for the printed report)."""
    next_cell = gridworld_env.transition_table(variant)
    path = [gridworld_env.START]
    while len(path) <= max_steps and path[-1] != gridworld_env.GOAL:
        path.append(int(next_cell[path[-1], policy[path[-1]]]))
    return path


def epsilon_greedy(q_s: np.ndarray, epsilon: float, rng: np.random.Generator) -> int:
    """A random action with probability epsilon, else a greedy one with ties broken uniformly at random."""
    if rng.random() < epsilon:
        return int(rng.integers(len(q_s)))
    best = np.flatnonzero(q_s == q_s.max())
    return int(best[rng.integers(len(best))]) if len(best) > 1 else int(best[0])


def q_learning(env: gym.Env, reward_table: np.ndarray | None, args: Args, seed: int, variant: str) -> dict:
    """Tabular Q-learning for args.num_episodes episodes; reward_table None means the environment's reward.

    Returns per episode the training length, the cumulative env steps at its end, and the greedy policy's length
    on `variant` evaluated after it.
    """
    rng = np.random.default_rng(seed)
    q = np.zeros((gridworld_env.N_CELLS, gridworld_env.N_ACTIONS))
    lengths, steps_at_end, greedy_lengths = [], [], []
    total_steps = 0
    obs, _ = env.reset(seed=seed)
    for _ in range(args.num_episodes):
        s = int(obs.argmax())
        length, terminated, truncated = 0, False, False
        while not (terminated or truncated):
            a = epsilon_greedy(q[s], args.epsilon, rng)
            obs, env_reward, terminated, truncated, _ = env.step(a)
            s_next = int(obs.argmax())
            r = env_reward if reward_table is None else reward_table[s, a]  # the recovered reward replaces it
            target = r if terminated else r + args.gamma * q[s_next].max()  # truncation still bootstraps
            q[s, a] += args.alpha * (target - q[s, a])
            s = s_next
            length += 1
        total_steps += length
        lengths.append(length)
        steps_at_end.append(total_steps)
        greedy_lengths.append(gridworld_env.greedy_episode_length(q.argmax(1), variant))
        obs, _ = env.reset()
    return {
        "lengths": np.array(lengths),
        "steps": np.array(steps_at_end),
        "greedy": np.array(greedy_lengths),
        "q": q,
    }


def time_to_optimum(run: dict, optimum: int) -> tuple[float, float]:
    """(env steps, episodes) until the greedy policy first reaches the optimum and keeps it to the last episode."""
    at_optimum = run["greedy"] == optimum
    if not at_optimum[-1]:
        return float("nan"), float("nan")
    off = np.flatnonzero(~at_optimum)
    first = 0 if len(off) == 0 else off[-1] + 1  # first episode of the final streak at the optimum
    return float(run["steps"][first]), float(first + 1)


def run_metrics(run: dict, optimum: int, final_window: int) -> dict:
    steps, episodes = time_to_optimum(run, optimum)
    return {
        "steps_to_optimum": steps,
        "episodes_to_optimum": episodes,
        # area under the episode-length curve against the episode number: the env steps the episodes took
        "auc": float(run["lengths"].sum()),
        "final_episode_length": float(run["lengths"][-final_window:].mean()),
        "final_greedy_episode_length": float(run["greedy"][-1]),
    }


def nan_to_none(x: float):
    return None if not np.isfinite(x) else float(x)


def interpolate_curves(runs: list[dict], grid: np.ndarray) -> np.ndarray:
    """Each seed's episode length (at the env step its episode ended) on a common step grid; (seeds, points).

    np.interp holds the first episode's length before it ends and the last one's after the seed's budget ran out.
    """
    return np.stack([np.interp(grid, run["steps"], run["lengths"]) for run in runs])


def fig6(curves: dict, optimum: int, tamer_length: float | None, title: str, tamer_label: str) -> Figure:
    """Paper Fig. 6: mean and spread (+-1 std and min-max bands) over seeds of episode length against env steps."""
    fig = Figure(figsize=(7, 5), layout="constrained")
    ax = fig.subplots()
    colours = {"recovered": "tab:blue", "env": "tab:orange"}
    labels = {"recovered": "Q-learning, INFORM recovered reward", "env": "Q-learning, environment reward"}
    for arm, (grid, values) in curves.items():
        mean, std = values.mean(0), values.std(0)
        ax.plot(grid, mean, color=colours[arm], label=f"{labels[arm]} (mean, n={len(values)})")
        ax.fill_between(grid, values.min(0), values.max(0), color=colours[arm], alpha=0.12, lw=0)
        ax.fill_between(grid, np.maximum(mean - std, 0), mean + std, color=colours[arm], alpha=0.25, lw=0)
    ax.axhline(optimum, color="black", ls="--", lw=1, label=f"optimum ({optimum})")
    if tamer_length is not None:
        ax.axhline(tamer_length, color="tab:red", ls=":", lw=1.5, label=f"{tamer_label} ({tamer_length:g})")
    ax.set(xlabel="environment steps", ylabel="episode length", ylim=(0, 210))
    ax.set_title(f"{title}\nline: mean over seeds; bands: +-1 std (dark), min-max (light)", fontsize=10)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, fontsize=8)
    ax.grid(alpha=0.3)
    return fig


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


def run_arm(args: Args, arm: str, seeds: list, source: dict, variant: str, optimum: int, runs: list, writer) -> None:
    """Q-learning for every seed of one arm (the recovered reward, or the env's); finished runs are appended."""
    for i, seed in enumerate(seeds):
        env = gym.make(args.env_id)
        t_seed = time.time()
        run = q_learning(env, source["table"] if arm == "recovered" else None, args, seed, variant)
        env.close()
        run["seconds"] = time.time() - t_seed
        runs.append(run)
        m = run_metrics(run, optimum, args.final_window)
        for length, greedy, step in zip(run["lengths"], run["greedy"], run["steps"], strict=True):
            writer.add_scalar(f"qlearning/{arm}/seed_{seed}/episode_length", length, step)
            writer.add_scalar(f"qlearning/{arm}/seed_{seed}/greedy_episode_length", greedy, step)
        print(
            f"[{arm}] seed {seed} ({i + 1}/{len(seeds)}): {args.num_episodes} episodes | "
            f"{int(run['steps'][-1]):,} env steps | greedy {int(run['greedy'][-1])} | "
            f"steps to optimum {m['steps_to_optimum']:,.0f} | episodes to optimum {m['episodes_to_optimum']:.0f} | "
            f"{run['seconds']:.1f}s",
            flush=True,
        )


def main(args: Args, source: dict) -> dict:
    run_name = f"{args.env_id}__{args.exp_name}__{args.seed}__{int(time.time())}"
    run_start = time.time()
    torch.set_num_threads(args.num_threads)
    variant = gym.make(args.env_id).unwrapped.variant
    seeds = [args.seed + i for i in range(args.num_seeds)]

    # Reward-shape report and the baselines, from the inputs alone
    optimum = gridworld_env.greedy_episode_length(gridworld_env.optimal_q(variant, args.gamma).argmax(1), variant)
    shape = reward_shape_report(source["table"], args.gamma, args.dense_threshold)
    tamer_length = None
    if source["tamer_policy"] is not None:
        tamer_length = float(gridworld_env.greedy_episode_length(source["tamer_policy"], variant))

    run_dir = make_run_dir(run_name)
    writer = SummaryWriter(run_dir)
    writer.add_text(
        "hyperparameters",
        "|param|value|\n|-|-|\n" + "\n".join(f"|{key}|{value}|" for key, value in vars(args).items()),
    )
    print(f"run directory: {run_dir}", flush=True)
    print(f"optimum on {args.env_id}: {optimum} steps", flush=True)
    if tamer_length is None:
        print(f"TAMER baseline: no network at {source['tamer_path']}, skipped", flush=True)
    else:
        print(f"TAMER baseline ({source['tamer_path']}) on {args.env_id}: {tamer_length:g} steps", flush=True)
    vi_policies = {v: value_iteration(source["table"], gridworld_env.transition_table(v), args.gamma).argmax(1)
                   for v in ("plain", "wall")}  # fmt: skip
    print("reward shape: " + " | ".join(f"{k.removeprefix('reward/')} {v:.4g}" for k, v in shape.items()), flush=True)
    for v, policy in vi_policies.items():
        print(
            f"  greedy path of value iteration on the recovered reward, {v} maze: {greedy_path(policy, v)}", flush=True
        )

    # Q-learning, both arms on the same seeds
    runs = {arm: [] for arm in ARMS}
    times = {}
    arm = ARMS[0]
    try:
        for arm in ARMS:
            run_arm(args, arm, seeds, source, variant, optimum, runs[arm], writer)
            times[f"time/{arm}_s"] = sum(run["seconds"] for run in runs[arm])
    except KeyboardInterrupt:
        # what finished is kept: the summary records the seeds done per arm and no figure is drawn
        print(f"interrupted during the {arm} arm; the summary in {run_dir} says what finished", file=sys.stderr)
        summary = {
            **{f"qlearning/{a}/seeds_done": len(runs[a]) for a in ARMS},
            "wall_time_s": time.time() - run_start,
            "seed": args.seed,
            "script": os.path.basename(__file__),
            "status": "interrupted",
            "phase": arm,
            "args": asdict(args),
        }
        write_json_atomic(f"{run_dir}/summary.json", summary)
        writer.close()
        return summary

    # Curves on a common env-step grid per arm, the mean to TensorBoard, mean and spread to fig6.png
    curves = {}
    for arm in ARMS:
        grid = np.linspace(0, max(int(run["steps"][-1]) for run in runs[arm]), args.grid_points + 1)[1:]
        curves[arm] = (grid, interpolate_curves(runs[arm], grid))
        for step, mean in zip(grid, curves[arm][1].mean(0), strict=True):
            writer.add_scalar(f"qlearning/{arm}/episode_length", mean, int(step))
    tamer_label = "TAMER, untrained on the wall" if variant == "wall" else "TAMER"
    figure = fig6(curves, optimum, tamer_length, f"{args.env_id}: Q-learning, {len(seeds)} seeds", tamer_label)
    figure.savefig(f"{run_dir}/fig6.png", dpi=120)

    tamer_key = "eval/wall/tamer_episode_length" if variant == "wall" else "eval/tamer_episode_length"
    summary = {"optimum_episode_length": optimum, tamer_key: tamer_length}
    for arm in ARMS:
        per_seed = [run_metrics(run, optimum, args.final_window) for run in runs[arm]]
        for metric in (*METRICS, "final_greedy_episode_length"):
            values = np.array([m[metric] for m in per_seed])
            reached = values[np.isfinite(values)]
            key = f"qlearning/{arm}/{metric}"
            summary[f"{key}_mean"] = nan_to_none(reached.mean()) if len(reached) else None
            summary[f"{key}_std"] = nan_to_none(reached.std()) if len(reached) else None
            summary[f"{key}_per_seed"] = [nan_to_none(v) for v in values]
        summary[f"qlearning/{arm}/n_reached"] = int(np.isfinite([m["steps_to_optimum"] for m in per_seed]).sum())
        summary[f"qlearning/{arm}/total_env_steps_mean"] = float(np.mean([run["steps"][-1] for run in runs[arm]]))
    for key, value in summary.items():
        if isinstance(value, int | float) and not isinstance(value, bool):
            writer.add_scalar(key, value, 0)
    summary.update(shape)
    summary.update(
        {
            "reward/source": os.path.abspath(source["path"]),
            "reward/env_id": source["meta"].get("env_id"),
            "reward/tamer_path": os.path.abspath(source["tamer_path"]) if tamer_length is not None else None,
            "seeds": seeds,
            **times,
            "wall_time_s": time.time() - run_start,
            "seed": args.seed,
            "script": os.path.basename(__file__),
            "status": "completed",
            "args": asdict(args),
        }
    )
    write_json_atomic(f"{run_dir}/summary.json", summary)
    writer.close()
    for arm in ARMS:
        k = f"qlearning/{arm}"
        mean, std = summary[f"{k}/steps_to_optimum_mean"], summary[f"{k}/steps_to_optimum_std"]
        reached = "never" if mean is None else f"{mean:,.0f} ± {std:,.0f}"
        print(
            f"{arm}: steps to optimum {reached} (reached by {summary[f'{k}/n_reached']}/{len(seeds)}) | "
            f"final episode length {summary[f'{k}/final_episode_length_mean']:.1f} | "
            f"auc {summary[f'{k}/auc_mean']:,.0f}",
            flush=True,
        )
    print(f"done in {summary['wall_time_s']:.1f}s; summary: {run_dir}/summary.json, figure: {run_dir}/fig6.png")
    return summary


def parse_args() -> Args:
    """tyro's command line, with tyro's multi-line error box shortened to one line."""
    captured = io.StringIO()
    try:
        with contextlib.redirect_stderr(captured):
            return tyro.cli(Args)
    except SystemExit as e:
        if e.code == 0:  # --help
            raise
        message = []
        for line in captured.getvalue().splitlines()[1:]:  # the first line is the box's title bar
            text = line.strip().strip("│╰╯").strip()
            if not text or set(text) <= set("─"):
                if message:
                    break
                continue
            message.append(text)
        raise ValueError(" ".join(message) + " (see --help)") from None


if __name__ == "__main__":
    try:
        args = parse_args()
        check_args(args)
        source = resolve_source(args)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    summary = main(args, source)
    sys.exit(130 if summary["status"] == "interrupted" else 0)
