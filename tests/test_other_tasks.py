"""INFORM beyond Pusher: any continuous-action Gymnasium env from its --env-id alone (inform_sac_pusher.py and
oracle_train.py), episodes judged by a final distance from `info` or by their return, Pusher's own pieces skipped."""

import glob
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
import torch
import tyro
from conftest import REPO

import inform_sac_pusher as isp

SCRIPT = os.path.join(REPO, "inform_sac_pusher.py")
TINY = [
    "--tamer-total-timesteps", "600",
    "--tamer-learning-starts", "300",
    "--tamer-batch-size", "64",
    "--sleep-gradient-steps", "200",
    "--sleep-batch-size", "64",
    "--eval-episodes", "2",
    "--authors-test-episodes", "3",
]  # fmt: skip
TINY_ORACLE = ["--train-oracle", "--oracle-total-timesteps", "5300"]  # SAC learns after 5,000 random steps


def run(cwd, *flags, script=SCRIPT, timeout=300):
    return subprocess.run([sys.executable, script, *flags], cwd=cwd, capture_output=True, text=True, timeout=timeout)


def summary_of(tmp_path) -> tuple[str, dict]:
    (run_dir,) = glob.glob(str(tmp_path / "runs" / "*"))
    with open(os.path.join(run_dir, "summary.json")) as f:
        return run_dir, json.load(f)


def test_outcome_by_distance_and_by_return_hand_computed():
    by_distance = isp.Outcome("reward_dist", 0.08)
    assert by_distance({"reward_dist": -0.05}, -30.0) == (0.05, True, 0.05)
    assert by_distance({"reward_dist": -0.08}, -30.0) == (0.08, False, 0.08)  # strictly below the threshold
    by_return = isp.Outcome("reward_dist", 0.08, min_return=-10.0)
    assert by_return({"reward_dist": -0.05}, -12.0) == (0.05, False, 12.0)  # close, but the return decides
    assert by_return({"reward_dist": -0.5}, -10.0) == (0.5, True, 10.0)
    distance, success, shortfall = isp.Outcome("tip_error", 0.02, min_return=100.0)({"other": 1.0}, 150.0)
    assert math.isnan(distance) and success and shortfall == -150.0


def test_fallback_expert_set_is_drawn_from_the_episodes_the_sleep_sees():
    """With no success, the expert set is the closest 10% of episodes; a held-out episode is never one of them (it
    once was, and the sleep then sampled from an empty set)."""
    buffer = isp.ReplayBuffer(30, obs_dim=1, act_dim=1, device=torch.device("cpu"))
    for start, shortfall in ((0, 0.3), (10, 0.1), (20, 0.2)):  # three failed episodes of ten steps
        for _ in range(10):
            buffer.add(torch.zeros(1), torch.zeros(1), torch.zeros(1), False)
        buffer.tag_episode(start, shortfall, False)
    idx, fallback = buffer.expert_indices()
    assert fallback == 1 and idx.tolist() == list(range(10, 20))  # the closest episode
    keep = torch.ones(30, dtype=torch.bool)
    keep[10:20] = False  # held out
    idx, fallback = buffer.expert_indices(keep)
    assert fallback == 1 and idx.tolist() == list(range(20, 30))  # the closest of the rest
    buffer.success[0:10] = True  # a success the sleep sees: the success set, no fallback
    idx, fallback = buffer.expert_indices(keep)
    assert fallback == 0 and idx.tolist() == list(range(10))


def test_reacher_end_to_end_from_its_env_id(tmp_path):
    """Reacher-v5 from --env-id alone: the teacher trained here, success by Reacher's own reward_dist, the obstacle
    test skipped and said so in the summary, the rest of the run as on Pusher."""
    proc = run(tmp_path, "--env-id", "Reacher-v5", "--success-distance", "0.02", *TINY_ORACLE, *TINY)
    assert proc.returncode == 0, proc.stderr[-2000:]
    run_dir, summary = summary_of(tmp_path)
    assert summary["status"] == "completed" and summary["args"]["env_id"] == "Reacher-v5"
    assert "Pusher" in summary["obstacle/skipped"] and not any(k.startswith("eval/obstacle/") for k in summary)
    assert not glob.glob(os.path.join(run_dir, "obstacle_*.npz"))
    for p in isp.POLICIES:
        for key in ("return", "final_distance", "success_rate"):
            assert np.isfinite(summary[f"eval/{p}_{key}"]) and np.isfinite(summary[f"eval/authors_test/{p}_{key}"])
    assert summary["feedback/steps"] == 600 and summary["sleep/episodes"] == 12  # Reacher's episodes: 50 steps
    ckpt = torch.load(os.path.join(run_dir, "inform_actor.pt"), weights_only=True)
    assert ckpt["env_id"] == "Reacher-v5" and ckpt["kwargs"]["obs_dim"] == 10 and ckpt["kwargs"]["act_dim"] == 2
    assert "obstacle distance" not in proc.stdout and "inform: return" in proc.stdout


