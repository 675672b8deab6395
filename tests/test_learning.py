"""Tests that fail when learning breaks (issue 39): a learner at lr 0, a loss without gradient, the expert rows drawn
from the wrong set, or the teacher's schedule frozen each fail one of these, in the default suite. inform_utils/
mutations.py breaks the code on purpose, one way at a time, and checks that the tests it names here fail
(docs/mutations.md).

Each script runs in process on a tiny budget, with its own pieces (tamer_loss, update_actor, iq_loss, the night, the
teacher's Eq. 4) wrapped to record what they were given: the networks at their initialisation and at the end, every
loss, every alpha. The wrappers only read: the Pusher run with them gives the summary of a plain run of its flags,
number for number (checked by hand; it costs a second run, so it is not a test). Fixed seeds: the same
code gives the same numbers, so each threshold below sits between the value measured on the working code and the
value measured with the learning broken (both noted beside it), with a margin on either side.
"""

import contextlib
import copy
import io
import os
import signal
import sys
from types import SimpleNamespace

import numpy as np
import pytest
import torch
import tyro

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

import gridworld_env as g  # noqa: E402
import inform_dqn_gridworld as maze  # noqa: E402
import inform_sac_pusher as isp  # noqa: E402

# the teacher these tests' numbers were measured with (the default one until 2026-12-04)
TEACHER = os.path.join(REPO, "oracles", "Pusher-v5__sac_oracle_890k_below_bar.pt")


@contextlib.contextmanager
def in_process(monkeypatch_context, cwd):
    """A run of a script's main in this process: in `cwd`, its signal handlers (StopSignals) undone afterwards."""
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    monkeypatch_context.chdir(cwd)
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # the progress lines
            yield
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)


def first_and_last(values, first: int, last: int) -> tuple[float, float]:
    values = np.asarray(values)
    return float(values[:first].mean()), float(values[-last:].mean())


# ---------------------------------------------------------------------------------------------------------------------
# Pusher: one tiny day and night (seed 3: 800 env steps, 600 of them TAMER updates, then 100 sleep steps), ~10 s of CPU.
# The teacher is more lenient than the paper's (alpha 0.96 -> 0.98, not 0.99 -> 0.992), so that a third of the
# steps are labelled +1 rather than 2%: at this budget the paper's teacher labels too few for TAMER's actor to show
# what it learned. Every episode counts as a success (--success-distance 1), so the night has an expert set.
PUSHER_RUN = [
    "--seed", "3",
    "--tamer-total-timesteps", "800",
    "--tamer-learning-starts", "200",
    "--tamer-batch-size", "64",
    "--feedback-alpha-start", "0.96",
    "--feedback-alpha-end", "0.98",
    "--success-distance", "1.0",
    "--sleep-gradient-steps", "100",
    "--sleep-batch-size", "64",
    "--eval-episodes", "1",
    "--obstacle-episodes", "0",
    "--authors-test-episodes", "0",
    "--oracle-path", TEACHER,
    "--contact", "gymnasium",  # the teacher's (MuJoCo 4's own)
]  # fmt: skip


def mean_action(actor: isp.Actor, obs: torch.Tensor) -> torch.Tensor:
    with torch.no_grad():
        return actor(obs)[0].tanh() * actor.action_scale + actor.action_bias


