"""Bad input across the scripts: each case must be refused with a non-zero exit code and exactly one line on
stderr that names the problem, with no traceback and nothing written (no run directory, no output file). A flag
that tyro cannot parse (not an int, not a choice) gets tyro's own message instead of the one line (the ecosystem's
convention); the rest holds.

Every case runs in a fresh working directory holding the same inputs: a maze oracle, a checkpoint with a pickle
payload that would run code (weights_only loading must refuse it, and it must not have run), random bytes, a text
file, a Pusher oracle of the wrong shapes, a Pusher run directory whose summary.json lacks its args, and two runs
of one seed.
"""

import contextlib
import ctypes
import importlib
import json
import os
import random
import shlex
import subprocess
import sys

import numpy as np
import pytest
import torch
from test_plumbing_maze import small_disk  # a tmpfs of the given options, or a skip without root

import oracle_train as ot

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PUSHER_ORACLE = os.path.join(REPO, "oracles", "Pusher-v5__sac_oracle.pt")
V5_SOFT_TEACHER = os.path.join(REPO, "oracles", "Pusher-v5__sac_oracle_890k_below_bar.pt")  # mujoco 4's own contact
V4_TEACHER = os.path.join(REPO, "oracles", "Pusher-v4__sac_oracle.pt")  # trained under mujoco 2.3.7
EVALUATE = "inform_utils/evaluate_policy.py"  # python -m inform_utils.evaluate_policy
PWNED = "PWNED"  # the file the pickle payload would create if it were ever unpickled


class RunsCode:
    """Unpickling this calls os.system; weights_only loading must refuse it before it runs."""

    def __reduce__(self):
        return (os.system, (f"touch {PWNED}",))


def make_inputs(cwd) -> None:
    """Write every input file a case may name into the working directory."""
    ot.train_maze(
        ot.Args(env_id="KnoxStoneMazeWall-v0", method="value-iteration", output_path=str(cwd / "maze_oracle.pt"))
    )
    torch.save({"q_table": RunsCode(), "env_id": "KnoxStoneMaze-v0"}, cwd / "evil.pt")
    (cwd / "random.pt").write_bytes(random.Random(0).randbytes(4096))
    (cwd / "notes.txt").write_text("this is not a checkpoint\n")
    bad_shape = {"env_id": "Pusher-v5", "kwargs": {"obs_dim": 5, "act_dim": 7, "hidden": 8}}  # obs 5, not 23
    bad_shape.update(dict.fromkeys(["actor_state_dict", "qf_state_dict"], {}))
    bad_shape.update(action_low=-torch.ones(7), action_high=torch.ones(7))
    torch.save(bad_shape, cwd / "bad_shape.pt")
    run_dir = cwd / "pusher_run"  # a Pusher run whose summary.json lacks the args block
    run_dir.mkdir()
    np.savez(run_dir / "obstacle_distances.npz", tamer=np.ones(3), inform=np.ones(3))
    (run_dir / "summary.json").write_text(json.dumps({"seed": 1, "status": "completed"}))
    for name in ("seed1_a", "seed1_b"):  # two complete runs of the same seed
        (cwd / name).mkdir()
        np.savez(cwd / name / "obstacle_distances.npz", tamer=np.ones(3), inform=np.zeros(3))
        (cwd / name / "summary.json").write_text(json.dumps({"seed": 1, "args": {"success_distance": 0.08}}))


def case(id: str, script: str, flags: str, phrase: str, tyro: bool = False):
    """One bad input: the script, its flags (shell words), the phrase its error must contain; `tyro`: a malformed
    flag, which tyro reports in its own words (a box of several lines)."""
    return pytest.param(script, shlex.split(flags), phrase, tyro, id=id)


