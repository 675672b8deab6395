"""Saved days in the maze script: --save-buffer writes the day (runs/{run}/day.pt), --sleep-from sleeps on it again,
--sleep-seed gives another night on the same day."""

import glob
import json
import os
import random
import subprocess
import sys

import numpy as np
import pytest
import torch

import gridworld_env as g
import inform_dqn_gridworld as inform

SCRIPT = "inform_dqn_gridworld.py"
REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# a tiny run, as tests/test_inform_gridworld.py's
TINY = ["--tamer-total-timesteps", "2000", "--tamer-learning-starts", "500", "--sleep-gradient-steps", "200"]
NIGHT = ("eval/", "losses/", "sleep/", "feedback/")  # the numbers a night on the same day must reproduce
DOCUMENTED_KEYS = {"format", "script", "env_id", "seed", "day_args", "obs", "actions", "next_obs", "feedback",
                   "terminated", "success", "episode_start", "episode_end", "episode_length", "episode_success",
                   "h_net", "q_star", "rng", "day_stats"}  # fmt: skip


def run(cwd, *flags: str, study: bool = False) -> subprocess.CompletedProcess:
    """The script (or with `study`, the sleep study's module) in `cwd` (its runs/ lands there)."""
    cmd = [sys.executable, *(["-m", "inform_utils.sleep_variants_maze"] if study else [os.path.join(REPO, SCRIPT)])]
    env = {**os.environ, "PYTHONPATH": REPO}
    return subprocess.run([*cmd, *flags], cwd=cwd, env=env, capture_output=True, text=True, timeout=600)


def run_dirs(cwd) -> list[str]:
    return sorted(glob.glob(os.path.join(cwd, "runs", "*")))


def summary_of(run_dir: str) -> dict:
    with open(os.path.join(run_dir, "summary.json")) as f:
        return json.load(f)


def night(summary: dict) -> dict:
    return {k: v for k, v in summary.items() if k.startswith(NIGHT)}


def sleep_on(day_dir: str, cwd, *flags: str, study: bool = False) -> tuple[str, dict]:
    """A --sleep-from run on `day_dir`'s day in `cwd`: its new run directory and summary."""
    before = run_dirs(cwd)
    result = run(cwd, *TINY, "--sleep-from", day_dir, *flags, study=study)
    assert result.returncode == 0, result.stderr
    (new,) = set(run_dirs(cwd)) - set(before)
    return new, summary_of(new)


@pytest.fixture(scope="module")
def saved_day(tmp_path_factory):
    """A tiny run with --save-buffer (seed 3: its sleep runs, some episodes reach G in time)."""
    cwd = tmp_path_factory.mktemp("day")
    result = run(cwd, "--seed", "3", *TINY, "--save-buffer")
    assert result.returncode == 0, result.stderr
    (run_dir,) = run_dirs(cwd)
    summary = summary_of(run_dir)
    assert summary["status"] == "completed" and not summary["sleep_skipped"]
    return run_dir, summary


