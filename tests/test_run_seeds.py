import glob
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import pytest
from conftest import REPO, default_signals

from inform_utils import run_seeds

RUN_SEEDS = os.path.join(REPO, "inform_utils", "run_seeds.py")


def calls(tmp_path) -> list[tuple[int, float]]:
    lines = (tmp_path / "calls.txt").read_text().split("\n") if (tmp_path / "calls.txt").exists() else []
    return sorted((int(s), float(n)) for s, n in (line.split() for line in lines if line))


def test_aggregate_mean_std_n():
    table = run_seeds.aggregate([{"a": 1.0, "b": "x", "seed": 1}, {"a": 3.0, "b": "y", "seed": 2}])
    assert set(table) == {"a"}
    assert table["a"]["mean"] == 2.0 and table["a"]["std"] == pytest.approx(2**0.5) and table["a"]["n"] == 2


def test_runs_seeds_once_and_resumes(tmp_path, monkeypatch, fake_script):
    monkeypatch.chdir(tmp_path)
    args = run_seeds.Args(script="fake.py", exp_name="t", seeds=[1, 2, 3], workers=2)
    table = run_seeds.main(args)[""]
    assert table["eval/x"]["mean"] == 4.0 and table["eval/x"]["n"] == 3
    run_seeds.main(run_seeds.Args(script="fake.py", exp_name="t", seeds=[1, 2, 3, 4], workers=2))
    assert [s for s, _ in calls(tmp_path)] == [1, 2, 3, 4]  # finished seeds were not run again
    saved = json.load(open(os.path.join("runs", "t__table.json")))
    assert saved["table"]["eval/x"]["n"] == 4


def test_results_dir_keeps_completed_runs_and_resumes_after_runs_is_gone(tmp_path, monkeypatch, fake_script):
    """A new session starts without runs/: the runs kept in --results-dir still count, and the table uses them."""
    monkeypatch.chdir(tmp_path)
    kept = str(tmp_path / "results" / "k")
    run_seeds.main(run_seeds.Args(script="fake.py", exp_name="k", seeds=[1, 2], results_dir=kept))
    assert sorted(os.listdir(kept)) == sorted(d for d in os.listdir("runs") if "__k__" in d)
    for run_dir in os.listdir(kept):
        assert os.listdir(os.path.join(kept, run_dir)) == ["summary.json"]
    shutil.rmtree("runs")
    table = run_seeds.main(run_seeds.Args(script="fake.py", exp_name="k", seeds=[1, 2, 3], results_dir=kept))[""]
    assert [s for s, _ in calls(tmp_path)] == [1, 2, 3]  # seeds 1 and 2 were found in results/, not run again
    assert table["eval/x"]["n"] == 3 and len(os.listdir(kept)) == 3


def test_keep_copies_the_run_files_up_to_the_size_limit(tmp_path, monkeypatch, fake_script):
    monkeypatch.chdir(tmp_path)
    args = run_seeds.Args(script="fake.py", exp_name="s", seeds=[1], results_dir="results/s", keep_max_mb=1.0)
    run_seeds.main(args)
    (run_dir,) = [os.path.join("runs", d) for d in os.listdir("runs") if "__s__1__" in d]
    kept = os.path.join("results", "s", os.path.basename(run_dir))
    assert os.listdir(kept) == ["summary.json"]
    shutil.rmtree(kept)
    with open(os.path.join(run_dir, "small.npz"), "wb") as f:
        f.write(b"x" * 2**20)  # exactly the limit: kept
    with open(os.path.join(run_dir, "big.pt"), "wb") as f:
        f.write(b"x" * (2**20 + 1))
    os.makedirs(os.path.join(run_dir, "videos"))
    run_seeds.keep(args, run_seeds.Run(1, ()), since=0.0)
    assert sorted(os.listdir(kept)) == ["small.npz", "summary.json"]


def test_a_run_of_another_script_with_the_same_exp_name_does_not_count(tmp_path, monkeypatch, fake_script):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "other.py").write_text(fake_script.read_text())
    run_seeds.main(run_seeds.Args(script="other.py", exp_name="t", seeds=[1], workers=1))
    table = run_seeds.main(run_seeds.Args(script="fake.py", exp_name="t", seeds=[1], workers=1))[""]
    assert calls(tmp_path) == [(1, 0.0), (1, 0.0)]  # fake.py ran although other.py had seed 1
    assert table["eval/x"]["n"] == 1


