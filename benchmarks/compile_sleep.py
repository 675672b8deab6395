"""Does `torch.compile` make the sleep faster? The default sleep update of inform_sac_pusher.py (the IQ-Learn step on
Q, one actor step on Q, the soft target update), eager against compiled, at steady state.

Both run in this one process on the same synthetic buffer (Pusher's shapes, the script's default sizes and rates):
each is first warmed up (compilation happens there and is timed apart, in CPU and elapsed seconds), then they
alternate in rounds of `--steps-per-round` steps, each round starting with the next variant, so the machine's load
falls on all alike. The ratio of each round's pair is reported,
and its median; the CPU seconds of this process are the clock (`--clock wall` for elapsed time).

The compiled variants wrap the script's own loss functions, `iq_loss` and `actor_loss`, with `torch.compile`
(forward and backward graphs); `compile+optimizer` also compiles the two Adam steps.

    python benchmarks/compile_sleep.py                       # about 5 minutes on one core
    python benchmarks/compile_sleep.py --rounds 2 --steps-per-round 50 --warmup-steps 20   # a smoke run
"""

import importlib.util
import json
import os
import statistics
import time
from dataclasses import dataclass, field

import torch
import tyro

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@dataclass
class Args:
    variants: list[str] = field(default_factory=lambda: ["eager", "compile", "compile+optimizer"])
    """what to time: eager (the script as it is), compile (its iq_loss and actor_loss compiled), compile+optimizer"""
    warmup_steps: int = 300
    """sleep steps before timing starts (compilation, allocator and caches settle here)"""
    rounds: int = 7
    """timed rounds; in each, every variant runs --steps-per-round steps, one after the other"""
    steps_per_round: int = 500
    """sleep steps per variant and round"""
    buffer_size: int = 50_000
    """synthetic transitions (half of them tagged expert)"""
    clock: str = "process"
    """process: CPU seconds of this process (fair on a shared machine, one thread); wall: elapsed seconds"""
    threads: int = 1
    """torch threads (the scripts' default is one)"""
    seed: int = 1
    output: str = ""
    """also write the results as JSON here"""


