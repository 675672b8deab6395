"""The two INFORM scripts are siblings: single files that repeat their common code (CleanRL's choice), held the same
here, with the same flag for the same concept and the same reading order."""

import ast
import dataclasses
import inspect
import os

import pytest

import inform_dqn_gridworld as maze
import inform_sac_pusher as pusher

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED = (
    "stopped_while_starting",
    "linear_schedule",
    "soft_update",
    "Teacher",
    "Progress",
    "InputError",
    "Diverged",
    "StopSignals",
    "say",
    "make_run_dir",
    "write_json_atomic",
    "save_atomic",
    "end_run",
)
# the same concept, the same flag (each script has more of its own)
SHARED_FLAGS = (
    "exp_name",
    "seed",
    "torch_deterministic",
    "cuda",
    "num_threads",
    "capture_video",
    "save_model",
    "track",
    "wandb_project_name",
    "wandb_entity",
    "env_id",
    "oracle_path",
    "tamer_total_timesteps",
    "tamer_learning_starts",
    "tamer_batch_size",
    "tamer_h_lr",
    "feedback_alpha_start",
    "feedback_alpha_end",
    "teacher_noise",
    "teacher_sparsity",
    "teacher_delay",
    "credit_window",
    "feedback_budget",
    "budget_ends_forward_phase",
    "sleep_gradient_steps",
    "sleep_batch_size",
    "sleep_q_lr",
    "sleep_gamma",
    "sleep_temperature",
    "sleep_chi2_coef",
    "sleep_seed",
    "save_buffer",
    "sleep_from",
    "tau",
    "eval_frequency",
    "sleep_eval_frequency",
    "log_frequency",
    "evaluate",
)
# the reading order: these top-level definitions come in this order, and main comes before everything else
READING_ORDER = (
    "Args",
    "linear_schedule",
    "oracle_feedback",
    "Teacher",
    "tamer_loss",
    "soft_value",
    "iq_loss",
    "recover_reward",
    "ReplayBuffer",
    "forward_phase",
    "sleep_phase",
    "main",
)


def test_the_common_code_is_the_same_in_both_scripts():
    for name in SHARED:
        assert inspect.getsource(getattr(pusher, name)) == inspect.getsource(getattr(maze, name)), name


def test_the_same_concept_has_the_same_flag():
    for script in (pusher, maze):
        names = {f.name for f in dataclasses.fields(script.Args)}
        assert set(SHARED_FLAGS) <= names, (script.__name__, set(SHARED_FLAGS) - names)
    assert "sleep_tau" not in {f.name for f in dataclasses.fields(maze.Args)}  # the old names are gone


def test_both_scripts_read_top_to_bottom_in_one_order():
    for script in ("inform_sac_pusher.py", "inform_dqn_gridworld.py"):
        tree = ast.parse(open(os.path.join(REPO, script)).read())
        names = [getattr(node, "name", None) for node in tree.body]
        lines = [names.index(name) for name in READING_ORDER]
        assert lines == sorted(lines), (script, [READING_ORDER[i] for i in range(len(lines))])
        defined_after_main = [n for n in names[names.index("main") + 1 :] if n]
        assert "forward_phase" not in defined_after_main and "Evaluator" in defined_after_main, script
        assert "check_args" in defined_after_main and "StopSignals" in defined_after_main, script


def test_the_sleep_batch_is_replay_rows_then_expert_rows_in_both():
    for script in (pusher, maze):
        source = inspect.getsource(script.sleep_phase)
        assert "torch.cat([replay, expert])" in source, script.__name__
        assert "is_expert = torch.arange(2 * batch_size, device=device) >= batch_size" in source, script.__name__


def test_linear_schedule_by_hand():
    assert pusher.linear_schedule(1.0, 0.05, 10, 0) == 1.0
    assert pusher.linear_schedule(1.0, 0.05, 10, 5) == 1.0 + (0.05 - 1.0) * 5 / 10
    assert pusher.linear_schedule(1.0, 0.05, 10, 10) == pytest.approx(0.05, abs=1e-15)
    assert pusher.linear_schedule(1.0, 0.05, 10, 25) == pusher.linear_schedule(1.0, 0.05, 10, 10)  # then constant
    assert pusher.linear_schedule(0.3, 0.7, 0, 0) == 0.3  # a zero duration does not divide by zero
    # the teacher's alpha over a Pusher forward phase, bit for bit the formula the paper-budget runs used
    n = 200_000
    for step in (0, 1, 12_345, n - 1):
        assert pusher.linear_schedule(0.99, 0.992, n - 1, step) == 0.99 + (0.992 - 0.99) * step / max(n - 1, 1)


def test_the_siblings_are_called_alike():
    params = {script: list(inspect.signature(script.main).parameters) for script in (pusher, maze)}
    assert params[pusher][0::2] == params[maze][0::2] == ["args", "stop"]  # main(args, oracle, stop, day)
    assert params[pusher][1].startswith("oracle") and params[maze][1].startswith("oracle")
    assert params[pusher][3] == params[maze][3] == "day"
    for script in (pusher, maze):
        assert list(inspect.signature(script.Evaluator).parameters) == ["args", "writer"], script.__name__
        assert list(inspect.signature(script.evaluate).parameters)[1] == "env", script.__name__  # (policy, env, ...)
        assert list(inspect.signature(script.evaluate_saved).parameters) == ["args"], script.__name__
        assert list(inspect.signature(script.read_checkpoint).parameters) == ["path", "flag", "env_id"], script.__name__
