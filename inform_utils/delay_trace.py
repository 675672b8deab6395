"""Where a late teacher's +1 lands, traced step by step on the maze (why --teacher-delay 1 fails and 2 can work).

Runs the maze script itself (its `main`, in a temporary directory, the sleep cut to one step) with a teacher that
records every signal: the step it was about, the transitions it labels, and whether Eq. 4 calls a labelled move good.
A signal about step t lands on step t + d (and, with a credit window k, on the k - 1 steps before that). The maze is a
grid: an agent that goes x -> y and back y -> x walks a 2-cycle, and a signal d steps late lands on the same move of
the cycle when d is even and on the *reverse* move when d is odd. The reverse of a good move is a bad one, so an odd
delay teaches H to turn back; a window k > 1 adds the steps after t (d = 2, k = 3 labels t + 1 too: the reverse).

    python -m inform_utils.delay_trace --delay 1 --credit-window 1 --seed 1
    python -m inform_utils.delay_trace --table   # every (delay, window) of the table, the first seeds
"""

import contextlib
import io
import os
import signal
import sys
import tempfile
from dataclasses import dataclass, field

import numpy as np
import tyro

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import gridworld_env  # noqa: E402
import inform_dqn_gridworld as inform  # noqa: E402


@dataclass
class Args:
    delay: int = 1
    """--teacher-delay of the traced run"""
    credit_window: int = 1
    """--credit-window of the traced run"""
    seed: int = 1
    """--seed of the traced run"""
    tamer_total_timesteps: int = 10000
    """--tamer-total-timesteps (the maze's default)"""
    show: int = 40
    """lines of the step-by-step trace to print (from step --show-from)"""
    show_from: int = 1000
    """first step shown (H is trained from step 1000 on, by default)"""
    table: bool = False
    """instead of one trace: the label statistics and TAMER's final greedy length for each (delay, window) below"""
    cases: list[str] = field(default_factory=lambda: ["0,1", "1,1", "2,1", "1,2", "2,3", "3,1", "4,1"])
    """(delay, window) pairs of --table"""
    seeds: list[int] = field(default_factory=lambda: [1, 2, 3])
    """seeds of --table"""


def traced_run(delay: int, window: int, seed: int, total: int):
    """A real run of the maze script (its `main`, in a temporary directory, no sleep), with a teacher that records
    (step about, steps labelled) for each +1 and the replay buffer kept for the trace."""
    args = inform.Args(seed=seed, teacher_delay=delay, credit_window=window, tamer_total_timesteps=total,
                       sleep_gradient_steps=1)  # fmt: skip
    inform.check_args(args)
    signals, buffers = [], []

    class TracingTeacher(inform.Teacher):
        def __call__(self, step, h_star):
            labelled = super().__call__(step, h_star)
            if labelled:
                signals.append((step - self.delay, labelled))
            return labelled

    class KeptBuffer(inform.ReplayBuffer):
        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            buffers.append(self)

    patched = {"Teacher": TracingTeacher, "ReplayBuffer": KeptBuffer}
    originals = {name: getattr(inform, name) for name in patched}
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    cwd = os.getcwd()
    with (
        tempfile.TemporaryDirectory() as tmp,
        contextlib.redirect_stdout(io.StringIO()),
        contextlib.redirect_stderr(io.StringIO()),
    ):
        os.chdir(tmp)
        try:
            for name, cls in patched.items():
                setattr(inform, name, cls)
            summary = inform.main(args, None, inform.StopSignals())
        finally:
            os.chdir(cwd)
            for name, cls in originals.items():
                setattr(inform, name, cls)
            for sig, handler in handlers.items():
                signal.signal(sig, handler)
    (buffer,) = buffers
    q_star = gridworld_env.optimal_q("plain")  # the script's oracle: gamma 0.99
    cells = buffer.obs[: buffer.size].argmax(1).numpy()
    next_cells = buffer.next_obs[: buffer.size].argmax(1).numpy()
    actions = buffer.actions[: buffer.size].numpy()
    best = q_star[cells].max(1)
    good = q_star[cells, actions] >= best - (1 - args.feedback_alpha_start) * np.abs(best)  # Eq. 4
    assert summary["feedback/positive"] == len(signals)  # the trace is the run
    return cells, next_cells, actions, good, signals, int(summary["eval/tamer_episode_length"])


def label_stats(cells, next_cells, actions, good, signals) -> dict:
    """Of all +1 labels: the share on a move Eq. 4 calls good, and the share on the reverse of the move it was about
    (back to the cell that move came from)."""
    on_good = on_reverse = total = 0
    for about, labelled in signals:
        for i in labelled:
            total += 1
            on_good += bool(good[i])
            on_reverse += bool(cells[i] == next_cells[about] and next_cells[i] == cells[about] and i != about)
    return {"labels": total, "on_good": on_good / max(total, 1), "on_reverse": on_reverse / max(total, 1)}


def main(args: Args) -> None:
    name = gridworld_env.ACTION_NAMES
    if args.table:
        print("| delay | window | seed | +1 labels | on a good move | on the reverse of the move judged | "
              "TAMER greedy length |\n| --- | --- | --- | --- | --- | --- | --- |")  # fmt: skip
        for case in args.cases:
            d, k = map(int, case.split(","))
            for seed in args.seeds:
                cells, nxt, acts, good, signals, length = traced_run(d, k, seed, args.tamer_total_timesteps)
                st = label_stats(cells, nxt, acts, good, signals)
                print(f"| {d} | {k} | {seed} | {st['labels']} | {st['on_good']:.2f} | {st['on_reverse']:.2f} | "
                      f"{length} |", flush=True)  # fmt: skip
        return
    cells, nxt, acts, good, signals, length = traced_run(args.delay, args.credit_window, args.seed,
                                                         args.tamer_total_timesteps)  # fmt: skip
    about_of = {i: about for about, labelled in signals for i in labelled}
    print(
        f"delay {args.delay}, window {args.credit_window}, seed {args.seed}: step | cell --move--> cell | Eq. 4 | "
        "+1 label received (about which step)"
    )
    for t in range(args.show_from, min(args.show_from + args.show, len(cells))):
        label = ""
        if t in about_of:
            a = about_of[t]
            label = f"+1 about step {a} ({cells[a]} {name[acts[a]]}, {'good' if good[a] else 'bad'})"
            label += " -> lands on a " + ("good" if good[t] else "BAD") + " move"
        print(
            f"{t:6d} | {cells[t]:2d} --{name[acts[t]]:>5}--> {nxt[t]:2d} | {'good' if good[t] else 'bad ':4} | {label}"
        )
    st = label_stats(cells, nxt, acts, good, signals)
    print(
        f"{st['labels']} +1 labels: {st['on_good']:.0%} on a good move, {st['on_reverse']:.0%} on the reverse of "
        f"the move judged; TAMER's greedy path from S: {length} steps (19 is the optimum, 200 never reaches G)"
    )


if __name__ == "__main__":
    main(tyro.cli(Args))