CASES = [
    case("oracle_train-seed-not-an-int", "oracle_train.py", "--seed abc", "Error parsing --seed", tyro=True),
    case("oracle_train-gamma-out-of-range", "oracle_train.py", "--env-id KnoxStoneMaze-v0 --gamma 1.5",
         "--gamma must be in [0, 1], got 1.5"),
    case("oracle_train-dqn-budget-below-a-batch", "oracle_train.py",
         "--env-id KnoxStoneMaze-v0 --method dqn --maze-dqn-timesteps 50",
         "--maze-dqn-batch-size 128 is larger than --maze-dqn-timesteps 50"),
    case("oracle_train-resume-pickle-with-code", "oracle_train.py", "--resume evil.pt", "refused"),
    case("oracle_train-resume-random-bytes", "oracle_train.py", "--resume random.pt",
         "random.pt: not a complete torch checkpoint"),
    case("gridworld-text-file-as-oracle", "inform_dqn_gridworld.py", "--oracle-path notes.txt",
         "notes.txt: not a torch checkpoint"),
    case("gridworld-pusher-oracle", "inform_dqn_gridworld.py", f"--oracle-path {shlex.quote(PUSHER_ORACLE)}",
         "not a maze oracle checkpoint"),
    case("gridworld-negative-seed", "inform_dqn_gridworld.py", "--seed -1", "--seed must be >= 0"),
    case("gridworld-zero-budget", "inform_dqn_gridworld.py", "--feedback-budget 0", "--feedback-budget must be >= 1"),
    case("pusher-zero-budget", "inform_sac_pusher.py", "--feedback-budget 0", "--feedback-budget must be >= 1"),
    case("pusher-negative-seed", "inform_sac_pusher.py", "--seed -2", "--seed must be >= 0"),
    case("pusher-evaluate-missing-file", EVALUATE, "pusher nope.pt", "policy nope.pt: no such file"),
    case("pusher-evaluate-bad-seed", EVALUATE, "pusher nope.pt --seed -1", "--seed must be >= 0"),
    case("maze-evaluate-missing-file", EVALUATE, "maze nope.pt", "the network nope.pt: no such file"),
    case("maze-evaluate-code", EVALUATE, "maze evil.pt", "refused, it holds more than tensors"),
    case("pusher-unknown-env-id", "inform_sac_pusher.py", "--env-id Pusher-v9",
         "--env-id Pusher-v9: Gymnasium cannot make it"),
    case("pusher-oracle-pickle-with-code", "inform_sac_pusher.py", "--oracle-path evil.pt",
         "--oracle-path evil.pt: cannot be read as a weights-only torch checkpoint (UnpicklingError)"),
    case("pusher-maze-oracle", "inform_sac_pusher.py", "--oracle-path maze_oracle.pt", "not an oracle checkpoint"),
    case("pusher-teacher-of-mujoco-4s-contact", "inform_sac_pusher.py", f"--oracle-path {shlex.quote(V5_SOFT_TEACHER)}",
         "made under the gymnasium contact, and this run's is mujoco-2.3; pass --contact gymnasium"),
    case("pusher-v4-teacher-under-mujoco-4s-contact", "inform_sac_pusher.py",
         f"--env-id Pusher-v4 --contact gymnasium --oracle-path {shlex.quote(V4_TEACHER)}",
         "made under the mujoco-2.3 contact, and this run's is gymnasium; pass --contact mujoco-2.3"),
    case("teacher_check-contact-not-a-choice", "inform_utils/teacher_check.py", f"{V4_TEACHER} --contact soft",
         "invalid choice", tyro=True),
    case("pusher-oracle-wrong-shapes", "inform_sac_pusher.py", "--oracle-path bad_shape.pt",
         "shapes obs 5 act 7 do not match Pusher-v5 (obs 23, act 7)"),
    case("qlearning-reward-pickle-with-code", "q_learning_recovered_reward.py", "--reward-path evil.pt",
         "evil.pt as a torch checkpoint (UnpicklingError"),
    case("run_seeds-zero-workers", "inform_utils/run_seeds.py", "--workers 0", "--workers must be >= 1"),
    case("pusher-exp-name-with-a-newline", "inform_sac_pusher.py", "--exp-name 'a\nb'", "--exp-name 'a\\nb'"),
    case("maze-exp-name-with-a-newline", "inform_dqn_gridworld.py", "--exp-name 'a\nb'", "--exp-name 'a\\nb'"),
    case("reward-exp-name-outside-runs", "q_learning_recovered_reward.py", "--exp-name ../x", "--exp-name '../x'"),
    case("pusher-more-threads-than-cpus", "inform_sac_pusher.py", "--num-threads 100000", "more than this machine's"),
    case("evaluate_policy-more-threads-than-cpus", EVALUATE, "pusher oracles/none.pt --num-threads 100000",
         "more than this machine's"),
    case("sleep_study-campaign-outside-results", "inform_utils/sleep_study.py", "--table --campaign ../../../tmp/x",
         "--campaign '../../../tmp/x': one folder name"),
    case("sleep_study-with-campaigns-without-table", "inform_utils/sleep_study.py", "--with-campaigns c50k",
         "--with-campaigns 'c50k': campaigns (folder names under results/) beside --table's, for the table only"),
    case("sleep_study-with-campaigns-the-campaign", "inform_utils/sleep_study.py",
         "--table --campaign c --with-campaigns c", "--with-campaigns 'c': campaigns (folder names under results/)"),
    case("sleep_study-retest-from-nowhere", "inform_utils/sleep_study.py", "--campaign c --retest-from nope",
         "--retest-from nope: no such folder (the runs of the nights, runs/)"),
    case("sleep_study-retest-from-with-table", "inform_utils/sleep_study.py", "--table --campaign c --retest-from runs",
         "--retest-from: for a campaign of Pusher nights already kept, without --days, --variants, --table or"),
    case("sleep_study-retest-from-an-empty-campaign", "inform_utils/sleep_study.py", "--campaign c --retest-from .",
         "--campaign c: no kept nights in results/c"),
    case("run_seeds-missing-script", "inform_utils/run_seeds.py", "--script nope.py", "nope.py: no such script"),
    case("run_seeds-seed-not-an-int", "inform_utils/run_seeds.py", "--seeds x", "Error parsing --seeds", tyro=True),
    case("pusher-layout-not-a-choice", "inform_sac_pusher.py", "--obstacle-layout diagonal", "invalid choice",
         tyro=True),
    case("plot_results-missing-runs-dir", "inform_utils/plot_results.py", "--runs-dir nope",
         "--runs-dir nope: no such directory"),
    case("obstacle-missing-run", "inform_utils/pusher_obstacle_stats.py", "nope_dir",
         "nope_dir: no obstacle_distances.npz"),
    case("obstacle-same-seed-twice", "inform_utils/pusher_obstacle_stats.py", "seed1_a seed1_b",
         "seed 1 given more than once"),
    case("obstacle-summary-without-args", "inform_utils/pusher_obstacle_stats.py", "pusher_run",
         "not a summary of inform_sac_pusher.py"),
    case("obstacle-fig5a-a-directory", "inform_utils/pusher_obstacle_stats.py", "seed1_a --fig5a seed1_b",
         "--fig5a seed1_b: must name a file"),
    case("plot_results-out-an-existing-file", "inform_utils/plot_results.py", "--runs-dir seed1_a --out notes.txt",
         "--out notes.txt: exists and is not a directory"),
]  # fmt: skip


