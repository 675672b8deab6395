import glob
import json
import math
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch
from conftest import Child

import gridworld_env as g
import inform_dqn_gridworld as inform
from inform_utils.evaluate_policy import load_q_network

SCRIPT = "inform_dqn_gridworld.py"
REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TINY = ["--tamer-total-timesteps", "2000", "--tamer-learning-starts", "500", "--sleep-gradient-steps", "200"]


class TableQ(torch.nn.Module):
    """A Q table as a network on one-hot observations, for hand-computed cases."""

    def __init__(self, table):
        super().__init__()
        self.table = torch.nn.Parameter(torch.tensor(table, dtype=torch.float32))

    def forward(self, obs):
        return obs @ self.table


def one_hot(cells, n):
    return torch.eye(n)[torch.tensor(cells)]


# Eq. 4 -----------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "q_sa, q_best, alpha, expected",
    [
        (1.0, 1.0, 0.999, 1.0),  # the oracle's own action
        (0.9995, 1.0, 0.999, 1.0),  # within 0.1% of the best
        (0.99, 1.0, 0.999, 0.0),  # one step worse at gamma 0.99: too far
        (0.8, 1.0, 0.8, 1.0),  # Q >= alpha Q* exactly at the boundary
        (-10.05, -10.0, 0.99, 1.0),  # negative Q: threshold -10 - 0.01 * 10 = -10.1 = (2 - alpha) Q*
        (-10.2, -10.0, 0.99, 0.0),
        (-10.0, -10.0, 1.0, 1.0),  # alpha 1: only the best action
    ],
)
def test_oracle_feedback_eq4(q_sa, q_best, alpha, expected):
    assert inform.oracle_feedback(q_sa, q_best, alpha) == expected


def test_oracle_feedback_eq4_on_arrays_and_exact_q():
    q = g.optimal_q("plain")
    h = inform.oracle_feedback(q, q.max(1, keepdims=True), 0.999)
    # with exact Q* and alpha 0.999 the teacher says yes to exactly the optimal actions
    assert np.array_equal(h == 1.0, q >= q.max(1, keepdims=True) - 1e-12)


# Eq. 1 -----------------------------------------------------------------------------------------------------------
def test_tamer_loss_eq1():
    h_net = TableQ([[0.5, -1.0], [2.0, 0.0]])
    obs = one_hot([0, 1, 1], 2)
    actions = torch.tensor([0, 0, 1])
    feedback = torch.tensor([1.0, 1.0, 0.0])
    expected = ((0.5 - 1.0) ** 2 + (2.0 - 1.0) ** 2 + (0.0 - 0.0) ** 2) / 3  # no discount, no bootstrap
    assert inform.tamer_loss(h_net, obs, actions, feedback).item() == pytest.approx(expected)


# Eq. 2 -----------------------------------------------------------------------------------------------------------
def soft_v(row, temp):
    """V = temp * logsumexp(Q / temp) of one row of Q values, by hand."""
    return temp * math.log(sum(math.exp(x / temp) for x in row))


def test_iq_loss_eq2_by_hand():
    """Eq. 2 term by term, with a target network unlike the online one: y(s') = (1 - terminated) gamma V_target(s'),
    V(s) from the online network on s."""
    online, target_table = [[1.0, 0.0], [0.0, 2.0]], [[0.5, -1.0], [3.0, 1.0]]
    q_net, target = TableQ(online), TableQ(target_table)
    # row 0: expert, s=0 a=0 s'=1; row 1: replay, s=1 a=1 s'=0, terminated; row 2: replay, s=0 a=1 s'=0
    cells, actions_, next_cells, done = [0, 1, 0], [0, 1, 1], [1, 0, 0], [0.0, 1.0, 0.0]
    obs, next_obs = one_hot(cells, 2), one_hot(next_cells, 2)
    actions, terminated = torch.tensor(actions_), torch.tensor(done)
    is_expert = torch.tensor([True, False, False])
    gamma, temp, chi2 = 0.5, 0.5, 0.5
    loss, terms = inform.iq_loss(q_net, target, obs, actions, next_obs, terminated, is_expert, gamma, temp, chi2)
    y = [(1 - d) * gamma * soft_v(target_table[c], temp) for c, d in zip(next_cells, done, strict=True)]
    assert y[1] == 0.0 and y[0] != gamma * soft_v(online[1], temp)  # the target's V, and not the online one's
    q_sa = [online[c][a] for c, a in zip(cells, actions_, strict=True)]  # 1, 2, 0
    td = [q - t for q, t in zip(q_sa, y, strict=True)]
    value = sum(soft_v(online[c], temp) - t for c, t in zip(cells, y, strict=True)) / 3  # V(s): online, on s
    expert_term, value_term, chi2_term = terms["iq_expert_term"], terms["iq_value_term"], terms["iq_chi2_term"]
    assert expert_term.item() == pytest.approx(-td[0], rel=1e-5)
    assert value_term.item() == pytest.approx(value, rel=1e-5)
    assert chi2_term.item() == pytest.approx(chi2 * sum(x * x for x in td) / 3, rel=1e-5)
    assert loss.item() == pytest.approx(-td[0] + value + chi2 * sum(x * x for x in td) / 3, rel=1e-5)


