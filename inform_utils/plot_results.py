"""Draw the paper's figures from finished runs (their TensorBoard events, summary.json and saved arrays).

    python -m inform_utils.plot_results --maze-exp fig3 --pusher-exp fig3 --out docs/figures

Without --out the figures go into a fresh folder runs/figures__{time} (never over the committed docs/figures). A
run whose files cannot be read, or a maze run whose sleep was skipped (no INFORM), is left out, and the figure and the
output say so; a damaged recovered_reward.pt (its CRC-32) is refused. Writes, each only when its runs exist:
- fig3_maze.png: TAMER's greedy episode length against env steps, INFORM's against sleep steps, the oracle (Fig. 3);
- fig3_pusher.png: the same for Pusher's return (Fig. 3);
- fig5b_obstacle.png: final object-goal distances of TAMER and INFORM on the obstacle env (Fig. 5b);
- fig6_wall_maze.png: tabular agents on the wall maze, every arm of the reward-experiment runs (Fig. 6);
- recovered_reward.png: the recovered reward of one maze run, drawn over the maze;
- teacher_curves.png: with --teacher-curves (and then only it), teachers' training curves (oracle_train.py's
  eval_curve.csv): success and final distance on the selection starts against environment steps, the expert bar.

    python -m inform_utils.plot_results --teacher-curves results/teachers/Pusher-v5__demos_rlpd_eval_curve.csv \
        results/teachers/Pusher-v5__sac_oracle_890k_below_bar_eval_curve.csv --out docs/figures
"""

import csv
import glob
import io
import os
import sys
import time
from dataclasses import dataclass

import matplotlib
import numpy as np
import torch
import tyro
from matplotlib.figure import Figure
from matplotlib.patches import Polygon, Rectangle
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

import gridworld_env
from inform_utils.files import atomic, check_crc, read_json, read_npz
from oracle_train import EXPERT_FINAL_DISTANCE, EXPERT_SUCCESS_RATE

COLOURS = {"oracle": "black", "tamer": "tab:orange", "inform": "tab:blue"}


@dataclass
class Args:
    maze_exp: str = "inform_dqn_gridworld"
    """exp_name of the gridworld runs (one per seed)"""
    pusher_exp: str = "inform_sac_pusher"
    """exp_name of the Pusher runs (one per seed)"""
    qlearning_exp: str = "q_learning_recovered_reward"
    """exp_name of the reward-experiment runs (each holds one reward source and one bootstrap, with all agents)"""
    runs_dir: str = "runs"
    """where the runs are"""
    out: str | None = None
    """where the PNGs go (None: a fresh folder runs/figures__{time}, never over what the repository keeps)"""
    teacher_curves: tuple[str, ...] = ()
    """eval_curve.csv files of oracle_train.py runs, drawn together in teacher_curves.png (each labelled by its name)"""


def mtime(path: str) -> float:
    return os.lstat(path).st_mtime  # a dangling link too (it is then left out, with a note)


def completed_runs(runs_dir: str, pattern: str, notes: list[str] | None = None) -> list[str]:
    """Run directories matching the pattern whose summary.json says completed, newest per seed. A summary that cannot
    be read, and a run whose sleep was skipped (no INFORM to draw), are left out with a note in `notes`."""
    by_seed, notes = {}, [] if notes is None else notes
    for path in sorted(glob.glob(os.path.join(runs_dir, pattern, "summary.json")), key=mtime):
        try:
            summary = read_json(path)
        except ValueError as e:
            notes.append(f"left out {os.path.basename(os.path.dirname(path))}: {str(e).removeprefix(path + ': ')}")
            continue
        if summary.get("status") == "completed" and summary.get("sleep_skipped"):
            notes.append(f"left out {os.path.basename(os.path.dirname(path))}: its sleep was skipped (no INFORM)")
        elif summary.get("status") == "completed":
            by_seed[summary.get("seed")] = os.path.dirname(path)
    return [by_seed[s] for s in sorted(by_seed)]


