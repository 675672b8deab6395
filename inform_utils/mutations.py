"""The mutation check: break the learning on purpose, one mutation at a time, in a copy of the code, and see that the
default test suite notices. Each mutation replaces one exact piece of source (it must occur exactly once, so a
refactor that moves it makes the mutation fail loudly rather than pass silently) and names the tests that should
catch it; a mutation is caught when those tests fail on the mutated copy.

    python -m inform_utils.mutations            # every mutation: caught / missed, exit 1 if any is missed
    python -m inform_utils.mutations --only pusher_tamer_h_lr0 maze_v_from_target
    python -m inform_utils.mutations --list

First the named tests run on an unmutated copy (a test that fails anyway would "catch" every mutation): if any fails
there, nothing else runs (exit 2). Run before a release (docs/mutations.md: the command, the last output, the time).
The copy holds the files git tracks and the new files it does not ignore, as they are in the working tree, so the
repository itself is never touched.
"""

import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field

import tyro

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@dataclass(frozen=True)
class Mutation:
    name: str
    file: str
    old: str
    new: str
    tests: tuple[str, ...]  # pytest node ids or files, relative to the repository, run with -m "not slow"
    what: str


PUSHER, MAZE, TABULAR = "inform_sac_pusher.py", "inform_dqn_gridworld.py", "q_learning_recovered_reward.py"
LEARNING = "tests/test_learning.py"
PUSHER_EQ2 = f"{LEARNING}::test_pusher_iq_loss_eq2_with_a_target_unlike_the_critic"
MAZE_EQ2 = "tests/test_inform_gridworld.py::test_iq_loss_eq2_by_hand"
MAZE_EQ2_GRADIENT = "tests/test_inform_gridworld.py::test_iq_loss_uses_target_network_on_next_state_without_gradient"
MAZE_OPTIMUM, MAZE_LOSSES = f"{LEARNING}::test_maze_short_run_reaches_the_optimum", f"{LEARNING}::test_maze_losses_fall"
TABULAR_LEARNS = "tests/test_q_learning_recovered_reward.py::test_each_bootstrap_learns_a_known_good_reward"
STUDY, METHODS_TESTS = "inform_utils/sleep_variants_pusher.py", "tests/test_sleep_methods.py"
DWBC_LEARNS = f"{METHODS_TESTS}::test_dwbc_finds_the_success_sets_action_where_failures_share_its_states"
PU_TD3BC_LEARNS = f"{METHODS_TESTS}::test_pu_td3bc_learns_its_reward_first_then_acts_on_where_an_action_leads"
# iq_loss's last line is the same in both scripts: its value kept, its gradient zero (no error at backward())
IQ_TOTAL = "return sum(terms.values()), terms  # the total and its named terms: the sleep logs whatever terms come back"
NO_GRADIENT = "return sum(terms.values()).detach() + 0.0 * sum(terms.values()), terms  # the same value, no gradient"