def test_grid_runs_every_point_for_every_seed_and_resumes_by_the_recorded_args(tmp_path, monkeypatch, fake_script):
    monkeypatch.chdir(tmp_path)
    tables = run_seeds.main(run_seeds.Args(script="fake.py", exp_name="g", seeds=[1, 2], grid=["noise=0,0.5"]))
    assert calls(tmp_path) == [(1, 0.0), (1, 0.5), (2, 0.0), (2, 0.5)]
    assert tables["noise=0"]["eval/x"]["mean"] == 3.0 and tables["noise=0.5"]["eval/x"]["mean"] == 3.5
    assert tables["noise=0"]["eval/x"]["n"] == tables["noise=0.5"]["eval/x"]["n"] == 2
    # a new grid value (and 0.50 written differently): only the new point runs; the runs of the same seed at other
    # grid points (same exp_name, same seed) are told apart by the args their summary.json records
    tables = run_seeds.main(run_seeds.Args(script="fake.py", exp_name="g", seeds=[1, 2], grid=["noise=0,0.50,0.25"]))
    assert calls(tmp_path) == [(1, 0.0), (1, 0.25), (1, 0.5), (2, 0.0), (2, 0.25), (2, 0.5)]
    assert set(tables) == {"noise=0", "noise=0.50", "noise=0.25"} and tables["noise=0.25"]["eval/x"]["mean"] == 3.25
    saved = json.load(open(os.path.join("runs", "g__table.json")))
    assert [p["point"] for p in saved["points"]] == [{"noise": "0"}, {"noise": "0.50"}, {"noise": "0.25"}]
    assert "table" not in saved  # with a grid, one table per point


def test_flags_after_the_double_dash_also_tell_runs_apart(tmp_path, monkeypatch, fake_script):
    monkeypatch.chdir(tmp_path)
    run_seeds.main(run_seeds.Args(script="fake.py", exp_name="f", seeds=[1], script_args=["--noise", "0.5"]))
    run_seeds.main(run_seeds.Args(script="fake.py", exp_name="f", seeds=[1], script_args=["--noise", "0.5"]))
    run_seeds.main(run_seeds.Args(script="fake.py", exp_name="f", seeds=[1], script_args=["--noise=0.7"]))
    assert calls(tmp_path) == [(1, 0.5), (1, 0.7)]


def test_flag_values_and_recorded_args():
    flags = run_seeds.flag_values(["--random-starts", "--no-save-model", "--x=1", "--seeds", "1", "2", "--lr", "-1e-3"])
    assert flags == {"random-starts": True, "save-model": False, "x": ["1"], "seeds": ["1", "2"], "lr": ["-1e-3"]}
    recorded = {"random_starts": True, "save_model": False, "x": 1, "seeds": [1, 2], "lr": -0.001}
    assert run_seeds.ran_with(recorded, flags)
    assert not run_seeds.ran_with({**recorded, "save_model": True}, flags)
    assert not run_seeds.ran_with({**recorded, "seeds": [1, 3]}, flags)
    assert not run_seeds.ran_with({k: v for k, v in recorded.items() if k != "x"}, flags)  # a flag it did not have
    assert run_seeds.ran_with({"path": None, "name": "a"}, {"path": ["None"], "name": ["a"]})


def test_a_failed_run_is_reported_with_the_tail_of_its_log_and_the_table_has_the_rest(run_script, fake_script):
    result = run_script("inform_utils/run_seeds.py", "--script", "fake.py", "--exp-name", "e", "--seeds", "1", "2",
                        "--", "--fail-seed", "2")  # fmt: skip
    assert result.returncode == 1, result.stdout + result.stderr
    assert "seed 2: failed" in result.stdout and "boom: seed 2 refuses to run" in result.stdout
    assert "e: 1 of 2 seeds finished, missing [2]" in result.stdout
    assert result.stderr.splitlines() == [result.stderr.strip()]  # one line
    assert result.stderr.startswith("error: 1 of 2 run(s) did not finish (failed: seed 2)")


