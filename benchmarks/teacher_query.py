"""The teacher's per-step query on Pusher (Q*(s, a) and Q*(s, a*) by `oracle_q`, then Eq. 4), two teachers side by
side: A B A B over `--rounds`, a ratio per pair, the median reported. The card's day asks once per environment step.

    python benchmarks/teacher_query.py oracles/Pusher-v5__sac_oracle_890k_below_bar.pt oracles/Pusher-v5__sac_oracle.pt
"""

import statistics
import sys
import time
from dataclasses import dataclass

import torch
import tyro

sys.path.insert(0, __file__.rsplit("/benchmarks/", 1)[0])
import inform_sac_pusher as isp  # noqa: E402


@dataclass
class Args:
    before: tyro.conf.Positional[str]
    """the teacher measured first in each pair"""
    after: tyro.conf.Positional[str]
    """the teacher compared with it"""
    env_id: str = "Pusher-v5"
    rounds: int = 10
    queries: int = 2000
    """queries per teacher and round"""


def main(args: Args) -> None:
    torch.set_num_threads(1)
    cpu, generator = torch.device("cpu"), torch.Generator().manual_seed(0)
    teachers = [isp.oracle_from_checkpoint(isp.read_checkpoint(p, "--oracle-path", args.env_id), cpu)
                for p in (args.before, args.after)]  # fmt: skip
    obs_dim, act_dim = teachers[0][0].fc1.in_features, teachers[0][0].fc_mean.out_features
    obs, action = torch.randn(obs_dim, generator=generator), torch.rand(act_dim, generator=generator) * 4 - 2
    ratios = []
    for r in range(args.rounds):
        seconds = [0.0, 0.0]
        for i in (0, 1) if r % 2 == 0 else (1, 0):
            actor, qf = teachers[i]
            t0 = time.perf_counter()
            with torch.no_grad():
                for _ in range(args.queries):
                    isp.oracle_feedback(*isp.oracle_q(actor, qf, obs, action), 0.99)
            seconds[i] = time.perf_counter() - t0
        ratios.append(seconds[1] / seconds[0])
        us = [1e6 * s / args.queries for s in seconds]
        print(f"round {r}: {us[0]:.0f} / {us[1]:.0f} us a query, after / before {ratios[-1]:.3f}", flush=True)
    print(f"after / before: median {statistics.median(ratios):.3f} [{min(ratios):.3f}, {max(ratios):.3f}]")


if __name__ == "__main__":
    main(tyro.cli(Args))