def load_script():
    spec = importlib.util.spec_from_file_location("inform_sac_pusher", os.path.join(REPO, "inform_sac_pusher.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class Sleep:
    """The default sleep update (inform_sac_pusher.sleep_phase with its default flags) on a synthetic buffer."""

    def __init__(self, script, variant: str, buffer: dict, seed: int):
        a = script.Args()
        torch.manual_seed(seed)
        obs_dim, act_dim = buffer["obs"].shape[1], buffer["actions"].shape[1]
        self.q_net = script.QEnsemble(obs_dim, act_dim, script.HIDDEN_SIZE, n=1)
        self.q_target = script.QEnsemble(obs_dim, act_dim, script.HIDDEN_SIZE, n=1)
        self.q_target.load_state_dict(self.q_net.state_dict())
        self.actor = script.Actor(
            obs_dim, act_dim, script.HIDDEN_SIZE, -2.0 * torch.ones(act_dim), 2.0 * torch.ones(act_dim)
        )
        self.q_optimizer = torch.optim.Adam(self.q_net.parameters(), lr=a.sleep_q_lr, foreach=True)
        self.actor_optimizer = torch.optim.Adam(self.actor.parameters(), lr=a.sleep_policy_lr, foreach=True)
        self.a, self.buffer, self.soft_update = a, buffer, script.soft_update
        self.gamma, self.tau = script.SLEEP_GAMMA, script.TAU  # constants of the script, not flags
        self.iq_loss, self.actor_loss = script.iq_loss, script.actor_loss
        self.q_step, self.actor_step = self.q_optimizer.step, self.actor_optimizer.step
        if variant.startswith("compile"):
            self.iq_loss, self.actor_loss = torch.compile(self.iq_loss), torch.compile(self.actor_loss)
        if variant == "compile+optimizer":
            self.q_step, self.actor_step = torch.compile(self.q_step), torch.compile(self.actor_step)
        n = buffer["obs"].shape[0]
        self.replay_idx = torch.arange(n)
        self.expert_idx = torch.arange(n // 2, n)
        self.is_expert = torch.arange(2 * a.sleep_batch_size) >= a.sleep_batch_size

    def step(self) -> None:
        a, b = self.a, self.buffer
        replay = self.replay_idx[torch.randint(0, self.replay_idx.numel(), (a.sleep_batch_size,))]
        expert = self.expert_idx[torch.randint(0, self.expert_idx.numel(), (a.sleep_batch_size,))]
        idx = torch.cat([replay, expert])
        obs, actions, next_obs, terminated = b["obs"][idx], b["actions"][idx], b["next_obs"][idx], b["terminated"][idx]
        loss, _ = self.iq_loss(
            self.q_net, self.q_target, obs, actions, next_obs, terminated, self.is_expert, self.gamma,
            a.sleep_temperature, a.sleep_chi2_coef, self.actor,
        )  # fmt: skip
        self.q_optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.q_step()
        self.q_net.requires_grad_(False)
        pi_loss, _ = self.actor_loss(self.q_net, self.actor, obs[~self.is_expert], a.sleep_temperature)
        self.actor_optimizer.zero_grad(set_to_none=True)
        pi_loss.backward()
        self.q_net.requires_grad_(True)
        self.actor_step()
        self.soft_update(self.q_target, self.q_net, self.tau)


def main(args: Args) -> dict:
    torch.set_num_threads(args.threads)
    clock = time.process_time if args.clock == "process" else time.perf_counter
    script = load_script()
    g = torch.Generator().manual_seed(args.seed)
    n, obs_dim, act_dim = args.buffer_size, 23, 7  # Pusher's observation and action sizes
    buffer = {
        "obs": torch.randn(n, obs_dim, generator=g),
        "next_obs": torch.randn(n, obs_dim, generator=g),
        "actions": torch.rand(n, act_dim, generator=g) * 4 - 2,
        "terminated": torch.zeros(n),
    }
    sleeps, warmup = {}, {}
    for variant in args.variants:
        sleeps[variant] = Sleep(script, variant, buffer, args.seed)
        start, wall = clock(), time.perf_counter()
        for _ in range(args.warmup_steps):
            sleeps[variant].step()
        warmup[variant] = clock() - start
        warmup[f"{variant}_wall"] = time.perf_counter() - wall  # compilation's worker processes show only here
        print(
            f"{variant}: warm-up {args.warmup_steps} steps in {warmup[variant]:.1f} s "
            f"({warmup[f'{variant}_wall']:.1f} s elapsed)",
            flush=True,
        )
    per_step = {variant: [] for variant in args.variants}
    for r in range(args.rounds):
        k = r % len(args.variants)  # each round starts with the next variant: no one always runs first
        for variant in args.variants[k:] + args.variants[:k]:
            start = clock()
            for _ in range(args.steps_per_round):
                sleeps[variant].step()
            per_step[variant].append((clock() - start) / args.steps_per_round)
        line = " | ".join(f"{v} {1000 * per_step[v][-1]:.2f} ms" for v in args.variants)
        print(f"round {r + 1}/{args.rounds}: {line}", flush=True)
    results = {"clock": args.clock, "threads": args.threads, "torch": torch.__version__}
    print(f"\nms per sleep step (median of {args.rounds} rounds) and speed-up over eager (median of the round pairs):")
    for variant in args.variants:
        ratios = [e / c for e, c in zip(per_step["eager"], per_step[variant], strict=True)]
        ms = 1000 * statistics.median(per_step[variant])
        speedup = statistics.median(ratios)
        results[variant] = {
            "warmup_s": warmup[variant],
            "warmup_wall_s": warmup[f"{variant}_wall"],
            "ms_per_step": ms,
            "speedup": speedup,
            "speedup_min": min(ratios),
            "speedup_max": max(ratios),
        }
        spread = f"{min(ratios):.2f}-{max(ratios):.2f}"
        warm = f"warm-up {warmup[variant]:.0f} s ({warmup[f'{variant}_wall']:.0f} s elapsed)"
        print(f"  {variant:18s} {ms:7.2f} ms  x{speedup:.2f} ({spread})  {warm}")
    if args.output:
        with open(args.output, "w") as f:
            json.dump(results, f, indent=1)
    return results


if __name__ == "__main__":
    main(tyro.cli(Args))
