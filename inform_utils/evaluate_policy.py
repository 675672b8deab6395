"""Re-evaluate a saved policy of a core script under its run's final tests; prints JSON and writes nothing. Like
CleanRL's evaluation helpers, it imports the script's agent and evaluation.

- `pusher`: inform_sac_pusher.py's tamer_actor.pt, inform_actor.pt or an oracle: deterministic and sampled actions
  from the run's start (or random starts), and on Pusher the obstacle test.
- `maze`: inform_dqn_gridworld.py's tamer_h.pt or inform_q.pt, greedily: on the maze the episode length from S, on
  the wall maze and from the start set, and the success rate from every cell; on a toy-text task, greedy episodes from
  fixed reset seeds.

    python -m inform_utils.evaluate_policy pusher runs/<run>/inform_actor.pt
    python -m inform_utils.evaluate_policy pusher oracles/Pusher-v4__sac_oracle.pt --env-id Pusher-v4 --random-starts
    python -m inform_utils.evaluate_policy maze runs/<run>/inform_q.pt
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
import importlib  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from typing import Literal  # noqa: E402

import tyro  # noqa: E402


@dataclass
class Pusher:
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
    contact: Literal["mujoco-2.3", "gymnasium"] = "mujoco-2.3"
    """Pusher's contact, as the run's --contact (runs before the setting: Pusher-v4 mujoco-2.3, Pusher-v5 gymnasium)"""
    num_threads: int = 1
    """torch CPU threads"""
    stream: int = 0
    """another stream of sampled actions from the same starts (0: the stream of --seed, as the run's final tests)"""


@dataclass
class Maze:
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


SUBCOMMANDS = {"pusher": Pusher, "maze": Maze}


def run_args(script, args, path_field: str):
    """The script's own Args with these values, checked by the script's check_args (its ranges, its messages)."""
    values = {f.name: getattr(args, f.name) for f in dataclasses.fields(args) if f.name not in (path_field, "stream")}
    run = script.Args(**values)
    script.check_args(run)
    return run


def evaluate_pusher(args: Pusher) -> dict:
    """The saved policy's eval/policy_* metrics and the obstacle test's, as the run's final evaluation gives them."""
    import torch

    import inform_sac_pusher as isp

    run = run_args(isp, args, "policy")
    torch.manual_seed(run.seed)
    torch.set_num_threads(run.num_threads)
    actor = isp.actor_from_checkpoint(isp.read_checkpoint(args.policy, "policy", run.env_id))
    outcome = run.outcome()
    evaluator = isp.Evaluator(run.env_id, run.seed, run.random_starts, outcome, None, run.contact)
    if args.stream:
        if args.stream < 0:
            raise isp.InputError(f"--stream {args.stream}: must be >= 0 (0: the run's own stream)")
        evaluator.generator.manual_seed(run.seed + 12345 + 1_000_003 * args.stream)
    metrics = evaluator("policy", actor, 0, run.eval_episodes)
    obstacle = {"obstacle/skipped": isp.obstacle_skipped(run.env_id, run.obstacle_episodes)}
    if obstacle["obstacle/skipped"] is None:
        test = (run.env_id, run.seed, run.obstacle_layout, run.obstacle_episodes, outcome)
        obstacle, _, _ = isp.obstacle_test(*test, {"policy": actor}, evaluator.generator, run.contact)
    evaluator.close()
    return {**metrics, **obstacle}


def load_q_network(path: str, n_states: int = 30, flag: str = "the network"):
    """A saved H or Q network of inform_dqn_gridworld.py (tamer_h.pt, inform_q.pt), rebuilt from its arguments, for
    `n_states`-d one-hot observations, with finite weights; the script's InputError otherwise."""
    import torch

    import inform_dqn_gridworld as maze

    ckpt = maze.read_checkpoint(path, flag)
    try:
        net = maze.QNetwork(**ckpt["kwargs"])
        net.load_state_dict(ckpt["state_dict"])
    except (KeyError, TypeError, RuntimeError) as e:
        raise maze.InputError(f"{path}: not a saved network of this script ({str(e).splitlines()[0][:160]})") from None
    if net.kwargs["obs_dim"] != n_states:
        raise maze.InputError(f"{path}: a network for {net.kwargs['obs_dim']}-d observations, not {n_states}-d")
    if not all(torch.isfinite(t).all() for t in net.state_dict().values()):
        raise maze.InputError(f"{path}: its weights hold NaN or inf")
    return net


def evaluate_maze(args: Maze) -> dict:
    """The saved network's greedy policy under the run's final tests (eval/policy_* and the maze's variants)."""
    import torch

    import inform_dqn_gridworld as maze

    run = run_args(maze, args, "network")
    evaluator = maze.Evaluator(run.env_id, run.success_max_steps, run.eval_episodes, run.seed)
    n_states = evaluator.envs["plain"].observation_space.shape[0]
    net = load_q_network(args.network, n_states)
    metrics = evaluator("policy", maze.greedy_actions(net, torch.device("cpu"), n_states), 0)
    evaluator.close()
    return metrics


def main() -> int:
    args = tyro.extras.subcommand_cli_from_dict(SUBCOMMANDS, description=__doc__.split("\n\n")[0])
    script = importlib.import_module("inform_sac_pusher" if isinstance(args, Pusher) else "inform_dqn_gridworld")
    try:
        print(json.dumps(evaluate_pusher(args) if isinstance(args, Pusher) else evaluate_maze(args), indent=2))
    except script.InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