MUTATIONS: list[Mutation] = [
    # the Pusher's day
    Mutation("pusher_tamer_h_lr0", PUSHER,
             "h_optimizer = torch.optim.Adam(h_net.parameters(), lr=args.tamer_h_lr, foreach=True)",
             "h_optimizer = torch.optim.Adam(h_net.parameters(), lr=0.0, foreach=True)",
             (f"{LEARNING}::test_pusher_tamer_h_loss_falls",
              f"{LEARNING}::test_pusher_tamer_actor_moves_towards_the_positive_actions"),
             "TAMER's H optimiser at lr 0"),
    Mutation("pusher_tamer_actor_lr0", PUSHER,
             "actor_optimizer = torch.optim.Adam(tamer_actor.parameters(), lr=TAMER_POLICY_LR, foreach=True)",
             "actor_optimizer = torch.optim.Adam(tamer_actor.parameters(), lr=0.0, foreach=True)",
             (f"{LEARNING}::test_pusher_tamer_actor_moves_towards_the_positive_actions",),
             "TAMER's actor optimiser at lr 0 (H learns, the actor stays as it was initialised)"),
    Mutation("pusher_alpha_schedule_frozen", PUSHER,
             "feedback_alpha = linear_schedule(args.feedback_alpha_start, args.feedback_alpha_end, n - 1, step)",
             "feedback_alpha = args.feedback_alpha_start",
             (f"{LEARNING}::test_pusher_teachers_alpha_rises_from_start_to_end",),
             "the teacher's alpha stays at --feedback-alpha-start all day"),
    # the Pusher's night
    Mutation("pusher_inform_actor_lr0", PUSHER,
             "inform_optimizer = torch.optim.Adam(inform_actor.parameters(), lr=args.sleep_policy_lr, foreach=True)",
             "inform_optimizer = torch.optim.Adam(inform_actor.parameters(), lr=0.0, foreach=True)",
             (f"{LEARNING}::test_pusher_inform_actor_ends_away_from_tamers_and_up_the_critic",),
             "INFORM's actor optimiser at lr 0 (INFORM stays TAMER's actor)"),
    Mutation("pusher_night_critic_lr0", PUSHER,
             "q_optimizer = torch.optim.Adam(q_net.parameters(), lr=args.sleep_q_lr, foreach=True)",
             "q_optimizer = torch.optim.Adam(q_net.parameters(), lr=0.0, foreach=True)",
             (f"{LEARNING}::test_pusher_night_critic_loss_falls",),
             "the night's critic optimiser at lr 0"),
    Mutation("pusher_iq_loss_no_gradient", PUSHER, IQ_TOTAL, NO_GRADIENT,
             (f"{LEARNING}::test_pusher_night_critic_loss_falls",),
             "iq_loss keeps its value but has no gradient"),
    Mutation("pusher_v_from_target", PUSHER,
             "v_s = soft_value(q_net, actor, obs, temperature)",
             "v_s = soft_value(target_net, actor, obs, temperature)",
             (PUSHER_EQ2,),
             "V(s) from the target critic instead of the online one"),
    Mutation("pusher_y_from_online", PUSHER,
             "y = (1.0 - terminated) * gamma * soft_value(target_net, actor, next_obs, temperature)",
             "y = (1.0 - terminated) * gamma * soft_value(q_net, actor, next_obs, temperature)",
             (PUSHER_EQ2,),
             "y(s') from the online critic instead of the target"),
    Mutation("pusher_terminated_ignored", PUSHER,
             "y = (1.0 - terminated) * gamma * soft_value(target_net, actor, next_obs, temperature)",
             "y = gamma * soft_value(target_net, actor, next_obs, temperature)",
             (PUSHER_EQ2,),
             "y(s') bootstraps past a terminal transition (Pusher never terminates: only Eq. 2's test can tell)"),
    # the maze's day
    Mutation("maze_tamer_lr0", MAZE,
             "h_optimizer = torch.optim.Adam(h_net.parameters(), lr=args.tamer_h_lr, fused=True)",
             "h_optimizer = torch.optim.Adam(h_net.parameters(), lr=0.0, fused=True)",
             (MAZE_OPTIMUM, MAZE_LOSSES),
             "TAMER's H optimiser at lr 0"),
    Mutation("maze_alpha_schedule_frozen", MAZE,
             "feedback_alpha = linear_schedule(args.feedback_alpha_start, args.feedback_alpha_end, n - 1, step)",
             "feedback_alpha = args.feedback_alpha_start",
             (f"{LEARNING}::test_maze_teachers_alpha_moves_from_start_to_end",),
             "the teacher's alpha stays at --feedback-alpha-start all day"),
    # the maze's night
    Mutation("maze_night_q_lr0", MAZE,
             "self.optimizer = torch.optim.Adam(self.q_net.parameters(), lr=lr, fused=True)",
             "self.optimizer = torch.optim.Adam(self.q_net.parameters(), lr=0.0, fused=True)",
             (MAZE_OPTIMUM, MAZE_LOSSES),
             "the night's Q optimiser at lr 0"),
    Mutation("maze_iq_loss_no_gradient", MAZE, IQ_TOTAL, NO_GRADIENT,
             (MAZE_OPTIMUM, MAZE_LOSSES, MAZE_EQ2_GRADIENT),
             "iq_loss keeps its value but has no gradient"),
    Mutation("maze_expert_rows_from_all_replay", MAZE,
             "expert = expert_idx[torch.randint(0, expert_idx.numel(), (batch_size,), device=device)]",
             "expert = torch.randint(0, buffer.size, (batch_size,), device=device)",
             (f"{LEARNING}::test_maze_expert_rows_come_from_the_success_set",),
             "the night's expert rows drawn from all of the replay, not the success set"),
    Mutation("maze_v_from_target", MAZE,
             "v_s = soft_value(q, temperature)",
             "v_s = soft_value(target_net(obs), temperature)",
             (MAZE_EQ2, MAZE_EQ2_GRADIENT),
             "V(s) from the target network instead of the online one"),
    Mutation("maze_y_from_online", MAZE,
             "y = (1.0 - terminated) * gamma * soft_value(target_net(next_obs), temperature)",
             "y = (1.0 - terminated) * gamma * soft_value(q_net(next_obs), temperature)",
             (MAZE_EQ2, MAZE_EQ2_GRADIENT),
             "y(s') from the online network instead of the target (the maze's TAU of 1 hides it from learning)"),
    Mutation("maze_terminated_ignored", MAZE,
             "y = (1.0 - terminated) * gamma * soft_value(target_net(next_obs), temperature)",
             "y = gamma * soft_value(target_net(next_obs), temperature)",
             (MAZE_EQ2,),
             "y(s') bootstraps past G"),
    # the nights of other methods (the sleep study's): each mechanism removed on a day whose failures share the
    # success set's states
    Mutation("dwbc_without_weights", STUDY,
             'dwbc_policy_loss(nll[expert], nll[other], d[expert], d[other], DWBC["alpha"], DWBC["eta"])',
             "torch.cat([nll[expert], nll[other]]).mean()",
             (DWBC_LEARNS,),
             "DWBC's policy loss without d's weights: plain cloning of every row"),
    Mutation("dwbc_d_fixed", STUDY,
             'return d.clamp(*DWBC["d_range"])',
             "return d * 0.0 + 0.5",
             (DWBC_LEARNS,),
             "DWBC's discriminator output fixed at 0.5 (its weights then 4.5 on the success set, 1 on the rest)"),
    Mutation("pu_td3bc_plain_cross_entropy", STUDY,
             'loss = nn_pu_loss(reward(obs[p]).squeeze(-1), reward(obs[u]).squeeze(-1), eta)',
             "loss = F.softplus(-reward(obs[p])).mean() + F.softplus(reward(obs[u])).mean()",
             (PU_TD3BC_LEARNS,),
             "the reward's stage by plain cross-entropy: the day's success rows counted as negatives, not PU"),
    Mutation("pu_td3bc_critic_weight0", STUDY,
             'td3bc_actor_loss(self.critic(z, pi)[0], pi, actions, TD3BC["alpha"])',
             "td3bc_actor_loss(self.critic(z, pi)[0], pi, actions, 0.0)",
             (PU_TD3BC_LEARNS,),
             "TD3+BC's critic weight (alpha) at 0: plain cloning of the batch's actions"),
    # the tabular agents on the recovered reward
    Mutation("tabular_alpha0", TABULAR,
             "q[s, a] += args.alpha * (target - q[s, a])",
             "q[s, a] += 0.0 * (target - q[s, a])",
             (TABULAR_LEARNS,),
             "tabular Q-learning at alpha 0"),
    Mutation("tabular_recovered_reward_ignored", TABULAR,
             'r = reward["table"][s, a]',
             "r = env_reward",
             (TABULAR_LEARNS,),
             "the recovered reward ignored: the tabular agent learns from the env's reward"),
]  # fmt: skip


