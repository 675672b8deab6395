"""Tests of inform_sac_pusher.py: equations on hand-computed cases, the obstacle env, smoke runs, the recovered
reward, bad input. Smoke runs use tiny budgets and run with cwd in a pytest tmp_path."""

import glob
import json
import os
import signal
import subprocess
import sys
import time

import gymnasium as gym
import numpy as np
import pytest
import torch
import torch.nn as nn
import tyro

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

from conftest import Child  # noqa: E402

import inform_sac_pusher as isp  # noqa: E402

SCRIPT = os.path.join(REPO, "inform_sac_pusher.py")
SHIPPED = os.path.join(REPO, "oracles", "Pusher-v5__sac_oracle.pt")
SOFT_CONTACT_TEACHER = os.path.join(REPO, "oracles", "Pusher-v5__sac_oracle_gymnasium_contact.pt")
TINY = [
    "--tamer-total-timesteps", "600",
    "--tamer-learning-starts", "300",
    "--tamer-batch-size", "64",
    "--sleep-gradient-steps", "200",
    "--sleep-batch-size", "64",
    "--eval-episodes", "2",
    "--obstacle-episodes", "3",
    "--authors-test-episodes", "3",
]  # fmt: skip
TINY_ORACLE = ["--train-oracle", "--oracle-total-timesteps", "5300"]  # SAC learns after 5,000 random steps


def run(cwd, *flags, timeout=120, module=None):
    """The script, or with `module` one of inform_utils/ (python -m inform_utils.MODULE), in the directory cwd."""
    cmd, env = [sys.executable, SCRIPT], None
    if module is not None:
        cmd, env = [sys.executable, "-m", f"inform_utils.{module}"], {**os.environ, "PYTHONPATH": REPO}
    return subprocess.run([*cmd, *flags], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


# ---------------------------------------------------------------------------------------------------------------
# equations on hand-computed cases


def test_oracle_feedback_eq4_positive_and_negative_q():
    alpha = 0.9
    # Q* >= 0: h = 1 iff Q*(s,a) >= alpha Q*(s,a*) = 9
    q_best = torch.tensor([10.0, 10.0, 10.0])
    assert isp.oracle_feedback(torch.tensor([9.5, 9.0, 8.9]), q_best, alpha).tolist() == [1.0, 1.0, 0.0]
    # Q* < 0 (Pusher): h = 1 iff Q*(s,a) >= (2 - alpha) Q*(s,a*) = -11
    q_best = torch.tensor([-10.0, -10.0, -10.0, -10.0])
    q_sa = torch.tensor([-10.0, -10.5, -11.0, -11.5])
    assert isp.oracle_feedback(q_sa, q_best, alpha).tolist() == [1.0, 1.0, 1.0, 0.0]
    # alpha = 1: only actions at least as good as the oracle's earn +1
    assert isp.oracle_feedback(torch.tensor([-10.01, -9.9]), torch.tensor([-10.0, -10.0]), 1.0).tolist() == [0.0, 1.0]


class StubQ(nn.Module):
    """Q(s, a) = s[0] + a[0], shaped [1, B] like a one-member QEnsemble."""

    def forward(self, obs, act):
        return (obs[:, 0] + act[:, 0]).unsqueeze(0)


class StubActor:
    """Always samples action 0 with log pi = -1."""

    def get_action(self, obs, generator=None):
        zeros = torch.zeros(obs.shape[0], 1)
        return zeros, -torch.ones(obs.shape[0]), zeros


def test_tamer_loss_eq1():
    h_net = isp.QEnsemble(3, 2, hidden=4, n=2)
    for p in h_net.parameters():
        nn.init.zeros_(p)
    with torch.no_grad():
        h_net.fc3.bias[0].fill_(0.5)  # H_1 = 0.5
        h_net.fc3.bias[1].fill_(1.0)  # H_2 = 1
    h = torch.tensor([1.0, 0.0])
    loss = isp.tamer_loss(h_net, torch.zeros(2, 3), torch.zeros(2, 2), h)
    # twin 1: ((0.5-1)^2 + 0.5^2)/2 = 0.25; twin 2: (0 + 1)/2 = 0.5
    assert loss.item() == pytest.approx(0.75)


def test_iq_loss_eq2_hand_computed_with_terminal():
    obs = torch.tensor([[1.0], [2.0], [3.0], [4.0]])
    act = torch.tensor([[0.5], [0.0], [1.0], [0.0]])
    next_obs = torch.tensor([[2.0], [3.0], [4.0], [5.0]])
    terminated = torch.tensor([0.0, 1.0, 0.0, 0.0])  # the second transition ends the episode: y = 0
    is_expert = torch.tensor([False, False, True, True])
    loss, terms = isp.iq_loss(StubQ(), StubQ(), obs, act, next_obs, terminated, is_expert, 0.9, 0.1, 0.5, StubActor())
    # Q(s,a) = [1.5, 2, 4, 4]; V(x) = x + 0.1; y = (1 - done) 0.9 V(s') = [1.89, 0, 3.69, 4.59]
    # Q - y = [-0.39, 2, 0.31, -0.59]; V(s) - y = [-0.79, 2.1, -0.59, -0.49]
    expert, value, chi2 = terms["iq_expert_term"], terms["iq_value_term"], terms["iq_chi2_term"]
    assert expert.item() == pytest.approx(-(0.31 - 0.59) / 2, abs=1e-5)
    assert value.item() == pytest.approx((-0.79 + 2.1 - 0.59 - 0.49) / 4, abs=1e-5)
    assert chi2.item() == pytest.approx(0.5 * (0.39**2 + 2**2 + 0.31**2 + 0.59**2) / 4, abs=1e-5)
    assert loss.item() == pytest.approx(0.14 + 0.0575 + 0.5745375, abs=1e-5)
    _, terms = isp.iq_loss(StubQ(), StubQ(), obs, act, next_obs, terminated, is_expert, 0.9, 0.1, 0.0, StubActor())
    assert terms["iq_chi2_term"].item() == 0.0


def test_recover_reward_eq3_with_terminal():
    r = isp.recover_reward(torch.tensor([1.0, 2.0]), torch.tensor([3.0, 4.0]), torch.tensor([0.0, 1.0]), 0.9)
    assert r.tolist() == pytest.approx([1.0 - 0.9 * 3.0, 2.0], abs=1e-5)
    # through the reward object: Q(s,a) = s + a, V(s') = s' + 0.1 (stub networks)
    reward = isp.RecoveredReward(StubQ(), StubActor(), gamma=0.9, temperature=0.1, samples=2)
    out = reward(np.array([[1.0], [2.0]]), np.array([[0.5], [0.0]]), np.array([[2.0], [3.0]]), np.array([0, 1]))
    assert out == pytest.approx([1.5 - 0.9 * 2.1, 2.0], abs=1e-5)


# ---------------------------------------------------------------------------------------------------------------
# obstacle variant


@pytest.mark.parametrize("layout", isp.OBSTACLE_LAYOUTS)
def test_obstacle_env_check_env_and_boxes(layout):
    from gymnasium.utils.env_checker import check_env

    boxes = isp.obstacle_positions(layout, *isp.start_and_goal("Pusher-v5", 2))
    env = isp.make_env("Pusher-v5", seed=0, obstacles=boxes)
    check_env(env.unwrapped, skip_render_check=True)
    env.reset(seed=0)
    model, data = env.unwrapped.model, env.unwrapped.data
    for i, (x, y) in enumerate(boxes):
        geom = model.geom(f"obstacle_{i}")
        assert np.allclose(data.geom(f"obstacle_{i}").xpos, [x, y, -0.325])
        assert np.allclose(geom.size, [0.015, 0.015, 0.015])
        assert int(geom.contype[0]) == 1 and int(geom.conaffinity[0]) == 1
    # the installed model is untouched: the plain env has no obstacle
    plain = isp.make_env("Pusher-v5", seed=0)
    assert plain.unwrapped.model.ngeom == model.ngeom - 3
    env.close()
    plain.close()


def test_distance_to_segment_by_hand():
    a, b = np.array([0.0, 0.0]), np.array([1.0, 0.0])
    assert isp.distance_to_segment(np.array([0.5, 0.3]), a, b) == pytest.approx(0.3)
    assert isp.distance_to_segment(np.array([-0.3, 0.4]), a, b) == pytest.approx(0.5)  # beyond an end: to the end
    assert isp.distance_to_segment(np.array([1.0, 0.0]), a, b) == pytest.approx(0.0)


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 7, 11])
def test_bisector_boxes_sit_on_the_path_for_every_start(seed):
    start, goal = isp.start_and_goal("Pusher-v5", seed)
    assert np.allclose(goal, [0.45, -0.05], atol=1e-6)
    boxes = isp.obstacle_positions("bisector", start, goal)
    assert np.allclose(boxes[1], (start + goal) / 2)  # the middle box on the straight path, halfway
    assert isp.distance_to_segment(boxes[1], start, goal) < 1e-9
    for box in (boxes[0], boxes[2]):  # the others on the perpendicular bisector, the paper's spacing away
        assert np.linalg.norm(box - boxes[1]) == pytest.approx(0.0424)
        assert np.dot(box - boxes[1], goal - start) == pytest.approx(0.0, abs=1e-9)
        assert np.linalg.norm(box - start) == pytest.approx(np.linalg.norm(box - goal))


