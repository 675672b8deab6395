"""How far the night moved TAMER's actor, and what a random move of the same size does to the return at the run's
start: is the night's harm its direction, or does any small change of TAMER's actor hurt there?

For each Pusher run directory (its tamer_actor.pt and inform_actor.pt, as `results/v4paper/*` keep them):

- the night's move: the relative size of the weights' change, |theta_inform - theta_tamer| / |theta_tamer| (every
  weight and bias of the actor), and how far it moves the mean action, the mean over the states of TAMER's
  deterministic episode from the run's fixed start of |a_inform(s) - a_tamer(s)| (Euclidean, in torque units);
- the returns, deterministic actions from the fixed start: TAMER's, INFORM's, and TAMER's moved by `--perturbations`
  random directions, each layer's change drawn Gaussian and scaled to the night's change of that layer (the same
  size in weights), then rescaled as a whole so that it moves the mean action as far as the night did (the same
  size in what the actor does). Printed: the median and range of those returns and how many end a success.

    python -m inform_utils.actor_shift results/v5paper/* --perturbations 20
    .venv-v4/bin/python -m inform_utils.actor_shift results/v4paper/* --perturbations 20
"""

import copy
import os
import sys
from dataclasses import dataclass

import numpy as np
import torch
import tyro

import inform_sac_pusher as isp
from inform_utils.files import BadFile, read_json, write_json


@dataclass
class Args:
    runs: tyro.conf.Positional[list[str]]
    """Pusher run directories holding tamer_actor.pt and inform_actor.pt (and summary.json: env id, seed, success)"""
    perturbations: int = 20
    """random moves of TAMER's actor per run"""
    seed: int = 0
    """the seed of the random directions"""
    out: str | None = None
    """also write the numbers here as JSON"""


def episode(actor, env, seed: int, outcome, keep_states: bool = False) -> dict:
    """One deterministic episode from the fixed start (the env and the actor are deterministic: one is all); with
    `keep_states`, its observations too."""
    res = isp.evaluate(actor, env, 1, lambda ep: seed, True, None, outcome)
    out = {"return": res["return"], "final_distance": res["final_distance"], "success": bool(res["success_rate"])}
    return {**out, "states": torch.as_tensor(res["trajectories"][0], dtype=torch.float32)} if keep_states else out


def mean_action(actor, states: torch.Tensor) -> torch.Tensor:
    with torch.no_grad():
        return actor.get_action(states)[2]


def moved(actor, direction: dict, scale: float):
    out = copy.deepcopy(actor)
    with torch.no_grad():
        for name, p in out.named_parameters():
            p.add_(scale * direction[name])
    return out


def action_shift(actor, base, states: torch.Tensor) -> float:
    return float((mean_action(actor, states) - mean_action(base, states)).norm(dim=1).mean())


def scale_to(tamer, direction: dict, states: torch.Tensor, target: float) -> float:
    """The factor on `direction` that moves TAMER's mean action by `target` on `states` (bisection on a log scale)."""
    low, high = 0.0, 1.0
    while action_shift(moved(tamer, direction, high), tamer, states) < target and high < 1e4:
        low, high = high, high * 2
    for _ in range(40):
        mid = (low + high) / 2
        low, high = (mid, high) if action_shift(moved(tamer, direction, mid), tamer, states) < target else (low, mid)
    return (low + high) / 2


