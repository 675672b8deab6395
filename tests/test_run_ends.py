"""Every way a run ends is clean, in both INFORM scripts: SIGINT, SIGTERM and SIGHUP while starting, in each phase and
after the end, and a reader of stdout that dies. Real signals and real broken pipes, in children started with default
signals, every wait bounded. Each test checks the exit code (128 + the signal) and summary.json's status and phase."""

import glob
import json
import os
import signal
import subprocess
import sys
import threading
import time

import pytest
from conftest import REPO, Child, default_signals

MAZE = os.path.join(REPO, "inform_dqn_gridworld.py")
PUSHER = os.path.join(REPO, "inform_sac_pusher.py")
# phases long enough that a signal sent on their first progress line lands in them (see test_inform_gridworld.py)
MAZE_TAMER = [MAZE, "--tamer-total-timesteps", "400000"]  # long enough that no stop can come after its end
MAZE_SLEEP = [MAZE, "--tamer-total-timesteps", "2000", "--tamer-learning-starts", "500", "--sleep-gradient-steps",
              "20000"]  # fmt: skip
PUSHER_TINY = ["--tamer-total-timesteps", "600", "--tamer-learning-starts", "300", "--tamer-batch-size", "64",
               "--sleep-gradient-steps", "200", "--sleep-batch-size", "64", "--eval-episodes", "2",
               "--authors-test-episodes", "3"]  # fmt: skip
SIGNALS = [signal.SIGINT, signal.SIGTERM, signal.SIGHUP]


def summary_of(cwd) -> dict | None:
    found = glob.glob(os.path.join(cwd, "runs", "*", "summary.json"))
    assert len(found) <= 1, found
    if not found:
        return None
    with open(found[0]) as f:
        return json.load(f)


def assert_clean(stderr: str) -> None:
    assert "Traceback" not in stderr and "Exception ignored" not in stderr, stderr[-3000:]


def assert_stopped(cwd, sig_name: str, phases) -> dict:
    summary = summary_of(cwd)
    assert summary is not None, "no summary.json"
    assert summary["status"] == "interrupted" and summary["phase"] in phases and summary["signal"] == sig_name, summary
    return summary


def handler_installed(pid: int, sig: int) -> bool:
    """Linux: the process catches `sig` (SigCgt in /proc/<pid>/status)."""
    try:
        with open(f"/proc/{pid}/status") as f:
            caught = int(next(line for line in f if line.startswith("SigCgt:")).split()[1], 16)
    except (OSError, StopIteration):
        return False
    return bool(caught & (1 << (sig - 1)))


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="reads /proc/<pid>/status (Linux)")
@pytest.mark.parametrize("script", [MAZE, PUSHER], ids=["maze", "pusher"])
@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_a_stop_while_the_libraries_load_is_one_line(tmp_path, script, sig):
    """The first handler is in place before torch loads (seconds): the stop then ends the process with one line and
    the signal's code, and nothing is written (no run exists yet) - or, on a machine so fast that the run began, a
    summary says where it stopped."""
    child = Child([sys.executable, script], tmp_path)
    deadline = time.monotonic() + 60
    while not handler_installed(child.proc.pid, signal.SIGHUP):  # Python's own handlers never catch SIGHUP
        if time.monotonic() > deadline or child.proc.poll() is not None:
            child.fail("the early handler was never installed")
        time.sleep(0.005)
    child.proc.send_signal(sig)
    returncode, _, stderr = child.finish(timeout=60)
    assert returncode == 128 + sig, (returncode, stderr)
    assert_clean(stderr)
    if summary_of(tmp_path) is None:
        assert stderr.strip() == f"interrupted ({sig.name}) while starting; no run was made", stderr
        assert not os.path.exists(tmp_path / "runs") or not os.listdir(tmp_path / "runs")
    else:
        assert_stopped(tmp_path, sig.name, {"startup", "oracle", "tamer"})


