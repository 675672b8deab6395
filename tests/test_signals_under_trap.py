"""The suite's SIGINT cases must not depend on how the suite is started: a background job of a non-interactive
shell ignores SIGINT, and its children inherit that unless a test restores the default."""

import os
import subprocess
import sys

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SIGINT_CASES = [
    "tests/test_pusher.py::test_signal_ends_the_run_cleanly[tamer-SIGINT]",
    "tests/test_pusher.py::test_oracle_train_signal_keeps_the_last_training_state[SIGINT]",
    "tests/test_inform_gridworld.py::test_signal_ends_the_run_cleanly[2-sleep-130]",
    "tests/test_q_learning_recovered_reward.py::test_a_real_signal_keeps_what_finished[2-130]",
    "tests/test_run_seeds.py::test_a_signal_stops_the_runs_which_save_and_are_rerun_on_resume[2]",
]


def test_sigint_cases_pass_when_pytest_runs_with_sigint_ignored():
    shell = 'trap "" INT; exec "$0" -m pytest -q -p no:cacheprovider "$@"'
    proc = subprocess.run(["bash", "-c", shell, sys.executable, *SIGINT_CASES], cwd=REPO, capture_output=True,
                          text=True, timeout=900)  # fmt: skip
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]
    assert f"{len(SIGINT_CASES)} passed" in proc.stdout, proc.stdout[-3000:]
