"""inform_utils.actor_shift, the v5 night's diagnosis: the night's move measured on a run, and random moves of TAMER's
actor scaled to the same size."""

import json
import os
import subprocess
import sys

import pytest
import torch

import inform_sac_pusher as isp
from inform_utils import actor_shift

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


pytestmark = pytest.mark.usefixtures("one_thread")  # conftest.py


def actor(seed):
    torch.manual_seed(seed)
    return isp.Actor(23, 7, 32, -2 * torch.ones(7), 2 * torch.ones(7))


def test_a_random_move_is_scaled_to_the_actions_change_asked_for():
    tamer, states = actor(0), torch.randn(50, 23, generator=torch.Generator().manual_seed(1))
    direction = {
        n: torch.randn(p.shape, generator=torch.Generator().manual_seed(2)) for n, p in tamer.named_parameters()
    }
    for target in (0.01, 0.3):
        factor = actor_shift.scale_to(tamer, direction, states, target)
        assert actor_shift.action_shift(actor_shift.moved(tamer, direction, factor), tamer, states) == pytest.approx(
            target, rel=1e-3
        )
    assert actor_shift.action_shift(tamer, tamer, states) == 0.0


def test_a_night_that_did_not_move_the_actor_moves_nothing(tmp_path):
    """A run whose INFORM actor is TAMER's: the night moved it by 0, so every random move of that size is no move at all
    and returns TAMER's return; a night that moved it reports its size."""
    for name, a in (("same", actor(0)), ("moved", actor(1))):
        run = tmp_path / name
        run.mkdir()
        isp.save_actor(str(run / "tamer_actor.pt"), actor(0), env_id="Pusher-v5")
        isp.save_actor(str(run / "inform_actor.pt"), a, env_id="Pusher-v5")
        args = {"env_id": "Pusher-v5", "success_distance": 0.08, "success_info_key": "reward_dist"}
        (run / "summary.json").write_text(json.dumps({"seed": 3, "args": args}))
    cmd = [sys.executable, "-m", "inform_utils.actor_shift", str(tmp_path / "same"), str(tmp_path / "moved"),
           "--perturbations", "2", "--out", str(tmp_path / "out.json")]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO, timeout=300)
    assert proc.returncode == 0, proc.stderr
    same, moved = json.loads((tmp_path / "out.json").read_text())
    assert same["relative_weight_change"] == 0 and same["mean_action_change"] == 0
    assert same["tamer"] == same["inform"]
    for m in same["random_moves"]:
        assert m["same_weights"] == m["same_actions"] == same["tamer"]
    assert moved["relative_weight_change"] > 0.5 and moved["mean_action_change"] > 0
    assert len(moved["random_moves"]) == 2 and proc.stdout.count("\n") == 2


@pytest.mark.parametrize(
    ("flags", "phrase"),
    [
        ([], "pass at least one Pusher run directory"),
        (["run", "--perturbations", "0"], "--perturbations must be >= 1"),
        (["run", "--perturbations", "-5"], "--perturbations must be >= 1"),
        (["run", "--out", "run"], "--out run: must name a file"),
    ],
)
def test_bad_input_is_one_line_before_the_work(tmp_path, flags, phrase):
    """Issue 55, item 13: with no run folders, exit 0 and nothing printed; --perturbations 0 or -5, a traceback after
    all the work; --out naming a folder, a traceback and a stray <out>.tmp."""
    (tmp_path / "run").mkdir()
    cmd = [sys.executable, "-m", "inform_utils.actor_shift", *flags]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, timeout=300,
                          env={**os.environ, "PYTHONPATH": REPO})  # fmt: skip
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert proc.stderr.strip().splitlines() == [proc.stderr.strip()] and proc.stderr.startswith("error: ")
    assert phrase in proc.stderr and os.listdir(tmp_path) == ["run"] and proc.stdout == ""


def test_a_truncated_summary_is_one_line(tmp_path):
    (tmp_path / "summary.json").write_text('{"seed": 3, "ar')
    proc = subprocess.run([sys.executable, "-m", "inform_utils.actor_shift", str(tmp_path)], capture_output=True,
                          text=True, cwd=REPO, timeout=300)  # fmt: skip
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.startswith(f"error: {tmp_path / 'summary.json'}: cannot read it (half-written or damaged")
