"""run_seeds.py --launcher slurm against a real Slurm (bash .ci/slurm_up.sh up starts a single-node one; .ci/run does
that and sets INFORM_REQUIRE_SLURM=1, which turns the skip below into a failure)."""

import glob
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import pytest
from conftest import REPO, default_signals

pytestmark = pytest.mark.slurm
RUN_SEEDS = os.path.join(REPO, "inform_utils", "run_seeds.py")
GRIDWORLD = os.path.join(REPO, "inform_dqn_gridworld.py")


def slurm_missing() -> str | None:
    """Why no Slurm is usable here, or None."""
    if shutil.which("sbatch") is None:
        return "no sbatch on PATH"
    try:
        out = subprocess.run(["sinfo", "-h", "-o", "%t"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired) as e:
        return f"sinfo failed: {e}"
    if out.returncode != 0:
        return f"sinfo failed: {out.stderr.strip()[:200]}"
    if not any(
        state.rstrip("*~#!%$@^-") in {"idle", "mix", "mixed", "alloc", "allocated"} for state in out.stdout.split()
    ):
        return f"no node up (sinfo node states: {out.stdout.split()})"
    return None


@pytest.fixture(scope="module", autouse=True)
def slurm():
    reason = slurm_missing()
    if reason:
        message = f"no Slurm up ({reason}); start one with `bash .ci/slurm_up.sh up` (root, Debian)"
        if os.environ.get("INFORM_REQUIRE_SLURM") == "1":
            pytest.fail(f"INFORM_REQUIRE_SLURM=1 but {message}")
        pytest.skip(message)


def run_seeds(tmp_path, *flags: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, RUN_SEEDS, "--poll-seconds", "1", *flags], cwd=tmp_path,
                          capture_output=True, text=True, timeout=timeout)  # fmt: skip


def calls(tmp_path) -> list[int]:
    path = tmp_path / "calls.txt"
    return sorted(int(line.split()[0]) for line in path.read_text().splitlines()) if path.exists() else []


def in_queue(array_id: str) -> list[str]:
    out = subprocess.run(["squeue", "-h", "-r", "-o", "%i", "-j", array_id], capture_output=True, text=True)
    return out.stdout.split()


def array_id(stdout: str) -> str:
    return stdout.split("as Slurm job array ", 1)[1].split()[0]


def test_two_gridworld_seeds_and_a_grid_through_slurm_then_resume(tmp_path):
    flags = ["--script", GRIDWORLD, "--exp-name", "ci", "--seeds", "1", "2", "--launcher", "slurm", "--slurm-time",
             "10", "--grid", "tamer-total-timesteps=300,400", "--", "--sleep-gradient-steps", "100",
             "--tamer-learning-starts", "100"]  # fmt: skip
    result = run_seeds(tmp_path, *flags)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "submitted 4 run(s)" in result.stdout and " pending, " in result.stdout and " running, " in result.stdout
    assert "0 pending, 0 running, 4 done, 0 failed or stopped" in result.stdout
    saved = json.load(open(tmp_path / "runs" / "ci__table.json"))
    points = {p["point"]["tamer-total-timesteps"]: p for p in saved["points"]}
    assert set(points) == {"300", "400"}
    for steps, point in points.items():
        table = point["table"]
        assert table["feedback/steps"]["values"] == [int(steps)] * 2  # each grid point ran with its own flag
        assert table["eval/oracle_episode_length"] == {"mean": 19.0, "std": 0.0, "n": 2, "values": [19.0, 19.0]}
        for seed, path in point["runs"].items():
            summary = json.load(open(tmp_path / path))
            assert summary["seed"] == int(seed) and summary["status"] == "completed"
            assert summary["args"]["tamer_total_timesteps"] == int(steps)
    assert "ci [tamer-total-timesteps=300]: 2 of 2 seeds finished" in result.stdout
    print(result.stdout)

    again = run_seeds(tmp_path, *flags)
    assert again.returncode == 0, again.stdout + again.stderr
    assert "submitted" not in again.stdout and "already finished, not run again" in again.stdout


def test_a_failed_job_is_reported_with_the_tail_of_its_stderr(tmp_path, fake_script):
    result = run_seeds(tmp_path, "--script", "fake.py", "--exp-name", "f", "--seeds", "1", "2", "--launcher",
                       "slurm", "--slurm-time", "5", "--slurm-mem", "1G", "--", "--fail-seed", "2")  # fmt: skip
    assert result.returncode == 1, result.stdout + result.stderr
    assert "seed 2: failed: exit 1" in result.stdout and "boom: seed 2 refuses to run" in result.stdout
    assert "f: 1 of 2 seeds finished, missing [2]" in result.stdout
    assert result.stderr.splitlines() == ["error: 1 of 2 run(s) did not finish (failed: seed 2); run the same "
                                          "command again to rerun them"]  # fmt: skip


