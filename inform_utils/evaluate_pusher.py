"""Re-evaluate a saved policy of inform_sac_pusher.py (tamer_actor.pt, inform_actor.pt, or an oracle) under the run's
final-evaluation protocol: deterministic and sampled actions from the run's start (or random starts), and on Pusher
the obstacle test. Prints JSON; writes nothing. Like CleanRL's evaluation helpers, it imports the script's agent.

    python -m inform_utils.evaluate_pusher runs/<run>/inform_actor.pt
    python -m inform_utils.evaluate_pusher oracles/Pusher-v4__sac_oracle.pt --env-id Pusher-v4 --random-starts
"""

import os
import signal


def stopped_while_starting(signum, frame):  # a stop: one line, nothing was written
    os.write(2, f"interrupted ({signal.Signals(signum).name}); nothing was written\n".encode())
    os._exit(128 + signum)


if __name__ == "__main__":  # before the slow imports, so that no stop ends in a traceback
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        if signal.getsignal(sig) is not signal.SIG_IGN:
            signal.signal(sig, stopped_while_starting)

import dataclasses  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from typing import Literal  # noqa: E402

import torch  # noqa: E402
import tyro  # noqa: E402

import inform_sac_pusher as isp  # noqa: E402


@dataclass
class Args:
    policy: tyro.conf.Positional[str]
    """the saved actor: a run's tamer_actor.pt or inform_actor.pt, or an oracle checkpoint"""
    env_id: str = "Pusher-v5"
    """the env it was trained on (as the run's --env-id)"""
    seed: int = 1
    """the run's seed: its fixed start, and the seed of the sampled actions"""
    random_starts: bool = False
    """random initial states instead of the run's fixed start"""
    eval_episodes: int = 20
    """episodes with deterministic and with sampled actions"""
    obstacle_episodes: int = 100
    """episodes on the obstacle variant (Pusher; 0: none)"""
    obstacle_layout: Literal["bisector", "paper"] = "bisector"
    """the boxes (as the run's --obstacle-layout)"""
    success_distance: float = 0.08
    """as the run's --success-distance"""
    success_info_key: str = "reward_dist"
    """as the run's --success-info-key"""
    success_return: float | None = None
    """as the run's --success-return"""
    num_threads: int = 1
    """torch CPU threads"""


def evaluate_policy(args: Args) -> dict:
    """The saved policy's eval/policy_* metrics and the obstacle test's, as the run's final evaluation gives them."""
    run_args = isp.Args(**{f.name: getattr(args, f.name) for f in dataclasses.fields(Args) if f.name != "policy"})
    isp.check_args(run_args)  # the script's ranges and checks, with its one-line messages
    torch.manual_seed(run_args.seed)
    torch.set_num_threads(run_args.num_threads)
    actor = isp.actor_from_checkpoint(isp.read_checkpoint(args.policy, "policy", run_args.env_id))
    evaluator = isp.Evaluator(run_args, writer=None)
    metrics = evaluator("policy", actor, 0, run_args.eval_episodes)
    obstacle = {"obstacle/skipped": isp.obstacle_skipped(run_args.env_id, run_args.obstacle_episodes)}
    if obstacle["obstacle/skipped"] is None:
        test = (run_args.env_id, run_args.seed, run_args.obstacle_layout, run_args.obstacle_episodes)
        obstacle, _, _ = isp.obstacle_test(*test, isp.Outcome.from_args(run_args), {"policy": actor},
                                           evaluator.generator)  # fmt: skip
    evaluator.close()
    return {**metrics, **obstacle}


def main() -> int:
    args = tyro.cli(Args)
    try:
        print(json.dumps(evaluate_policy(args), indent=2))
    except isp.InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
