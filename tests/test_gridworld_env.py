import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import gridworld_env as g

MAZE = """\
+---+---+---+---+---+---+
|                SA | G |
+   +---+---+---+---+   +
|   |###|               |
+   +---+   +---+---+   +
|   |###|   |###|###|   |
+   +---+   +---+---+   +
|   |###|               |
+   +---+   +   +   +   +
|   |###|               |
+   +---+---+---+---+   +
|                       |
+---+---+---+---+---+---+
"""


@pytest.mark.parametrize("env_id", list(g.ENV_IDS))
def test_check_env(env_id):
    env = gym.make(env_id)
    check_env(env.unwrapped)
    assert env.spec.max_episode_steps == 200


def test_layout_matches_the_drawing():
    assert g.N_CELLS == 30 and len(g.BLOCKED) == 6
    env = gym.make("KnoxStoneMaze-v0", render_mode="ansi")
    env.reset(seed=0)
    assert env.render() == MAZE
    assert env.render().count("###") == 6 and env.render().count("S") == 1  # S stays marked under the agent


def test_wall_variant_adds_two_walls_in_column_5():
    env = gym.make("KnoxStoneMazeWall-v0", render_mode="ansi")
    env.reset(seed=0)
    lines = env.render().splitlines()
    assert lines[4] == "+   +---+   +---+---+---+" and lines[6] == "+   +---+   +---+---+---+"
    plain, wall = g.transition_table("plain"), g.transition_table("wall")
    assert plain[10, 1] == 13 and wall[10, 1] == 10  # 10 down: into 13 on the plain maze, a wall on the variant
    assert plain[18, 0] == 13 and wall[18, 0] == 18
    assert (wall != 13).sum() == 30 * 4 - 4  # only 13's own moves "stay" at 13: nothing else enters it


def test_shortest_paths():
    assert g.greedy_episode_length(g.optimal_q("plain").argmax(1), "plain") == 19
    assert g.greedy_episode_length(g.optimal_q("wall").argmax(1), "wall") == 25
    # the plain maze's optimal policy runs into the new wall
    assert g.greedy_episode_length(g.optimal_q("plain").argmax(1), "wall") == 200


def test_optimal_q_values():
    q = g.optimal_q("plain", gamma=0.99)
    assert q[10, 0] == pytest.approx(1.0)  # from 10, up enters G
    assert q[g.START].max() == pytest.approx(0.99**18)  # 19 steps: reward discounted 18 times
    assert q[g.START, 3] == pytest.approx(0.99 * q[g.START].max())  # right bumps into the wall: stay, lose a step


def test_step_reward_and_termination():
    env = gym.make("KnoxStoneMaze-v0")
    obs, info = env.reset(seed=0)
    assert obs.shape == (30,) and obs[g.START] == 1 and obs.sum() == 1 and info["cell"] == g.START
    obs, reward, terminated, truncated, _ = env.step(3)  # wall between S and G
    assert obs[g.START] == 1 and reward == 0 and not terminated
    env.reset(options={"start_cell": 10})
    obs, reward, terminated, truncated, _ = env.step(0)
    assert obs[g.GOAL] == 1 and reward == 1.0 and terminated and not truncated


def test_truncation_at_200_steps():
    env = gym.make("KnoxStoneMaze-v0")
    env.reset(seed=0)
    for t in range(1, 201):
        _, _, terminated, truncated, _ = env.step(0)  # up from S: the border, forever
        assert not terminated and truncated == (t == 200)


def test_start_set_resets_are_seeded():
    env = gym.make("KnoxStoneMazeStartSet-v0")
    starts = [env.reset(seed=s)[1]["cell"] for s in range(40)]
    assert set(starts) <= set(g.START_SET) and len(set(starts)) > 3
    assert starts == [env.reset(seed=s)[1]["cell"] for s in range(40)]


def test_any_start_covers_every_cell_but_the_goal():
    env = gym.make("KnoxStoneMazeAnyStart-v0")
    starts = {env.reset(seed=s)[1]["cell"] for s in range(400)}
    assert starts == set(range(g.N_CELLS)) - {g.GOAL}


def test_rgb_render():
    env = gym.make("KnoxStoneMaze-v0", render_mode="rgb_array")
    env.reset(seed=0)
    img = env.render()
    assert img.shape == (192, 192, 3) and img.dtype == np.uint8