@pytest.mark.parametrize(
    ("flags", "phrase"),
    [
        (["--grid", "noise"], "expected FLAG=VALUE,VALUE,..."),
        (["--grid", "noise=0,,1"], "expected FLAG=VALUE,VALUE,..."),
        (["--grid", "seed=1,2"], "--seed is set by run_seeds itself"),
        (["--grid", "noise=0,1", "--grid", "noise=2"], "--grid noise given twice"),
        (["--grid", "noise=0,1", "--", "--noise", "3"], "--grid noise is also among the script's flags"),
        (["--launcher", "slurm"], "no sbatch on PATH"),
        (["--launcher", "slurm", "--slurm-mem", "4X"], "--slurm-mem '4X': expected a size like 4G or 500M"),
        (["--launcher", "slurm", "--slurm-time", "0"], "--slurm-time and --slurm-cpus-per-task must be >= 1"),
        (["--", "--seed", "5"], "--seed after -- is set by run_seeds itself"),
        (["--", "--exp-name=x"], "--exp-name after -- is set by run_seeds itself"),
        (["--runs-dir", "elsewhere"], "--runs-dir elsewhere: the scripts write their runs to runs/"),
    ],
)
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, fake_script, flags, phrase):
    (tmp_path / "bin").mkdir()  # a PATH without Slurm's commands (the run itself uses sys.executable)
    env = {**os.environ, "PATH": str(tmp_path / "bin")}
    before = sorted(os.listdir(tmp_path))
    result = subprocess.run([sys.executable, RUN_SEEDS, "--script", "fake.py", *flags], cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=120)  # fmt: skip
    assert result.returncode == 2, result.stdout + result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and phrase in lines[0], result.stderr
    assert sorted(os.listdir(tmp_path)) == before


def wait_for(predicate, proc, seconds: float, what: str):
    """Poll until predicate() holds; on timeout kill proc and fail with its output."""
    deadline = time.time() + seconds
    while time.time() < deadline:
        if predicate():
            return
        if proc.poll() is not None:
            break
        time.sleep(0.2)
    out, err = stop(proc)
    pytest.fail(f"{what} did not happen within {seconds}s (exit {proc.returncode})\nstdout:\n{out}\nstderr:\n{err}")


def stop(proc) -> tuple[str | None, str | None]:
    """SIGTERM first, so run_seeds stops its runs (a killed run_seeds would leave them running), then SIGKILL."""
    proc.terminate()
    try:
        return proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.communicate(timeout=30)


def finish(proc, seconds: float) -> tuple[str, str]:
    try:
        return proc.communicate(timeout=seconds)
    except subprocess.TimeoutExpired:
        out, err = stop(proc)
        pytest.fail(f"no exit within {seconds}s after the signal\nstdout:\n{out}\nstderr:\n{err}")


TINY_BUT_LONG = ["--", "--tamer-total-timesteps", "100000", "--sleep-gradient-steps", "100"]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_stops_the_runs_which_save_and_are_rerun_on_resume(tmp_path, sig):
    """A real kill of run_seeds.py running two gridworld seeds: the signal reaches each run once, each writes
    summary.json status interrupted with that signal, run_seeds reports them and exits 128 + the signal; their
    summaries do not count as finished, so the same command runs them again."""
    cmd = [sys.executable, RUN_SEEDS, "--script", os.path.join(REPO, "inform_dqn_gridworld.py"), "--exp-name", "s",
           "--seeds", "1", "2", "--workers", "2", "--threads", "1", *TINY_BUT_LONG]  # fmt: skip
    proc = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=default_signals)  # fmt: skip
    # both runs have made their run directories (a run of 100k steps then trains for minutes on this machine)
    logs = [tmp_path / "runs" / "logs" / f"s__{seed}.log" for seed in (1, 2)]
    wait_for(lambda: all(p.exists() and "run directory" in p.read_text() for p in logs), proc, 120, "both runs")
    time.sleep(3)  # past the few lines between "run directory" and the try block that saves on a signal
    proc.send_signal(sig)
    out, err = finish(proc, 120)
    assert proc.returncode == 128 + sig, out + err
    name = signal.Signals(sig).name
    summaries = [json.load(open(p)) for p in glob.glob(str(tmp_path / "runs" / "*__s__*" / "summary.json"))]
    assert sorted(s["seed"] for s in summaries) == [1, 2], out + err
    assert all(s["status"] == "interrupted" and s["signal"] == name for s in summaries), summaries
    assert "seed 1: interrupted" in out and "seed 2: interrupted" in out and f"by {name}" in out
    assert err.strip().splitlines()[-1].startswith(f"error: stopped by {name}; 2 run(s) not finished")
    args = run_seeds.Args(script="inform_dqn_gridworld.py", exp_name="s", runs_dir=str(tmp_path / "runs"),
                          script_args=TINY_BUT_LONG[1:])  # fmt: skip
    assert run_seeds.newest_summary(args, run_seeds.Run(1, ())) is None  # so a resume runs seed 1 again


