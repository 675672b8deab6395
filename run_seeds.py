"""Run one of the INFORM scripts for several seeds in parallel worker processes, then gather their summary.json
files into one table (mean, std, n per key). Resumable: a seed whose run already finished is not run again.

In the spirit of CleanRL's benchmark utility.

    python run_seeds.py --script inform_dqn_gridworld.py --exp-name fig3 --seeds 1 2 3 4 5 --workers 2
    python run_seeds.py --script inform_sac_pusher.py --exp-name fig3 --seeds 1 2 3 -- --random-starts
"""

import contextlib
import glob
import io
import json
import math
import os
import shlex
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import tyro


@dataclass
class Args:
    script: str = "inform_dqn_gridworld.py"
    """the script to run (it must take --seed, --exp-name and --num-threads)"""
    exp_name: str = "seeds"
    """the experiment name: runs are runs/{env_id}__{exp_name}__{seed}__{time}; it is how finished runs are found"""
    seeds: list[int] = field(default_factory=lambda: [1, 2, 3, 4, 5])
    """the seeds to run"""
    workers: int = 2
    """runs side by side"""
    threads: int = 0
    """torch threads per run (0: the machine's cores divided among the workers)"""
    runs_dir: str = "runs"
    """where the script writes its runs (relative to the working directory)"""
    logs_dir: str = "runs/logs"
    """where each run's stdout and stderr go"""
    script_args: tyro.conf.Positional[list[str]] = field(default_factory=list)
    """extra flags for every run, after a `--`"""


def finished_summary(runs_dir: str, exp_name: str, seed: int, script: str) -> str | None:
    """The newest summary.json of a completed run of this script, experiment and seed, if there is one (two
    scripts may share an experiment name: each summary.json names the script that wrote it)."""
    paths = sorted(glob.glob(os.path.join(runs_dir, f"*__{exp_name}__{seed}__*", "summary.json")), key=os.path.getmtime)
    for path in reversed(paths):
        with open(path) as f:
            summary = json.load(f)
        if summary.get("status") == "completed" and summary.get("script") == os.path.basename(script):
            return path
    return None


def run_one(args: Args, seed: int, threads: int) -> tuple[int, int, float]:
    """Run the script for one seed; returns (seed, exit code, seconds)."""
    cmd = [sys.executable, args.script, "--seed", str(seed), "--exp-name", args.exp_name, "--num-threads",
           str(threads), *args.script_args]  # fmt: skip
    os.makedirs(args.logs_dir, exist_ok=True)
    log = os.path.join(args.logs_dir, f"{args.exp_name}__{seed}.log")
    start = time.time()
    with open(log, "w") as f:
        f.write(shlex.join(cmd) + "\n")
        f.flush()
        code = subprocess.call(cmd, stdout=f, stderr=subprocess.STDOUT)
    print(f"seed {seed}: exit {code} after {time.time() - start:.0f}s (log: {log})", flush=True)
    return seed, code, time.time() - start


def aggregate(summaries: list[dict]) -> dict[str, dict]:
    """Mean, sample std and n of every numeric key the summaries share."""
    table = {}
    for key in sorted(summaries[0]):
        values = [s[key] for s in summaries if isinstance(s.get(key), int | float) and not isinstance(s[key], bool)]
        values = [v for v in values if math.isfinite(v)]
        if not values or key == "seed":
            continue
        mean = sum(values) / len(values)
        std = math.sqrt(sum((v - mean) ** 2 for v in values) / (len(values) - 1)) if len(values) > 1 else 0.0
        table[key] = {"mean": mean, "std": std, "n": len(values), "values": values}
    return table


def main(args: Args) -> dict:
    todo = [s for s in args.seeds if finished_summary(args.runs_dir, args.exp_name, s, args.script) is None]
    done = sorted(set(args.seeds) - set(todo))
    if done:
        print(f"already finished, not run again: seeds {done}", flush=True)
    threads = args.threads or max(1, (os.cpu_count() or 1) // args.workers)
    if todo:
        print(f"running {args.script} for seeds {todo}: {args.workers} workers, {threads} thread(s) each", flush=True)
        with ThreadPoolExecutor(args.workers) as pool:
            list(pool.map(lambda seed: run_one(args, seed, threads), todo))

    paths = {s: finished_summary(args.runs_dir, args.exp_name, s, args.script) for s in args.seeds}
    missing = [s for s, p in paths.items() if p is None]
    summaries = []
    for path in filter(None, paths.values()):
        with open(path) as f:
            summaries.append(json.load(f))
    if not summaries:
        print(f"error: no run of {args.exp_name} finished; see the logs in {args.logs_dir}", file=sys.stderr)
        sys.exit(1)
    table = aggregate(summaries)
    print(
        f"\n{args.exp_name}: {len(summaries)} of {len(args.seeds)} seeds finished"
        + (f", missing {missing}" if missing else "")
    )
    print("| key | mean | std | n |\n| --- | --- | --- | --- |")
    for key, row in table.items():
        print(f"| {key} | {row['mean']:.4g} | {row['std']:.3g} | {row['n']} |")
    out = os.path.join(args.runs_dir, f"{args.exp_name}__table.json")
    with open(out + ".tmp", "w") as f:
        json.dump({"script": args.script, "seeds": args.seeds, "runs": paths, "table": table}, f, indent=2)
    os.replace(out + ".tmp", out)
    print(f"table written to {out}")
    return table


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
        if args.workers < 1 or args.threads < 0 or not args.seeds:
            raise ValueError("--workers must be >= 1, --threads >= 0, and --seeds non-empty")
        if not os.path.isfile(args.script):
            raise ValueError(f"{args.script}: no such script")
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    main(args)