def test_iq_loss_uses_target_network_on_next_state_without_gradient():
    """y(s') from the target on s', a constant: the gradient reaches the online network only, and it is Eq. 2's by
    hand: -1/N_expert on each expert (s, a), plus softmax(Q(s, .) / temp) / N on each row's s (the value term)."""
    online, target_table = [[1.0, 0.0], [0.0, 2.0]], [[5.0, 5.0], [-3.0, 7.0]]
    q_net, target = TableQ(online), TableQ(target_table)
    obs, next_obs = one_hot([0, 1], 2), one_hot([1, 1], 2)
    actions, terminated, is_expert = torch.tensor([0, 1]), torch.tensor([0.0, 0.0]), torch.tensor([True, False])
    gamma, temp = 0.9, 0.5
    loss, terms = inform.iq_loss(q_net, target, obs, actions, next_obs, terminated, is_expert, gamma, temp, 0.0)
    y = gamma * soft_v([-3.0, 7.0], temp)  # both rows go to s' = 1
    assert terms["iq_expert_term"].item() == pytest.approx(-(1.0 - y), rel=1e-5)
    assert terms["iq_value_term"].item() == pytest.approx(
        (soft_v(online[0], temp) + soft_v(online[1], temp)) / 2 - y, rel=1e-5
    )
    assert terms["iq_chi2_term"].item() == 0.0
    loss.backward()
    assert target.table.grad is None
    expected = torch.zeros(2, 2)
    expected[0, 0] -= 1.0  # the one expert row, s=0 a=0
    for cell in (0, 1):
        expected[cell] += torch.softmax(torch.tensor(online[cell]) / temp, 0) / 2
    assert torch.allclose(q_net.table.grad, expected, atol=1e-6), q_net.table.grad


def test_chi2_flag_turns_the_regulariser_off():
    q_net = TableQ([[1.0, 0.0], [0.0, 2.0]])
    args = (q_net, q_net, one_hot([0, 1], 2), torch.tensor([0, 1]), one_hot([1, 0], 2), torch.tensor([0.0, 1.0]))
    chi2_term = inform.iq_loss(*args, torch.tensor([True, False]), 0.5, 1.0, 0.0)[1]["iq_chi2_term"]
    assert chi2_term.item() == 0.0


# Eq. 3 -----------------------------------------------------------------------------------------------------------
def test_recover_reward_eq3():
    q_sa = torch.tensor([1.0, 2.0])
    v_next = torch.tensor([3.0, 4.0])
    terminated = torch.tensor([0.0, 1.0])
    r = inform.recover_reward(q_sa, v_next, terminated, 0.5)
    assert r.tolist() == pytest.approx([1.0 - 0.5 * 3.0, 2.0])  # a terminal transition keeps Q(s, a)


def test_reward_table_is_eq3_over_the_maze():
    rng = np.random.default_rng(0)
    table = rng.normal(size=(30, 4))
    r = inform.reward_table(TableQ(table), g.transition_table("plain"), 0.9, 0.5, torch.device("cpu")).numpy()
    assert r.shape == (30, 4)
    v = 0.5 * np.log(np.exp(table / 0.5).sum(1))
    assert r[10, 0] == pytest.approx(table[10, 0], abs=1e-5)  # 10 up enters G: terminated
    assert r[4, 2] == pytest.approx(table[4, 2] - 0.9 * v[3], abs=1e-5)  # S left moves to cell 3
    assert r[4, 0] == pytest.approx(table[4, 0] - 0.9 * v[4], abs=1e-5)  # S up bumps: s' = s


