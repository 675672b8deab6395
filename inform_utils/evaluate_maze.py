"""Re-evaluate a saved network of inform_dqn_gridworld.py (tamer_h.pt or inform_q.pt) greedily, under the run's
final tests: on the maze, the episode length from S, on the wall maze and from the start set, and the success rate
from every cell; on a toy-text task, greedy episodes from fixed reset seeds. Prints JSON; writes nothing. Like
CleanRL's evaluation helpers, it imports the script's agent.

    python -m inform_utils.evaluate_maze runs/<run>/inform_q.pt
    python -m inform_utils.evaluate_maze runs/<run>/tamer_h.pt --env-id FrozenLake-v1 --success-max-steps 100
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

import torch  # noqa: E402
import tyro  # noqa: E402

import inform_dqn_gridworld as maze  # noqa: E402


@dataclass
class Args:
    network: tyro.conf.Positional[str]
    """the saved network: a run's tamer_h.pt or inform_q.pt"""
    env_id: str = "KnoxStoneMaze-v0"
    """the env it was trained on (as the run's --env-id)"""
    seed: int = 1
    """the run's seed (a toy-text task's reset seeds)"""
    success_max_steps: int = 30
    """as the run's --success-max-steps"""
    eval_episodes: int = 20
    """greedy episodes on a toy-text task (the maze's tests are one episode from each start cell)"""


def evaluate_network(args: Args) -> dict:
    """The saved network's greedy policy under the run's final tests (eval/policy_* and the maze's variants)."""
    run_args = maze.Args(**{f.name: getattr(args, f.name) for f in dataclasses.fields(Args) if f.name != "network"})
    maze.check_args(run_args)  # the script's ranges and checks, with its one-line messages
    evaluator = maze.Evaluator(run_args.env_id, run_args.success_max_steps, run_args.eval_episodes, run_args.seed)
    n_states = evaluator.envs["plain"].observation_space.shape[0]
    net = maze.load_q_network(args.network, n_states)
    metrics = evaluator("policy", maze.greedy_actions(net, torch.device("cpu"), n_states), 0)
    evaluator.close()
    return metrics


def main() -> int:
    args = tyro.cli(Args)
    try:
        print(json.dumps(evaluate_network(args), indent=2))
    except maze.InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
