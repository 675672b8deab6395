import os
import queue
import signal
import subprocess
import sys
import threading
import time

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)


@pytest.fixture
def run_script(tmp_path):
    """Run one of the repo's scripts in a fresh working directory, so its runs/ lands in tmp_path."""

    def run(script: str, *flags: str, timeout: float = 300) -> subprocess.CompletedProcess:
        cmd, env = [sys.executable, os.path.join(REPO, script)], None
        if script.startswith("inform_utils/"):  # the helpers run as modules: python -m inform_utils.run_seeds
            cmd = [sys.executable, "-m", script.removesuffix(".py").replace("/", ".")]
            env = {**os.environ, "PYTHONPATH": REPO}
        return subprocess.run([*cmd, *flags], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=timeout)

    run.cwd = tmp_path
    return run


def default_signals():
    """In the child: every signal that stops a run at its default, whatever the test runner inherited (trap '' INT;
    nohup; a shell's `&`, which ignores SIGINT and SIGQUIT, so that a suite run in the background sent its children
    a SIGQUIT they ignored)."""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT, signal.SIGXCPU, signal.SIGUSR1,
                signal.SIGUSR2):  # fmt: skip
        signal.signal(sig, signal.SIG_DFL)


class Child:
    """A process whose output is read by threads, so that every wait is bounded; a failure shows its output."""

    def __init__(self, cmd, cwd):
        self.proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     preexec_fn=default_signals)  # fmt: skip
        self.out, self.err, self.lines = [], [], queue.Queue()
        self.threads = [
            threading.Thread(target=self._read, args=(self.proc.stdout, self.out, True), daemon=True),
            threading.Thread(target=self._read, args=(self.proc.stderr, self.err, False), daemon=True),
        ]
        for thread in self.threads:
            thread.start()

    def _read(self, stream, store, to_queue):
        for line in stream:
            store.append(line)
            if to_queue:
                self.lines.put(line)
        if to_queue:
            self.lines.put(None)

    def fail(self, why):
        self.proc.kill()
        self.proc.wait(30)
        for thread in self.threads:
            thread.join(10)
        pytest.fail(f"{why}\n--- stdout ---\n{''.join(self.out)[-3000:]}\n--- stderr ---\n{''.join(self.err)[-3000:]}")

    def wait_for_line(self, prefix, timeout=180):
        deadline = time.monotonic() + timeout
        while True:
            try:
                line = self.lines.get(timeout=max(deadline - time.monotonic(), 0.01))
            except queue.Empty:
                self.fail(f"no line starting with {prefix!r} within {timeout}s")
            if line is None:
                self.fail(f"the process ended (code {self.proc.wait(30)}) before a line starting with {prefix!r}")
            if line.startswith(prefix):
                return line

    def finish(self, timeout=120):
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.fail(f"still running {timeout}s after the signal")
        for thread in self.threads:
            thread.join(30)
        return self.proc.returncode, "".join(self.out), "".join(self.err)


FAKE_SCRIPT = '''
"""Stands in for a training script (tests of run_seeds.py): writes runs/Fake-v0__{exp}__{seed}__{ns}/summary.json
with its flags under "args", as the real scripts do. --fail-seed N: seed N exits 1 with a message on stderr. While
the file "block" exists it waits (at most 600 s), so a test can stop it: SIGTERM/SIGINT are handled as the real
scripts handle them (summary.json status interrupted with the phase and the signal, exit 143 / 130)."""
import json, os, signal, sys, time

def flag(name, default, kind):  # --name value or --name=value, as argparse reads them
    for i, arg in enumerate(sys.argv):
        if arg == name:
            return kind(sys.argv[i + 1])
        if arg.startswith(name + "="):
            return kind(arg.split("=", 1)[1])
    return default

seed, exp = flag("--seed", 1, int), flag("--exp-name", "x", str)
noise, fail_seed = flag("--noise", 0.0, float), flag("--fail-seed", -1, int)
with open("calls.txt", "a") as f:
    f.write(f"{seed} {noise}\\n")
if seed == fail_seed:
    print(f"boom: seed {seed} refuses to run", file=sys.stderr)
    sys.exit(1)
run_dir = f"runs/Fake-v0__{exp}__{seed}__{time.time_ns()}"
os.makedirs(run_dir)
received = []

def stop(signum, frame):
    received.append(signal.Signals(signum).name)
    raise KeyboardInterrupt

signal.signal(signal.SIGTERM, stop)
if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
    signal.signal(signal.SIGINT, stop)
summary = {"status": "completed"}
print("started", flush=True)
try:
    deadline = time.time() + 600
    while os.path.exists("block") and time.time() < deadline:
        time.sleep(0.1)
except KeyboardInterrupt:
    summary = {"status": "interrupted", "phase": "forward", "signal": received[-1] if received else "SIGINT"}
summary.update({"script": os.path.basename(sys.argv[0]), "seed": seed, "eval/x": seed * 2.0 + noise,
                "args": {"seed": seed, "exp_name": exp, "noise": noise, "fail_seed": fail_seed}})
with open(f"{run_dir}/summary.json.tmp", "w") as f:
    json.dump(summary, f)
os.replace(f"{run_dir}/summary.json.tmp", f"{run_dir}/summary.json")
sys.exit({"completed": 0, "interrupted": 143 if received[-1:] == ["SIGTERM"] else 130}[summary["status"]])
'''