def test_sigterm_to_run_seeds_in_the_background_and_the_resume(tmp_path, fake_script):
    """run_seeds.py started with & by a non-interactive shell (SIGINT ignored, as such shells do): kill -TERM still
    stops it cleanly, and running the same command again completes the interrupted runs."""
    (tmp_path / "block").write_text("")
    cmd = f"{sys.executable} {RUN_SEEDS} --script fake.py --exp-name b --seeds 1 2 --workers 2"
    script = f"{cmd} > out.txt 2> err.txt & echo $! > pid.txt; wait $!; echo $? > rc.txt"
    shell = subprocess.Popen(["bash", "-c", script], cwd=tmp_path, preexec_fn=default_signals)
    wait_for(lambda: len(calls(tmp_path)) == 2 and (tmp_path / "pid.txt").exists(), shell, 60, "both runs starting")
    wait_for(lambda: (tmp_path / "out.txt").exists(), shell, 10, "output")
    time.sleep(0.5)
    os.kill(int((tmp_path / "pid.txt").read_text()), signal.SIGTERM)
    finish(shell, 60)
    out, err = (tmp_path / "out.txt").read_text(), (tmp_path / "err.txt").read_text()
    assert (tmp_path / "rc.txt").read_text().strip() == "143", out + err
    assert "seed 1: interrupted" in out and "seed 2: interrupted" in out and "by SIGTERM" in out, out
    assert err.strip().startswith("error: stopped by SIGTERM; 2 run(s) not finished"), err
    (tmp_path / "block").unlink()
    result = subprocess.run(cmd.split(), cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "already finished" not in result.stdout and "b: 2 of 2 seeds finished" in result.stdout
    assert calls(tmp_path) == [(1, 0.0), (1, 0.0), (2, 0.0), (2, 0.0)]


def test_one_thread_per_run_by_default(run_script, fake_script):
    """On a shared 2-core machine one run with 2 threads was 7x slower than with 1 (issue 20): 1 is the default."""
    result = run_script("inform_utils/run_seeds.py", "--script", "fake.py", "--exp-name", "e", "--seeds", "1",
                        "--workers", "1")  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    assert "1 workers, 1 thread(s) each" in result.stdout, result.stdout


@pytest.mark.parametrize("name", ["a/b", "../x", "..", "x" * 101, ""])
def test_an_experiment_name_that_would_leave_runs_is_one_line(run_script, fake_script, name):
    result = run_script("inform_utils/run_seeds.py", "--script", "fake.py", "--exp-name", name, "--seeds", "1")
    assert result.returncode == 2, result.stdout + result.stderr
    assert result.stderr.startswith("error: --exp-name") and result.stderr.count("\n") == 1, result.stderr
    assert not (run_script.cwd / "runs").exists() and not (run_script.cwd / "calls.txt").exists()


def test_a_half_copied_run_in_the_results_dir_never_counts(tmp_path, monkeypatch, fake_script):
    """keep() copies into {run}.tmp, then renames: a copy cut short leaves only the .tmp, which is not a run."""
    monkeypatch.chdir(tmp_path)
    half = tmp_path / "results" / "Fake-v0__h__1__5.tmp"
    half.mkdir(parents=True)
    summary = {"status": "completed", "script": "fake.py", "seed": 1, "eval/x": 99.0, "args": {"seed": 1}}
    (half / "summary.json").write_text(json.dumps(summary))
    args = run_seeds.Args(script="fake.py", exp_name="h", seeds=[1], results_dir="results")
    assert run_seeds.newest_summary(args, run_seeds.Run(1, ())) is None
    table = run_seeds.main(args)[""]
    assert calls(tmp_path) == [(1, 0.0)] and table["eval/x"]["mean"] == 2.0  # the run itself, not the .tmp's 99


def test_two_campaigns_of_one_name_never_write_one_log(tmp_path, fake_script):
    """While one run_seeds runs seed 1, a second with the same name leaves that run alone, and its log untouched."""
    (tmp_path / "block").write_text("")
    cmd = [sys.executable, RUN_SEEDS, "--script", "fake.py", "--exp-name", "twice", "--seeds", "1"]
    first = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             preexec_fn=default_signals)  # fmt: skip
    log = tmp_path / "runs" / "logs" / "twice__1.log"
    wait_for(lambda: len(calls(tmp_path)) == 1 and log.exists(), first, 60, "the first campaign's run")
    second = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    (tmp_path / "block").unlink()
    out, err = finish(first, 60)
    assert first.returncode == 0, out + err
    assert second.returncode == 1 and "another run_seeds is running it" in second.stdout, second.stdout
    assert calls(tmp_path) == [(1, 0.0)]  # the second campaign started nothing
    assert log.read_text().count("fake.py") == 1 and "started" in log.read_text()


