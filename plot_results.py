"""Draw the paper's figures from finished runs (their TensorBoard events, summary.json and saved arrays).

    python plot_results.py --maze-exp fig3 --pusher-exp fig3 --out docs/figures

Writes, each only when its runs exist:
- fig3_maze.png: TAMER's greedy episode length against env steps, INFORM's against sleep steps, the oracle (Fig. 3);
- fig3_pusher.png: the same for Pusher's return (Fig. 3);
- fig5b_obstacle.png: final object-goal distances of TAMER and INFORM on the obstacle env (Fig. 5b);
- fig6_wall_maze.png: Q-learning on the wall maze with the recovered and the environment reward (Fig. 6);
- recovered_reward.png: the recovered reward of one maze run, drawn over the maze.
"""

import contextlib
import glob
import io
import json
import os
import sys
from dataclasses import dataclass

import numpy as np
import torch
import tyro
from matplotlib.figure import Figure
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from inform_dqn_gridworld import reward_figure

COLOURS = {"oracle": "black", "tamer": "tab:orange", "inform": "tab:blue", "recovered": "tab:blue", "env": "tab:red"}


@dataclass
class Args:
    maze_exp: str = "inform_dqn_gridworld"
    """exp_name of the gridworld runs (one per seed)"""
    pusher_exp: str = "inform_sac_pusher"
    """exp_name of the Pusher runs (one per seed)"""
    qlearning_exp: str = "q_learning_recovered_reward"
    """exp_name of the reward-experiment run (it holds all its seeds)"""
    runs_dir: str = "runs"
    """where the runs are"""
    out: str = "docs/figures"
    """where the PNGs go"""


def completed_runs(runs_dir: str, pattern: str) -> list[str]:
    """Run directories matching the pattern whose summary.json says completed, newest per seed."""
    by_seed = {}
    for path in sorted(glob.glob(os.path.join(runs_dir, pattern, "summary.json")), key=os.path.getmtime):
        with open(path) as f:
            summary = json.load(f)
        if summary.get("status") == "completed":
            by_seed[summary.get("seed")] = os.path.dirname(path)
    return [by_seed[s] for s in sorted(by_seed)]


def curves(run_dirs: list[str], tag: str, last_step_arg: str) -> tuple[np.ndarray, np.ndarray]:
    """One scalar tag from several runs on a common step grid: (steps, values[run, step]), up to the phase's
    budget (the run's args[last_step_arg]); a final value some scripts log past it is left out."""
    series = []
    for run_dir in run_dirs:
        with open(os.path.join(run_dir, "summary.json")) as f:
            last_step = json.load(f)["args"][last_step_arg]
        acc = EventAccumulator(run_dir, size_guidance={"scalars": 0})
        acc.Reload()
        events = {e.step: e.value for e in acc.Scalars(tag) if e.step <= last_step}  # a repeated step: the last
        series.append((np.array(sorted(events)), np.array([events[s] for s in sorted(events)])))
    grid = series[0][0]
    return grid, np.stack([np.interp(grid, steps, values) for steps, values in series])


def band(ax, steps, values, label, colour):
    mean, std = values.mean(0), values.std(0)
    ax.plot(steps, mean, label=f"{label} (n={len(values)})", color=colour)
    ax.fill_between(steps, mean - std, mean + std, color=colour, alpha=0.2)


