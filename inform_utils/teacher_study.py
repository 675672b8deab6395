"""Tables and figures of the maze teacher study (docs/teacher_notes.md) from finished runs of inform_dqn_gridworld.py.

    python -m inform_utils.teacher_study --runs-dir runs/teachers_study/runs --out docs/figures

Runs are grouped by their exp_name (see docs/teacher_notes.md for the commands that make them):
- robustness: `base` (the perfect teacher), `noise{p}`, `sparsity{q}`, `delay{d}_w{k}`;
- teacher knowledge: `base` (exact Q*), `qlearn50`, `dqn` (learned teachers via --oracle-path);
- feedback efficiency: TAMER's +1 signals until its greedy path first has 19 steps (from `base`, evaluated every
  100 env steps), against `sleep_after_{k}`: INFORM sleeping after k env steps.
Prints markdown tables and writes teacher_robustness.png, teacher_knowledge.png and teacher_efficiency.png.
"""

import glob
import json
import math
import os
import re
import sys
from dataclasses import dataclass

import matplotlib
import numpy as np
import tyro
from matplotlib.figure import Figure

OPTIMUM = 19  # the shortest path S -> G of the plain maze
ROBUSTNESS = [  # (group, label, exp_name)
    ("perfect", "perfect teacher", "base"),
    ("noise", "noise p = 0.1", "noise0.1"),
    ("noise", "noise p = 0.2", "noise0.2"),
    ("noise", "noise p = 0.3", "noise0.3"),
    ("sparsity", "sparsity q = 0.5", "sparsity0.5"),
    ("sparsity", "sparsity q = 0.2", "sparsity0.2"),
    ("delay", "delay d = 1, window 1", "delay1_w1"),
    ("delay", "delay d = 1, window 2", "delay1_w2"),
    ("delay", "delay d = 2, window 1", "delay2_w1"),
    ("delay", "delay d = 2, window 3", "delay2_w3"),
]
KNOWLEDGE = [("exact Q* (value iteration)", "base"), ("half-trained Q-learner (50 episodes)", "qlearn50"),
             ("DQN (20k steps)", "dqn")]  # fmt: skip


@dataclass
class Args:
    runs_dir: str = "runs/teachers_study/runs"
    """where the run directories are"""
    out: str = "docs/figures"
    """where the PNGs go"""
    env_id: str = "KnoxStoneMaze-v0"
    """the env id in the run directory names"""


def load_runs(runs_dir: str, env_id: str) -> dict[str, dict[int, dict]]:
    """exp_name -> seed -> summary (with its run directory), completed runs only, the newest per seed."""
    runs: dict[str, dict[int, dict]] = {}
    paths = sorted(glob.glob(os.path.join(runs_dir, f"{env_id}__*", "summary.json")), key=os.path.getmtime)
    for path in paths:
        with open(path) as f:
            summary = json.load(f)
        if summary.get("status") != "completed" or summary.get("script") != "inform_dqn_gridworld.py":
            continue
        summary["run_dir"] = os.path.dirname(path)
        runs.setdefault(summary["args"]["exp_name"], {})[summary["seed"]] = summary
    return runs


def column(runs: dict[int, dict], key: str) -> np.ndarray:
    """One metric per seed; NaN where a run has none (a skipped sleep makes no INFORM policy to evaluate)."""
    return np.array([runs[seed].get(key) for seed in sorted(runs)], dtype=float)


def mean_sd(values: np.ndarray, digits: int = 2) -> str:
    return f"{values.mean():.{digits}f} ± {values.std(ddof=1) if len(values) > 1 else 0.0:.{digits}f}"


def no_sleep(runs: dict[int, dict]) -> int:
    """Runs whose buffer held no successful episode: the sleep was skipped and there is no INFORM policy."""
    return int((column(runs, "sleep/expert_transitions") == 0).sum())


