"""Aggregate the Pusher obstacle robustness test over seeds (paper Sec. VI-B: INFORM closer, p < 0.0001).

Reads `obstacle_distances.npz` (per-episode final object-goal distances) and `summary.json` from each run
directory written by inform_sac_pusher.py, prints per-seed and pooled means and standard deviations, and two tests
of TAMER against INFORM final distances:

- the headline, over seeds: a paired t-test (scipy.stats.ttest_rel) of the seeds' mean distances, n = the number of
  seeds. A seed's 100 episodes share one policy and one start, so the seed is the unit that repeats;
- beside it, on the pooled episodes: Welch's t-test (scipy.stats.ttest_ind, equal_var=False), which counts every
  episode as independent and so overstates significance.

A margin (TAMER's mean distance minus INFORM's, on a seed or averaged over seeds) smaller than TAMER's own sampling
spread is "within noise". With one sampling stream per seed, that spread is estimated as twice the standard error of
TAMER's per-seed mean (2 sd / sqrt(episodes), averaged over the seeds).

    python -m inform_utils.pusher_obstacle_stats runs/Pusher-v5__inform_sac_pusher__1__* \
        runs/Pusher-v5__inform_sac_pusher__2__* runs/Pusher-v5__inform_sac_pusher__3__*
"""

import io
import os
import sys
import warnings
from dataclasses import dataclass

import numpy as np
import tyro
from scipy import stats

if not __package__:  # run as a file (python inform_utils/pusher_obstacle_stats.py): its package from the repository
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from inform_utils.files import atomic, read_json, read_npz, write_json  # noqa: E402


@dataclass
class Args:
    run_dirs: tyro.conf.Positional[tuple[str, ...]]
    """run directories of inform_sac_pusher.py (one per seed), each with obstacle_distances.npz"""
    output: str | None = None
    """optional path of a JSON file with the aggregated numbers"""
    fig5a: str | None = None
    """optional path of a PNG: the object's xy paths of TAMER and INFORM with and without the boxes (paper Fig. 5a),
    one panel per run directory (deterministic actions, from the run's obstacle_paths.npz)"""
    per_seed_table: bool = False
    """also print each run's final evaluation as a Markdown table (returns, how far below the oracle, distances,
    successes, the authors' sampled test, the obstacle test, the buffer's successful episodes, wall time)"""


def load_run(run_dir: str) -> dict:
    path = os.path.join(run_dir, "obstacle_distances.npz")
    if not os.path.isfile(path) or not os.path.isfile(os.path.join(run_dir, "summary.json")):
        raise ValueError(f"{run_dir}: no obstacle_distances.npz and summary.json (did the run finish?)")
    summary = read_json(os.path.join(run_dir, "summary.json"))  # BadFile, a ValueError: one line, exit 2
    distances = read_npz(path)  # truncated, damaged or pickled: one line too
    if not isinstance(summary.get("args"), dict) or "success_distance" not in summary["args"]:
        raise ValueError(f"{run_dir}/summary.json: not a summary of inform_sac_pusher.py (no args.success_distance)")
    if "tamer" not in distances or "inform" not in distances:
        raise ValueError(f"{path}: needs 'tamer' and 'inform' arrays")
    return {
        "seed": summary.get("seed"),
        "run_dir": run_dir,
        "distances": distances,
        "success_distance": summary["args"]["success_distance"],
        "layout": summary["args"].get("obstacle_layout", "paper"),
        "min_box_distance_to_path": summary.get("obstacle/min_box_distance_to_path"),
        "summary": summary,
    }


