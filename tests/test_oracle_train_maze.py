import json

import gymnasium as gym
import numpy as np
import pytest
import torch

import gridworld_env as g
import inform_dqn_gridworld as inform
import oracle_train as ot


def walked_length(policy: np.ndarray, env_id: str) -> int:
    """A greedy table policy's episode length from S, walked in the Gymnasium env itself (not through the maze's
    transition table, as greedy_episode_length does): 200, the time limit, if it never reaches G."""
    env = gym.make(env_id)
    obs, _ = env.reset(seed=0)
    steps, terminated, truncated = 0, False, False
    while not (terminated or truncated):  # the env's time limit is 200 steps
        obs, _, terminated, truncated, _ = env.step(int(policy[int(obs.argmax())]))
        steps += 1
    env.close()
    return steps if terminated else 200


def test_value_iteration_oracle_round_trips(run_script):
    result = run_script("oracle_train.py", "--env-id", "KnoxStoneMaze-v0", "--output-path", "vi.pt")
    assert result.returncode == 0, result.stderr
    ckpt = torch.load(run_script.cwd / "vi.pt", weights_only=True)
    assert ckpt["algorithm"] == "value-iteration" and ckpt["evaluation"]["episode_length"] == 19
    q = inform.load_oracle(str(run_script.cwd / "vi.pt"), "KnoxStoneMaze-v0")
    assert np.allclose(q, g.optimal_q("plain"))
    assert not (run_script.cwd / "vi.pt.tmp").exists()  # written atomically


