"""The plumbing of inform_sac_pusher.py holds where users have broken it: each probe ends either with one `error:` line
and exit 2 before anything is written (bad input), or with a summary.json whose status says what happened."""

import contextlib
import errno
import glob
import io
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch
import tyro
from conftest import REPO

import inform_sac_pusher as isp

SCRIPT = os.path.join(REPO, "inform_sac_pusher.py")
SHIPPED = os.path.join(REPO, "oracles", "Pusher-v5__sac_oracle.pt")
TINY = ["--tamer-total-timesteps", "600", "--tamer-learning-starts", "300", "--tamer-batch-size", "64",
        "--sleep-gradient-steps", "100", "--sleep-batch-size", "64", "--eval-episodes", "1", "--obstacle-episodes", "1",
        "--authors-test-episodes", "1", "--success-distance", "1.0"]  # fmt: skip


def run(cwd, *flags, env=None, timeout=300):
    return subprocess.run([sys.executable, SCRIPT, *flags], cwd=cwd, capture_output=True, text=True, timeout=timeout,
                          env=env)  # fmt: skip


def refused(tmp_path, *flags, needle):
    proc = run(tmp_path, *flags, timeout=120)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), proc.stderr[-2000:]
    assert needle in lines[0], lines[0]
    assert not os.listdir(tmp_path), os.listdir(tmp_path)  # nothing written


def summary_of(cwd) -> tuple[str, dict]:
    (run_dir,) = glob.glob(os.path.join(str(cwd), "runs", "*"))
    with open(os.path.join(run_dir, "summary.json")) as f:
        return run_dir, json.load(f)


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_a_success_return_that_is_not_a_number_is_refused(tmp_path, value):
    refused(tmp_path, "--success-return", value, needle=f"--success-return must be in (-inf, inf), got {value}")


@pytest.mark.parametrize("name", ["../x", "a/b", "x" * 300, ".."])
def test_run_names_stay_inside_runs(tmp_path, name):
    refused(tmp_path, "--exp-name", name, needle="not one folder name in runs/")


@pytest.mark.parametrize("flag", ["--seed", "--sleep-seed"])
@pytest.mark.parametrize("value", [str(2**32), "-1"])
def test_seeds_are_what_numpy_and_torch_accept(tmp_path, flag, value):
    refused(tmp_path, flag, value, needle=f"{flag} must be >= 0 and < 4294967296, got {value}")


def test_the_largest_seed_numpy_takes_passes_the_checks():
    isp.check_args(tyro.cli(isp.Args, args=["--seed", str(2**32 - 1), "--sleep-seed", str(2**32 - 1)]))


@pytest.mark.skipif(not os.path.isfile(SHIPPED), reason="shipped oracle missing")
def test_a_nan_oracle_is_refused(tmp_path):
    ckpt = torch.load(SHIPPED, weights_only=True)
    ckpt["qf_state_dict"] = {k: torch.full_like(v, float("nan")) for k, v in ckpt["qf_state_dict"].items()}
    torch.save(ckpt, tmp_path.parent / "nan_oracle.pt")
    refused(tmp_path, "--oracle-path", str(tmp_path.parent / "nan_oracle.pt"), needle="networks hold NaN or inf")


@pytest.fixture(scope="module")
def day(tmp_path_factory):
    cwd = tmp_path_factory.mktemp("day")
    assert run(cwd, *TINY, "--save-buffer").returncode == 0
    return summary_of(cwd)[0]


def tamper(day, tmp_path, **changes):
    saved = torch.load(os.path.join(day, "day.pt"), weights_only=True)
    for key, change in changes.items():
        saved[key] = change(saved[key])
    os.makedirs(tmp_path / "day")
    torch.save(saved, tmp_path / "day" / "day.pt")
    return str(tmp_path / "day")


def with_item(index, value):
    def change(tensor):
        tensor = tensor.clone()
        tensor[index] = value
        return tensor

    return change