# success tag and buffer ---------------------------------------------------------------------------------------------
def test_success_tag():
    assert inform.is_success(True, 1.0, 19, 30, 1.0)  # G (+1) in 19 steps
    assert inform.is_success(True, 1.0, 29, 30, 1.0)
    assert not inform.is_success(True, 1.0, 30, 30, 1.0)  # fewer than 30 steps
    assert not inform.is_success(False, 0.0, 5, 30, 1.0)  # truncated, not at the goal


def test_buffer_tags_whole_trajectories():
    buf = inform.ReplayBuffer(10, 2, torch.device("cpu"))
    for i in range(3):
        buf.add(np.eye(2)[0], 1, np.eye(2)[1], i == 2)
    buf.tag_episode(0, True)
    for _ in range(2):
        buf.add(np.eye(2)[1], 0, np.eye(2)[1], False)
    buf.tag_episode(3, False)
    assert buf.size == 5 and buf.success[:5].tolist() == [True, True, True, False, False]
    assert buf.terminated[:5].tolist() == [0, 0, 1, 0, 0]


def test_greedy_actions_and_evaluate():
    import gymnasium as gym

    q = g.optimal_q("plain")
    policy = inform.greedy_actions(TableQ(q), torch.device("cpu"))
    assert np.array_equal(policy, q.argmax(1))
    length, success = inform.evaluate(policy, gym.make("KnoxStoneMaze-v0"), inform.start_cells(g.START), 30)
    assert (length, success) == (19, 1.0)
    length, success = inform.evaluate(policy, gym.make("KnoxStoneMazeWall-v0"), inform.start_cells(g.START), 30)
    assert (length, success) == (200, 0.0)


# the script end to end ----------------------------------------------------------------------------------------------
SUMMARY_KEYS = (
    [f"eval/{p}_episode_length" for p in inform.POLICIES]
    + [f"eval/wall/{p}_episode_length" for p in inform.POLICIES]
    + [f"eval/start_set/{p}_{m}" for p in inform.POLICIES for m in ("episode_length", "success_rate")]
    + [f"eval/all_starts/{p}_success_rate" for p in inform.POLICIES]
    + ["feedback/positive", "feedback/perfect_positive", "feedback/steps", "time/oracle_s", "time/tamer_s",
       "time/sleep_s", "time/eval_s", "wall_time_s", "seed", "args", "status", "losses/iq_loss",
       "losses/iq_expert_term", "losses/iq_value_term", "losses/iq_chi2_term"]
)  # fmt: skip


def only_run_dir(cwd):
    dirs = glob.glob(os.path.join(cwd, "runs", "*"))
    assert len(dirs) == 1, dirs
    return dirs[0]


def test_smoke_run_writes_the_outputs(run_script):
    result = run_script(SCRIPT, "--seed", "3", *TINY)
    assert result.returncode == 0, result.stderr
    run_dir = only_run_dir(run_script.cwd)
    assert os.path.basename(run_dir).startswith("KnoxStoneMaze-v0__inform_dqn_gridworld__3__")
    summary = json.load(open(os.path.join(run_dir, "summary.json")))
    assert set(SUMMARY_KEYS) <= set(summary), set(SUMMARY_KEYS) - set(summary)
    assert summary["status"] == "completed" and summary["feedback/steps"] == 2000
    assert summary["sleep/expert_transitions"] > 0  # the sleep loop really ran
    assert glob.glob(os.path.join(run_dir, "events.out.tfevents.*"))
    reward = torch.load(os.path.join(run_dir, "recovered_reward.pt"), weights_only=True)
    assert reward["reward"].shape == (30, 4)
    for name in ("tamer_h.pt", "inform_q.pt"):
        ckpt = torch.load(os.path.join(run_dir, name), weights_only=True)
        net = inform.QNetwork(**ckpt["kwargs"])
        net.load_state_dict(ckpt["state_dict"])
    # the saved INFORM network reproduces the reported greedy episode length
    policy = inform.greedy_actions(net, torch.device("cpu"))
    assert g.greedy_episode_length(policy, "plain") == summary["eval/inform_episode_length"]


def test_tensorboard_tags(run_script):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    assert run_script(SCRIPT, *TINY).returncode == 0
    acc = EventAccumulator(only_run_dir(run_script.cwd))
    acc.Reload()
    tags = set(acc.Tags()["scalars"])
    expected = {"charts/episodic_return", "charts/episodic_length", "charts/SPS", "feedback/positive",
                "feedback/positive_rate", "feedback/alpha", "losses/tamer_loss", "losses/iq_loss",
                "losses/iq_expert_term", "losses/iq_value_term", "losses/iq_chi2_term"}  # fmt: skip
    expected |= {k for k in SUMMARY_KEYS if k.startswith("eval/")}
    assert expected <= tags, expected - tags
    assert "sleep/recovered_reward" in acc.Tags()["images"]
    # curves during the phases, not just a final point
    assert len(acc.Scalars("eval/tamer_episode_length")) >= 4
    assert len(acc.Scalars("eval/inform_episode_length")) >= 2


