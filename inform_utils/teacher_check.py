"""Check a Pusher teacher against the expert bar (docs/protocol.md, "Oracles and the expert bar"), on starts it was
neither trained nor chosen on: deterministic (mean-action) episodes from random starts on a block of reset seeds of
its own, and from the fixed start of each seed the results use. Prints one JSON object: success rate, the final
distances' mean and quantiles, the return, and each fixed start's final distance; --out writes it too. Under the
contact it was trained under (as recorded), or --contact's. And the pace
of the push: how fast the object closes on the goal, in the successful and the failed episodes apart (on Pusher-v5,
under MuJoCo 4's soft contact, a failure is mostly a push still under way when the episode ends).

    python -m inform_utils.teacher_check oracles/Pusher-v5__sac_oracle.pt --episodes 100 --fixed-seeds 1 2 3 4 5
"""

import json
import os
import sys
import warnings
from dataclasses import dataclass, field
from typing import Literal

import gymnasium as gym
import numpy as np
import torch
import tyro

import inform_sac_pusher as isp
from inform_utils.files import atomic, cut, run_tool
from oracle_train import EXPERT_FINAL_DISTANCE, EXPERT_SUCCESS_RATE

SUCCESS_DISTANCE = 0.08  # the paper's success tag, on v4 and v5 alike
PACE_WINDOW = 10  # steps over which the object's closing speed on the goal is measured
STILL_CLOSING = 0.01  # m/s: an episode whose object closes faster than this over its last window ends mid-push


@dataclass
class Args:
    checkpoint: tyro.conf.Positional[str]
    """an oracle checkpoint of oracle_train.py"""
    episodes: int = 100
    """random-start episodes"""
    reset_seed: int = 7_000_000
    """the first reset seed of the random starts (training used the run's seed, selection 1,000,000 on, the final
    evaluation 20,000 on)"""
    fixed_seeds: list[int] = field(default_factory=lambda: list(range(1, 11)))
    """seeds whose fixed start (reset with the seed, the paper's protocol) is tested too"""
    out: str | None = None
    """also write the JSON here"""
    contact: Literal[isp.CONTACTS] | None = None
    """Pusher's contact to check it under (inform_sac_pusher.py --contact); None: the one it was trained under"""


@torch.no_grad()
def final_distance(actor: isp.Actor, env: gym.Env, reset_seed: int) -> tuple[float, float, np.ndarray]:
    """|info["reward_dist"]| at the end, the return, and the object's distance to the goal in the table's plane
    before each step and after the last (isp.object_xy; the goal, fixed, at obs[20:22])."""
    obs, _ = env.reset(seed=reset_seed)
    done = False
    ep_return = 0.0
    info = {}
    path = [np.linalg.norm(isp.object_xy(obs) - obs[20:22])]
    while not done:
        _, _, action = actor.get_action(torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0))
        obs, reward, terminated, truncated, info = env.step(action[0].numpy())
        ep_return += float(reward)
        done = terminated or truncated
        path.append(np.linalg.norm(isp.object_xy(obs) - obs[20:22]))
    return abs(float(info["reward_dist"])), ep_return, np.array(path)


def pace(paths: np.ndarray, dt: float) -> dict | None:
    """Means over episodes (rows: the object's distances to the goal, one a step) of the start distance (m), the
    fastest and the last closing speed over PACE_WINDOW steps (m/s), and the share still closing faster than
    STILL_CLOSING at the end; the fastest episode's fastest closing speed; None for no episode."""
    if len(paths) == 0:
        return None
    closing = (paths[:, :-PACE_WINDOW] - paths[:, PACE_WINDOW:]) / (PACE_WINDOW * dt)
    return {"episodes": len(paths), "start_distance": float(paths[:, 0].mean()),
            "peak_closing_speed": float(closing.max(axis=1).mean()), "fastest_closing_speed": float(closing.max()),
            "last_closing_speed": float(closing[:, -1].mean()),
            "still_closing": float((closing[:, -1] > STILL_CLOSING).mean())}  # fmt: skip


