"""A file read back is the file that was saved. torch.load does not check the CRC-32 that torch.save's zip archive
keeps per member, so 64 flipped bytes in a day, a teacher or a network were used as they were. Every reader checks the
archive first: a flipped copy of each kind of file is refused in one line naming it, and the shipped files pass."""

import glob
import os
import shutil
import subprocess
import sys

import pytest
import torch

import inform_dqn_gridworld as maze
import inform_sac_pusher as isp
import oracle_train as ot
import q_learning_recovered_reward as qr
from inform_utils.recovered_reward import load as load_recovered_reward

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
V5_TEACHER = os.path.join(REPO, "oracles", "Pusher-v5__sac_oracle.pt")
MAZE_RUN = os.path.join(REPO, "results", "maze_reward12", "KnoxStoneMaze-v0__reward12__1__1796039345")
V4_RUN = glob.glob(os.path.join(REPO, "results", "v4paper", "Pusher-v4__v4paper__1__*"))[0]


def flipped(source: str, dest) -> str:
    """A copy of `source` with 64 bytes inverted in its middle (where the tensors' bytes are)."""
    data = bytearray(open(source, "rb").read())
    middle = len(data) // 2
    data[middle : middle + 64] = bytes(b ^ 0xFF for b in data[middle : middle + 64])
    os.makedirs(os.path.dirname(str(dest)), exist_ok=True)
    with open(dest, "wb") as f:
        f.write(data)
    return str(dest)


def test_the_shipped_and_committed_files_pass():
    for name in sorted(os.listdir(os.path.join(REPO, "oracles"))):
        isp.check_crc(os.path.join(REPO, "oracles", name), name)
    for path in (*glob.glob(os.path.join(V4_RUN, "*.pt")), *glob.glob(os.path.join(MAZE_RUN, "*.pt"))):
        isp.check_crc(path, path)


def test_a_flipped_pusher_teacher_actor_and_critic_are_refused(tmp_path):
    with pytest.raises(isp.InputError, match="damaged since it was saved"):
        isp.read_checkpoint(flipped(V5_TEACHER, tmp_path / "t.pt"), "--oracle-path", "Pusher-v5")
    with pytest.raises(isp.InputError, match="damaged"):  # evaluate_policy and make_gifs read actors so
        isp.read_checkpoint(flipped(f"{V4_RUN}/inform_actor.pt", tmp_path / "a.pt"), "policy", "Pusher-v4")
    run_dir = tmp_path / "run"
    shutil.copytree(V4_RUN, run_dir)
    flipped(f"{V4_RUN}/inform_critic.pt", run_dir / "inform_critic.pt")
    with pytest.raises(isp.InputError, match="inform_critic.pt: damaged"):  # the recovered reward's networks
        load_recovered_reward(str(run_dir))


def test_a_flipped_day_is_refused_before_it_is_read(tmp_path):
    """Any torch file named day.pt will do: the archive is checked before its contents."""
    with pytest.raises(isp.InputError, match=r"--sleep-from .*day.pt: damaged"):
        isp.load_day(str(os.path.dirname(flipped(f"{V4_RUN}/tamer_actor.pt", tmp_path / "run" / "day.pt"))))


def test_a_flipped_maze_teacher_and_network_are_refused(tmp_path):
    maze_teacher = tmp_path / "vi.pt"
    torch.save({"q_table": torch.rand(30, 4, dtype=torch.float64), "env_id": "KnoxStoneMaze-v0"}, maze_teacher)
    maze.read_checkpoint(str(maze_teacher), "--oracle-path")  # intact: read
    with pytest.raises(maze.InputError, match="damaged since it was saved"):
        maze.read_checkpoint(flipped(str(maze_teacher), tmp_path / "bad.pt"), "--oracle-path")
    with pytest.raises(ValueError, match="damaged since it was saved"):  # the reward experiment's input
        qr.load_inform_network(flipped(f"{MAZE_RUN}/inform_q.pt", tmp_path / "q" / "inform_q.pt"))


def test_a_flipped_training_state_and_warm_start_are_refused(tmp_path):
    with pytest.raises(ot.InputError, match="--init-from .* damaged"):
        ot.read_teacher(flipped(V5_TEACHER, tmp_path / "t.pt"), 23, 7, 256, False)
    sac = ot.SAC(3, 2, -torch.ones(2).numpy(), torch.ones(2).numpy(), 8, 1e-3, 1e-3, 0.2, True, torch.device("cpu"))
    ot.save_training_state(
        str(tmp_path / "state.pt"), sac, ot.ReplayBuffer(10, 3, 2, torch.device("cpu")), 10, ot.Args()
    )
    with pytest.raises(ot.InputError, match="--resume .* damaged"):
        ot.read_training_state(flipped(str(tmp_path / "state.pt"), tmp_path / "bad_state.pt"))


def test_teacher_check_refuses_a_flipped_teacher_and_bad_input_in_one_line(tmp_path):
    bad = flipped(V5_TEACHER, tmp_path / "flipped.pt")
    torch.save({"q_table": torch.zeros(30, 4), "env_id": "KnoxStoneMaze-v0", "algorithm": "value-iteration"},
               tmp_path / "maze.pt")  # fmt: skip
    (tmp_path / "notes.txt").write_text("not a checkpoint")
    cases = {
        bad: "damaged since it was saved",
        "missing.pt": "no such file",
        str(tmp_path): "a directory, not a file",
        str(tmp_path / "maze.pt"): "not a SAC teacher",
        str(tmp_path / "notes.txt"): "not a complete torch checkpoint",
        f"{V5_TEACHER} --episodes 0": "--episodes must be >= 1",
        f"{V5_TEACHER} --out {tmp_path}": "--out",
    }
    for flags, needle in cases.items():
        proc = subprocess.run([sys.executable, "-m", "inform_utils.teacher_check", *flags.split()], cwd=tmp_path,
                              env={**os.environ, "PYTHONPATH": REPO}, capture_output=True, text=True)  # fmt: skip
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1 and needle in lines[0], (flags, proc.stderr[-2000:])