def test_paper_boxes_are_on_the_path_only_for_the_authors_start():
    start, goal = isp.start_and_goal("Pusher-v5", 0)
    assert np.allclose(start, [0.257, -0.338], atol=1e-3)  # the authors' reset seed 0 (docs/protocol.md)
    paper = isp.obstacle_positions("paper", start, goal)
    assert isp.distance_to_segment(paper[1], start, goal) == pytest.approx(0.017, abs=1e-3)
    start, goal = isp.start_and_goal("Pusher-v5", 1)
    assert min(isp.distance_to_segment(b, start, goal) for b in paper) > 0.19  # seed 1: far off the path


# ---------------------------------------------------------------------------------------------------------------
# smoke runs


def check_run(tmp_path, proc):
    assert proc.returncode == 0, proc.stderr[-2000:]
    run_dirs = glob.glob(str(tmp_path / "runs" / "*"))
    assert len(run_dirs) == 1
    run_dir = run_dirs[0]
    assert glob.glob(os.path.join(run_dir, "events.out.tfevents.*"))
    with open(os.path.join(run_dir, "summary.json")) as f:
        summary = json.load(f)
    assert summary["status"] == "completed"
    for p in isp.POLICIES:
        for key in ("return", "final_distance", "success_rate"):
            assert np.isfinite(summary[f"eval/{p}_{key}"])
            assert np.isfinite(summary[f"eval/{p}_{key}_sampled"])
        for key in ("final_distance", "final_distance_std", "success_rate"):
            assert np.isfinite(summary[f"eval/obstacle/{p}_{key}"])
    for key in ("feedback/positive", "feedback/steps", "time/oracle_s", "time/tamer_s", "time/sleep_s"):
        assert key in summary
    for key in ("time/eval_s", "wall_time_s", "seed", "args"):
        assert key in summary
    assert summary["feedback/steps"] == 600
    for name in ("tamer_actor.pt", "tamer_h.pt", "inform_actor.pt", "inform_critic.pt"):
        ckpt = torch.load(os.path.join(run_dir, name), weights_only=True)
        assert "state_dict" in ckpt and "kwargs" in ckpt and ckpt["env_id"] == "Pusher-v5"
    with np.load(os.path.join(run_dir, "obstacle_distances.npz")) as d:
        assert d["tamer"].shape == (3,) and d["inform"].shape == (3,)
    with np.load(os.path.join(run_dir, "obstacle_paths.npz")) as d:  # Fig. 5a: 100 steps, the reset state first
        assert d["boxes"].shape == (3, 2) and d["inform_obstacle"].shape == (101, 2)
        assert np.allclose(d["tamer_plain"][0], d["start"]) and np.allclose(d["oracle_obstacle"][0], d["start"])
    assert len(summary["obstacle/box_positions"]) == 3
    assert summary["obstacle/min_box_distance_to_path"] < 1e-6  # the default bisector layout: on the path
    for p in isp.POLICIES:
        rate = summary[f"eval/authors_test/{p}_success_rate"]
        assert rate * 3 == pytest.approx(round(rate * 3)) and 0 <= round(rate * 3) <= 3  # a mean over its 3 episodes
        assert np.isfinite(summary[f"eval/authors_test/{p}_return"])
    # the recovered reward loads from the run directory and drives a wrapped env
    from inform_utils.recovered_reward import RecoveredRewardWrapper, load

    env = RecoveredRewardWrapper(gym.make("Pusher-v5"), load(run_dir))
    env.reset(seed=0)
    _, r, _, _, info = env.step(env.action_space.sample())
    assert isinstance(r, float) and "env_reward" in info
    return run_dir, summary