def robustness_table(runs) -> str:
    rows = ["| teacher | n | +1 signals | TAMER length | INFORM length | TAMER at 19 | INFORM at 19 | "
            "TAMER all-starts | INFORM all-starts | INFORM >= TAMER | no sleep |", "|" + " --- |" * 11]  # fmt: skip
    for _, label, name in ROBUSTNESS:
        if name not in runs:
            continue
        r = runs[name]
        t_len, i_len = column(r, "eval/tamer_episode_length"), column(r, "eval/inform_episode_length")
        t_all, i_all = column(r, "eval/all_starts/tamer_success_rate"), column(r, "eval/all_starts/inform_success_rate")
        n = len(r)
        rows.append(f"| {label} | {n} | {column(r, 'feedback/positive').mean():.0f} | {mean_sd(t_len, 1)} | "
                    f"{mean_sd(i_len, 1)} | {(t_len == OPTIMUM).sum()}/{n} | {(i_len == OPTIMUM).sum()}/{n} | "
                    f"{mean_sd(t_all)} | {mean_sd(i_all)} | {(i_all >= t_all).sum()}/{n} | "
                    f"{no_sleep(r)} |")  # fmt: skip
    return "\n".join(rows)


def knowledge_table(runs) -> str:
    rows = ["| teacher | n | +1 signals | TAMER length | INFORM length | TAMER all-starts (per seed) | "
            "INFORM all-starts (per seed) | INFORM >= TAMER | expert transitions |", "|" + " --- |" * 9]  # fmt: skip
    for label, name in KNOWLEDGE:
        if name not in runs:
            continue
        r = runs[name]
        t_all, i_all = column(r, "eval/all_starts/tamer_success_rate"), column(r, "eval/all_starts/inform_success_rate")
        per_seed = lambda v: f"{v.mean():.2f} ({', '.join(f'{x * 29:.0f}' for x in v)} of 29)"  # noqa: E731
        rows.append(f"| {label} | {len(r)} | {column(r, 'feedback/positive').mean():.0f} | "
                    f"{mean_sd(column(r, 'eval/tamer_episode_length'), 1)} | "
                    f"{mean_sd(column(r, 'eval/inform_episode_length'), 1)} | {per_seed(t_all)} | "
                    f"{per_seed(i_all)} | {(i_all >= t_all).sum()}/{len(r)} | "
                    f"{column(r, 'sleep/expert_transitions').mean():.0f} |")  # fmt: skip
    return "\n".join(rows)


def sleep_runs(runs) -> list[tuple[int, dict[int, dict]]]:
    found = [(int(m.group(1)), r) for name, r in runs.items() if (m := re.fullmatch(r"sleep_after_(\d+)", name))]
    return sorted(found, key=lambda kr: kr[0])


