"""Issue 71, the core scripts and the sleep study: nothing lost, round four. A saved day's settings are checked as JSON
values when it is read (not when the night's summary is written); an interrupted run records how long its phase ran
and keeps its mid-run checks under a name of their own; the sham builds H as the day built it; tamer_h.pt keeps
its constructor arguments whole; the study takes a stop signalled twice at once as one stop, names a day by its
content (not by how long it took), says nothing of OpenBLAS for a record changed by hand, refuses a Pusher study
without the obstacle test up front, and checks what it reads."""

import glob
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time

import pytest
import torch
from conftest import REPO, default_signals
from test_day_hack import MAZE_DAY, MAZE_NIGHT, PUSHER_DAY, PUSHER_NIGHT

import inform_dqn_gridworld as maze
import inform_sac_pusher as isp
from inform_utils import sleep_study as ss
from inform_utils import sleep_variants_maze as svm
from inform_utils import sleep_variants_pusher as svp

ENV = {**os.environ, "PYTHONPATH": REPO, "OMP_NUM_THREADS": "1"}
SCRIPTS = {"pusher": ("inform_sac_pusher.py", PUSHER_DAY, PUSHER_NIGHT), "maze": ("inform_dqn_gridworld.py", MAZE_DAY,
                                                                               MAZE_NIGHT)}  # fmt: skip
MAZE = "inform_dqn_gridworld.py"


def run(cwd, *cmd: str, timeout: float = 300) -> subprocess.CompletedProcess:
    cmd = [sys.executable, *([os.path.join(REPO, cmd[0])] if cmd[0].endswith(".py") else [cmd[0]]), *cmd[1:]]
    return subprocess.run(cmd, cwd=cwd, env=ENV, capture_output=True, text=True, timeout=timeout)


def one_error_line(proc: subprocess.CompletedProcess, *phrases: str) -> str:
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), (proc.returncode, proc.stderr)
    assert all(p in lines[0] for p in phrases), lines[0]
    return lines[0]


def made_runs(cwd) -> list[str]:
    return sorted(glob.glob(os.path.join(cwd, "runs", "*")))


@pytest.fixture(scope="module")
def days(tmp_path_factory):
    """A tiny saved day of each script: {"pusher": its run directory, "maze": ...}."""
    root, out = tmp_path_factory.mktemp("days"), {}
    for name, (script, day_flags, night_flags) in SCRIPTS.items():
        proc = run(root, script, *day_flags, *night_flags, "--save-buffer", "--exp-name", name)
        assert proc.returncode == 0, proc.stderr[-2000:]
        (run_dir,) = glob.glob(str(root / "runs" / f"*__{name}__*"))
        out[name] = str(root / name)
        shutil.move(run_dir, out[name])
    return out


def tampered(day_dir: str, dest, change) -> str:
    """A copy of the day in `dest` with `change(day)` made to its day.pt; its folder."""
    day = torch.load(os.path.join(day_dir, "day.pt"), weights_only=True)
    change(day)
    os.makedirs(dest, exist_ok=True)
    torch.save(day, os.path.join(dest, "day.pt"))
    return str(dest)


# item 1: a day's settings are JSON values (a known flag's of its type), checked when the day is read ---------------
BAD_SETTINGS = {
    "a tensor for a flag": ("day_args", "tamer_batch_size", torch.tensor(64), "not a JSON value"),
    "bytes for a copy's setting": ("day_args", "notes", b"\x00\x01", "not a JSON value"),
    "a string for a count": ("day_args", "tamer_batch_size", "64", "type: str is not an instance of int"),
    "a tensor among the stats": ("day_stats", "feedback/positive", torch.tensor(3), "not a JSON value"),
}


@pytest.mark.parametrize("script", SCRIPTS)
@pytest.mark.parametrize("case", BAD_SETTINGS)
def test_a_day_whose_settings_are_no_json_values_is_refused_when_read(days, tmp_path, script, case):
    """A tensor or bytes among a day's settings ran the whole night, then failed in write_json_atomic: no summary."""
    part, name, value, phrase = BAD_SETTINGS[case]
    bad = tampered(days[script], tmp_path / "bad", lambda day: day[part].__setitem__(name, value))
    core = isp if script == "pusher" else maze
    with pytest.raises(core.InputError, match=re.escape(f"{part}[{name!r}] is ") + f".*{re.escape(phrase)}$"):
        core.load_day(bad)