def test_smoke_in_script_oracle(tmp_path):
    proc = run(tmp_path, *TINY_ORACLE, *TINY)
    run_dir, summary = check_run(tmp_path, proc)
    assert summary["oracle_path"] is None
    ckpt = torch.load(os.path.join(run_dir, "oracle.pt"), weights_only=True)
    assert ckpt["env_id"] == "Pusher-v5" and ckpt["training_steps"] == 5300


@pytest.mark.skipif(not os.path.isfile(SHIPPED), reason="shipped oracle missing")
def test_smoke_oracle_path_and_determinism(tmp_path):
    flags = ["--oracle-path", SHIPPED, *TINY]
    (tmp_path / "a").mkdir()
    _, first = check_run(tmp_path / "a", run(tmp_path / "a", *flags))
    assert first["oracle_path"] == SHIPPED
    (tmp_path / "b").mkdir()
    no_gpu_cuda = [] if torch.cuda.is_available() else ["--cuda"]  # without a GPU, --cuda stays on the CPU: no change
    _, second = check_run(tmp_path / "b", run(tmp_path / "b", *flags, *no_gpu_cuda))
    assert second["args"]["cuda"] == bool(no_gpu_cuda)
    for key, value in first.items():
        if key.startswith(("eval/", "feedback/", "losses/", "sleep/")):
            assert second[key] == value, key
    # inform_utils.evaluate_policy re-runs the final evaluation of a saved policy: deterministic actions give the
    # run's numbers
    (run_dir,) = glob.glob(str(tmp_path / "a" / "runs" / "*"))
    streams = {}
    for policy in ("tamer", "inform"):
        proc = run(tmp_path / "a", "pusher", f"{run_dir}/{policy}_actor.pt", "--eval-episodes", "2",
                   "--obstacle-episodes", "3", module="evaluate_policy")  # fmt: skip
        assert proc.returncode == 0, proc.stderr
        metrics = streams[0] = json.loads(proc.stdout)
        assert metrics["eval/policy_return"] == first[f"eval/{policy}_return"]
        assert metrics["eval/policy_final_distance"] == first[f"eval/{policy}_final_distance"]
        det = "eval/obstacle/{}_final_distance_deterministic"
        assert metrics[det.format("policy")] == first[det.format(policy)]
    # --stream: another stream of sampled actions from the same start (the sleep study's TAMER spread)
    proc = run(tmp_path / "a", "pusher", f"{run_dir}/inform_actor.pt", "--eval-episodes", "2", "--obstacle-episodes",
               "0", "--stream", "1", module="evaluate_policy")  # fmt: skip
    streams[1] = json.loads(proc.stdout)
    assert streams[1]["eval/policy_return"] == streams[0]["eval/policy_return"]
    assert streams[1]["eval/policy_return_sampled"] != streams[0]["eval/policy_return_sampled"]
    assert len(glob.glob(str(tmp_path / "a" / "runs" / "*"))) == 1  # evaluating writes no run
    # the obstacle statistics and Fig. 5a read the run
    stats_script = os.path.join(REPO, "inform_utils", "pusher_obstacle_stats.py")
    stats = subprocess.run([sys.executable, stats_script, run_dir, "--fig5a", str(tmp_path / "fig5a.png")],
                           capture_output=True, text=True, timeout=120)  # fmt: skip
    assert stats.returncode == 0, stats.stderr
    assert "INFORM closer than TAMER on" in stats.stdout and (tmp_path / "fig5a.png").stat().st_size > 10_000


@pytest.mark.skipif(not os.path.isfile(SHIPPED), reason="shipped oracle missing")
def test_feedback_budget_ends_the_day_after_exactly_n_positives(tmp_path):
    flags = [*TINY, "--feedback-budget", "5", "--budget-ends-forward-phase", "--teacher-delay", "2"]
    proc = run(tmp_path, *flags, "--credit-window", "3")
    assert proc.returncode == 0, proc.stderr[-2000:]
    (run_dir,) = glob.glob(str(tmp_path / "runs" / "*"))
    with open(os.path.join(run_dir, "summary.json")) as f:
        summary = json.load(f)
    assert summary["status"] == "completed" and summary["feedback/positive"] == 5
    assert summary["feedback/perfect_positive"] >= 5 and summary["feedback/steps"] < 600
    assert summary["args"]["teacher_delay"] == 2 and summary["args"]["credit_window"] == 3


@pytest.mark.skipif(not os.path.isfile(SHIPPED), reason="shipped oracle missing")
def test_a_copied_script_finds_the_teacher_or_says_where_it_looked(tmp_path):
    import shutil

    copy = tmp_path / "elsewhere" / "my_inform.py"
    copy.parent.mkdir()
    shutil.copy(SCRIPT, copy)
    (tmp_path / "a").mkdir()  # no oracles/ here either: a note names both places, then a tiny oracle is trained
    proc = subprocess.run([sys.executable, str(copy), *TINY_ORACLE[1:], *TINY], cwd=tmp_path / "a", capture_output=True,
                          text=True, timeout=300)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "no shipped teacher found" in proc.stderr and "--oracle-path" in proc.stderr
    assert str(copy.parent / "oracles") in proc.stderr and str(tmp_path / "a" / "oracles") in proc.stderr
    (tmp_path / "b" / "oracles").mkdir(parents=True)  # the teacher under the working directory is found
    shutil.copy(SHIPPED, tmp_path / "b" / "oracles")
    proc = subprocess.run([sys.executable, str(copy), *TINY], cwd=tmp_path / "b", capture_output=True, text=True,
                          timeout=300)  # fmt: skip
    assert proc.returncode == 0 and "no shipped teacher" not in proc.stderr, proc.stderr[-2000:]
    (run_dir,) = glob.glob(str(tmp_path / "b" / "runs" / "*"))
    with open(os.path.join(run_dir, "summary.json")) as f:
        assert json.load(f)["oracle_path"] == str(tmp_path / "b" / "oracles" / "Pusher-v5__sac_oracle.pt")