@pytest.fixture(scope="module")
def pusher(tmp_path_factory):
    """The tiny Pusher run, recorded: H and the TAMER actor at their initialisation, the night's critic at its
    initialisation, every H loss and IQ loss of the training steps, the teacher's alpha at every step, the buffer, and
    the networks at the end."""
    if not os.path.isfile(TEACHER):
        pytest.skip("the teacher of these tests is missing")
    rec = SimpleNamespace(h_losses=[], iq_losses=[], alphas=[], h_init=None, actor_init=None, q_init=None)
    real = SimpleNamespace(tamer_loss=isp.tamer_loss, update_actor=isp.update_actor, iq_loss=isp.iq_loss,
                           oracle_feedback=isp.oracle_feedback, sleep_phase=isp.sleep_phase)  # fmt: skip

    def tamer_loss(h_net, obs, actions, feedback):
        if rec.h_init is None:  # the first call comes before H's first step
            rec.h_init = copy.deepcopy(h_net)
        loss = real.tamer_loss(h_net, obs, actions, feedback)
        rec.h_losses.append(loss.item())
        return loss

    def update_actor(h_net, actor, *rest):
        if rec.actor_init is None:  # before the actor's first step
            rec.actor_init = copy.deepcopy(actor)
        rec.h_net = h_net
        return real.update_actor(h_net, actor, *rest)

    def iq_loss(q_net, target_net, *rest, **kwargs):  # keywords pass through, as a hack's new term would
        if rec.q_init is None:  # before the critic's first step
            rec.q_init = copy.deepcopy(q_net)
        rec.q_net, rec.q_target = q_net, target_net
        loss, terms = real.iq_loss(q_net, target_net, *rest, **kwargs)
        rec.iq_losses.append(loss.item())
        return loss, terms

    def oracle_feedback(q_star_sa, q_star_best, alpha):
        rec.alphas.append(alpha)
        return real.oracle_feedback(q_star_sa, q_star_best, alpha)

    class Night(isp.Night):
        def __init__(self, tamer_actor, *rest, **settings):
            rec.tamer_actor = tamer_actor
            super().__init__(tamer_actor, *rest, **settings)

    def sleep_phase(night, buffer, *rest, **kwargs):
        rec.buffer, rec.inform_actor = buffer, night.actor
        return real.sleep_phase(night, buffer, *rest, **kwargs)

    args = tyro.cli(isp.Args, args=PUSHER_RUN)
    rec.args = args
    with pytest.MonkeyPatch.context() as mp, in_process(mp, tmp_path_factory.mktemp("pusher")):
        for wrapper in (tamer_loss, update_actor, iq_loss, oracle_feedback, sleep_phase, Night):
            mp.setattr(isp, wrapper.__name__, wrapper)
        mp.setattr(isp, "PERIODIC_EVAL_EPISODES", 1)  # evaluation draws from its own generator: no number moves
        rec.summary = isp.main(
            args,
            isp.load_oracle(
                args.env_id, args.contact, args.oracle_path, args.train_oracle, args.oracle_total_timesteps
            ),
            isp.StopSignals(),
        )
    assert rec.summary["status"] == "completed", rec.summary.get("error")
    n = rec.buffer.size
    rec.obs, rec.actions, rec.feedback = rec.buffer.obs[:n], rec.buffer.actions[:n], rec.buffer.feedback[:n]
    return rec


def test_pusher_tamer_h_loss_falls(pusher):
    """Eq. 1's loss falls over the day: on its training batches, and on every labelled transition of the day (H at
    the end against H at its initialisation). Measured: the batches 0.425 (first 20 steps) -> 0.038 (last 50), a
    ratio of 0.09; the whole day 0.670 -> 0.029, a ratio of 0.04. H at lr 0: the batches 0.926 -> 0.636 (0.69), the
    whole day unchanged (1)."""
    assert len(pusher.h_losses) == 600  # one H step per env step after the 200 random ones
    first, last = first_and_last(pusher.h_losses, 20, 50)
    assert last < 0.3 * first, (first, last)
    with torch.no_grad():
        before = isp.tamer_loss(pusher.h_init, pusher.obs, pusher.actions, pusher.feedback).item()
        after = isp.tamer_loss(pusher.h_net, pusher.obs, pusher.actions, pusher.feedback).item()
    assert after < 0.2 * before, (before, after)