@pytest.mark.parametrize("script", SCRIPTS)
def test_the_night_on_such_a_day_refuses_it_in_one_line_before_it_runs(days, tmp_path, script):
    bad = tampered(days[script], tmp_path / "bad", lambda day: day["day_args"].__setitem__("seed", torch.tensor(3)))
    proc = run(tmp_path, SCRIPTS[script][0], "--sleep-from", bad, *SCRIPTS[script][2])
    one_error_line(proc, "day_args['seed'] is tensor(3), not a JSON value")
    assert made_runs(tmp_path) == []


def test_a_five_megabyte_setting_is_kept_whole_and_said_in_a_short_line(days, tmp_path):
    notes = "x" * 5_000_000
    day = tampered(days["pusher"], tmp_path / "day", lambda day: day["day_args"].__setitem__("notes", notes))
    proc = run(tmp_path, "inform_sac_pusher.py", "--sleep-from", day, *PUSHER_NIGHT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert max(map(len, proc.stdout.splitlines())) < 1000 and "'notes': 'xxx" in proc.stdout
    (run_dir,) = made_runs(tmp_path)
    assert json.load(open(os.path.join(run_dir, "summary.json")))["day_settings"]["notes"] == notes


# item 3: an interrupted run records the time its phase ran, and its mid-run checks under a name of their own ------
STOPPED_MID_TAMER = """
import os, signal, sys
import {module} as core

core.EVAL_FREQUENCY = {every}  # periodic checks every {every} steps of the day
calls, update = [], core.Day.update

def stop_at(self, *a, **kw):  # SIGTERM at the {n}th update of H, as Ctrl-C or kill sends it
    calls.append(1)
    if len(calls) == {n}:
        os.kill(os.getpid(), signal.SIGTERM)
    return update(self, *a, **kw)

core.Day.update = stop_at
sys.exit(core.cli(core.Args(**{kwargs})))
"""


@pytest.mark.parametrize("script", SCRIPTS)
def test_a_run_stopped_mid_tamer_records_how_long_it_ran_and_no_check_as_a_final_result(tmp_path, script):
    """It recorded time/tamer_s 0.0 after ~85 s, and eval/tamer_* held the check at step 10,000 as final results."""
    if script == "pusher":
        kwargs = dict(tamer_total_timesteps=5000, tamer_learning_starts=100, tamer_batch_size=64, eval_episodes=1,
                      oracle_path=PUSHER_DAY[PUSHER_DAY.index("--oracle-path") + 1])  # fmt: skip
        module, every, n, tests = "inform_sac_pusher", 200, 450, ("tamer_return", "oracle_return")
    else:
        module, every, n, tests = "inform_dqn_gridworld", 500, 700, ("tamer_episode_length", "oracle_episode_length")
        kwargs = dict(tamer_total_timesteps=5000, tamer_learning_starts=100)
    code = STOPPED_MID_TAMER.format(module=module, every=every, n=n, kwargs=kwargs)
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=ENV, capture_output=True, text=True,
                          timeout=300)  # fmt: skip
    assert proc.returncode == 128 + signal.SIGTERM, proc.stderr[-2000:]
    (run_dir,) = made_runs(tmp_path)
    summary = json.load(open(os.path.join(run_dir, "summary.json")))
    assert summary["status"] == "interrupted" and summary["phase"] == "tamer"
    assert summary["time/tamer_s"] > 0.05, summary["time/tamer_s"]  # it ran; the stop came ~n steps in
    for name in tests:  # a mid-run check is no final result: it keeps a name of its own
        assert f"eval/{name}" not in summary and f"eval/last_check/{name}" in summary, sorted(summary)


# items 4 and 5: the sham builds H from the day's kwargs; tamer_h.pt keeps them whole ---------------------------------
def test_the_pusher_sham_builds_h_as_the_day_built_it():
    """ShamControl rebuilt H from today's constants: a day whose H had LayerNorm (or another width) was a traceback."""
    kwargs = {"obs_dim": 23, "act_dim": 7, "hidden": 64, "n": 2, "layer_norm": True}
    h_net, actor = isp.QEnsemble(**kwargs), isp.Actor(23, 7, isp.HIDDEN_SIZE)
    args = svp.Args(sleep_control="sham", sleep_batch_size=4)
    night = args.night(
        actor, torch.device("cpu"), tamer={"h_net": h_net, "h_kwargs": kwargs, "day_settings": {}, "ent_coef": 0.5}
    )
    assert night.h_net.norm is not None and night.h_net.fc1.weight.shape[2] == 64
    theirs = h_net.state_dict()
    assert all(torch.equal(value, theirs[name]) for name, value in night.h_net.state_dict().items())
    batch = (torch.randn(8, 23), torch.rand(8, 7) * 4 - 2, torch.randn(8, 23), torch.ones(8), torch.zeros(8))
    night.update(1, batch)  # H learns on