def save(fig: Figure, path: str) -> None:
    """A PNG whole or not at all."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=120)
    with atomic(path, "wb") as f:
        f.write(buffer.getvalue())


def curves(run_dirs: list[str], tag: str, last_step_arg: str) -> tuple[np.ndarray, np.ndarray]:
    """One scalar tag from several runs on a common step grid: (steps, values[run, step]), up to the phase's
    budget (the run's args[last_step_arg]); a final value some scripts log past it is left out."""
    series = []
    for run_dir in run_dirs:
        last_step = read_json(os.path.join(run_dir, "summary.json"))["args"][last_step_arg]
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


def fig3(run_dirs: list[str], metric: str, ylabel: str, path: str, title: str, notes: tuple = ()) -> None:
    """TAMER against env steps (left), INFORM against sleep steps (right), the oracle as a line in both; the runs left
    out (`notes`) said under it."""
    fig = Figure(figsize=(11, 4))
    day, night = fig.subplots(1, 2, sharey=True)
    steps, tamer = curves(run_dirs, f"eval/tamer_{metric}", "tamer_total_timesteps")
    band(day, steps, tamer, "TAMER", COLOURS["tamer"])
    sleep_steps, inform = curves(run_dirs, f"eval/inform_{metric}", "sleep_gradient_steps")
    band(night, sleep_steps, inform, "INFORM", COLOURS["inform"])
    oracle = np.mean([read_json(os.path.join(d, "summary.json"))[f"eval/oracle_{metric}"] for d in run_dirs])
    for ax in (day, night):
        ax.axhline(oracle, color=COLOURS["oracle"], ls="--", lw=2, label="oracle", zorder=3)
        ax.legend(loc="lower right")
        ax.grid(alpha=0.3)
    # the axes share y: leave room above and below the oracle's line, so it never sits on the frame
    low, high = day.get_ylim()
    low, high = min(low, oracle), max(high, oracle)
    day.set_ylim(low - 0.08 * (high - low), high + 0.08 * (high - low))
    day.set(xlabel="environment steps (forward phase)", ylabel=ylabel, title=f"{title}: day (TAMER)")
    night.set(xlabel="gradient steps (sleep phase, no env steps)", title=f"{title}: sleep (INFORM)")
    fig.tight_layout(rect=(0, 0.05 if notes else 0, 1, 1))
    if notes:
        text = "; ".join(notes)
        fig.text(0.01, 0.01, text if len(text) < 220 else f"{text[:200]}... ({len(notes)} runs left out)", fontsize=7)
    save(fig, path)


def fig5b(run_dirs: list[str], path: str) -> None:
    """Final object-goal distance on the obstacle env, every episode of every seed, per policy."""
    data = {}
    for run_dir in run_dirs:
        for policy, values in read_npz(os.path.join(run_dir, "obstacle_distances.npz")).items():
            data.setdefault(policy, []).append(values)
    policies = [p for p in ("oracle", "tamer", "inform") if p in data]
    fig = Figure(figsize=(6, 4))
    ax = fig.subplots()
    ax.boxplot([np.concatenate(data[p]) for p in policies], tick_labels=[p.upper() for p in policies])
    ax.set(ylabel="final object-goal distance (m)", title=f"Pusher + obstacle, {len(run_dirs)} seeds")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save(fig, path)


def reward_figure(table: np.ndarray, title: str):
    """The recovered reward drawn over the maze: each free cell split into four triangles, one per action.

    A copy of inform_dqn_gridworld.reward_figure: a helper script does not import a training script."""
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


REWARD_STYLE = {  # reward -> (colour, label); bootstrap -> (line style, label); the names of the arms' keys
    "recovered_network": ("tab:blue", "INFORM reward, network on the wall's s'"),
    "recovered_table": ("tab:green", "INFORM reward, plain-maze table (variant)"),
    "env": ("tab:red", "env reward"),
}
BOOTSTRAP_STYLE = {"sampled": ("-", "sampled bootstrap (SARSA-like)"), "max": ("--", "max bootstrap (Q-learning)")}


def completed_reward_runs(runs_dir: str, exp_name: str) -> dict:
    """The reward-experiment runs per episode budget and arm: {num_episodes: {arm: run_dir}}, the newest run holding
    the arm (an env arm appears in every run of its bootstrap; runs on the same seeds hold the same agents)."""
    found = {}
    pattern = os.path.join(runs_dir, f"KnoxStoneMazeWall-v0__{exp_name}__*", "summary.json")
    for path in sorted(glob.glob(pattern), key=mtime):
        summary = read_json(path)
        if summary.get("status") == "completed" and "arms" in summary:  # older runs had no agents.npz
            for arm in summary["arms"]:
                found.setdefault(summary["args"]["num_episodes"], {})[arm] = (os.path.dirname(path), summary)
    return found


def fig6(runs: dict, path: str) -> None:
    """Fig. 6 redrawn with every arm: training episode length against env steps, mean over agents and the 25-75th
    percentile band, one panel per episode budget; the optimum and TAMER's greedy policy on the wall maze (untrained
    there) as lines."""
    budgets = sorted(runs)
    fig = Figure(figsize=(7 * len(budgets), 6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(budgets), squeeze=False)[0])
    for ax, budget in zip(axes, budgets, strict=True):
        arms = runs[budget]
        for arm in sorted(arms, key=lambda a: (list(REWARD_STYLE).index(a.split("/")[1]), a)):
            run_dir, summary = arms[arm]
            bootstrap, reward = arm.split("/")
            colour, reward_label = REWARD_STYLE[reward]
            style, bootstrap_label = BOOTSTRAP_STYLE[bootstrap.removesuffix("_bootstrap")]
            npz = read_npz(os.path.join(run_dir, "agents.npz"), (f"{arm}/steps", f"{arm}/lengths"))
            steps, lengths = npz[f"{arm}/steps"], npz[f"{arm}/lengths"]
            grid = np.linspace(0, steps[:, -1].max(), 300)[1:]
            # an agent that finished its episodes in fewer steps is held at its last length (np.interp does that)
            values = np.stack([np.interp(grid, s, v) for s, v in zip(steps, lengths, strict=True)])
            n, n_stay = summary[f"{arm}/n_agents"], summary[f"{arm}/n_stay_optimum"]
            median = summary[f"{arm}/steps_to_stay_optimum_median"]
            reached = f"{n_stay}/{n} stay at 25" + (f", median {median / 1000:.1f}k steps" if median else "")
            ax.plot(grid, values.mean(0), color=colour, ls=style, label=f"{reward_label}, {bootstrap_label}: {reached}")
            lo, hi = np.percentile(values, [25, 75], axis=0)
            ax.fill_between(grid, lo, hi, color=colour, alpha=0.1, lw=0)
        summary = next(iter(arms.values()))[1]
        ax.axhline(summary["optimum_episode_length"], color="black", ls=":", lw=1, label="optimum (25)")
        tamer = summary.get("eval/wall/tamer_episode_length_per_run") or []
        known = [t for t in tamer if t is not None]
        if known:
            label = f"TAMER's greedy policy, untrained on the wall ({len(known)} runs, lengths {sorted(set(known))})"
            ax.axhline(np.mean(known), color="tab:orange", ls="-.", lw=1.5, label=label)
        ax.set(xlabel="environment steps", ylabel="training episode length", ylim=(0, 210))
        ax.set_title(f"Wall maze (Fig. 6), {budget} episodes per agent: mean over agents, band 25-75th percentile",
                     fontsize=10)  # fmt: skip
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.12), fontsize=8)
        ax.grid(alpha=0.3)
    save(fig, path)