@pytest.mark.parametrize("script", [MAZE, PUSHER], ids=["maze", "pusher"])
@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_a_stop_as_soon_as_the_run_directory_exists(tmp_path, script, sig):
    """Start-up: the signal goes out on the first line (the run directory); the summary says the phase it hit."""
    flags = PUSHER_TINY if script == PUSHER else []
    child = Child([sys.executable, script, *flags], tmp_path)
    child.wait_for_line("run dir")
    child.proc.send_signal(sig)
    returncode, _, stderr = child.finish(timeout=60)
    assert returncode == 128 + sig, (returncode, stderr)
    assert_clean(stderr)
    assert_stopped(tmp_path, sig.name, {"startup", "oracle", "tamer"})


@pytest.mark.parametrize(("cmd", "phase"), [(MAZE_TAMER, "tamer"), (MAZE_SLEEP, "sleep")], ids=["tamer", "sleep"])
def test_sighup_in_each_maze_phase(tmp_path, cmd, phase):
    """A closed terminal (SIGHUP) saves what finished, as Ctrl-C and SIGTERM do (test_inform_gridworld.py)."""
    child = Child([sys.executable, *cmd], tmp_path)
    child.wait_for_line(f"[{phase}]")
    child.proc.send_signal(signal.SIGHUP)
    returncode, _, stderr = child.finish(timeout=60)
    assert returncode == 129, (returncode, stderr)
    assert_clean(stderr)
    assert f"interrupted (SIGHUP) during the {phase} phase" in stderr
    assert_stopped(tmp_path, "SIGHUP", {phase})


@pytest.mark.parametrize("sig", [signal.SIGQUIT, signal.SIGXCPU, signal.SIGUSR1], ids=lambda s: s.name)
def test_the_other_catchable_stops_save_what_finished(tmp_path, sig):
    """Ctrl-\\ (SIGQUIT), a cluster's CPU-time limit (SIGXCPU, `ulimit -t`) and SIGUSR1 killed a run with no
    summary; now they stop it as SIGTERM does."""
    child = Child([sys.executable, *MAZE_TAMER], tmp_path)
    child.wait_for_line("[tamer]")
    child.proc.send_signal(sig)
    returncode, _, stderr = child.finish(timeout=60)
    assert returncode == 128 + sig, (returncode, stderr)
    assert_clean(stderr)
    assert_stopped(tmp_path, sig.name, {"tamer"})


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_a_stop_in_the_pusher_final_evaluation(tmp_path, sig):
    """The Pusher's last phase (final evaluation and the obstacle test) is long enough to be hit for sure."""
    child = Child([sys.executable, PUSHER, *PUSHER_TINY, "--obstacle-episodes", "2000"], tmp_path)
    child.wait_for_line("[eval] final evaluation", timeout=300)
    child.proc.send_signal(sig)
    returncode, _, stderr = child.finish(timeout=60)
    assert returncode == 128 + sig, (returncode, stderr)
    assert_clean(stderr)
    assert_stopped(tmp_path, sig.name, {"eval"})


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_a_signal_after_the_end(tmp_path, sig):
    """After the summary is written the run is complete: a signal then only sets the exit code (if the process is
    still there to get it) and never a traceback."""
    child = Child([sys.executable, MAZE, "--tamer-total-timesteps", "1500", "--tamer-learning-starts", "500",
                   "--sleep-gradient-steps", "100"], tmp_path)  # fmt: skip
    child.wait_for_line("oracle: 19 steps")  # printed after summary.json is written
    child.proc.send_signal(sig)
    returncode, _, stderr = child.finish(timeout=60)
    assert returncode in (0, 128 + sig), (returncode, stderr)
    assert_clean(stderr)
    assert summary_of(tmp_path)["status"] == "completed"


def start_piped(cmd, cwd, **kwargs):
    """The script with its stdout on a pipe we read ourselves (to close it), stderr collected by a thread; with
    Python's fault handler on, so that a hang can be shown (finish_piped)."""
    env = {**os.environ, "PYTHONFAULTHANDLER": "1"}
    proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, **kwargs)
    err = []
    thread = threading.Thread(target=lambda: err.extend(proc.stderr), daemon=True)
    thread.start()
    return proc, err, thread


