import glob
import json
import os
import runpy
import sys

import gymnasium as gym
import numpy as np
import pytest
import torch

import gridworld_env as g
import q_learning_recovered_reward as qrr

SCRIPT = "q_learning_recovered_reward.py"
SCRIPT_PATH = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), SCRIPT)
GRIDWORLD_TINY = ["--tamer-total-timesteps", "2000", "--tamer-learning-starts", "500", "--sleep-gradient-steps", "200",
                  "--eval-frequency", "500", "--sleep-eval-frequency", "100"]  # fmt: skip


def env_reward_table(variant: str) -> np.ndarray:
    """The environment's own reward as a table: +1 for the move that enters G."""
    return (g.transition_table(variant) == g.GOAL).astype(np.float64)


def shaped_reward_table(variant: str, gamma: float = 0.99) -> np.ndarray:
    """Potential-based shaping of the env reward with Phi = V*: the same optimal policy, a dense signal."""
    next_cell = g.transition_table(variant)
    v = g.optimal_q(variant, gamma).max(1)
    not_done = next_cell != g.GOAL
    return env_reward_table(variant) + gamma * not_done * v[next_cell] - v[:, None]


def save_table(path, table, env_id="KnoxStoneMaze-v0"):
    torch.save({"reward": torch.as_tensor(table, dtype=torch.float32), "env_id": env_id, "gamma": 0.99}, path)


def args_for(**overrides) -> qrr.Args:
    args = qrr.Args(**overrides)
    qrr.check_args(args)
    return args


# the pieces -------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "variant, table_fn, episodes",
    [("wall", env_reward_table, 300), ("wall", shaped_reward_table, 40), ("plain", shaped_reward_table, 40)],
)
def test_q_learning_on_a_known_good_reward_reaches_the_optimum(variant, table_fn, episodes):
    env = gym.make("KnoxStoneMazeWall-v0" if variant == "wall" else "KnoxStoneMaze-v0")
    optimum = 25 if variant == "wall" else 19
    run = qrr.q_learning(env, table_fn(variant), args_for(num_episodes=episodes), seed=0, variant=variant)
    assert run["greedy"][-1] == optimum
    steps, episodes_to = qrr.time_to_optimum(run, optimum)
    assert np.isfinite(steps) and 1 <= episodes_to <= episodes
    assert run["steps"][-1] == run["lengths"].sum()


def test_env_reward_arm_is_the_table_of_the_env_reward():
    """reward_table None (the env's +1) and the same reward as a table give the same run for one seed."""
    args = args_for(num_episodes=30)
    a = qrr.q_learning(gym.make("KnoxStoneMazeWall-v0"), None, args, seed=3, variant="wall")
    b = qrr.q_learning(gym.make("KnoxStoneMazeWall-v0"), env_reward_table("wall"), args, seed=3, variant="wall")
    assert np.array_equal(a["lengths"], b["lengths"]) and np.array_equal(a["q"], b["q"])


def test_epsilon_greedy_breaks_ties_at_random_and_is_seeded():
    rng = np.random.default_rng(0)
    picks = {qrr.epsilon_greedy(np.zeros(4), 0.0, rng) for _ in range(200)}
    assert picks == {0, 1, 2, 3}  # argmax-first would always say 0
    assert {qrr.epsilon_greedy(np.array([0.0, 1.0, 1.0, -1.0]), 0.0, rng) for _ in range(200)} == {1, 2}
    one = [qrr.epsilon_greedy(np.zeros(4), 0.1, np.random.default_rng(5)) for _ in range(5)]
    two = [qrr.epsilon_greedy(np.zeros(4), 0.1, np.random.default_rng(5)) for _ in range(5)]
    assert one == two


def test_time_to_optimum_needs_the_optimum_kept_to_the_end():
    run = {"greedy": np.array([200, 25, 200, 25, 25]), "steps": np.array([200, 300, 500, 530, 555])}
    assert qrr.time_to_optimum(run, 25) == (530.0, 4.0)  # the first visit (episode 2) did not last
    run["greedy"] = np.array([25, 25, 25, 25, 25])
    assert qrr.time_to_optimum(run, 25) == (200.0, 1.0)
    run["greedy"] = np.array([200, 25, 25, 25, 40])
    steps, episodes = qrr.time_to_optimum(run, 25)
    assert np.isnan(steps) and np.isnan(episodes)


