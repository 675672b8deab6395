"""The reward INFORM recovers on a continuous task (Eq. 3), for any Gymnasium agent: `load` rebuilds it from a run of
inform_sac_pusher.py (its inform_critic.pt and inform_actor.pt), and `RecoveredRewardWrapper` gives an env that
reward, the env's own in info["env_reward"]. imitation's habit: a learned reward is an object with one call,
reward(obs, action, next_obs, terminated) -> array, and a wrapper.

    from inform_utils.recovered_reward import RecoveredRewardWrapper, load
    env = RecoveredRewardWrapper(gym.make("Pusher-v5"), load("runs/<run>"))
"""

import os

import gymnasium as gym
import torch

import inform_sac_pusher as isp


def load(run_dir: str, samples: int = 16) -> isp.RecoveredReward:
    """The recovered reward of a run: its INFORM critic and actor, each checked (CRC-32) and read weights-only."""
    for name in ("inform_critic.pt", "inform_actor.pt"):
        isp.check_crc(os.path.join(run_dir, name), os.path.join(run_dir, name))
    critic = torch.load(os.path.join(run_dir, "inform_critic.pt"), weights_only=True)
    q_net = isp.QEnsemble(**critic["kwargs"])
    q_net.load_state_dict(critic["state_dict"])
    actor = isp.actor_from_checkpoint(torch.load(os.path.join(run_dir, "inform_actor.pt"), weights_only=True))
    return isp.RecoveredReward(q_net, actor, critic["gamma"], critic["temperature"], samples)


class RecoveredRewardWrapper(gym.Wrapper):
    """Any Gymnasium agent trains on the recovered reward; the env's own goes to info['env_reward']."""

    def __init__(self, env: gym.Env, reward_fn: isp.RecoveredReward):
        super().__init__(env)
        self.reward_fn, self._obs = reward_fn, None

    def reset(self, **kwargs):
        self._obs, info = self.env.reset(**kwargs)
        return self._obs, info

    def step(self, action):
        next_obs, reward, terminated, truncated, info = self.env.step(action)
        new_reward, self._obs = float(self.reward_fn(self._obs, action, next_obs, terminated)[0]), next_obs
        return next_obs, new_reward, terminated, truncated, {**info, "env_reward": reward}
