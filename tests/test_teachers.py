"""The teacher model of docs/protocol.md (noise, sparsity, delay, credit window, budget) on hand-made sequences, and
the maze script's teacher flags and live-human mode end to end (through a pipe and through a pseudo-terminal)."""

import glob
import json
import math
import os
import re
import select
import subprocess
import sys
import time

import numpy as np
import pytest
import torch
from conftest import default_signals

import inform_dqn_gridworld as inform

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPT = "inform_dqn_gridworld.py"
TINY = ["--tamer-total-timesteps", "1000", "--tamer-learning-starts", "200", "--sleep-gradient-steps", "100"]


def feed(teacher, answers):
    """Hand the teacher one perfect answer per step; the list of buffer indices labelled +1 at each step."""
    labels = [teacher(step, float(h)) for step, h in enumerate(answers)]
    assert all(h == 1.0 for step_labels in labels for h in step_labels.values())  # the simulated teacher gives +1
    return [list(step_labels) for step_labels in labels]


def within_5_sigma(count, n, p):
    """A binomial(n, p) count lies within 5 standard deviations of its mean (fails with probability < 1e-6)."""
    return abs(count - n * p) <= 5 * math.sqrt(n * p * (1 - p))


# the teacher on hand-made sequences --------------------------------------------------------------------------------
ANSWERS = [1, 0, 0, 1, 1, 0, 1, 0, 0, 0, 1, 0]


def test_the_defaults_are_the_perfect_teacher():
    teacher = inform.Teacher(seed=3)
    assert feed(teacher, ANSWERS) == [[t] if h else [] for t, h in enumerate(ANSWERS)]
    assert teacher.positives == teacher.perfect_positives == sum(ANSWERS) and not teacher.gone


@pytest.mark.parametrize("delay", [1, 2, 3])
def test_delay_moves_each_signal_d_steps_later(delay):
    labelled = feed(inform.Teacher(delay=delay), ANSWERS)
    expected = [[t] if t >= delay and ANSWERS[t - delay] else [] for t in range(len(ANSWERS))]
    assert labelled == expected
    # the signals about the last `delay` steps are still on their way when the sequence ends: lost
    assert sum(map(len, labelled)) == sum(ANSWERS[: len(ANSWERS) - delay])


@pytest.mark.parametrize(
    "delay, window, expected",
    [
        (0, 1, {0: [0], 3: [3], 4: [4], 6: [6], 10: [10]}),
        (0, 3, {0: [0], 3: [1, 2, 3], 4: [2, 3, 4], 6: [4, 5, 6], 10: [8, 9, 10]}),  # clipped at the first index
        (2, 3, {2: [0, 1, 2], 5: [3, 4, 5], 6: [4, 5, 6], 8: [6, 7, 8]}),  # window d + 1 covers the step judged
        (1, 1, {1: [1], 4: [4], 5: [5], 7: [7], 11: [11]}),  # window 1: only the later transition, not the judged one
    ],
)
def test_credit_window_labels_the_most_recent_transitions(delay, window, expected):
    labelled = feed(inform.Teacher(delay=delay, credit_window=window), ANSWERS)
    assert {t: idx for t, idx in enumerate(labelled) if idx} == expected
    for t, h in enumerate(ANSWERS):  # a window of delay + 1 always includes the transition the signal was about
        if h and t + delay < len(ANSWERS) and window == delay + 1:
            assert t in labelled[t + delay]


@pytest.mark.parametrize("budget", [0, 1, 7, 40])
def test_budget_stops_at_exactly_n_positives(budget):
    teacher = inform.Teacher(budget=budget, delay=1)
    labelled = feed(teacher, [1] * 100)
    delivered = [t for t, idx in enumerate(labelled) if idx]
    assert len(delivered) == teacher.positives == budget
    assert delivered == list(range(1, budget + 1))  # the first N, then nothing: the teacher has left
    assert teacher.gone and teacher.perfect_positives == 100