@dataclass
class Args:
    only: list[str] = field(default_factory=list)
    """the mutations to try (names; default: all)"""
    list: bool = False
    """list the mutations and exit"""
    timeout: float = 900
    """seconds a mutation's tests may take (a mutation that makes them hang counts as caught)"""


def copy_repo(dest: str) -> None:
    """The files git tracks, and the new ones it would (not ignored), as they are in the working tree."""
    listing = ["git", "-C", REPO, "ls-files", "-z", "--cached", "--others", "--exclude-standard"]
    files = subprocess.run(listing, capture_output=True, text=True, check=True).stdout.split("\0")
    for name in filter(None, files):
        src = os.path.join(REPO, name)
        if os.path.isfile(src):
            os.makedirs(os.path.dirname(os.path.join(dest, name)) or dest, exist_ok=True)
            shutil.copy2(src, os.path.join(dest, name))


def apply(root: str, m: Mutation) -> None:
    path = os.path.join(root, m.file)
    with open(path) as f:
        source = f.read()
    count = source.count(m.old)
    if count != 1:
        raise SystemExit(f"error: mutation {m.name}: its piece of {m.file} occurs {count} times, not once; update it")
    with open(path, "w") as f:
        f.write(source.replace(m.old, m.new))


def run_tests(root: str, tests, timeout: float) -> tuple[int | None, str, list[str]]:
    """pytest on `tests` in the copy at `root` (-m "not slow", one thread): its exit code (None: timed out), its last
    line, and the node ids that failed or errored."""
    cmd = [sys.executable, "-m", "pytest", "-q", "-rfE", "-m", "not slow", "-p", "no:cacheprovider", *tests]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": root}
    try:
        proc = subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None, f"timed out after {timeout:.0f}s", []
    lines = proc.stdout.strip().splitlines() or [""]
    failed = [line.split(" ", 1)[1].split(" - ")[0] for line in lines if line.startswith(("FAILED ", "ERROR "))]
    return proc.returncode, lines[-1] if proc.returncode in (0, 1) else (proc.stdout + proc.stderr)[-800:], failed


