"""The nights of other methods (inform_utils/sleep_variants_pusher.py --sleep-method): each loss on a hand-worked
case, and each learner learning on a day made by hand, where the same learner broken (learning rate 0) does not; DWBC
and the PU reward + TD3+BC on a day whose failures share the success set's states and take other actions, where only
the method's own mechanism (d's weights, the PU reward, the critic) finds the success set's action (docs/mutations.md:
each mechanism removed fails these tests)."""

import copy
import math

import pytest
import torch

import inform_sac_pusher as isp
from inform_utils import sleep_variants_pusher as variants

ALPHA, ETA = variants.DWBC_DRAFT["alpha"], variants.DWBC_DRAFT["eta"]


pytestmark = pytest.mark.usefixtures("one_thread")  # conftest.py


def test_pu_loss_by_hand():
    """eta E_e[-log d] + E_o[-log(1 - d)] - eta E_e[-log(1 - d)], with d_e = (0.8, 0.5), d_o = (0.25,), eta 0.5:
    0.5 * (0.2231 + 0.6931) / 2 + 0.2877 - 0.5 * (1.6094 + 0.6931) / 2 = 0.2291 + 0.2877 - 0.5756 = -0.0589."""
    d_e, d_o = torch.tensor([0.8, 0.5]), torch.tensor([0.25])
    expected = 0.5 * (-math.log(0.8) - math.log(0.5)) / 2 - math.log(0.75) - 0.5 * (-math.log(0.2) - math.log(0.5)) / 2
    assert variants.pu_loss(d_e, d_o, 0.5).item() == pytest.approx(expected, abs=1e-6)
    assert expected == pytest.approx(-0.0589, abs=1e-4)


def test_dwbc_policy_loss_by_hand():
    """alpha E_e[nll] - E_e[nll (eta / (d (1 - d)) + 1)] + E_o[nll (1 / (1 - d) - 1)], an other row only where d >= 0.5,
    alpha 10, eta 0.5: nll_e = (1, 2) at d_e = (0.5, 0.9), nll_o = (3, 4) at d_o = (0.75, 0.4):
    (7 * 1 + 3.4444 * 2) / 2 + (3 * 3 + 0 * 4) / 2 = 6.9444 + 4.5 = 11.4444."""
    nll_e, nll_o, d_e, d_o = (
        torch.tensor([1.0, 2.0]),
        torch.tensor([3.0, 4.0]),
        torch.tensor([0.5, 0.9]),
        torch.tensor([0.75, 0.4]),
    )
    assert variants.dwbc_policy_loss(nll_e, nll_o, d_e, d_o, 10.0, 0.5).item() == pytest.approx(11.4444, abs=1e-4)


def test_dwbc_keeps_every_expert_weight_positive_in_its_d_range():
    """d is clipped to [0.1, 0.9]; there the expert weight alpha - 1 - eta / (d (1 - d)) is at least 9 - 0.5 / 0.09
    (the draft's alpha 10) and 6.5 - 0.5 / 0.09 (the release's 7.5): positive. Both discriminators stay in the range."""
    for recipe, disc in (
        (variants.DWBC_DRAFT, variants.Discriminator(3, 2)),
        (variants.DWBC, variants.DWBCDiscriminator(3, 2)),
    ):
        (low, high), alpha, eta = recipe["d_range"], recipe["alpha"], recipe["eta"]
        d = torch.linspace(low, high, 101)
        least = alpha - 1 - eta / (low * (1 - low))
        assert (alpha - 1 - eta / (d * (1 - d))).min().item() == pytest.approx(least, rel=1e-5) and least > 0
        out = disc(torch.randn(64, 3) * 100, torch.randn(64, 2) * 100, torch.randn(64, 2) * 1e3)
        assert out.min().item() >= low and out.max().item() <= high


def test_dwbc_runs_at_its_releases_settings():
    """The settings of ryanxhr/DWBC at a1e9d8a (docs/protocol.md names each line); the draft's kept apart."""
    assert {k: variants.DWBC[k] for k in ("alpha", "eta", "lr", "weight_decay", "d_every", "steps")} == {
        "alpha": 7.5, "eta": 0.5, "lr": 1e-4, "weight_decay": 5e-3, "d_every": 100, "steps": 500_000}  # fmt: skip
    assert variants.DWBC["log_pi_range"] == (-20.0, 10.0) and variants.DWBC["d_range"] == (0.1, 0.9)
    assert (variants.DWBC_DRAFT["alpha"], variants.DWBC_DRAFT["lr"]) == (10.0, 3e-4)


