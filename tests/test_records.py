"""No run ends as completed without its record. On a real disk (a tmpfs, needs root) out of inodes or out of space just
as the last file is written, each script says so in one line and exits 1: the INFORM scripts (their summary.json),
the reward experiment (its agents, figure and summary), the oracle trainer (its checkpoint and report). A caller
(run_seeds, Slurm, CI) then counts the run as failed; nothing half-written is left."""

import contextlib
import glob
import json
import os
import subprocess
import sys

import pytest
from conftest import Child
from test_plumbing_maze import small_disk  # a tmpfs of the given options, or a skip without root

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REWARD_RUN = os.path.join(REPO, "results", "maze_reward12", "KnoxStoneMaze-v0__reward12__1__1796039345")
PUSHER_TINY = ["--tamer-total-timesteps", "600", "--tamer-learning-starts", "300", "--tamer-batch-size", "64",
               "--sleep-gradient-steps", "20", "--sleep-batch-size", "64", "--eval-episodes", "1",
               "--obstacle-episodes", "1", "--authors-test-episodes", "1"]  # fmt: skip
COMMANDS = {
    "maze": ["inform_dqn_gridworld.py", "--tamer-total-timesteps", "2000", "--tamer-learning-starts", "500",
             "--sleep-gradient-steps", "50"],
    "pusher": ["inform_sac_pusher.py", *PUSHER_TINY],
    "reward": ["q_learning_recovered_reward.py", "--reward-path", REWARD_RUN, "--num-seeds", "1", "--num-episodes",
               "20"],
    "oracle": ["oracle_train.py", "--env-id", "Pusher-v5", "--total-timesteps", "300", "--learning-starts", "200",
               "--batch-size", "32", "--hidden-size", "32", "--eval-frequency", "300", "--eval-episodes", "1",
               "--final-eval-episodes", "1"],
}  # fmt: skip


def run(name: str, cwd) -> subprocess.CompletedProcess:
    script, *flags = COMMANDS[name]
    return subprocess.run([sys.executable, os.path.join(REPO, script), *flags], cwd=cwd, capture_output=True,
                          text=True, timeout=600)  # fmt: skip


def written(root) -> list[tuple[str, int]]:
    return sorted((os.path.relpath(os.path.join(d, f), root), os.path.getsize(os.path.join(d, f)))
                  for d, _, files in os.walk(root) for f in files)  # fmt: skip


def assert_no_record(proc, disk, name: str) -> None:
    assert proc.returncode == 1, (proc.returncode, proc.stdout[-1500:], proc.stderr[-3000:])
    errors = [line for line in proc.stderr.splitlines() if line.startswith(("error: ", "failed: "))]
    assert len(errors) == 1 and "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert "No space left on device" in errors[0] and proc.stderr.strip().endswith(errors[0]), proc.stderr[-3000:]
    assert "completed in" not in proc.stdout and "done in" not in proc.stdout, proc.stdout[-1500:]
    files = [f for f, _ in written(disk)]
    assert not [f for f in files if ".tmp" in f], files  # nothing half-written
    if name != "oracle":
        assert not [f for f in files if f.endswith(("summary.json", "agents.npz", "fig6.png"))], files


@pytest.mark.parametrize("name", list(COMMANDS))
def test_a_disk_out_of_inodes_at_the_last_file_is_no_completed_run(tmp_path, name):
    """A reference run counts the files and directories a run makes; the same run on a tmpfs with one inode fewer
    (the tmpfs's root takes one) cannot make the last of them."""
    reference = tmp_path / "reference"
    reference.mkdir()
    proc = run(name, reference)
    assert proc.returncode == 0, proc.stderr[-3000:]
    inodes = sum(len(dirs) + len(files) for _, dirs, files in os.walk(reference))
    with small_disk(tmp_path / "disk", f"size=50m,nr_inodes={inodes}") as disk:  # root + all but the last
        assert_no_record(run(name, disk), disk, name)