def try_mutation(m: Mutation, timeout: float) -> tuple[str, float, str]:
    with tempfile.TemporaryDirectory(prefix=f"mutation_{m.name}_") as root:
        copy_repo(root)
        apply(root, m)
        start = time.time()
        code, last, failed = run_tests(root, m.tests, timeout)
        seconds = time.time() - start
        if code is None:
            return "caught (timeout)", seconds, last
        if code == 0:
            return "missed", seconds, last
        if code == 1:  # tests failed
            return "caught", seconds, f"{last}: {', '.join(name.split('::')[-1] for name in failed)}"
        return f"error (pytest exit {code})", seconds, last


def baseline(chosen: list[Mutation], timeout: float) -> tuple[bool, float, str]:
    """The named tests on an unmutated copy: they must pass, or a mutation's "caught" means nothing."""
    tests = list(dict.fromkeys(test for m in chosen for test in m.tests))
    with tempfile.TemporaryDirectory(prefix="mutation_baseline_") as root:
        copy_repo(root)
        start = time.time()
        code, last, failed = run_tests(root, tests, timeout)
    return code == 0, time.time() - start, f"{last} {' '.join(failed)}".strip()


def main(args: Args) -> int:
    chosen = [m for m in MUTATIONS if not args.only or m.name in args.only]
    unknown = set(args.only) - {m.name for m in MUTATIONS}
    if unknown:
        print(f"error: no mutation named {', '.join(sorted(unknown))}", file=sys.stderr)
        return 2
    if args.list:
        for m in chosen:
            print(f"{m.name}: {m.what} ({m.file}; tests: {' '.join(m.tests)})")
        return 0
    ok, seconds, detail = baseline(chosen, args.timeout)
    print(f"baseline (no mutation): {'passed' if ok else 'FAILED'} in {seconds:.0f}s | {detail}", flush=True)
    if not ok:
        print("error: the named tests fail on the unmutated code; fix that first", file=sys.stderr)
        return 2
    missed = 0
    for m in chosen:
        outcome, seconds, detail = try_mutation(m, args.timeout)
        missed += outcome != "caught" and not outcome.startswith("caught")
        print(f"{m.name}: {outcome} in {seconds:.0f}s | {m.what} | {detail}", flush=True)
    print(f"{len(chosen) - missed} of {len(chosen)} mutations caught")
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main(tyro.cli(Args)))
