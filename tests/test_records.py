"""No run ends as completed without its record. On a real disk (a tmpfs, needs root) out of inodes or out of space just
as the last file is written, each script says so in one line and exits 1: the INFORM scripts (their summary.json),
the reward experiment (its agents, figure and summary), the oracle trainer (its checkpoint and report). A caller
(run_seeds, Slurm, CI) then counts the run as failed; nothing half-written is left."""

import os
import subprocess
import sys

import pytest
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