def test_reward_shape_report_on_known_tables():
    report = qrr.reward_shape_report(env_reward_table("plain"), 0.99, 1e-3)
    assert report["reward/density"] == pytest.approx(1 / (29 * 4))  # one non-zero entry: 10 up
    assert report["reward/plain/policy_agreement"] == 1.0 and report["reward/plain/agreement_states"] == 29
    # on the wall maze, cell 13 is cut off (no path to G), so 28 states count; the plain-maze reward (10 up) is still
    # the wall maze's, so its optimal policy is the wall maze's
    assert report["reward/wall/agreement_states"] == 28 and report["reward/wall/policy_agreement"] == 1.0
    assert report["reward/wall/vi_episode_length"] == 25 and report["reward/wall/positive_self_loops"] == 0
    # a reward for bumping into the new wall at 18 (up) is a loop the wall maze's optimal policy never leaves
    table = shaped_reward_table("plain")
    table[18, 0] = 1.0
    report = qrr.reward_shape_report(table, 0.99, 1e-3)
    assert report["reward/wall/positive_self_loops"] == 1 and report["reward/wall/vi_episode_length"] == 200


def test_value_iteration_on_the_env_reward_is_optimal_q():
    for variant in ("plain", "wall"):
        q = qrr.value_iteration(env_reward_table(variant), g.transition_table(variant), 0.99)
        assert np.allclose(q, g.optimal_q(variant, 0.99), atol=1e-8)


def test_main_is_deterministic_and_never_reuses_a_run_dir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    save_table(tmp_path / "r.pt", shaped_reward_table("plain"))
    args = args_for(reward_path=str(tmp_path / "r.pt"), num_episodes=30, num_seeds=2, seed=4)
    summaries = []
    for _ in range(2):
        summary = qrr.main(args, qrr.resolve_source(args))
        summaries.append({k: v for k, v in summary.items() if not (k.startswith("time/") or k == "wall_time_s")})
    assert len(glob.glob("runs/*/summary.json")) == 2
    assert summaries[0] == summaries[1]
    assert summaries[0]["seeds"] == [4, 5] and summaries[0]["eval/wall/tamer_episode_length"] is None


def test_ctrl_c_keeps_what_finished(tmp_path, monkeypatch):
    """Ctrl-C (KeyboardInterrupt) during the second arm: summary says interrupted, with the arm and seeds done."""
    monkeypatch.chdir(tmp_path)
    save_table(tmp_path / "r.pt", shaped_reward_table("plain"))
    args = args_for(reward_path=str(tmp_path / "r.pt"), num_episodes=10, num_seeds=2, seed=1)
    real, calls = qrr.q_learning, []

    def q_learning_then_ctrl_c(*a, **kw):
        calls.append(1)
        if len(calls) == 3:  # the first seed of the second arm
            raise KeyboardInterrupt
        return real(*a, **kw)

    monkeypatch.setattr(qrr, "q_learning", q_learning_then_ctrl_c)
    summary = qrr.main(args, qrr.resolve_source(args))
    (path,) = glob.glob("runs/*/summary.json")
    assert json.load(open(path)) == summary
    assert summary["status"] == "interrupted" and summary["phase"] == qrr.ARMS[1]
    assert summary[f"qlearning/{qrr.ARMS[0]}/seeds_done"] == 2 and summary[f"qlearning/{qrr.ARMS[1]}/seeds_done"] == 0
    assert not glob.glob("runs/*/fig6.png")


# the script end to end --------------------------------------------------------------------------------------------
SUMMARY_KEYS = [f"qlearning/{arm}/{m}_{s}" for arm in qrr.ARMS for m in qrr.METRICS for s in ("mean", "std")] + [
    f"qlearning/{arm}/n_reached" for arm in qrr.ARMS
] + ["optimum_episode_length", "eval/wall/tamer_episode_length", "reward/source", "reward/density",
     "reward/plain/policy_agreement", "reward/wall/policy_agreement", "seed", "args", "status",
     "wall_time_s"]  # fmt: skip


