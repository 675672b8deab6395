import glob
import json
import math
import os
import runpy
import selectors
import signal
import subprocess
import sys
import time

import gymnasium as gym
import numpy as np
import pytest
import torch
from conftest import default_signals

import gridworld_env as g
import q_learning_recovered_reward as qrr

SCRIPT = "q_learning_recovered_reward.py"
SCRIPT_PATH = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), SCRIPT)
GRIDWORLD_TINY = ["--tamer-total-timesteps", "2000", "--tamer-learning-starts", "500", "--sleep-gradient-steps", "100"]
WALL, PLAIN = g.transition_table("wall"), g.transition_table("plain")
UP, LEFT = 0, 2


def env_reward_table(variant: str) -> np.ndarray:
    """The environment's own reward as a table: +1 for the move that enters G."""
    return (g.transition_table(variant) == g.GOAL).astype(np.float64)


def shaped_reward_table(variant: str, gamma: float = 0.99) -> np.ndarray:
    """Potential-based shaping of the env reward with Phi = V*: the same optimal policy, a dense signal."""
    next_cell = g.transition_table(variant)
    v = g.optimal_q(variant, gamma).max(1)
    return env_reward_table(variant) + gamma * (next_cell != g.GOAL) * v[next_cell] - v[:, None]


def save_network(path, seed=0, obs_dim=30, **meta):
    """A random 30-32-32-4 network in inform_dqn_gridworld.py's format (state_dict, kwargs, env_id, gamma, temp)."""
    torch.manual_seed(seed)
    net = qrr.QNetwork(obs_dim, 4)
    meta = {"env_id": "KnoxStoneMaze-v0", "gamma": 0.99, "temperature": 0.1, **meta}
    kwargs = {"obs_dim": obs_dim, "n_actions": 4, "hidden": 32}
    torch.save({"state_dict": net.state_dict(), "kwargs": kwargs, **meta}, path)
    return net


def make_gridworld_run(path, seed=0):
    """A directory shaped like a gridworld run: inform_q.pt, tamer_h.pt and the plain-maze recovered_reward.pt."""
    os.makedirs(path, exist_ok=True)
    net = save_network(os.path.join(path, "inform_q.pt"), seed)
    save_network(os.path.join(path, "tamer_h.pt"), seed + 100, gamma=None, temperature=None)
    table = qrr.transition_reward_table(net, PLAIN, 0.99, 0.1)
    torch.save({"reward": torch.as_tensor(table, dtype=torch.float32), "env_id": "KnoxStoneMaze-v0", "gamma": 0.99,
                "temperature": 0.1}, os.path.join(path, "recovered_reward.pt"))  # fmt: skip
    return net


def args_for(**overrides) -> qrr.Args:
    args = qrr.Args(**overrides)
    qrr.check_args(args)
    return args


# Eq. 3 on the transition actually made -----------------------------------------------------------------------------
def test_blocked_move_uses_s_prime_equal_s_by_hand():
    torch.manual_seed(3)
    net = qrr.QNetwork(30, 4)
    with torch.no_grad():
        q = net(torch.eye(30)).double().numpy()
    gamma, temp = 0.99, 0.1
    v = [temp * math.log(sum(math.exp(x / temp) for x in q[s])) for s in range(30)]  # soft value, written out
    wall = qrr.transition_reward_table(net, WALL, gamma, temp)
    plain = qrr.transition_reward_table(net, PLAIN, gamma, temp)
    assert WALL[18, UP] == 18 and PLAIN[18, UP] == 13  # the new wall blocks 18 -> 13
    assert wall[18, UP] == pytest.approx(q[18, UP] - gamma * v[18], abs=1e-5)  # s' = s
    assert plain[18, UP] == pytest.approx(q[18, UP] - gamma * v[13], abs=1e-5)
    assert wall[18, LEFT] == pytest.approx(q[18, LEFT] - gamma * v[17], abs=1e-5) == plain[18, LEFT]
    assert wall[10, UP] == pytest.approx(q[10, UP], abs=1e-6)  # entering G terminates: no V(s') term
    assert wall[4, UP] == pytest.approx(q[4, UP] - gamma * v[4], abs=1e-5)  # the border: s' = s as well
    # the batch form (one transition at a time) agrees with the table
    eye = torch.eye(30)
    one = qrr.recovered_reward(net, eye[18], torch.tensor(UP), eye[18], torch.tensor(0.0), gamma, temp)
    assert float(one) == pytest.approx(wall[18, UP], abs=1e-6)


