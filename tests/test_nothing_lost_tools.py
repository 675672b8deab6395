"""Issue 71, the tools: each checks its flags and its destination before the first episode, refuses bad input in one
`error:` line with exit 2 (inform_utils/files.py's BadInput and run_tool, one helper for every tool that takes it),
stops on a signal between two steps in one line with exit 128 + the signal, and writes a file whole or not at all.
The page takes numbers, frames and take-overs only as they are, and its record says how the day ended."""

import json
import math
import os
import re
import subprocess
import sys
import tempfile

import numpy as np
import pytest
import torch
from conftest import REPO, default_signals
from test_browser_teacher import Session, lines
from test_teacher_demos import TINY, make_demos

import inform_sac_pusher as isp
import oracle_train as ot
from browser_teacher import BrowserTeacher
from inform_utils import pusher_control, scripted_person_pusher, teacher_check
from inform_utils.demos import read_demos
from inform_utils.files import BadInput, atomic, cut

READ_ONLY = "/sys"  # a folder nobody writes into, root included


def skip_if_writable(folder: str) -> None:
    try:
        tempfile.TemporaryFile(dir=folder).close()
    except OSError:
        return
    pytest.skip(f"{folder} takes files here: no read-only folder to test with")


def run_module(cwd, module: str, *flags: str) -> subprocess.CompletedProcess:
    """python -m module (or python -c code with module "-c"), in `cwd`, with the signals at their defaults."""
    cmd = [sys.executable, *(["-c"] if module == "-c" else ["-m", module]), *flags]
    return subprocess.run(cmd, cwd=cwd, env={**os.environ, "PYTHONPATH": REPO, "OMP_NUM_THREADS": "1"},
                          capture_output=True, text=True, timeout=120, preexec_fn=default_signals)  # fmt: skip


def one_error_line(proc: subprocess.CompletedProcess, code: int = 2, start: str = "error: ") -> str:
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == code and len(lines) == 1 and lines[0].startswith(start), proc.stderr[-2000:]
    return lines[0]


# ---------------------------------------------------------------------------------------------------------------------
# pusher_control: the checks before the first episode, the stops, the save


@pytest.mark.parametrize(
    ("flags", "phrase"),
    [
        ({"episodes": 0}, "--episodes must be >= 1, got 0"),
        ({"episodes": -3}, "--episodes must be >= 1, got -3"),
        ({"first_seed": -1}, "--first-seed -1: the reset seeds lie in 0 .. 2**63 - 1"),
        ({"first_seed": 2**63 - 1, "episodes": 2}, "the first is at most 9223372036854775806"),
        ({"env_id": "Reacher-v5"}, "--env-id Reacher-v5: the demonstrators push Pusher's object"),
        ({"success_distance": math.nan}, "--success-distance must be a distance above 0"),
        ({"success_distance": -1.0}, "--success-distance must be a distance above 0"),
        ({"demonstrator": "mpc", "mpc_ctrl_weight": math.inf}, "--mpc-ctrl-weight inf: a price of torque is 0 or"),
        ({"demonstrator": "mpc", "mpc_ctrl_weight": math.nan}, "--mpc-ctrl-weight nan: a price of torque is 0 or"),
        ({"demonstrator": "mpc", "mpc_samples": 10**12}, "MPPI averages 2 or more action sequences, at most 10,000"),
        ({"save_demos": f"{READ_ONLY}/d.npz"}, f"--save-demos {READ_ONLY}: cannot write into {READ_ONLY}"),
        ({"save_demos": "notes.txt/d.npz"}, "notes.txt is a file, not a directory"),
    ],
)  # fmt: skip
def test_pusher_control_checks_its_flags_and_destination_before_the_first_episode(tmp_path, monkeypatch, flags,
                                                                                  phrase):  # fmt: skip
    """Every refusal before the env is made: an hour of episodes never ends in a traceback at the save (the seeds,
    int64 in the file, a folder that cannot take the file), nor in NaN actions (an infinite price of torque)."""
    if READ_ONLY in str(flags.get("save_demos")):
        skip_if_writable(READ_ONLY)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "notes.txt").write_text("")

    def no_env(*args, **kwargs):
        raise AssertionError("an episode's env was made before the flags were checked")

    monkeypatch.setattr(isp, "make_env", no_env)
    with pytest.raises(BadInput, match=re.escape(phrase)):
        pusher_control.main(pusher_control.Args(**{"episodes": 1, **flags}))
    assert os.listdir(tmp_path) == ["notes.txt"]