def test_smoke_on_a_real_gridworld_run(run_script):
    """A tiny gridworld run writes the table; without --reward-path the script finds it, says so, and runs."""
    assert run_script("inform_dqn_gridworld.py", "--seed", "2", *GRIDWORLD_TINY).returncode == 0
    (gridworld_dir,) = glob.glob(os.path.join(run_script.cwd, "runs", "*"))
    result = run_script(SCRIPT, "--num-episodes", "15", "--num-seeds", "2", "--seed", "3")
    assert result.returncode == 0, result.stderr
    assert "reward table:" in result.stdout and os.path.basename(gridworld_dir) in result.stdout
    (run_dir,) = glob.glob(
        os.path.join(run_script.cwd, "runs", "KnoxStoneMazeWall-v0__q_learning_recovered_reward__3__*")
    )
    summary = json.load(open(os.path.join(run_dir, "summary.json")))
    assert set(SUMMARY_KEYS) <= set(summary), set(SUMMARY_KEYS) - set(summary)
    assert summary["status"] == "completed" and summary["optimum_episode_length"] == 25
    assert os.path.samefile(summary["reward/source"], os.path.join(gridworld_dir, "recovered_reward.pt"))
    # the TAMER baseline is the saved network's greedy length on the wall maze
    ckpt = torch.load(os.path.join(gridworld_dir, "tamer_h.pt"), weights_only=True)
    net = qrr.QNetwork(**ckpt["kwargs"])
    net.load_state_dict(ckpt["state_dict"])
    policy = net(torch.eye(30)).argmax(1).numpy()
    assert summary["eval/wall/tamer_episode_length"] == g.greedy_episode_length(policy, "wall")
    assert os.path.getsize(os.path.join(run_dir, "fig6.png")) > 10_000

    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(run_dir)
    acc.Reload()
    tags = set(acc.Tags()["scalars"])
    for arm in qrr.ARMS:
        assert f"qlearning/{arm}/episode_length" in tags
        assert len(acc.Scalars(f"qlearning/{arm}/seed_3/episode_length")) == 15


# bad input: one "error:" line, a non-zero exit, no run directory --------------------------------------------------
def corrupt_file(path):
    save_table(path, np.zeros((30, 4)))
    data = open(path, "rb").read()
    open(path, "wb").write(data[: len(data) // 2])


BAD_INPUTS = {
    "missing": (lambda p: None, "does not exist"),
    "wrong shape": (lambda p: save_table(p, np.zeros((29, 4))), "shape"),
    "corrupt": (corrupt_file, "cannot read"),
    "not a checkpoint": (lambda p: open(p, "w").write('{"hello": 1}\n'), "cannot read"),
    "no reward tensor": (lambda p: torch.save({"state_dict": {}, "kwargs": {}}, p), "'reward'"),
    "a bare tensor": (lambda p: torch.save(torch.zeros(30, 4), p), "expected a dict"),
    "NaN": (lambda p: save_table(p, np.full((30, 4), np.nan)), "NaN"),
}


def run_main_in_process(monkeypatch, capsys, *flags):
    monkeypatch.setattr(sys, "argv", [SCRIPT, *flags])
    with pytest.raises(SystemExit) as exit_info:
        runpy.run_path(SCRIPT_PATH, run_name="__main__")
    return exit_info.value.code, capsys.readouterr().err


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_bad_reward_file_is_one_line_and_leaves_nothing(case, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    make, message = BAD_INPUTS[case]
    make(tmp_path / "r.pt")
    code, err = run_main_in_process(monkeypatch, capsys, "--reward-path", str(tmp_path / "r.pt"))
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error:") and message in lines[0], err
    assert not os.path.exists(tmp_path / "runs")


@pytest.mark.parametrize(
    "flags, message",
    [([], "no --reward-path given"), (["--num-seeds", "0"], "--num-seeds"), (["--epsilon", "2"], "--epsilon")],
)
def test_bad_flags_are_one_line(flags, message, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code, err = run_main_in_process(monkeypatch, capsys, *flags)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error:") and message in lines[0], err
    assert not os.path.exists(tmp_path / "runs")


def test_corrupt_tamer_network_is_an_error_too(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    save_table(tmp_path / "recovered_reward.pt", np.zeros((30, 4)))
    open(tmp_path / "tamer_h.pt", "w").write("not a network")
    code, err = run_main_in_process(monkeypatch, capsys, "--reward-path", str(tmp_path))
    assert code == 2 and err.startswith("error:") and "TAMER" in err and len(err.strip().splitlines()) == 1


def test_bad_input_in_a_real_process_has_no_traceback(run_script):
    (run_script.cwd / "r.pt").write_bytes(b"\x80\x04garbage")
    result = run_script(SCRIPT, "--reward-path", "r.pt")
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and lines[0].startswith("error:"), result.stderr
    assert "Traceback" not in result.stderr and not os.path.exists(run_script.cwd / "runs")
