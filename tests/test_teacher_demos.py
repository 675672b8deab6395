"""A teacher from demonstrations (oracle_train.py --demos, --clone-steps, --layer-norm): the demonstrator's steps are
written whole and read back without unpickling; each way's mechanism is where the run calls it (the batch's share of
demonstrations, the cloning, the critics' warm-up), each test failing with it removed; a LayerNorm teacher is rebuilt
by the core script and refused by networks built without it; a resumed run refuses other demonstrations; bad input is
one line."""

import glob
import os

import gymnasium as gym
import numpy as np
import pytest
import torch
from conftest import REPO

import inform_sac_pusher as isp
import oracle_train as ot
from inform_utils import pusher_control, teacher_check
from inform_utils.demos import clone_step, read_demos
from inform_utils.files import BadInput

DEMO_EPISODES = 2  # the scripted demonstrator: 200 steps in a fraction of a second
TINY = ["--env-id", "Pusher-v5", "--batch-size", "64", "--hidden-size", "32", "--eval-frequency", "200",
        "--eval-episodes", "1", "--final-eval-episodes", "1", "--checkpoint-frequency", "200", "--log-frequency", "100",
        "--output-path", "oracle.pt"]  # fmt: skip


def make_demos(path, success=(True, False), reward=None) -> dict:
    """pusher_control's --save-demos file of the scripted demonstrator's first two episodes; `success` overrides the
    episodes' tags (it succeeds on neither), `reward` every step's reward."""
    pusher_control.main(pusher_control.Args(episodes=DEMO_EPISODES, save_demos=str(path)))
    data = dict(np.load(path, allow_pickle=False))
    data["episode_success"] = np.array(success)
    if reward is not None:
        data["rew"] = np.full_like(data["rew"], reward)
    os.remove(path)
    np.savez(path, **data)
    return data


def demo_states(data):
    return torch.as_tensor(data["obs"]), torch.as_tensor(data["act"])


@pytest.fixture
def demos(tmp_path):
    path = tmp_path / "demos.npz"
    return path, make_demos(path)


def test_the_demonstrations_are_written_whole_and_read_back(tmp_path, capsys):
    path = tmp_path / "d.npz"
    pusher_control.main(pusher_control.Args(episodes=DEMO_EPISODES, save_demos=str(path)))
    assert f"200 steps of {DEMO_EPISODES} episodes written" in capsys.readouterr().out
    env = gym.make("Pusher-v5")
    got = read_demos(str(path), env, ot.Args(), None, ot.InputError)
    assert got["steps"] == 200 and got["all"]["obs"].shape == (200, 23) and got["all"]["act"].shape == (200, 7)
    assert len(got["success"]["rew"]) == 0  # the scripted demonstrator succeeds on neither start
    with np.load(path, allow_pickle=False) as npz:  # the reward is the sum of its terms, so it can be re-weighted
        terms = npz["reward_dist"] + npz["reward_ctrl"] + npz["reward_near"]
        np.testing.assert_allclose(npz["rew"], terms, rtol=1e-5, atol=1e-6)
        weighted = read_demos(str(path), env, ot.Args(reward_dist_weight=3.0), None, ot.InputError)["all"]["rew"]
        expected = 3 * npz["reward_dist"] + npz["reward_ctrl"] + npz["reward_near"]
        np.testing.assert_allclose(weighted.numpy(), expected, rtol=1e-5)
    with pytest.raises(BadInput, match="name a new file"):  # never over a file
        pusher_control.main(pusher_control.Args(episodes=1, save_demos=str(path)))


def test_cloning_brings_the_actor_to_the_demonstrated_actions(demos):
    path, data = demos
    env = gym.make("Pusher-v5")
    got = read_demos(str(path), env, ot.Args(), None, ot.InputError)
    torch.manual_seed(0)
    sac = ot.SAC(23, 7, env.action_space.low, env.action_space.high, 64, 1e-3, 1e-3, 0.2, True, torch.device("cpu"))
    clone_rb = ot.ReplayBuffer.of(got["success"], torch.device("cpu"))
    obs, act = clone_rb.data["obs"], clone_rb.data["act"]

    def error():
        with torch.no_grad():
            return (sac.actor.get_action(obs)[2] - act).abs().mean().item()

    before = error()
    for _ in range(1000):
        clone_step(sac, clone_rb.sample(64))
    assert error() < 0.8 * before, (before, error())  # 0.59 -> 0.39 m here: a likelihood's first steps move the std