def test_day_pt_holds_the_day(saved_day):
    run_dir, summary = saved_day
    day = torch.load(os.path.join(run_dir, "day.pt"), weights_only=True)
    assert DOCUMENTED_KEYS <= set(day), DOCUMENTED_KEYS - set(day)
    assert day["format"] == "inform-day-1" and day["script"] == SCRIPT
    assert (day["env_id"], day["seed"]) == ("KnoxStoneMaze-v0", 3)
    assert set(day["day_args"]) == set(inform.DAY_ARGS)
    assert not any(name.startswith("sleep_") for name in day["day_args"])
    assert day["day_args"]["tamer_total_timesteps"] == 2000 and day["day_args"]["tamer_learning_starts"] == 500
    # the buffer, cut to its size
    n = summary["feedback/steps"]
    assert day["obs"].shape == day["next_obs"].shape == (n, g.N_CELLS)
    for name in ("actions", "feedback", "terminated", "success"):
        assert day[name].shape == (n,), name
    assert int(day["feedback"].sum()) == summary["feedback/positive"]  # the perfect teacher labels one step a signal
    assert int(day["success"].sum()) == summary["sleep/expert_transitions"]
    # the episode table: consecutive rows that cover the buffer
    start, end, length = day["episode_start"], day["episode_end"], day["episode_length"]
    assert start.dtype == end.dtype == length.dtype == torch.int64 and day["episode_success"].dtype == torch.bool
    assert start[0] == 0 and end[-1] == n and torch.equal(start[1:], end[:-1])
    assert torch.equal(length, end - start) and int(length.sum()) == n
    for s, e, success in zip(start.tolist(), end.tolist(), day["episode_success"].tolist(), strict=True):
        assert day["success"][s:e].tolist() == [success] * (e - s)
        assert day["terminated"][s : e - 1].sum() == 0  # G ends an episode
    assert day["episode_success"].any()
    # the networks and the stats
    assert torch.equal(day["q_star"], torch.as_tensor(g.optimal_q("plain")))
    tamer_h = torch.load(os.path.join(run_dir, "tamer_h.pt"), weights_only=True)
    assert day["h_net"]["kwargs"] == tamer_h["kwargs"]
    assert all(torch.equal(day["h_net"]["state_dict"][k], v) for k, v in tamer_h["state_dict"].items())
    assert {"torch", "numpy", "python"} <= set(day["rng"])
    assert day["day_stats"] == {k: v for k, v in summary.items() if k.startswith("feedback/") or k == "time/tamer_s"}


def test_sleep_from_gives_the_same_night(saved_day, tmp_path):
    run_dir, summary = saved_day
    assert summary["sleep_from"] is None
    # the day's seed replaces this one; --cuda on a machine without a GPU stays on the CPU and changes nothing
    no_gpu_cuda = [] if torch.cuda.is_available() else ["--cuda"]
    new_dir, new = sleep_on(run_dir, tmp_path, "--seed", "9", *no_gpu_cuda)
    assert os.path.basename(new_dir).startswith("KnoxStoneMaze-v0__inform_dqn_gridworld__3__")
    assert new["sleep_from"] == os.path.abspath(run_dir) and new["args"]["seed"] == 3
    assert new["args"]["cuda"] == bool(no_gpu_cuda)
    assert new["status"] == "completed" and not os.path.exists(os.path.join(new_dir, "day.pt"))
    assert night(new) == night(summary)  # bit for bit, every key
    assert len(night(new)) >= 25 and "losses/iq_loss" in new and "feedback/positive" in new
    assert new["time/tamer_s"] == summary["time/tamer_s"]  # the day's cost, copied
    ours, theirs = (torch.load(os.path.join(d, "inform_q.pt"), weights_only=True) for d in (new_dir, run_dir))
    assert all(torch.equal(ours["state_dict"][k], v) for k, v in theirs["state_dict"].items())


def test_sleep_seed_gives_another_night_and_the_same_one_twice(saved_day, tmp_path):
    run_dir, summary = saved_day
    _, seven = sleep_on(run_dir, tmp_path, "--sleep-seed", "7")
    assert seven["args"]["sleep_seed"] == 7
    assert seven["losses/iq_loss"] != summary["losses/iq_loss"]  # another Q network, other batches
    assert {k: v for k, v in night(seven).items() if k.startswith("feedback/")} == {
        k: v for k, v in night(summary).items() if k.startswith("feedback/")
    }  # the same day
    # a full run with --sleep-seed 7 re-seeds before its sleep too: the same night again
    (tmp_path / "full").mkdir()
    result = run(tmp_path / "full", "--seed", "3", *TINY, "--sleep-seed", "7")
    assert result.returncode == 0, result.stderr
    (full_dir,) = run_dirs(tmp_path / "full")
    assert night(summary_of(full_dir)) == night(seven)


