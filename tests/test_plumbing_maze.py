"""Plumbing that holds, in the maze script: a disk that fills, a read-only or full disk at the start, run names outside
runs/, seeds numpy cannot take, TAMER diverging, a NaN oracle, a closed stdin for the human teacher, a tampered day.
Each ends with one `error:` line and exit 2 before anything is written, or with a summary.json that says what
happened."""

import contextlib
import errno
import glob
import json
import os
import signal
import subprocess
import sys

import numpy as np
import pytest
import torch
from conftest import REPO

import gridworld_env as g
import inform_dqn_gridworld as inform

SCRIPT = os.path.join(REPO, "inform_dqn_gridworld.py")
TINY = ["--tamer-total-timesteps", "2000", "--tamer-learning-starts", "500", "--sleep-gradient-steps", "200"]


def run(cwd, *flags, stdin=None, shell_suffix=""):
    if shell_suffix:  # e.g. "<&-": the script started with its standard input closed
        command = " ".join([sys.executable, SCRIPT, *flags]) + " " + shell_suffix
        return subprocess.run(["bash", "-c", command], cwd=cwd, capture_output=True, text=True, timeout=300)
    return subprocess.run([sys.executable, SCRIPT, *flags], cwd=cwd, input=stdin, capture_output=True, text=True,
                          timeout=300)  # fmt: skip


def assert_one_line(proc, cwd, needle, code=2):
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == code and len(lines) == 1 and lines[0].startswith("error:"), (proc.returncode, proc.stderr)
    assert needle in lines[0] and "Traceback" not in proc.stderr, proc.stderr
    assert not os.path.exists(os.path.join(cwd, "runs")) or not os.listdir(os.path.join(cwd, "runs"))


def only_summary(cwd) -> dict:
    (path,) = glob.glob(os.path.join(cwd, "runs", "*", "summary.json"))
    with open(path) as f:
        return json.load(f)


# a disk that fills while the day is saved ----------------------------------------------------------------------------
def test_a_disk_that_fills_during_save_buffer_fails_with_the_reason_and_no_partial_file(tmp_path, monkeypatch):
    """torch.save writes part of day.pt, then the disk is full: status failed with the reason, the partial
    day.pt.tmp removed, the summary written, one line and no traceback (in process, as a 2 MB disk would)."""
    real_save = torch.save

    def fills_up(obj, f, *a, **kw):
        if getattr(f, "name", "").endswith("day.pt.tmp"):
            f.write(b"x" * 100_000)
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_save(obj, f, *a, **kw)

    monkeypatch.setattr(inform.torch, "save", fills_up)
    monkeypatch.chdir(tmp_path)
    args = inform.Args(tamer_total_timesteps=600, tamer_learning_starts=100, sleep_gradient_steps=10, save_buffer=True)
    inform.check_args(args)
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    try:
        summary = inform.main(args, None, inform.StopSignals())  # no exception: a full disk is not a bug
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
    assert summary["status"] == "failed" and summary["phase"] == "tamer"
    assert "No space left on device" in summary["error"]
    written = only_summary(tmp_path)
    assert written["status"] == "failed" and written["error"] == summary["error"]
    (run_dir,) = glob.glob(str(tmp_path / "runs" / "*"))
    assert not glob.glob(os.path.join(run_dir, "day.pt*"))  # neither the day nor its partial file


@contextlib.contextmanager
def small_disk(path, options="size=2m"):
    path.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)]).returncode:
        pytest.skip("needs root to mount a small tmpfs")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)])


def test_a_real_2mb_disk_that_fills_during_save_buffer(tmp_path):
    with small_disk(tmp_path / "disk") as disk:
        proc = run(disk, "--save-buffer", "--sleep-gradient-steps", "10")
        assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
        summary = only_summary(disk)
        assert summary["status"] == "failed" and "day.pt" in summary["error"] and "OSError" in summary["error"]
        assert not glob.glob(str(disk / "runs" / "*" / "day.pt*"))


@pytest.mark.parametrize("kind", ["read-only", "full"])
def test_a_read_only_or_full_disk_at_the_start_is_one_line(tmp_path, kind):
    with small_disk(tmp_path / "disk", "ro,size=2m" if kind == "read-only" else "size=2m") as disk:
        if kind == "full":
            with contextlib.suppress(OSError), open(disk / "fill", "wb") as f:
                while True:
                    f.write(bytes(1 << 16))
        proc = run(disk, *TINY)
        needle = "Read-only file system" if kind == "read-only" else "No space left on device"
        assert_one_line(proc, disk, needle)