@pytest.mark.skipif(not os.path.isfile(SHIPPED), reason="shipped oracle missing")
def test_the_working_directorys_teacher_comes_before_one_above_the_script(tmp_path, monkeypatch):
    import shutil

    for where in ("home/oracles", "home/project/oracles", "cwd/oracles"):
        (tmp_path / where).mkdir(parents=True)
    shutil.copy(SHIPPED, tmp_path / "home" / "oracles")  # a stray teacher above the script's directory
    shutil.copy(SHIPPED, tmp_path / "cwd" / "oracles")
    monkeypatch.setattr(isp, "REPO_DIR", str(tmp_path / "home" / "project"))
    monkeypatch.chdir(tmp_path / "cwd")
    assert isp.load_oracle("Pusher-v5", "mujoco-2.3", None, False, 200000)["path"] == str(
        tmp_path / "cwd" / "oracles" / "Pusher-v5__sac_oracle.pt"
    )
    shutil.copy(SHIPPED, tmp_path / "home" / "project" / "oracles")  # beside the script comes first
    assert isp.load_oracle("Pusher-v5", "mujoco-2.3", None, False, 200000)["path"] == str(
        tmp_path / "home" / "project" / "oracles" / "Pusher-v5__sac_oracle.pt"
    )


def test_save_load_same_actions(tmp_path):
    torch.manual_seed(0)
    actor = isp.Actor(23, 7, 32, action_low=-2 * np.ones(7), action_high=2 * np.ones(7))
    isp.save_actor(str(tmp_path / "actor.pt"), actor, env_id="Pusher-v5")
    loaded = isp.actor_from_checkpoint(isp.read_checkpoint(str(tmp_path / "actor.pt"), "policy", "Pusher-v5"))
    obs = torch.randn(16, 23)
    a1, logp1, mean1 = actor.get_action(obs, torch.Generator().manual_seed(3))
    a2, logp2, mean2 = loaded.get_action(obs, torch.Generator().manual_seed(3))
    assert torch.equal(a1, a2) and torch.equal(logp1, logp2) and torch.equal(mean1, mean2)
    assert not (tmp_path / "actor.pt.tmp").exists()  # written atomically
    with pytest.raises(isp.InputError, match="trained on Pusher-v5, not Pusher-v4"):
        isp.read_checkpoint(str(tmp_path / "actor.pt"), "policy", "Pusher-v4")


@pytest.mark.skipif(not os.path.isfile(SHIPPED), reason="shipped oracle missing")
@pytest.mark.parametrize(("phase", "sig"), [("tamer", "SIGINT"), ("sleep", "SIGINT"), ("sleep", "SIGTERM")])
def test_signal_ends_the_run_cleanly(tmp_path, phase, sig):
    flags = [*TINY, "--tamer-total-timesteps", "100000" if phase == "tamer" else "600"]
    flags += ["--sleep-gradient-steps", "100000"]
    child = Child([sys.executable, SCRIPT, *flags], tmp_path)
    child.wait_for_line(f"[{phase}]", timeout=120)
    child.proc.send_signal(getattr(signal, sig))
    returncode, _, stderr = child.finish()
    assert returncode == {"SIGINT": 130, "SIGTERM": 143}[sig] and "Traceback" not in stderr, stderr
    (run_dir,) = glob.glob(str(tmp_path / "runs" / "*"))
    with open(os.path.join(run_dir, "summary.json")) as f:
        summary = json.load(f)
    assert summary["status"] == "interrupted" and summary["phase"] == phase and summary["signal"] == sig
    assert os.path.exists(os.path.join(run_dir, "tamer_actor.pt")) == (phase == "sleep")  # what finished is saved
    assert not os.path.exists(os.path.join(run_dir, "inform_actor.pt"))
    assert not glob.glob(os.path.join(run_dir, "*.tmp"))


@pytest.mark.skipif(not os.path.isfile(SHIPPED), reason="shipped oracle missing")
def test_sigterm_stops_a_run_started_in_the_background(tmp_path):
    # a background job of a non-interactive shell ignores SIGINT; SIGTERM (kill, Slurm) must still stop it cleanly
    flags = [*TINY, "--sleep-gradient-steps", "100000"]
    shell = 'trap "" INT; "$0" "$@" & echo "pid $!"; wait $!'
    child = Child(["bash", "-c", shell, sys.executable, SCRIPT, *flags], tmp_path)
    pid = int(child.wait_for_line("pid ", timeout=120).split()[1])
    child.wait_for_line("[sleep]", timeout=120)
    os.kill(pid, signal.SIGTERM)
    returncode, _, stderr = child.finish()
    assert returncode == 143 and "Traceback" not in stderr, stderr
    (run_dir,) = glob.glob(str(tmp_path / "runs" / "*"))
    with open(os.path.join(run_dir, "summary.json")) as f:
        summary = json.load(f)
    assert (summary["status"], summary["phase"], summary["signal"]) == ("interrupted", "sleep", "SIGTERM")


