"""inform_utils.pusher_obstacle_stats on damaged input: one line, exit 2, nothing written."""

import os
import subprocess
import sys

import numpy as np
from conftest import REPO


def test_a_truncated_npz_is_one_line(tmp_path):
    """Issue 55, item 12: pusher_obstacle_stats on a truncated obstacle_distances.npz: a BadZipFile traceback."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "summary.json").write_text('{"seed": 1, "args": {"success_distance": 0.08}}')
    np.savez(run / "obstacle_distances.npz", tamer=np.ones(50), inform=np.zeros(50))
    data = (run / "obstacle_distances.npz").read_bytes()
    (run / "obstacle_distances.npz").write_bytes(data[: len(data) // 2])
    cmd = [sys.executable, "-m", "inform_utils.pusher_obstacle_stats", str(run), "--output", str(tmp_path / "o.json")]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO, timeout=120)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    npz = run / "obstacle_distances.npz"
    assert (
        proc.stderr.strip()
        == f"error: {npz}: cannot read it (half-written or damaged (BadZipFile: File is not a zip file))"
    )
    assert sorted(os.listdir(tmp_path)) == ["run"]