def test_the_network_reward_on_the_plain_maze_is_the_saved_table(tmp_path):
    net = make_gridworld_run(tmp_path / "run")
    saved, _ = qrr.load_reward_table(str(tmp_path / "run" / "recovered_reward.pt"))
    with torch.no_grad():  # Eq. 3 written out cell by cell: r = Q(s, a) - gamma V(s'), no V(s') on entering G
        q = net(torch.eye(30)).double().numpy()
    v = 0.1 * np.log(np.exp(q / 0.1).sum(1))
    by_hand = np.array([[q[s, a] - (0.0 if PLAIN[s, a] == g.GOAL else 0.99 * v[PLAIN[s, a]]) for a in range(4)]
                        for s in range(30)])  # fmt: skip
    assert np.allclose(saved, by_hand, atol=1e-5)
    (source,) = qrr.resolve_sources(args_for(reward_path=(str(tmp_path / "run"),)))
    assert np.array_equal(source["reward"]["next_cell"], WALL)  # default --env-id: the wall maze's s'
    assert not np.allclose(source["reward"]["table"], saved)


# the tabular agents ------------------------------------------------------------------------------------------------
def test_td_target_sampled_and_max():
    q = np.zeros((30, 4))
    q[7] = [1.0, -2.0, 3.0, 0.5]
    rng = np.random.default_rng(0)
    assert qrr.td_target(q, 0.5, 7, True, "max", 0.9, 0.05, rng) == 0.5  # no bootstrap past G
    assert qrr.td_target(q, 0.5, 7, True, "sampled", 0.9, 0.05, rng) == 0.5
    assert qrr.td_target(q, 0.5, 7, False, "max", 0.9, 1.0, rng) == pytest.approx(0.5 + 0.9 * 3.0)
    assert qrr.td_target(q, 0.5, 7, False, "sampled", 0.9, 0.0, rng) == pytest.approx(0.5 + 0.9 * 3.0)
    sampled = {qrr.td_target(q, 0.0, 7, False, "sampled", 1.0, 1.0, rng) for _ in range(200)}
    assert sampled == {1.0, -2.0, 3.0, 0.5}  # epsilon 1: every a' is drawn, the max is not assumed


@pytest.mark.parametrize("bootstrap", ["sampled", "max"])
@pytest.mark.parametrize("variant", ["wall", "plain"])
def test_each_bootstrap_learns_a_known_good_reward(bootstrap, variant):
    env = gym.make("KnoxStoneMazeWall-v0" if variant == "wall" else "KnoxStoneMaze-v0")
    optimum = 25 if variant == "wall" else 19
    reward = {"table": shaped_reward_table(variant), "next_cell": g.transition_table(variant)}
    run = qrr.train_agent(env, reward, args_for(num_episodes=40, bootstrap=bootstrap), seed=0, variant=variant)
    assert run["greedy"][-1] == optimum
    steps, episodes = qrr.stays_at_optimum(run, optimum)
    assert np.isfinite(steps) and 1 <= episodes <= 40
    assert run["steps"][-1] == run["lengths"].sum()


def test_the_reward_must_be_the_one_of_the_transition_made():
    """A reward computed for the plain maze's s' but claimed for the wall maze is caught at the first mismatch."""
    reward = {"table": shaped_reward_table("plain"), "next_cell": PLAIN}
    with pytest.raises(RuntimeError, match="computed for s'"):
        qrr.train_agent(gym.make("KnoxStoneMazeWall-v0"), reward, args_for(num_episodes=50), seed=0, variant="wall")