def test_pusher_control_refuses_in_one_line_and_exit_2_and_takes_pusher_v4(tmp_path):
    """On the command line (run_tool): one `error:` line, exit 2 (SystemExit's text exited 1), nothing written;
    Pusher-v4 (its own class on mujoco>=3, as the core builds it) runs."""
    line = one_error_line(
        run_module(tmp_path, "inform_utils.pusher_control", "--episodes", "0", "--save-demos", "d.npz")
    )
    assert line == "error: --episodes must be >= 1, got 0"
    assert os.listdir(tmp_path) == []
    v4 = run_module(tmp_path, "inform_utils.pusher_control", "--env-id", "Pusher-v4", "--episodes", "1")
    assert v4.returncode == 0 and v4.stderr == "" and "on Pusher-v4" in v4.stdout, v4.stderr[-2000:]


def test_demonstrations_go_into_a_folder_made_for_them(tmp_path):
    """A missing folder is made (its nearest existing parent was checked writable first); the file is whole."""
    path = tmp_path / "new" / "deeper" / "d.npz"
    pusher_control.main(pusher_control.Args(episodes=1, save_demos=str(path)))
    with np.load(path, allow_pickle=False) as npz:
        assert npz["act"].shape == (100, 7) and list(npz["episode_seed"]) == [0]
    assert os.listdir(path.parent) == ["d.npz"]


def test_steps_with_nan_or_inf_are_never_saved(tmp_path):
    """What a teacher would refuse to read is refused at the save, and nothing is written (--mpc-ctrl-weight inf
    wrote 700 NaN actions and exited 0)."""
    record = {name: [np.zeros(7 if name == "act" else 23) if name in ("obs", "act", "next_obs") else 0.0] * 100
              for name in pusher_control.DEMO_FIELDS}  # fmt: skip
    record["act"][3] = np.full(7, np.nan)
    path = tmp_path / "d.npz"
    with pytest.raises(BadInput, match="the demonstrator's steps hold NaN or inf"):
        pusher_control.save_demos(str(path), record, "Pusher-v5", "scripted", range(1), [0.1], 0.08, "mujoco-2.3")
    assert os.listdir(tmp_path) == []


SIGNAL_IN = """
import os, runpy, signal, sys
import numpy as np
import inform_sac_pusher as isp
kill = lambda: os.kill(os.getpid(), signal.{signal})
where = {where!r}
if where == "episode":  # mid-episode: the object's position is read at every step
    real_xy = isp.object_xy
    isp.object_xy = lambda obs: (kill(), real_xy(obs))[1]
else:  # while the .npz is being written: its bytes are all there, the rename is still to come
    real_save = np.savez_compressed
    np.savez_compressed = lambda file, **arrays: (real_save(file, **arrays), kill())
sys.argv = ["pusher_control", "--episodes", "2", "--save-demos", "d.npz"]
runpy.run_module("inform_utils.pusher_control", run_name="__main__")
"""


def test_a_stop_mid_episode_is_one_line_and_leaves_nothing(tmp_path):
    """Ctrl-C was a KeyboardInterrupt traceback: the handler records it, the next step stops, exit 130."""
    proc = run_module(tmp_path, "-c", SIGNAL_IN.format(signal="SIGINT", where="episode"))
    line = one_error_line(proc, 130, "interrupted (SIGINT)")
    assert "nothing was written" in line and os.listdir(tmp_path) == [], line


