"""INFORM on Gymnasium's toy-text tasks (inform_dqn_gridworld.py --env-id FrozenLake-v1 | CliffWalking-v1 | Taxi-v4):
exact Q* from the env's own model, success on the task's goal, the maze's own tests skipped."""

import glob
import json
import os
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
import tyro
from conftest import REPO

import inform_dqn_gridworld as maze

SCRIPT = os.path.join(REPO, "inform_dqn_gridworld.py")
TINY = ["--seed", "1", "--tamer-total-timesteps", "3000", "--sleep-gradient-steps", "500", "--eval-episodes", "5"]


def run(cwd, *flags, timeout=300, module=None):
    """The script, or with `module` one of inform_utils/ (python -m inform_utils.MODULE), in the directory cwd."""
    cmd, env = [sys.executable, SCRIPT], None
    if module is not None:
        cmd, env = [sys.executable, "-m", f"inform_utils.{module}"], {**os.environ, "PYTHONPATH": REPO}
    return subprocess.run([*cmd, *flags], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def summaries(cwd) -> dict[str, dict]:
    found = {}
    for path in sorted(glob.glob(str(cwd / "runs" / "*" / "summary.json"))):
        with open(path) as f:
            found[os.path.dirname(path)] = json.load(f)
    return found


def test_value_iteration_on_the_ice_by_hand():
    """Deterministic 4x4 FrozenLake: the goal (15) pays 1 and ends the episode, so Q*(14, right) = 1, one step more
    costs a factor gamma, and the start (0) is 6 moves away: V*(0) = gamma^5. Holes are worth nothing."""
    env = maze.OneHot(gym.make("FrozenLake-v1", is_slippery=False))
    q = maze.optimal_q(env, 0.9)
    right, down = 2, 1  # the map: SFFF / FHFH / FFFH / HFFG
    assert q[14, right] == pytest.approx(1.0) and q[13, right] == pytest.approx(0.9)
    assert q[10, down] == pytest.approx(0.9)  # 10 -> 14 -> goal
    assert q.max(1)[0] == pytest.approx(0.9**5)
    assert np.all(q[[5, 7, 11, 12, 15]] == 0.0)  # the holes and the goal: terminal, nothing follows


def test_value_iteration_on_slippery_ice_satisfies_bellman():
    """Slippery moves: Q* is the expected value over the model's outcomes, Bellman's equation to 1e-8."""
    env = maze.make_env("FrozenLake-v1")
    gamma = 0.99
    q = maze.optimal_q(env, gamma)
    model = env.unwrapped.P
    for s in range(16):
        for a in range(4):
            target = sum(p * (r + gamma * (not done) * q[s2].max()) for p, s2, r, done in model[s][a])
            assert q[s, a] == pytest.approx(target, abs=1e-8)
    assert 0.5 < q[0].max() < 0.6  # slippery: the best the start can hope for is about 0.54 at gamma 0.99


def test_the_goal_is_the_terminal_with_the_top_reward():
    ice = maze.make_env("FrozenLake-v1")
    assert maze.top_reward(ice) == 1.0
    assert maze.top_reward(maze.make_env("CliffWalking-v1")) == -1.0  # every step costs 1; the cliff 100
    assert maze.top_reward(maze.make_env("Taxi-v4")) == 20.0  # the drop-off
    assert maze.top_reward(maze.make_env("KnoxStoneMaze-v0")) == 1.0
    assert not maze.is_success(True, 0.0, 5, 30, 1.0)  # FrozenLake's hole: the episode ends with nothing
    assert maze.is_success(True, 1.0, 5, 30, 1.0) and not maze.is_success(True, 1.0, 30, 30, 1.0)  # in time only
    assert not maze.is_success(False, 1.0, 5, 30, 1.0)
    assert maze.make_env("CliffWalking-v1").spec.max_episode_steps == maze.TOY_TEXT_MAX_STEPS  # none of its own
    obs, _ = ice.reset(seed=0)
    assert obs.shape == (16,) and obs.sum() == 1.0 and obs[0] == 1.0  # one-hot, as the maze's observations


def test_cliff_walking_end_to_end_from_its_env_id(tmp_path):
    """CliffWalking-v1 from --env-id alone: the teacher is its exact Q*, the day and the night run as on the maze, the
    summary says what was skipped, and inform_utils.evaluate_policy reads the saved INFORM network back on the task."""
    proc = run(tmp_path, "--env-id", "CliffWalking-v1", *TINY)
    assert proc.returncode == 0, proc.stderr[-2000:]
    ((run_dir, summary),) = summaries(tmp_path).items()
    assert summary["status"] == "completed" and "wall maze" in summary["maze_tests/skipped"]
    assert summary["eval/oracle_episode_length"] == 13.0 and summary["eval/oracle_success_rate"] == 1.0  # 13 steps
    for p in maze.POLICIES:
        length = summary[f"eval/{p}_episode_length"]
        assert 13.0 <= length <= maze.TOY_TEXT_MAX_STEPS
        # one start, deterministic moves: every episode ends alike, at the goal (a success) or at the step limit
        assert summary[f"eval/{p}_success_rate"] == float(length < maze.TOY_TEXT_MAX_STEPS)
    assert not any(k.startswith(("eval/wall/", "eval/start_set/", "eval/all_starts/")) for k in summary)
    assert os.path.isfile(os.path.join(run_dir, "inform_q.pt"))
    assert not os.path.exists(os.path.join(run_dir, "recovered_reward.pt"))  # the maze's table only
    evaluated = run(tmp_path, "maze", os.path.join(run_dir, "inform_q.pt"), "--env-id", "CliffWalking-v1", "--seed",
                    "1", "--eval-episodes", "5", module="evaluate_policy")  # fmt: skip
    assert evaluated.returncode == 0, evaluated.stderr[-2000:]
    assert json.loads(evaluated.stdout)["eval/policy_episode_length"] == summary["eval/inform_episode_length"]


def test_a_saved_toy_text_day_sleeps_again_to_the_same_numbers(tmp_path):
    """--save-buffer and --sleep-from on FrozenLake: the same night on the saved day gives the same INFORM."""
    (tmp_path / "day").mkdir()
    assert run(tmp_path / "day", "--env-id", "FrozenLake-v1", "--success-max-steps", "100", *TINY,
               "--save-buffer").returncode == 0  # fmt: skip
    ((day_dir, day),) = summaries(tmp_path / "day").items()
    (tmp_path / "night").mkdir()
    proc = run(tmp_path / "night", "--sleep-from", day_dir, "--sleep-gradient-steps", "500")
    assert proc.returncode == 0, proc.stderr[-2000:]
    ((_, night),) = summaries(tmp_path / "night").items()
    assert day["sleep/expert_transitions"] > 0  # a night with something to consolidate
    for key in ("eval/inform_episode_length", "eval/inform_success_rate", "losses/iq_loss", "feedback/positive"):
        assert night[key] == day[key], key


@pytest.mark.parametrize(
    ("flags", "needle"),
    [
        (["--env-id", "CartPole-v1"], "env.unwrapped.P"),
        (["--env-id", "Pendulum-v1"], "continuous tasks run in inform_sac_pusher.py"),
        (["--env-id", "NoSuchEnv-v0"], "Gymnasium cannot make it"),
        (["--env-id", "Taxi-v4", "--teacher", "human"], "--teacher human: the maze's only"),
        (["--env-id", "FrozenLake-v1", "--capture-video"], "--capture-video: the maze's only"),
    ],
)
def test_a_task_without_a_model_is_refused_in_one_line(flags, needle):
    with pytest.raises(maze.InputError) as err:
        maze.check_args(tyro.cli(maze.Args, args=flags))
    assert needle in str(err.value) and "\n" not in str(err.value)