def test_same_seed_same_numbers(run_script):
    summaries = []
    for _ in range(2):
        assert run_script(SCRIPT, "--seed", "7", *TINY).returncode == 0
    for run_dir in sorted(glob.glob(os.path.join(run_script.cwd, "runs", "*"))):
        summary = json.load(open(os.path.join(run_dir, "summary.json")))
        summaries.append({k: v for k, v in summary.items() if not (k.startswith("time/") or k == "wall_time_s")})
    assert len(summaries) == 2  # and the second run did not overwrite the first
    assert summaries[0] == summaries[1]


@pytest.mark.parametrize(
    "flags, message",
    [
        (["--tamer-total-timesteps", "-5"], "--tamer-total-timesteps"),
        (["--feedback-alpha-start", "1.5"], "--feedback-alpha-start"),
        (["--env-id", "CartPole-v1"], "--env-id"),
        (["--sleep-temperature", "0"], "--sleep-temperature"),
        (["--tamer-total-timesteps", "100"], "--tamer-learning-starts"),
        (["--sleep-seed", "-1"], "--sleep-seed"),
    ],
)
def test_bad_input_is_one_line_and_leaves_nothing(run_script, flags, message):
    result = run_script(SCRIPT, *flags)
    assert result.returncode != 0
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and message in lines[0], result.stderr
    assert "Traceback" not in result.stderr
    assert not os.path.exists(os.path.join(run_script.cwd, "runs"))


@pytest.mark.slow
def test_default_run_learns_the_optimum(run_script):
    """The paper's Fig. 3 claim on one seed: TAMER and INFORM both reach the 19-step optimum."""
    result = run_script(SCRIPT, "--seed", "1")
    assert result.returncode == 0, result.stderr
    summary = json.load(open(os.path.join(only_run_dir(run_script.cwd), "summary.json")))
    assert summary["eval/oracle_episode_length"] == 19
    assert summary["eval/tamer_episode_length"] == 19
    assert summary["eval/inform_episode_length"] == 19


# reliability: bad files, interruption, divergence, re-evaluation ---------------------------------------------------
class CodeCarrier:
    def __reduce__(self):
        return (os.system, ("echo this must never run",))


def bad_checkpoints(tmp):
    """Files an --oracle-path or inform_utils.evaluate_policy may be given, each wrong in its own way."""
    paths = {}
    good = tmp / "good.pt"
    torch.save({"q_table": torch.zeros(30, 4), "env_id": "KnoxStoneMaze-v0"}, good)
    paths["truncated"] = tmp / "truncated.pt"
    paths["truncated"].write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    paths["not a checkpoint"] = tmp / "notes.txt"
    paths["not a checkpoint"].write_text("hello")
    paths["carries code"] = tmp / "evil.pt"
    torch.save({"q_table": CodeCarrier()}, paths["carries code"])
    paths["wrong env"] = tmp / "wall.pt"
    torch.save({"q_table": torch.zeros(30, 4), "env_id": "KnoxStoneMazeWall-v0"}, paths["wrong env"])
    paths["wrong shape"] = tmp / "shape.pt"
    torch.save({"q_table": torch.zeros(29, 4), "env_id": "KnoxStoneMaze-v0"}, paths["wrong shape"])
    paths["not a dict"] = tmp / "list.pt"
    torch.save([1, 2], paths["not a dict"])
    paths["no q table"] = tmp / "net.pt"
    torch.save({"state_dict": {}, "env_id": "KnoxStoneMaze-v0"}, paths["no q table"])
    return paths


BAD_FILES = [
    ("truncated", "truncated"),
    ("not a checkpoint", "not a torch checkpoint"),
    ("carries code", "refused"),
    ("wrong env", "not for --env-id"),
    ("wrong shape", "expected (30, 4)"),
    ("not a dict", "expected a dict"),
    ("no q table", "no 'q_table'"),
]