def test_pusher_tamer_actor_moves_towards_the_positive_actions(pusher):
    """At the day's states, the TAMER actor's mean action ends nearer the actions the teacher labelled +1, and not
    nearer the others: the contrast (how much nearer the +1 actions got, minus how much nearer the rest got) is what
    H taught. Whatever H says, the actor also drifts towards the middle of the action box (the entropy term through
    the tanh), where the +1 actions lie on average: hence the contrast, not the +1 distance alone. Measured (35% of
    the day labelled +1): the +1 actions 0.197 nearer, the others 0.097 farther, contrast 0.294. H at lr 0: 0.056
    nearer, contrast 0.047; the actor at lr 0: 0 and 0. (Seeds 1 and 2 of the same run: contrast 0.26 and 0.18
    working, 0.10 and -0.03 with H at lr 0.)"""
    positive = pusher.feedback > 0
    assert 0.1 < positive.float().mean() < 0.9  # both kinds of label to compare
    distance = {}
    for when, actor in (("init", pusher.actor_init), ("end", pusher.tamer_actor)):
        gap = (mean_action(actor, pusher.obs) - pusher.actions).norm(dim=1)
        distance[when] = (gap[positive].mean().item(), gap[~positive].mean().item())
    nearer_positive = distance["init"][0] - distance["end"][0]
    nearer_other = distance["init"][1] - distance["end"][1]
    assert nearer_positive - nearer_other > 0.15, distance
    assert nearer_positive > 0.1, distance


def test_pusher_teachers_alpha_rises_from_start_to_end(pusher):
    """Eq. 4's alpha goes linearly from --feedback-alpha-start at the first step to --feedback-alpha-end at the last
    (the teacher gets stricter), one value per env step."""
    alphas = np.array(pusher.alphas)
    n = pusher.args.tamer_total_timesteps
    assert alphas.shape == (n,)
    assert alphas[0] == pytest.approx(0.96, abs=1e-12) and alphas[-1] == pytest.approx(0.98, abs=1e-12)
    assert np.allclose(alphas, 0.96 + 0.02 * np.arange(n) / (n - 1), rtol=0, atol=1e-12)


def pusher_iq_loss_on_the_day(pusher, q_net) -> float:
    """Eq. 2 of `q_net` on every transition of the day (the replay rows) and every success transition (the expert
    rows), with the night's final target critic and INFORM actor, V(s) sampled from a fixed seed."""
    buffer, n = pusher.buffer, pusher.buffer.size
    success = buffer.success[:n]
    rows = lambda x: torch.cat([x[:n], x[:n][success]])  # noqa: E731
    is_expert = torch.arange(n + int(success.sum())) >= n
    a = pusher.args
    with torch.random.fork_rng(), torch.no_grad():
        torch.manual_seed(0)
        loss, _ = isp.iq_loss(q_net, pusher.q_target, rows(buffer.obs), rows(buffer.actions), rows(buffer.next_obs),
                              rows(buffer.terminated), is_expert, isp.SLEEP_GAMMA, a.sleep_temperature,
                              a.sleep_chi2_coef, pusher.inform_actor)  # fmt: skip
    return loss.item()


def test_pusher_night_critic_loss_falls(pusher):
    """The IQ critic's loss (Eq. 2) falls over the night: on its training batches, and on the whole day (the critic
    at the end against the critic at its initialisation, with the same target, actor and samples). Measured: the
    batches 0.094 (first 10 steps) -> 0.053 (last 10), the whole day 0.110 -> 0.032. The critic at lr 0, or iq_loss
    without gradient: the batches 0.103 -> 0.110, the whole day unchanged."""
    assert len(pusher.iq_losses) == 100
    first, last = first_and_last(pusher.iq_losses, 10, 10)
    assert first - last > 0.015, (first, last)
    before, after = pusher_iq_loss_on_the_day(pusher, pusher.q_init), pusher_iq_loss_on_the_day(pusher, pusher.q_net)
    assert before - after > 0.03, (before, after)


def test_pusher_inform_actor_ends_away_from_tamers_and_up_the_critic(pusher):
    """The night starts INFORM's actor from TAMER's; it must end elsewhere, and where the night's critic rates it
    higher. Measured at the day's states (mean actions, the final critic): mean |a_inform - a_tamer| = 0.21 and
    Q(s, a_inform) - Q(s, a_tamer) = 0.020 (0.14-0.19 and 0.0014-0.017 on the other days tried: seeds 1 and 2, and
    this day with TAMER's H or actor at lr 0). INFORM's actor at lr 0: both exactly 0."""
    inform_actions = mean_action(pusher.inform_actor, pusher.obs)
    tamer_actions = mean_action(pusher.tamer_actor, pusher.obs)
    assert (inform_actions - tamer_actions).norm(dim=1).mean().item() > 0.02
    with torch.no_grad():
        gain = (pusher.q_net(pusher.obs, inform_actions) - pusher.q_net(pusher.obs, tamer_actions)).mean().item()
    assert gain > 0.001, gain