def test_a_sigterm_during_the_save_leaves_the_file_whole_and_nothing_beside_it(tmp_path):
    """SIGTERM during the save killed the process between the write and the rename: `d.npz.tmpPID.npz` stayed beside
    the target. Now the save ends whole, then the run stops (exit 143), saying so."""
    proc = run_module(tmp_path, "-c", SIGNAL_IN.format(signal="SIGTERM", where="save"))
    one_error_line(proc, 143, "SIGTERM received at the end; what was written is whole")
    assert os.listdir(tmp_path) == ["d.npz"]
    with np.load(tmp_path / "d.npz", allow_pickle=False) as npz:
        assert npz["rew"].shape == (200,)


def test_an_atomic_file_is_made_as_open_makes_it(tmp_path):
    """files.atomic's file: the umask's mode (mkstemp's 0600 hid a tool's output from the group), and on an error
    nothing beside the target."""
    umask = os.umask(0o022)
    try:
        with atomic(str(tmp_path / "a.json")) as f:
            f.write("{}")
        with pytest.raises(RuntimeError), atomic(str(tmp_path / "b.json")) as f:
            raise RuntimeError
    finally:
        os.umask(umask)
    assert os.stat(tmp_path / "a.json").st_mode & 0o777 == 0o644 and os.listdir(tmp_path) == ["a.json"]


# ---------------------------------------------------------------------------------------------------------------------
# oracle_train --demos: the file checked as pusher_control's demonstrations; --demo-ratio; a stop while cloning


def damaged(path, how: str) -> str:
    """A copy of the demonstrations at `path`, damaged `how`; its path."""
    data = dict(np.load(path, allow_pickle=False))
    out = f"{path}.{how}.npz"
    if how == "npy":  # an .npy renamed .npz
        np.save(out + ".npy", data["obs"])
        os.replace(out + ".npy", out)
        return out
    change = {"rew_0d": {"rew": np.float32(1.0)}, "seed_0d": {"episode_seed": np.int64(3)},
              "str_obs": {"obs": data["obs"].astype(str)}, "str_act": {"act": data["act"].astype(str)},
              "str_dist": {"reward_dist": data["reward_dist"].astype(str)}}[how]  # fmt: skip
    np.savez(out, **{**data, **change})
    return out


@pytest.mark.parametrize(
    ("how", "phrase"),
    [
        ("npy", "one .npy array, not an .npz archive of named arrays"),
        ("rew_0d", ": rew: not an array of numbers"),
        ("seed_0d", ": episode_seed: not an array of numbers"),
        ("str_obs", ": obs: not an array of numbers"),
        ("str_act", ": act: not an array of numbers"),
        ("str_dist", ": reward_dist: not an array of numbers"),
    ],
)
def test_demonstrations_of_the_wrong_kind_are_one_line(tmp_path, how, phrase):
    """Each was a traceback (TypeError, or len() of a 0-d array): now oracle_train's InputError, one line."""
    path = tmp_path / "d.npz"
    make_demos(path)
    bad = damaged(path, how)
    import gymnasium as gym

    with pytest.raises(ot.InputError, match=phrase) as refused:  # the reward re-weighted: reward_dist is read
        read_demos(bad, gym.make("Pusher-v5"), ot.Args(reward_dist_weight=2.0), None, ot.InputError)
    assert str(refused.value).startswith(f"--demos {bad}") and "\n" not in str(refused.value)


