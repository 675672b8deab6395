"""Demonstrations for a teacher (oracle_train.py --demos): the .npz that `python -m inform_utils.pusher_control
--save-demos` writes, read without unpickling and checked against the run, as tensors for two buffers: every step
(RLPD's half of each batch, and the critics' warm-up) and the steps of the successful episodes (what --clone-steps
clones); and the pretraining that --clone-steps runs before SAC's first step.

    python -m inform_utils.pusher_control --episodes 150 --demonstrator mpc --first-seed 3000000 --save-demos d.npz
    python oracle_train.py --env-id Pusher-v5 --demos d.npz --layer-norm --total-timesteps 1000000
"""

import numpy as np
import torch

import inform_sac_pusher as isp
from inform_utils.files import BadFile, read_npz, sha256

# a step of pusher_control --save-demos: the transition, then the reward's terms (to re-weight it)
FIELDS = ("obs", "act", "next_obs", "rew", "term", "reward_dist", "reward_ctrl", "reward_near")
EPISODE_FIELDS = ("episode_seed", "episode_distance", "episode_success")


def read_demos(path: str, env, args, resume_state: dict | None, error: type[Exception]) -> dict:
    """{"all": FIELDS' tensors, "success": the same for the successful episodes' steps, "sha256", "steps"}; `error`
    (oracle_train's InputError), one line, for a file that is not such demonstrations, not the resumed run's, or
    not usable by the run (`args`: oracle_train's: --env-id, --reward-dist-weight, --total-timesteps, --clone-steps)."""
    env_id, reward_dist_weight = args.env_id, args.reward_dist_weight
    try:  # the shared reader: a directory, an .npy, a damaged archive, a missing array: each one line
        digest, data = sha256(path), read_npz(path, (*FIELDS, *EPISODE_FIELDS, "env_id"))
    except BadFile as e:
        raise error(f"--demos {e}: not demonstrations of pusher_control --save-demos") from None
    if resume_state is not None and resume_state.get("demos_sha256") != digest:
        raise error(f"--demos {path}: not the demonstrations this run was trained with (their SHA-256 differs)")
    numbers = (*FIELDS, *EPISODE_FIELDS)  # each an array of numbers, one row a step or an episode
    if not_numbers := [k for k in numbers if data[k].ndim == 0 or data[k].dtype.kind not in "biuf"]:
        raise error(f"--demos {path}: {', '.join(not_numbers)}: not an array of numbers with a row a step or an "
                    "episode; not demonstrations of pusher_control --save-demos")  # fmt: skip
    contact = str(data.get("contact", "gymnasium"))  # saved before the setting: mujoco 4's
    if str(data["env_id"]) != env_id:
        raise error(f"--demos {path}: demonstrations of {data['env_id']}, not {env_id}")
    if contact != (ours := isp.contact_of(env_id, args.contact)):
        raise error(f"--demos {path}: made under the {contact} contact, this run's is {ours}; pass --contact {contact}")
    steps, episodes = len(data["rew"]), len(data["episode_seed"])
    obs_shape, act_shape = (steps, *env.observation_space.shape), (steps, *env.action_space.shape)
    fits = [
        data["act"].shape == act_shape,
        data["obs"].shape == data["next_obs"].shape == obs_shape,
        data["episode_success"].shape == (episodes,) and data["episode_success"].dtype == bool,
        episodes > 0 and steps == episodes * env.spec.max_episode_steps,  # whole episodes: Pusher never ends early
        *(data[name].shape == (steps,) for name in FIELDS[3:]),
    ]
    if not all(fits):
        raise error(f"--demos {path}: {steps} steps of {episodes} episodes, observations {data['obs'].shape[1:]} and "
                    f"actions {data['act'].shape[1:]}: not whole {env_id} episodes of pusher_control")  # fmt: skip
    low, high = env.action_space.low, env.action_space.high
    if not all(np.isfinite(data[name]).all() for name in FIELDS[:5]) or (data["act"] < low).any() or \
            (data["act"] > high).any():  # fmt: skip
        raise error(f"--demos {path}: holds NaN or inf, or actions outside {env_id}'s limits")
    if reward_dist_weight is not None:  # the reward re-weighted as the run's env weighs it (recorded at weight 1)
        terms = data["reward_dist"] * reward_dist_weight + data["reward_ctrl"] + data["reward_near"]
        if not np.isfinite(terms).all():
            raise error(f"--demos {path}: its steps lack the reward's terms that --reward-dist-weight needs")
        data["rew"] = terms.astype(np.float32)
    tensors = {name: torch.as_tensor(data[name], dtype=torch.float32) for name in FIELDS[:5]}
    success_rows = torch.as_tensor(np.repeat(data["episode_success"], env.spec.max_episode_steps))
    if steps >= args.total_timesteps or (args.clone_steps and not success_rows.any()):
        raise error(f"--demos {path}: its {steps} steps " + ("leave none of --total-timesteps" if
                    steps >= args.total_timesteps else "hold no successful episode to clone"))  # fmt: skip
    return {"all": tensors, "success": {name: t[success_rows] for name, t in tensors.items()}, "sha256": digest,
            "steps": steps}  # fmt: skip


def pretrain(sac, clone_rb, demo_rb, args, amp, stop) -> None:
    """--clone-steps N before SAC's first step: N steps of cloning the successful demonstrations into the actor
    (clone_step), then N steps of the critics alone on all of them (SAC's update, the actor not moved), so that the
    critics know the cloned actor's actions before they move it. `stop` is called before every step."""
    for _ in range(args.clone_steps):
        stop()
        clone_step(sac, clone_rb.sample(args.batch_size))
    for _ in range(args.clone_steps):
        stop()
        sac.update(demo_rb.sample(args.batch_size), args.gamma, args.tau, False, amp)


def clone_step(sac, batch) -> None:
    """One gradient step of SAC's actor on -log pi(a|s) of the demonstrated actions (behaviour cloning); an action at
    its limit is taken 0.1% inside it (at the limit, its pre-tanh value is infinite)."""
    obs, _, actions, _, _ = batch
    actor, inside = sac.actor, sac.actor.action_scale * 0.999
    loss = -actor.log_prob(obs, actions.clamp(actor.action_bias - inside, actor.action_bias + inside)).mean()
    sac.actor_optimizer.zero_grad(set_to_none=True)
    loss.backward()
    sac.actor_optimizer.step()
    sac.losses["clone_loss"] = loss