def test_no_budget_never_leaves():
    teacher = inform.Teacher(budget=None)
    feed(teacher, [1] * 500)
    assert teacher.positives == 500 and not teacher.gone


@pytest.mark.parametrize("noise", [0.1, 0.2, 0.3])
def test_noise_flips_about_p_of_the_signals(noise):
    n = 4000
    teacher = inform.Teacher(noise=noise, seed=11)
    kept = sum(bool(idx) for idx in feed(teacher, [1] * n))  # a flipped +1 is no feedback
    assert within_5_sigma(n - kept, n, noise), (n - kept, n * noise)
    teacher = inform.Teacher(noise=noise, seed=12)
    made = sum(bool(idx) for idx in feed(teacher, [0] * n))  # a flipped "no" is a +1
    assert within_5_sigma(made, n, noise), (made, n * noise)
    assert teacher.perfect_positives == 0


@pytest.mark.parametrize("sparsity", [0.5, 0.2])
def test_sparsity_keeps_about_q_of_the_positives(sparsity):
    n = 4000
    answers = [1, 0] * (n // 2)
    labelled = feed(inform.Teacher(sparsity=sparsity, seed=5), answers)
    kept = [t for t, idx in enumerate(labelled) if idx]
    assert within_5_sigma(len(kept), n // 2, sparsity), (len(kept), n // 2 * sparsity)
    assert all(answers[t] for t in kept)  # sparsity only drops clicks, it never invents one


def test_the_random_stream_does_not_depend_on_the_answers():
    a, b = inform.Teacher(noise=0.3, sparsity=0.5, seed=9), inform.Teacher(noise=0.3, sparsity=0.5, seed=9)
    feed(a, [1] * 50)
    feed(b, [0] * 50)
    assert a.rng.random() == b.rng.random()
    assert feed(inform.Teacher(noise=0.3, seed=4), ANSWERS * 5) == feed(inform.Teacher(noise=0.3, seed=4), ANSWERS * 5)


def class_source(path, name="Teacher"):
    text = open(path).read()
    start = text.index(f"class {name}:")
    end = re.search(r"\n(def |class |# ALGO|# TRY|@)", text[start + 1 :])
    return text[start : start + 1 + end.start()].rstrip() if end else text[start:].rstrip()


def test_both_inform_scripts_teachers_answer_alike():
    """Each script carries its own Teacher (one may change alone); with the same flags they label the same steps."""
    import inform_sac_pusher as pusher

    for person in ({}, {"noise": 0.3}, {"sparsity": 0.5, "delay": 2, "credit_window": 3}, {"budget": 3}):
        a, b = pusher.Teacher(**person, seed=4), inform.Teacher(**person, seed=4)
        assert feed(a, ANSWERS * 5) == feed(b, ANSWERS * 5), person
        assert (a.positives, a.perfect_positives) == (b.positives, b.perfect_positives), person


# the maze script's teacher flags -------------------------------------------------------------------------------------
def summary_of(cwd, pattern="*"):
    dirs = glob.glob(os.path.join(cwd, "runs", pattern))
    assert len(dirs) == 1, dirs
    return json.load(open(os.path.join(dirs[0], "summary.json"))), dirs[0]


def test_distorted_teacher_flags_are_recorded(run_script):
    flags = ["--teacher-noise", "0.2", "--teacher-sparsity", "0.5", "--teacher-delay", "2", "--credit-window", "3"]
    result = run_script(SCRIPT, "--seed", "4", *TINY, *flags)
    assert result.returncode == 0, result.stderr
    summary, _ = summary_of(run_script.cwd)
    assert summary["args"]["teacher_noise"] == 0.2 and summary["args"]["credit_window"] == 3
    assert summary["args"]["teacher"] == "oracle" and summary["args"]["feedback_budget"] is None
    assert summary["feedback/steps"] == 1000 and 0 < summary["feedback/positive"] < 1000
    assert summary["feedback/positive"] != summary["feedback/perfect_positive"]  # the distortions did something


def test_budget_freezes_h_or_ends_the_forward_phase(run_script):
    """Budget 30: the teacher leaves after exactly 30 +1 signals. Without the flag the agent keeps acting (all steps
    in the buffer) with H frozen; with it the phase ends there. The same seed gives the same frozen H either way."""
    budget = ["--seed", "2", *TINY, "--feedback-budget", "30"]
    assert run_script(SCRIPT, *budget, "--exp-name", "goes_on").returncode == 0
    result = run_script(SCRIPT, *budget, "--budget-ends-forward-phase", "--exp-name", "ends")
    assert result.returncode == 0, result.stderr
    goes_on, goes_on_dir = summary_of(run_script.cwd, "*goes_on*")
    ends, ends_dir = summary_of(run_script.cwd, "*__ends__*")
    assert goes_on["feedback/positive"] == ends["feedback/positive"] == 30
    assert goes_on["feedback/steps"] == 1000 and goes_on["sleep/replay_transitions"] == 1000
    assert 30 <= ends["feedback/steps"] < 1000 and ends["sleep/replay_transitions"] == ends["feedback/steps"]
    h = [torch.load(os.path.join(d, "tamer_h.pt"), weights_only=True)["state_dict"] for d in (goes_on_dir, ends_dir)]
    assert all(torch.equal(h[0][k], h[1][k]) for k in h[0])  # nothing learnt after the teacher left
    assert goes_on["eval/tamer_episode_length"] == ends["eval/tamer_episode_length"]


@pytest.mark.parametrize(
    "flags, message",
    [
        (["--teacher-noise", "1.5"], "--teacher-noise"),
        (["--credit-window", "0"], "--credit-window"),
        (["--feedback-budget", "-1"], "--feedback-budget"),
        (["--teacher", "human", "--teacher-noise", "0.1"], "--teacher human"),
    ],
)
def test_bad_teacher_values_are_one_line(run_script, flags, message):
    result = run_script(SCRIPT, *flags)
    assert result.returncode == 2, (result.returncode, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and message in lines[0], result.stderr
    assert not os.path.exists(os.path.join(run_script.cwd, "runs"))


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"teacher_noise": float("nan")}, "--teacher-noise"),
        ({"teacher_sparsity": -0.1}, "--teacher-sparsity"),
        ({"teacher_delay": -2}, "--teacher-delay"),
        ({"teacher": "human", "teacher_delay": 1, "credit_window": 2}, "drop --teacher-delay, --credit-window"),
    ],
)
def test_bad_teacher_values_are_refused_before_the_run(changes, message):
    with pytest.raises(inform.InputError, match=re.escape(message)):
        inform.check_args(inform.Args(**changes))