# bad input: one line, exit 2, nothing written -------------------------------------------------------------------------
@pytest.mark.parametrize(
    "flags, needle",
    [
        (["--exp-name", "../../x"], "not one folder name in runs/"),
        (["--exp-name", "a/b"], "not one folder name in runs/"),
        (["--exp-name", "x" * 300], "not one folder name in runs/"),
        (["--seed", str(2**32)], "--seed must be >= 0 and below 4294967296"),
        (["--sleep-seed", str(2**32)], "--sleep-seed must be >= 0 and below 4294967296"),
        (["--seed", "-1"], "--seed must be >= 0"),
    ],
    ids=["dotdot", "separator", "300-characters", "seed", "sleep-seed", "negative-seed"],
)
def test_run_names_and_seeds_are_checked_before_anything_is_written(tmp_path, flags, needle):
    assert_one_line(run(tmp_path, *flags), tmp_path, needle)
    assert not os.path.exists(tmp_path / "x") and os.listdir(tmp_path) == []


def test_a_nan_oracle_is_refused_in_one_line(tmp_path):
    torch.save({"q_table": torch.full((g.N_CELLS, g.N_ACTIONS), float("nan")), "env_id": "KnoxStoneMaze-v0"},
               tmp_path / "nan.pt")  # fmt: skip
    assert_one_line(run(tmp_path, "--oracle-path", "nan.pt"), tmp_path, "NaN")


def test_the_human_teacher_with_stdin_closed_is_one_line(tmp_path):
    assert_one_line(run(tmp_path, "--teacher", "human", shell_suffix="<&-"), tmp_path, "standard input")


# TAMER diverging: named as TAMER's, with the flag that helps ----------------------------------------------------------
def test_tamer_diverging_is_named_with_its_flag(tmp_path):
    proc = run(tmp_path, *TINY, "--tamer-h-lr", "1e30")
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    summary = only_summary(tmp_path)
    assert summary["status"] == "diverged" and summary["phase"] == "tamer"
    assert "TAMER's H diverged" in summary["error"] and "--tamer-h-lr" in summary["error"]
    assert summary["error"] in proc.stderr


# a tampered day, refused on load -------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def day_file(tmp_path_factory):
    """A small day saved by save_day (an episode that reaches G, one cut off by the phase's end)."""
    path = tmp_path_factory.mktemp("day")
    args = inform.Args(seed=4, tamer_total_timesteps=5000)
    inform.check_args(args)
    buffer = inform.ReplayBuffer(10, g.N_CELLS, torch.device("cpu"))
    eye = np.eye(g.N_CELLS, dtype=np.float32)
    for i in range(6):
        buffer.add(eye[i], i % 4, eye[i + 1], i == 2)
        if i == 2:
            buffer.tag_episode(0, True)
    buffer.feedback[[1, 4]] = 1.0
    day = inform.Day(args.day_settings(), torch.device("cpu"), g.N_CELLS, g.N_ACTIONS)
    inform.save_day(str(path / "day.pt"), day, buffer, g.optimal_q("plain"), {"feedback/steps": 6})
    return path


def tamper(day_dir, tmp_path, change) -> str:
    day = torch.load(os.path.join(day_dir, "day.pt"), weights_only=True)
    change(day)
    out = tmp_path / "tampered"
    out.mkdir()
    torch.save(day, out / "day.pt")
    return str(out)


TAMPERINGS = {
    "episode_end[0] = 10**9": lambda day: day["episode_end"].__setitem__(0, 10**9),
    "a negative episode index": lambda day: day["episode_start"].__setitem__(1, -3),
    "a feedback of 9": lambda day: day["feedback"].__setitem__(1, 9.0),
    "an action of 7": lambda day: day["actions"].__setitem__(0, 7),
}


@pytest.mark.parametrize("change", TAMPERINGS.values(), ids=TAMPERINGS.keys())
def test_a_tampered_day_is_refused_on_load(day_file, tmp_path, change):
    tampered = tamper(day_file, tmp_path, change)
    with pytest.raises(inform.InputError, match="tampered"):
        inform.load_day(tampered)
    inform.load_day(str(day_file))  # the untouched day loads


def test_a_tampered_day_is_one_line_from_the_command_line(day_file, tmp_path):
    tampered = tamper(day_file, tmp_path, TAMPERINGS["episode_end[0] = 10**9"])
    assert_one_line(run(tmp_path, "--sleep-from", tampered), tmp_path, "episode_start, episode_end out of range")