def test_success_by_return_tags_the_day_by_return(tmp_path):
    """--success-return judges episodes by their return, on an env with no distance at all (InvertedPendulum ends
    when the pole falls): a bar every episode clears makes every episode a success; one no episode can reach leaves
    none, and the sleep falls back to the episodes with the highest returns."""
    flags = ["--env-id", "InvertedPendulum-v5", *TINY_ORACLE, *TINY]
    (tmp_path / "low").mkdir()
    (tmp_path / "high").mkdir()
    assert run(tmp_path / "low", *flags, "--success-return", "0").returncode == 0
    assert run(tmp_path / "high", *flags, "--success-return", "1e9").returncode == 0
    _, low = summary_of(tmp_path / "low")
    _, high = summary_of(tmp_path / "high")
    assert low["sleep/success_episodes"] == low["sleep/episodes"] > 1 and low["sleep/expert_fallback"] == 0
    assert low["eval/tamer_success_rate"] == 1.0 and low["eval/tamer_final_distance"] is None  # no distance: null
    assert high["sleep/success_episodes"] == 0 and high["sleep/expert_fallback"] == 1
    assert high["eval/inform_success_rate"] == 0.0
    assert low["feedback/steps"] == high["feedback/steps"] == 600  # the same day; only its tags differ


@pytest.mark.parametrize(
    ("flags", "needle"),
    [
        (["--env-id", "CartPole-v1"], "not continuous (Box); discrete tasks run in inform_dqn_gridworld.py"),
        (["--env-id", "NoSuchEnv-v0"], "Gymnasium cannot make it"),
        (["--env-id", "InvertedPendulum-v5"], "no 'reward_dist'"),
        (["--env-id", "Reacher-v5", "--success-info-key", "tip"], "--success-return"),
    ],
)
def test_an_env_that_cannot_be_judged_is_refused_in_one_line(flags, needle):
    with pytest.raises(isp.InputError) as err:
        isp.check_args(tyro.cli(isp.Args, args=flags))
    assert needle in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize(
    "flags",
    [
        ["--env-id", "CartPole-v1"],
        ["--env-id", "NoSuchEnv-v0"],
        ["--env-id", "InvertedPendulum-v5"],
        ["--env-id", "InvertedPendulum-v5", "--success-return", "100"],
        ["--env-id", "Reacher-v5"],
        ["--env-id", "Reacher-v5", "--success-info-key", "tip"],
    ],
)
def test_the_teacher_script_takes_the_same_envs(flags):
    """check_env is copied into oracle_train.py (single-file scripts) with its own hints: both take or refuse an env
    alike, with the same message up to the hint."""
    import oracle_train

    errors = []
    for module in (isp, oracle_train):
        try:
            module.check_env(tyro.cli(module.Args, args=flags))
            errors.append(None)
        except module.InputError as e:
            errors.append(str(e).split("; ")[0].split(", not continuous")[0])
    assert errors[0] == errors[1]


def test_oracle_train_on_reacher_gives_a_teacher_the_script_takes(tmp_path):
    """oracle_train.py --env-id Reacher-v5 chooses its checkpoint by Reacher's success, and inform_sac_pusher.py
    --oracle-path accepts what it writes."""
    oracle = str(tmp_path / "reacher_oracle.pt")
    proc = run(tmp_path, "--env-id", "Reacher-v5", "--success-distance", "0.02", "--total-timesteps", "600",
               "--learning-starts", "300", "--batch-size", "64", "--hidden-size", "64", "--eval-frequency", "300",
               "--eval-episodes", "2", "--final-eval-episodes", "2", "--output-path", oracle,
               script=os.path.join(REPO, "oracle_train.py"))  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    ckpt = torch.load(oracle, weights_only=True)
    assert ckpt["env_id"] == "Reacher-v5" and np.isfinite(ckpt["evaluation"]["final_distance"])
    (run_dir,) = glob.glob(str(tmp_path / "runs" / "*"))
    with open(os.path.join(run_dir, "eval_curve.csv")) as f:
        assert f.read().splitlines()[0] == "step,success_rate,final_distance,return"
    args = tyro.cli(isp.Args, args=["--env-id", "Reacher-v5", "--oracle-path", oracle])
    assert (
        isp.load_oracle(args.env_id, args.contact, args.oracle_path, args.train_oracle, args.oracle_total_timesteps)[
            "env_id"
        ]
        == "Reacher-v5"
    )
