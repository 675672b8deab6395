"""--track (CleanRL's): Weights & Biases mirrors the TensorBoard events, in both INFORM scripts and oracle_train.py.
An optional dependency: without it, --track is one line of error; with it (CI installs it), a run in
WANDB_MODE=offline keeps a wandb run beside its events."""

import glob
import importlib.util
import json
import os
import subprocess
import sys

import pytest
from conftest import REPO

import inform_dqn_gridworld as maze
import inform_sac_pusher as pusher
import oracle_train


@pytest.mark.parametrize("module", [maze, pusher, oracle_train], ids=["maze", "pusher", "oracle_train"])
def test_track_without_wandb_is_one_line(module, monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "wandb" else real(name, *a))
    args = module.Args(track=True, env_id="Pusher-v5") if module is oracle_train else module.Args(track=True)
    if module is maze:
        args = args.fill_teacher_defaults()
    with pytest.raises(module.InputError, match="pip install wandb"):
        module.check_args(args)


def run_offline(tmp_path, script, *flags):
    env = {**os.environ, "WANDB_MODE": "offline", "WANDB_SILENT": "true"}
    cmd = [sys.executable, os.path.join(REPO, script), "--track", *flags]
    proc = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    (run_dir,) = glob.glob(str(tmp_path / "runs" / "*"))
    offline = glob.glob(os.path.join(run_dir, "wandb", "offline-run-*", "run-*.wandb"))
    assert offline and os.path.getsize(offline[0]) > 0
    return run_dir


MAZE_TINY = ["--tamer-total-timesteps", "1000", "--tamer-learning-starts", "200", "--sleep-gradient-steps", "100"]
ORACLE_TINY = ["--env-id", "Pusher-v5", "--total-timesteps", "300", "--learning-starts", "200", "--batch-size", "64"]
ORACLE_TINY += ["--hidden-size", "32", "--eval-frequency", "300", "--eval-episodes", "1", "--final-eval-episodes", "1"]


@pytest.mark.skipif(importlib.util.find_spec("wandb") is None, reason="wandb is not installed (CI installs it)")
@pytest.mark.parametrize("script", ["inform_dqn_gridworld.py", "oracle_train.py"])
def test_track_offline_keeps_a_wandb_run_beside_the_events(tmp_path, script):
    flags = MAZE_TINY if script == "inform_dqn_gridworld.py" else [*ORACLE_TINY, "--output-path", "oracle.pt"]
    run_dir = run_offline(tmp_path, script, *flags)
    if script == "inform_dqn_gridworld.py":
        with open(os.path.join(run_dir, "summary.json")) as f:
            assert json.load(f)["status"] == "completed"
