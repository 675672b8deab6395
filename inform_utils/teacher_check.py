"""Check a Pusher teacher against the expert bar (docs/protocol.md, "Oracles and the expert bar"), on starts it was
neither trained nor chosen on: deterministic (mean-action) episodes from random starts on a block of reset seeds of
its own, and from the fixed start of each seed the results use. Prints one JSON object: success rate, the final
distances' mean and quantiles, the return, and each fixed start's final distance; --out writes it too.

    python -m inform_utils.teacher_check oracles/Pusher-v5__sac_oracle.pt --episodes 100 --fixed-seeds 1 2 3 4 5
"""

import json
from dataclasses import dataclass, field

import gymnasium as gym
import numpy as np
import torch
import tyro

from oracle_train import Actor

SUCCESS_DISTANCE = 0.08  # the paper's success tag, on v4 and v5 alike
EXPERT_SUCCESS_RATE = 0.95
EXPERT_FINAL_DISTANCE = 0.06


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


@torch.no_grad()
def final_distance(actor: Actor, env: gym.Env, reset_seed: int) -> tuple[float, float]:
    obs, _ = env.reset(seed=reset_seed)
    done = False
    ep_return = 0.0
    info = {}
    while not done:
        _, _, action = actor.get_action(torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0))
        obs, reward, terminated, truncated, info = env.step(action[0].numpy())
        ep_return += float(reward)
        done = terminated or truncated
    return abs(float(info["reward_dist"])), ep_return


def check(args: Args) -> dict:
    ckpt = torch.load(args.checkpoint, weights_only=True, map_location="cpu")
    actor = Actor(**ckpt["kwargs"], action_low=ckpt["action_low"], action_high=ckpt["action_high"])
    actor.load_state_dict(ckpt["actor_state_dict"])
    env = gym.make(ckpt["env_id"])
    runs = [final_distance(actor, env, args.reset_seed + ep) for ep in range(args.episodes)]
    distances = np.array([d for d, _ in runs])
    fixed = {seed: final_distance(actor, env, seed)[0] for seed in args.fixed_seeds}
    env.close()
    success = float((distances < SUCCESS_DISTANCE).mean())
    levels = {"p10": 0.1, "p25": 0.25, "p50": 0.5, "p75": 0.75, "p90": 0.9}
    quantiles = {name: np.quantile(distances, q) for name, q in levels.items()}
    return {
        "checkpoint": args.checkpoint,
        "env_id": ckpt["env_id"],
        "training_steps": int(ckpt.get("training_steps", -1)),
        "random_starts": {
            "episodes": args.episodes,
            "first_reset_seed": args.reset_seed,
            "success_rate": success,
            "final_distance": float(distances.mean()),
            "final_distance_quantiles": {k: float(v) for k, v in quantiles.items()},
            "return": float(np.mean([r for _, r in runs])),
        },
        "fixed_starts": {str(seed): d for seed, d in fixed.items()},
        "fixed_start_successes": int(sum(d < SUCCESS_DISTANCE for d in fixed.values())),
        "meets_the_bar": bool(
            success >= EXPERT_SUCCESS_RATE
            and distances.mean() <= EXPERT_FINAL_DISTANCE
            and all(d < SUCCESS_DISTANCE for d in fixed.values())
        ),
    }


if __name__ == "__main__":
    args = tyro.cli(Args)
    result = check(args)
    text = json.dumps(result, indent=1)
    print(text)
    if args.out:
        with open(args.out, "w") as f:
            f.write(text + "\n")