def hand_made_day(n: int = 2000, obs_dim: int = 4, act_dim: int = 2) -> isp.ReplayBuffer:
    """Half the transitions a success (states around +1, action +0.5 on every dimension), half not (states around -1,
    action -0.5), in 20 episodes of 100 steps."""
    torch.manual_seed(0)
    buffer = isp.ReplayBuffer(n, obs_dim, act_dim, torch.device("cpu"))
    for episode in range(n // 100):
        success = episode % 2 == 0
        sign = 1.0 if success else -1.0
        start = buffer.size
        for _ in range(100):
            obs = sign + 0.3 * torch.randn(obs_dim)
            buffer.add(obs, torch.full((act_dim,), 0.5 * sign) + 0.05 * torch.randn(act_dim), obs, False)
        buffer.tag_episode(start, 0.0 if success else 1.0, success)
    return buffer


def sleep(night, buffer: isp.ReplayBuffer, steps: int, batch_size: int = 64) -> None:
    replay_idx, expert_idx, _ = night.memories(buffer)
    for step in range(1, steps + 1):
        night.update(step, isp.sleep_batch(buffer, batch_size, expert_idx, replay_idx))


def shared_states_day(n: int = 2000, obs_dim: int = 4, act_dim: int = 2) -> isp.ReplayBuffer:
    """Episodes of 10 steps, half of them a success: 5 steps in states shared by all (around 0), then 5 in the
    episode's own region (around +1 a success, -1 a failure), the last step terminal; a success acts +0.5 on every
    dimension, a failure -0.5, in the shared states too. Only what sets the two apart in the shared states (an action's
    weight, where it leads) can find +0.5 there: cloning every row gives 0."""
    torch.manual_seed(0)
    buffer = isp.ReplayBuffer(n, obs_dim, act_dim, torch.device("cpu"))
    for episode in range(n // 10):
        sign = 1.0 if episode % 2 == 0 else -1.0
        start = buffer.size
        obs = [0.3 * torch.randn(obs_dim) for _ in range(5)] + [sign + 0.3 * torch.randn(obs_dim) for _ in range(6)]
        for t in range(10):
            action = torch.full((act_dim,), 0.5 * sign) + 0.05 * torch.randn(act_dim)
            buffer.add(obs[t], action, obs[t + 1], t == 9)
        buffer.tag_episode(start, 0.0 if sign > 0 else 1.0, sign > 0)
    return buffer


def shared_rows(buffer: isp.ReplayBuffer) -> torch.Tensor:
    shared = torch.zeros(buffer.size, dtype=torch.bool)
    for start, _, _ in buffer.episodes:
        shared[start : start + 5] = True
    return shared


def test_dwbc_finds_the_success_sets_action_where_failures_share_its_states():
    """The release's DWBC on shared_states_day, 300 steps, its discriminator updated every step (the release's 1 in
    100 would need 30,000 steps here; the loss and the weights are the release's): on the shared states d tells the
    success rows from the failures by more than 0.5, and the actor's mean action there comes within 0.1 of the
    successes' +0.5. Measured: d 0.90 against 0.10, an error of 0.009. Without d's weights (cloning every row alike):
    0.49; with d fixed at 0.5 (weights 4.5 and 1): 0.17 and no gap."""
    buffer = shared_states_day()
    torch.manual_seed(1)
    night = variants.Args(sleep_method="dwbc", sleep_batch_size=64).night(isp.Actor(4, 2), torch.device("cpu"), {})
    assert isinstance(night, variants.DWBCNight)
    night.d_every = 1
    replay_idx, _, _ = night.memories(buffer)
    assert not buffer.success[replay_idx].any()  # the unlabelled set leaves the success set out, as the release's
    sleep(night, buffer, 300)
    success, shared = buffer.success[: buffer.size], shared_rows(buffer)
    with torch.no_grad():
        obs, actions = buffer.obs[: buffer.size], buffer.actions[: buffer.size]
        d = night.discriminator(obs, actions, variants.unit_log_pi(night.actor, obs, actions))
        error = (variants.mean_action(night.actor, obs[shared & success]) - 0.5).abs().mean().item()
    gap = (d[shared & success].mean() - d[shared & ~success].mean()).item()
    assert gap > 0.5 and error < 0.1, (gap, error)


def test_pu_td3bc_learns_its_reward_first_then_acts_on_where_an_action_leads(monkeypatch):
    """The PU reward + TD3+BC on shared_states_day (the reward's stage read every 100 steps, at most 1,500), then 600
    TD3+BC steps. The reward, learned first and frozen: above 0.85 on the successes' own states, below 0.1 on the
    failures'; the actor's mean action on the shared states above 0.4, where cloning the batch's actions alone gives
    0.25 (its success rows, then the day's). Measured: 0.96 and 0.001, 0.70. With plain cross-entropy for the PU loss
    (the success rows among the day's counted as negatives) the reward on the successes' states is 0.65; with the
    critic's weight at 0 the action is 0.29."""
    monkeypatch.setitem(variants.PU_REWARD, "every", 100)
    monkeypatch.setitem(variants.PU_REWARD, "max_steps", 1500)
    buffer = shared_states_day()
    torch.manual_seed(1)
    night = variants.Args(sleep_method="pu_td3bc", sleep_batch_size=64).night(isp.Actor(4, 2), torch.device("cpu"), {})
    assert isinstance(night, variants.PUTD3BCNight)
    tamer = copy.deepcopy(night.actor)
    sleep(night, buffer, 600)
    assert not any(p.requires_grad for p in night.reward.parameters())  # frozen before TD3+BC's first step
    record = night.stats()
    assert 0 < record["pu_reward/best_step"] <= record["pu_reward/steps"] <= 1500
    success, shared = buffer.success[: buffer.size], shared_rows(buffer)
    obs = buffer.obs[: buffer.size]
    with torch.no_grad():
        r = night.relabelled(obs)
        action = variants.mean_action(night.actor, obs[shared & success]).mean().item()
        folded = variants.NormalisedActor(tamer, night.obs_mean, night.obs_std)  # as the night started
        starts = [variants.mean_action(actor, obs[:50]) for actor in (tamer, folded, folded.raw())]
    assert type(night.actor) is isp.Actor  # folded back onto raw states: what is saved and tested
    assert torch.allclose(starts[0], starts[1], atol=1e-5) and torch.allclose(starts[0], starts[2], atol=1e-5)
    good, bad = r[success & ~shared].mean().item(), r[~success & ~shared].mean().item()
    assert good > 0.85 and bad < 0.1 and action > 0.4, (good, bad, action)


def night_of(method: str, broken: bool):
    """A method's night from TAMER's (random) actor; `broken`: every optimizer at learning rate 0, nothing moves."""
    torch.manual_seed(1)
    args = variants.Args(sleep_method=method, sleep_batch_size=64)
    night = args.night(isp.Actor(4, 2), torch.device("cpu"), tamer={})
    for optimizer in [v for v in vars(night).values() if isinstance(v, torch.optim.Optimizer)] if broken else []:
        for group in optimizer.param_groups:
            group["lr"] = 0.0
    return night


@pytest.mark.parametrize("broken", [False, True], ids=["learns", "lr0_does_not"])
def test_draft_dwbc_night_learns_the_success_sets_actions_and_tells_them_apart(broken):
    """The draft DWBC (the committed `dwbc` nights): on the hand-made day, 300 steps: the discriminator scores the
    success rows above the others by more than
    0.3, and the actor's mean action on success states comes within 0.15 of the successes' +0.5. Measured: a gap of
    0.80 and an error of 0.014 (0.456 at the start); at learning rate 0, -0.03 and 0.456: each check can fail."""
    buffer = hand_made_day()
    night = night_of("dwbc_draft", broken)
    assert isinstance(night, variants.DraftDWBCNight)
    sleep(night, buffer, 300)
    success = buffer.success[: buffer.size]
    with torch.no_grad():
        obs, actions = buffer.obs[: buffer.size], buffer.actions[: buffer.size]
        d = night.discriminator(obs, actions, night.actor.log_prob(obs, actions, per_dimension=True))
        mean_action = night.actor.get_action(obs[success])[2]
    gap = (d[success].mean() - d[~success].mean()).item()
    error = (mean_action - 0.5).abs().mean().item()
    learned = gap > 0.3 and error < 0.15
    assert learned != broken, (gap, error)


def test_the_non_negative_pu_loss_by_hand():
    """On logits: eta softplus(-f_e) + max(0, softplus(f_o) - eta softplus(f_e)), eta 0.5. f_e = 0, f_o = 0: 0.5 *
    0.6931 + max(0, 0.6931 - 0.3466) = 0.6931, as pu_loss at d = 0.5. f_e = 4, f_o = 0: the negative part 0.6931 -
    0.5 * 4.0181 < 0 is held at 0, leaving 0.5 * 0.0181 = 0.0091."""
    zero, four = torch.zeros(1), torch.full((1,), 4.0)
    assert variants.nn_pu_loss(zero, zero, 0.5).item() == pytest.approx(math.log(2), abs=1e-6)
    half = torch.full((1,), 0.5)
    assert variants.pu_loss(half, half, 0.5).item() == pytest.approx(math.log(2), abs=1e-6)
    assert variants.nn_pu_loss(four, zero, 0.5).item() == pytest.approx(0.5 * math.log1p(math.exp(-4)), abs=1e-6)


def test_td3bc_actor_loss_by_hand():
    """-alpha / mean|Q| * mean Q + mean (pi - a)^2, alpha 2.5: Q = (2, -4), pi - a = (0.5, -1) in one dimension:
    -2.5 / 3 * (-1) + (0.25 + 1) / 2 = 0.8333 + 0.625 = 1.4583."""
    q_pi, pi, a = torch.tensor([2.0, -4.0]), torch.tensor([[0.5], [0.0]]), torch.tensor([[0.0], [1.0]])
    assert variants.td3bc_actor_loss(q_pi, pi, a, 2.5).item() == pytest.approx(1.4583, abs=1e-4)


@pytest.mark.parametrize("broken", [False, True], ids=["learns", "lr0_does_not"])
def test_draft_oril_night_learns_a_reward_that_tells_success_apart_and_a_critic_that_values_it(broken):
    """The draft ORIL (the committed `oril` nights): on the hand-made day, 1,000 steps: the reward scores success
    observations above the others by more than
    0.3, the critic values the success states above the others by more than 0.1, and the actor's mean action on
    success states comes within 0.2 of their +0.5. Measured: 0.93, 3.3 and 0.10 (0.49 after 300 steps; the actor
    moves every 2nd step at 3e-4). At learning rate 0 none of it happens."""
    buffer = hand_made_day()
    night = night_of("oril_draft", broken)
    assert isinstance(night, variants.DraftORILNight)
    sleep(night, buffer, 1000)
    success = buffer.success[: buffer.size]
    with torch.no_grad():
        obs, actions = buffer.obs[: buffer.size], buffer.actions[: buffer.size]
        r = torch.sigmoid(night.reward(obs)).squeeze(-1)
        q = night.critic(obs, actions).min(0).values
        error = (variants.mean_action(night.actor, obs[success]) - 0.5).abs().mean().item()
    gap, q_gap = (r[success].mean() - r[~success].mean()).item(), (q[success].mean() - q[~success].mean()).item()
    learned = gap > 0.3 and q_gap > 0.1 and error < 0.2
    assert learned != broken, (gap, q_gap, error)


def test_sleep_variant_records_what_the_night_ran_with():
    """summary.json's sleep_variant names the settings the chosen night uses, at the values it used: DWBC its own
    learning rate and not the cloning term or the actor's states it ignores; the sham TAMER's rates; the maze's sham
    H's rate and not Eq. 2's."""
    from inform_utils import sleep_variants_maze as maze_variants

    def words(args):
        return dict(w.split("=", 1) for w in args.sleep_variant().split())

    dwbc = words(variants.Args(sleep_method="dwbc"))
    assert dwbc["method"] == "dwbc" and float(dwbc["policy_lr"]) == variants.DWBC["lr"]
    assert not {"bc_coef", "actor_states"} & set(dwbc)
    draft = words(variants.Args(sleep_method="dwbc_draft"))
    assert draft["method"] == "dwbc_draft" and float(draft["policy_lr"]) == variants.DWBC_DRAFT["lr"]
    sham = words(variants.Args(sleep_control="sham"))
    assert float(sham["policy_lr"]) == isp.TAMER_POLICY_LR and float(sham["h_lr"]) == variants.Args().tamer_h_lr
    assert not {"bc_coef", "actor_states"} & set(sham)
    assert words(variants.Args())["bc_coef"] == "0.0" and "h_lr" not in words(variants.Args())  # the IQ night: all
    maze_sham = words(maze_variants.Args(sleep_control="sham"))
    assert float(maze_sham["h_lr"]) == maze_variants.Args().tamer_h_lr and "temperature" in maze_sham
    assert not {"q_lr", "chi2_coef", "loss_rows"} & set(maze_sham)