class LinearQ(torch.nn.Module):
    """Q(s, a) = w_s s[0] + w_a a[0] + b, shaped [1, B] like a one-member QEnsemble."""

    def __init__(self, w_s: float, w_a: float, b: float):
        super().__init__()
        self.w = torch.nn.Parameter(torch.tensor([w_s, w_a, b]))

    def forward(self, obs, act):
        return (self.w[0] * obs[:, 0] + self.w[1] * act[:, 0] + self.w[2]).unsqueeze(0)


class FixedActor:
    """Always samples action 0.5 with log pi = -1."""

    def get_action(self, obs, generator=None):
        half = torch.full((obs.shape[0], 1), 0.5)
        return half, -torch.ones(obs.shape[0]), half


def test_pusher_iq_loss_eq2_with_a_target_unlike_the_critic():
    """Eq. 2 by hand, the target critic unlike the online one: y(s') from the target on s', V(s) from the online
    critic on s, nothing after a terminal transition."""
    q_net, target = LinearQ(1.0, 2.0, 0.0), LinearQ(-0.5, 1.0, 3.0)
    obs = torch.tensor([[1.0], [2.0], [3.0], [4.0]])
    act = torch.tensor([[0.5], [0.0], [1.0], [-1.0]])
    next_obs = torch.tensor([[2.0], [3.0], [4.0], [5.0]])
    terminated = torch.tensor([0.0, 1.0, 0.0, 0.0])
    is_expert = torch.tensor([False, False, True, True])
    gamma, temp, chi2 = 0.9, 0.1, 0.5
    loss, terms = isp.iq_loss(q_net, target, obs, act, next_obs, terminated, is_expert, gamma, temp, chi2, FixedActor())
    # V(x) = Q(x, 0.5) - temp * log pi = Q(x, 0.5) + 0.1
    v_target = lambda s: -0.5 * s + 1.0 * 0.5 + 3.0 + temp  # noqa: E731
    v_online = lambda s: 1.0 * s + 2.0 * 0.5 + temp  # noqa: E731
    y = [(1 - d) * gamma * v_target(s) for s, d in zip([2.0, 3.0, 4.0, 5.0], [0, 1, 0, 0], strict=True)]
    q_sa = [1.0 * s + 2.0 * a for s, a in zip([1.0, 2.0, 3.0, 4.0], [0.5, 0.0, 1.0, -1.0], strict=True)]
    td = [q - t for q, t in zip(q_sa, y, strict=True)]
    expert = -(td[2] + td[3]) / 2
    value = sum(v_online(s) - t for s, t in zip([1.0, 2.0, 3.0, 4.0], y, strict=True)) / 4
    chi2_term = chi2 * sum(x * x for x in td) / 4
    assert terms["iq_expert_term"].item() == pytest.approx(expert, abs=1e-5)
    assert terms["iq_value_term"].item() == pytest.approx(value, abs=1e-5)
    assert terms["iq_chi2_term"].item() == pytest.approx(chi2_term, abs=1e-5)
    assert loss.item() == pytest.approx(expert + value + chi2_term, abs=1e-5)
    loss.backward()
    assert target.w.grad is None  # y(s') is a constant of the step
    assert q_net.w.grad is not None and q_net.w.grad.abs().sum() > 0