def snapshot(root) -> set[str]:
    return {os.path.relpath(os.path.join(d, name), root) for d, dirs, files in os.walk(root) for name in dirs + files}


@pytest.mark.parametrize(("script", "flags", "phrase", "tyro"), CASES)
def test_bad_input_is_refused_in_one_line(run_script, script, flags, phrase, tyro):
    cwd = run_script.cwd
    make_inputs(cwd)
    before = snapshot(cwd)
    result = run_script(script, *flags, timeout=120)
    lines = result.stderr.splitlines()
    assert result.returncode != 0, f"exit 0 on bad input; stdout: {result.stdout[-500:]}"
    assert "Traceback" not in result.stderr, result.stderr[-2000:]
    if tyro:  # tyro's message; a script that still shortens it to one line passes too
        assert phrase in result.stderr, result.stderr
    else:
        assert len(lines) == 1 and lines[0].strip(), f"expected one line on stderr, got {len(lines)}: {result.stderr!r}"
        assert lines[0].startswith("error: ") and phrase in lines[0], lines[0]
    assert not (cwd / PWNED).exists()  # the pickle payload never ran
    assert not any((cwd / "runs").glob("*")), "a run directory was left behind"
    assert snapshot(cwd) == before, f"files written: {sorted(snapshot(cwd) - before)}"