def test_the_reward_experiment_on_a_disk_that_fills_at_its_figure(tmp_path):
    """Room for the events and the agents but not for the figure and the summary: one line, none of the three."""
    reference = tmp_path / "reference"
    reference.mkdir()
    assert run("reward", reference).returncode == 0
    pages = {os.path.basename(f).split(".")[0]: -(-size // 4096) for f, size in written(reference)}
    room = pages["events"] + pages["agents"] + pages["fig6"] // 2  # the figure is several times a page
    with small_disk(tmp_path / "disk", f"size={room * 4096}") as disk:
        assert_no_record(run("reward", disk), disk, "reward")


# TensorBoard's writer on a full disk (issue 55, item 10) ------------------------------------------------------------
def test_a_disk_that_fills_mid_day_while_tensorboard_writes_is_one_line(tmp_path):
    """The disk fills while the maze's day runs and stays full: TensorBoard's writer thread fails at its next event. It
    was a traceback from that thread and another from writer.close(); it is the run's one line, exit 1, no record."""
    script, *flags = COMMANDS["maze"]
    with small_disk(tmp_path / "disk", "size=4m") as disk:
        child = Child([sys.executable, os.path.join(REPO, script), *flags], disk)
        child.wait_for_line("[tamer]")
        with contextlib.suppress(OSError), open(disk / "fill", "wb") as f:
            while True:
                f.write(bytes(1 << 16))
        code, out, err = child.finish()
        assert_no_record(subprocess.CompletedProcess(script, code, out, err), disk, "maze")


A_MOMENT = """
import errno, sys
import tyro
from tensorboard.compat.tensorflow_stub.io import gfile
import {module} as core

append, full = gfile.LocalFileSystem.append, []

def append_or_full(self, filename, file_content, binary_mode=False):  # no room for the first {tag!r} event, once
    if not full and {tag!r}.encode() in file_content:
        full.append(filename)
        raise OSError(errno.ENOSPC, "No space left on device")
    return append(self, filename, file_content, binary_mode)

gfile.LocalFileSystem.append = append_or_full
sys.exit(core.cli(tyro.cli(core.Args, args={flags!r})))
"""


PUSHER_SHORT = ["inform_sac_pusher.py", "--tamer-total-timesteps", "300", "--tamer-learning-starts", "200",
                "--tamer-batch-size", "64", "--sleep-gradient-steps", "20", "--sleep-batch-size", "64",
                "--eval-episodes", "1", "--obstacle-episodes", "0", "--authors-test-episodes", "1"]  # fmt: skip


@pytest.mark.parametrize(
    ("command", "tag"),
    [(COMMANDS["maze"], "charts/"), (PUSHER_SHORT, "charts/"), (PUSHER_SHORT, "eval/authors_test/")],
    ids=["maze-mid-day", "pusher-mid-day", "pusher-its-last-events"],
)
def test_a_disk_full_for_a_moment_while_tensorboard_writes_is_one_line_and_a_failed_run(tmp_path, command, tag):
    """TensorBoard's writer thread finds the disk full for one event, mid-day or at the run's last events (which no
    write of main's follows): one line, exit 1, and the summary says failed with the reason, not completed."""
    script, *flags = command
    code = A_MOMENT.format(module=script.removesuffix(".py"), tag=tag, flags=flags)
    env = {**os.environ, "PYTHONPATH": REPO, "OMP_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=600)  # fmt: skip
    assert proc.returncode == 1, (proc.returncode, proc.stderr[-3000:])
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert "No space left on device" in errors[0] and proc.stderr.strip().endswith(errors[0]), proc.stderr[-3000:]
    (path,) = glob.glob(str(tmp_path / "runs" / "*" / "summary.json"))
    with open(path) as f:
        summary = json.load(f)
    assert summary["status"] == "failed" and "No space left on device" in summary["error"], summary.get("error")
    assert summary["phase"] == ("tamer" if tag == "charts/" else "eval"), summary["phase"]
