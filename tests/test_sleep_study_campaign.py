"""The sleep study as a campaign: a night counts only for its own day (by content) and flags, bad input and a night
that refuses its input exit 2, a stop ends in one line, and the table reads what results/ holds whatever state its
files are in."""

import glob
import json
import os
import shutil
import signal
import subprocess
import sys

import numpy as np
import pytest
from conftest import REPO, default_signals

from inform_utils import sleep_study as ss

MAZE = "inform_dqn_gridworld.py"
TINY_DAY = ["--tamer-total-timesteps", "2000", "--tamer-learning-starts", "500", "--sleep-gradient-steps", "200"]
ENV = {**os.environ, "PYTHONPATH": REPO}


def study(cwd, *flags: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "inform_utils.sleep_study", *flags]
    return subprocess.run(cmd, cwd=cwd, env=ENV, capture_output=True, text=True, timeout=600)


def one_error_line(proc: subprocess.CompletedProcess, phrase: str) -> None:
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and phrase in lines[0], proc.stderr[-2000:]


@pytest.fixture(scope="module")
def maze_days(tmp_path_factory):
    """Two tiny maze days (seeds 3 and 4) in folders of one name: A/mday and B/mday."""
    root = tmp_path_factory.mktemp("days")
    for folder, seed in (("A", "3"), ("B", "4")):
        cmd = [sys.executable, os.path.join(REPO, MAZE), "--seed", seed, *TINY_DAY, "--save-buffer"]
        proc = subprocess.run(cmd, cwd=root, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr[-2000:]
        (run_dir,) = [d for d in glob.glob(str(root / "runs" / "*")) if f"__{seed}__" in d]
        os.makedirs(root / folder)
        shutil.move(run_dir, root / folder / "mday")
    return root / "A" / "mday", root / "B" / "mday"


def test_a_night_counts_only_for_its_own_day_and_flags(maze_days, tmp_path):
    """Issue 55, item 1: the study resumed by folder name alone. Another ending after `--`, or another day.pt in a
    folder of the same name, is refused in one line (exit 2) and runs nothing; the campaign's own nights resume."""
    day_a, day_b = maze_days
    base = ["--script", MAZE, "--campaign", "c", "--variants", "sham", "--sleep-seeds", "1"]
    first = study(tmp_path, "--days", str(day_a), *base, "--", "--sleep-gradient-steps", "30")
    assert first.returncode == 0, first.stderr[-2000:]
    kept = tmp_path / "results" / "c" / "mday" / "sham__sleep1"
    summary = json.loads((kept / "summary.json").read_text())
    assert summary["args"]["sleep_gradient_steps"] == 30
    runs = sorted(os.listdir(tmp_path / "runs"))

    other = study(tmp_path, "--days", str(day_a), *base, "--", "--sleep-gradient-steps", "99", "--sleep-temperature",
                  "0.5")  # fmt: skip
    assert other.returncode == 2 and "ran with other flags after --" in other.stderr, other.stdout + other.stderr
    one_error_line(other, "--campaign c: ")
    again = study(tmp_path, "--days", str(day_a), *base)  # no flags after --: not the campaign's either
    assert again.returncode == 2 and "ran with other flags after -- (--sleep-gradient-steps 30)" in again.stderr
    another_day = study(tmp_path, "--days", str(day_b), *base, "--", "--sleep-gradient-steps", "30")
    assert another_day.returncode == 2 and "a night on another day.pt" in another_day.stderr, another_day.stderr
    assert "OPENBLAS_CORETYPE" in another_day.stderr, another_day.stderr  # how to re-make it where it was made
    both = study(tmp_path, "--days", str(day_a), str(day_b), *base, "--", "--sleep-gradient-steps", "30")
    one_error_line(both, "two different days in folders of one name")
    assert both.returncode == 2
    assert sorted(os.listdir(tmp_path / "runs")) == runs  # nothing ran
    assert json.loads((kept / "summary.json").read_text()) == summary

    resumed = study(tmp_path, "--days", str(day_a), *base, "--", "--sleep-gradient-steps", "30")
    assert resumed.returncode == 0 and "[study]" not in resumed.stdout and "| sham | 1 |" in resumed.stdout
    (kept / "night.json").unlink()  # a night kept by an older study: no record of its day and flags, never run over
    older = study(tmp_path, "--days", str(day_a), *base, "--", "--sleep-gradient-steps", "30")
    assert older.returncode == 2 and "no readable record of its day and flags" in older.stderr


def test_a_day_remade_by_its_command_resumes_its_campaign(maze_days, tmp_path):
    """A day is deterministic, so it is re-made rather than kept; but day.pt keeps how long the day took, so the
    re-made file has another sha256 and the campaign refused it as another day. Re-made, it resumes: its kept night is
    not run again, the new night runs on it, and the first file is accepted again beside both."""
    day_a = maze_days[0]
    proc = subprocess.run([sys.executable, os.path.join(REPO, MAZE), "--seed", "3", *TINY_DAY, "--save-buffer"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=600)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    (run_dir,) = glob.glob(str(tmp_path / "runs" / "*"))
    shutil.move(run_dir, tmp_path / "mday")
    assert ss.sha256(str(tmp_path / "mday" / "day.pt")) != ss.sha256(str(day_a / "day.pt"))  # only the clock differs
    base = ["--script", MAZE, "--campaign", "c", "--variants", "sham", "--", "--sleep-gradient-steps", "30"]

    first = study(tmp_path, "--days", str(day_a), "--sleep-seeds", "1", *base)
    assert first.returncode == 0, first.stderr[-2000:]
    kept = (tmp_path / "results" / "c" / "mday" / "sham__sleep1" / "summary.json").read_text()
    remade = study(tmp_path, "--days", "mday", "--sleep-seeds", "1", "2", *base)
    assert remade.returncode == 0, remade.stderr[-2000:]
    assert "mday: re-made" in remade.stdout and remade.stdout.count("sham sleep seed") == 1
    assert "sham sleep seed 2" in remade.stdout
    assert (tmp_path / "results" / "c" / "mday" / "sham__sleep1" / "summary.json").read_text() == kept
    again = study(tmp_path, "--days", str(day_a), "--sleep-seeds", "1", "2", *base)
    assert again.returncode == 0 and "sham sleep seed" not in again.stdout, again.stdout + again.stderr


def test_a_study_whose_nights_refuse_their_input_exits_2(maze_days, tmp_path):
    """Issue 55, item 4: a maze day given to the Pusher's study: its night refuses it, and so would every night; the
    study stops there in one line (it exited 0 after "failed (2)" and "no completed nights")."""
    proc = study(tmp_path, "--days", str(maze_days[0]), "--variants", "default", "sham", "--sleep-seeds", "1")
    assert proc.returncode == 2, proc.stdout + proc.stderr
    one_error_line(proc, "the default night on")
    assert proc.stdout.count("[study]") == 1 and not (tmp_path / "results" / "sleep_study").exists()


def test_a_night_that_fails_makes_the_study_exit_1(tmp_path, monkeypatch, capsys):
    """A night that fails for another reason than its input: the others run, the table prints, then one line and
    exit 1."""
    (tmp_path / "day").mkdir()
    (tmp_path / "day" / "day.pt").write_bytes(b"a day")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(ss, "run_child", lambda cmd, stop: subprocess.CompletedProcess(cmd, 1, "", "out of memory"))
    args = ss.Args(days=["day"], script=MAZE, campaign="c", variants=["default", "sham"], sleep_seeds=[1])
    assert ss.study_main(args, []) == 1
    out, err = capsys.readouterr()
    assert out.count("[study] failed (exit 1: out of memory)") == 2 and "no completed nights" in out
    assert err.startswith("error: 2 of 2 night(s) or tests failed (default sleep seed 1 on day; sham sleep seed 1")
    assert not os.path.exists("results/c/day")


@pytest.mark.parametrize(
    ("flags", "phrase"),
    [
        (["--days", "nowhere"], "nowhere holds no day.pt"),
        (["--variants", "nap"], "unknown variant(s) nap"),
        (["--table", "--campaign", "../x"], "one folder name"),
        (["--days", "day", "--results-dir", "afile/results"], "afile is a file, not a directory"),
        (["--days", "day", "--random-start-episodes", "0"], "--random-start-episodes and --gradient-steps be >= 1"),
    ],
)
def test_bad_input_exits_2_in_one_line(tmp_path, flags, phrase):
    """Issue 55, item 14: the study's bad input exited 1."""
    (tmp_path / "day").mkdir()
    (tmp_path / "day" / "day.pt").write_bytes(b"a day")
    (tmp_path / "afile").write_text("")
    proc = study(tmp_path, *flags)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    one_error_line(proc, phrase)
    assert sorted(os.listdir(tmp_path)) == ["afile", "day"]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_stop_ends_the_study_in_one_line(maze_days, tmp_path, sig):
    """Issue 55, item 7: Ctrl-C (SIGINT to the study's process group) was a KeyboardInterrupt traceback; SIGTERM to
    the study, exit 143 with no line and its night left running. The night in progress is stopped and not kept."""
    cmd = [sys.executable, "-m", "inform_utils.sleep_study", "--script", MAZE, "--days", str(maze_days[0]),
           "--campaign", "c", "--variants", "default", "--sleep-seeds", "1", "--", "--sleep-gradient-steps",
           "10000000"]  # fmt: skip
    proc = subprocess.Popen(cmd, cwd=tmp_path, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=default_signals, process_group=0)  # fmt: skip
    try:
        assert proc.stdout.readline().startswith("[study] mday default sleep seed 1")
        if sig == signal.SIGINT:
            os.killpg(proc.pid, sig)  # a terminal's Ctrl-C
        else:
            proc.send_signal(sig)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 128 + sig, err
    assert "Traceback" not in err
    one_error_line(subprocess.CompletedProcess(cmd, proc.returncode, out, err), f"stopped by {sig.name}")
    assert not (tmp_path / "results" / "c" / "mday" / "default__sleep1").exists()
    summaries = glob.glob(str(tmp_path / "runs" / "*" / "summary.json"))  # the night saved what finished, if it began
    assert all(json.loads(open(p).read())["status"] == "interrupted" for p in summaries)


# what a tiny Pusher night's summary holds for each policy (no offline pick: eval/inform_selected_* is not there)
VALUES = {key.format(p=p): value for p in ("oracle", "tamer", "inform")
          for key, value in (("eval/{p}_return", -30.0), ("eval/{p}_success_rate", 0.0),
                             ("eval/{p}_final_distance", 0.2), ("eval/obstacle/{p}_final_distance", 0.25),
                             ("eval/authors_test/{p}_final_distance", 0.2))}  # fmt: skip


def pusher_night(path, summary: dict, policies=("tamer", "inform")) -> None:
    path.mkdir(parents=True)
    (path / "summary.json").write_text(json.dumps({"status": "completed", "seed": 1, **summary}))
    (path / "random_starts.json").write_text("{}")
    np.savez(path / "obstacle_distances.npz", **{p: np.array([0.2, 0.3]) for p in policies})


def test_the_table_of_tiny_nights_without_an_offline_pick(tmp_path):
    """Issue 52, item 5: tiny nights have no inform_selected (the offline criterion picked none): the table was
    KeyError: 'inform_selected is not a file in the archive'. It prints, without that policy's rows."""
    values = VALUES
    for variant in ("default", "sham", "bc"):
        pusher_night(tmp_path / "c" / "day" / f"{variant}__sleep1", values)
    text = ss.table(ss.Args(results_dir=str(tmp_path), campaign="c"))
    assert "3 nights on 1 day(s)" in text and "| default | 1 |" in text
    assert "| default, offline pick |" not in text


def test_the_rule_reads_each_budget_from_its_own_campaign(tmp_path):
    """Issue 56: one --table prints the rule for the methods at every budget, a campaign a budget (--with-campaigns).
    dwbc, bc and the sham on one day at 5,000 steps (campaign c) and at 50,000 (c50k), each with TAMER's other streams
    in its own folder: c's range 1.0, c50k's 3.0, so the 50,000-step row's plain-task spread is read from c50k. A
    campaign of no nights, or one holding a budget --campaign holds too, is refused in one line."""
    for campaign, steps, streams in (("c", 5000, [-30.0, -29.0]), ("c50k", 50000, [-30.0, -27.0])):
        for variant, distance in (("dwbc", 0.18), ("bc", 0.20), ("sham", 0.19)):
            pusher_night(tmp_path / campaign / "day" / f"{variant}__sleep1",
                         {**VALUES, "args": {"env_id": "Pusher-v4", "sleep_gradient_steps": steps},
                          "sleep_variant": "policy_lr=0.0001", "eval/obstacle/inform_final_distance": distance,
                          "eval/inform_return_sampled": -30.0, "eval/tamer_return_sampled": -30.0})  # fmt: skip
        (tmp_path / campaign / "day" / "tamer_streams.json").write_text(json.dumps(
            {"eval/tamer_return_sampled": {"2": streams[1]}}))  # fmt: skip
    args = ss.Args(results_dir=str(tmp_path), campaign="c")
    assert "| Pusher-v4 | 50000 |" not in ss.table(args)  # one campaign: its own budget only
    text = ss.table(ss.Args(results_dir=str(tmp_path), campaign="c", with_campaigns=["c50k"]))
    rows = {line.split(" | ")[1]: line for line in text.splitlines() if " | dwbc (0.0001) | " in line}  # the rule's
    assert "| dwbc (0.0001) | 1 | -0.0200 m, p = -, closer on 1 of 1 |" in rows["5000"]
    assert "(spread 1.00)" in rows["5000"] and "(spread 3.00)" in rows["50000"]
    assert "Pusher-v4, 50000 gradient steps, the means over the 1 days" in text
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="--with-campaigns empty: no completed nights under"):
        ss.table(ss.Args(results_dir=str(tmp_path), campaign="c", with_campaigns=["empty"]))
    shutil.copytree(tmp_path / "c", tmp_path / "c2")
    with pytest.raises(ValueError, match="its nights of 5000 gradient steps are a budget of --campaign c too"):
        ss.table(ss.Args(results_dir=str(tmp_path), campaign="c", with_campaigns=["c2"]))


def test_the_table_leaves_out_nights_it_cannot_read_and_says_why(tmp_path):
    """Issue 55, item 9: a night folder without summary.json, a dangling `*__sleep*` link, a half-written summary, an
    unreadable random_starts.json or a truncated obstacle file: each was a traceback. The table prints the nights it
    can read and names each other one with its cause."""
    values = VALUES
    day = tmp_path / "c" / "day"
    pusher_night(day / "default__sleep1", values)
    (day / "default__sleep2").mkdir()  # no summary.json
    os.symlink(tmp_path / "nowhere", day / "default__sleep3")  # a dangling link
    pusher_night(day / "default__sleep4", values)
    (day / "default__sleep4" / "summary.json").write_text('{"status": "compl')  # half-written
    pusher_night(day / "default__sleep5", values)
    (day / "default__sleep5" / "random_starts.json").write_bytes(b"\xff\xfe{")  # unreadable as text
    pusher_night(day / "default__sleep6", values)
    npz = day / "default__sleep6" / "obstacle_distances.npz"
    npz.write_bytes(npz.read_bytes()[:100])  # truncated
    text = ss.table(ss.Args(results_dir=str(tmp_path), campaign="c"))
    assert "1 nights on 1 day(s)" in text and "| default | 1 |" in text
    notes = {line.split(", ", 1)[0].removeprefix("not in the table: "): line.split(", ", 1)[1]
             for line in text.splitlines() if line.startswith("not in the table: ")}  # fmt: skip
    assert set(notes) == {f"c/day/default__sleep{i}" for i in (2, 3, 4, 5, 6)}, text
    assert "summary.json: cannot read it (no such file)" in notes["c/day/default__sleep2"]
    assert "summary.json: cannot read it (no such file)" in notes["c/day/default__sleep3"]
    assert "half-written or damaged" in notes["c/day/default__sleep4"]
    assert "random_starts.json: cannot read it" in notes["c/day/default__sleep5"]
    assert "obstacle_distances.npz: cannot read it" in notes["c/day/default__sleep6"]


def test_a_night_is_kept_whole_or_not_at_all(tmp_path, monkeypatch):
    """Issue 55, item 9: on a full disk the study died mid-copy and left a 0-byte summary.json in results/. A night is
    copied into a hidden folder that takes its place at once; a failed copy leaves nothing, and one line."""
    run_dir = tmp_path / "runs" / "night"
    pusher_night(run_dir, {"args": {"env_id": "Pusher-v5"}})
    monkeypatch.chdir(tmp_path)
    stdout = f"run directory: {run_dir}\n"
    monkeypatch.setattr(ss, "run_child", lambda cmd, stop: subprocess.CompletedProcess(cmd, 0, stdout, ""))
    monkeypatch.setattr(ss, "random_starts", lambda *a: {"random_starts/episodes": 2})
    copies = []

    def copy_on_a_full_disk(src, dest):
        copies.append(dest)
        if len(copies) == 2:
            raise OSError(28, "No space left on device")
        shutil.copy(src, dest)

    monkeypatch.setattr(ss, "copy", copy_on_a_full_disk)
    args = ss.Args(days=["day"], campaign="c")
    with pytest.raises(OSError, match="cannot keep the night in results/c/day/default__sleep1 .No space left"):
        ss.run_night(args, "day", "default", 1, {"flags": []}, ss.Stop())
    assert os.listdir("results/c/day") == []  # no night, no hidden half-copy
    monkeypatch.setattr(ss, "copy", lambda src, dest: shutil.copy(src, dest))
    assert ss.run_night(args, "day", "default", 1, {"flags": []}, ss.Stop())
    assert sorted(os.listdir("results/c/day/default__sleep1")) == ["night.json", "obstacle_distances.npz",
                                                                   "random_starts.json", "summary.json"]  # fmt: skip