def test_human_teacher_may_have_a_budget():
    args = inform.Args(teacher="human", feedback_budget=10, budget_ends_forward_phase=True)
    inform.check_args(args)  # accepted, with the human defaults filled in and the budget kept
    assert (args.feedback_budget, args.tamer_learning_starts, args.start_e, args.end_e) == (10, 1, 0.0, 0.0)


def test_all_starts_success_by_hand():
    evaluator = inform.Evaluator("KnoxStoneMaze-v0", 30, 20, 1, None)
    q_star = inform.gridworld_env.optimal_q("plain")
    assert evaluator("oracle", q_star.argmax(1), 0)["eval/all_starts/oracle_success_rate"] == 1.0
    # always "up": only the cells of column 5 below G get there (10, 13, 18, 23, 29)
    metrics = evaluator("up", np.zeros(30, dtype=int), 0)
    assert metrics["eval/all_starts/up_success_rate"] == pytest.approx(5 / 29)
    evaluator.close()


# a live human: through a pipe and through a pseudo-terminal ----------------------------------------------------------
# The start-set maze with seed 12 and random moves only (--start-e 1 --end-e 1; the human mode's default is none):
# all-"y" answers then go with a random walk that reaches G in time within 50 steps (at step 8; on the plain maze a
# random walk from S needs far longer), so the sleep has expert data and really runs.
HUMAN = ["--teacher", "human", "--env-id", "KnoxStoneMazeStartSet-v0", "--seed", "12", "--start-e", "1", "--end-e", "1",
         "--tamer-total-timesteps", "1000", "--tamer-learning-starts", "32",
         "--sleep-gradient-steps", "50"]  # fmt: skip