def test_q_learning_oracle_is_a_usable_imperfect_teacher(run_script):
    flags = ["--env-id", "KnoxStoneMaze-v0", "--method", "q-learning", "--maze-episodes", "20", "--seed", "1"]
    assert run_script("oracle_train.py", *flags, "--output-path", "ql.pt").returncode == 0
    ckpt = torch.load(run_script.cwd / "ql.pt", weights_only=True)
    assert ckpt["training_steps"] > 0 and ckpt["q_table"].shape == (30, 4)
    q = ckpt["q_table"].numpy()
    assert not np.allclose(q, g.optimal_q("plain"))  # a half-trained table, not Q*
    assert walked_length(q.argmax(1), "KnoxStoneMaze-v0") == ckpt["evaluation"]["episode_length"]
    result = run_script(
        "inform_dqn_gridworld.py", "--oracle-path", "ql.pt", "--tamer-total-timesteps", "2000",
        "--tamer-learning-starts", "500", "--sleep-gradient-steps", "100",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr


def test_default_output_path_names_env_and_method(run_script):
    assert run_script("oracle_train.py", "--env-id", "KnoxStoneMazeWall-v0").returncode == 0
    ckpt = torch.load(run_script.cwd / "oracles" / "KnoxStoneMazeWall-v0__value-iteration_oracle.pt", weights_only=True)
    assert ckpt["evaluation"]["episode_length"] == 25


def test_method_must_fit_the_env(run_script):
    result = run_script("oracle_train.py", "--env-id", "KnoxStoneMaze-v0", "--method", "sac")
    assert result.returncode == 2 and result.stderr.startswith("error:") and len(result.stderr.splitlines()) == 1
    assert not (run_script.cwd / "oracles").exists()


@pytest.mark.slow
def test_dqn_oracle_round_trips_and_teaches(run_script):
    """The default DQN budget reaches a successful greedy policy; its q_table is the saved network's Q."""
    flags = ["--env-id", "KnoxStoneMaze-v0", "--method", "dqn", "--seed", "1", "--output-path", "dqn.pt"]
    result = run_script("oracle_train.py", *flags)
    assert result.returncode == 0, result.stderr
    assert not (run_script.cwd / "dqn.pt.tmp").exists()  # written atomically
    ckpt = torch.load(run_script.cwd / "dqn.pt", weights_only=True)
    assert ckpt["algorithm"] == "dqn" and ckpt["env_id"] == "KnoxStoneMaze-v0"
    assert ckpt["obs_shape"] == [g.N_CELLS] and ckpt["act_shape"] == [g.N_ACTIONS]
    assert ckpt["training_steps"] == ot.Args.maze_dqn_timesteps and ckpt["training_seed"] == 1
    net = ot.MazeQNetwork(**ckpt["kwargs"])
    net.load_state_dict(ckpt["state_dict"])
    with torch.no_grad():
        q_net = net(torch.eye(g.N_CELLS)).double()
    assert ckpt["q_table"].dtype == torch.float64 and torch.equal(ckpt["q_table"], q_net)
    q = inform.load_oracle(str(run_script.cwd / "dqn.pt"), "KnoxStoneMaze-v0")
    assert np.array_equal(q, q_net.numpy())
    length = walked_length(q.argmax(1), "KnoxStoneMaze-v0")
    assert length == ckpt["evaluation"]["episode_length"]
    assert length < 30  # a successful teacher (the success tag), learned in well under a minute
    result = run_script(
        "inform_dqn_gridworld.py", "--oracle-path", "dqn.pt", "--tamer-total-timesteps", "2000",
        "--tamer-learning-starts", "500", "--sleep-gradient-steps", "100",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    (summary,) = (run_script.cwd / "runs").glob("*/summary.json")
    assert json.loads(summary.read_text())["eval/oracle_episode_length"] == length


def train_in_process(tmp_path, name: str, **kwargs) -> dict:
    """Run oracle_train's maze path in this process (no interpreter start-up) and read the checkpoint back."""
    args = ot.Args(output_path=str(tmp_path / name), **kwargs)
    ot.check_args(args)  # raises InputError on bad input
    ot.train_maze(args)
    return torch.load(tmp_path / name, weights_only=True)


def test_dqn_oracle_is_deterministic_for_a_seed(tmp_path):
    tiny = {"env_id": "KnoxStoneMaze-v0", "method": "dqn", "maze_dqn_timesteps": 1500, "maze_dqn_learning_starts": 300}
    first = train_in_process(tmp_path, "a.pt", seed=3, **tiny)
    again = train_in_process(tmp_path, "b.pt", seed=3, **tiny)
    other = train_in_process(tmp_path, "c.pt", seed=4, **tiny)
    assert torch.equal(first["q_table"], again["q_table"])
    assert all(torch.equal(first["state_dict"][k], again["state_dict"][k]) for k in first["state_dict"])
    assert first["evaluation"] == again["evaluation"]
    assert not torch.equal(first["q_table"], other["q_table"])


@pytest.mark.parametrize("method", ot.METHODS["maze"])
def test_every_maze_checkpoint_holds_env_shapes_steps_and_evaluation(tmp_path, method):
    budget = {"maze_episodes": 5, "maze_dqn_timesteps": 600, "maze_dqn_learning_starts": 200}
    ckpt = train_in_process(tmp_path, "o.pt", env_id="KnoxStoneMazeWall-v0", method=method, seed=2, **budget)
    assert ckpt["algorithm"] == method and ckpt["env_id"] == "KnoxStoneMazeWall-v0"
    assert ckpt["obs_shape"] == [g.N_CELLS] and ckpt["act_shape"] == [g.N_ACTIONS] and ckpt["n_actions"] == 4
    assert tuple(ckpt["q_table"].shape) == (g.N_CELLS, g.N_ACTIONS)
    steps = ckpt["training_steps"]
    assert isinstance(steps, int)
    if method == "q-learning":
        assert 5 <= steps <= 5 * 200  # 5 episodes of at most 200 steps (the time limit)
    else:
        assert steps == {"value-iteration": 0, "dqn": 600}[method]
    length = walked_length(ckpt["q_table"].numpy().argmax(1), "KnoxStoneMazeWall-v0")
    assert ckpt["evaluation"] == {"episode_length": float(length)}
    assert ("state_dict" in ckpt) == (method == "dqn")
    assert not (tmp_path / "o.pt.tmp").exists()