def test_a_day_saved_and_restored_in_process(tmp_path):
    """save_day and load_day + restore_day by hand: the buffer, its episodes (one cut off) and the random streams."""
    args = inform.Args(seed=4, tamer_total_timesteps=5000)
    inform.check_args(args)
    buffer = inform.ReplayBuffer(10, g.N_CELLS, torch.device("cpu"))
    eye = np.eye(g.N_CELLS, dtype=np.float32)
    for i in range(7):  # an episode that reaches G, one cut off by the time limit, one cut off by the phase's end
        buffer.add(eye[i], i % 4, eye[i + 1], i == 2)
        if i in (2, 4):
            buffer.tag_episode(0 if i == 2 else 3, i == 2)
    buffer.feedback[[1, 5]] = 1.0
    day = inform.Day(args.day_settings(), torch.device("cpu"), g.N_CELLS, g.N_ACTIONS)
    h_net = day.h_net
    random.seed(1)
    np.random.seed(2)
    torch.manual_seed(3)
    inform.save_day(str(tmp_path / "day.pt"), day, buffer, g.optimal_q("plain"), {"feedback/steps": 7})
    expected = (random.random(), np.random.rand(), torch.rand(3))

    day = inform.load_day(str(tmp_path))
    assert [day["day_args"][k] for k in ("seed", "teacher_noise", "tamer_total_timesteps")] == [4, 0.0, 5000]
    assert day["episode_start"].tolist() == [0, 3, 5] and day["episode_end"].tolist() == [3, 5, 7]
    assert day["episode_success"].tolist() == [True, False, False] and day["episode_ended"].tolist() == [1, 1, 0]
    q_star, restored, learner = inform.restore_day(day, torch.device("cpu"))
    h = learner.h_net
    assert (random.random(), np.random.rand()) == expected[:2] and torch.equal(torch.rand(3), expected[2])
    assert restored.size == 7 and restored.episodes == buffer.episodes
    for name in inform.DAY_TENSORS:
        assert torch.equal(getattr(restored, name), getattr(buffer, name)[:7]), name
    assert np.array_equal(q_star, g.optimal_q("plain"))
    assert torch.equal(h(torch.eye(g.N_CELLS)), h_net(torch.eye(g.N_CELLS)))