def test_the_pace_of_a_push_by_hand_and_on_the_v5_teacher():
    """pace(): a push closing 0.005 m a step (0.1 m/s at Pusher's dt 0.05) for 40 steps then resting, and one closing
    0.001 m a step to the end (0.02 m/s, so still closing); teacher_check's JSON splits episodes by outcome."""
    pushed = np.r_[np.linspace(0.30, 0.10, 41), np.full(60, 0.10)]
    slow = np.linspace(0.30, 0.20, 101)
    late = np.r_[np.full(91, 0.30), np.linspace(0.30, 0.27, 11)[1:]]  # still until step 90, then 0.003 m a step
    got = teacher_check.pace(np.array([pushed, slow, late]), 0.05)
    assert got["episodes"] == 3 and got["start_distance"] == pytest.approx(0.30)
    assert got["peak_closing_speed"] == pytest.approx((0.1 + 0.02 + 0.06) / 3)
    assert got["fastest_closing_speed"] == pytest.approx(0.1)
    assert got["last_closing_speed"] == pytest.approx((0.0 + 0.02 + 0.06) / 3) and got["still_closing"] == 2 / 3
    assert teacher_check.pace(np.zeros((0, 101)), 0.05) is None
    teacher = os.path.join(REPO, "oracles", "Pusher-v5__sac_oracle.pt")
    actor, env = isp.actor_from_checkpoint(teacher_check.read_teacher(teacher)), gym.make("Pusher-v5")
    assert len(teacher_check.final_distance(actor, env, 7_000_000)[2]) == 101  # before each of 100 steps, and after
    checked = teacher_check.check(teacher_check.Args(teacher, episodes=4, fixed_seeds=[]))["random_starts"]
    split = [checked["pace"][k]["episodes"] if checked["pace"][k] else 0 for k in ("success", "failure")]
    assert split == [round(4 * checked["success_rate"]), 4 - round(4 * checked["success_rate"])]


def test_a_run_from_demonstrations_clones_warms_and_counts_their_steps(run_script, demos):
    """--clone-steps with no SAC update after (learning starts past the budget): the written actor is the clone, the
    critics are warmed on the demonstrations (Q on their steps well below the fresh critics' ~0, as the rewards are
    ~-1 a step), the run's steps start after the demonstrator's 200, and the teacher keeps its LayerNorm."""
    path, data = demos
    flags = [*TINY, "--demos", str(path), "--layer-norm", "--total-timesteps", "400", "--learning-starts", "400"]
    result = run_script("oracle_train.py", *flags, "--clone-steps", "1000", "--policy-lr", "1e-3")
    assert result.returncode == 0, result.stderr[-3000:]
    ckpt = isp.read_checkpoint(str(run_script.cwd / "oracle.pt"), "--oracle-path", "Pusher-v5")
    assert ckpt["kwargs"]["layer_norm"] is True
    actor, qf = isp.oracle_from_checkpoint(ckpt, torch.device("cpu"))  # the core script rebuilds the LayerNorm teacher
    assert qf.norm is not None
    checked = teacher_check.check(teacher_check.Args(str(run_script.cwd / "oracle.pt"), episodes=1, fixed_seeds=[1]))
    assert checked["random_starts"]["episodes"] == 1  # the bar's command reads a LayerNorm teacher too
    obs, act = demo_states(data)
    success = torch.as_tensor(np.repeat(data["episode_success"], 100))
    with torch.no_grad():
        clone_error = (actor.get_action(obs[success])[2] - act[success]).abs().mean().item()
        q_demo = qf(obs, act).mean().item()
    fresh = ot.Actor(23, 7, 32, -2 * np.ones(7), 2 * np.ones(7))
    with torch.no_grad():
        fresh_error = (fresh.get_action(obs[success])[2] - act[success]).abs().mean().item()
    assert clone_error < 0.8 * fresh_error, (clone_error, fresh_error)
    assert q_demo < -0.5, q_demo
    (run_dir,) = glob.glob(str(run_script.cwd / "runs" / "*"))
    with open(os.path.join(run_dir, "eval_curve.csv")) as f:
        assert [line.split(",")[0] for line in f.read().splitlines()[1:]] == ["400"]  # 200 demonstrated + 200 its own
    state = torch.load(os.path.join(run_dir, "training_state.pt"), weights_only=True)
    assert state["global_step"] == 400 and int(state["buf_n"]) == 200 and len(state["demos_sha256"]) == 64
    # the demonstrations changed under the run's --demos path: its resume is refused in one line
    os.remove(path)
    make_demos(path, reward=0.0)
    result = run_script("oracle_train.py", "--resume", os.path.join(run_dir, "training_state.pt"),
                        "--total-timesteps", "600", "--output-path", "resumed.pt")  # fmt: skip
    assert result.returncode == 2 and result.stderr.strip().splitlines() == [
        f"error: --demos {path}: not the demonstrations this run was trained with (their SHA-256 differs)"
    ], result.stderr[-2000:]


