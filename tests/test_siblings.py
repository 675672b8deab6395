"""The two INFORM scripts are siblings: single files (CleanRL's choice) that hold identical only a short block of
plumbing, use the same flag for the same concept, and read top to bottom in one order. Everything else (the teacher
included) may change in one script without breaking the other's tests."""

import ast
import dataclasses
import inspect
import os

import pytest

import inform_dqn_gridworld as maze
import inform_sac_pusher as pusher

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPTS = ("inform_sac_pusher.py", "inform_dqn_gridworld.py")
BEGIN, END = "# --- shared plumbing: the same in inform_dqn_gridworld.py ---", "# --- end of shared plumbing ---"
# the same concept, the same flag (each script has more of its own)
SHARED_FLAGS = (
    "exp_name", "seed", "capture_video", "track", "env_id", "eval_episodes", "cuda", "oracle_path",
    "tamer_total_timesteps", "tamer_learning_starts", "tamer_batch_size", "tamer_h_lr", "feedback_alpha_start",
    "feedback_alpha_end", "teacher_noise", "teacher_sparsity", "teacher_delay", "credit_window", "feedback_budget",
    "budget_ends_forward_phase", "sleep_gradient_steps", "sleep_batch_size", "sleep_q_lr", "sleep_temperature",
    "sleep_chi2_coef", "sleep_seed", "save_buffer", "sleep_from",
)  # fmt: skip
# the reading order: these top-level definitions come in this order, and main before the plumbing
READING_ORDER = ("Args", "make_env", "linear_schedule", "oracle_feedback", "Teacher", "tamer_loss", "soft_value",
                 "iq_loss", "recover_reward", "ReplayBuffer", "Day", "forward_phase", "sleep_phase",
                 "main")  # fmt: skip


def shared_block(script: str) -> list[str]:
    lines = open(os.path.join(REPO, script)).read().splitlines()
    return lines[lines.index(BEGIN) : lines.index(END) + 1]


def test_only_a_short_block_of_plumbing_is_held_identical():
    blocks = [shared_block(script) for script in SCRIPTS]
    assert blocks[0] == blocks[1]
    assert 20 < len(blocks[0]) <= 150, len(blocks[0])


def test_the_same_concept_has_the_same_flag():
    for script in (pusher, maze):
        names = {f.name for f in dataclasses.fields(script.Args)}
        assert set(SHARED_FLAGS) <= names, (script.__name__, set(SHARED_FLAGS) - names)
    assert "sleep_tau" not in {f.name for f in dataclasses.fields(maze.Args)}  # the old names are gone


def test_the_study_switches_are_not_core_flags():
    for script in (pusher, maze):
        names = {f.name for f in dataclasses.fields(script.Args)}
        assert not names & {"sleep_control", "sleep_loss_rows", "sleep_holdout_fraction", "sleep_twin_critics"}


def test_both_scripts_read_top_to_bottom_in_one_order():
    for script in SCRIPTS:
        tree = ast.parse(open(os.path.join(REPO, script)).read())
        names = [getattr(node, "name", None) for node in tree.body]
        lines = [names.index(name) for name in READING_ORDER]
        assert lines == sorted(lines), script
        after_main = [n for n in names[names.index("main") + 1 :] if n]
        assert "forward_phase" not in after_main and "sleep_phase" not in after_main, script
        assert {"check_args", "StopSignals", "end_run"} <= set(after_main), script


def test_the_sleep_batch_is_replay_rows_then_expert_rows_in_both():
    for script in (pusher, maze):
        source = inspect.getsource(script)
        assert "torch.cat([replay, expert])" in source, script.__name__


def test_linear_schedule_by_hand():
    for script in (pusher, maze):
        f = script.linear_schedule
        assert f(1.0, 0.05, 10, 0) == 1.0
        assert f(1.0, 0.05, 10, 5) == 1.0 + (0.05 - 1.0) * 5 / 10
        assert f(1.0, 0.05, 10, 10) == pytest.approx(0.05, abs=1e-15)
        assert f(1.0, 0.05, 10, 25) == f(1.0, 0.05, 10, 10)  # then constant
        assert f(0.3, 0.7, 0, 0) == 0.3  # a zero duration does not divide by zero
    # the teacher's alpha over a Pusher forward phase, bit for bit the formula the paper-budget runs used
    n = 200_000
    for step in (0, 1, 12_345, n - 1):
        assert pusher.linear_schedule(0.99, 0.992, n - 1, step) == 0.99 + (0.992 - 0.99) * step / max(n - 1, 1)


def test_the_siblings_are_called_alike():
    params = {script: list(inspect.signature(script.main).parameters) for script in (pusher, maze)}
    assert params[pusher][:4:2] == params[maze][:4:2] == ["args", "stop"]  # main(args, oracle, stop, saved, ...)
    assert params[pusher][1].startswith("oracle") and params[maze][1].startswith("oracle")
    assert params[pusher][3] == params[maze][3] == "saved"  # a saved day (--sleep-from), or None
    for script in (pusher, maze):  # the day's learner and settings in one object, which the day's phase takes
        assert list(inspect.signature(script.forward_phase).parameters)[0] == "day"
        assert set(script.DAY_ARGS) == set(script.Args().day_settings())
    from inform_utils import browser_pusher, sleep_variants_maze, sleep_variants_pusher

    for module, script in ((browser_pusher, pusher), (sleep_variants_pusher, pusher), (sleep_variants_maze, maze)):
        assert set(script.DAY_ARGS) <= set(module.Args().day_settings()), module  # a flag redefined stays the day's