def efficiency_table(runs) -> tuple[str, str]:
    """TAMER's +1 signals to its first 19-step greedy path, and INFORM's after sleeping at k env steps."""
    base = runs.get("base", {})
    tamer = {seed: s["feedback/positive_to_tamer_optimum"] for seed, s in base.items()}
    tamer_step = {seed: s["feedback/step_to_tamer_optimum"] for seed, s in base.items()}
    seeds = sorted(tamer)
    rows = ["| run | " + " | ".join(f"seed {s}" for s in seeds) + " | reached 19 |", "|" + " --- |" * (len(seeds) + 2)]
    rows.append("| TAMER alone: +1 signals (env step) at its first 19 | "
                + " | ".join("never" if tamer[s] is None else f"{tamer[s]} ({tamer_step[s]})" for s in seeds)
                + f" | {sum(tamer[s] is not None for s in seeds)}/{len(seeds)} |")  # fmt: skip
    first = {}  # seed -> (+1 signals, k) of the smallest k at which INFORM's greedy path is 19 after the sleep
    for k, r in sleep_runs(runs):
        cells = []
        for s in seeds:
            if s not in r:
                cells.append("-")
                continue
            pos, length = r[s]["feedback/positive"], r[s].get("eval/inform_episode_length", math.nan)
            slept = r[s]["sleep/expert_transitions"] > 0
            cells.append(
                f"{pos}: {length:.0f}" + (" *" if length == OPTIMUM else "") + ("" if slept else " (no sleep)")
            )
            if length == OPTIMUM and slept and s not in first:
                first[s] = (pos, k)
        reached = sum(r[s].get("eval/inform_episode_length") == OPTIMUM for s in seeds if s in r)
        t_reached = sum(r[s]["eval/tamer_episode_length"] == OPTIMUM for s in seeds if s in r)
        rows.append(f"| INFORM, sleep after k = {k}: +1 signals: INFORM length | " + " | ".join(cells)
                    + f" | {reached}/{len(r)} (TAMER {t_reached}/{len(r)}) |")  # fmt: skip
    ratio_rows = ["| seed | TAMER +1 to 19 | INFORM: smallest k reaching 19 | its +1 signals | ratio |",
                  "| --- | --- | --- | --- | --- |"]  # fmt: skip
    for s in seeds:
        if tamer[s] is None or s not in first:
            ratio_rows.append(f"| {s} | {tamer[s]} | {first.get(s, ('-', 'none'))[1]} | - | - |")
        else:
            ratio_rows.append(f"| {s} | {tamer[s]} | {first[s][1]} | {first[s][0]} | {first[s][0] / tamer[s]:.2f} |")
    return "\n".join(rows), "\n".join(ratio_rows)