# a campaign counts only its own runs ----------------------------------------------------------------------------------
TYRO_SCRIPT = """
\"\"\"A training script with a tyro Args: runs/Fake-v0__{exp}__{seed}__{ns}/summary.json, args recorded.\"\"\"
import dataclasses, json, os, sys, time
import tyro


@dataclasses.dataclass
class Args:
    seed: int = 1
    \"\"\"the seed\"\"\"
    exp_name: str = "x"
    \"\"\"the experiment\"\"\"
    noise: float = 0.0
    \"\"\"the teacher's noise\"\"\"


if __name__ == "__main__":
    args = tyro.cli(Args)
    with open("calls.txt", "a") as f:
        f.write(f"{args.seed} {args.noise}\\n")
    run_dir = f"runs/Fake-v0__{args.exp_name}__{args.seed}__{time.time_ns()}"
    os.makedirs(run_dir)
    summary = {"status": "completed", "script": os.path.basename(sys.argv[0]), "seed": args.seed,
               "eval/x": args.seed + args.noise, "args": dataclasses.asdict(args)}
    with open(f"{run_dir}/summary.json", "w") as f:
        json.dump(summary, f)
"""


def test_a_run_of_another_experiment_whose_name_ends_in_the_campaigns_does_not_count(tmp_path, monkeypatch,
                                                                                     fake_script):  # fmt: skip
    monkeypatch.chdir(tmp_path)
    run_seeds.main(run_seeds.Args(script="fake.py", exp_name="pilot__camp", seeds=[1], workers=1))
    assert glob.glob("runs/Fake-v0__pilot__camp__1__*")  # which *__camp__1__* also matches
    table = run_seeds.main(run_seeds.Args(script="fake.py", exp_name="camp", seeds=[1], workers=1))[""]
    assert calls(tmp_path) == [(1, 0.0), (1, 0.0)] and table["eval/x"]["n"] == 1


def test_a_run_made_with_a_flag_the_campaign_does_not_pass_does_not_count(tmp_path, monkeypatch):
    """Every field of the script's Args is compared, not only the flags the campaign passes: a seed run with
    --noise 0.4 is not a finished seed of the campaign at the default noise (and then is, at --noise 0.4)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "tyro_fake.py").write_text(TYRO_SCRIPT)
    run_seeds.main(run_seeds.Args(script="tyro_fake.py", exp_name="camp", seeds=[1], script_args=["--noise", "0.4"]))
    table = run_seeds.main(run_seeds.Args(script="tyro_fake.py", exp_name="camp", seeds=[1]))[""]
    assert calls(tmp_path) == [(1, 0.0), (1, 0.4)] and table["eval/x"]["values"] == [1.0]
    run_seeds.main(run_seeds.Args(script="tyro_fake.py", exp_name="camp", seeds=[1], script_args=["--noise=0.4"]))
    assert len(calls(tmp_path)) == 2  # both finished now: nothing ran


def test_a_grid_of_a_flag_or_value_the_script_refuses_runs_nothing(tmp_path):
    (tmp_path / "tyro_fake.py").write_text(TYRO_SCRIPT)
    for grid, phrase in (("nonflag=1,2", "Unrecognized options: --nonflag"), ("noise=abc,2", "Error parsing --noise")):
        result = subprocess.run([sys.executable, RUN_SEEDS, "--script", "tyro_fake.py", "--grid", grid], cwd=tmp_path,
                                capture_output=True, text=True, timeout=120)  # fmt: skip
        lines = result.stderr.splitlines()
        assert result.returncode == 2 and len(lines) == 1 and phrase in lines[0], result.stderr
    assert sorted(os.listdir(tmp_path)) == ["tyro_fake.py"]


def test_recorded_args_against_the_campaigns():
    campaign = {"args": {"seed": 0, "exp_name": "c", "noise": 0.1, "new": 3}, "defaults": {"new": 3, "noise": 0.0}}
    assert run_seeds.is_campaigns({"seed": 7, "exp_name": "c", "noise": 0.1, "new": 3, "removed": 1}, campaign)
    assert run_seeds.is_campaigns({"seed": 7, "exp_name": "c", "noise": 0.1}, campaign)  # "new" at its default
    assert not run_seeds.is_campaigns({"seed": 7, "exp_name": "c", "noise": 0.2, "new": 3}, campaign)
    changed = {**campaign, "args": {**campaign["args"], "new": 4}}
    assert not run_seeds.is_campaigns({"seed": 7, "exp_name": "c", "noise": 0.1}, changed)  # made before "new"


def test_a_pusher_v5_run_from_before_the_contact_setting_ran_under_mujoco_4s_own():
    """Its default now is the 2.3 contact: an old Pusher-v5 run is not the default campaign's; Pusher-v4's (made on
    mujoco 2.3.7) and other tasks' are."""
    for env_id, old_contact in (("Pusher-v5", "gymnasium"), ("Pusher-v4", "mujoco-2.3"), ("Reacher-v5", "mujoco-2.3")):
        for contact in ("mujoco-2.3", "gymnasium"):
            campaign = {"args": {"env_id": env_id, "contact": contact}, "defaults": {"contact": "mujoco-2.3"}}
            assert run_seeds.is_campaigns({"env_id": env_id}, campaign) == (contact == old_contact), (env_id, contact)


