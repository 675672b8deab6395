"""oracle_train.py's plumbing holds where a user pushes it: run names stay inside runs/, seeds are ones numpy and torch
take, a disk that fills while a checkpoint is written leaves no partial file and says so in one line, and a
success return that is not a number is refused. Bad input: one `error:` line, exit 2, nothing written."""

import dataclasses
import errno
import glob
import math
import os
import shutil
import subprocess
import sys
import uuid

import numpy as np
import pytest
import torch

import oracle_train as ot

PUSHER_TINY = ["--env-id", "Pusher-v5", "--total-timesteps", "400", "--learning-starts", "200", "--batch-size", "64",
               "--hidden-size", "32", "--eval-frequency", "200", "--eval-episodes", "1", "--final-eval-episodes", "1",
               "--checkpoint-frequency", "200", "--log-frequency", "100", "--output-path", "oracle.pt"]  # fmt: skip


def refused_in_one_line(result, phrase: str) -> None:
    assert result.returncode == 2, (result.returncode, result.stderr[-2000:])
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and phrase in lines[0], result.stderr[-2000:]
    assert "Traceback" not in result.stderr
    assert not list(result.cwd.iterdir()), "something was written"


@pytest.fixture
def oracle(run_script):
    """oracle_train.py in an empty directory; the result remembers the directory, to show nothing was written."""

    def run(*flags, timeout=300):
        result = run_script("oracle_train.py", *flags, timeout=timeout)
        result.cwd = run_script.cwd
        return result

    return run


# ---------------------------------------------------------------------------------------------------------------
# run names stay inside runs/


@pytest.mark.parametrize(
    "name", ["../x", "a/b", "../../outside", "x" * 300, ".."], ids=["up", "nested", "up2", "long", "dots"]
)
@pytest.mark.parametrize("env_id", ["Pusher-v5", "KnoxStoneMaze-v0"])
def test_a_run_name_outside_runs_is_refused_in_one_line(oracle, name, env_id):
    result = oracle("--env-id", env_id, "--exp-name", name, "--total-timesteps", "400", "--learning-starts", "200")
    refused_in_one_line(result, "--exp-name")
    assert not os.path.exists(os.path.join(result.cwd, "..", "x")) and not os.path.exists(result.cwd / ".." / "outside")


def test_names_that_stay_inside_runs_are_taken():
    for name in ("oracle_sac", "my-run.v2", "..x", "x" * 150):
        ot.check_args(ot.Args(exp_name=name, env_id="KnoxStoneMaze-v0"))  # raises on refusal


def test_a_run_directory_is_one_component_under_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = ot.Args(exp_name="my-run.v2", env_id="Pusher-v5", seed=7)
    first, second = ot.new_run_dir(args), ot.new_run_dir(args)  # the same second: a suffix, never the same directory
    for run_dir in (first, second):
        assert os.path.dirname(run_dir) == "runs" and os.path.isdir(run_dir)
    assert first != second and os.path.basename(first).startswith("Pusher-v5__my-run.v2__7__")


# ---------------------------------------------------------------------------------------------------------------
# seeds numpy and torch take: 0 <= seed < 2**32, checked before anything is written


@pytest.mark.parametrize("seed", ["4294967296", "-1", "99999999999999999999"])
@pytest.mark.parametrize("env_id", ["Pusher-v5", "KnoxStoneMaze-v0"])
def test_a_seed_numpy_refuses_is_refused_before_anything_is_written(oracle, seed, env_id):
    refused_in_one_line(oracle("--env-id", env_id, "--method", "dqn" if "Maze" in env_id else "sac", "--seed", seed),
                        "--seed must be in [0, 4294967295]")  # fmt: skip


def test_the_largest_seed_trains():
    args = ot.Args(env_id="KnoxStoneMaze-v0", method="dqn", seed=2**32 - 1, maze_dqn_timesteps=300,
                   maze_dqn_learning_starts=100, maze_dqn_batch_size=32)  # fmt: skip
    ot.check_args(args)
    assert isinstance(ot.maze_dqn(ot.gym.make(args.env_id), args), ot.MazeQNetwork)  # numpy and torch take it


