"""A scripted person teaches the maze through a pseudo-terminal: it reads the screen of
`inform_dqn_gridworld.py --teacher human` as a person would (where A stands, which way its arrow points) and answers
as exact Q* would: y when the move is the best one there (Eq. 4), Enter otherwise. It answers until the agent's own
(greedy) way from S reaches G and the agent has walked from S to G in time once (so the sleep has something to learn
from), then types q. Per seed: the answers until TAMER's greedy path first reached G, the answers given in all, and
the episode lengths at the end.

    python -m inform_utils.scripted_person --seeds 1 2 3 4 5
    python -m inform_utils.scripted_person --keep-dir person_days --flags=--save-buffer   # days to sleep on again
"""

import glob
import json
import os
import pty
import re
import select
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field

import numpy as np
import tyro

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)
import gridworld_env  # noqa: E402

PROMPT = b"[y / Enter / q] "


@dataclass
class Args:
    seeds: list[int] = field(default_factory=lambda: [1, 2, 3, 4, 5])
    """seeds of the runs taught, one after the other"""
    max_answers: int = 1000
    """give up (q) after this many answers"""
    script: str = os.path.join(REPO, "inform_dqn_gridworld.py")
    """the maze script to teach"""
    flags: list[str] = field(default_factory=list)
    """extra flags for the script (the human mode's defaults otherwise)"""
    timeout: float = 600.0
    """seconds a whole run may take"""
    keep_dir: str | None = None
    """keep each seed's run in {keep_dir}/seed{seed}/runs/ (with --flags=--save-buffer: a day to sleep on again with
    --sleep-from); default: each run in a temporary directory, removed"""


def read_move(screen: str) -> tuple[int, int, int, int]:
    """From the last screen: (cell of A, its move, the agent's own way from S in steps or 200, walks in time)."""
    header = list(re.finditer(r"its own way from S: (reaches G in (\d+) steps|does not reach G yet) \| "
                              r"walks to G in time: (\d+)", screen))[-1]  # fmt: skip
    maze = screen[header.end() :].split("\n")
    rows = [line.rstrip("\r") for line in maze if line.startswith("|")][: gridworld_env.ROWS]
    for r, line in enumerate(rows):
        for c in range(gridworld_env.COLS):
            cell_text = line[1 + 4 * c : 4 + 4 * c]
            if cell_text[1] == "A":
                action = gridworld_env.ARROWS.index(cell_text[2])
                own_way = int(header.group(2)) if header.group(2) else 200
                return gridworld_env.CELL_INDEX[(r, c)], action, own_way, int(header.group(3))
    raise ValueError("no agent A on the screen:\n" + screen[-2000:])


def teach(seed: int, args: Args, q_star: np.ndarray, cwd: str) -> dict:
    master, slave = pty.openpty()
    proc = subprocess.Popen([sys.executable, args.script, "--teacher", "human", "--seed", str(seed), *args.flags],
                            cwd=cwd, stdin=slave, stdout=slave, stderr=subprocess.PIPE, close_fds=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # fmt: skip
    os.close(slave)
    seen, answers, deadline = b"", 0, time.monotonic() + args.timeout
    try:
        while True:
            while PROMPT not in seen:
                ready, _, _ = select.select([master], [], [], max(deadline - time.monotonic(), 0))
                chunk = os.read(master, 65536) if ready else b""
                if not chunk:
                    raise RuntimeError(f"seed {seed}: no prompt; screen:\n{seen.decode()[-2000:]}")
                seen += chunk
            screen, seen = seen.decode(errors="replace"), b""
            cell, action, own_way, walks = read_move(screen)
            if (own_way < 200 and walks >= 1) or answers >= args.max_answers:
                os.write(master, b"q\n")
                break
            good = q_star[cell, action] >= q_star[cell].max() - (1 - 0.999) * abs(q_star[cell].max())  # Eq. 4
            os.write(master, b"y\n" if good else b"\n")
            answers += 1
        proc.wait(max(deadline - time.monotonic(), 1))
    finally:
        os.close(master)
        if proc.poll() is None:
            proc.kill()
            proc.wait(30)
    (path,) = glob.glob(os.path.join(cwd, "runs", "*", "summary.json"))
    with open(path) as f:
        summary = json.load(f)
    return {"seed": seed, "exit": proc.returncode, **summary}


def main(args: Args) -> list[dict]:
    q_star = gridworld_env.optimal_q("plain")
    results = []
    print("| seed | answers until TAMER's greedy path reached G | answers in all | +1 given in all | "
          "TAMER greedy length | INFORM greedy length | sleep skipped |\n| --- | --- | --- | --- | --- | --- | --- |",
          flush=True)  # fmt: skip
    for seed in args.seeds:
        with tempfile.TemporaryDirectory() as tmp:
            cwd = os.path.join(args.keep_dir, f"seed{seed}") if args.keep_dir else tmp
            os.makedirs(cwd, exist_ok=True)
            if glob.glob(os.path.join(cwd, "runs", "*")):
                sys.exit(f"error: {cwd}/runs is not empty; give --keep-dir a new directory")
            r = teach(seed, args, q_star, cwd)
        results.append(r)
        print(f"| {seed} | {r['feedback/answers_to_tamer_goal']} | {r['feedback/answers']} | "
              f"{r.get('feedback/positive')} | {r['eval/tamer_episode_length']:.0f} | "
              f"{r.get('eval/inform_episode_length', '-')} | {r['sleep_skipped']} |", flush=True)  # fmt: skip
    reached = [r["feedback/answers_to_tamer_goal"] for r in results if r["feedback/answers_to_tamer_goal"] is not None]
    print(
        f"TAMER's greedy path reached G on {len(reached)}/{len(results)} seeds; answers needed: max "
        f"{max(reached, default=None)}, median {int(np.median(reached)) if reached else None}",
        flush=True,
    )
    return results


if __name__ == "__main__":
    main(tyro.cli(Args))
