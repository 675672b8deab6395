"""Can the night clone what the day's demonstrator did? How much of a saved day's actions its observations explain
(issue 69: the planner's pushes at the Pusher's page reach no night).

For each saved day (a run directory with day.pt, `--save-buffer`): a network of the actor's size (two hidden layers
of 256, ReLU) is fit by squared error to the actions of the chosen rows (by default the steps a person drove) in four
of every five episodes, and its R^2 is measured on the same rows of the fifth, episodes it never saw. Beside it, the
same fit on the same states to the day's expert teacher's mean action: a demonstrator whose action is a function of
the observation, the ceiling the rows' number and spread allow. A held-out R^2 near 0 where the expert's is well
above it says that the demonstrator acted on what the observation does not show (a planner's sampling and its plan,
the object's velocity): cloning learns its noise, at any step size and for any number of steps.

    python -m inform_utils.clonable runs/<day> [runs/<day> ...] --out clonable.json

Also in the JSON: the night's success set (its rows) and how many of them a person drove.
"""

import os
from dataclasses import dataclass
from typing import Literal

import torch
import tyro

import inform_sac_pusher as isp
from inform_utils.files import BadInput, cut, run_tool, write_json

HELD_OUT = 5  # every fifth episode (0, 5, 10, ...) is held out


@dataclass
class Args:
    days: tyro.conf.Positional[list[str]]
    """run directories holding a day.pt (made with --save-buffer)"""
    rows: Literal["driven", "success", "all"] = "driven"
    """the demonstrator's rows: the steps a person drove, the success set, or every step"""
    steps: int = 4000
    """gradient steps of each fit (Adam at 3e-4, batches of 256)"""
    seed: int = 0
    """the seed of the networks and batches"""
    out: str | None = None
    """also write the numbers here as JSON (a new file)"""


def r_squared(pred: torch.Tensor, target: torch.Tensor) -> float:
    """1 - the squared error over the squared deviation from the rows' mean action (all dimensions pooled)."""
    return float(1 - (pred - target).pow(2).sum() / (target - target.mean(0)).pow(2).sum())


def fit(obs: torch.Tensor, actions: torch.Tensor, train: torch.Tensor, test: torch.Tensor, steps: int,
        seed: int) -> tuple[float, float]:  # fmt: skip
    """R^2 on the fitted rows and on the held-out ones."""
    gen = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    hidden = isp.HIDDEN_SIZE
    net = torch.nn.Sequential(torch.nn.Linear(obs.shape[1], hidden), torch.nn.ReLU(), torch.nn.Linear(hidden, hidden),
                              torch.nn.ReLU(), torch.nn.Linear(hidden, actions.shape[1]))  # fmt: skip
    optimizer = torch.optim.Adam(net.parameters(), lr=3e-4)
    for _ in range(steps):
        batch = train[torch.randint(len(train), (256,), generator=gen)]
        loss = (net(obs[batch]) - actions[batch]).pow(2).mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    with torch.no_grad():
        return r_squared(net(obs[train]), actions[train]), r_squared(net(obs[test]), actions[test])


def split(run_dir: str, rows: str) -> tuple[dict, torch.Tensor, torch.Tensor]:
    """The day read and checked (isp.load_day), and its chosen rows: those of the episodes fitted, those held out."""
    try:
        day = isp.load_day(run_dir)
    except isp.InputError as e:
        raise BadInput(str(e).replace("--sleep-from ", "")) from None
    episode = torch.zeros(len(day["obs"]), dtype=torch.long)
    for i, (start, end) in enumerate(zip(day["episode_start"].tolist(), day["episode_end"].tolist(), strict=True)):
        episode[start:end] = i
    chosen = {"driven": day["driven"].bool(), "success": day["success"].bool(), "all": torch.ones_like(episode) > 0}
    held = episode % HELD_OUT == 0
    train, test = (chosen[rows] & ~held).nonzero().squeeze(-1), (chosen[rows] & held).nonzero().squeeze(-1)
    if min(len(train), len(test)) < 2:
        raise BadInput(f"{cut(run_dir, 200)}: {len(train)} {rows} rows to fit and {len(test)} held out; it needs 2 "
                       f"or more of each (a day whose rows span {HELD_OUT} episodes or more)")  # fmt: skip
    if any(bool((day["actions"][idx] == day["actions"][idx][0]).all()) for idx in (train, test)):
        raise BadInput(f"{cut(run_dir, 200)}: the {rows} rows' actions are all the same: R^2 measures nothing there")
    return day, train, test


def measure(run_dir: str, day: dict, train: torch.Tensor, test: torch.Tensor, args: Args) -> dict:
    obs, actions = day["obs"], day["actions"]
    expert = isp.actor_from_checkpoint(day["oracle"])
    with torch.no_grad():
        expert_actions = expert.get_action(obs)[2]  # its mean action on the day's states
    fitted, held_out = fit(obs, actions, train, test, args.steps, args.seed)
    expert_fitted, expert_held_out = fit(obs, expert_actions, train, test, args.steps, args.seed)
    success, driven = day["success"].bool(), day["driven"].bool()
    return {"day": run_dir, "success set rows": int(success.sum()), "of them driven": int((success & driven).sum()),
            "rows": args.rows, "fitted rows": len(train), "held-out rows": len(test),
            "R2 fitted": round(fitted, 3), "R2 held out": round(held_out, 3),
            "expert R2 fitted": round(expert_fitted, 3), "expert R2 held out": round(expert_held_out, 3)}  # fmt: skip


def main(args: Args) -> list[dict]:
    if args.steps < 1:
        raise BadInput(f"--steps must be >= 1, got {args.steps}")
    if args.out is not None and (os.path.lexists(args.out) or not os.path.isdir(os.path.dirname(args.out) or ".")):
        raise BadInput(f"--out {cut(args.out, 200)}: give a new file in an existing folder (nothing is overwritten)")
    days = [(run_dir, *split(run_dir, args.rows)) for run_dir in args.days]  # every day checked before the first fit
    torch.set_num_threads(1)
    results = []
    print("| day | rows fitted / held out | R^2 fitted | R^2 held out | the expert's R^2 fitted | held out |")
    print("| --- | --- | --- | --- | --- | --- |", flush=True)
    for run_dir, day, train, test in days:
        r = measure(run_dir, day, train, test, args)
        results.append(r)
        print(f"| {run_dir} | {r['fitted rows']} / {r['held-out rows']} | {r['R2 fitted']} | {r['R2 held out']} | "
              f"{r['expert R2 fitted']} | {r['expert R2 held out']} |", flush=True)  # fmt: skip
    if args.out is not None:
        write_json(args.out, results)
    return results


if __name__ == "__main__":
    run_tool(main, tyro.cli(Args))
