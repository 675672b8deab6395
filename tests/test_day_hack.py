"""The day is open, as the night is: the hacks a researcher makes to the day (a teacher that answers -1, LayerNorm in
TAMER's H) are made on copies of the core scripts, in the places docs/shape.md names, and work; a teacher's answer
reaches the buffer and H's loss as given (-1, 0.5); a day saved by a hacked copy is either slept on by the original
script and the study, its settings recorded whole in the night's summary.json, or refused in one line naming what
the original does not know. Never a setting dropped without a word (what load_day did before the Day object), never
a traceback for a day with other networks."""

import glob
import json
import os
import shutil
import subprocess
import sys

import pytest
import torch
from conftest import REPO

sys.path.insert(0, REPO)

import inform_dqn_gridworld as maze  # noqa: E402
import inform_sac_pusher as isp  # noqa: E402

TEACHER = ["--oracle-path", os.path.join(REPO, "oracles", "Pusher-v5__sac_oracle.pt")]
PUSHER_DAY = ["--seed", "3", "--tamer-total-timesteps", "600", "--tamer-learning-starts", "200",
              "--tamer-batch-size", "64", "--success-distance", "1.0", *TEACHER]  # fmt: skip
PUSHER_NIGHT = ["--sleep-gradient-steps", "50", "--sleep-batch-size", "64", "--eval-episodes", "1",
                "--obstacle-episodes", "0", "--authors-test-episodes", "0"]  # fmt: skip
MAZE_DAY = ["--seed", "3", "--tamer-total-timesteps", "2000", "--tamer-learning-starts", "500"]
MAZE_NIGHT = ["--sleep-gradient-steps", "100"]


def patch(text: str, old: str, new: str) -> str:
    """One edit of a hack; its anchor must be in the code exactly once (else the recipe is out of date)."""
    assert text.count(old) == 1, f"the hack's anchor is in the script {text.count(old)} times, not once: {old!r}"
    return text.replace(old, new)


# the hacks, each edit in one of the places docs/shape.md counts -------------------------------------------------------
NEGATIVE_FLAG = '''    teacher_negative_beta: Annotated[float | None, {range}, DAY] = None
    """the hack: the teacher answers -1 when Q*(s, a) < Q*(s, a*) - (1 - beta) |Q*(s, a*)| (TAMER's signed feedback)"""
'''


def negative_teacher(code: str, range_: str, returned: str) -> str:
    """A teacher that answers -1 as well as Eq. 4's 1 and 0: the flag (Args), the answer (Day.answer)."""
    anchor = "\n    # The teacher as a person"
    code = patch(code, anchor, "\n" + NEGATIVE_FLAG.format(range=range_).rstrip("\n") + anchor)
    beta = 'self.settings["teacher_negative_beta"]'
    worse = f"q_star_sa < q_star_best - (1 - {beta}) * abs(q_star_best)"
    return patch(code, f"        return {returned}\n", f"        h = {returned}\n"
                 f"        return -1.0 if {beta} is not None and h == 0 and {worse} else h\n")  # fmt: skip


def pusher_negative(code: str) -> str:
    return negative_teacher(code, "UNIT", "oracle_feedback(q_star_sa, q_star_best, alpha).item()")


def maze_negative(code: str) -> str:
    return negative_teacher(code, 'Range("[0, 1]")', "oracle_feedback(q_star_sa, q_star_best, alpha)")


LAYER_NORM_FLAG = """
    tamer_layer_norm: Annotated[bool, DAY] = False
    \"\"\"the hack: LayerNorm after each hidden layer of TAMER's H\"\"\""""


def pusher_layer_norm(code: str) -> str:
    """LayerNorm in TAMER's H: the flag (Args), H's arguments (Day); QEnsemble has the layer (its `layer_norm`)."""
    code = patch(code, "\n    # The teacher as a person", LAYER_NORM_FLAG + "\n    # The teacher as a person")
    return patch(code, '{**shapes, "n": 2}', '{**shapes, "n": 2, "layer_norm": s["tamer_layer_norm"]}')