def test_env_arm_is_the_table_of_the_env_reward():
    args = args_for(num_episodes=30)
    a = qrr.train_agent(gym.make("KnoxStoneMazeWall-v0"), None, args, seed=3, variant="wall")
    reward = {"table": env_reward_table("wall"), "next_cell": WALL}
    b = qrr.train_agent(gym.make("KnoxStoneMazeWall-v0"), reward, args, seed=3, variant="wall")
    assert np.array_equal(a["lengths"], b["lengths"]) and np.array_equal(a["q"], b["q"])


def test_epsilon_greedy_breaks_ties_at_random_and_is_seeded():
    rng = np.random.default_rng(0)
    assert {qrr.epsilon_greedy(np.zeros(4), 0.0, rng) for _ in range(200)} == {0, 1, 2, 3}
    assert {qrr.epsilon_greedy(np.array([0.0, 1.0, 1.0, -1.0]), 0.0, rng) for _ in range(200)} == {1, 2}
    one = [qrr.epsilon_greedy(np.zeros(4), 0.1, np.random.default_rng(5)) for _ in range(5)]
    assert one == [qrr.epsilon_greedy(np.zeros(4), 0.1, np.random.default_rng(5)) for _ in range(5)]


def test_metrics_first_episode_and_stays():
    run = {"lengths": np.array([200, 25, 60, 25, 25]), "greedy": np.array([200, 25, 200, 25, 25]),
           "steps": np.array([200, 225, 285, 310, 335])}  # fmt: skip
    assert qrr.first_optimum(run, 25) == (225.0, 2.0)
    assert qrr.stays_at_optimum(run, 25) == (310.0, 4.0)  # the greedy visit at episode 2 did not last
    run["greedy"] = np.array([200, 25, 25, 25, 40])
    assert all(np.isnan(qrr.stays_at_optimum(run, 25)))
    run["lengths"] = np.array([200, 30, 60, 26, 27])
    assert all(np.isnan(qrr.first_optimum(run, 25)))
    assert qrr.censored_median(np.array([1.0, np.nan, 3.0])) == 3.0  # the agent that never reached ranks last
    assert np.isinf(qrr.censored_median(np.array([1.0, np.nan, np.nan])))  # over half never: no median


# diagnosis ---------------------------------------------------------------------------------------------------------
def test_value_iteration_and_the_loop_diagnosis():
    for variant in ("plain", "wall"):
        q = qrr.value_iteration(env_reward_table(variant), g.transition_table(variant), 0.99)
        assert np.allclose(q, g.optimal_q(variant, 0.99), atol=1e-8)
    assert qrr.diagnose(env_reward_table("wall"), "wall", 0.99, 0.05)["max/loop"] == []
    # every move costs 0.015, bumping at 18 (up) only 0.001: under the max the agent walks to 18 and stays there
    table = np.full((30, 4), -0.015)
    table[18, UP] = -0.001
    d = qrr.diagnose(table, "wall", 0.99, 0.05)
    assert d["max/episode_length"] == 200 and d["max/loop"] == [18]
    assert d["max/loop_worth"] == pytest.approx(-0.001 / 0.01)  # staying forever: -0.1
    assert d["max/loop_to_goal_steps"] == 9  # 18 -> 17 16 15 12 7 8 9 10 -> G: -0.13
    assert d["max/loop_to_goal_return"] == pytest.approx(-0.015 * (1 - 0.99**9) / 0.01)
    assert d["shortest_path/steps"] == 25
    # under the epsilon-greedy fixed point (the sampled bootstrap's) staying also pays for the random moves at 18,
    # forever, and that tips it here: the agent goes on to G
    assert d["sampled/episode_length"] == 25
    assert d["max/q_stay_in_max_loop"] > d["max/q_leave_max_loop_for_goal"]
    assert d["sampled/q_stay_in_max_loop"] < d["sampled/q_leave_max_loop_for_goal"]


