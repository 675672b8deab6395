import numpy as np
import torch

import gridworld_env as g
import inform_dqn_gridworld as inform


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
    assert g.greedy_episode_length(q.argmax(1), "plain") == ckpt["evaluation"]["episode_length"]
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
