"""The sleep study's variants of the Pusher night, on inform_sac_pusher.py's declared surface (as CleanRL's evaluation
helpers import a script's agent): the actor's start and its states, its schedule, the rows of Eq. 2's value and
chi-squared terms, twin critics, a behaviour-cloning term, the sham and cloning controls, the hold-out offline
criterion that picks a checkpoint without the environment, and nights of other methods built for a night's data
(--sleep-method: DWBC at its release's settings, a PU reward + TD3+BC staged as ORIL stages it, and the drafts the
first committed nights of these methods ran).

It runs like the core script, normally on a saved day, with the study's switches on top, and writes the same run
directory, files and summary.json (`sleep_variant` and the study's flags in `args`). With no study flag it gives the
core's numbers; with the flags of commit cdfc757's script it gives that script's numbers. Each variant subclasses the
core's Night and calls its loss and actor objective, so a term added there runs here too; a night flag that the chosen
control or method does not use (`hears`) is refused in one line, never recorded as if it ran.

    python -m inform_utils.sleep_variants_pusher --sleep-from runs/<day> --sleep-seed 1 --sleep-control sham
    python -m inform_utils.sleep_variants_pusher --sleep-from runs/<day> --sleep-holdout-fraction 0.15 \
        --sleep-twin-critics --sleep-loss-rows expert
    python -m inform_utils.sleep_variants_pusher --sleep-from runs/<day> --sleep-seed 1 --sleep-method dwbc
"""

import contextlib
import os
import signal
import sys


def stopped_while_starting(signum, frame):  # as the core script's: a stop while torch loads is one line
    with contextlib.suppress(OSError):
        os.write(2, f"interrupted ({signal.Signals(signum).name}) while starting; no run was made\n".encode())
    os._exit(128 + signum)


if __name__ == "__main__":
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        if signal.getsignal(sig) is not signal.SIG_IGN:
            signal.signal(sig, stopped_while_starting)

import copy  # noqa: E402
import dataclasses  # noqa: E402
import math  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from typing import Annotated, Literal  # noqa: E402

import torch  # noqa: E402
import torch.nn.functional as F  # noqa: E402
import tyro  # noqa: E402

import inform_sac_pusher as core  # noqa: E402


@dataclass
class Args(core.Args):
    # The sleep study's switches (docs/protocol.md, "Saved days and the sleep's variants")
    sleep_control: Literal["none", "bc", "sham"] = "none"
    """a control in place of the INFORM actor's update, same steps: bc = behaviour cloning on the success set (the
    mean action's squared error on the expert rows); sham = TAMER's own update (H on the feedback, the actor on H),
    no consolidation. The soft Q network sleeps as usual"""
    sleep_method: Literal["iq", "dwbc", "pu_td3bc", "dwbc_draft", "oril_draft"] = "iq"
    """the night's method (docs/protocol.md, "Nights of other methods"): iq = the core's IQ-Learn night; dwbc =
    discriminator-weighted behaviour cloning (Xu et al., ICML 2022) at its release's settings: a discriminator tells
    the success set from the day's other rows, and its output weights the cloning of both; pu_td3bc = a
    positive-unlabelled reward of observations learned first (ORIL's stage, Zolna et al. 2020), then TD3+BC on the day
    relabelled with it, states normalised; dwbc_draft and oril_draft = the drafts the nights committed as `dwbc` and
    `oril` before 2026-12-05 ran (the draft's DWBC settings; a PU reward learned alongside TD3+BC)"""
    sleep_init_actor_from_tamer: bool = True
    """start the INFORM actor from the TAMER actor (consolidation); False starts it from scratch (unset: the
    protocol's)"""
    sleep_actor_states: Literal["replay", "replay+expert", "expert"] | None = None
    """the states of each batch the INFORM actor is trained on: the replay rows, both halves, or the expert rows
    (None: the protocol's, replay ours)"""
    sleep_policy_frequency: Annotated[int | None, core.In(1)] = None
    """the INFORM actor is updated this many times every this many gradient steps (CleanRL's delayed policy update;
    None: the protocol's, 1 ours, 2 the authors')"""
    sleep_loss_rows: Literal["all", "expert"] = "all"
    """the rows of Eq. 2's value and chi-squared terms: the whole batch (the paper), or the expert rows only
    (IQ-Learn's offline recipe, its `value_expert` loss)"""
    sleep_twin_critics: bool = False
    """two soft Q networks, each trained on Eq. 2, their minimum in V(s) and in the actor's objective"""
    sleep_bc_coef: Annotated[float, core.In(0)] = 0.0
    """a behaviour-cloning term on the INFORM actor, TD3+BC style: the Q objective divided by mean |Q| at the batch's
    own actions (TD3+BC takes it at the policy's), plus this weight times the squared error of the mean action on the
    expert rows; 0 turns it off"""
    sleep_holdout_fraction: Annotated[float, core.In(0, 1)] = 0.0
    """hold this fraction of the day's episodes out of the sleep (split by episode, fixed by the seed) and log the
    offline criterion on them every 1,000 steps; the checkpoint it picks is kept and tested as `inform_selected`"""

    def night_settings(self) -> dict:
        """The core's settings and the study's switches, under what the chosen night fixes (its `fixed`)."""
        settings = super().night_settings() | {
            "loss_rows": self.sleep_loss_rows, "twin_critics": self.sleep_twin_critics, "bc_coef": self.sleep_bc_coef,
            "holdout_fraction": self.sleep_holdout_fraction,
        }  # fmt: skip
        return settings | self.night_kind().fixed  # what the night fixes itself, recorded as what ran

    def sleep_variant(self) -> str:
        """The core's line with only the settings the chosen night uses (and the sham's H rate): what ran."""
        kind, words = self.night_kind(), super().sleep_variant().split()
        if kind.hears is not None:
            unused = set(self.night_settings()) - kind.hears - set(kind.fixed)
            words = [w for w in words if w.split("=")[0] not in unused]
        words += [f"h_lr={self.tamer_h_lr}"] if kind is ShamControl else []
        return f"method={self.sleep_method} control={self.sleep_control} " + " ".join(words)

    def night_kind(self) -> type:
        return CONTROLS[self.sleep_control] if self.sleep_control != "none" else METHODS[self.sleep_method]

    def night(self, tamer_actor, device, tamer: dict):
        kind = self.night_kind()
        extra = tamer | {"h_lr": self.tamer_h_lr} if kind is ShamControl else {}  # it goes on from the day's H
        return kind(tamer_actor, device, holdout_seed=self.seed, **self.night_settings(), **extra)


