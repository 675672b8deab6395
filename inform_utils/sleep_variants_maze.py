"""The maze's sleep study: the variants of the night that inform_utils/sleep_study.py compares, beside the core script
(as CleanRL's evaluation helpers import a script's agent). It runs exactly as inform_dqn_gridworld.py does (the same
run directory, files, summary.json and lines), normally on a saved day, with the study's switches added:

    python -m inform_utils.sleep_variants_maze --sleep-from runs/<day> --sleep-seed 1 --sleep-control sham
    python -m inform_utils.sleep_variants_maze --sleep-from runs/<day> --sleep-loss-rows expert

--sleep-loss-rows expert: the value and chi-squared terms of Eq. 2 on the expert rows only (IQ-Learn's offline recipe,
its `value_expert` loss). --sleep-control bc: behaviour cloning on the success set in place of Eq. 2 (cross-entropy of
Q(s, .) / temperature on the expert rows); sham: TAMER's own update (H from the day's, Eq. 1 on the replay rows), no
consolidation. Same steps and batches as the night. With neither switch, the core's night, number for number.
"""

import sys
from dataclasses import dataclass
from typing import Literal

import torch
import torch.nn.functional as F

import inform_dqn_gridworld as core


class ExpertRows(core.Sleep):
    """Eq. 2 with its value and chi-squared terms on the expert rows only."""

    def loss(self, obs, actions, next_obs, feedback, terminated, is_expert):
        return core.iq_loss(self.q_net, self.q_target, obs, actions, next_obs, terminated, is_expert, self.gamma,
                            self.temperature, self.chi2_coef, rows=is_expert)  # fmt: skip


class CloningControl(core.Sleep):
    """Behaviour cloning on the success set: cross-entropy of Q(s, .) / temperature on the expert rows, no Eq. 2."""

    tag = "bc_loss"

    def loss(self, obs, actions, next_obs, feedback, terminated, is_expert):
        return F.cross_entropy(self.q_net(obs[is_expert]) / self.temperature, actions[is_expert]), {}


class ShamControl(core.Sleep):
    """TAMER goes on learning from its memories at its own rate: H from the day's, Eq. 1 on the replay rows."""

    tag = "sham_loss"

    def __init__(self, obs_dim, n_actions, lr, temperature, chi2_coef, device, h_net, h_lr):
        super().__init__(obs_dim, n_actions, lr, temperature, chi2_coef, device)
        self.q_net.load_state_dict(h_net.state_dict())
        self.optimizer = torch.optim.Adam(self.q_net.parameters(), lr=h_lr, fused=True)

    def loss(self, obs, actions, next_obs, feedback, terminated, is_expert):
        return core.tamer_loss(self.q_net, obs[~is_expert], actions[~is_expert], feedback[~is_expert]), {}


@dataclass
class Args(core.Args):
    sleep_loss_rows: Literal["all", "expert"] = "all"
    """the rows of Eq. 2's value and chi-squared terms: the whole batch (the paper), or the expert rows only
    (IQ-Learn's offline recipe, its `value_expert` loss)"""
    sleep_control: Literal["none", "bc", "sham"] = "none"
    """a control in place of the sleep, same steps and batches: bc = behaviour cloning on the success set; sham =
    TAMER's own update (H from the day's, Eq. 1 on the replay rows), no consolidation"""

    def sleep_learner(self, obs_dim, n_actions, h_net, device) -> core.Sleep:
        hp = (obs_dim, n_actions, self.sleep_q_lr, self.sleep_temperature, self.sleep_chi2_coef, device)
        if self.sleep_control == "sham":
            return ShamControl(*hp, h_net=h_net, h_lr=self.tamer_h_lr)
        if self.sleep_control == "bc":
            return CloningControl(*hp)
        return (ExpertRows if self.sleep_loss_rows == "expert" else core.Sleep)(*hp)

    def sleep_variant(self) -> str:
        return (f"control={self.sleep_control} loss_rows={self.sleep_loss_rows} temperature={self.sleep_temperature} "
                f"steps={self.sleep_gradient_steps} seed={self.sleep_seed}")  # fmt: skip


if __name__ == "__main__":
    sys.exit(core.cli(Args))
