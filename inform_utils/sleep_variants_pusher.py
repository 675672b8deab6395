"""The sleep study's variants of the Pusher night, on inform_sac_pusher.py's declared surface (as CleanRL's evaluation
helpers import a script's agent): the actor's start and its states, its schedule, the rows of Eq. 2's value and
chi-squared terms, twin critics, a behaviour-cloning term, the sham and cloning controls, and the hold-out offline
criterion that picks a checkpoint without the environment.

It runs like the core script, normally on a saved day, with the study's switches on top, and writes the same run
directory, files and summary.json (`sleep_variant` and the study's flags in `args`). With no study flag it gives the
core's numbers; with the flags of commit cdfc757's script it gives that script's numbers.

    python -m inform_utils.sleep_variants_pusher --sleep-from runs/<day> --sleep-seed 1 --sleep-control sham
    python -m inform_utils.sleep_variants_pusher --sleep-from runs/<day> --sleep-holdout-fraction 0.15 \
        --sleep-twin-critics --sleep-loss-rows expert
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
import tyro  # noqa: E402

import inform_sac_pusher as core  # noqa: E402


@dataclass
class Args(core.Args):
    # The sleep study's switches (docs/protocol.md, "Saved days and the sleep's variants")
    sleep_control: Literal["none", "bc", "sham"] = "none"
    """a control in place of the INFORM actor's update, same steps: bc = behaviour cloning on the success set (the
    mean action's squared error on the expert rows); sham = TAMER's own update (H on the feedback, the actor on H),
    no consolidation. The soft Q network sleeps as usual"""
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
    """a behaviour-cloning term on the INFORM actor, TD3+BC style: the Q objective divided by mean |Q|, plus this
    weight times the squared error of the mean action on the expert rows; 0 turns it off"""
    sleep_holdout_fraction: Annotated[float, core.In(0, 1)] = 0.0
    """hold this fraction of the day's episodes out of the sleep (split by episode, fixed by the seed) and log the
    offline criterion on them every 1,000 steps; the checkpoint it picks is kept and tested as `inform_selected`"""


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

    def __init__(self, args: Args, buffer, held: torch.Tensor, writer):
        self.args = args
        self.writer = writer
        self.batch = buffer.batch(held)
        self.success = buffer.success[held]
        starts = torch.tensor([start for start, _, _ in buffer.episodes], device=held.device)
        self.episodes = int(torch.isin(starts, held).sum())
        self.best = -math.inf
        self.selected = None  # {"step", "actor"} of the best checkpoint so far
        self.last = {}
        self.q_pi_previous = None

    @torch.no_grad()
    def __call__(self, step: int, q_net, q_target, actor) -> float:
        args = self.args
        obs, actions, next_obs, _, terminated = self.batch
        cuda = obs.device.type == "cuda"
        with torch.random.fork_rng(devices=[torch.cuda.current_device()] if cuda else []):  # the sleep's RNG untouched
            expert = self.success.nonzero().squeeze(-1)
            loglik = actor.log_prob(obs[expert], actions[expert]).mean().item() if expert.numel() else float("nan")
            rows = self.success if args.sleep_loss_rows == "expert" else None
            gamma, temp, chi2 = core.SLEEP_GAMMA, args.sleep_temperature, args.sleep_chi2_coef
            loss, terms = core.iq_loss(
                q_net, q_target, obs, actions, next_obs, terminated, self.success, gamma, temp, chi2, actor, rows
            )
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
            self.writer.add_scalar(tag, value, step)
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


def sleep_phase(args: Args, buffer, tamer_actor, evaluator, writer, device, h_net=None, ent_coef=1.0):
    """The core's night with the study's switches (the core's sleep_phase is this with every switch at its default).
    TAMER's H and entropy coefficient at the day's end are needed only by the sham control. Returns the soft Q, the
    INFORM actor, the stats and, with a hold-out, the checkpoint the offline criterion picked (else None)."""
    recipe = core.sleep_recipe(args)
    held = held_out(args.sleep_holdout_fraction, args.seed, buffer, device)  # episodes the sleep never sees
    keep = torch.ones(buffer.size, dtype=torch.bool, device=device)
    if held is not None:
        keep[held] = False
    replay_idx = keep.nonzero().squeeze(-1)
    expert_idx, fallback_episodes = buffer.expert_indices(keep)
    if fallback_episodes:
        print(
            f"[sleep] warning: no successful episode; using the {fallback_episodes} episodes that came closest "
            "(the smallest final distance, or with --success-return the highest return) as the expert set",
            flush=True,
        )
    print(f"[sleep] {expert_idx.numel()} expert transitions, {replay_idx.numel()} in the buffer", flush=True)
    obs_dim, act_dim, hidden = buffer.obs.shape[1], buffer.actions.shape[1], core.HIDDEN_SIZE
    n_critics = 2 if args.sleep_twin_critics else 1
    q_net = core.QEnsemble(obs_dim, act_dim, hidden, n=n_critics).to(device)
    q_target = core.QEnsemble(obs_dim, act_dim, hidden, n=n_critics).to(device)
    q_target.load_state_dict(q_net.state_dict())
    low = tamer_actor.action_bias - tamer_actor.action_scale
    high = tamer_actor.action_bias + tamer_actor.action_scale
    inform_actor = core.Actor(obs_dim, act_dim, hidden, low, high).to(device)
    if recipe["sleep_init_actor_from_tamer"] or args.sleep_control == "sham":
        inform_actor.load_state_dict(tamer_actor.state_dict())
    q_optimizer = torch.optim.Adam(q_net.parameters(), lr=args.sleep_q_lr, foreach=True)
    policy_lr = core.TAMER_POLICY_LR if args.sleep_control == "sham" else args.sleep_policy_lr
    inform_optimizer = torch.optim.Adam(inform_actor.parameters(), lr=policy_lr, foreach=True)
    if args.sleep_control == "sham":  # TAMER goes on learning from its memories: H and the actor, TAMER's rates
        sham_h = core.QEnsemble(obs_dim, act_dim, hidden, n=2).to(device)
        sham_h.load_state_dict(h_net.state_dict())
        sham_h_optimizer = torch.optim.Adam(sham_h.parameters(), lr=args.tamer_h_lr, foreach=True)
        log_ent_coef = torch.full((1,), math.log(ent_coef), device=device, requires_grad=True)
        ent_coef_optimizer = torch.optim.Adam([log_ent_coef], lr=args.tamer_h_lr, foreach=True)
    batch_size, gamma = args.sleep_batch_size, core.SLEEP_GAMMA
    temp, chi2 = args.sleep_temperature, args.sleep_chi2_coef
    is_expert = torch.arange(2 * batch_size, device=device) >= batch_size  # the batch: replay rows, then expert rows
    rows = is_expert if args.sleep_loss_rows == "expert" else None  # of the value and chi2 terms
    actor_rows = {"replay": ~is_expert, "expert": is_expert, "replay+expert": slice(None)}[recipe["sleep_actor_states"]]
    frequency, steps = recipe["sleep_policy_frequency"], recipe["sleep_gradient_steps"]
    stats = {"sleep/expert_transitions": int(expert_idx.numel()), "sleep/expert_fallback": int(fallback_episodes > 0)}
    losses = {}
    criterion = OfflineCriterion(args, buffer, held, writer) if held is not None else None
    pi_loss = torch.zeros((), device=device)
    progress = core.Progress("sleep", steps, evaluator=evaluator)
    for step in range(1, steps + 1):
        core.StopSignals.check()
        obs, actions, next_obs, feedback, terminated = core.sleep_batch(buffer, batch_size, expert_idx, replay_idx)
        loss, terms = core.iq_loss(
            q_net, q_target, obs, actions, next_obs, terminated, is_expert, gamma, temp, chi2, inform_actor, rows
        )
        q_optimizer.zero_grad(set_to_none=True)
        loss.backward()
        q_optimizer.step()
        for _ in range(frequency if step % frequency == 0 else 0):
            if args.sleep_control == "sham":  # control: TAMER's own update (Eq. 1, then its actor on H), no Q
                pi_loss = core.tamer_loss(sham_h, obs[~is_expert], actions[~is_expert], feedback[~is_expert])
                sham_h_optimizer.zero_grad(set_to_none=True)
                pi_loss.backward()
                sham_h_optimizer.step()
                core.update_actor(
                    sham_h, inform_actor, obs[~is_expert], log_ent_coef, inform_optimizer, ent_coef_optimizer
                )
                continue
            q_net.requires_grad_(False)  # the actor's gradient flows through Q, but none is kept on it
            if args.sleep_control == "bc":  # control: behaviour cloning on the success set, no Q
                pi_loss = (inform_actor.get_action(obs[is_expert])[2] - actions[is_expert]).pow(2).mean()
            else:
                pi_loss, _ = core.actor_loss(q_net, inform_actor, obs[actor_rows], temp)
            if args.sleep_bc_coef > 0:  # TD3+BC: the Q objective made scale-free, plus cloning the experts
                pi_loss = (
                    pi_loss / q_net(obs, actions).abs().mean().detach()
                    + args.sleep_bc_coef
                    * (inform_actor.get_action(obs[is_expert])[2] - actions[is_expert]).pow(2).mean()
                )
            inform_optimizer.zero_grad(set_to_none=True)
            pi_loss.backward()
            q_net.requires_grad_(True)
            inform_optimizer.step()
        core.soft_update(q_target, q_net, core.TAU)

        last_step = step == steps
        if step % core.LOG_FREQUENCY == 0 or last_step or step % 100 == 0:
            tags = {"iq_loss": loss, **terms, "inform_actor_loss": pi_loss}
            losses = core.check_finite(
                tags, losses, "the sleep loss", f"gradient step {step}", "--sleep-q-lr or --sleep-policy-lr"
            )
        if step % core.LOG_FREQUENCY == 0 or last_step:
            for tag, value in losses.items():
                writer.add_scalar(tag, value, step)
            writer.add_scalar("sleep/SPS", progress.sps(step), step)
        report = {"iq_loss": losses.get("losses/iq_loss")}
        if step % core.SLEEP_EVAL_FREQUENCY == 0 or last_step:
            metrics = evaluator("inform", inform_actor, step, core.PERIODIC_EVAL_EPISODES)
            report["eval return"] = metrics["eval/inform_return"]
            if criterion is not None:  # no environment: the held-out episodes only
                report["criterion"] = criterion(step, q_net, q_target, inform_actor)
        progress(step, **report)
    selected = None
    if criterion is not None:
        stats.update(criterion.stats())
        selected = criterion.selected
    return q_net, inform_actor, {**stats, **losses}, selected


if __name__ == "__main__":
    sys.exit(core.cli(untyped_to_protocol(tyro.cli(Args), sys.argv[1:]), sleep=sleep_phase))
