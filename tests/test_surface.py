"""inform_utils/ uses only the names declared here for each script (DECLARED): a script stays free to change everything
else, and each declared name exists."""

import ast
import glob
import os

from conftest import REPO

SCRIPTS = {"inform_sac_pusher", "inform_dqn_gridworld", "oracle_train"}


# the only names of each script that inform_utils/ may use: a script stays free to change everything else
DECLARED = {
    "inform_sac_pusher": {
        "Args", "main", "cli", "check_args", "make_env", "Outcome", "In", "InputError", "StopSignals",  # running it
        "QEnsemble", "Actor", "HIDDEN_SIZE", "Teacher", "oracle_q", "oracle_feedback", "linear_schedule",  # the parts
        "tamer_loss", "update_actor", "iq_loss", "soft_value", "recover_reward", "soft_update", "SLEEP_GAMMA",
        "RecoveredReward",  # inform_utils/recovered_reward.py loads it from a run
        "DAY",  # the mark of a day's flag (the page's Args redefine some)
        "TAMER_POLICY_LR",
        "Night",  # the night, which the study subclasses
        "Day", "ReplayBuffer", "DAY_TENSORS",  # the day, which the page subclasses (--no-driven-in-h)
        "Evaluator", "evaluate", "obstacle_test", "obstacle_skipped", "object_xy", "check_video", "video_env",
        "mujoco_major", "read_checkpoint", "check_crc", "oracle_from_checkpoint", "actor_from_checkpoint",
        "PUSHER_IDS",  # teacher_check reports the push's pace, the page shows the arm: Pusher only
        "CONTACTS", "contact_of", "made_under", "contact_as_mujoco23",  # Pusher's contact; contact_check applies it
        "load_oracle",  # the scripted person judges with the teacher the runs load
        "load_day",  # clonable reads a saved day as --sleep-from does, checked
    },
    "inform_dqn_gridworld": {
        "Args", "Sleep", "cli", "main", "check_args", "Evaluator", "StopSignals", "Teacher", "ReplayBuffer",
        "tamer_loss", "iq_loss", "greedy_actions", "QNetwork", "read_checkpoint", "InputError",
    },
    "oracle_train": {"EXPERT_SUCCESS_RATE", "EXPERT_FINAL_DISTANCE"},  # the bar (teachers load through the pusher)
}  # fmt: skip


def used(path: str) -> dict[str, set[str]]:
    """{script: names} that one helper takes from the scripts: `from script import x` and `alias.x`."""
    tree = ast.parse(open(path).read())
    aliases = {}
    names = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name in SCRIPTS:
                    aliases[alias.asname or alias.name] = alias.name
        elif isinstance(node, ast.ImportFrom) and node.module in SCRIPTS:
            names.setdefault(node.module, set()).update(alias.name for alias in node.names)
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases:
            names.setdefault(aliases[node.value.id], set()).add(node.attr)
    return names


def test_inform_utils_uses_only_the_declared_names():
    seen = set()
    for path in sorted(glob.glob(os.path.join(REPO, "inform_utils", "*.py"))):
        for script, names in used(path).items():
            seen.add(script)
            extra = names - DECLARED[script]
            assert not extra, f"{os.path.basename(path)} uses {sorted(extra)} of {script}.py, not in DECLARED"
    assert seen == {s for s in SCRIPTS if DECLARED[s]}  # it saw every script's imports (a rename would not slip by)


def test_every_declared_name_is_defined_at_the_top_level_of_its_script():
    for script, names in DECLARED.items():
        tree = ast.parse(open(os.path.join(REPO, script + ".py")).read())
        defined = {node.name for node in tree.body if isinstance(node, (ast.FunctionDef, ast.ClassDef))}
        defined |= {t.id for node in tree.body if isinstance(node, ast.Assign) for t in node.targets
                    if isinstance(t, ast.Name)}  # fmt: skip
        assert names <= defined, f"{script}.py no longer defines {sorted(names - defined)}"