@pytest.mark.parametrize(
    ("changes", "needle"),
    [
        ({"episode_end": with_item(0, 10**9)}, "the day's episode table"),
        ({"episode_start": with_item(1, -5)}, "the day's episode table"),
        ({"obs": lambda t: t[:, :5]}, "the day's shapes"),
        ({"actions": with_item((3, 0), float("nan"))}, "the day's values"),
        ({"terminated": with_item(2, 7.0)}, "the day's terminated flags"),
        ({"feedback": lambda t: t[:-1]}, "the day's shapes"),
        ({"episode_shortfall": lambda t: "x"}, "not a day as --save-buffer writes it"),
    ],
    ids=["episode_end", "negative_start", "obs_shape", "nan_action", "terminated_7", "short_feedback", "not_tensor"],
)
def test_a_tampered_day_is_refused_on_load(day, tmp_path, changes, needle):
    path = tamper(day, tmp_path, **changes)
    with pytest.raises(isp.InputError) as err:
        isp.load_day(path)
    assert needle in str(err.value) and "\n" not in str(err.value)


def test_a_tampered_day_is_one_line_before_anything_is_written(day, tmp_path):
    path = tamper(day, tmp_path / "in", episode_end=with_item(0, 10**9))
    (tmp_path / "cwd").mkdir()
    refused(tmp_path / "cwd", "--sleep-from", path, needle="the day's episode table are not what --save-buffer writes")


@pytest.mark.skipif(not os.path.isfile(SHIPPED), reason="shipped oracle missing")
def test_tamer_diverging_is_named_as_tamers_with_the_flag_that_helps(tmp_path):
    proc = run(tmp_path, *TINY, "--tamer-h-lr", "1e30")
    # MuJoCo may warn of the NaN action it was given before the check (its own line, not ours): ours is one line
    lines = [line for line in proc.stderr.splitlines() if line.strip() and not line.startswith("WARNING: Nan, Inf")]
    assert proc.returncode == 1 and len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert "TAMER's feedback model H" in lines[0] and "--tamer-h-lr" in lines[0], lines[0]
    _, summary = summary_of(tmp_path)
    assert summary["status"] == "diverged" and summary["phase"] == "tamer" and "--tamer-h-lr" in summary["error"]


def in_process_run(tmp_path, monkeypatch, *flags) -> dict:
    monkeypatch.chdir(tmp_path)
    args = tyro.cli(isp.Args, args=[*TINY, *flags])
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    try:
        return isp.main(
            args,
            isp.load_oracle(
                args.env_id, args.contact, args.oracle_path, args.train_oracle, args.oracle_total_timesteps
            ),
            isp.StopSignals(),
        )
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)


@pytest.mark.skipif(not os.path.isfile(SHIPPED), reason="shipped oracle missing")
def test_a_disk_that_fills_while_saving_the_day_fails_with_the_reason_and_leaves_no_partial_file(tmp_path, monkeypatch):
    real_save = torch.save

    def full_disk(obj, f, *args, **kwargs):  # as torch reports ENOSPC: part of the file written, then RuntimeError
        if str(getattr(f, "name", f)).endswith("day.pt.tmp"):
            f.write(b"\0" * 200_000)
            raise RuntimeError("[enforce fail at inline_container.cc:603] . unexpected pos 1 vs 0: file write failed")
        return real_save(obj, f, *args, **kwargs)

    monkeypatch.setattr(torch, "save", full_disk)
    summary = in_process_run(tmp_path, monkeypatch, "--save-buffer")  # no exception: the reason is known
    run_dir, written = summary_of(tmp_path)
    assert written["status"] == "failed" and written["phase"] == "tamer" and "file write failed" in written["error"]
    assert written["error"].startswith("OSError: runs/") and summary["status"] == "failed"
    assert not glob.glob(os.path.join(run_dir, "*.tmp")) and os.path.isfile(os.path.join(run_dir, "tamer_actor.pt"))


@pytest.mark.skipif(not os.path.isfile(SHIPPED), reason="shipped oracle missing")
def test_a_disk_that_fills_while_writing_the_obstacle_paths_leaves_no_partial_file(tmp_path, monkeypatch):
    """Issue 55, item 11: obstacle_*.npz were written in place; on a full disk obstacle_paths.npz was left at 8,192 of
    its 12,072 bytes. As np.savez meets a full disk: two pages written, then ENOSPC. Neither file is half there."""
    real_savez = np.savez

    def full_disk(file, *args, **kwargs):
        name = str(getattr(file, "name", file))
        if "obstacle_paths" not in name:
            return real_savez(file, *args, **kwargs)
        whole = io.BytesIO()
        real_savez(whole, *args, **kwargs)
        with open(name, "wb") if isinstance(file, str) else contextlib.nullcontext(file) as f:
            f.write(whole.getvalue()[:8192])
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(np, "savez", full_disk)
    short = ["--tamer-total-timesteps", "300", "--tamer-learning-starts", "200", "--sleep-gradient-steps", "10"]
    summary = in_process_run(tmp_path, monkeypatch, *short, "--authors-test-episodes", "0")  # no exception
    run_dir, written = summary_of(tmp_path)
    assert written["status"] == "failed" and written["phase"] == "eval" and "No space left" in written["error"]
    assert summary["status"] == "failed" and os.path.isfile(os.path.join(run_dir, "obstacle_distances.npz"))
    assert not glob.glob(os.path.join(run_dir, "obstacle_paths*")), os.listdir(run_dir)  # nor its .tmp