@pytest.mark.skipif(not os.path.isfile(SHIPPED), reason="shipped oracle missing")
def test_divergence_is_reported(tmp_path):
    proc = run(tmp_path, *TINY, "--sleep-q-lr", "1e10")
    assert proc.returncode == 1 and "Traceback" not in proc.stderr, proc.stderr
    (line,) = proc.stderr.strip().splitlines()
    assert "diverged" in line and "gradient step 100" in line
    (run_dir,) = glob.glob(str(tmp_path / "runs" / "*"))
    with open(os.path.join(run_dir, "summary.json")) as f:
        summary = json.load(f)
    assert summary["status"] == "diverged" and summary["phase"] == "sleep"
    assert os.path.exists(os.path.join(run_dir, "tamer_actor.pt"))


def test_shipped_oracle_checkpoint():
    ckpt = torch.load(SHIPPED, weights_only=True)
    assert ckpt["env_id"] == "Pusher-v5" and ckpt["obs_shape"] == [23] and ckpt["act_shape"] == [7]
    assert ckpt["random_starts"] and ckpt["training_steps"] > 0
    assert set(ckpt["evaluation"]) >= {"return", "final_distance", "success_rate"}
    assert os.path.getsize(SHIPPED) < 5_000_000


# ---------------------------------------------------------------------------------------------------------------
# the recovered reward ranks the oracle's trajectories above random ones


def rollouts(env, policy, episodes, seed):
    data = []
    for ep in range(episodes):
        obs, _ = env.reset(seed=seed + ep)
        done, traj = False, []
        while not done:
            action = policy(obs)
            next_obs, _, terminated, truncated, _ = env.step(action)
            traj.append((obs, action, next_obs, float(terminated)))
            obs, done = next_obs, terminated or truncated
        data.append([np.array(x, dtype=np.float32) for x in zip(*traj, strict=True)])
    return data


def recovered_reward_auc(oracle_path: str, torch_seed: int) -> tuple[float, list, list]:
    """IQ-Learn (Eq. 2) on 10 oracle and 10 random Pusher-v5 trajectories, the oracle's as the success set; the
    chance that the recovered reward (Eq. 3) scores an oracle trajectory above a random one (AUC, 0.5 is chance)."""
    torch.manual_seed(torch_seed)
    torch.set_num_threads(1)
    ckpt = torch.load(oracle_path, weights_only=True)
    oracle_actor, _ = isp.oracle_from_checkpoint(ckpt, torch.device("cpu"))
    env = isp.make_env("Pusher-v5", 0, contact=isp.made_under(ckpt, "Pusher-v5"))  # the teacher's own contact

    def oracle_policy(obs):
        with torch.no_grad():
            return oracle_actor.get_action(torch.as_tensor(obs, dtype=torch.float32)[None])[2][0].numpy()

    expert = rollouts(env, oracle_policy, 10, seed=0)
    rand = rollouts(env, lambda obs: env.action_space.sample(), 10, seed=100)
    env.close()
    obs, act, nxt, term = (torch.as_tensor(np.concatenate(x)) for x in zip(*(expert + rand), strict=True))
    n_expert = sum(len(t[0]) for t in expert)
    q_net, q_target = isp.QEnsemble(23, 7, 64, n=1), isp.QEnsemble(23, 7, 64, n=1)
    q_target.load_state_dict(q_net.state_dict())
    actor = isp.Actor(23, 7, 64, env.action_space.low, env.action_space.high)
    q_opt = torch.optim.Adam(q_net.parameters(), lr=1e-3)
    pi_opt = torch.optim.Adam(actor.parameters(), lr=3e-4)
    B = 128
    is_expert = torch.cat([torch.zeros(B, dtype=torch.bool), torch.ones(B, dtype=torch.bool)])
    for _ in range(1500):  # the sleep phase on a hand-made buffer: oracle trajectories are the success set
        idx = torch.cat([torch.randint(0, len(obs), (B,)), torch.randint(0, n_expert, (B,))])
        loss, _ = isp.iq_loss(
            q_net, q_target, obs[idx], act[idx], nxt[idx], term[idx], is_expert, 0.99, 0.01, 0.5, actor
        )
        q_opt.zero_grad()
        loss.backward()
        q_opt.step()
        pi_loss, _ = isp.actor_loss(q_net, actor, obs[idx[:B]], 0.01)
        pi_opt.zero_grad()
        pi_loss.backward()
        pi_opt.step()
        isp.soft_update(q_target, q_net, 0.005)
    reward = isp.RecoveredReward(q_net, actor, 0.99, 0.01, samples=4)
    expert_returns = [reward(*t).sum() for t in expert]
    random_returns = [reward(*t).sum() for t in rand]
    return float(np.mean([e > r for e in expert_returns for r in random_returns])), expert_returns, random_returns


def test_recovered_reward_ranks_oracle_above_random():
    # One seed's AUC swings with float rounding (seed 0 gave 0.42 on this machine with the code of b0369e4 and 0.93
    # on CI's): 1,500 IQ-Learn steps on 20 trajectories are a short sleep. Measured with this code, the shipped 330k
    # oracle, torch seeds 0-2: AUC 0.99, 1.00, 0.62, the oracle's mean recovered return above the random one's in
    # 3 of 3 (the 200k oracle: 0.72, 0.08, 0.83; 2 of 3). So the test asks for the median of three seeds. The teacher
    # is round three's on MuJoCo 4's own contact, which this test passed with (the shipped one since 2026-12-06 is
    # another), on its own contact.
    results = [recovered_reward_auc(SOFT_CONTACT_TEACHER, seed) for seed in (0, 1, 2)]
    aucs = [auc for auc, _, _ in results]
    above = sum(np.mean(e) > np.mean(r) for _, e, r in results)
    assert sorted(aucs)[1] >= 0.75 and above >= 2, (aucs, above)


# ---------------------------------------------------------------------------------------------------------------
# bad input: one line on stderr, exit 2, no run directory