def test_unknown_partition_is_one_line_before_anything_is_written(tmp_path, fake_script):
    before = sorted(os.listdir(tmp_path))
    result = run_seeds(tmp_path, "--script", "fake.py", "--launcher", "slurm", "--slurm-partition", "nosuch")
    assert result.returncode == 2, result.stdout + result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: --slurm-partition nosuch: no such partition"), lines
    assert sorted(os.listdir(tmp_path)) == before


def test_more_cpus_than_a_node_has_is_one_line(tmp_path, fake_script):
    result = run_seeds(tmp_path, "--script", "fake.py", "--launcher", "slurm", "--slurm-cpus-per-task", "4096")
    assert result.returncode == 2, result.stdout + result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: --launcher slurm: Slurm refuses a job of"), lines


def test_a_job_over_its_time_limit_is_reported_as_such(tmp_path, fake_script):
    """--slurm-time 1 and a run that would wait 10 minutes: Slurm stops it after a minute (about 70 s here, no CPU
    used); the run saves what finished on Slurm's SIGTERM; run_seeds reports the time limit."""
    (tmp_path / "block").write_text("")
    result = run_seeds(tmp_path, "--script", "fake.py", "--exp-name", "t", "--seeds", "1", "--launcher", "slurm",
                       "--slurm-time", "1")  # fmt: skip
    assert result.returncode == 1, result.stdout + result.stderr
    assert "seed 1: timeout: job " in result.stdout and "exceeded --slurm-time 1 min" in result.stdout
    assert "the run stopped by SIGTERM during the forward phase" in result.stdout
    assert result.stderr.splitlines() == ["error: 1 of 1 run(s) did not finish (timeout: seed 1); run the same "
                                          "command again to rerun them"]  # fmt: skip
    (summary_path,) = glob.glob(str(tmp_path / "runs" / "*__t__1__*" / "summary.json"))
    summary = json.load(open(summary_path))
    assert summary["status"] == "interrupted" and summary["signal"] == "SIGTERM"


def test_sigterm_to_run_seeds_cancels_its_jobs_and_a_rerun_resumes(tmp_path, fake_script):
    """kill -TERM of run_seeds --launcher slurm: it cancels its job array (Slurm sends the runs SIGTERM, they save),
    reports the runs as interrupted and exits 143; the same command then runs them again."""
    (tmp_path / "block").write_text("")
    cmd = [sys.executable, RUN_SEEDS, "--poll-seconds", "1", "--script", "fake.py", "--exp-name", "k", "--seeds", "1",
           "2", "--launcher", "slurm", "--slurm-time", "10"]  # fmt: skip
    proc = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=default_signals)  # fmt: skip
    deadline = time.time() + 120
    while len(calls(tmp_path)) < 2 and time.time() < deadline and proc.poll() is None:
        time.sleep(0.2)
    started = len(calls(tmp_path)) == 2
    proc.send_signal(signal.SIGTERM)
    try:
        out, err = proc.communicate(timeout=180)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate(timeout=30)
        pytest.fail(f"run_seeds did not exit within 180 s of SIGTERM\nstdout:\n{out}\nstderr:\n{err}")
    assert started, f"the two jobs did not start within 120 s\nstdout:\n{out}\nstderr:\n{err}"
    assert proc.returncode == 143, out + err
    assert "cancelling Slurm job array" in out
    assert "seed 1: interrupted: job " in out and "seed 2: interrupted: job " in out and "by SIGTERM" in out, out
    assert err.strip().splitlines()[-1].startswith("error: stopped by SIGTERM; 2 run(s) not finished"), err
    assert in_queue(array_id(out)) == []
    summaries = [json.load(open(p)) for p in glob.glob(str(tmp_path / "runs" / "*__k__*" / "summary.json"))]
    assert sorted((s["seed"], s["status"], s["signal"]) for s in summaries) == [
        (1, "interrupted", "SIGTERM"),
        (2, "interrupted", "SIGTERM"),
    ]

    (tmp_path / "block").unlink()
    again = run_seeds(tmp_path, *cmd[3:])
    assert again.returncode == 0, again.stdout + again.stderr
    assert "submitted 2 run(s)" in again.stdout and "k: 2 of 2 seeds finished" in again.stdout
    assert calls(tmp_path) == [1, 1, 2, 2]