def run_with_input(cwd, flags, text, timeout=240):
    return subprocess.run([sys.executable, os.path.join(REPO, SCRIPT), *flags], cwd=cwd, input=text,
                          capture_output=True, text=True, timeout=timeout)  # fmt: skip


def test_human_through_a_pipe(tmp_path):
    result = run_with_input(tmp_path, HUMAN, "y\n" * 50 + "q\n")
    assert result.returncode == 0, result.stderr[-3000:]
    summary, _ = summary_of(tmp_path)
    assert summary["status"] == "completed" and summary["feedback/positive"] == 50
    assert summary["feedback/steps"] == 50 and summary["args"]["teacher"] == "human"
    assert summary["sleep/expert_transitions"] > 0 and "losses/iq_loss" in summary  # the sleep ran to its end
    out = result.stdout
    assert out.count("good move? [y / Enter / q]") == 51 and "answers 49 | positives given 49" in out
    assert "+---+---+---+---+---+---+" in out and re.search(r"A[\^v<>]", out)  # the maze, the agent and its move
    assert "INFORM (after the sleep), greedy from S:" in out and "thank you: 50 steps taught, 50 positives" in out


def test_human_end_of_input_is_q_and_enter_is_no_feedback(tmp_path):
    result = run_with_input(tmp_path, HUMAN, "y\n\nmaybe\ny\n\n")  # "maybe" is asked again, not counted
    assert result.returncode == 0, result.stderr[-3000:]
    summary, _ = summary_of(tmp_path)
    assert summary["feedback/positive"] == 2 and summary["feedback/steps"] == 4
    assert "'maybe'? type y" in result.stdout


def test_human_through_a_pseudo_terminal(tmp_path):
    import pty

    master, slave = pty.openpty()
    proc = subprocess.Popen([sys.executable, os.path.join(REPO, SCRIPT), *HUMAN], cwd=tmp_path, stdin=slave,
                            stdout=slave, stderr=subprocess.PIPE, close_fds=True,
                            preexec_fn=default_signals)  # fmt: skip
    os.close(slave)
    seen = b""

    def read_until(marker: bytes, timeout: float = 120) -> None:
        nonlocal seen
        deadline = time.monotonic() + timeout
        while marker not in seen:
            ready, _, _ = select.select([master], [], [], max(deadline - time.monotonic(), 0))
            chunk = b""
            if ready:
                try:
                    chunk = os.read(master, 4096)
                except OSError:  # the child closed the terminal
                    pass
            if not chunk:
                proc.kill()
                proc.wait(10)
                pytest.fail(f"no {marker!r} within {timeout}s; terminal:\n{seen.decode()[-3000:]}\n"
                            f"stderr:\n{proc.stderr.read().decode()[-3000:]}")  # fmt: skip
            seen += chunk

    prompt = b"[y / Enter / q] "
    try:
        for answer in (b"y\n", b"y\n", b"\n", b"y\n", b"q\n"):
            read_until(prompt)
            seen = seen.replace(prompt, b"", 1)  # count each prompt once
            os.write(master, answer)
        read_until(b"summary: ")
        try:
            proc.wait(60)
        except subprocess.TimeoutExpired:
            proc.kill()
            pytest.fail(f"did not exit; terminal:\n{seen.decode()[-3000:]}")
    finally:
        os.close(master)
    assert proc.returncode == 0, proc.stderr.read().decode()
    summary, _ = summary_of(tmp_path)
    assert summary["feedback/positive"] == 3 and summary["feedback/steps"] == 4
    assert b"(Enter)" not in seen  # a terminal echoes what the person types: the script does not