def fig3(run_dirs: list[str], metric: str, ylabel: str, path: str, title: str) -> None:
    """TAMER against env steps (left), INFORM against sleep steps (right), the oracle as a line in both."""
    fig = Figure(figsize=(11, 4))
    day, night = fig.subplots(1, 2, sharey=True)
    steps, tamer = curves(run_dirs, f"eval/tamer_{metric}", "tamer_total_timesteps")
    band(day, steps, tamer, "TAMER", COLOURS["tamer"])
    sleep_steps, inform = curves(run_dirs, f"eval/inform_{metric}", "sleep_gradient_steps")
    band(night, sleep_steps, inform, "INFORM", COLOURS["inform"])
    oracle = np.mean([json.load(open(os.path.join(d, "summary.json")))[f"eval/oracle_{metric}"] for d in run_dirs])
    for ax in (day, night):
        ax.axhline(oracle, color=COLOURS["oracle"], ls=":", lw=1.5, label="oracle", zorder=3)
        ax.legend()
        ax.grid(alpha=0.3)
    day.set(xlabel="environment steps (forward phase)", ylabel=ylabel, title=f"{title}: day (TAMER)")
    night.set(xlabel="gradient steps (sleep phase, no env steps)", title=f"{title}: sleep (INFORM)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def fig5b(run_dirs: list[str], path: str) -> None:
    """Final object-goal distance on the obstacle env, every episode of every seed, per policy."""
    data = {}
    for run_dir in run_dirs:
        with np.load(os.path.join(run_dir, "obstacle_distances.npz")) as npz:
            for policy in npz.files:
                data.setdefault(policy, []).append(npz[policy])
    policies = [p for p in ("oracle", "tamer", "inform") if p in data]
    fig = Figure(figsize=(6, 4))
    ax = fig.subplots()
    ax.boxplot([np.concatenate(data[p]) for p in policies], tick_labels=[p.upper() for p in policies])
    ax.set(ylabel="final object-goal distance (m)", title=f"Pusher + obstacle, {len(run_dirs)} seeds")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def fig6(run_dir: str, path: str) -> None:
    """Q-learning on the wall maze: mean and spread over seeds of episode length against env steps."""
    summary = json.load(open(os.path.join(run_dir, "summary.json")))
    fig = Figure(figsize=(7, 4))
    ax = fig.subplots()
    for arm, label in (("recovered", "Q-learning, INFORM's reward"), ("env", "Q-learning, env reward")):
        acc = EventAccumulator(run_dir, size_guidance={"scalars": 0})
        acc.Reload()
        tags = sorted(t for t in acc.Tags()["scalars"] if t.startswith(f"qlearning/{arm}/seed_") and
                      t.endswith("/episode_length") and "greedy" not in t)  # fmt: skip
        # a seed that finished its episodes in fewer steps is held at its last length (np.interp does that)
        grid = np.linspace(0, max(acc.Scalars(t)[-1].step for t in tags), 200)
        values = np.stack([np.interp(grid, [e.step for e in acc.Scalars(t)], [e.value for e in acc.Scalars(t)])
                           for t in tags])  # fmt: skip
        band(ax, grid, values, label, COLOURS[arm])
    ax.axhline(summary["optimum_episode_length"], color="black", ls="--", label="optimum")
    if "eval/wall/tamer_episode_length" in summary:
        ax.axhline(summary["eval/wall/tamer_episode_length"], color=COLOURS["tamer"], ls=":", label="TAMER policy")
    ax.set(xlabel="environment steps", ylabel="episode length", title="Wall maze (Fig. 6)")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(args: Args) -> None:
    if not os.path.isdir(args.runs_dir):
        raise ValueError(f"--runs-dir {args.runs_dir}: no such directory (run the experiments first, see README)")
    os.makedirs(args.out, exist_ok=True)
    written = []
    maze = completed_runs(args.runs_dir, f"KnoxStoneMaze-v0__{args.maze_exp}__*")
    if maze:
        fig3(maze, "episode_length", "greedy episode length", f"{args.out}/fig3_maze.png", "Maze")
        ckpt = torch.load(os.path.join(maze[0], "recovered_reward.pt"), weights_only=True)
        seed = json.load(open(os.path.join(maze[0], "summary.json")))["seed"]
        reward_figure(ckpt["reward"].numpy(), f"recovered reward r(s, a), seed {seed}").savefig(
            f"{args.out}/recovered_reward.png", dpi=120
        )
        written += ["fig3_maze.png", "recovered_reward.png"]
    pusher = completed_runs(args.runs_dir, f"Pusher-v*__{args.pusher_exp}__*")
    if pusher:
        fig3(pusher, "return", "episode return", f"{args.out}/fig3_pusher.png", "Pusher")
        fig5b(pusher, f"{args.out}/fig5b_obstacle.png")
        written += ["fig3_pusher.png", "fig5b_obstacle.png"]
    qlearning = completed_runs(args.runs_dir, f"KnoxStoneMazeWall-v0__{args.qlearning_exp}__*")
    if qlearning:
        fig6(qlearning[-1], f"{args.out}/fig6_wall_maze.png")
        written.append("fig6_wall_maze.png")
    print(f"wrote {', '.join(written) or 'nothing (no finished runs found)'} to {args.out}")


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
        main(parse_args())
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