# ---------------------------------------------------------------------------------------------------------------------
# The maze: a short run (seed 1: 2,000 env steps, 300 sleep steps, ~2.5 s of CPU) reaches the 19-step optimum from S.
# The cheapest budget that does it on seed 1: 1,500 env steps (1,400: no episode reaches G in time, so no night) and
# on that day 100 sleep steps (75 do not); on the 2,000-step day below, 150 sleep steps (100 do not). The run below has
# a third more env steps than the cheapest and twice the sleep steps its day needs; TAMER is at 19 from env step 1,500.
# Seeds 2-5 reach 19 at this budget too.
MAZE_RUN = dict(seed=1, tamer_total_timesteps=2000, tamer_learning_starts=500, sleep_gradient_steps=300)


@pytest.fixture(scope="module")
def maze_run(tmp_path_factory):
    """The short maze run, recorded: H at its initialisation, every IQ loss, the night's Q at its initialisation,
    every sleep batch (its buffer indices and its expert mask), the expert set and the buffer."""
    rec = SimpleNamespace(iq_losses=[], batches=[], h_init=None, q_init=None)
    real = SimpleNamespace(tamer_loss=maze.tamer_loss, iq_loss=maze.iq_loss, sleep_phase=maze.sleep_phase)

    def tamer_loss(h_net, obs, actions, feedback):
        if rec.h_init is None:
            rec.h_init = copy.deepcopy(h_net)
        rec.h_net = h_net
        return real.tamer_loss(h_net, obs, actions, feedback)

    def iq_loss(q_net, *rest, **kwargs):
        if rec.q_init is None:
            rec.q_init = copy.deepcopy(q_net)
        loss, terms = real.iq_loss(q_net, *rest, **kwargs)
        rec.iq_losses.append(loss.item())
        return loss, terms

    def sleep_phase(learner, buffer, expert_idx, *rest):
        rec.buffer, rec.expert_idx, rec.learner = buffer, expert_idx.clone(), learner
        batch, update = buffer.batch, learner.update
        drawn = []

        def recording_batch(idx):
            drawn.append(idx.clone())
            return batch(idx)

        def recording_update(b, is_expert):
            rec.batches.append((drawn.pop(), is_expert.clone()))
            return update(b, is_expert)

        buffer.batch, learner.update = recording_batch, recording_update
        try:
            return real.sleep_phase(learner, buffer, expert_idx, *rest)
        finally:
            del buffer.batch, learner.update

    args = maze.Args(**MAZE_RUN)
    maze.check_args(args)
    with pytest.MonkeyPatch.context() as mp, in_process(mp, tmp_path_factory.mktemp("maze")):
        for wrapper in (tamer_loss, iq_loss, sleep_phase):
            mp.setattr(maze, wrapper.__name__, wrapper)
        rec.summary = maze.main(args, None, maze.StopSignals())
    assert rec.summary["status"] == "completed", rec.summary.get("error")
    assert not rec.summary["sleep_skipped"], "no episode of the day reached G in time: there was no night"
    return rec


def test_maze_short_run_reaches_the_optimum(maze_run):
    """The paper's Fig. 3 claim, in the fast suite: TAMER's and INFORM's greedy paths from S are the 19-step
    optimum. Broken learning gives 200 (a loop, the step limit): TAMER's or the night's Q at lr 0, iq_loss without
    gradient."""
    summary = maze_run.summary
    assert summary["eval/oracle_episode_length"] == 19
    assert summary["eval/tamer_episode_length"] == 19
    assert summary["eval/inform_episode_length"] == 19
    policy = maze.greedy_actions(maze_run.learner.q_net, torch.device("cpu"))  # the network the night trained
    assert g.greedy_episode_length(policy, "plain") == 19


def maze_iq_loss_on_the_day(maze_run, q_net) -> float:
    """Eq. 2 of `q_net` on every transition of the day (the replay rows) and every success transition (the expert
    rows), with the night's final target network."""
    buffer, n, learner = maze_run.buffer, maze_run.buffer.size, maze_run.learner
    success = buffer.success[:n]
    rows = lambda x: torch.cat([x[:n], x[:n][success]])  # noqa: E731
    is_expert = torch.arange(n + int(success.sum())) >= n
    with torch.no_grad():
        loss, _ = maze.iq_loss(q_net, learner.q_target, rows(buffer.obs), rows(buffer.actions), rows(buffer.next_obs),
                               rows(buffer.terminated), is_expert, learner.gamma, learner.temperature,
                               learner.chi2_coef)  # fmt: skip
    return loss.item()