def test_the_maze_sham_builds_h_as_the_day_built_it():
    """The maze's sham loaded the day's H into a network of today's width: an H 64 wide was a traceback."""
    h_net = maze.QNetwork(30, 4, hidden=64)
    night = svm.Args(sleep_control="sham").sleep_learner(30, 4, h_net, torch.device("cpu"))
    assert night.q_net.kwargs == h_net.kwargs and night.q_net is not h_net
    obs = torch.eye(30)[torch.randint(0, 30, (8,))]
    batch = (obs, torch.randint(0, 4, (8,)), obs, torch.ones(8), torch.zeros(8))
    night.update(batch, torch.arange(8) >= 4)  # H learns on, and its target follows


def test_tamer_h_pt_keeps_the_constructor_arguments_whole(tmp_path):
    """save_critic wrote obs_dim, act_dim, hidden and n: a LayerNorm H could not be rebuilt from its own file."""
    kwargs = {"obs_dim": 23, "act_dim": 7, "hidden": 32, "n": 2, "layer_norm": True}
    isp.save_critic(str(tmp_path / "tamer_h.pt"), isp.QEnsemble(**kwargs), kwargs, env_id="Pusher-v5")
    ckpt = torch.load(tmp_path / "tamer_h.pt", weights_only=True)
    assert ckpt["kwargs"] == kwargs
    isp.QEnsemble(**ckpt["kwargs"]).load_state_dict(ckpt["state_dict"])


# item 8: what counted as positive -------------------------------------------------------------------------------------
GRADED = """
import sys
import inform_sac_pusher as core

class Graded(core.Day):  # a teacher whose yes is worth a half
    def answer(self, *a):
        return 0.5 * super().answer(*a)

core.Day = Graded
sys.exit(core.cli(core.Args(**{kwargs})))
"""