def test_demonstrations_on_the_command_line_a_directory_and_a_ratio_without_them(run_script, tmp_path):
    """The CLI's line for an .npy renamed .npz; a directory is said to be one (it was "no such file"); --demo-ratio
    without --demos is refused, not recorded as the share of batches nobody drew."""
    make_demos(tmp_path / "d.npz")
    bad = damaged(tmp_path / "d.npz", "npy")
    line = one_error_line(run_script("oracle_train.py", "--env-id", "Pusher-v5", "--demos", bad))
    assert "one .npy array" in line and not (run_script.cwd / "runs").exists(), line
    (tmp_path / "folder.npz").mkdir()
    with pytest.raises(ot.InputError, match=r"--demos .*folder\.npz: a directory, not a file"):
        ot.check_args(ot.Args(env_id="Pusher-v5", demos=str(tmp_path / "folder.npz")))
    with pytest.raises(ot.InputError, match="--demo-ratio 0.9 is the share of --demos in each batch: it needs --demos"):
        ot.check_args(ot.Args(env_id="Pusher-v5", demo_ratio=0.9))
    ot.check_args(ot.Args(env_id="Pusher-v5", demo_ratio=0.9, demos=str(tmp_path / "d.npz")))  # with them: fine


STOP_WHILE_CLONING = """
import os, runpy, signal, sys
import inform_utils.demos as demos
real = demos.clone_step
def clone_step(sac, batch):  # Ctrl-C during the first step of cloning
    os.kill(os.getpid(), signal.SIGINT)
    real(sac, batch)
demos.clone_step = clone_step
sys.argv = ["oracle_train.py", *{flags!r}]
runpy.run_path({script!r}, run_name="__main__")
"""


def test_a_stop_while_cloning_names_no_state_and_leaves_no_folder(tmp_path, monkeypatch):
    """Stopped during --clone-steps, the run said to go on with `--resume <run dir>/training_state.pt` where no state
    was ever saved, and left an empty folder in runs/. Nothing could be kept then: none is made, and it says so."""
    make_demos(tmp_path / "d.npz", success=(True, False))
    flags = [*TINY, "--demos", str(tmp_path / "d.npz"), "--total-timesteps", "400", "--clone-steps", "1000"]
    code = STOP_WHILE_CLONING.format(flags=flags, script=os.path.join(REPO, "oracle_train.py"))
    proc = run_module(tmp_path, "-c", code)
    line = one_error_line(proc, 130, "interrupted (SIGINT)")
    assert line.endswith("no oracle checkpoint was written; no training state was saved to resume from"), line
    assert not (tmp_path / "runs").exists() or os.listdir(tmp_path / "runs") == []
    monkeypatch.setattr(ot.Stop, "state", None)
    assert ot.resumable() == "no training state was saved to resume from"
    monkeypatch.setattr(ot.Stop, "state", "runs/x/training_state.pt")  # once one is saved (or resumed from)
    assert ot.resumable() == "--resume runs/x/training_state.pt continues from it"


def test_a_long_exp_name_is_not_echoed_whole():
    for name in ("a" * 5000, "a" * 5000 + "/b"):
        with pytest.raises(ot.InputError) as refused:
            ot.check_args(ot.Args(exp_name=name))
        assert len(str(refused.value)) < 200 and "is too long" in str(refused.value)


def test_cut_keeps_names_whole_and_says_how_long():
    keys = ", ".join(f'"qf.{i}.norm.weight"' for i in range(40))
    text = f"Unexpected key(s) in state_dict: {keys}"
    short = cut(text, 120)
    assert len(short) < 160 and short.endswith(f" ... ({len(text):,} characters)"), short
    assert all(k.endswith('weight"') for k in short.split(" ... ")[0].split(": ")[1].split(", ")), short
    assert cut("a" * 5000, 60) == "a" * 60 + " ... (5,000 characters)"
    assert cut("two\nlines") == "two lines"


# ---------------------------------------------------------------------------------------------------------------------
# scripted_person_pusher and teacher_check: the ranges before any work