# the study's tables -------------------------------------------------------------------------------------------------
def fake_run(runs_dir, name, seed, **metrics):
    run_dir = runs_dir / f"KnoxStoneMaze-v0__{name}__{seed}__0"
    run_dir.mkdir(parents=True)
    summary = {"status": "completed", "script": SCRIPT, "seed": seed, "args": {"exp_name": name},
               "eval/tamer_episode_length": 19.0, "eval/inform_episode_length": 19.0, "feedback/positive": 100,
               "eval/all_starts/tamer_success_rate": 0.5, "eval/all_starts/inform_success_rate": 0.5,
               "sleep/expert_transitions": 10, **metrics}  # fmt: skip
    (run_dir / "summary.json").write_text(json.dumps(summary))


def test_teacher_study_tables(tmp_path):
    from inform_utils import teacher_study

    fake_run(tmp_path, "base", 1, **{"feedback/positive_to_tamer_optimum": 400, "feedback/step_to_tamer_optimum": 1500})
    fake_run(tmp_path, "base", 2, **{"feedback/positive_to_tamer_optimum": None, "feedback/step_to_tamer_optimum": None,
                                     "eval/all_starts/inform_success_rate": 0.25})  # fmt: skip
    fake_run(tmp_path, "sleep_after_250", 1, **{"feedback/positive": 60, "eval/inform_episode_length": 200.0})
    fake_run(tmp_path, "sleep_after_500", 1, **{"feedback/positive": 120})
    fake_run(tmp_path, "sleep_after_1000", 1, **{"feedback/positive": 240})
    fake_run(tmp_path, "sleep_after_500", 2, **{"feedback/positive": 130})
    runs = teacher_study.load_runs(str(tmp_path), "KnoxStoneMaze-v0")
    table, ratios = teacher_study.efficiency_table(runs)
    assert "| TAMER alone: +1 signals (env step) at its first 19 | 400 (1500) | never | 1/2 |" in table
    assert "| 1 | 400 | 500 | 120 | 0.30 |" in ratios  # the smallest k whose sleep reached 19, not a later one
    assert "| 2 | None | 500 | - | - |" in ratios
    assert "| perfect teacher | 2 | 100 |" in teacher_study.robustness_table(runs)
    assert "| 1/2 |" in teacher_study.robustness_table(runs)  # INFORM >= TAMER on seed 1 only


def test_a_person_who_stops_too_early_gets_an_honest_skip(tmp_path):
    """Five answers on the plain maze, then q: no walk reached G in time, so no sleep, no INFORM policy, no INFORM
    files, and advice a person can follow (not a flag to raise)."""
    result = run_with_input(tmp_path, ["--teacher", "human", "--seed", "1"], "y\n" * 5 + "q\n")
    assert result.returncode == 0, result.stderr[-3000:]
    summary, run_dir = summary_of(tmp_path)
    assert summary["status"] == "completed" and summary["sleep_skipped"] is True
    assert summary["sleep/expert_transitions"] == 0 and not any(k.startswith("eval/inform") for k in summary)
    assert not os.path.exists(os.path.join(run_dir, "inform_q.pt"))
    assert not os.path.exists(os.path.join(run_dir, "recovered_reward.pt"))
    assert os.path.exists(os.path.join(run_dir, "tamer_h.pt"))
    assert "INFORM (after the sleep)" not in result.stdout and "TAMER (what you taught)" in result.stdout
    assert "keep teaching until the agent has walked from S to G" in result.stderr
    assert "--tamer-total-timesteps" not in result.stderr