def tamer_curve(run_dir: str) -> tuple[np.ndarray, np.ndarray]:
    """TAMER's greedy episode length against the +1 signals given so far (TensorBoard, logged every 100 steps)."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(run_dir, size_guidance={"scalars": 0})
    acc.Reload()
    positives = {e.step: e.value for e in acc.Scalars("feedback/positive")}
    pairs = [(positives[e.step], e.value) for e in acc.Scalars("eval/tamer_episode_length") if e.step in positives]
    return np.array([p for p, _ in pairs]), np.array([v for _, v in pairs])


def robustness_figure(runs, path: str) -> None:
    fig = Figure(figsize=(13, 4))
    axes = fig.subplots(1, 3, sharey=True)
    groups = {"noise": ("noise p", [("base", 0.0), ("noise0.1", 0.1), ("noise0.2", 0.2), ("noise0.3", 0.3)]),
              "sparsity": ("sparsity q", [("base", 1.0), ("sparsity0.5", 0.5), ("sparsity0.2", 0.2)])}  # fmt: skip
    for ax, (title, (xlabel, points)) in zip(axes[:2], groups.items(), strict=True):
        points = [(name, x) for name, x in points if name in runs]
        for policy, colour in (("tamer", "tab:orange"), ("inform", "tab:blue")):
            values = [column(runs[name], f"eval/all_starts/{policy}_success_rate") for name, _ in points]
            xs = [x for _, x in points]
            for x, v in zip(xs, values, strict=True):
                ax.scatter([x] * len(v), v, color=colour, alpha=0.35, s=14)
            ax.plot(xs, [v.mean() for v in values], "-o", color=colour, label=policy.upper())
        ax.set(title=f"teacher {title}", xlabel=xlabel)
    ax = axes[2]
    names = [n for n in ("base", "delay1_w1", "delay1_w2", "delay2_w1", "delay2_w3") if n in runs]
    for i, name in enumerate(names):
        for offset, (policy, colour) in zip((-0.17, 0.17), (("tamer", "tab:orange"), ("inform", "tab:blue")),
                                            strict=True):  # fmt: skip
            v = column(runs[name], f"eval/all_starts/{policy}_success_rate")
            ax.bar(i + offset, v.mean(), width=0.32, color=colour, alpha=0.7)
            ax.scatter([i + offset] * len(v), v, color="black", s=8)
    ax.set_xticks(
        range(len(names)), [n.replace("base", "d0 w1").replace("delay", "d").replace("_", " ") for n in names]
    )
    ax.set(title="teacher delay d, credit window w")
    axes[0].set_ylabel("greedy success from the 29 start cells")
    axes[0].legend()
    fig.suptitle("Maze: INFORM and TAMER under imperfect teachers (n = 5 seeds; dots are seeds)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def knowledge_figure(runs, path: str) -> None:
    fig = Figure(figsize=(6.5, 4))
    ax = fig.subplots()
    names = [(label, name) for label, name in KNOWLEDGE if name in runs]
    for i, (_, name) in enumerate(names):
        t = column(runs[name], "eval/all_starts/tamer_success_rate")
        v = column(runs[name], "eval/all_starts/inform_success_rate")
        for a, b in zip(t, v, strict=True):
            ax.plot([i - 0.15, i + 0.15], [a, b], color="0.6", lw=0.8)
        ax.scatter([i - 0.15] * len(t), t, color="tab:orange", label="TAMER" if i == 0 else None, zorder=3)
        ax.scatter([i + 0.15] * len(v), v, color="tab:blue", label="INFORM" if i == 0 else None, zorder=3)
    ax.set_xticks(range(len(names)), [label.replace(" (", "\n(") for label, _ in names])
    ax.set(ylabel="greedy success from the 29 start cells", ylim=(-0.03, 1.03),
           title="Teacher knowledge (lines join one seed's TAMER and INFORM)")  # fmt: skip
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def efficiency_figure(runs, path: str) -> None:
    fig = Figure(figsize=(7, 4.2))
    ax = fig.subplots()
    for i, (_, summary) in enumerate(sorted(runs.get("base", {}).items())):
        x, y = tamer_curve(summary["run_dir"])
        ax.plot(x, y, color="tab:orange", alpha=0.6, lw=1, label="TAMER during its forward phase" if i == 0 else None)
    for i, (k, r) in enumerate(sleep_runs(runs)):
        pos = column(r, "feedback/positive")
        length = column(r, "eval/inform_episode_length")
        colour = matplotlib.colormaps["viridis"](0.1 + 0.8 * i / max(len(sleep_runs(runs)) - 1, 1))
        ax.scatter(pos, length, color=colour, zorder=3, label=f"INFORM after sleeping at k = {k}")
    ax.axhline(OPTIMUM, color="black", ls="--", lw=0.8, label="optimum (19)")
    ax.set(xscale="log", ylim=(0, 210), xlabel="+1 signals given by the teacher",
           ylabel="greedy episode length from S (200 = never)",
           title="Feedback efficiency (perfect teacher, n = 5)")  # fmt: skip
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(args: Args) -> None:
    if not os.path.isdir(args.runs_dir):
        raise ValueError(f"--runs-dir {args.runs_dir}: no such directory")
    runs = load_runs(args.runs_dir, args.env_id)
    if not runs:
        raise ValueError(f"--runs-dir {args.runs_dir}: no completed inform_dqn_gridworld.py runs of {args.env_id}")
    os.makedirs(args.out, exist_ok=True)
    print("## a. Robustness\n\n" + robustness_table(runs) + "\n")
    print("## b. Teacher knowledge\n\n" + knowledge_table(runs) + "\n")
    table, ratios = efficiency_table(runs)
    print("## c. Feedback efficiency\n\n" + table + "\n\n" + ratios + "\n")
    robustness_figure(runs, os.path.join(args.out, "teacher_robustness.png"))
    knowledge_figure(runs, os.path.join(args.out, "teacher_knowledge.png"))
    efficiency_figure(runs, os.path.join(args.out, "teacher_efficiency.png"))
    print(f"figures: {args.out}/teacher_robustness.png, teacher_knowledge.png, teacher_efficiency.png")


if __name__ == "__main__":
    parsed = tyro.cli(Args)  # a malformed flag: tyro's own message, exit 2
    try:
        main(parsed)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