def read_until(proc, prefix: str, timeout: float = 180) -> None:
    lines, done = [], threading.Event()

    def read():
        for line in proc.stdout:
            lines.append(line)
            if line.startswith(prefix):
                break
        done.set()

    threading.Thread(target=read, daemon=True).start()
    if not done.wait(timeout) or not lines or not lines[-1].startswith(prefix):
        proc.kill()
        pytest.fail(f"no line starting with {prefix!r} within {timeout}s: {''.join(lines)[-2000:]}")


def finish_piped(proc, err, thread, timeout: float, what: str) -> str:
    """Wait for a process of start_piped, bounded; its collected stderr. A hang fails with the stack of every thread of
    the child (the fault handler prints them on SIGABRT)."""
    try:
        proc.wait(timeout)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGABRT)
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            proc.kill()
        thread.join(15)
        pytest.fail(f"{what} {timeout} s after the stop; the child's threads:\n{''.join(err)[-6000:]}")
    thread.join(30)
    return "".join(err)


@pytest.mark.parametrize(("cmd", "phase"), [(MAZE_TAMER, "tamer"), ([PUSHER, *PUSHER_TINY], "tamer")],
                         ids=["maze", "pusher"])  # fmt: skip
def test_the_reader_of_stdout_dies(tmp_path, cmd, phase):
    """`python ... | head`: the reader goes away mid-run; the run saves what finished and ends with 141 (SIGPIPE)."""
    proc, err, thread = start_piped([sys.executable, *cmd], tmp_path, preexec_fn=default_signals)
    read_until(proc, f"[{phase}]")
    proc.stdout.close()  # the only reader: the script's next line hits a broken pipe
    stderr = finish_piped(proc, err, thread, 180, "still running")
    assert proc.returncode == 141, (proc.returncode, stderr)
    assert_clean(stderr)
    assert_stopped(tmp_path, "SIGPIPE", {phase})


def test_ctrl_c_behind_a_pipe_to_tee(tmp_path):
    """`python ... | tee log` and Ctrl-C: the terminal sends SIGINT to both; tee dies at once, so the script's last
    lines meet a broken pipe. The summary is saved all the same, the exit code is 130 and nothing crashes."""
    log = open(tmp_path / "log.txt", "w")
    proc = subprocess.Popen([sys.executable, *MAZE_TAMER], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, process_group=0,
                            preexec_fn=default_signals)  # fmt: skip
    tee = subprocess.Popen(["tee"], stdin=proc.stdout, stdout=log, process_group=proc.pid,
                           preexec_fn=default_signals)  # the pipeline's process group, as a shell makes it  # fmt: skip
    proc.stdout.close()  # tee is the only reader
    deadline = time.monotonic() + 180
    while "[tamer]" not in (tmp_path / "log.txt").read_text():
        if time.monotonic() > deadline or proc.poll() is not None:
            proc.kill()
            tee.kill()
            pytest.fail(f"no [tamer] line in the log: {(tmp_path / 'log.txt').read_text()[-2000:]}")
        time.sleep(0.1)
    os.killpg(proc.pid, signal.SIGINT)  # what the terminal does on Ctrl-C: the whole foreground group
    try:
        _, stderr = proc.communicate(timeout=120)
        tee.wait(30)
    except subprocess.TimeoutExpired:
        proc.kill()
        tee.kill()
        pytest.fail("still running 120 s after Ctrl-C")
    assert proc.returncode == 130 and tee.returncode != 0, (proc.returncode, tee.returncode, stderr)
    assert_clean(stderr)
    assert_stopped(tmp_path, "SIGINT", {"tamer"})


def test_ctrl_c_while_a_person_is_asked(tmp_path):
    """--teacher human waits for an answer: Ctrl-C there saves the run (status interrupted, phase tamer)."""
    proc, err, thread = start_piped([sys.executable, MAZE, "--teacher", "human"], tmp_path, stdin=subprocess.PIPE,
                                    preexec_fn=default_signals)  # fmt: skip
    proc.stdin.write("y\n")
    proc.stdin.flush()
    read_until(proc, "good move?")  # the prompt ends without a newline: wait for the second one
    read_until(proc, "the agent moves")
    proc.send_signal(signal.SIGINT)
    stderr = finish_piped(proc, err, thread, 120, "still waiting for an answer")
    assert proc.returncode == 130, (proc.returncode, stderr)
    assert_clean(stderr)
    assert_stopped(tmp_path, "SIGINT", {"tamer"})


