"""The maze's sleep study: the variants of the night that inform_utils/sleep_study.py compares, beside the core script
(as CleanRL's evaluation helpers import a script's agent). It runs exactly as inform_dqn_gridworld.py does (the same
run directory, files, summary.json and lines), normally on a saved day, with the study's switches added:

    python -m inform_utils.sleep_variants_maze --sleep-from runs/<day> --sleep-seed 1 --sleep-control sham
    python -m inform_utils.sleep_variants_maze --sleep-from runs/<day> --sleep-loss-rows expert

--sleep-loss-rows expert: the value and chi-squared terms of Eq. 2 on the expert rows only (IQ-Learn's offline recipe,
its `value_expert` loss). --sleep-control bc: behaviour cloning on the success set in place of Eq. 2 (cross-entropy of
Q(s, .) / temperature on the expert rows); sham: TAMER's own update (H from the day's, Eq. 1 on the replay rows), no
consolidation. Same steps and batches as the night. With neither switch, the core's night, number for number. A night
flag that the chosen control does not use (`hears`) is refused in one line, never recorded as if it ran.
"""

import copy
import sys
from dataclasses import dataclass, fields
from typing import Literal

import torch
import torch.nn.functional as F
import tyro

import inform_dqn_gridworld as core


class StudySleep(core.Sleep):
    """The core's night with the study's switch: Eq. 2's value and chi-squared terms on all rows or the expert rows
    only. At its default, the core's night, number for number; a term added to the core's `loss` runs here too."""

    hears = None  # the night settings this night uses (None: all); a flag for any other is refused

    def __init__(self, obs_dim, n_actions, device, *, loss_rows: str, **settings):
        super().__init__(obs_dim, n_actions, device, **settings)
        self.loss_rows = loss_rows

    def loss(self, obs, actions, next_obs, feedback, terminated, is_expert, **kw):
        rows = is_expert if self.loss_rows == "expert" else None
        return super().loss(obs, actions, next_obs, feedback, terminated, is_expert, rows=rows, **kw)


class CloningControl(StudySleep):
    """Behaviour cloning on the success set: cross-entropy of Q(s, .) / temperature on the expert rows, no Eq. 2."""

    tag = "bc_loss"
    hears = {"q_lr", "temperature"}

    def loss(self, obs, actions, next_obs, feedback, terminated, is_expert, **kw):
        return F.cross_entropy(self.q_net(obs[is_expert]) / self.temperature, actions[is_expert]), {}


class ShamControl(StudySleep):
    """TAMER goes on learning from its memories at its own rate: H from the day's, Eq. 1 on the replay rows."""

    tag = "sham_loss"
    hears = {"temperature"}  # H's own rate (--tamer-h-lr), no Eq. 2; the recovered reward's temperature (from H)

    def __init__(self, obs_dim, n_actions, device, *, h_net, h_lr, **settings):
        super().__init__(obs_dim, n_actions, device, **settings)
        self.q_net, self.q_target = copy.deepcopy(h_net), copy.deepcopy(h_net)  # the day's H as the day built it
        self.optimizer = torch.optim.Adam(self.q_net.parameters(), lr=h_lr, fused=True)

    def loss(self, obs, actions, next_obs, feedback, terminated, is_expert, **kw):
        return core.tamer_loss(self.q_net, obs[~is_expert], actions[~is_expert], feedback[~is_expert]), {}


@dataclass
class Args(core.Args):
    sleep_loss_rows: Literal["all", "expert"] = "all"
    """the rows of Eq. 2's value and chi-squared terms: the whole batch (the paper), or the expert rows only
    (IQ-Learn's offline recipe, its `value_expert` loss)"""
    sleep_control: Literal["none", "bc", "sham"] = "none"
    """a control in place of the sleep, same steps and batches: bc = behaviour cloning on the success set; sham =
    TAMER's own update (H from the day's, Eq. 1 on the replay rows), no consolidation"""

    def night_settings(self) -> dict:
        return super().night_settings() | {"loss_rows": self.sleep_loss_rows}

    def sleep_learner(self, obs_dim, n_actions, h_net, device) -> core.Sleep:
        kind = NIGHTS[self.sleep_control]
        extra = {"h_net": h_net, "h_lr": self.tamer_h_lr} if kind is ShamControl else {}  # it goes on from the day's H
        return kind(obs_dim, n_actions, device, **self.night_settings(), **extra)

    def sleep_variant(self) -> str:
        """The core's line with only the settings the chosen night uses (and the sham's H rate): what ran."""
        kind, words = NIGHTS[self.sleep_control], super().sleep_variant().split()
        if kind.hears is not None:
            words = [w for w in words if w.split("=")[0] not in set(self.night_settings()) - kind.hears]
        words += [f"h_lr={self.tamer_h_lr}"] if kind is ShamControl else []
        return f"control={self.sleep_control} " + " ".join(words)


NIGHTS = {"none": StudySleep, "bc": CloningControl, "sham": ShamControl}  # by --sleep-control


def unheard(args: Args) -> list[str]:
    """The night flags set (away from their defaults) that the chosen night does not use: a control hears only some."""
    hears = NIGHTS[args.sleep_control].hears
    defaults = {f.name: f.default for f in fields(Args)}
    flags = [f"sleep_{k}" for k in args.night_settings() if hears is not None and k not in hears]
    return [f"--{flag.replace('_', '-')}" for flag in flags
            if getattr(args, flag, None) is not None and getattr(args, flag) != defaults.get(flag)]  # fmt: skip


def run(argv: list[str]) -> int:
    args = tyro.cli(Args, args=argv)
    if flags := unheard(args):
        uses = ", ".join(sorted(NIGHTS[args.sleep_control].hears)) or "none of them"
        print(f"error: {' and '.join(flags)} would not change --sleep-control {args.sleep_control} (of the night's "
              f"settings it uses {uses}): leave it unset", file=sys.stderr)  # fmt: skip
        return 2
    return core.cli(args)


if __name__ == "__main__":
    sys.exit(run(sys.argv[1:]))