def test_a_resume_whose_seed_plus_step_numpy_refuses_is_refused(tmp_path):
    """A resumed run seeds numpy with --seed + the saved step: past 2**32 it is refused before anything is written."""
    sac = ot.SAC(3, 2, -torch.ones(2).numpy(), torch.ones(2).numpy(), 8, 1e-3, 1e-3, 0.2, True, torch.device("cpu"))
    rb = ot.ReplayBuffer(10, 3, 2, torch.device("cpu"))
    ot.save_training_state(str(tmp_path / "state.pt"), sac, rb, step=10, args=ot.Args())
    state = ot.read_training_state(str(tmp_path / "state.pt"))
    for seed, fits in ((2**32 - 11, True), (2**32 - 10, False)):
        args = ot.Args(seed=seed, resume=str(tmp_path / "state.pt"))
        if fits:
            assert ot.load_training_state(state, sac, rb, args) == 10
        else:
            with pytest.raises(ot.InputError, match=r"2\*\*32"):
                ot.load_training_state(state, sac, rb, args)
    assert sorted(os.listdir(tmp_path)) == ["state.pt"]


# ---------------------------------------------------------------------------------------------------------------
# --success-return (and every other ranged flag) must be a number in its range


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_a_success_return_that_is_not_a_number_is_refused(oracle, value):
    refused_in_one_line(
        oracle(*PUSHER_TINY, "--success-return", value), f"--success-return must be finite, got {value}"
    )


def test_every_ranged_flag_refuses_a_value_outside_its_range():
    """Each Range beside a flag in Args is checked: just outside it, and NaN, are refused with the flag's name."""
    ranged = {f.name: f.type.__metadata__[0] for f in dataclasses.fields(ot.Args) if hasattr(f.type, "__metadata__")}
    assert len(ranged) >= 35 and "success_return" in ranged and "seed" in ranged
    for name, rule in ranged.items():
        kind = type(getattr(ot.Args, name) if getattr(ot.Args, name) is not None else 0.0)
        below = rule.low if rule.open_low else rule.low - (1 if kind is int else 1e-9)
        bad = [math.nan] if kind is float else []
        bad += [kind(below)] if math.isfinite(rule.low) else []
        bad += [kind(rule.high + 1)] if math.isfinite(rule.high) else []
        assert bad, name
        for value in bad:
            with pytest.raises(ot.InputError, match=f"--{name.replace('_', '-')} must be"):
                ot.check_args(dataclasses.replace(ot.Args(env_id="KnoxStoneMaze-v0"), **{name: value}))


# ---------------------------------------------------------------------------------------------------------------
# a disk that fills while a checkpoint is written


class FullDisk:
    """open() whose files take `room` bytes between them, then fail as a full disk does (the bytes that fit stay)."""

    def __init__(self, room: int):
        self.room = room

    def __call__(self, path, mode="r", *args, **kwargs):
        self.file = open(path, mode, *args, **kwargs)
        return self

    def write(self, data):
        self.file.write(data[: self.room])
        if len(data) > self.room:
            self.room = 0
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.room -= len(data)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.file.close()


def test_a_checkpoint_that_fills_the_disk_leaves_no_partial_file(tmp_path, monkeypatch):
    monkeypatch.setattr(ot, "open", FullDisk(room=1000), raising=False)  # the module's open shadows the builtin
    path = str(tmp_path / "oracle.pt")
    with pytest.raises(OSError) as caught:
        ot.atomic_save({"q_table": torch.zeros(30, 4, dtype=torch.float64)}, path)
    assert caught.value.errno == errno.ENOSPC and caught.value.filename == path
    assert os.listdir(tmp_path) == []  # neither oracle.pt nor oracle.pt.tmp