@pytest.mark.parametrize("module", ["inform_dqn_gridworld", "inform_sac_pusher", "q_learning_recovered_reward"])
def test_a_stop_signal_is_only_recorded_and_the_next_loop_head_raises(module, tmp_path):
    """The ~120 s hang after a stop came from a KeyboardInterrupt raised inside the writer's queue put (issue 20: in
    queue.Queue.put after the item is queued and before `not_empty.notify()`, which leaves the writer's thread asleep
    until its next flush, and close() waits for it). The handler now only records the signal: a signal during a writer
    call lets the call finish, the next StopSignals.check() (at a loop's head) raises once, and close() is quick."""
    import importlib

    from torch.utils.tensorboard import SummaryWriter

    script = importlib.import_module(module)
    handlers = {sig: signal.getsignal(sig) for sig in SIGNALS}
    try:
        signal.signal(signal.SIGHUP, signal.SIG_DFL)  # under nohup SIGHUP is ignored, and a run leaves it so
        stop = script.StopSignals()
        writer = SummaryWriter(str(tmp_path))
        calls = []
        real = writer.add_scalar

        def add_scalar_hit_by_a_signal(*args, **kwargs):
            os.kill(os.getpid(), signal.SIGHUP)  # delivered here, inside the call
            time.sleep(0.05)  # Python runs the handler at the next bytecode: still inside
            calls.append("returned")
            return real(*args, **kwargs)

        writer.add_scalar = add_scalar_hit_by_a_signal
        writer.add_scalar("x", 1.0, 1)  # no exception inside the library call
        assert calls == ["returned"] and stop.received == ["SIGHUP"]
        with pytest.raises(KeyboardInterrupt):
            script.StopSignals.check()
        script.StopSignals.check()  # once: main is saving what finished
        stop.finished = True
        started = time.monotonic()
        writer.close()
        assert time.monotonic() - started < 5.0
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
        script.StopSignals.current = None


@pytest.mark.parametrize("script", ["pusher", "maze"])
def test_an_error_after_the_run_directory_exists_still_leaves_a_summary(tmp_path, monkeypatch, script):
    """A bug in the final evaluation: summary.json says failed with the error's line, then the error goes on up (a bug
    deserves its traceback). In-process, with a piece of the final evaluation (the Pusher's final_evaluation, the
    maze's reward table) replaced by one that raises."""
    sys.path.insert(0, REPO)
    import inform_dqn_gridworld as maze
    import inform_sac_pusher as pusher

    module = {"pusher": pusher, "maze": maze}[script]

    def broken(*args, **kwargs):
        raise RuntimeError("a bug in the final evaluation\nsecond line")

    monkeypatch.setattr(module, {"pusher": "final_evaluation", "maze": "reward_table"}[script], broken)
    monkeypatch.chdir(tmp_path)
    handlers = {sig: signal.getsignal(sig) for sig in SIGNALS}
    try:
        if script == "pusher":
            flags = dict(zip(PUSHER_TINY[::2], PUSHER_TINY[1::2], strict=True))
            args = pusher.Args(**{k[2:].replace("-", "_"): int(v) for k, v in flags.items()})
            with pytest.raises(RuntimeError, match="a bug in the final evaluation"):
                pusher.main(
                    args,
                    pusher.load_oracle(
                        args.env_id, args.contact, args.oracle_path, args.train_oracle, args.oracle_total_timesteps
                    ),
                    pusher.StopSignals(),
                )
        else:
            args = maze.Args(tamer_total_timesteps=2000, tamer_learning_starts=500, sleep_gradient_steps=200)
            args = args.fill_teacher_defaults()
            with pytest.raises(RuntimeError, match="a bug in the final evaluation"):
                maze.main(args, None, maze.StopSignals())
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
    summary = summary_of(tmp_path)
    assert summary["status"] == "failed" and summary["phase"] == "eval"
    assert summary["error"] == "RuntimeError: a bug in the final evaluation"
    assert summary["feedback/steps"] > 0  # what finished before the error is in it