def unheard(args: Args) -> list[str]:
    """The night flags set (away from their defaults) that the chosen night does not use: a control hears only some."""
    hears = args.night_kind().hears
    defaults = {f.name: f.default for f in dataclasses.fields(Args)}
    flags = [f"sleep_{k}" for k in args.night_settings() if hears is not None and k not in hears]
    return [f"--{flag.replace('_', '-')}" for flag in flags
            if getattr(args, flag, None) is not None and getattr(args, flag) != defaults.get(flag)]  # fmt: skip


def untyped_to_protocol(args: Args, argv: list[str]) -> Args:
    """--sleep-init-actor-from-tamer is a plain bool (its --no- form is the study's): left untyped, it is the
    protocol's, as the core's None fields are."""
    typed = any(a.split("=")[0] in ("--sleep-init-actor-from-tamer", "--no-sleep-init-actor-from-tamer") for a in argv)
    return args if typed else dataclasses.replace(args, sleep_init_actor_from_tamer=None)


def held_out(fraction: float, seed: int, buffer, device) -> torch.Tensor | None:
    """The transitions of `fraction` of the day's episodes, drawn by the seed (None: no hold-out)."""
    if fraction == 0:
        return None
    n = len(buffer.episodes)
    k = min(n - 1, max(1, round(fraction * n)))
    chosen = torch.randperm(n, generator=torch.Generator().manual_seed(seed + 15)).tolist()[:k]
    return torch.cat([torch.arange(*buffer.episodes[i][:2], device=device) for i in sorted(chosen)])