def test_maze_losses_fall(maze_run):
    """Eq. 1 over the day and Eq. 2 over the night, each on the whole day: the network at the end against the same
    network at its initialisation (Eq. 2 with the night's final target). Measured: H 0.424 -> 0.00004; IQ 1.654 ->
    0.113 (on the training batches 0.187 -> 0.121, first and last 10 steps). TAMER at lr 0: no episode of the day
    reaches G in time, so there is no night (the fixture fails); the night's Q at lr 0, or iq_loss without gradient:
    the whole day's IQ loss unchanged (0.189)."""
    buffer, n = maze_run.buffer, maze_run.buffer.size
    with torch.no_grad():
        before = maze.tamer_loss(maze_run.h_init, buffer.obs[:n], buffer.actions[:n], buffer.feedback[:n]).item()
        after = maze.tamer_loss(maze_run.h_net, buffer.obs[:n], buffer.actions[:n], buffer.feedback[:n]).item()
    assert after < 0.2 * before, (before, after)
    assert len(maze_run.iq_losses) == MAZE_RUN["sleep_gradient_steps"]
    before = maze_iq_loss_on_the_day(maze_run, maze_run.q_init)
    after = maze_iq_loss_on_the_day(maze_run, maze_run.learner.q_net)
    assert before - after > 0.5, (before, after)


def test_maze_expert_rows_come_from_the_success_set(maze_run):
    """The night's expert set is the success set (the transitions of the episodes tagged success), and every row the
    loss treats as expert is drawn from it, while the replay rows come from the whole buffer (failures too)."""
    buffer, n = maze_run.buffer, maze_run.buffer.size
    success = buffer.success[:n]
    assert 0 < success.sum() < n  # successes and failures: the test can tell the two apart
    assert torch.equal(maze_run.expert_idx, success.nonzero().squeeze(1))
    assert len(maze_run.batches) == MAZE_RUN["sleep_gradient_steps"]
    expert_rows = torch.cat([idx[is_expert] for idx, is_expert in maze_run.batches])
    replay_rows = torch.cat([idx[~is_expert] for idx, is_expert in maze_run.batches])
    batch_size = maze_run.summary["args"]["sleep_batch_size"]
    assert expert_rows.numel() == replay_rows.numel() == batch_size * MAZE_RUN["sleep_gradient_steps"]
    assert bool(success[expert_rows].all()), "an expert row from outside the success set"
    assert not bool(success[replay_rows].all())  # the replay rows are the whole buffer's
    assert len(set(expert_rows.tolist())) > 0.5 * int(success.sum())  # drawn across the success set, not one episode


def test_maze_teachers_alpha_moves_from_start_to_end(tmp_path):
    """Eq. 4's alpha goes linearly from --feedback-alpha-start to --feedback-alpha-end over the day (the maze's
    defaults are both 0.999, so a run with two alphas)."""
    alphas = []
    real = maze.oracle_feedback

    def oracle_feedback(q_sa, q_best, alpha):
        alphas.append(alpha)
        return real(q_sa, q_best, alpha)

    args = maze.Args(seed=1, tamer_total_timesteps=600, tamer_learning_starts=100, sleep_gradient_steps=10,
                     feedback_alpha_start=0.9, feedback_alpha_end=0.999)  # fmt: skip
    maze.check_args(args)
    with pytest.MonkeyPatch.context() as mp, in_process(mp, tmp_path):
        mp.setattr(maze, "oracle_feedback", oracle_feedback)
        summary = maze.main(args, None, maze.StopSignals())
    assert summary["status"] == "completed"
    assert len(alphas) == 600
    assert alphas[0] == pytest.approx(0.9, abs=1e-12) and alphas[-1] == pytest.approx(0.999, abs=1e-12)
    assert np.allclose(alphas, 0.9 + 0.099 * np.arange(600) / 599, rtol=0, atol=1e-12)