def copy_of(tmp_path, script: str, hack) -> str:
    """The repository's scripts and study modules in tmp_path (made here), `script` hacked."""
    os.makedirs(tmp_path)
    for name in ("inform_sac_pusher.py", "inform_dqn_gridworld.py", "gridworld_env.py"):
        shutil.copy(os.path.join(REPO, name), tmp_path)
    shutil.copytree(os.path.join(REPO, "inform_utils"), tmp_path / "inform_utils")
    (tmp_path / script).write_text(hack((tmp_path / script).read_text()))
    return str(tmp_path)


def run(cwd, code_dir, cmd: list[str]) -> tuple[subprocess.CompletedProcess, str | None, dict | None]:
    """A command with the code in code_dir; its result, and the run it made and its summary (None: none)."""
    before = set(glob.glob(os.path.join(cwd, "runs", "*")))
    env = {**os.environ, "PYTHONPATH": code_dir, "OMP_NUM_THREADS": "1"}
    cmd = [os.path.join(code_dir, cmd[0]), *cmd[1:]] if cmd[0].endswith(".py") else cmd
    result = subprocess.run([sys.executable, *cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
    made = set(glob.glob(os.path.join(cwd, "runs", "*"))) - before
    if not made:
        return result, None, None
    (run_dir,) = made
    with open(os.path.join(run_dir, "summary.json")) as f:
        return result, run_dir, json.load(f)


CASES = {  # script, hack, study module, day flags, night flags, the hack's own flag
    "pusher -1": ("inform_sac_pusher.py", pusher_negative, "sleep_variants_pusher", PUSHER_DAY, PUSHER_NIGHT,
                  ["--teacher-negative-beta", "0.9"]),
    "maze -1": ("inform_dqn_gridworld.py", maze_negative, "sleep_variants_maze", MAZE_DAY, MAZE_NIGHT,
                ["--teacher-negative-beta", "0.999"]),
}  # fmt: skip


@pytest.mark.parametrize("case", CASES)
def test_a_teacher_that_answers_minus_one_fills_the_buffer_and_the_original_records_its_day(case, tmp_path):
    script, hack, study, day_flags, night_flags, flag = CASES[case]
    code = copy_of(tmp_path / "copy", script, hack)
    result, day_dir, day = run(tmp_path, code, [script, *day_flags, *night_flags, "--save-buffer", *flag])
    assert result.returncode == 0 and day["status"] == "completed", result.stderr[-2000:]
    saved = torch.load(os.path.join(day_dir, "day.pt"), weights_only=True)
    labels = set(saved["feedback"].unique().tolist())
    assert -1.0 in labels and 1.0 in labels, labels  # the teacher's -1 reached the buffer as given
    assert saved["day_args"]["teacher_negative_beta"] == float(flag[1])

    for cmd in ([script], ["-m", f"inform_utils.{study}"], ["-m", f"inform_utils.{study}", "--sleep-control", "sham"]):
        result, _, night = run(tmp_path, REPO, [*cmd, "--sleep-from", day_dir, *night_flags])  # the original's
        assert result.returncode == 0 and night["status"] == "completed", (cmd, result.stderr[-2000:])
        assert night["day_settings"]["teacher_negative_beta"] == float(flag[1]), cmd  # recorded, not dropped
        assert "teacher_negative_beta" in result.stdout, cmd  # and said


def test_a_day_with_layer_norm_in_h_sleeps_in_its_copy_and_in_the_original(tmp_path):
    code = copy_of(tmp_path / "copy", "inform_sac_pusher.py", pusher_layer_norm)
    day_cmd = ["inform_sac_pusher.py", *PUSHER_DAY, *PUSHER_NIGHT, "--save-buffer", "--tamer-layer-norm"]
    result, day_dir, day = run(tmp_path, code, day_cmd)
    assert result.returncode == 0 and day["status"] == "completed", result.stderr[-2000:]
    saved = torch.load(os.path.join(day_dir, "day.pt"), weights_only=True)
    assert saved["tamer_h"]["kwargs"]["layer_norm"] is True and "norm" in saved["tamer_h"]["state_dict"]

    result, _, night = run(tmp_path, code, ["inform_sac_pusher.py", "--sleep-from", day_dir, *PUSHER_NIGHT])
    assert result.returncode == 0 and night["status"] == "completed", result.stderr[-2000:]  # rebuilt from kwargs
    assert night["day_settings"]["tamer_layer_norm"] is True

    for cmd in (["inform_sac_pusher.py"], ["-m", "inform_utils.sleep_variants_pusher"]):  # the original's
        result, run_dir, night = run(tmp_path, REPO, [*cmd, "--sleep-from", day_dir, *PUSHER_NIGHT])
        assert result.returncode == 0 and night["status"] == "completed", (cmd, result.stderr[-2000:])
        assert night["day_settings"]["tamer_layer_norm"] is True  # H rebuilt with its LayerNorm, the setting kept


# a teacher's answer as given, in the buffer and in H's loss ----------------------------------------------------------
def test_the_teacher_passes_any_answer_on_as_given():
    for teacher_class in (isp.Teacher, maze.Teacher):
        teacher = teacher_class(credit_window=2)
        assert teacher(0, -1.0) == {0: -1.0} and teacher(1, 0.5) == {0: 0.5, 1: 0.5}
        assert teacher(2, 0.0) == {} and teacher(3, 1.0) == {2: 1.0, 3: 1.0}
        assert teacher.positives == 2  # the budget counts positive answers
        flipped = teacher_class(noise=1.0)  # a flip: Eq. 4's 1 <-> 0, a signed answer's sign
        assert flipped(0, 1.0) == {} and flipped(1, 0.0) == {1: 1.0} and flipped(2, -1.0) == {2: 1.0}


SIGNED = """
import sys
import {module} as core

class Signed(core.Day):  # -1 where Eq. 4 answers 0, 0.5 where it answers 1
    def answer(self, *a):
        return 0.5 if super().answer(*a) > 0 else -1.0

seen = set()
def tamer_loss(h_net, obs, actions, feedback, loss=core.tamer_loss):
    seen.update(feedback.unique().tolist())
    return loss(h_net, obs, actions, feedback)

core.Day, core.tamer_loss = Signed, tamer_loss
code = core.cli(core.Args(**{kwargs}))
print("H's targets:", sorted(seen))
sys.exit(code)
"""


@pytest.mark.parametrize("module", ["inform_sac_pusher", "inform_dqn_gridworld"])
def test_answers_of_minus_one_and_one_half_reach_the_buffer_and_h_as_given(module, tmp_path):
    if module == "inform_sac_pusher":
        kwargs = dict(tamer_total_timesteps=400, tamer_learning_starts=200, tamer_batch_size=64, success_distance=1.0,
                      sleep_gradient_steps=10, sleep_batch_size=64, eval_episodes=1, obstacle_episodes=0,
                      authors_test_episodes=0, save_buffer=True, oracle_path=TEACHER[1])  # fmt: skip
    else:
        kwargs = dict(tamer_total_timesteps=600, tamer_learning_starts=100, sleep_gradient_steps=10, save_buffer=True)
    env = {**os.environ, "PYTHONPATH": REPO, "OMP_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-c", SIGNED.format(module=module, kwargs=kwargs)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=600)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "H's targets: [-1.0, 0.5]" in proc.stdout, proc.stdout[-1000:]
    (day_file,) = glob.glob(str(tmp_path / "runs" / "*" / "day.pt"))
    assert set(torch.load(day_file, weights_only=True)["feedback"].unique().tolist()) == {-1.0, 0.5}


# a saved day's networks are checked on load -----------------------------------------------------------------------
@pytest.mark.parametrize("script", ["inform_sac_pusher.py", "inform_dqn_gridworld.py"])
def test_a_day_whose_tamer_networks_hold_nan_is_refused_in_one_line(script, tmp_path):
    day_flags, night_flags = (PUSHER_DAY, PUSHER_NIGHT) if script == "inform_sac_pusher.py" else (MAZE_DAY, MAZE_NIGHT)
    result, day_dir, _ = run(tmp_path, REPO, [script, *day_flags, *night_flags, "--save-buffer"])
    assert result.returncode == 0, result.stderr[-2000:]
    saved = torch.load(os.path.join(day_dir, "day.pt"), weights_only=True)
    net = saved["tamer_actor"] if "tamer_actor" in saved else saved["h_net"]
    next(iter(net["state_dict"].values())).view(-1)[0] = float("nan")
    os.makedirs(tmp_path / "nan")
    torch.save(saved, tmp_path / "nan" / "day.pt")
    result, run_dir, _ = run(tmp_path, REPO, [script, "--sleep-from", str(tmp_path / "nan"), *night_flags])
    assert result.returncode == 2 and run_dir is None, result.stderr[-2000:]
    assert result.stderr.count("\n") == 1 and "NaN" in result.stderr, result.stderr


# the maze's paths check what they are given, and its long tests look for a stop (issue 55, items 3 and 6) ---------
def test_a_maze_network_holding_nan_is_refused_by_evaluate_policy(tmp_path):
    net = maze.QNetwork(30, 4)
    with torch.no_grad():
        net.network[0].weight[0, 0] = float("nan")
    maze.save_network(str(tmp_path / "inform_q.pt"), net, env_id="KnoxStoneMaze-v0")  # the script's own writer
    env = {**os.environ, "PYTHONPATH": REPO}
    cmd = [sys.executable, "-m", "inform_utils.evaluate_policy", "maze", str(tmp_path / "inform_q.pt")]
    result = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 2 and result.stderr.count("\n") == 1 and "NaN" in result.stderr, result.stderr


def test_the_maze_evaluation_looks_for_a_stop_every_episode(monkeypatch):
    stop = type("Stop", (), {"received": ["SIGTERM"], "raised": False, "finished": False})()
    monkeypatch.setattr(maze.StopSignals, "current", stop)
    env = maze.make_env("FrozenLake-v1")
    with pytest.raises(KeyboardInterrupt):  # before a single episode of the 100,000
        maze.evaluate(maze.np.zeros(16, dtype=int), env, [{"seed": s} for s in range(100_000)], 100)
    assert stop.raised


# the sham control on a day whose H is another network (issue 71) ----------------------------------------------------
def maze_wider_h(code: str) -> str:
    """H 64 wide by QNetwork's constructor default alone: the day's saved kwargs say so, no flag does."""
    return patch(code, "n_actions: int, hidden: int = 32):", "n_actions: int, hidden: int = 64):")


SHAM_CASES = {  # script, hack, study module, day flags, night flags, the hack's flag, what the day's H is
    "pusher LayerNorm": ("inform_sac_pusher.py", pusher_layer_norm, "sleep_variants_pusher", PUSHER_DAY, PUSHER_NIGHT,
                         ["--tamer-layer-norm"], {"layer_norm": True}),
    "maze 64 wide": ("inform_dqn_gridworld.py", maze_wider_h, "sleep_variants_maze", MAZE_DAY, MAZE_NIGHT, [],
                     {"hidden": 64}),
}  # fmt: skip


@pytest.mark.parametrize("case", SHAM_CASES)
def test_a_sham_night_on_a_day_whose_h_is_another_network(case, tmp_path):
    """ShamControl rebuilt H from today's constants: a traceback. It is built from the day's saved kwargs, which the
    night's summary records (an H changed by a constructor default alone says so nowhere else); the day's tamer_h.pt
    rebuilds from its own kwargs (Pusher's omitted layer_norm)."""
    script, hack, study, day_flags, night_flags, flag, h = SHAM_CASES[case]
    code = copy_of(tmp_path / "copy", script, hack)
    result, day_dir, day = run(tmp_path, code, [script, *day_flags, *night_flags, "--save-buffer", *flag])
    assert result.returncode == 0 and day["status"] == "completed", result.stderr[-2000:]
    saved_h = torch.load(os.path.join(day_dir, "tamer_h.pt"), weights_only=True)
    assert h.items() <= saved_h["kwargs"].items(), saved_h["kwargs"]
    (isp.QEnsemble if script == "inform_sac_pusher.py" else maze.QNetwork)(**saved_h["kwargs"]).load_state_dict(
        saved_h["state_dict"])  # fmt: skip

    cmd = ["-m", f"inform_utils.{study}", "--sleep-from", day_dir, "--sleep-control", "sham", *night_flags]
    result, _, night = run(tmp_path, REPO, cmd)  # the original study's sham
    assert result.returncode == 0 and night["status"] == "completed", result.stderr[-2000:]
    assert h.items() <= night["tamer_h_kwargs"].items(), night["tamer_h_kwargs"]
