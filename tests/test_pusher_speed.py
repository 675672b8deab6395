"""The speed work on inform_sac_pusher.py's hot loops moves no number: the faster actor step (no weight gradients on
the critic, Adam's foreach form) gives the old step's parameters to the last bit, and the in-script teacher's SAC is
deterministic. (The opt-in --bf16 of the teachers lives in oracle_train.py.) Speed itself is measured in
benchmarks/benchmark.py, not here."""

import contextlib
import io
import os
import sys

import torch

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

import inform_sac_pusher as isp  # noqa: E402


def old_update_actor(q_net, actor, obs, log_ent_coef, actor_optimizer, ent_coef_optimizer, target_entropy):
    """The actor step before the speed work: the critic got (and dropped) weight gradients, Adam looped."""
    pi_loss, logp = isp.actor_loss(q_net, actor, obs, log_ent_coef.detach().exp())
    actor_optimizer.zero_grad(set_to_none=True)
    pi_loss.backward()
    actor_optimizer.step()
    q_net.zero_grad(set_to_none=True)
    ent_coef_loss = (-log_ent_coef.exp() * (logp.detach() + target_entropy)).mean()
    ent_coef_optimizer.zero_grad(set_to_none=True)
    ent_coef_loss.backward()
    ent_coef_optimizer.step()


def make_sac(seed, foreach):
    torch.manual_seed(seed)
    q_net, actor = isp.QEnsemble(23, 7, 64, n=2), isp.Actor(23, 7, 64, -2 * torch.ones(7), 2 * torch.ones(7))
    log_ent_coef = torch.zeros(1, requires_grad=True)
    optimizers = (torch.optim.Adam(actor.parameters(), lr=3e-4, foreach=foreach),
                  torch.optim.Adam([log_ent_coef], lr=1e-3, foreach=foreach))  # fmt: skip
    return q_net, actor, log_ent_coef, optimizers


def test_actor_step_is_bit_identical_to_the_old_one():
    obs = torch.randn(5, 32, 23, generator=torch.Generator().manual_seed(3))
    new, old = make_sac(0, foreach=True), make_sac(0, foreach=False)
    torch.manual_seed(1)  # the actions' noise
    for batch in obs:
        isp.update_actor(new[0], new[1], batch, new[2], *new[3])  # SAC's target entropy, -dim(A) = -7
    torch.manual_seed(1)
    for batch in obs:
        old_update_actor(old[0], old[1], batch, old[2], *old[3], -7.0)
    assert all(p.grad is None for p in new[0].parameters())  # the critic kept no gradient
    assert new[0].fc1.weight.requires_grad  # and still learns in its own step
    for a, b in zip([*new[1].parameters(), new[2]], [*old[1].parameters(), old[2]], strict=True):
        assert torch.equal(a, b)
    assert not torch.equal(new[1].fc1.weight, make_sac(0, foreach=True)[1].fc1.weight)  # it did learn


class NullWriter:
    def add_scalar(self, *args, **kwargs):
        pass


def tiny_oracle(seed):
    """The in-script teacher's SAC, 60 updates after its 5,000 random steps."""
    torch.manual_seed(seed)
    outcome = isp.Outcome()
    with contextlib.redirect_stdout(io.StringIO()):
        actor, qf, _ = isp.train_oracle("Pusher-v5", 1, 5060, outcome, NullWriter(), torch.device("cpu"))
    return torch.cat([p.detach().flatten() for p in (*actor.parameters(), *qf.parameters())])


def test_the_oracles_sac_is_deterministic_and_learns():
    first, again, other = tiny_oracle(1), tiny_oracle(1), tiny_oracle(2)
    assert torch.equal(first, again)  # same seed, same numbers
    assert torch.isfinite(first).all() and not torch.equal(first, other)