def test_unreadable_summaries_of_the_campaign_do_not_stop_it(tmp_path, monkeypatch, fake_script, capsys):
    """Issue 55, item 8: a matching summary.json that is truncated, a dangling link or unreadable (here a directory)
    crashed run_seeds before any run, so the campaign could never resume. Such a run is not a finished one: it is run
    again, with a warning."""
    monkeypatch.chdir(tmp_path)
    for seed, kind in ((1, "truncated"), (2, "dangling"), (3, "unreadable")):
        run_dir = tmp_path / "runs" / f"Fake-v0__u__{seed}__1"
        run_dir.mkdir(parents=True)
        if kind == "truncated":
            (run_dir / "summary.json").write_text('{"status": "completed", "seed": 1, "scr')
        elif kind == "dangling":
            os.symlink(tmp_path / "nowhere.json", run_dir / "summary.json")
        else:
            (run_dir / "summary.json").mkdir()
    table = run_seeds.main(run_seeds.Args(script="fake.py", exp_name="u", seeds=[1, 2, 3], workers=1))[""]
    assert [s for s, _ in calls(tmp_path)] == [1, 2, 3] and table["eval/x"]["n"] == 3
    err = capsys.readouterr().err
    assert "half-written or damaged" in err and "a dangling link" in err and "a directory, not a file" in err


def test_a_results_dir_that_cannot_be_written_is_refused_before_any_run(tmp_path, fake_script):
    """Issue 55, item 8: a --results-dir that cannot take files was a traceback after the runs, with no table. It is
    refused first, in one line; a copy that fails later (a full disk) leaves the run in runs/ and the table comes."""
    (tmp_path / "afile").write_text("")
    result = subprocess.run([sys.executable, RUN_SEEDS, "--script", "fake.py", "--exp-name", "r", "--seeds", "1",
                             "--results-dir", "afile/kept"], cwd=tmp_path, capture_output=True, text=True,
                            timeout=120)  # fmt: skip
    assert result.returncode == 2, result.stdout + result.stderr
    assert result.stderr.strip() == f"error: --results-dir afile/kept: {tmp_path / 'afile'} is a file, not a directory"
    assert not (tmp_path / "calls.txt").exists()


def test_a_run_that_cannot_be_kept_stays_in_runs_and_the_table_comes(tmp_path, monkeypatch, fake_script, capsys):
    monkeypatch.chdir(tmp_path)

    def full_disk(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(run_seeds.shutil, "copy2", full_disk)
    table = run_seeds.main(run_seeds.Args(script="fake.py", exp_name="f", seeds=[1], results_dir="kept"))[""]
    assert table["eval/x"]["n"] == 1 and os.listdir("kept") == []  # no half-copied run
    assert "not kept in kept/Fake-v0__f__1__" in capsys.readouterr().err