def aggregate(runs: list[dict]) -> dict:
    policies = [p for p in ("oracle", "tamer", "inform") if all(p in r["distances"] for r in runs)]
    out = {"seeds": [r["seed"] for r in runs], "episodes_per_seed": int(len(runs[0]["distances"]["tamer"]))}
    for p in policies:
        pooled = np.concatenate([r["distances"][p] for r in runs])
        seed_means = np.array([r["distances"][p].mean() for r in runs])
        out[f"{p}_mean"] = float(pooled.mean())
        out[f"{p}_std"] = float(pooled.std(ddof=1)) if pooled.size > 1 else 0.0
        out[f"{p}_seed_means"] = seed_means.tolist()
        out[f"{p}_seed_mean_std"] = float(seed_means.std(ddof=1)) if len(runs) > 1 else 0.0
        out[f"{p}_success_rate"] = float((pooled < runs[0]["success_distance"]).mean())
    closer = np.array(out["inform_seed_means"]) < np.array(out["tamer_seed_means"])
    out["inform_closer_seeds"] = int(closer.sum())
    out["layouts"] = sorted({r["layout"] for r in runs})
    out["min_box_distance_to_path"] = [r["min_box_distance_to_path"] for r in runs]
    margins = np.array(out["tamer_seed_means"]) - np.array(out["inform_seed_means"])  # positive: INFORM closer
    out["margins"], out["margin"] = margins.tolist(), float(margins.mean())
    out["tamer_sampling_spread"] = sampling_spread([r["distances"]["tamer"] for r in runs])
    out["inform_closer_seeds_beyond_noise"] = int((margins > out["tamer_sampling_spread"]).sum())
    out["within_noise"] = bool(abs(out["margin"]) < out["tamer_sampling_spread"])
    tamer = np.concatenate([r["distances"]["tamer"] for r in runs])
    inform = np.concatenate([r["distances"]["inform"] for r in runs])
    with warnings.catch_warnings():  # near-identical distances: t and p say it (inf, 0), not a warning on stderr
        warnings.filterwarnings("ignore", "Precision loss occurred in moment calculation", RuntimeWarning)
        welch = stats.ttest_ind(tamer, inform, equal_var=False)
        out["welch_t_episodes"], out["welch_p_episodes"] = float(welch.statistic), float(welch.pvalue)
        if len(runs) > 1:
            paired = stats.ttest_rel(out["tamer_seed_means"], out["inform_seed_means"])
            out["paired_t_seed_means"], out["paired_p_seed_means"] = float(paired.statistic), float(paired.pvalue)
            welch = stats.ttest_ind(out["tamer_seed_means"], out["inform_seed_means"], equal_var=False)
            out["welch_t_seed_means"], out["welch_p_seed_means"] = float(welch.statistic), float(welch.pvalue)
    return out


def sampling_spread(episodes: list[np.ndarray]) -> float:
    """TAMER's own sampling spread of a seed's mean distance: twice its standard error (2 sd / sqrt(episodes)),
    averaged over the seeds. A margin smaller than this could come from the sampled actions alone."""
    return float(np.mean([2 * e.std(ddof=1) / np.sqrt(e.size) if e.size > 1 else 0.0 for e in episodes]))


def per_seed_table(runs: list[dict]) -> str:
    """One row per run of its summary's final evaluation (deterministic actions), then the returns' mean and sd."""

    def successes(values: list[float]) -> str:  # one fixed-start episode gives 0 or 1; random starts give a rate
        whole = all(float(v).is_integer() for v in values)
        return " / ".join(f"{v:.0f}" if whole else f"{v:.2f}" for v in values)

    head = ["seed", "oracle return", "TAMER return", "INFORM return", "INFORM below the oracle", "TAMER below"]
    head += ["final distance O / T / I", "success O / T / I", "authors' test (100 sampled), success T / I"]
    head += ["obstacle distance T / I", "successful episodes in the buffer", "wall time"]
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    returns = {p: [] for p in ("oracle", "tamer", "inform")}
    for run in runs:
        s = run["summary"]
        ret = {p: s[f"eval/{p}_return"] for p in returns}
        for p in returns:
            returns[p].append(ret[p])
        below = [(ret["oracle"] - ret[p]) / abs(ret["oracle"]) for p in ("inform", "tamer")]
        cells = [str(run["seed"]), *(f"{ret[p]:.2f}" for p in returns), *(f"{b:.1%}" for b in below)]
        cells.append(" / ".join(f"{s[f'eval/{p}_final_distance']:.3f}" for p in returns))
        cells.append(successes([s[f"eval/{p}_success_rate"] for p in returns]))
        cells.append(
            " / ".join(f"{s.get(f'eval/authors_test/{p}_success_rate', float('nan')):.2f}" for p in ("tamer", "inform"))
        )
        cells.append(" / ".join(f"{run['distances'][p].mean():.3f}" for p in ("tamer", "inform")))
        cells.append(f"{s.get('sleep/success_episodes', 0):,} of {s.get('sleep/episodes', 0):,}")
        cells.append(f"{s['wall_time_s']:,.0f} s" if "wall_time_s" in s else "-")
        lines.append("| " + " | ".join(cells) + " |")
    sd = (lambda v: float(np.std(v, ddof=1))) if len(runs) > 1 else (lambda v: 0.0)
    means = [f"{np.mean(returns[p]):.2f} ± {sd(returns[p]):.2f}" for p in returns]
    lines.append("| " + " | ".join(["mean ± std", *means, *[""] * (len(head) - 4)]) + " |")
    return "\n".join(lines)