@pytest.mark.parametrize(
    ("flags", "phrase"),
    [
        ({"drive": True, "rehearse": 0}, "--rehearse must be >= 1 episode, got 0"),
        ({"drive": True, "rehearse": -2}, "--rehearse must be >= 1 episode, got -2"),
        ({"drive": True, "rehearse": 1, "seeds": [-1]}, "--seeds must be one or more seeds >= 0, got -1"),
        ({"drive": True, "rehearse": 1, "flags": "--env-id Reacher-v5"}, "--flags: --env-id Reacher-v5: the person"),
        ({"drive": True, "rehearse": 1, "flags": "--env-id=Reacher-v5"}, "--flags: --env-id Reacher-v5: the person"),
        ({"drive": True, "rehearse": 1, "flags": '--exp-name "x'}, "No closing quotation"),
        ({"drive": True, "rehearse": 1, "page_flags": "--takeover-steps '5"}, "--page-flags .*No closing quotation"),
        ({"rehearse": 1}, "--rehearse rehearses the driving person's push: it needs --drive"),
        ({"drive": True, "rehearse": 1, "pace": 0.0}, r"--pace must be in \(0, 100\] steps a second"),
        ({"drive": True, "rehearse": 1, "reaction": (-5.0, -1.0)}, "--reaction must be LOW HIGH seconds with 0 <="),
        ({"drive": True, "rehearse": 1, "reaction": (0.8, 0.3)}, "--reaction must be LOW HIGH seconds with 0 <="),
        ({"drive": True, "take_after_noes": -1}, "--take-after-noes must be >= 0, .* got -1"),
        ({"take_after_noes": 3}, "--take-after-noes .* needs --drive and no --rehearse, got 3"),
        ({"drive": True, "rehearse": 1, "take_after_noes": 3}, "--take-after-noes .* needs --drive and no --rehearse"),
        ({"drive": True, "page_flags": "--drive-by Object"}, "--drive-by must be fingertip or object, got Object"),
        ({"drive": True, "flags": "--drive-by object"}, "--drive-by .* in --page-flags, not --flags"),
    ],
)  # fmt: skip
def test_the_scripted_person_checks_its_flags_first(monkeypatch, flags, phrase):
    """Each was a traceback, or accepted silently (a rehearsal without --drive, at pace 0, reacting in -5 s)."""
    for name in ("rehearse", "check_before_writing", "load_oracle"):  # no work before the checks
        monkeypatch.setattr(scripted_person_pusher, name, lambda *a: pytest.fail("work began before the checks"))
    with pytest.raises(BadInput, match=phrase):
        scripted_person_pusher.main(scripted_person_pusher.Args(**{"seeds": [1], **flags}))


CTRL_C_AT_THE_ENV = """
import os, runpy, signal, sys
import inform_sac_pusher as isp
real = isp.make_env
isp.make_env = lambda *a, **k: (os.kill(os.getpid(), signal.SIGINT), real(*a, **k))[1]  # Ctrl-C as the work starts
sys.argv = ["tool", *{flags!r}]
runpy.run_module({module!r}, run_name="__main__")
"""


@pytest.mark.parametrize(
    ("module", "flags"),
    [
        ("inform_utils.teacher_check", [os.path.join(REPO, "oracles", "Pusher-v5__sac_oracle.pt"), "--episodes", "1"]),
        ("inform_utils.scripted_person_pusher", ["--drive", "--rehearse", "1", "--seeds", "1"]),
    ],
)
def test_ctrl_c_in_a_tool_without_stop_points_is_one_line(tmp_path, module, flags):
    """Ctrl-C during teacher_check or the scripted person's rehearsal was a KeyboardInterrupt traceback."""
    proc = run_module(tmp_path, "-c", CTRL_C_AT_THE_ENV.format(flags=flags, module=module))
    one_error_line(proc, 130, "interrupted (SIGINT) before the work was done")
    assert os.listdir(tmp_path) == []


def test_the_scripted_persons_folders_are_checked_writable_first(monkeypatch):
    """--out-dir where nothing can be written: refused before the browser starts (os.makedirs' traceback came after
    it), in one line through the helper both scripted persons share."""
    from inform_utils import scripted_person_browser

    skip_if_writable(READ_ONLY)
    monkeypatch.setattr(scripted_person_browser, "browser_missing", lambda: None)
    with pytest.raises(BadInput, match=f"--out-dir {READ_ONLY}/table: cannot write into {READ_ONLY}"):
        scripted_person_browser.check_before_writing(scripted_person_pusher.Args(out_dir=f"{READ_ONLY}/table"))