def test_every_batch_holds_its_share_of_demonstrations(run_script, tmp_path):
    """Demonstrations whose every step earns +1 (the env's own ~-1): with --demo-ratio 1 the critics learn a positive
    Q on them, which only a batch drawn from them can teach (a tiny fixed entropy coefficient: autotuned from 1, the
    entropy bonus alone makes Q positive)."""
    path = tmp_path / "plus_one.npz"
    data = make_demos(path, reward=1.0)
    flags = [*TINY, "--demos", str(path), "--demo-ratio", "1", "--total-timesteps", "800", "--learning-starts", "200",
             "--no-autotune", "--ent-coef", "1e-4"]  # fmt: skip
    result = run_script("oracle_train.py", *flags)
    assert result.returncode == 0, result.stderr[-3000:]
    ckpt = isp.read_checkpoint(str(run_script.cwd / "oracle.pt"), "--oracle-path", "Pusher-v5")
    _, qf = isp.oracle_from_checkpoint(ckpt, torch.device("cpu"))
    with torch.no_grad():
        assert qf(*demo_states(data)).mean().item() > 0.5  # 1.8 here; -0.8 from a batch without them


def test_a_warm_start_across_layer_norm_is_refused_in_one_line(run_script):
    shipped = os.path.join(os.path.dirname(ot.__file__), "oracles", "Pusher-v5__sac_oracle.pt")
    flags = [*TINY, "--hidden-size", "256", "--total-timesteps", "400", "--init-from", shipped, "--layer-norm"]
    result = run_script("oracle_train.py", *flags)
    assert result.returncode == 2 and result.stderr.strip().splitlines() == [
        f"error: --init-from {shipped}: its critics are without LayerNorm; pass --no-layer-norm"
    ], result.stderr[-2000:]


def test_a_layer_norm_critic_refuses_to_load_into_one_without():
    with_norm, without = isp.QEnsemble(23, 7, 16, n=2, layer_norm=True), isp.QEnsemble(23, 7, 16, n=2)
    with pytest.raises(RuntimeError, match="norm"):
        without.load_state_dict(with_norm.state_dict())
    x, a = torch.randn(5, 23), torch.randn(5, 7)
    with_norm.load_state_dict({**without.state_dict(), "norm": torch.ones(())})
    assert not torch.allclose(with_norm(x, a), without(x, a))  # the same weights, normalised: other values


def test_bad_demonstrations_are_refused_in_one_line(run_script, tmp_path):
    (tmp_path / "x.npz").write_bytes(b"not a zip")
    result = run_script("oracle_train.py", "--demos", str(tmp_path / "x.npz"))
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and "not demonstrations of pusher_control" in lines[0], lines
    assert not (run_script.cwd / "runs").exists()


@pytest.mark.parametrize(
    "case, phrase",
    [("missing", "no such file"), ("maze", "the maze trains no SAC to read it"),
     ("clone_without", "--clone-steps clones demonstrations into a new actor"),
     ("no_success", "no successful episode to clone"), ("too_long", "leave none of --total-timesteps"),
     ("other_env", "demonstrations of Pusher-v5, not Reacher-v5")],
)  # fmt: skip
def test_bad_demonstrations_are_refused_before_anything_is_written(tmp_path, monkeypatch, demos, case, phrase):
    """In-process (the one-line report is the test above's): InputError, and no runs/ made."""
    path, _ = demos
    if case == "no_success":
        make_demos(tmp_path / "none.npz", success=(False, False))
    flags = {"missing": {"demos": "nowhere.npz"}, "maze": {"env_id": "KnoxStoneMaze-v0", "demos": str(path)},
             "clone_without": {"clone_steps": 5}, "no_success": {"demos": str(tmp_path / "none.npz"), "clone_steps": 5},
             "too_long": {"demos": str(path), "total_timesteps": 200, "batch_size": 64},
             "other_env": {"env_id": "Reacher-v5", "demos": str(path)}}[case]  # fmt: skip
    monkeypatch.chdir(tmp_path)
    args = ot.Args(**flags)
    with pytest.raises(ot.InputError, match=phrase):
        ot.check_args(args)
        ot.train_sac(args)
    assert not (tmp_path / "runs").exists()