def fig5a(runs: list[dict], path: str) -> None:
    """The object's path with (solid) and without (dashed) the boxes, per policy; boxes, start and goal drawn."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    fig = Figure(figsize=(4 * len(runs), 4.2))
    axes = fig.subplots(1, len(runs), squeeze=False)[0]
    for ax, run in zip(axes, runs, strict=True):
        paths = read_npz(os.path.join(run["run_dir"], "obstacle_paths.npz"))
        for name, colour in (("tamer", "tab:orange"), ("inform", "tab:blue")):
            ax.plot(*paths[f"{name}_plain"].T, "--", color=colour, lw=1, label=f"{name.upper()}, no boxes")
            ax.plot(*paths[f"{name}_obstacle"].T, "-", color=colour, lw=2, label=f"{name.upper()}, boxes")
        for x, y in paths["boxes"]:
            ax.add_patch(Rectangle((x - 0.015, y - 0.015), 0.03, 0.03, color="0.3"))
        ax.plot(*paths["start"], "ko", ms=5, label="object start")
        ax.plot(*paths["goal"], "r*", ms=12, label="goal")
        ax.set_title(f"seed {run['seed']} ({run['layout']} layout)")
        ax.set_xlabel("x (m)")
        ax.set_aspect("equal", adjustable="datalim")
    axes[0].set_ylabel("y (m)")
    axes[0].legend(fontsize=7, loc="best")
    fig.tight_layout()
    buffer = io.BytesIO()  # the PNG whole or not at all
    fig.savefig(buffer, format="png", dpi=120)
    with atomic(path, "wb") as f:
        f.write(buffer.getvalue())


def main(args: Args) -> dict:
    runs = [load_run(d) for d in args.run_dirs]
    seeds = [r["seed"] for r in runs]
    if len(set(seeds)) < len(seeds):  # the samples of a t-test must be independent: one run per seed
        twice = sorted({s for s in seeds if seeds.count(s) > 1})
        raise ValueError(f"seed {', '.join(map(str, twice))} given more than once: pass one run directory per seed")
    out = aggregate(runs)
    print(f"obstacle test: {len(runs)} seeds {out['seeds']}, {out['episodes_per_seed']} episodes per policy and seed")
    for p in ("oracle", "tamer", "inform"):
        if f"{p}_mean" in out:
            per_seed = ", ".join(f"{m:.3f}" for m in out[f"{p}_seed_means"])
            print(
                f"  {p:>6}: final distance {out[f'{p}_mean']:.4f} +- {out[f'{p}_std']:.4f} (pooled episodes) | "
                f"per-seed means [{per_seed}] | success rate {out[f'{p}_success_rate']:.2f}"
            )
    side = "closer" if out["margin"] > 0 else "farther"
    noise = " (within noise)" if out["within_noise"] else ""
    print(
        f"  INFORM {side} than TAMER by {abs(out['margin']):.4f} m on average over the seeds{noise}; TAMER's "
        f"sampling spread (2 standard errors of a seed's mean) {out['tamer_sampling_spread']:.4f} m"
    )
    if "paired_p_seed_means" in out:
        print(
            f"  per seed (the headline): paired t-test TAMER vs INFORM over the {len(runs)} seeds' means: "
            f"t = {out['paired_t_seed_means']:.3f}, p = {out['paired_p_seed_means']:.3g}"
        )
    else:
        print("  per seed (the headline): one seed, no test")
    print(
        f"  pooled episodes (beside it; a seed's episodes share one policy and one start): Welch t-test TAMER vs "
        f"INFORM, t = {out['welch_t_episodes']:.3f}, p = {out['welch_p_episodes']:.3g}"
    )
    print(
        f"  INFORM closer than TAMER on {out['inform_closer_seeds']} of {len(runs)} seeds "
        f"({out['inform_closer_seeds_beyond_noise']} beyond the sampling spread); layout {out['layouts']}"
    )
    if args.per_seed_table:
        print(per_seed_table(runs))
    if args.fig5a:
        fig5a(runs, args.fig5a)
        print(f"  Fig. 5a: {args.fig5a}")
    if args.output:
        write_json(args.output, out, indent=2)
    return out


if __name__ == "__main__":
    try:
        args = tyro.cli(Args)  # a malformed flag: tyro's own message, exit 2
        if not args.run_dirs:
            raise ValueError("pass at least one run directory")
        for flag, path in (("--fig5a", args.fig5a), ("--output", args.output)):  # before any work: a file to write
            if path is not None and (os.path.isdir(path) or not os.path.isdir(os.path.dirname(path) or ".")):
                raise ValueError(f"{flag} {path}: must name a file in an existing directory")
        main(args)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