def read_curve(path: str) -> dict[str, np.ndarray]:
    """An eval_curve.csv's columns step, success_rate and final_distance; ValueError if it is not one."""
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
        columns = {
            name: np.array([float(row[name]) for row in rows]) for name in ("step", "success_rate", "final_distance")
        }
        if rows:
            return columns
    except (OSError, KeyError, TypeError, ValueError, csv.Error):
        pass
    raise ValueError(f"--teacher-curves {path}: not an eval_curve.csv of oracle_train.py with an evaluation")


def curve_label(path: str) -> str:
    """A curve's name: its file's (results/teachers/X_eval_curve.csv: X), or its run's (runs/X/eval_curve.csv: X)."""
    name = os.path.basename(path).removesuffix(".csv").removesuffix("eval_curve").removesuffix("_")
    return name or os.path.basename(os.path.dirname(os.path.abspath(path)))


def teacher_figure(curves: dict[str, dict], path: str) -> None:
    """Success rate (left) and final distance (right) on the selection starts against environment steps, one line per
    curve (by its label), the expert bar (oracle_train's) dashed."""
    fig = Figure(figsize=(11, 4))
    success, distance = fig.subplots(1, 2, sharex=True)
    for label, curve in curves.items():
        success.plot(curve["step"], curve["success_rate"], label=label)
        distance.plot(curve["step"], curve["final_distance"], label=label)
    for ax, bar, ylabel in ((success, EXPERT_SUCCESS_RATE, "success rate"),
                            (distance, EXPERT_FINAL_DISTANCE, "final distance (m)")):  # fmt: skip
        ax.axhline(bar, color=COLOURS["oracle"], ls="--", lw=1.5, label="expert bar")
        ax.set(xlabel="environment steps (demonstrated steps counted)", ylabel=ylabel)
        ax.grid(alpha=0.3)
    success.legend(loc="center left", fontsize=8)
    fig.suptitle("Teachers' training: 100 selection starts every 10,000 steps")
    fig.tight_layout()
    save(fig, path)