@pytest.mark.parametrize("module", ["inform_sac_pusher", "inform_dqn_gridworld"])
def test_a_new_flag_is_never_refused_for_its_default(module):
    """A hacker adds `coef: float = 0.0` (or an int 0, or a negative shift) to Args: only flags listed in RANGES have a
    range, so the run starts; the listed ones are still checked."""
    import dataclasses
    import importlib

    script = importlib.import_module(module)
    new_flags = [("new_coef", float, 0.0), ("new_count", int, 0), ("new_shift", float, -1.0)]
    extended = dataclasses.make_dataclass("Extended", new_flags, bases=(script.Args,))
    script.check_args(extended())  # no InputError
    with pytest.raises(script.InputError, match="--tamer-total-timesteps must be >= 1, got 0"):
        script.check_args(extended(tamer_total_timesteps=0))
    if module == "inform_sac_pusher":  # its ranges sit beside the flags (Annotated[..., In(...)])
        assert 0.0 in script.In(0, 1, "[]") and 0.0 not in script.In(0, 1, "(]")
        assert 1.0 in script.In(0, 1, "(]") and float("nan") not in script.In(0)
    else:  # its ranges sit beside the flags too (Annotated[..., Range("[0, 1]")]), read by check_args
        script.check_args(extended(teacher_noise=0.0, teacher_sparsity=1.0, sleep_chi2_coef=0.0))  # the closed ends
        with pytest.raises(script.InputError, match=r"--sleep-q-lr must be in \(0, inf\), got 0.0"):
            script.check_args(extended(sleep_q_lr=0.0))
        with pytest.raises(script.InputError, match=r"--sleep-chi2-coef must be in \[0, inf\), got nan"):
            script.check_args(extended(sleep_chi2_coef=float("nan")))


# where a run cannot be written, or a file cannot be read (issue 55, item 14) ------------------------------------------
@pytest.mark.parametrize("script", ["inform_sac_pusher.py", "inform_dqn_gridworld.py"])
@pytest.mark.parametrize("kind", ["a file", "a dangling link", "read-only"])
def test_a_runs_folder_that_cannot_take_a_run_is_one_line_and_exit_2(run_script, script, kind):
    """runs/ a file, a dangling link, or a read-only disk: the Pusher said `NotADirectoryError...` and exited 1 where
    the maze said "cannot write into ..." and exited 2; both say the latter, before anything is written."""
    runs = run_script.cwd / "runs"
    if kind == "a file":
        runs.write_text("")
    elif kind == "a dangling link":
        runs.symlink_to(run_script.cwd / "nowhere")
    disk = small_disk(runs, "ro,size=1m") if kind == "read-only" else contextlib.nullcontext()
    with disk:
        before = snapshot(run_script.cwd)
        result = run_script(script, timeout=120)  # the checks refuse it: no run starts
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2 and len(lines) == 1 and "Traceback" not in result.stderr, result.stderr[-2000:]
        assert lines[0].startswith(f"error: cannot write into {runs}: "), lines[0]
        assert snapshot(run_script.cwd) == before and (kind == "read-only" or not os.path.isdir(runs))


def no_root_powers():
    """In the child, before it runs: root reads any file whatever its mode; without these two capabilities it cannot."""
    libc = ctypes.CDLL(None, use_errno=True)
    for capability in (1, 2):  # CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH, out of the bounding set: exec keeps neither
        if libc.prctl(24, capability, 0, 0, 0) != 0:  # PR_CAPBSET_DROP
            raise OSError(ctypes.get_errno(), "prctl(PR_CAPBSET_DROP)")