def shift(run_dir: str, perturbations: int, generator: torch.Generator) -> dict:
    summary = read_json(os.path.join(run_dir, "summary.json"))
    run = summary["args"]
    actors = {}
    for name in ("tamer", "inform"):
        path = os.path.join(run_dir, f"{name}_actor.pt")
        actors[name] = isp.actor_from_checkpoint(isp.read_checkpoint(path, "actor", run["env_id"]))
    tamer, inform = actors["tamer"], actors["inform"]
    env = isp.make_env(run["env_id"], summary["seed"], contact=isp.made_under(run, run["env_id"]) or isp.CONTACTS[0])
    outcome = isp.Outcome(run.get("success_info_key", "reward_dist"), run["success_distance"],
                          run.get("success_return"))  # fmt: skip
    tamer_episode = episode(tamer, env, summary["seed"], outcome, keep_states=True)
    states = tamer_episode.pop("states")
    pairs = zip(tamer.named_parameters(), inform.named_parameters(), strict=True)
    delta = {name: p_i.detach() - p_t.detach() for (name, p_t), (_, p_i) in pairs}
    size = float(torch.sqrt(sum((d**2).sum() for d in delta.values())))
    norm = float(torch.sqrt(sum((p.detach() ** 2).sum() for p in tamer.parameters())))
    target = action_shift(inform, tamer, states)
    random_moves = []
    for _ in range(perturbations):
        direction = {}
        for name, d in delta.items():
            g = torch.randn(d.shape, generator=generator)
            direction[name] = g * (d.norm() / g.norm().clamp_min(1e-12))
        same_weights = episode(moved(tamer, direction, 1.0), env, summary["seed"], outcome)
        factor = scale_to(tamer, direction, states, target)
        same_actions = episode(moved(tamer, direction, factor), env, summary["seed"], outcome)
        random_moves.append({"same_weights": same_weights, "same_actions": same_actions, "factor": factor})
    inform_episode = episode(inform, env, summary["seed"], outcome)
    env.close()
    return {
        "run": run_dir,
        "env_id": run["env_id"],
        "seed": summary["seed"],
        "relative_weight_change": size / norm,
        "mean_action_change": target,
        "tamer": tamer_episode,
        "inform": inform_episode,
        "random_moves": random_moves,
    }


def line(r: dict) -> str:
    def spread(kind):
        returns = [m[kind]["return"] for m in r["random_moves"]]
        wins = sum(m[kind]["success"] for m in r["random_moves"])
        return f"{np.median(returns):.1f} [{min(returns):.1f}, {max(returns):.1f}], {wins}/{len(returns)} succeed"

    factors = [m["factor"] for m in r["random_moves"]]
    return (
        f"{os.path.basename(os.path.normpath(r['run']))}: night moves weights {r['relative_weight_change']:.3f}, "
        f"mean action {r['mean_action_change']:.3f} | TAMER {r['tamer']['return']:.1f} "
        f"({'success' if r['tamer']['success'] else 'fail'}), INFORM {r['inform']['return']:.1f} "
        f"({'success' if r['inform']['success'] else 'fail'}) | random, same weights: {spread('same_weights')}; "
        f"same action change (x{np.median(factors):.2f}): {spread('same_actions')}"
    )


def check(args: Args) -> None:
    """Bad input, before the work: ValueError, one line."""
    if not args.runs:
        raise ValueError("pass at least one Pusher run directory (with tamer_actor.pt and inform_actor.pt)")
    if args.perturbations < 1:
        raise ValueError(f"--perturbations must be >= 1 (random moves per run), got {args.perturbations}")
    if args.out is not None and (os.path.isdir(args.out) or not os.path.isdir(os.path.dirname(args.out) or ".")):
        raise ValueError(f"--out {args.out}: must name a file in an existing directory")


def main() -> int:
    args = tyro.cli(Args, description=__doc__.split("\n\n")[0])
    try:
        check(args)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    torch.set_num_threads(1)
    generator = torch.Generator().manual_seed(args.seed)
    results = []
    try:
        for run_dir in args.runs:
            results.append(shift(run_dir, args.perturbations, generator))
            print(line(results[-1]), flush=True)
    except (isp.InputError, BadFile, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyError as e:  # a summary.json without what a Pusher run records
        print(f"error: a summary.json lacks {e} (not a Pusher run of inform_sac_pusher.py?)", file=sys.stderr)
        return 2
    if args.out:
        write_json(args.out, results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