def write_bad_checkpoints(tmp_path):
    corrupt = tmp_path / "corrupt.pt"
    corrupt.write_bytes(b"not a checkpoint")
    ckpt = torch.load(SHIPPED, weights_only=True)
    wrong_env = tmp_path / "wrong_env.pt"
    torch.save({**ckpt, "env_id": "Pusher-v4"}, wrong_env)
    wrong_shape = tmp_path / "wrong_shape.pt"
    torch.save({**ckpt, "kwargs": {**ckpt["kwargs"], "obs_dim": 10}}, wrong_shape)
    wrong_weights = tmp_path / "wrong_weights.pt"
    torch.save({**ckpt, "kwargs": {**ckpt["kwargs"], "hidden": 32}}, wrong_weights)
    return {"corrupt": corrupt, "wrong_env": wrong_env, "wrong_shape": wrong_shape, "wrong_weights": wrong_weights}


BAD_FLAGS = [
    (["--tamer-total-timesteps", "-5"], "tamer-total-timesteps"),
    (["--sleep-gradient-steps", "0"], "sleep-gradient-steps"),
    (["--obstacle-episodes", "-1"], "obstacle-episodes"),
    (["--feedback-alpha-start", "1.5"], "feedback-alpha-start"),
    (["--env-id", "CartPole-v1"], "env-id"),
    (["--tamer-batch-size", "1000000"], "tamer-batch-size"),
    (["--oracle-path", "missing.pt"], "missing.pt"),
    (["--oracle-path", "{corrupt}"], "corrupt.pt"),
    (["--oracle-path", "{wrong_env}"], "wrong_env.pt"),
    (["--oracle-path", "{wrong_shape}"], "wrong_shape.pt"),
    (["--oracle-path", "{wrong_weights}"], "wrong_weights.pt"),
    (["--train-oracle", "--oracle-total-timesteps", "100"], "--oracle-total-timesteps must be >= 5001"),
    (["--teacher-noise", "1.5"], "teacher-noise"),
    (["--teacher-sparsity", "-0.1"], "teacher-sparsity"),
    (["--teacher-delay", "-1"], "teacher-delay"),
    (["--credit-window", "0"], "credit-window"),
    (["--feedback-budget", "-3"], "feedback-budget"),
    (["--success-return", "nan"], "--success-return must be in (-inf, inf), got nan"),
    (["--sleep-temperature", "inf"], "--sleep-temperature must be in (0, inf), got inf"),
    (["--seed", str(2**32)], "--seed must be >= 0 and < 4294967296"),
    (["--sleep-seed", "-1"], "--sleep-seed must be >= 0 and < 4294967296"),
    (["--exp-name", "../x"], "not one folder name in runs/"),
    (["--sleep-chi2-coef", "-0.1"], "--sleep-chi2-coef must be in [0, inf)"),
    (["--oracle-path", "x.pt", "--train-oracle"], "exclude each other"),
]


@pytest.mark.skipif(not os.path.isfile(SHIPPED), reason="shipped oracle missing")
def test_bad_input_messages(tmp_path):
    """Every bad input is rejected by check_args or load_oracle with a one-line message naming the flag or file."""
    paths = write_bad_checkpoints(tmp_path)
    cases = list(BAD_FLAGS)
    if isp.mujoco_major() >= 3:  # a teacher of MuJoCo 4's own contact, under the 2.3 one
        cases.append((["--oracle-path", SOFT_CONTACT_TEACHER], "made under the gymnasium contact"))
    for flags, needle in cases:
        flags = [f.format(**paths) if f.startswith("{") else f for f in flags]
        args = tyro.cli(isp.Args, args=flags)
        with pytest.raises(isp.InputError) as err:
            isp.check_args(args)
            isp.load_oracle(args.env_id, args.contact, args.oracle_path, args.train_oracle, args.oracle_total_timesteps)
        message = str(err.value)
        assert "\n" not in message and needle in message, (flags, message)


@pytest.mark.skipif(not os.path.isfile(SHIPPED), reason="shipped oracle missing")
def test_bad_input_exits_before_creating_anything(tmp_path):
    paths = write_bad_checkpoints(tmp_path)
    for flags in (["--tamer-total-timesteps", "-5"], ["--oracle-path", str(paths["wrong_weights"])]):
        proc = run(tmp_path, *flags, timeout=60)
        assert proc.returncode == 2, (flags, proc.stderr)
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: "), (flags, proc.stderr)
        assert not (tmp_path / "runs").exists(), flags