# the script: in process --------------------------------------------------------------------------------------------
def test_main_is_deterministic_and_never_reuses_a_run_dir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    make_gridworld_run(tmp_path / "a", seed=1)
    make_gridworld_run(tmp_path / "b", seed=2)
    args = args_for(reward_path=("a", "b"), num_episodes=20, num_seeds=2, seed=4, bootstrap="max")
    summaries = []
    for _ in range(2):
        summary = qrr.main(args, qrr.resolve_sources(args))
        summaries.append({k: v for k, v in summary.items() if not (k.startswith("time/") or k == "wall_time_s")})
    assert len(glob.glob("runs/*/summary.json")) == 2
    assert summaries[0] == summaries[1]
    s = summaries[0]
    assert s["seeds"] == [4, 5, 6, 7] and s["arms"] == ["max_bootstrap/recovered_network", "max_bootstrap/env"]
    assert s["max_bootstrap/env/n_agents"] == 4 and len(s["max_bootstrap/env/steps_to_first_optimum_per_agent"]) == 4
    assert len(s["eval/wall/tamer_episode_length_per_run"]) == 2 and s["bootstrap"] == "max"
    (run_dir,) = glob.glob("runs/*")[:1]
    with np.load(os.path.join(run_dir, "agents.npz")) as npz:
        assert npz["max_bootstrap/env/lengths"].shape == (4, 20)


def test_ctrl_c_keeps_what_finished(tmp_path, monkeypatch):
    """Ctrl-C (KeyboardInterrupt) during the second arm: summary says interrupted, with the arm and agents done."""
    monkeypatch.chdir(tmp_path)
    make_gridworld_run(tmp_path / "a")
    args = args_for(reward_path=("a",), num_episodes=10, num_seeds=2, seed=1)
    real, calls = qrr.train_agent, []

    def train_then_ctrl_c(*a, **kw):
        calls.append(1)
        if len(calls) == 3:  # the first agent of the second arm
            raise KeyboardInterrupt
        return real(*a, **kw)

    monkeypatch.setattr(qrr, "train_agent", train_then_ctrl_c)
    summary = qrr.main(args, qrr.resolve_sources(args))
    (path,) = glob.glob("runs/*/summary.json")
    assert json.load(open(path)) == json.loads(json.dumps(summary))
    assert summary["status"] == "interrupted" and summary["phase"] == "sampled_bootstrap/env"
    assert summary["signal"] == "SIGINT"
    assert summary["sampled_bootstrap/recovered_network/agents_done"] == 2
    assert summary["sampled_bootstrap/env/agents_done"] == 0
    assert not glob.glob("runs/*/fig6.png")