# The slow set (`pytest -m slow`): the learning checks, the snapshots (every tiny run's numbers as before a refactor),
# a real browser, Slurm, Weights & Biases, the hacks on copies of the scripts, filming, and signals under a trap; whole
# runs of tens of seconds each, or tests that need what a newcomer's machine lacks. The README's command leaves it out
# (`-m "not slow"`); CI runs both sets, so every test.
SLOW_FILES = {"test_learning.py", "test_snapshot.py", "test_day_hack.py", "test_night_hack.py", "test_slurm.py",
              "test_track.py", "test_capture_video.py", "test_signals_under_trap.py",
              "test_scripted_person_browser.py"}  # fmt: skip
SLOW_FIXTURES = {"browser", "new_page"}  # Playwright driving Chromium
WAIT_S = 20.0  # the bound on every wait for a condition in a browser test (a loaded machine; a pass takes far less)


@pytest.fixture(scope="module")
def browser():
    from inform_utils.scripted_person_browser import browser_missing

    why = browser_missing()
    if why:
        if os.environ.get("INFORM_REQUIRE_BROWSER") == "1":
            pytest.fail(f"INFORM_REQUIRE_BROWSER=1 but {why}")
        pytest.skip(why)
    from playwright.sync_api import sync_playwright

    from inform_utils.scripted_person_browser import CHROMIUM, CHROMIUM_ARGS

    with sync_playwright() as playwright:
        chromium = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield chromium
        chromium.close()


@pytest.fixture
def new_page(browser):
    """Open the page in a browser session of its own; at the end, no script error on any page."""
    errors, contexts = [], []

    def open_page(url: str):
        context = browser.new_context(viewport={"width": 900, "height": 720})
        contexts.append(context)
        page = context.new_page()
        page.on("pageerror", lambda error: errors.append(str(error)))
        page.set_default_timeout(WAIT_S * 1000)
        page.goto(url)
        return page

    yield open_page
    for context in contexts:
        context.close()
    assert not errors, errors


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.path.name in SLOW_FILES or SLOW_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.slow)


@pytest.fixture
def fake_script(tmp_path):
    """fake.py in tmp_path: a training script's contract (summary.json, args, SIGTERM) in a few lines."""
    path = tmp_path / "fake.py"
    path.write_text(FAKE_SCRIPT)
    return path


def pytest_sessionfinish(session, exitstatus):
    """INFORM_NO_SKIPS=1 (CI's marker steps): a step that skipped a test, or ran none, fails, so that a venv that
    cannot run what the step is for (Pusher-v4 without mujoco 2.3.7) never passes empty."""
    if os.environ.get("INFORM_NO_SKIPS") != "1":
        return
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    stats = reporter.stats if reporter else {}
    skipped, passed = len(stats.get("skipped", [])), len(stats.get("passed", []))
    if skipped or not passed:
        reasons = sorted(
            {str(r.longrepr[-1]) if isinstance(r.longrepr, tuple) else "" for r in stats.get("skipped", [])}
        )
        print(f"\nINFORM_NO_SKIPS: {passed} passed, {skipped} skipped {reasons}: this step must run its tests")
        session.exitstatus = 1


@pytest.fixture
def one_thread():
    """One torch thread, as the scripts run: two threads beside a busy machine's other jobs spin and crawl."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