def assert_one_line_error(result, cwd, message):
    assert result.returncode == 2, (result.returncode, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and message in lines[0], result.stderr
    assert "Traceback" not in result.stderr and "this must never run" not in result.stdout + result.stderr
    assert not os.path.exists(os.path.join(cwd, "runs"))


@pytest.mark.parametrize("kind, message", BAD_FILES)
def test_bad_oracle_checkpoint(run_script, kind, message):
    path = bad_checkpoints(run_script.cwd)[kind]
    assert_one_line_error(run_script(SCRIPT, "--oracle-path", str(path)), run_script.cwd, message)


@pytest.mark.parametrize(
    "flags, message",
    [
        (["--oracle-path", "missing.pt"], "no such file"),
    ],
)
def test_bad_command_line(run_script, flags, message):
    assert_one_line_error(run_script(SCRIPT, *flags), run_script.cwd, message)


def test_oracle_path_is_used(run_script):
    """A teacher from a file replaces exact Q*: here a deliberately bad one whose best action is always 'up'."""
    q = np.zeros((30, 4))
    q[:, 0] = 1.0
    torch.save({"q_table": torch.tensor(q), "env_id": "KnoxStoneMaze-v0"}, run_script.cwd / "up.pt")
    result = run_script(SCRIPT, "--oracle-path", "up.pt", *TINY)
    assert result.returncode == 0, result.stderr
    summary = json.load(open(os.path.join(only_run_dir(run_script.cwd), "summary.json")))
    assert summary["eval/oracle_episode_length"] == 200  # 'up' from S hits the border forever
    assert summary["sleep/expert_transitions"] == 0  # nobody reached the goal in time
    assert summary["eval/tamer_episode_length"] == 200


def test_save_load_same_actions(tmp_path):
    torch.manual_seed(0)
    net = inform.QNetwork(30, 4)
    inform.save_network(str(tmp_path / "q.pt"), net, env_id="KnoxStoneMaze-v0")
    loaded = load_q_network(str(tmp_path / "q.pt"))
    obs = torch.eye(30)
    assert torch.equal(net(obs), loaded(obs))
    assert np.array_equal(inform.greedy_actions(net, "cpu"), inform.greedy_actions(loaded, "cpu"))


def test_evaluate_mode_reproduces_the_run(run_script):
    assert run_script(SCRIPT, *TINY).returncode == 0
    run_dir = only_run_dir(run_script.cwd)
    summary = json.load(open(os.path.join(run_dir, "summary.json")))
    for name, policy in (("tamer_h.pt", "tamer"), ("inform_q.pt", "inform")):
        result = run_script("inform_utils/evaluate_policy.py", "maze", os.path.join(run_dir, name))
        assert result.returncode == 0, result.stderr
        metrics = json.loads(result.stdout)
        for key in ("episode_length", "wall/{}_episode_length", "start_set/{}_success_rate"):
            ours = "eval/" + (key.format("policy") if "{}" in key else f"policy_{key}")
            theirs = "eval/" + (key.format(policy) if "{}" in key else f"{policy}_{key}")
            assert metrics[ours] == summary[theirs], (name, key)
    assert len(glob.glob(os.path.join(run_script.cwd, "runs", "*"))) == 1  # evaluating writes no run


# Long phases, so that the signal surely lands in the phase named: each prints its first progress line after 5% of
# its steps (2k of 40k env steps; 1k of 20k gradient steps) and has at least ten seconds to go after it.
LONG_PHASE = {
    "tamer": ["--tamer-total-timesteps", "40000"],
    "sleep": ["--tamer-total-timesteps", "2000", "--tamer-learning-starts", "500", "--sleep-gradient-steps", "20000"],
}
FIRST_EVAL = {"tamer": "[tamer] 2000/", "sleep": "[sleep] 1000/"}  # the progress line of the first evaluation


def assert_interrupted_run(cwd, phase, signal_name):
    run_dir = only_run_dir(cwd)
    summary = json.load(open(os.path.join(run_dir, "summary.json")))
    assert summary["status"] == "interrupted" and summary["phase"] == phase and summary["signal"] == signal_name
    assert os.path.exists(os.path.join(run_dir, "tamer_h.pt")) == (phase == "sleep")  # what finished is saved
    assert not os.path.exists(os.path.join(run_dir, "inform_q.pt"))
    policy = "inform" if phase == "sleep" else "tamer"  # the curves so far, under a name that says they are (issue 71)
    assert f"eval/last_check/{policy}_episode_length" in summary and f"eval/{policy}_episode_length" not in summary


@pytest.mark.parametrize(
    "sig, phase, code",
    [(signal.SIGINT, "tamer", 130), (signal.SIGINT, "sleep", 130), (signal.SIGTERM, "sleep", 143)],
)  # fmt: skip
def test_signal_ends_the_run_cleanly(tmp_path, sig, phase, code):
    """Ctrl-C and SIGTERM (kill, Slurm) both save what finished and write summary.json with status interrupted."""
    child = Child([sys.executable, os.path.join(REPO, SCRIPT), *LONG_PHASE[phase]], tmp_path)
    child.wait_for_line(FIRST_EVAL[phase])
    child.proc.send_signal(sig)
    returncode, _, stderr = child.finish()
    assert returncode == code and "Traceback" not in stderr, (returncode, stderr)
    assert f"interrupted ({sig.name}) during the {phase} phase" in stderr
    assert_interrupted_run(tmp_path, phase, sig.name)


def test_sigterm_stops_a_run_started_in_the_background(tmp_path):
    """`python ... &` from a script: SIGINT is ignored there (POSIX), SIGTERM still saves what finished."""
    run = f"'{sys.executable}' '{os.path.join(REPO, SCRIPT)}' {' '.join(LONG_PHASE['tamer'])}"
    command = f"{run} > out.txt 2> err.txt & echo pid=$!; wait $!; echo rc=$?"
    child = Child(["bash", "-c", command], tmp_path)
    pid = int(child.wait_for_line("pid=").strip().split("=")[1])

    def text(name: str) -> str:  # the shell may echo the pid before the background job has opened its files
        return (tmp_path / name).read_text() if (tmp_path / name).exists() else ""

    deadline = time.monotonic() + 180
    while FIRST_EVAL["tamer"] not in text("out.txt"):
        if time.monotonic() > deadline or child.proc.poll() is not None:
            child.fail(f"no evaluation in out.txt:\n{text('out.txt')[-2000:]}\nerr.txt:\n{text('err.txt')[-2000:]}")
        time.sleep(0.2)
    if os.path.exists(f"/proc/{pid}/status"):  # Linux: the background run ignores SIGINT, as the shell set it up
        with open(f"/proc/{pid}/status") as f:
            ignored = int(next(line for line in f if line.startswith("SigIgn:")).split()[1], 16)
        assert ignored & (1 << (signal.SIGINT - 1))
    os.kill(pid, signal.SIGTERM)
    returncode, stdout, _ = child.finish()
    assert returncode == 0 and "rc=143" in stdout, (stdout, (tmp_path / "err.txt").read_text())
    assert "Traceback" not in (tmp_path / "err.txt").read_text()
    assert_interrupted_run(tmp_path, "tamer", "SIGTERM")


def test_divergence_is_reported(run_script):
    result = run_script(SCRIPT, *TINY[:4], "--sleep-gradient-steps", "1000", "--sleep-q-lr", "1e9")
    assert result.returncode == 1
    assert "Traceback" not in result.stderr and "diverged" in result.stderr and "step" in result.stderr
    summary = json.load(open(os.path.join(only_run_dir(run_script.cwd), "summary.json")))
    assert summary["status"] == "diverged" and summary["phase"] == "sleep"


@pytest.mark.parametrize("script, flag", [("inform_dqn_gridworld.py", "--teacher-noise"),
                                          ("q_learning_recovered_reward.py", "--reward-path")])  # fmt: skip
def test_a_copied_script_asks_for_the_maze_module(tmp_path, script, flag):
    """Copied without gridworld_env.py: --help still works, and a run says in one line what is missing, with the exit
    code of any other bad input (2)."""
    import shutil

    shutil.copy(os.path.join(REPO, script), tmp_path / "my_copy.py")
    env = {**os.environ, "PYTHONPATH": ""}
    proc = subprocess.run([sys.executable, "my_copy.py", "--help"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=120, env=env)  # fmt: skip
    assert proc.returncode == 0 and flag in proc.stdout, proc.stderr
    proc = subprocess.run([sys.executable, "my_copy.py", "--seed", "1"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=120, env=env)  # fmt: skip
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    (line,) = proc.stderr.strip().splitlines()
    assert line.startswith("error: ") and "gridworld_env.py" in line and "copy it next to this script" in line
    assert not os.path.exists(tmp_path / "runs")
    shutil.copy(os.path.join(REPO, "gridworld_env.py"), tmp_path)  # with the maze beside it, the copy runs
    proc = subprocess.run([sys.executable, "my_copy.py", "--help"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=120, env=env)  # fmt: skip
    assert proc.returncode == 0 and flag in proc.stdout, proc.stderr