def test_fig6_of_plot_results_draws_every_arm(tmp_path, monkeypatch):
    from inform_utils import plot_results

    monkeypatch.chdir(tmp_path)
    make_gridworld_run(tmp_path / "a")
    for bootstrap in ("sampled", "max"):
        args = args_for(reward_path=("a",), num_episodes=5, num_seeds=2, bootstrap=bootstrap, exp_name="fig6")
        qrr.main(args, qrr.resolve_sources(args))
    runs = plot_results.completed_reward_runs("runs", "fig6")
    assert sorted(runs[5]) == ["max_bootstrap/env", "max_bootstrap/recovered_network", "sampled_bootstrap/env",
                               "sampled_bootstrap/recovered_network"]  # fmt: skip
    plot_results.fig6(runs, str(tmp_path / "fig6.png"))
    assert (tmp_path / "fig6.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# the script: real processes ----------------------------------------------------------------------------------------
def test_smoke_on_a_real_gridworld_run(run_script):
    """A tiny gridworld run; without --reward-path the script finds it, says so, and runs on its network."""
    assert run_script("inform_dqn_gridworld.py", "--seed", "2", *GRIDWORLD_TINY).returncode == 0
    (gridworld_dir,) = glob.glob(os.path.join(run_script.cwd, "runs", "*"))
    result = run_script(SCRIPT, "--num-episodes", "15", "--num-seeds", "2", "--seed", "3")
    assert result.returncode == 0, result.stderr
    assert "gridworld run:" in result.stdout and os.path.basename(gridworld_dir) in result.stdout
    (run_dir,) = glob.glob(os.path.join(run_script.cwd, "runs", "KnoxStoneMazeWall-v0__q_learning_recovered_reward_*"))
    summary = json.load(open(os.path.join(run_dir, "summary.json")))
    arm = "sampled_bootstrap/recovered_network"
    keys = [f"{arm}/n_first_optimum", f"{arm}/steps_to_stay_optimum_median", "sampled_bootstrap/env/n_agents",
            f"{arm}/greedy_optimal_fraction_mean", "diagnosis/max/episode_length_per_run", "bootstrap_rule",
            "eval/wall/tamer_episode_length"]  # fmt: skip
    assert set(keys) <= set(summary), set(keys) - set(summary)
    assert summary["status"] == "completed" and summary["optimum_episode_length"] == 25
    assert os.path.samefile(summary["reward/paths"][0], os.path.join(gridworld_dir, "inform_q.pt"))
    ckpt = torch.load(os.path.join(gridworld_dir, "tamer_h.pt"), weights_only=True)
    net = qrr.QNetwork(**ckpt["kwargs"])
    net.load_state_dict(ckpt["state_dict"])
    policy = net(torch.eye(30)).argmax(1).numpy()
    assert summary["eval/wall/tamer_episode_length_per_run"] == [g.greedy_episode_length(policy, "wall")]
    assert os.path.getsize(os.path.join(run_dir, "fig6.png")) > 10_000


def read_until(proc, text: str, timeout: float) -> str:
    """The child's stdout until `text` appears; on timeout kill the child and fail with what it wrote."""
    out, deadline = b"", time.monotonic() + timeout
    sel = selectors.DefaultSelector()
    sel.register(proc.stdout, selectors.EVENT_READ)
    while text.encode() not in out:
        left = deadline - time.monotonic()
        if left <= 0 or proc.poll() is not None:
            proc.kill()
            rest, err = proc.communicate(timeout=30)
            pytest.fail(f"no {text!r} from the child (exit {proc.returncode}); stdout: {out + rest!r}; stderr: {err!r}")
        if sel.select(timeout=min(left, 1.0)):
            out += os.read(proc.stdout.fileno(), 4096)
    return out.decode()


@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_real_signal_keeps_what_finished(sig, code, tmp_path):
    make_gridworld_run(tmp_path / "a")
    proc = subprocess.Popen(
        [sys.executable, SCRIPT_PATH, "--reward-path", "a", "--num-episodes", "1000000", "--bootstrap", "max"],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        preexec_fn=default_signals,
    )
    read_until(proc, "run directory:", timeout=120)
    proc.send_signal(sig)
    try:
        _, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate(timeout=30)
        pytest.fail(f"the child did not stop within 60 s of {sig.name}; stdout: {out!r}; stderr: {err!r}")
    assert proc.returncode == code, err
    assert f"interrupted ({sig.name})" in err.decode() and "Traceback" not in err.decode()
    (path,) = glob.glob(str(tmp_path / "runs" / "*" / "summary.json"))
    summary = json.load(open(path))
    assert summary["status"] == "interrupted" and summary["signal"] == sig.name
    assert summary["phase"] == "max_bootstrap/recovered_network"
    assert summary["max_bootstrap/recovered_network/agents_done"] == 0


# bad input: one "error:" line, a non-zero exit, no run directory --------------------------------------------------
def corrupt_network(path):
    save_network(path)
    data = open(path, "rb").read()
    open(path, "wb").write(data[: len(data) // 2])


def weights_that_do_not_fit(path):
    save_network(path)
    ckpt = torch.load(path, weights_only=True)
    ckpt["kwargs"]["hidden"] = 16
    torch.save(ckpt, path)


BAD_NETWORKS = {
    "missing": (lambda p: None, "does not exist"),
    "corrupt": (corrupt_network, "cannot read INFORM network"),
    "text file": (lambda p: open(p, "w").write('{"hello": 1}\n'), "cannot read INFORM network"),
    "a bare tensor": (lambda p: torch.save(torch.zeros(30, 4), p), "expected a dict"),
    "a reward table": (lambda p: torch.save({"reward": torch.zeros(30, 4)}, p), "needs 'state_dict' and 'kwargs'"),
    "learnt on the wall maze": (lambda p: save_network(p, env_id="KnoxStoneMazeWall-v0"), "from the plain maze"),
    "not a maze network": (lambda p: save_network(p, env_id="CartPole-v1"), "not for one of the mazes"),
    "another maze's size": (lambda p: save_network(p, obs_dim=36), "not the maze's 30 cells"),
    "no temperature": (lambda p: save_network(p, temperature=None), "'temperature' > 0"),
    "weights do not fit": (weights_that_do_not_fit, "cannot rebuild the INFORM network"),
}
BAD_TABLES = {
    "wrong shape": (lambda p: torch.save({"reward": torch.zeros(29, 4)}, p), "shape"),
    "NaN": (lambda p: torch.save({"reward": torch.full((30, 4), float("nan"))}, p), "NaN"),
    "no reward tensor": (lambda p: torch.save({"state_dict": {}, "kwargs": {}}, p), "'reward'"),
}


def run_main_in_process(monkeypatch, capsys, *flags):
    monkeypatch.setattr(sys, "argv", [SCRIPT, *flags])
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    try:  # run as __main__, the script installs its own signal handlers first: give pytest its own back
        with pytest.raises(SystemExit) as exit_info:
            runpy.run_path(SCRIPT_PATH, run_name="__main__")
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
    return exit_info.value.code, capsys.readouterr().err


def assert_one_error_line(code, err, message, tmp_path):
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error:") and message in lines[0], err
    assert not os.path.exists(tmp_path / "runs")


@pytest.mark.parametrize("case", sorted(BAD_NETWORKS))
def test_bad_network_file_is_one_line_and_leaves_nothing(case, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    os.makedirs("run")
    make, message = BAD_NETWORKS[case]
    make("run/inform_q.pt")
    code, err = run_main_in_process(monkeypatch, capsys, "--reward-path", "run")
    assert_one_error_line(code, err, message, tmp_path)


@pytest.mark.parametrize("case", sorted(BAD_TABLES))
def test_bad_reward_table_is_one_line_and_leaves_nothing(case, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    make, message = BAD_TABLES[case]
    make("r.pt")
    code, err = run_main_in_process(monkeypatch, capsys, "--reward-source", "table", "--reward-path", "r.pt")
    assert_one_error_line(code, err, message, tmp_path)


@pytest.mark.parametrize(
    "flags, message",
    [
        ([], "no --reward-path given"),
        (["--num-seeds", "0"], "--num-seeds"),
        (["--epsilon", "2"], "--epsilon"),
    ],  # a malformed flag (e.g. --bootstrap mean) gets tyro's own message: tests/test_pusher.py
)
def test_bad_flags_are_one_line(flags, message, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code, err = run_main_in_process(monkeypatch, capsys, *flags)
    assert_one_error_line(code, err, message, tmp_path)


def test_corrupt_tamer_network_is_an_error_too(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    make_gridworld_run(tmp_path / "run")
    open(tmp_path / "run" / "tamer_h.pt", "w").write("not a network")
    code, err = run_main_in_process(monkeypatch, capsys, "--reward-path", "run")
    assert_one_error_line(code, err, "TAMER", tmp_path)


def test_bad_input_in_a_real_process_has_no_traceback(run_script):
    os.makedirs(run_script.cwd / "run")
    save_network(run_script.cwd / "run" / "inform_q.pt", env_id="KnoxStoneMazeWall-v0")
    result = run_script(SCRIPT, "--reward-path", "run")
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and lines[0].startswith("error:"), result.stderr
    assert "plain maze" in lines[0] and not os.path.exists(run_script.cwd / "runs")