@pytest.mark.parametrize(
    ("script", "flags", "phrase"),
    [
        ("inform_sac_pusher.py", ["--seed", "abc"], "Error parsing --seed"),
        ("inform_sac_pusher.py", ["--obstacle-layout", "diagonal"], "invalid choice 'diagonal'"),
        ("oracle_train.py", ["--total-timesteps", "1.5"], "Error parsing --total-timesteps"),
        ("inform_dqn_gridworld.py", ["--seed", "abc"], "Error parsing --seed"),
        ("inform_dqn_gridworld.py", ["--teacher", "robot"], "invalid choice 'robot'"),
        ("q_learning_recovered_reward.py", ["--num-seeds", "x"], "Error parsing --num-seeds"),
        ("inform_utils/run_seeds.py", ["--seeds", "x"], "Error parsing --seeds"),
        ("inform_utils/run_seeds.py", ["--launcher", "cloud"], "invalid choice 'cloud'"),
        ("inform_utils/plot_results.py", ["--nope", "1"], "Unrecognized options"),
        ("inform_utils/pusher_obstacle_stats.py", ["--nope", "1"], "Unrecognized options"),
        ("inform_utils/teacher_study.py", ["--nope", "1"], "Unrecognized options"),
    ],
)
def test_malformed_flags_get_tyros_message(tmp_path, script, flags, phrase):
    """A flag tyro cannot parse, in every script: tyro's own message (what CleanRL's users see), exit 2, no
    traceback, nothing written. Our own checks (ranges, files, env ids) are one `error:` line: see test_bad_input.py."""
    cmd = [sys.executable, os.path.join(REPO, script)]
    if script.startswith("inform_utils/"):  # the helpers run as modules
        cmd = [sys.executable, "-m", script.removesuffix(".py").replace("/", ".")]
    proc = subprocess.run([*cmd, *flags], cwd=tmp_path, capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PYTHONPATH": REPO})  # fmt: skip
    assert proc.returncode == 2 and phrase in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr and not list(tmp_path.iterdir()), proc.stderr


# ---------------------------------------------------------------------------------------------------------------
# one SAC for the Pusher oracle, in two scripts (CleanRL repeats code across files): held together here


def test_both_scripts_carry_the_same_networks_and_judge_episodes_alike():
    import inspect

    import inform_dqn_gridworld
    import oracle_train

    for name in ("BatchedLinear", "QEnsemble", "Actor", "soft_update", "Outcome", "check_crc"):
        assert inspect.getsource(getattr(isp, name)) == inspect.getsource(getattr(oracle_train, name)), (
            f"{name} differs between inform_sac_pusher.py and oracle_train.py; a teacher's checkpoint loads into "
            "either script's networks, so change both alike (a new layer: an argument off by default in both)"
        )
    for name in ("check_crc", "strict_json", "check_settings", "cut"):  # beside the shared plumbing: the same code
        assert inspect.getsource(getattr(isp, name)) == inspect.getsource(getattr(inform_dqn_gridworld, name)), name


def test_both_scripts_train_the_same_oracle_and_load_each_others(tmp_path):
    """inform_sac_pusher.py --train-oracle and oracle_train.py, one seed and budget: the same networks to the last
    bit (oracle_train.py evaluates during training; that must not move its random stream). Each checkpoint loads
    into the other script's networks and passes --oracle-path's checks."""
    import oracle_train

    proc = run(tmp_path, "--seed", "4", *TINY_ORACLE, "--tamer-total-timesteps", "300", "--tamer-learning-starts",
               "200", "--tamer-batch-size", "32", "--sleep-gradient-steps", "10", "--sleep-batch-size", "32",
               "--eval-episodes", "1", "--obstacle-episodes", "1", "--authors-test-episodes", "1")  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    (in_script,) = glob.glob(str(tmp_path / "runs" / "*" / "oracle.pt"))
    proc = subprocess.run([sys.executable, os.path.join(REPO, "oracle_train.py"), "--seed", "4", "--hidden-size", "256",
                           "--total-timesteps", "5300", "--learning-starts", "5000", "--batch-size", "256",
                           "--eval-frequency", "2650",
                           "--eval-episodes", "1", "--final-eval-episodes", "1", "--output-path", "trained.pt"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    a = isp.read_checkpoint(in_script, "--oracle-path", "Pusher-v5")
    (latest,) = glob.glob(str(tmp_path / "runs" / "*" / "oracle_latest.pt"))  # trained.pt is the best evaluation's
    b = isp.read_checkpoint(latest, "--oracle-path", "Pusher-v5")
    isp.read_checkpoint(str(tmp_path / "trained.pt"), "--oracle-path", "Pusher-v5")
    for key in ("actor_state_dict", "qf_state_dict"):
        assert a[key].keys() == b[key].keys()
        for name in a[key]:
            assert torch.equal(a[key][name], b[key][name]), (key, name)
    assert a["kwargs"] == b["kwargs"] and torch.equal(a["action_low"], b["action_low"])
    assert a["training_steps"] == b["training_steps"] == 5300
    for ckpt in (a, b):  # each loads into oracle_train.py's networks too
        oracle_train.Actor(**ckpt["kwargs"]).load_state_dict(ckpt["actor_state_dict"])
        oracle_train.QEnsemble(**ckpt["kwargs"]).load_state_dict(ckpt["qf_state_dict"])


# ---------------------------------------------------------------------------------------------------------------


def mujoco_below_3() -> bool:
    try:
        import mujoco

        return int(mujoco.__version__.split(".")[0]) < 3
    except ImportError:
        return False


@pytest.mark.pusher_v4
@pytest.mark.skipif(not mujoco_below_3(), reason="Pusher-v4 needs mujoco<3 (pip install mujoco==2.3.7)")
def test_smoke_pusher_v4(tmp_path):
    proc = run(
        tmp_path,
        "--env-id", "Pusher-v4",
        *TINY_ORACLE,
        *TINY,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    (run_dir,) = glob.glob(str(tmp_path / "runs" / "*"))
    with open(os.path.join(run_dir, "summary.json")) as f:
        assert json.load(f)["status"] == "completed"


def test_oracle_train_pusher_smoke_and_resume(tmp_path):
    """oracle_train.py writes a checkpoint inform_sac_pusher.py accepts; --resume continues from the saved state."""
    script = os.path.join(REPO, "oracle_train.py")
    flags = ["--env-id", "Pusher-v5", "--learning-starts", "200", "--batch-size", "64", "--hidden-size", "32"]
    flags += ["--eval-frequency", "200", "--eval-episodes", "1", "--final-eval-episodes", "2"]
    flags += ["--checkpoint-frequency", "200", "--log-frequency", "100", "--output-path", "oracle.pt"]
    proc = subprocess.run(
        [sys.executable, script, *flags, "--total-timesteps", "400"], cwd=tmp_path, capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    ckpt = isp.read_checkpoint(str(tmp_path / "oracle.pt"), "--oracle-path", "Pusher-v5")
    assert ckpt["total_timesteps"] == 400 and ckpt["training_steps"] in (200, 400)
    assert ckpt["evaluation"]["episodes"] == 2 and ckpt["selection_evaluation"]["episodes"] == 1
    # best.pt is the evaluation with the highest success rate, then the smallest final distance, of those logged
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    (run_dir,) = glob.glob(str(tmp_path / "runs" / "*"))
    events = EventAccumulator(run_dir).Reload()
    success = {e.step: e.value for e in events.Scalars("eval/oracle_success_rate")}
    distance = {e.step: e.value for e in events.Scalars("eval/oracle_final_distance")}
    assert sorted(success) == [200, 400]
    best_step = max(success, key=lambda step: (success[step], -distance[step]))
    best = torch.load(os.path.join(run_dir, "best.pt"), weights_only=True)
    assert best["training_steps"] == ckpt["training_steps"] == best_step
    assert best["evaluation"]["final_distance"] == pytest.approx(distance[best_step], rel=1e-6)
    assert best["evaluation"]["reset_seed"] == 1_000_000
    (state,) = glob.glob(str(tmp_path / "runs" / "*" / "training_state.pt"))
    proc = subprocess.run(
        [sys.executable, script, *flags, "--total-timesteps", "600", "--resume", state, "--overwrite"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "resumed from" in proc.stdout
    assert torch.load(tmp_path / "oracle.pt", weights_only=True)["total_timesteps"] == 600


def test_oracle_train_bf16_curve_and_stop_at_expert(tmp_path, monkeypatch):
    """--bf16 is recorded in the checkpoint; every evaluation is a row of eval_curve.csv; --stop-at-expert ends the
    training at the first evaluation that meets the bar (here a bar every policy meets, patched in-process)."""
    import oracle_train

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(oracle_train, "EXPERT_SUCCESS_RATE", 0.0)
    monkeypatch.setattr(oracle_train, "EXPERT_FINAL_DISTANCE", 10.0)
    args = oracle_train.Args(
        env_id="Pusher-v5", total_timesteps=600, learning_starts=200, batch_size=64, hidden_size=32,
        eval_frequency=300, eval_episodes=1, final_eval_episodes=1, checkpoint_frequency=300, log_frequency=100,
        output_path="oracle.pt", bf16=True, stop_at_expert=True,
    )  # fmt: skip
    oracle_train.train_sac(args)
    ckpt = torch.load(tmp_path / "oracle.pt", weights_only=True)
    assert ckpt["bf16"] is True and ckpt["num_threads"] == 1
    assert ckpt["training_steps"] == ckpt["total_timesteps"] == 300  # stopped at the first evaluation, not at 600
    (curve,) = glob.glob(str(tmp_path / "runs" / "*" / "eval_curve.csv"))
    rows = open(curve).read().splitlines()
    assert rows[0] == "step,success_rate,final_distance,return" and [r.split(",")[0] for r in rows[1:]] == ["300"]


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_oracle_train_signal_keeps_the_last_training_state(tmp_path, sig):
    flags = ["--env-id", "Pusher-v5", "--learning-starts", "100", "--batch-size", "32", "--hidden-size", "32"]
    flags += ["--checkpoint-frequency", "150", "--log-frequency", "50", "--total-timesteps", "100000"]
    flags += ["--eval-frequency", "100000", "--output-path", "oracle.pt"]
    child = Child([sys.executable, os.path.join(REPO, "oracle_train.py"), *flags], tmp_path)
    run_dir = child.wait_for_line("run directory:", timeout=120).split(":", 1)[1].strip()
    state = tmp_path / run_dir / "training_state.pt"
    deadline = time.time() + 120
    while not state.exists() and time.time() < deadline:  # the first state is saved at step 150
        time.sleep(0.2)
    child.proc.send_signal(getattr(signal, sig))
    returncode, _, stderr = child.finish()
    assert returncode == {"SIGINT": 130, "SIGTERM": 143}[sig] and "Traceback" not in stderr, stderr
    assert len(stderr.strip().splitlines()) == 1 and "--resume" in stderr
    assert not (tmp_path / "oracle.pt").exists()
    assert torch.load(state, weights_only=True)["global_step"] >= 150


@pytest.mark.parametrize("deterministic", [False, True], ids=["sampled", "deterministic"])
def test_episodes_side_by_side_give_one_envs_numbers_bit_for_bit(deterministic):
    """The final tests run episodes on copies of the env at once: every return, distance, observation and the
    generator's state afterwards must be those of one env running the episodes in turn (7 episodes on 3 copies:
    full batches and a short one; random starts, so each copy resets to a different state)."""
    actor = isp.oracle_from_checkpoint(isp.read_checkpoint(SHIPPED, "test", "Pusher-v5"), torch.device("cpu"))[0]
    runs = []
    for envs in ([isp.make_env("Pusher-v5", 1)], [isp.make_env("Pusher-v5", 1) for _ in range(3)]):
        generator = torch.Generator().manual_seed(3)
        res = isp.evaluate(actor, envs if len(envs) > 1 else envs[0], 7, lambda ep: 100 + ep, deterministic,
                           generator, isp.Outcome())  # fmt: skip
        runs.append((res, generator.get_state()))
    (one, after_one), (together, after_together) = runs
    assert np.array_equal(one["returns"], together["returns"]) and np.array_equal(
        one["distances"], together["distances"]
    )
    assert all(np.array_equal(a, b) for a, b in zip(one["trajectories"], together["trajectories"], strict=True))
    assert torch.equal(after_one, after_together)
    assert len(set(one["returns"].tolist())) == 7  # seven different episodes, not one repeated


def test_episodes_that_end_early_run_one_at_a_time_with_the_same_numbers():
    """An env whose episodes can end before the time limit (InvertedPendulum falls): the side-by-side run gives up and
    the episodes run in turn, drawing the noise as one env does."""
    env_id = "InvertedPendulum-v5"
    env = isp.make_env(env_id, 1)
    torch.manual_seed(0)
    actor = isp.Actor(4, 1, 16, env.action_space.low, env.action_space.high)
    outs = []
    for envs in (env, [isp.make_env(env_id, 1) for _ in range(4)]):
        generator = torch.Generator().manual_seed(5)
        res = isp.evaluate(actor, envs, 6, lambda ep: ep, False, generator, isp.Outcome())
        outs.append((res["returns"], generator.get_state()))
    assert np.array_equal(outs[0][0], outs[1][0]) and torch.equal(outs[0][1], outs[1][1])
    assert (outs[0][0] < 1000).all()  # the episodes did end early (the limit is 1,000 steps)


def test_one_row_at_a_time_computes_each_row_as_a_batch_of_one():
    torch.manual_seed(0)
    actor = isp.Actor(23, 7)
    obs, eps = torch.randn(50, 23) * 3, torch.randn(50, 7)
    with torch.no_grad():
        together = isp.one_row_at_a_time(actor).get_action(obs, eps=eps)
        alone = [actor.get_action(obs[i : i + 1], eps=eps[i : i + 1]) for i in range(50)]
    for k in (0, 2):  # the sampled and the mean action
        assert torch.equal(together[k], torch.cat([a[k] for a in alone]))