def test_the_scripted_persons_refusal_is_one_line_and_exit_2(tmp_path):
    proc = run_module(tmp_path, "inform_utils.scripted_person_pusher", "--rehearse", "1", "--seeds", "1")
    assert one_error_line(proc) == "error: --rehearse rehearses the driving person's push: it needs --drive"


@pytest.mark.parametrize("flags", [{"fixed_seeds": [1, -1]}, {"reset_seed": -5}])
def test_teacher_check_refuses_a_negative_seed_before_the_teacher_loads(monkeypatch, capsys, flags):
    monkeypatch.setattr(teacher_check, "read_teacher", lambda path: pytest.fail("the teacher loaded first"))
    assert teacher_check.main(teacher_check.Args("teacher.pt", episodes=1, **flags)) == 2
    line = capsys.readouterr().err.strip()
    assert line.startswith("error: --reset-seed and --fixed-seeds are seeds >= 0, got ") and "\n" not in line, line


def test_a_layer_norm_teacher_without_its_marker_is_named_as_the_tool_takes_it(tmp_path, capsys):
    """The tool takes the teacher as its argument (it said `--oracle-path`), and the reason is whole (it ended in
    `"nor`), with what to put right."""
    ckpt = torch.load(os.path.join(REPO, "oracles", "Pusher-v5__sac_oracle.pt"), weights_only=True)
    ckpt["qf_state_dict"] = isp.QEnsemble(23, 7, 256, n=2, layer_norm=True).state_dict()  # kwargs: no layer_norm
    path = str(tmp_path / "ln.pt")
    torch.save(ckpt, path)
    assert teacher_check.main(teacher_check.Args(path, episodes=1, fixed_seeds=[1])) == 2
    line = capsys.readouterr().err.strip()
    assert line.startswith(f"error: {path}: the networks do not load (RuntimeError: ") and "--oracle-path" not in line
    assert 'Unexpected key(s) in state_dict: "norm".' in line and "kwargs lack layer_norm: True" in line, line


# ---------------------------------------------------------------------------------------------------------------------
# the Pusher's page: what the handler takes, and how the day ended


@pytest.fixture
def pusher_page(tmp_path):
    """The Pusher's page streaming a step, a person's session on it."""
    with BrowserTeacher(str(tmp_path / "run"), "pusher", quiet=True, close_grace=0.3, linger=0,
                        takeover_after=60.0) as page:  # fmt: skip
        person = Session(page)
        person.load()
        for step in range(3):
            page.show(step, frame=np.zeros((4, 4, 3), np.uint8), action=[0.0] * 7)
        yield page, person


def test_the_page_takes_only_numbers_of_a_bounded_size_as_a_target(pusher_page):
    """A 4,000-digit integer dropped the connection (OverflowError in the handler), [true, false] was taken as
    (1, 0): both are a 400, and no take is logged."""
    page, person = pusher_page
    for target in ([10**4000, 0], [True, False], [0.5, float("nan")], [0.5, 1e400], ["0.5", 0]):
        status, body, _ = person.request("POST", "/drive", {"drive": "take", "target": target})
        assert status == 400 and b"target: [x, y]" in body, (target, status, body)
    assert not page.driving and lines(page, "drive") == []
    assert person.request("POST", "/drive", {"drive": "take", "target": [0.5, -0.2]})[0] == 200  # a real one is taken
    assert page.target == (0.5, -0.2) and [row["drive"] for row in lines(page, "drive")] == ["take"]


def test_a_release_without_a_take_is_not_logged(pusher_page):
    page, person = pusher_page
    status, body, _ = person.request("POST", "/drive", {"drive": "release"})
    assert status == 409 and json.loads(body)["why"] == "take the arm first"
    assert lines(page, "drive") == []