def test_graded_answers_say_what_counted_as_positive(tmp_path):
    kwargs = dict(tamer_total_timesteps=400, tamer_learning_starts=200, tamer_batch_size=64, success_distance=1.0,
                  sleep_gradient_steps=10, sleep_batch_size=64, eval_episodes=1, obstacle_episodes=0,
                  authors_test_episodes=0, oracle_path=PUSHER_DAY[PUSHER_DAY.index("--oracle-path") + 1])  # fmt: skip
    proc = subprocess.run([sys.executable, "-c", GRADED.format(kwargs=kwargs)], cwd=tmp_path, env=ENV,
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    (run_dir,) = made_runs(tmp_path)
    summary = json.load(open(os.path.join(run_dir, "summary.json")))
    assert summary["feedback/positive"] > 0 and summary["feedback/positive_label_mean"] == 0.5
    assert "every answer above 0, as one" in summary["feedback/counted_as_positive"]


# item 2: one stop per run however many signals come in its first moment ---------------------------------------------
class FakeChild:
    def __init__(self):
        self.signals = []

    def send_signal(self, sig):
        self.signals.append(sig)


def test_the_study_takes_two_signals_at_once_as_one_stop(monkeypatch):
    """`timeout` signals the study, then its process group: the second signal killed the night (SIGKILL)."""
    now = [100.0]
    monkeypatch.setattr(ss.time, "monotonic", lambda: now[0])
    stop, child = ss.Stop(), FakeChild()
    stop.procs.add(child)
    stop.handler(signal.SIGTERM, None)
    now[0] += 0.2
    stop.handler(signal.SIGTERM, None)
    stop.handler(signal.SIGINT, None)
    assert child.signals == [signal.SIGTERM] and stop.signum == signal.SIGTERM  # passed on once: the night saves
    now[0] += 5
    stop.handler(signal.SIGINT, None)  # a stop asked for again, later: the night is killed
    assert child.signals == [signal.SIGTERM, signal.SIGKILL]


def test_a_study_night_under_timeout_saves_what_finished(days, tmp_path):
    cmd = [sys.executable, "-m", "inform_utils.sleep_study", "--script", MAZE, "--days", days["maze"], "--campaign",
           "c", "--variants", "default", "--sleep-seeds", "1", "--", "--sleep-gradient-steps", "10000000"]  # fmt: skip
    proc = subprocess.Popen(cmd, cwd=tmp_path, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=default_signals, process_group=0)  # fmt: skip
    try:
        deadline = time.monotonic() + 120
        while not made_runs(tmp_path) and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
        assert made_runs(tmp_path), "the night never started"
        # as `timeout` does: the study, then its process group (two signals of one kind that come at once reach
        # Python as one; of two kinds, as two, and the first runs first)
        proc.send_signal(signal.SIGHUP)
        os.killpg(proc.pid, signal.SIGTERM)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 128 + signal.SIGHUP and "Traceback" not in err, err
    (run_dir,) = made_runs(tmp_path)
    summary = json.load(open(os.path.join(run_dir, "summary.json")))  # the night saved what finished
    assert summary["status"] == "interrupted" and summary["signal"] == "SIGHUP"


# item 7: a day's identity from its content ---------------------------------------------------------------------------
def remade_copy(day_dir: str, dest, minutes: float) -> str:
    """The day as its command makes it again: the same but for how long it took (and where its teacher was read)."""

    def took_longer(day):
        day["day_stats"].update({k: v + 60 * minutes for k, v in day["day_stats"].items() if k.startswith("time/")})
        if "oracle_path" in day:
            day["oracle_path"] = f"/elsewhere/{minutes}/oracle.pt"

    return tampered(day_dir, dest, took_longer)


@pytest.mark.parametrize("script", SCRIPTS)
def test_a_day_is_named_by_its_content_not_by_how_long_it_took(days, tmp_path, script):
    again = remade_copy(days[script], tmp_path / "again", 3)
    first, second = (os.path.join(d, "day.pt") for d in (days[script], again))
    assert ss.sha256(first) != ss.sha256(second) and ss.content_sha256(first) == ss.content_sha256(second)
    other = tampered(days[script], tmp_path / "other", lambda day: day["feedback"].__setitem__(0, 0.25))
    assert ss.content_sha256(os.path.join(other, "day.pt")) != ss.content_sha256(first)


def study(cwd, *flags: str) -> subprocess.CompletedProcess:
    return run(cwd, "-m", "inform_utils.sleep_study", *flags, timeout=600)


def test_a_campaign_knows_a_remade_day_by_content_and_an_old_record_by_its_clock(days, tmp_path):
    """night.json names its day by content (and the CPU kernels it ran on); a re-made day resumes the campaign, by
    content, and by an old record's sha256 (the clock put back); a record changed by hand is not blamed on OpenBLAS."""
    base = ["--script", MAZE, "--campaign", "c", "--variants", "default", "--sleep-seeds", "1", "--",
            "--sleep-gradient-steps", "30"]  # fmt: skip
    shutil.copytree(days["maze"], tmp_path / "first" / "mday")
    first = study(tmp_path, "--days", str(tmp_path / "first" / "mday"), *base)
    assert first.returncode == 0, first.stderr[-2000:]
    record_path = tmp_path / "results" / "c" / "mday" / "default__sleep1" / "night.json"
    record = json.loads(record_path.read_text())
    assert record["day_content_sha256"] == ss.content_sha256(str(tmp_path / "first" / "mday" / "day.pt"))
    assert record["cpu"].startswith(torch.backends.cpu.get_cpu_capability())

    again = remade_copy(days["maze"], tmp_path / "again" / "mday", 3)
    resumed = study(tmp_path, "--days", again, *base)
    assert resumed.returncode == 0 and "re-made" in resumed.stdout and "sleep seed 1:" not in resumed.stdout, (
        resumed.stdout + resumed.stderr)  # fmt: skip

    old = {k: v for k, v in record.items() if k not in ("day_content_sha256", "cpu")}  # as the study kept it before
    record_path.write_text(json.dumps(old))
    by_clock = study(tmp_path, "--days", again, *base)  # the re-made file with the night's clock put back: the same
    assert by_clock.returncode == 0 and "re-made" in by_clock.stdout and "sleep seed 1:" not in by_clock.stdout, (
        by_clock.stdout + by_clock.stderr)  # fmt: skip

    record_path.write_text(json.dumps({**record, "day_sha256": "0" * 64, "day_content_sha256": "0" * 64}))
    by_hand = study(tmp_path, "--days", str(tmp_path / "first" / "mday"), *base)
    line = one_error_line(by_hand, "night.json was changed since it was kept")
    assert "OpenBLAS" not in line and "OPENBLAS" not in line


# item 6: a Pusher study needs the obstacle test; a night without one of its files leaves nothing -------------------
def test_a_pusher_study_without_the_obstacle_test_is_refused_up_front(tmp_path):
    (tmp_path / "day").mkdir()
    (tmp_path / "day" / "day.pt").write_bytes(b"a day")
    for after in (["--obstacle-episodes", "0"], ["--obstacle-episodes=0"]):
        proc = study(tmp_path, "--days", "day", "--", *after)
        one_error_line(proc, "--obstacle-episodes 0", "obstacle_distances.npz")
        assert sorted(os.listdir(tmp_path)) == ["day"]  # nothing made, no empty folder


def test_a_night_that_left_out_a_file_is_a_failed_night_that_leaves_nothing(tmp_path, monkeypatch):
    """It was `cannot keep the night in .../default__sleep1 (No such file or directory)`, and an empty day folder."""
    run_dir = tmp_path / "runs" / "night"
    run_dir.mkdir(parents=True)
    (run_dir / "summary.json").write_text(json.dumps({"status": "completed", "seed": 1, "args": {"env_id": "x"}}))
    monkeypatch.chdir(tmp_path)
    stdout = f"run directory: {run_dir}\n"
    monkeypatch.setattr(ss, "run_child", lambda cmd, stop: subprocess.CompletedProcess(cmd, 0, stdout, ""))
    monkeypatch.setattr(ss, "random_starts", lambda *a: {"random_starts/episodes": 2})
    assert not ss.run_night(ss.Args(days=["day"], campaign="c"), "day", "default", 1, {"flags": []}, ss.Stop())
    assert not os.path.exists("results")


# item 9: the study's input checks ------------------------------------------------------------------------------------
def kept_night(path, summary: dict, random_starts="{}", record=None) -> None:
    path.mkdir(parents=True)
    (path / "summary.json").write_text(json.dumps({"status": "completed", "seed": 1, **summary}))
    (path / "random_starts.json").write_text(random_starts)
    if record is not None:
        (path / "night.json").write_text(json.dumps(record))


def test_a_damaged_night_record_is_one_line(tmp_path):
    (tmp_path / "day").mkdir()
    (tmp_path / "day" / "day.pt").write_bytes(b"a day")
    record = {"script": MAZE, "flags": 5, "random_start_episodes": None, "day_sha256": "x", "night_flags": []}
    kept_night(tmp_path / "results" / "c" / "day" / "default__sleep1", {}, record=record)
    proc = study(tmp_path, "--script", MAZE, "--days", "day", "--campaign", "c", "--variants", "default",
                 "--sleep-seeds", "1")  # fmt: skip
    one_error_line(proc, "default__sleep1 has a damaged record", "its flags is 5")


def test_the_table_names_a_night_it_cannot_read_with_its_cause(tmp_path):
    """random_starts.json holding strings, a completed summary.json holding nothing: tracebacks in --table."""
    day = tmp_path / "results" / "c" / "day"
    values = {f"eval/{p}_return": -30.0 for p in ("oracle", "tamer", "inform")}
    kept_night(day / "default__sleep1", values)
    kept_night(day / "default__sleep2", values, random_starts=json.dumps({"random_starts/episodes": "fifty"}))
    (day / "default__sleep3").mkdir()
    (day / "default__sleep3" / "summary.json").write_text('{"status": "completed"}')
    (day / "default__sleep3" / "random_starts.json").write_text("{}")
    proc = study(tmp_path, "--table", "--campaign", "c")
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert "1 nights on 1 day(s)" in proc.stdout
    assert 'not in the table: c/day/default__sleep2, its random_starts.json holds "fifty"' in proc.stdout
    assert "not in the table: c/day/default__sleep3, its summary.json's seed is null" in proc.stdout


@pytest.mark.parametrize(
    ("flags", "phrase"),
    [
        (["--days", "day", "--gradient-steps", "0"], "--gradient-steps be >= 1"),
        (["--table", "--campaign", "afile"], "--campaign afile: results/afile is not a folder of nights"),
        (["--table", "--campaign", "c", "--with-campaigns", "afile"], "--campaign afile"),
    ],
)
def test_bad_input_to_the_study_is_one_line_and_exit_2(tmp_path, flags, phrase):
    (tmp_path / "day").mkdir()
    (tmp_path / "day" / "day.pt").write_bytes(b"a day")
    (tmp_path / "results" / "c").mkdir(parents=True)
    (tmp_path / "results" / "afile").write_text("")
    one_error_line(study(tmp_path, *flags), phrase)


@pytest.mark.parametrize("core", [isp, maze])
def test_a_long_run_name_is_refused_in_a_short_line(core):
    """A 5,000-character --exp-name was echoed whole in its error."""
    with pytest.raises(core.InputError) as refused:
        core.check_run_name("Pusher-v5", "x" * 5000, 1)
    assert len(str(refused.value)) < 200 and "'xxxx" in str(refused.value) and "..." in str(refused.value)