def test_a_full_disk_is_one_line_naming_the_file(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(ot, "open", FullDisk(room=1000), raising=False)
    monkeypatch.setattr(sys, "argv", ["oracle_train.py", "--env-id", "KnoxStoneMaze-v0", "--output-path", "vi.pt"])
    with pytest.raises(SystemExit) as caught:
        ot.main()
    assert caught.value.code == 1
    lines = capsys.readouterr().err.strip().splitlines()
    assert (
        len(lines) == 1 and lines[0] == "failed: cannot write vi.pt: No space left on device; no partial file is left"
    )
    assert os.listdir(tmp_path) == []


@pytest.fixture
def small_disk(tmp_path):
    """A 2 MB tmpfs (needs root), nearly filled, so that the training's checkpoints do not fit."""
    disk = tmp_path / "disk"
    disk.mkdir()
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("mounting a tmpfs needs root")
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(disk)], capture_output=True).returncode:
        pytest.skip("cannot mount a tmpfs here")
    try:
        (disk / f"filler-{uuid.uuid4().hex}").write_bytes(b"\0" * (2 * 2**20 - 160 * 2**10))  # 160 KB stay free
        yield disk
    finally:
        subprocess.run(["umount", str(disk)], check=True)


def test_a_real_disk_that_fills_during_training_ends_in_one_line(small_disk):
    proc = subprocess.run([sys.executable, ot.__file__, *PUSHER_TINY], cwd=small_disk,
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    assert proc.returncode == 1, proc.stderr[-3000:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("failed: cannot write "), proc.stderr[-3000:]
    assert "No space left on device" in lines[0] and "--resume" in lines[0]
    left = [os.path.join(d, f) for d, _, files in os.walk(small_disk) for f in files]
    assert not [f for f in left if ".tmp" in f], left  # no partial file takes the space


# ---------------------------------------------------------------------------------------------------------------
# nothing overwritten that the user did not name; a resumed run keeps its flags; a warm start loads its teacher


def test_the_default_output_is_the_run_directory_and_an_existing_file_needs_overwrite(oracle):
    flags = [f for f in PUSHER_TINY if f not in ("--output-path", "oracle.pt")]
    result = oracle(*flags)
    assert result.returncode == 0, result.stderr[-2000:]
    (written,) = (result.cwd / "runs").glob("*/oracle.pt")  # the run's own, not oracles/
    assert not (result.cwd / "oracles").exists()
    shipped = result.cwd / "oracles" / "Pusher-v5__sac_oracle.pt"
    shipped.parent.mkdir()
    shipped.write_bytes(written.read_bytes())
    before = shipped.read_bytes()
    result = oracle(*flags, "--output-path", "oracles/Pusher-v5__sac_oracle.pt")
    assert result.returncode == 2 and "--overwrite" in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert shipped.read_bytes() == before and len(list((result.cwd / "runs").iterdir())) == 1  # no new run either
    result = oracle(*flags, "--output-path", "oracles/Pusher-v5__sac_oracle.pt", "--overwrite", "--seed", "2")
    assert result.returncode == 0 and shipped.read_bytes() != before  # named, and said so


@pytest.mark.parametrize("kind", ["fifo", "symlink"])
def test_an_output_path_that_is_not_a_regular_file_is_refused(oracle, tmp_path, kind):
    cwd = tmp_path  # the oracle fixture's working directory
    path = cwd / "out.pt"
    os.mkfifo(path) if kind == "fifo" else path.symlink_to("/dev/null")
    result = oracle("--env-id", "KnoxStoneMaze-v0", "--output-path", "out.pt", "--overwrite")
    assert result.returncode == 2 and "not a regular file" in result.stderr, result.stderr
    assert sorted(p.name for p in cwd.iterdir()) == ["out.pt"]


def test_a_resumed_run_keeps_its_flags_and_refuses_a_changed_one(oracle, tmp_path):
    flags = [f for f in PUSHER_TINY if f not in ("--output-path", "oracle.pt")]
    assert oracle(*flags, "--policy-lr", "1e-4").returncode == 0
    (state,) = (tmp_path / "runs").glob("*/training_state.pt")
    result = oracle("--resume", str(state), "--total-timesteps", "600")  # nothing else: the run's own flags
    assert result.returncode == 0, result.stderr[-2000:]
    ckpt = torch.load(state.parent / "oracle.pt", weights_only=True)
    assert ckpt["total_timesteps"] == 600 and ckpt["kwargs"]["hidden"] == 32  # --hidden-size 32 came back
    resumed = torch.load(state, weights_only=True)["args"]
    assert resumed["policy_lr"] == 1e-4 and resumed["total_timesteps"] == 600 and resumed["resume"] == str(state)
    result = oracle("--resume", str(state), "--total-timesteps", "800", "--policy-lr", "3e-4")
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "--policy-lr 0.0003 differs from the run's 0.0001" in result.stderr
    assert torch.load(state, weights_only=True)["global_step"] == 600  # not touched


def test_a_warm_start_takes_the_teachers_networks(tmp_path, monkeypatch):
    """--init-from: with no update (learning starts at the last step), the run's networks are the teacher's, and its
    actor acts from the first step (the buffer holds its actions, not uniform ones)."""
    monkeypatch.chdir(tmp_path)
    tiny = dict(env_id="Pusher-v5", learning_starts=200, batch_size=64, hidden_size=32, eval_frequency=200,
                eval_episodes=1, final_eval_episodes=1, checkpoint_frequency=200, log_frequency=100)  # fmt: skip
    ot.train_sac(ot.Args(**tiny, total_timesteps=400, output_path="teacher.pt", seed=3))
    teacher = torch.load("teacher.pt", weights_only=True)
    ot.train_sac(ot.Args(**tiny, total_timesteps=200, output_path="warm.pt", init_from="teacher.pt", ent_coef=0.05))
    warm = torch.load("warm.pt", weights_only=True)
    for key in ("actor_state_dict", "qf_state_dict"):
        for name, value in teacher[key].items():
            assert torch.equal(warm[key][name], value), (key, name)
    state = [s for s in glob.glob("runs/*/training_state.pt") if torch.load(s, weights_only=True)["args"]["init_from"]]
    saved = torch.load(state[0], weights_only=True)
    assert saved["log_ent_coef"].exp().item() == pytest.approx(0.05)
    actor = ot.Actor(**teacher["kwargs"], action_low=teacher["action_low"], action_high=teacher["action_high"])
    actor.load_state_dict(teacher["actor_state_dict"])
    with torch.no_grad():
        mean = actor.get_action(saved["buf_obs"])[2]
    # the sampled actions are the teacher's mean plus its noise: far closer to it than uniform actions would be
    assert (saved["buf_act"] - mean).abs().mean() < 0.5 * (torch.rand_like(mean) * 4 - 2 - mean).abs().mean()


def test_a_warm_start_that_does_not_fit_is_refused_in_one_line(oracle, tmp_path):
    refused_in_one_line(oracle("--init-from", "nothing.pt"), "--init-from nothing.pt: no such file")
    reacher = os.path.join(os.path.dirname(ot.__file__), "oracles", "Reacher-v5__sac_oracle.pt")
    result = oracle("--env-id", "Pusher-v5", "--init-from", reacher)
    assert result.returncode == 2 and "its networks are" in result.stderr and "Traceback" not in result.stderr
    assert not list(tmp_path.iterdir())


def test_reward_dist_weight_reaches_the_env_and_the_checkpoint_and_is_refused_elsewhere(tmp_path, monkeypatch):
    with pytest.raises(ot.InputError, match="--reward-dist-weight: InvertedPendulum-v5 has no reward_dist_weight"):
        ot.check_args(ot.Args(env_id="InvertedPendulum-v5", reward_dist_weight=3.0, success_return=0.0))
    env = ot.make_env("Pusher-v5", 1, reward_dist_weight=3.0)
    env.reset(seed=0)
    _, reward, _, _, info = env.step(env.action_space.sample())
    assert reward == pytest.approx(info["reward_dist"] + info["reward_near"] + info["reward_ctrl"])
    plain = ot.make_env("Pusher-v5", 1)
    plain.reset(seed=0)
    assert info["reward_dist"] == pytest.approx(3.0 * plain.step(np.zeros(7))[4]["reward_dist"], rel=0.05)
    monkeypatch.chdir(tmp_path)
    ot.train_sac(ot.Args(env_id="Pusher-v5", total_timesteps=200, learning_starts=100, batch_size=32, hidden_size=16,
                         eval_frequency=200, eval_episodes=1, final_eval_episodes=1, output_path="o.pt",
                         reward_dist_weight=3.0))  # fmt: skip
    assert torch.load("o.pt", weights_only=True)["reward_dist_weight"] == 3.0