def unreadable(path) -> dict:
    """chmod 000 `path`; the arguments of subprocess.run under which a script cannot read it (as root: no_root_powers;
    a skip where those cannot be dropped)."""
    os.chmod(path, 0)
    if os.geteuid() != 0:
        return {}
    try:
        probe = subprocess.run([sys.executable, "-c", f"open({str(path)!r}).close()"], preexec_fn=no_root_powers)
    except subprocess.SubprocessError:
        probe = None
    if probe is None or probe.returncode == 0:
        pytest.skip("running as root, and cannot drop the capabilities that let root read a chmod 000 file")
    return {"preexec_fn": no_root_powers}


@pytest.mark.parametrize("script", ["inform_dqn_gridworld.py", "inform_sac_pusher.py"])
def test_an_unreadable_day_is_said_so(tmp_path, script):
    """A day.pt this user may not read: the maze said "not a torch checkpoint, or a truncated one" (zipfile.is_zipfile
    takes any OSError for "not a zip"), the Pusher "not a complete torch checkpoint, or a damaged one"."""
    (tmp_path / "day").mkdir()
    torch.save({"format": "never read"}, tmp_path / "day" / "day.pt")
    extra = unreadable(tmp_path / "day" / "day.pt")
    result = subprocess.run([sys.executable, os.path.join(REPO, script), "--sleep-from", "day"], cwd=tmp_path,
                            capture_output=True, text=True, timeout=120, **extra)  # fmt: skip
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and "Traceback" not in result.stderr, result.stderr[-2000:]
    assert lines[0] == "error: --sleep-from day/day.pt: cannot read it (Permission denied)", lines[0]
    assert sorted(os.listdir(tmp_path)) == ["day"]


def test_a_day_made_under_the_other_contact_is_refused_and_slept_on_under_its_own(run_script):
    """A day of mujoco 4's own contact (recorded in the day and the summary): a night under the 2.3 contact (the
    default) is refused in one line that names the flag; with it, the night runs and records it."""
    if int(importlib.import_module("mujoco").__version__.split(".")[0]) < 3:
        pytest.skip("mujoco<3 has one contact")
    tiny = ["--tamer-total-timesteps", "400", "--tamer-learning-starts", "200", "--tamer-batch-size", "32",
            "--sleep-gradient-steps", "20", "--sleep-batch-size", "32", "--eval-episodes", "1",
            "--obstacle-episodes", "1", "--authors-test-episodes", "1"]  # fmt: skip
    made = run_script("inform_sac_pusher.py", *tiny, "--contact", "gymnasium", "--oracle-path", V5_SOFT_TEACHER,
                      "--save-buffer")  # fmt: skip
    assert made.returncode == 0, made.stderr[-2000:]
    assert made.stdout.splitlines()[0].startswith("[env] Pusher-v5, the gymnasium contact ("), made.stdout[:300]
    (day,) = (run_script.cwd / "runs").glob("*")
    assert json.loads((day / "summary.json").read_text())["contact"] == "gymnasium"
    assert torch.load(day / "day.pt", weights_only=True)["day_args"]["contact"] == "gymnasium"
    before = snapshot(run_script.cwd)
    refused = run_script("inform_sac_pusher.py", "--sleep-from", str(day), "--sleep-gradient-steps", "20")
    lines = refused.stderr.strip().splitlines()
    assert refused.returncode == 2 and len(lines) == 1, refused.stderr[-2000:]
    assert lines[0] == (f"error: --sleep-from {day}: made under the gymnasium contact, and this run's is mujoco-2.3; "
                        "pass --contact gymnasium, or a teacher or day made under mujoco-2.3")  # fmt: skip
    assert snapshot(run_script.cwd) == before
    night = run_script("inform_sac_pusher.py", "--sleep-from", str(day), "--contact", "gymnasium", *tiny[6:])
    assert night.returncode == 0, night.stderr[-2000:]
    (summary,) = [p for p in (run_script.cwd / "runs").glob("*/summary.json") if p.parent != day]
    assert json.loads(summary.read_text())["contact"] == "gymnasium"