def bad_day(tmp_path, kind: str) -> str:
    """A --sleep-from directory, wrong in its own way."""
    path = tmp_path / kind.replace(" ", "_")
    if kind != "no such directory":
        path.mkdir()
    if kind == "wrong format":
        torch.save({"format": "inform-day-0", "obs": torch.zeros(3, 30)}, path / "day.pt")
    if kind == "truncated":
        torch.save({"format": "inform-day-1", "obs": torch.zeros(300, 30)}, path / "full.pt")
        data = (path / "full.pt").read_bytes()
        (path / "day.pt").write_bytes(data[: len(data) // 2])
    return str(path)


@pytest.mark.parametrize(
    "kind, message",
    [
        ("no day.pt", "no day.pt in it"),
        ("no such directory", "no such directory"),
        ("wrong format", "not a saved day"),
        ("truncated", "truncated"),
    ],
)
def test_a_bad_sleep_from_is_one_line_and_leaves_nothing(tmp_path, kind, message):
    result = run(tmp_path, "--sleep-from", bad_day(tmp_path, kind))
    assert result.returncode == 2, (result.returncode, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and message in lines[0], result.stderr
    assert not os.path.exists(tmp_path / "runs")


def test_save_buffer_and_sleep_from_exclude_each_other(tmp_path):
    result = run(tmp_path, "--sleep-from", str(tmp_path), "--save-buffer")
    assert result.returncode == 2 and "--save-buffer" in result.stderr and "Traceback" not in result.stderr
    assert not os.path.exists(tmp_path / "runs")


@pytest.mark.parametrize(
    "flags, loss",
    [(["--sleep-control", "sham"], "losses/sham_loss"), (["--sleep-control", "bc"], "losses/bc_loss"),
     (["--sleep-loss-rows", "expert"], "losses/iq_loss")],
    ids=["sham", "bc", "expert-rows"],
)  # fmt: skip
def test_the_controls_and_the_expert_rows_sleep_on_a_saved_day(saved_day, tmp_path, flags, loss):
    day_dir, original = saved_day
    _, summary = sleep_on(day_dir, tmp_path, *flags, study=True)  # python -m inform_utils.sleep_variants_maze
    assert f"{flags[0].removeprefix('--sleep-').replace('-', '_')}={flags[1]}" in summary["sleep_variant"]
    assert summary["args"][flags[0].removeprefix("--").replace("-", "_")] == flags[1]  # the study flag, recorded
    assert loss in summary and 19 <= summary["eval/inform_episode_length"] <= 200  # 19: the maze's shortest path
    assert summary["feedback/positive"] == original["feedback/positive"]  # the same day
    if flags[1] != "expert":
        assert "losses/iq_expert_term" not in summary  # a control has no Eq. 2


def test_iq_loss_on_expert_rows_only():
    q_net = inform.QNetwork(2, 2)
    obs = torch.eye(2)
    args = (q_net, q_net, obs, torch.tensor([0, 1]), obs.flip(0), torch.tensor([0.0, 1.0]), torch.tensor([False, True]))
    _, every = inform.iq_loss(*args, 0.9, 0.5, 0.5)
    _, expert = inform.iq_loss(*args, 0.9, 0.5, 0.5, torch.tensor([False, True]))
    assert expert["iq_expert_term"] == every["iq_expert_term"]
    with torch.no_grad():
        q = q_net(obs)
        v = 0.5 * torch.logsumexp(q / 0.5, 1)
        y = torch.tensor([0.9 * v[1].item(), 0.0])  # the second transition ends the episode
        td = q[[0, 1], [0, 1]] - y
    assert expert["iq_value_term"].item() == pytest.approx((v[1] - y[1]).item(), rel=1e-5)
    assert expert["iq_chi2_term"].item() == pytest.approx(0.5 * td[1].item() ** 2, rel=1e-5)
    assert every["iq_value_term"].item() == pytest.approx((v - y).mean().item(), rel=1e-5)


def test_the_sleep_study_runs_maze_nights_and_tabulates_them(saved_day, tmp_path):
    """python -m inform_utils.sleep_study --script inform_dqn_gridworld.py: the maze's nights (the default with two
    sleep seeds, a control with both, a variant with the first), its own columns, and a rerun that runs nothing."""
    day_dir, _ = saved_day
    cwd = tmp_path  # the nights' runs/ and results/ land here
    cmd = [sys.executable, "-m", "inform_utils.sleep_study", "--script", SCRIPT, "--days", day_dir, "--campaign", "m"]
    cmd += ["--variants", "default", "sham", "expert_rows", "--sleep-seeds", "4", "5", "--", *TINY]
    env = {**os.environ, "PYTHONPATH": REPO}
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    nights = cwd / "results" / "m" / os.path.basename(day_dir)
    assert sorted(os.listdir(nights)) == ["default__sleep4", "default__sleep5", "expert_rows__sleep4", "sham__sleep4",
                                          "sham__sleep5"]  # fmt: skip
    summary = json.loads((nights / "expert_rows__sleep4" / "summary.json").read_text())
    assert summary["args"]["sleep_seed"] == 4 and summary["args"]["sleep_loss_rows"] == "expert"
    assert "held-out start cells: success" in proc.stdout and "obstacle" not in proc.stdout
    assert (
        "| default | 2 |" in proc.stdout
        and "| expert_rows | 1 |" in proc.stdout
        and "| tamer | 1 days |" in proc.stdout
    )
    again = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)  # resumes: nothing runs
    assert again.returncode == 0 and "[study]" not in again.stdout