def test_an_answer_about_frame_minus_7_is_refused(pusher_page):
    """seq -7 was credited to the oldest frame; a bool is no frame either."""
    page, person = pusher_page
    for seq in (-7, True):
        status, reply = person.answer("yes", None, f"n{seq}", seq=seq)
        assert status == 400 and "integers, 0 or more" in reply["error"], (seq, reply)
    assert page.answers() == [] and lines(page) == []
    assert person.answer("yes", None, "ok", seq=2) == (200, {"taken": True})  # the second frame: step 1
    assert [row["step"] for row in lines(page)] == [1]


def test_a_spent_budget_ends_the_pages_day_as_such(pusher_page):
    """The person's last yes of the budget ends the page's day then, and its record says why (it said "day done"
    once the night was over)."""
    from types import SimpleNamespace

    from inform_utils.browser_pusher import PageTeacher

    page, person = pusher_page
    teacher = object.__new__(PageTeacher)  # its day's part, without the arm and the camera
    arm = SimpleNamespace(unwrapped=SimpleNamespace(_get_obs=lambda: np.zeros(23)))
    teacher.__dict__.update(page=page, env=arm, budget=1, last_step=100, every=10**6, frame=np.zeros((4, 4, 3)),
                            credited={}, positives=0, perfect_positives=0, drove=False, labelled={})  # fmt: skip
    teacher(3, 0.0)
    assert person.answer("yes", None, "y1", seq=4) == (200, {"taken": True})
    teacher(4, 0.0)
    assert teacher.gone and [row["why"] for row in lines(page, "end")] == ["the budget of yes answers is spent"]


def test_an_interrupted_days_record_says_so(tmp_path, monkeypatch):
    """The page's answers.jsonl ended `"why": "day done"` for a day stopped by Ctrl-C: it ends with the run's own
    account (the core's summary). The run itself is stood in for: a page, then the summary of a stop in the day."""
    from inform_utils import browser_pusher

    class Teacher:  # PageTeacher without the arm and the camera
        def __init__(self, args, env, run_dir):
            self.page, self.labelled = BrowserTeacher(run_dir, "pusher", quiet=True, linger=0), {}

        def wait_for_person(self):
            pass

    def cli(args, make_teacher):
        run_dir = tmp_path / "runs" / "day"
        make_teacher(args, None, str(run_dir))
        summary = {"status": "interrupted", "phase": "tamer", "signal": "SIGINT"}
        (run_dir / "summary.json").write_text(json.dumps(summary))
        return 130

    monkeypatch.setattr(browser_pusher, "PageTeacher", Teacher)
    monkeypatch.setattr(isp, "cli", cli)
    monkeypatch.setattr(isp, "check_video", lambda env_id: None)
    monkeypatch.setattr(sys, "argv", ["browser_pusher"])
    assert browser_pusher.main() == 130
    with open(tmp_path / "runs" / "day" / "answers.jsonl") as f:
        ends = [row["why"] for row in map(json.loads, f) if row["event"] == "end"]
    assert ends == ["interrupted (SIGINT) during the tamer phase"]


# ---------------------------------------------------------------------------------------------------------------------
# smaller


def test_no_scipy_warning_before_a_one_line_error(tmp_path):
    """pusher_obstacle_stats on runs whose distances are all alike (t = inf): scipy's "Precision loss" warning went to
    stderr before the error line of a missing --fig5a input."""
    for seed in (1, 2):
        run = tmp_path / f"seed{seed}"
        run.mkdir()
        np.savez(run / "obstacle_distances.npz", tamer=np.ones(3), inform=np.zeros(3))
        (run / "summary.json").write_text(json.dumps({"seed": seed, "args": {"success_distance": 0.08}}))
    proc = run_module(tmp_path, "inform_utils.pusher_obstacle_stats", "seed1", "seed2", "--fig5a", "fig.png")
    assert one_error_line(proc) == "error: seed1/obstacle_paths.npz: cannot read it (no such file)"