@pytest.mark.slow
def test_a_scripted_person_teaches_the_maze_in_few_answers(tmp_path):
    """The human mode's promise, measured as in the README: a person answering as Q* would (y for the best move,
    Enter otherwise), through a pseudo-terminal, until TAMER's greedy path from S reaches G (seed 1). The taught day
    is kept (--keep-dir, --flags --save-buffer) to sleep on again."""
    from inform_utils import scripted_person

    args = scripted_person.Args(seeds=[1], max_answers=300, keep_dir=str(tmp_path), flags=["--save-buffer"])
    (result,) = scripted_person.main(args)
    assert len(glob.glob(str(tmp_path / "seed1" / "runs" / "*" / "day.pt"))) == 1
    with pytest.raises(SystemExit, match="not empty"):  # a kept run is never overwritten
        scripted_person.main(args)
    assert result["exit"] == 0 and result["status"] == "completed"
    assert result["feedback/answers_to_tamer_goal"] is not None and result["feedback/answers_to_tamer_goal"] <= 150
    assert result["eval/tamer_episode_length"] < 200  # TAMER's greedy policy reaches G from S
    assert result["sleep_skipped"] is False  # the person went on until one walk reached G in time: the agent slept


# the maze's delay table, explained (inform_utils/delay_trace.py traces a real run) --------------------------------
@pytest.mark.parametrize(
    "delay, window, landed_on",
    [(0, 1, {"left"}), (1, 1, {"right"}), (2, 1, {"left"}), (3, 1, {"right"}), (2, 3, {"left", "right"})],
)
def test_a_late_signal_in_a_two_cycle_lands_on_the_reverse_move_when_the_delay_is_odd(delay, window, landed_on):
    """The agent goes S -> 3 -> S -> 3 ...: left from S is the best move (+1), right from 3 back to S is not. A +1
    arriving d steps late lands on the same move of the cycle when d is even and on the reverse move when d is odd,
    and a window reaching back over the step after the judged one (d = 2, k = 3) labels the reverse move too. This is
    what the traced runs show: odd delays teach H to turn back, and its greedy path loops."""
    q_star = inform.gridworld_env.optimal_q("plain")
    moves = [(4, 2), (3, 3)] * 8  # (cell, action): S left, then 3 right, again and again
    teacher, landed = inform.Teacher(delay=delay, credit_window=window), set()
    for step, (cell, action) in enumerate(moves):
        h = float(inform.oracle_feedback(q_star[cell, action], q_star[cell].max(), 0.999))
        assert h == (action == 2)  # Eq. 4: only "left" from S is good
        landed |= {"left" if moves[i][1] == 2 else "right" for i in teacher(step, h)}
    assert landed == landed_on


@pytest.mark.slow
def test_the_traced_delayed_run_turns_back():
    """On a real run (seed 1, the maze's defaults) with --teacher-delay 1 most +1 signals label the reverse of the
    move they were about, and TAMER's greedy path never reaches G; with a delay of 2 few do."""
    from inform_utils import delay_trace

    odd = delay_trace.label_stats(*delay_trace.traced_run(1, 1, seed=1, total=10000)[:5])
    even = delay_trace.label_stats(*delay_trace.traced_run(2, 1, seed=1, total=10000)[:5])
    assert odd["on_reverse"] > 0.5 and odd["on_good"] < 0.5, odd
    assert even["on_reverse"] < 0.2 and even["on_good"] > 0.5, even


def test_the_human_teacher_reads_answers_from_a_stream_with_no_descriptor(monkeypatch, capsys):
    """Standard input replaced by a stream of text (a test's, an app embedding the script): its answers are read in
    order, then its end."""
    import io

    monkeypatch.setattr(sys, "stdin", io.StringIO("y\n\nq\n"))
    teacher = inform.HumanTeacher("plain", 30, inform.QNetwork(30, 4), torch.device("cpu"))
    assert [teacher.read_line() for _ in range(4)] == ["y\n", "\n", "q\n", ""]