def main(args: Args) -> None:
    teachers = {curve_label(p): read_curve(p) for p in dict.fromkeys(args.teacher_curves)}
    if len(teachers) < len(set(args.teacher_curves)):
        raise ValueError("--teacher-curves: two curves would have the same label (their file or run names)")
    if not os.path.isdir(args.runs_dir) and not teachers:
        raise ValueError(f"--runs-dir {args.runs_dir}: no such directory (run the experiments first, see README)")
    if args.out is None:  # a fresh folder: a run of plot_results never writes over another's, nor the repository's
        args.out = os.path.join("runs", f"figures__{time.strftime('%Y%m%d-%H%M%S')}")
        args.out += f"_{time.time_ns()}" if os.path.lexists(args.out) else ""
    if os.path.exists(args.out) and not os.path.isdir(args.out):
        raise ValueError(f"--out {args.out}: exists and is not a directory (the figures go into a directory)")
    if teachers:  # the teachers' figure alone: no run is read
        os.makedirs(args.out, exist_ok=True)
        teacher_figure(teachers, f"{args.out}/teacher_curves.png")
        print(f"wrote teacher_curves.png to {args.out}")
        return
    notes = []
    maze = completed_runs(args.runs_dir, f"KnoxStoneMaze-v0__{args.maze_exp}__*", notes)
    reward = None
    if maze:  # the checkpoint is verified (its CRC-32) before anything is drawn
        path = os.path.join(maze[0], "recovered_reward.pt")
        check_crc(path)
        reward = torch.load(path, weights_only=True)["reward"].numpy()
    os.makedirs(args.out, exist_ok=True)
    written = []
    if maze:
        fig3(maze, "episode_length", "greedy episode length", f"{args.out}/fig3_maze.png", "Maze", tuple(notes))
        seed = read_json(os.path.join(maze[0], "summary.json"))["seed"]
        save(reward_figure(reward, f"recovered reward r(s, a), seed {seed}"), f"{args.out}/recovered_reward.png")
        written += ["fig3_maze.png", "recovered_reward.png"]
    pusher_notes = []
    pusher = completed_runs(args.runs_dir, f"Pusher-v*__{args.pusher_exp}__*", pusher_notes)
    notes += pusher_notes
    if pusher:
        fig3(pusher, "return", "episode return", f"{args.out}/fig3_pusher.png", "Pusher", tuple(pusher_notes))
        fig5b(pusher, f"{args.out}/fig5b_obstacle.png")
        written += ["fig3_pusher.png", "fig5b_obstacle.png"]
    reward_runs = completed_reward_runs(args.runs_dir, args.qlearning_exp)
    if reward_runs:
        fig6(reward_runs, f"{args.out}/fig6_wall_maze.png")
        written.append("fig6_wall_maze.png")
    for note in notes:
        print(note)
    print(f"wrote {', '.join(written) or 'nothing (no finished runs found)'} to {args.out}")


if __name__ == "__main__":
    try:
        main(tyro.cli(Args))  # a malformed flag: tyro's own message, exit 2
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