def auc(scores: torch.Tensor, positive: torch.Tensor) -> float:
    """The probability that a positive scores above a negative, ties counted half (Mann-Whitney U); NaN without both."""
    from scipy.stats import rankdata

    n_pos = int(positive.sum())
    n_neg = positive.numel() - n_pos
    if n_pos == 0 or n_neg == 0:
        return float("nan")
    ranks = rankdata(scores.float().cpu().numpy())
    return float((ranks[positive.cpu().numpy()].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


class OfflineCriterion:
    """Choosing the sleep's checkpoint without the environment: on the held-out episodes, every evaluation of the sleep
    logs the expert log-likelihood (mean log pi(a|s) of the held-out success transitions), the IQ-Learn terms, the drift
    of Q(s, a~pi) and the AUC with which the recovered reward (Eq. 3) separates success from failure transitions. The
    criterion, fixed before any test return was seen: the highest expert log-likelihood picks the checkpoint."""

    def __init__(self, buffer, held: torch.Tensor):
        self.batch = buffer.batch(held)
        self.success = buffer.success[held]
        starts = torch.tensor([start for start, _, _ in buffer.episodes], device=held.device)
        self.episodes = int(torch.isin(starts, held).sum())
        self.best = -math.inf
        self.selected = None  # {"step", "actor"} of the best checkpoint so far
        self.last = {}
        self.q_pi_previous = None

    @torch.no_grad()
    def __call__(self, step: int, night: "StudyNight", writer) -> float:
        obs, actions, next_obs, _, terminated = self.batch
        q_net, actor, gamma, temp = night.q_net, night.actor, core.SLEEP_GAMMA, night.temperature
        cuda = obs.device.type == "cuda"
        with torch.random.fork_rng(devices=[torch.cuda.current_device()] if cuda else []):  # the sleep's RNG untouched
            expert = self.success.nonzero().squeeze(-1)
            loglik = actor.log_prob(obs[expert], actions[expert]).mean().item() if expert.numel() else float("nan")
            rows = self.success if night.loss_rows == "expert" else None
            loss, terms = core.iq_loss(q_net, night.q_target, obs, actions, next_obs, terminated, self.success, gamma,
                                       temp, night.chi2_coef, actor, rows)  # fmt: skip
            q_pi = q_net(obs, actor.get_action(obs)[0]).min(0).values.mean().item()
            v_next = core.soft_value(q_net, actor, next_obs, temp)
            reward = core.recover_reward(q_net(obs, actions).min(0).values, v_next, terminated, gamma)
        values = {
            "holdout/expert_loglik": loglik,
            "holdout/iq_loss": loss.item(),
            **{f"holdout/{name}": term.item() for name, term in terms.items()},
            "holdout/q_pi": q_pi,
            "holdout/reward_auc": auc(reward, self.success),
        }
        if self.q_pi_previous is not None:  # per 1,000 gradient steps
            values["holdout/q_pi_drift"] = (q_pi - self.q_pi_previous[1]) * 1000 / (step - self.q_pi_previous[0])
        self.q_pi_previous = (step, q_pi)
        for tag, value in values.items():
            writer.add_scalar(tag, value, step)
        self.last = values
        if math.isfinite(loglik) and loglik > self.best:
            self.best = loglik
            self.selected = {"step": step, "actor": copy.deepcopy(actor)}
        return loglik

    def stats(self) -> dict:
        return {
            **self.last,
            "holdout/episodes": self.episodes,
            "holdout/transitions": int(self.success.numel()),
            "holdout/success_transitions": int(self.success.sum()),
            "holdout/selected_step": self.selected["step"] if self.selected else None,
            "holdout/selected_expert_loglik": self.best if self.selected else None,
        }


class StudyNight(core.Night):
    """The core's night with the study's switches: the rows of Eq. 2's value and chi-squared terms, twin critics, a
    cloning term on the actor, and a hold-out whose offline criterion picks a checkpoint. Every switch at its default
    gives the core's night, number for number; a term added to the core's `loss` runs here too, and one added to its
    `actor_loss` in every night that keeps that objective (the controls and the methods update the actor their way)."""

    hears = None  # the night settings this night uses (None: all); a flag for any other is refused
    fixed = {}  # settings this night sets itself (a method's published values), recorded as what ran
    method_terms = {}  # a method's own terms of its last actor step, logged beside Eq. 2's

    def __init__(self, tamer_actor, device, *, loss_rows: str, twin_critics: bool, bc_coef: float,
                 holdout_fraction: float, holdout_seed: int, **settings):  # fmt: skip
        self.n_critics = 2 if twin_critics else 1
        super().__init__(tamer_actor, device, **settings)
        self.loss_rows, self.bc_coef = loss_rows, bc_coef
        self.holdout = (holdout_fraction, holdout_seed)
        self.criterion = None  # with a hold-out: the offline criterion on it

    def memories(self, buffer):  # the held-out episodes are never slept on, nor experts
        held = held_out(*self.holdout, buffer, self.is_expert.device)
        if held is None:
            return super().memories(buffer)
        self.criterion = OfflineCriterion(buffer, held)
        keep = torch.ones(buffer.size, dtype=torch.bool, device=held.device)
        keep[held] = False
        return keep.nonzero().squeeze(-1), *buffer.expert_indices(keep)

    def update(self, step, batch):
        loss, terms = super().update(step, batch)
        return loss, {**terms, **self.method_terms}

    def loss(self, obs, actions, next_obs, feedback, terminated, **kw):
        rows = self.is_expert if self.loss_rows == "expert" else None
        return super().loss(obs, actions, next_obs, feedback, terminated, rows=rows, **kw)

    def actor_loss(self, obs, actions, feedback):
        pi_loss = self.objective(obs, actions, feedback)
        if self.bc_coef > 0:  # TD3+BC: the objective made scale-free, plus cloning the experts
            pi_loss = pi_loss / self.q_net(obs, actions).abs().mean().detach()
            pi_loss = pi_loss + self.bc_coef * self.cloning_loss(obs, actions)
        return pi_loss

    def objective(self, obs, actions, feedback):  # the actor's own objective: the core's, on Q
        return super().actor_loss(obs, actions, feedback)

    def cloning_loss(self, obs, actions):  # the mean action's squared error on the expert rows
        return (self.actor.get_action(obs[self.is_expert])[2] - actions[self.is_expert]).pow(2).mean()

    def evaluated(self, step, writer):
        if self.criterion is None:
            return {}
        return {"criterion": self.criterion(step, self, writer)}  # the held-out episodes only: no environment

    def stats(self):
        if self.criterion is None:
            return {}
        self.selected = self.criterion.selected
        return self.criterion.stats()


class CloningControl(StudyNight):
    """Behaviour cloning on the success set in place of the actor's objective (the soft Q sleeps as usual)."""

    # not actor_states: it clones the expert rows
    hears = {"batch_size", "q_lr", "policy_lr", "temperature", "chi2_coef", "init_actor_from_tamer", "policy_frequency",
             "loss_rows", "twin_critics", "bc_coef", "holdout_fraction"}  # fmt: skip

    def objective(self, obs, actions, feedback):
        return self.cloning_loss(obs, actions)


class ShamControl(StudyNight):
    """TAMER goes on learning from its memories at its own rates: H from the day's by Eq. 1 on the replay rows, then
    its actor on H with its autotuned entropy; no consolidation (the soft Q sleeps as usual, unused)."""

    # TAMER's rates, from TAMER's actor, on the replay rows, no cloning term
    hears = {"batch_size", "q_lr", "temperature", "chi2_coef", "policy_frequency", "loss_rows", "twin_critics",
             "holdout_fraction"}  # fmt: skip
    fixed = {"policy_lr": core.TAMER_POLICY_LR, "init_actor_from_tamer": True}

    def __init__(self, tamer_actor, device, *, h_net, h_kwargs: dict, day_settings: dict, ent_coef: float, h_lr: float,
                 **settings):  # fmt: skip
        super().__init__(tamer_actor, device, **settings)
        self.driven_in_h = day_settings.get("driven_in_h", True)  # a page's --no-driven-in-h: H never heard them
        self.h_net = core.QEnsemble(**h_kwargs).to(device)  # as the day built its H (a saved day: from its kwargs)
        self.h_net.load_state_dict(h_net.state_dict())
        self.h_optimizer = torch.optim.Adam(self.h_net.parameters(), lr=h_lr, foreach=True)
        self.log_ent_coef = torch.full((1,), math.log(ent_coef), device=device, requires_grad=True)
        self.ent_coef_optimizer = torch.optim.Adam([self.log_ent_coef], lr=h_lr, foreach=True)

    def memories(self, buffer):  # H goes on hearing what it heard by day: not the person's steps, if kept out
        replay_idx, expert_idx, fallback = super().memories(buffer)
        if not self.driven_in_h:
            rows = torch.arange(buffer.size, device=expert_idx.device) if replay_idx is None else replay_idx
            replay_idx = rows[~buffer.driven[rows]]
        return replay_idx, expert_idx, fallback

    def update_actor(self, batch):  # Eq. 1 on the replay rows, then TAMER's actor step on H
        obs, actions, _, feedback, _ = batch
        replay = ~self.is_expert
        self.pi_loss = core.tamer_loss(self.h_net, obs[replay], actions[replay], feedback[replay])
        self.h_optimizer.zero_grad(set_to_none=True)
        self.pi_loss.backward()
        self.h_optimizer.step()
        core.update_actor(self.h_net, self.actor, obs[replay], self.log_ent_coef, self.actor_optimizer,
                          self.ent_coef_optimizer)  # fmt: skip


# DWBC (Xu et al., ICML 2022) as its authors' latest public code runs it: github.com/ryanxhr/DWBC at a1e9d8a
# (2023-01-05; algos/DWBC.py unchanged since b8f8917, 2022-07-21), read 2026-12-05; docs/protocol.md names the line of
# each: the weight of the expert cloning term, the class prior of the positive-unlabelled discriminator, the learning
# rate of both networks, the policy's weight decay, one discriminator update every `d_every` policy steps, the range d
# is clipped to, the range log pi is clipped to before the discriminator sees it (scaled to [0, 1]), the width of the
# discriminator's two input branches and of its hidden layer, and the release's own budget (--sleep-gradient-steps
# sets the night's)
DWBC = {"alpha": 7.5, "eta": 0.5, "lr": 1e-4, "weight_decay": 5e-3, "d_every": 100, "d_range": (0.1, 0.9),
        "log_pi_range": (-20.0, 10.0), "branch": 128, "hidden": 256, "steps": 500_000}  # fmt: skip
# the draft's settings (an early commit of that repository, 1da7f92, with the later log-pi clip): the committed
# nights named `dwbc` before 2026-12-05 ran these; `--sleep-method dwbc_draft` runs them again, number for number
DWBC_DRAFT = {"alpha": 10.0, "eta": 0.5, "lr": 3e-4, "weight_decay": 1e-3, "d_range": (0.1, 0.9)}


def pu_loss(d_expert: torch.Tensor, d_other: torch.Tensor, eta: float) -> torch.Tensor:
    # positive-unlabelled (DWBC's discriminator, ORIL's reward): the success set is positive, the other rows
    # unlabelled, eta the class prior: L = eta E_e[-log d] + E_o[-log(1 - d)] - eta E_e[-log(1 - d)]
    return -eta * d_expert.log().mean() - (1 - d_other).log().mean() + eta * (1 - d_expert).log().mean()


def dwbc_policy_loss(nll_expert, nll_other, d_expert, d_other, alpha: float, eta: float) -> torch.Tensor:
    # the cloning loss that L_d's dependence on log pi gives, d held fixed (nll = -log pi(a|s)), as the authors'
    # release weighs it: L_pi = alpha E_e[nll] - E_e[nll (eta / (d (1 - d)) + 1)] + E_o[nll (1 / (1 - d) - 1)], an
    # other row counted only where d >= 0.5 (weight d / (1 - d): how expert-like it looks), 0 elsewhere
    expert = (alpha - 1 - eta / (d_expert * (1 - d_expert))) * nll_expert
    other = torch.where(d_other >= 0.5, d_other / (1 - d_other), torch.zeros_like(d_other)) * nll_other
    return expert.mean() + other.mean()


def dwbc_actor_step(night, nll: torch.Tensor, d: torch.Tensor, d_loss: torch.Tensor, cfg: dict) -> None:
    """The policy's DWBC step on the batch's negative log-likelihoods `nll` weighted by the discriminator's `d` (taken
    before its update, no gradient), and the terms the night logs."""
    expert, other = night.is_expert, ~night.is_expert
    night.pi_loss = dwbc_policy_loss(nll[expert], nll[other], d[expert], d[other], cfg["alpha"], cfg["eta"])
    night.actor_optimizer.zero_grad(set_to_none=True)
    night.pi_loss.backward()
    night.actor_optimizer.step()
    night.method_terms = {"dwbc_d_loss": d_loss.detach(), "dwbc_d_expert": d[expert].mean(),
                          "dwbc_d_other": d[other].mean()}  # fmt: skip


def unit_log_pi(actor, obs, actions) -> torch.Tensor:
    """log pi(a|s) per action dimension, of the action in [-1, 1] (as the release's tasks scale them): the core
    actor's density on the env's bounds plus log(action_scale)."""
    return actor.log_prob(obs, actions, per_dimension=True) + actor.action_scale.log()


class DWBCDiscriminator(torch.nn.Module):
    """DWBC's d(s, a, log pi(a|s)) in [0.1, 0.9], shaped as the release's: (s, a) and log pi (per action dimension,
    clipped to [-20, 10], scaled to [0, 1], no gradient into the policy) each through a layer of 128, then together
    through one of 256."""

    def __init__(self, obs_dim: int, act_dim: int):
        super().__init__()
        self.sa = torch.nn.Linear(obs_dim + act_dim, DWBC["branch"])
        self.log_pi = torch.nn.Linear(act_dim, DWBC["branch"])
        self.hidden = torch.nn.Linear(2 * DWBC["branch"], DWBC["hidden"])
        self.out = torch.nn.Linear(DWBC["hidden"], 1)

    def forward(self, obs, actions, log_pi) -> torch.Tensor:
        low, high = DWBC["log_pi_range"]
        seen = (log_pi.detach().clamp(low, high) - low) / (high - low)
        x = torch.cat([F.relu(self.sa(torch.cat([obs, actions], -1))), F.relu(self.log_pi(seen))], -1)
        d = torch.sigmoid(self.out(F.relu(self.hidden(x)))).squeeze(-1)
        return d.clamp(*DWBC["d_range"])


def failures_only(replay_idx, expert_idx: torch.Tensor, size: int) -> torch.Tensor:
    """The night's rows that are not in the success set (DWBC's unlabelled set, which leaves its expert set out);
    the whole night if every row is a success."""
    rows = torch.arange(size, device=expert_idx.device) if replay_idx is None else replay_idx
    others = rows[~torch.isin(rows, expert_idx)]
    if others.numel() == 0:
        print("[sleep] warning: every episode of the night is a success; DWBC's unlabelled set is the whole night")
        return rows
    return others


class DWBCNight(StudyNight):
    """Discriminator-weighted behaviour cloning (Xu et al., ICML 2022) as the night, at its release's settings (DWBC):
    the unlabelled set is the night's rows outside the success set (the batch's replay rows); every step the
    discriminator's positive-unlabelled loss is taken on the batch, and every 100th step it updates d; the actor
    clones the success set and the unlabelled rows that look like it, weighted by d before that update
    (dwbc_policy_loss). The actor starts from TAMER's, on raw observations; the soft Q sleeps as usual (on these
    rows) and only gives the recovered reward."""

    # not the actor's learning rate (its own), its schedule (one step a night step), its states or the bc term
    hears = {"batch_size", "q_lr", "temperature", "chi2_coef", "init_actor_from_tamer", "loss_rows", "twin_critics",
             "holdout_fraction"}  # fmt: skip
    fixed = {"policy_lr": DWBC["lr"], "policy_frequency": 1}

    def __init__(self, tamer_actor, device, **settings):
        super().__init__(tamer_actor, device, **settings)
        obs_dim, act_dim = tamer_actor.fc1.in_features, tamer_actor.fc_mean.out_features
        self.discriminator = DWBCDiscriminator(obs_dim, act_dim).to(device)
        self.d_optimizer = torch.optim.Adam(self.discriminator.parameters(), lr=DWBC["lr"], foreach=True)
        self.actor_optimizer = torch.optim.Adam(self.actor.parameters(), lr=settings["policy_lr"],
                                                weight_decay=DWBC["weight_decay"], foreach=True)  # fmt: skip
        self.d_every, self.calls = DWBC["d_every"], 0

    def memories(self, buffer):
        replay_idx, expert_idx, fallback = super().memories(buffer)
        return failures_only(replay_idx, expert_idx, buffer.size), expert_idx, fallback

    def update_actor(self, batch):
        obs, actions, *_ = batch
        expert, other = self.is_expert, ~self.is_expert
        log_pi = unit_log_pi(self.actor, obs, actions)
        d = self.discriminator(obs, actions, log_pi)
        d_loss = pu_loss(d[expert], d[other], DWBC["eta"]) / DWBC["eta"]  # the release's scale: L_d / eta
        self.calls += 1
        if self.calls % self.d_every == 0:
            self.d_optimizer.zero_grad(set_to_none=True)
            d_loss.backward()
            self.d_optimizer.step()
        dwbc_actor_step(self, -log_pi.sum(-1), d.detach(), d_loss, DWBC)  # d before its update


class Discriminator(torch.nn.Module):
    """The draft DWBC's d(s, a, log pi(a|s)): one network on the three, log pi per action dimension clipped to
    [-20, 10] and scaled to [0, 1], no gradient into the policy."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: int = core.HIDDEN_SIZE):
        super().__init__()
        nn = torch.nn
        self.net = nn.Sequential(nn.Linear(obs_dim + 2 * act_dim, hidden), nn.ReLU(), nn.Linear(hidden, hidden),
                                 nn.ReLU(), nn.Linear(hidden, 1))  # fmt: skip

    def forward(self, obs, actions, log_pi) -> torch.Tensor:
        seen = (log_pi.detach().clamp(-20, 10) + 20) / 30
        d = torch.sigmoid(self.net(torch.cat([obs, actions, seen], -1))).squeeze(-1)
        return d.clamp(*DWBC_DRAFT["d_range"])


class DraftDWBCNight(StudyNight):
    """The draft of the DWBC night (`dwbc_draft`; the committed nights named `dwbc` before 2026-12-05), kept to re-run
    them: DWBC_DRAFT's settings, the whole day as the unlabelled set (successes included), the discriminator (one
    network, the draft's loss scale) updated every step. Not DWBC as its release runs it (DWBCNight)."""

    hears = {"batch_size", "q_lr", "temperature", "chi2_coef", "init_actor_from_tamer", "policy_frequency", "loss_rows",
             "twin_critics", "holdout_fraction"}  # fmt: skip
    fixed = {"policy_lr": DWBC_DRAFT["lr"]}

    def __init__(self, tamer_actor, device, **settings):
        super().__init__(tamer_actor, device, **settings)
        obs_dim, act_dim = tamer_actor.fc1.in_features, tamer_actor.fc_mean.out_features
        self.discriminator = Discriminator(obs_dim, act_dim).to(device)
        self.d_optimizer = torch.optim.Adam(self.discriminator.parameters(), lr=DWBC_DRAFT["lr"], foreach=True)
        self.actor_optimizer = torch.optim.Adam(self.actor.parameters(), lr=settings["policy_lr"],
                                                weight_decay=DWBC_DRAFT["weight_decay"], foreach=True)  # fmt: skip
        self.method_terms = {"dwbc_d_loss": torch.zeros((), device=device)}

    def update_actor(self, batch):
        obs, actions, *_ = batch
        expert, other = self.is_expert, ~self.is_expert
        log_pi = self.actor.log_prob(obs, actions, per_dimension=True)
        d = self.discriminator(obs, actions, log_pi)
        d_loss = pu_loss(d[expert], d[other], DWBC_DRAFT["eta"])
        log_pi = log_pi.sum(-1)
        self.d_optimizer.zero_grad(set_to_none=True)
        d_loss.backward()
        self.d_optimizer.step()
        dwbc_actor_step(self, -log_pi, d.detach(), d_loss, DWBC_DRAFT)  # d before its update


# TD3+BC (Fujimoto & Gu 2021) at its published settings (github.com/sfujim/TD3_BC, main.py): the BC weight alpha,
# target policy noise and its clip (times the action scale), the actor's delay, the target networks' rate, the
# discount, the learning rate of every network, and the constant added to the states' std where they are normalised
# (utils.py, normalize_states; on by default, --normalize)
TD3BC = {"alpha": 2.5, "policy_noise": 0.2, "noise_clip": 0.5, "delay": 2, "tau": 0.005, "gamma": 0.99, "lr": 3e-4,
         "std_eps": 1e-3}  # fmt: skip
# ORIL's positive-unlabelled reward (Zolna et al. 2020), learned first, to convergence on the day: eta the class
# prior; the stopping rule (ours): 10% of the night's success episodes and of its other episodes held out (at least
# one of each), the held-out PU loss read every `every` steps, stop when it has not fallen by more than `min_delta`
# for `patience` reads, or at `max_steps`; the reward of the best read is kept
PU_REWARD = {"eta": 0.5, "lr": 3e-4, "valid_fraction": 0.1, "every": 250, "patience": 4, "min_delta": 1e-4,
             "max_steps": 20_000}  # fmt: skip
# the draft's PU reward + TD3+BC (the committed nights named `oril` before 2026-12-05): TD3+BC's settings, eta 0.5
ORIL_DRAFT = {"eta": 0.5, "alpha": 2.5, "policy_noise": 0.2, "noise_clip": 0.5, "delay": 2, "tau": 0.005,
              "gamma": 0.99, "lr": 3e-4}  # fmt: skip


def nn_pu_loss(f_expert: torch.Tensor, f_other: torch.Tensor, eta: float) -> torch.Tensor:
    # pu_loss on logits f (d = sigmoid(f), -log d = softplus(-f), -log(1 - d) = softplus(f)), its negative part
    # E_o[-log(1 - d)] - eta E_e[-log(1 - d)] kept at or above 0 (the non-negative estimator, Kiryo et al. 2017):
    # without it the loss runs to -inf once the success rows are fitted (NaN by 2,000 steps on the tests' day)
    negative = F.softplus(f_other).mean() - eta * F.softplus(f_expert).mean()
    return eta * F.softplus(-f_expert).mean() + negative.clamp(min=0.0)


def td3bc_actor_loss(q_pi: torch.Tensor, pi_action: torch.Tensor, action: torch.Tensor, alpha: float) -> torch.Tensor:
    # TD3+BC: -lambda E[Q(s, pi(s))] + E[(pi(s) - a)^2], lambda = alpha / E|Q(s, pi(s))| held fixed
    return -alpha / q_pi.abs().mean().detach() * q_pi.mean() + (pi_action - action).pow(2).mean()


def mean_action(actor, obs: torch.Tensor) -> torch.Tensor:  # the actor as a deterministic policy, in the env's bounds
    return torch.tanh(actor(obs)[0]) * actor.action_scale + actor.action_bias


def td3bc_step(night, cfg: dict, batch: tuple, inputs: tuple, r: torch.Tensor) -> torch.Tensor:
    """One TD3+BC step of `night` (its critic, actor and their targets) on the rewards `r`: the twin critics towards
    r + gamma min Q'(s', pi'(s') + clipped noise), and every `delay`-th call the actor (its mean action, on the raw
    states) on lambda Q plus cloning the batch's actions, then both targets follow softly. `inputs`: the critics' (s,
    s'), raw or normalised. The critics' loss."""
    (obs, actions, next_obs, _, terminated), (obs_in, next_in) = batch, inputs
    scale, bias = night.actor.action_scale, night.actor.action_bias
    with torch.no_grad():  # TD3's target: clipped noise on the target actor's action, the twins' minimum
        noise = (torch.randn_like(actions) * cfg["policy_noise"]).clamp(-cfg["noise_clip"], cfg["noise_clip"])
        next_action = (mean_action(night.actor_target, next_obs) + noise * scale).clamp(bias - scale, bias + scale)
        y = r + (1.0 - terminated) * cfg["gamma"] * night.critic_target(next_in, next_action).min(0).values
    critic_loss = (night.critic(obs_in, actions) - y).pow(2).mean(-1).sum()
    night.critic_optimizer.zero_grad(set_to_none=True)
    critic_loss.backward()
    night.critic_optimizer.step()
    night.calls += 1
    if night.calls % cfg["delay"] == 0:
        night.critic.requires_grad_(False)  # the actor's gradient flows through Q1, but none is kept on it
        pi = mean_action(night.actor, obs)
        night.pi_loss = td3bc_actor_loss(night.critic(obs_in, pi)[0], pi, actions, cfg["alpha"])
        night.actor_optimizer.zero_grad(set_to_none=True)
        night.pi_loss.backward()
        night.critic.requires_grad_(True)
        night.actor_optimizer.step()
        core.soft_update(night.critic_target, night.critic, cfg["tau"])
        core.soft_update(night.actor_target, night.actor, cfg["tau"])
    return critic_loss


def reward_network(obs_dim: int) -> torch.nn.Module:  # R(s) = sigmoid(f(s))
    nn, hidden = torch.nn, core.HIDDEN_SIZE
    return nn.Sequential(
        nn.Linear(obs_dim, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, 1)
    )


def episode_split(buffer, rows: torch.Tensor, positive: torch.Tensor, fraction: float, seed: int):
    """(training rows, held-out rows) of the night's rows, by episode: `fraction` of its success episodes and of its
    other episodes (at least one of each), drawn by the seed; a kind with a single episode keeps it in both."""
    g = torch.Generator().manual_seed(seed + 16)
    night, good = torch.zeros(buffer.size, dtype=torch.bool), torch.zeros(buffer.size, dtype=torch.bool)
    night[rows.cpu()], good[positive.cpu()] = True, True
    train, held = night.clone(), torch.zeros(buffer.size, dtype=torch.bool)
    for kind in (True, False):
        episodes = [(s, e) for s, e, _ in buffer.episodes if night[s] and bool(good[s]) == kind]
        k = max(1, round(fraction * len(episodes))) if episodes else 0
        for i in torch.randperm(len(episodes), generator=g)[:k].tolist():
            start, end = episodes[i]
            held[start:end], train[start:end] = True, len(episodes) == 1
    return train.nonzero().squeeze(-1).to(rows.device), held.nonzero().squeeze(-1).to(rows.device)


def learn_pu_reward(reward, obs: torch.Tensor, positive: torch.Tensor, unlabelled: torch.Tensor, held: tuple,
                    batch_size: int) -> dict:  # fmt: skip
    """ORIL's first stage: R(s) = sigmoid(f(s)) learns, by the non-negative PU loss, the success set's observations
    (`positive`) against the whole night's (`unlabelled`), until the held-out loss (on `held`: its positive and
    unlabelled rows) stops falling (PU_REWARD's rule); the best read's weights are kept, then frozen. Its record."""
    optimizer = torch.optim.Adam(reward.parameters(), lr=PU_REWARD["lr"], foreach=True)
    device, eta = obs.device, PU_REWARD["eta"]
    best, best_step, state, waited, step = math.inf, 0, None, 0, 0
    while step < PU_REWARD["max_steps"] and waited < PU_REWARD["patience"]:
        for _ in range(PU_REWARD["every"]):
            p = positive[torch.randint(0, positive.numel(), (batch_size,), device=device)]
            u = unlabelled[torch.randint(0, unlabelled.numel(), (batch_size,), device=device)]
            loss = nn_pu_loss(reward(obs[p]).squeeze(-1), reward(obs[u]).squeeze(-1), eta)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
        step += PU_REWARD["every"]
        with torch.no_grad():
            held_loss = nn_pu_loss(reward(obs[held[0]]).squeeze(-1), reward(obs[held[1]]).squeeze(-1), eta).item()
        if held_loss < best - PU_REWARD["min_delta"]:
            best, best_step, state, waited = held_loss, step, copy.deepcopy(reward.state_dict()), 0
        else:
            waited += 1
    reward.load_state_dict(state)
    reward.requires_grad_(False)
    return {"pu_reward/steps": step, "pu_reward/best_step": best_step, "pu_reward/held_out_loss": best,
            "pu_reward/converged": int(waited >= PU_REWARD["patience"])}  # fmt: skip


class NormalisedActor(core.Actor):
    """The core's actor on states normalised by the day's mean and std (TD3+BC's normalisation): built from an actor
    on raw states with the normalisation folded into its first layer, so that it starts as the same policy;
    `raw()` folds it back into a core Actor on raw states (what is saved and tested)."""

    def __init__(self, actor: core.Actor, mean: torch.Tensor, std: torch.Tensor):
        scale, bias = actor.action_scale, actor.action_bias
        super().__init__(actor.fc1.in_features, actor.fc_mean.out_features, actor.fc1.out_features, bias - scale,
                         bias + scale)  # fmt: skip
        self.to(mean.device)
        self.load_state_dict(actor.state_dict())
        self.mean, self.std = mean, std  # not in the state_dict: raw() is what is saved
        with torch.no_grad():  # W s + b = (W std) z + (b + W mean), z = (s - mean) / std
            self.fc1.bias += self.fc1.weight @ mean
            self.fc1.weight *= std

    def forward(self, obs):
        return super().forward((obs - self.mean) / self.std)

    def raw(self) -> core.Actor:
        scale, bias = self.action_scale, self.action_bias
        actor = core.Actor(self.fc1.in_features, self.fc_mean.out_features, self.fc1.out_features, bias - scale,
                           bias + scale).to(self.mean.device)  # fmt: skip
        actor.load_state_dict(self.state_dict())
        with torch.no_grad():
            actor.fc1.weight /= self.std
            actor.fc1.bias -= actor.fc1.weight @ self.mean
        return actor


class PUTD3BCNight(StudyNight):
    """A PU reward + TD3+BC as the night (`pu_td3bc`), staged as ORIL stages its method (Zolna et al. 2020): first the
    reward R(s) is learned on the night's rows to convergence (learn_pu_reward), then frozen: the day relabelled with
    it; then TD3+BC learns on the relabelled day, its states normalised by the night's mean and std (TD3+BC's default):
    twin critics towards R(s) + gamma min Q'(s', pi'(s') + clipped noise), the actor (its mean action) every 2nd step on
    lambda Q plus cloning the day's actions. ORIL's offline learner was CRR; this is TD3+BC, so it is not named ORIL.
    The actor starts from TAMER's (the normalisation folded into its first layer); the soft Q sleeps as usual."""

    hears = {"batch_size", "q_lr", "temperature", "chi2_coef", "init_actor_from_tamer", "loss_rows", "twin_critics",
             "holdout_fraction"}  # fmt: skip
    fixed = {"policy_lr": TD3BC["lr"], "policy_frequency": 1}  # one TD3+BC step per night step; the actor's own delay

    def __init__(self, tamer_actor, device, **settings):
        super().__init__(tamer_actor, device, **settings)
        obs_dim, act_dim = tamer_actor.fc1.in_features, tamer_actor.fc_mean.out_features
        self.reward = reward_network(obs_dim).to(device)
        self.critic = core.QEnsemble(obs_dim, act_dim, core.HIDDEN_SIZE, n=2).to(device)
        self.critic_target = copy.deepcopy(self.critic)
        self.critic_optimizer = torch.optim.Adam(self.critic.parameters(), lr=TD3BC["lr"], foreach=True)
        self.batch_size, self.seed = settings["batch_size"], self.holdout[1]
        self.calls, self.reward_record = 0, {}
        self.obs_mean = self.obs_std = None

    def memories(self, buffer):
        replay_idx, expert_idx, fallback = super().memories(buffer)
        rows = torch.arange(buffer.size, device=expert_idx.device) if replay_idx is None else replay_idx
        train, held = episode_split(buffer, rows, expert_idx, PU_REWARD["valid_fraction"], self.seed)
        good = torch.isin(train, expert_idx)
        self.reward_record = learn_pu_reward(self.reward, buffer.obs, train[good], train,
                                             (held[torch.isin(held, expert_idx)], held), self.batch_size)  # fmt: skip
        states = buffer.obs[rows]
        self.obs_mean, self.obs_std = states.mean(0), states.std(0, unbiased=False) + TD3BC["std_eps"]
        self.actor = NormalisedActor(self.actor, self.obs_mean, self.obs_std)
        self.actor_optimizer = torch.optim.Adam(self.actor.parameters(), lr=TD3BC["lr"], foreach=True)
        self.actor_target = copy.deepcopy(self.actor)
        return replay_idx, expert_idx, fallback

    def relabelled(self, obs: torch.Tensor) -> torch.Tensor:  # the frozen reward: the day relabelled
        return torch.sigmoid(self.reward(obs).squeeze(-1))

    def update_actor(self, batch):
        obs, _, next_obs, _, _ = batch
        z, next_z = (obs - self.obs_mean) / self.obs_std, (next_obs - self.obs_mean) / self.obs_std
        with torch.no_grad():
            r = self.relabelled(obs)
        critic_loss = td3bc_step(self, TD3BC, batch, (z, next_z), r)
        self.method_terms = {"pu_td3bc_critic_loss": critic_loss.detach(), "pu_reward_expert": r[self.is_expert].mean(),
                             "pu_reward_other": r[~self.is_expert].mean()}  # fmt: skip

    def stats(self):  # the actor back on raw states (saved, tested), and what the reward's stage did
        stats = super().stats()
        if isinstance(self.actor, NormalisedActor):
            self.actor = self.actor.raw()
        if self.selected is not None and isinstance(self.selected["actor"], NormalisedActor):
            self.selected = {**self.selected, "actor": self.selected["actor"].raw()}
        return {**stats, **self.reward_record}


class DraftORILNight(StudyNight):
    """The draft of the ORIL night (`oril_draft`; the committed nights named `oril` before 2026-12-05), kept to re-run
    them: a PU reward and TD3+BC learned together, not ORIL (which learns its reward first, then CRR). Each step the
    reward R(s) = sigmoid(f(s)) learns, by nn_pu_loss, the success set's observations against the whole day's (the
    replay rows), and TD3+BC learns on the batch labelled with R as it is at that step, on raw states: twin critics
    towards R(s) + gamma min Q'(s', pi'(s') + clipped noise), the actor (its mean action) every 2nd step on lambda Q
    plus cloning the day's actions. The actor starts from TAMER's; the soft Q sleeps as usual."""

    hears = {"batch_size", "q_lr", "temperature", "chi2_coef", "init_actor_from_tamer", "loss_rows", "twin_critics",
             "holdout_fraction"}  # fmt: skip
    fixed = {"policy_lr": ORIL_DRAFT["lr"], "policy_frequency": 1}  # one TD3+BC step a night step; its own delay

    def __init__(self, tamer_actor, device, **settings):
        super().__init__(tamer_actor, device, **settings)
        obs_dim, act_dim, nn = tamer_actor.fc1.in_features, tamer_actor.fc_mean.out_features, torch.nn
        self.reward = nn.Sequential(nn.Linear(obs_dim, core.HIDDEN_SIZE), nn.ReLU(),
                                    nn.Linear(core.HIDDEN_SIZE, core.HIDDEN_SIZE), nn.ReLU(),
                                    nn.Linear(core.HIDDEN_SIZE, 1)).to(device)  # fmt: skip
        self.critic = core.QEnsemble(obs_dim, act_dim, core.HIDDEN_SIZE, n=2).to(device)
        self.critic_target, self.actor_target = copy.deepcopy(self.critic), copy.deepcopy(self.actor)
        self.r_optimizer = torch.optim.Adam(self.reward.parameters(), lr=ORIL_DRAFT["lr"], foreach=True)
        self.critic_optimizer = torch.optim.Adam(self.critic.parameters(), lr=ORIL_DRAFT["lr"], foreach=True)
        self.calls = 0

    def update_actor(self, batch):
        obs, _, next_obs, _, _ = batch
        f = self.reward(obs).squeeze(-1)  # R(s) = sigmoid(f(s))
        r_loss = nn_pu_loss(f[self.is_expert], f[~self.is_expert], ORIL_DRAFT["eta"])
        self.r_optimizer.zero_grad(set_to_none=True)
        r_loss.backward()
        self.r_optimizer.step()
        r = torch.sigmoid(f.detach())  # the reward as it was before this step's update
        critic_loss = td3bc_step(self, ORIL_DRAFT, batch, (obs, next_obs), r)
        self.method_terms = {"oril_reward_loss": r_loss.detach(), "oril_critic_loss": critic_loss.detach(),
                             "oril_reward_expert": r[self.is_expert].mean(),
                             "oril_reward_other": r[~self.is_expert].mean()}  # fmt: skip


CONTROLS = {"bc": CloningControl, "sham": ShamControl}  # by --sleep-control
METHODS = {
    "iq": StudyNight,
    "dwbc": DWBCNight,
    "pu_td3bc": PUTD3BCNight,
    "dwbc_draft": DraftDWBCNight,
    "oril_draft": DraftORILNight,
}  # by --sleep-method


def run(argv: list[str]) -> int:
    args = untyped_to_protocol(tyro.cli(Args, args=argv), argv)
    if args.sleep_control != "none" and args.sleep_method != "iq":
        print(f"error: --sleep-control {args.sleep_control} replaces the night, so --sleep-method {args.sleep_method} "
              "would not run: give one of them", file=sys.stderr)  # fmt: skip
        return 2
    if flags := unheard(args):
        night = (
            f"--sleep-control {args.sleep_control}"
            if args.sleep_control != "none"
            else f"--sleep-method {args.sleep_method}"
        )
        uses = ", ".join(sorted(args.night_kind().hears))
        print(f"error: {' and '.join(flags)} would not change {night} (it uses only {uses}): leave it unset",
              file=sys.stderr)  # fmt: skip
        return 2
    return core.cli(args)


if __name__ == "__main__":
    sys.exit(run(sys.argv[1:]))