@pytest.mark.skipif(not os.path.isfile(SHIPPED), reason="shipped oracle missing")
def test_a_full_disk_at_the_start_is_one_line(tmp_path, monkeypatch, capsys):
    def no_room(path, *args, **kwargs):
        raise OSError(28, "No space left on device", path)

    monkeypatch.setattr(os, "makedirs", no_room)
    summary = in_process_run(tmp_path, monkeypatch)
    assert summary["status"] == "failed" and "No space left on device" in summary["error"]
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: OSError: [Errno 28] No space left on device"), err


def can_mount_tmpfs(path) -> bool:
    if os.geteuid() != 0:
        return False
    mount = ["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(path)]
    return subprocess.run(mount, capture_output=True).returncode == 0


@pytest.mark.skipif(not os.path.isfile(SHIPPED), reason="shipped oracle missing")
def test_a_real_2mb_disk_that_fills_during_save_buffer(tmp_path):
    disk = tmp_path / "disk"
    disk.mkdir()
    if not can_mount_tmpfs(disk):
        pytest.skip("cannot mount a tmpfs here (needs root)")
    try:
        proc = run(disk, *TINY, "--save-buffer")
        assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
        run_dir, summary = summary_of(disk)
        assert summary["status"] == "failed" and "day.pt" in summary["error"], summary.get("error")
        assert not glob.glob(os.path.join(run_dir, "*.tmp")), os.listdir(run_dir)
    finally:
        subprocess.run(["umount", str(disk)], check=True)


@pytest.mark.skipif(not os.path.isfile(SHIPPED), reason="shipped oracle missing")
@pytest.mark.skipif(not __import__("importlib").util.find_spec("wandb"), reason="wandb is not installed")
def test_track_stops_within_two_seconds_of_a_signal(tmp_path):
    env = {**os.environ, "WANDB_MODE": "offline", "WANDB_SILENT": "true"}
    cmd = [sys.executable, SCRIPT, "--track", *TINY, "--sleep-gradient-steps", "100000"]
    proc = subprocess.Popen(cmd, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for line in proc.stdout:
        if line.startswith("[sleep]"):
            break
    sent = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    proc.communicate(timeout=60)
    took = time.monotonic() - sent
    assert proc.returncode == 143 and took < 2.0, (proc.returncode, took)
    _, summary = summary_of(tmp_path)
    assert summary["status"] == "interrupted" and summary["signal"] == "SIGTERM"


def test_mujocos_warnings_go_to_the_run_directory_not_the_working_directory(tmp_path, monkeypatch, capsys):
    """An unstable simulation (a diverging TAMER drives it there) makes MuJoCo warn: by default on stderr and into
    ./MUJOCO_LOG.TXT, the repository when run from it. Here into the run's own MUJOCO_LOG.TXT only."""
    import gymnasium as gym
    import mujoco

    monkeypatch.chdir(tmp_path)
    os.makedirs("runs/r")
    previous = mujoco.get_mju_user_warning()
    try:
        isp.mujoco_log_in("runs/r")
        env = gym.make("Pusher-v5")
        env.reset(seed=0)
        env.unwrapped.data.qvel[:] = 1e30
        for _ in range(3):
            env.unwrapped.do_simulation([0.0] * 7, 1)
    finally:
        mujoco.set_mju_user_warning(previous)
    assert sorted(os.listdir(tmp_path)) == ["runs"] and os.listdir("runs/r") == ["MUJOCO_LOG.TXT"]
    assert "The simulation is unstable" in open("runs/r/MUJOCO_LOG.TXT").read()
    assert capsys.readouterr().err == ""