def read_teacher(path: str) -> dict:
    """The SAC teacher at `path`, checked as --oracle-path checks it (its CRCs, weights only, its keys, its env's
    shapes); isp.InputError, one line that names it as this tool takes it (CHECKPOINT, not --oracle-path), otherwise."""
    if not os.path.isfile(path):
        what = "a directory, not a file" if os.path.isdir(path) else "no such file"
        raise isp.InputError(f"{path}: {what} (a teacher of oracle_train.py: oracles/Pusher-v5__sac_oracle.pt)")
    isp.check_crc(path, path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ckpt = torch.load(path, weights_only=True, map_location="cpu")
    except Exception as e:  # code in the pickle, or not a checkpoint at all
        raise isp.InputError(f"{path}: refused, not a weights-only torch checkpoint ({type(e).__name__})") from None
    if not isinstance(ckpt, dict) or ckpt.get("algorithm") != "sac":
        raise isp.InputError(f"{path}: not a SAC teacher of oracle_train.py (a maze teacher has no episodes to check)")
    try:
        return isp.read_checkpoint(path, "--oracle-path", str(ckpt.get("env_id")))
    except isp.InputError as e:
        why = str(e).removeprefix(f"--oracle-path {path}: ")
        if why.startswith("the networks do not load"):  # the core cuts its reason at 80 characters: say it whole
            why = f"the networks do not load ({networks_error(ckpt)})"
        raise isp.InputError(f"{path}: {why}") from None


def networks_error(ckpt: dict) -> str:
    """Why a teacher's networks do not load, on one line with whole key names (a long list cut between names)."""
    try:
        isp.oracle_from_checkpoint(ckpt, torch.device("cpu"))
    except Exception as e:
        why = cut(f"{type(e).__name__}: {e}", 400)
        critics = ckpt["qf_state_dict"]
        if not ckpt["kwargs"].get("layer_norm") and isinstance(critics, dict) and "norm" in critics:
            why += "; its critics are a LayerNorm's (the marker norm) but its kwargs lack layer_norm: True"
        return why
    return "they load here"


def check(args: Args) -> dict:
    ckpt = read_teacher(args.checkpoint)
    actor = isp.actor_from_checkpoint(ckpt)  # the kwargs may hold the critics' too (layer_norm)
    trained_under = isp.made_under(ckpt, ckpt["env_id"])
    contact = isp.contact_of(ckpt["env_id"], args.contact or trained_under or isp.CONTACTS[0])
    env = isp.make_env(ckpt["env_id"], 0, contact=contact)
    runs = [final_distance(actor, env, args.reset_seed + ep) for ep in range(args.episodes)]
    distances, paths = np.array([d for d, _, _ in runs]), np.array([path for _, _, path in runs])
    fixed = {seed: final_distance(actor, env, seed)[0] for seed in args.fixed_seeds}
    dt = env.unwrapped.dt  # seconds an action lasts
    env.close()
    success = float((distances < SUCCESS_DISTANCE).mean())
    levels = {"p10": 0.1, "p25": 0.25, "p50": 0.5, "p75": 0.75, "p90": 0.9}
    quantiles = {name: np.quantile(distances, q) for name, q in levels.items()}
    return {
        "checkpoint": args.checkpoint,
        "env_id": ckpt["env_id"],
        "training_steps": int(ckpt.get("training_steps", -1)),
        "contact": contact,
        "trained_under": trained_under,
        "random_starts": {
            "episodes": args.episodes,
            "first_reset_seed": args.reset_seed,
            "success_rate": success,
            "final_distance": float(distances.mean()),
            "final_distance_quantiles": {k: float(v) for k, v in quantiles.items()},
            "return": float(np.mean([r for _, r, _ in runs])),
            "pace": {  # the object's (Pusher's obs[17:19]); other envs have none
                outcome: pace(paths[ended], dt)
                for outcome, ended in (
                    ("success", distances < SUCCESS_DISTANCE),
                    ("failure", distances >= SUCCESS_DISTANCE),
                )
            }
            if ckpt["env_id"] in isp.PUSHER_IDS
            else None,
        },
        "fixed_starts": {str(seed): d for seed, d in fixed.items()},
        "fixed_start_successes": int(sum(d < SUCCESS_DISTANCE for d in fixed.values())),
        "meets_the_bar": bool(
            success >= EXPERT_SUCCESS_RATE
            and distances.mean() <= EXPERT_FINAL_DISTANCE
            and all(d < SUCCESS_DISTANCE for d in fixed.values())
        ),
    }


def main(args: Args) -> int:
    try:  # the ranges before the teacher loads: a seed below 0 was a traceback of gymnasium's reset
        if args.episodes < 1:
            raise isp.InputError(f"--episodes must be >= 1, got {args.episodes}")
        if args.reset_seed < 0 or min(args.fixed_seeds, default=0) < 0:
            seeds = " ".join(map(str, args.fixed_seeds))
            raise isp.InputError(f"--reset-seed and --fixed-seeds are seeds >= 0, got {args.reset_seed} and {seeds}")
        if args.out is not None and (os.path.isdir(args.out) or not os.path.isdir(os.path.dirname(args.out) or ".")):
            raise isp.InputError(f"--out {args.out}: must name a file in an existing directory")
        result = check(args)
    except isp.InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    text = json.dumps(result, indent=1)
    print(text)
    if args.out:
        with atomic(args.out) as f:
            f.write(text + "\n")
    return 0


if __name__ == "__main__":
    run_tool(main, tyro.cli(Args))
