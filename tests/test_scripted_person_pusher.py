"""inform_utils/scripted_person_pusher.py --drive (issue 53): the scripted person takes the arm through the Pusher's
page in Chromium and pushes, by clicks on the map and arrow keys, and answers y/n while the agent drives. A short day
at the page, then the nights; the browser test skips (saying why) without /usr/bin/chromium or playwright."""

import json
import os
import signal
import subprocess
import sys

import numpy as np
import pytest
from conftest import REPO, default_signals

from inform_utils import scripted_person_pusher as spp
from inform_utils.scripted_person_browser import browser_missing

TINY = ("--tamer-learning-starts 50 --tamer-batch-size 32 --sleep-batch-size 32 --sleep-gradient-steps 100 "
        "--eval-episodes 1 --obstacle-episodes 1 --authors-test-episodes 1")  # fmt: skip


def test_the_map_pixels_round_trip_and_the_person_goes_round_an_object_in_its_way():
    for point in ([0.63, -0.196], [0.45, -0.05], [-0.1, -0.8]):  # the last: the map's top left corner
        assert np.allclose(spp.from_pixel(*spp.to_pixel(point)), point, atol=0.5 / 240 + 1e-9)
    person = spp.DrivingPerson(np.random.default_rng(0), aim_noise=0.0)
    start = {"tip": [0.82, -0.6], "object": [0.6, -0.2], "goal": [0.45, -0.05]}
    assert person.decide(start, driving=False, target=None)[0][0] == "click"  # the episode's start: take the arm
    ahead = {"tip": [0.4, -0.05], "object": [0.6, -0.2], "goal": [0.45, -0.05]}  # the fingertip between it and goal
    (click,) = person.decide(ahead, driving=True, target=[0.4, -0.05])
    u = np.array([-0.15, 0.15]) / np.hypot(0.15, 0.15)
    waypoint = spp.from_pixel(*click[1:])
    assert abs((waypoint - np.array([0.6, -0.2])) @ np.array([-u[1], u[0]])) > 0.15  # beside the object, not through
    at_goal = {"tip": [0.5, -0.1], "object": [0.46, -0.06], "goal": [0.45, -0.05]}
    assert person.decide(at_goal, driving=True, target=[0.45, -0.05]) == [("release",)]


def test_a_person_who_takes_when_the_agent_goes_wrong_watches_until_its_nth_no_in_a_row():
    """--take-after-noes 3: at an episode's start the person watches; a yes ends a run of no's; the third no in a row
    has it take the arm at its next look; at the next episode's start it gives the arm back and watches again."""
    person = spp.DrivingPerson(np.random.default_rng(0), aim_noise=0.0, take_after=3)
    start = {"tip": [0.82, -0.6], "object": [0.6, -0.2], "goal": [0.45, -0.05]}
    assert person.decide(start, driving=False, target=None) == []
    for yes in (False, False, True, False, False):
        person.heard(yes)
        assert person.decide(start, driving=False, target=None) == []
    person.heard(False)
    assert person.decide(start, driving=False, target=None)[0][0] == "click"
    person.decide({**start, "object": [0.5, -0.1]}, driving=True, target=[0.5, -0.1])
    assert person.decide(start, driving=True, target=[0.5, -0.1]) == [("release",)] and person.noes == 0  # a reset
    assert person.decide(start, driving=False, target=None) == []


def test_a_holding_person_keeps_its_key_down_from_look_to_look_and_changes_it_with_its_answer():
    class Keyboard:
        def __init__(self):
            self.calls = []

        def __getattr__(self, name):  # press, down, up
            return lambda key: self.calls.append((name, key))

    page = type("Page", (), {"keyboard": Keyboard()})()
    pressing, holding = spp.Keys(page, hold=False), spp.Keys(page, hold=True)
    pressing.answer("y")
    for key in ("y", "y", "n"):
        holding.answer(key)
    holding.let_go()
    holding.let_go()
    assert page.keyboard.calls == [("press", "y"), ("down", "y"), ("up", "y"), ("down", "n"), ("up", "n")]


def test_a_rehearsal_without_the_page_pushes_the_object_nearer_the_goal():
    """--rehearse: the person's push with no browser, from the fixed start; it moves the object towards the goal, and
    with the person's hand idle (no take, no target) it stays about where it is."""
    import gymnasium as gym

    args = spp.Args(seeds=[4], drive=True, rehearse=1, pace=10.0)
    obs, _ = gym.make("Pusher-v5").reset(seed=4)
    start = float(np.linalg.norm(obs[17:19] - obs[20:22]))
    (final,) = spp.rehearse(args)[4]
    assert final < start - 0.01, (start, final)
    idle = spp.DrivingPerson.decide
    try:
        spp.DrivingPerson.decide = lambda self, view, driving, target: []
        (still,) = spp.rehearse(args)[4]
    finally:
        spp.DrivingPerson.decide = idle
    assert abs(still - start) < 0.01 and final < still - 0.01, (start, still, final)  # (the arm drifts from its reset)


def test_with_the_pages_drive_by_object_the_person_aims_at_the_goal_and_the_planner_pushes_it_home():
    """--page-flags "--drive-by object": the person's one click puts the target on the goal (no way round), and in the
    rehearsal the planner pushes the object home from seed 1's fixed start, where the person's own push does not."""
    person = spp.DrivingPerson(np.random.default_rng(0), aim_noise=0.0, drive_by="object")
    start = {"tip": [0.82, -0.6], "object": [0.6, -0.2], "goal": [0.45, -0.05]}
    ((what, *pixel),) = person.decide(start, driving=False, target=None)
    assert what == "click" and np.allclose(spp.from_pixel(*pixel), start["goal"], atol=0.005)
    args = spp.Args(seeds=[1], drive=True, rehearse=1, pace=5.0, page_flags="--drive-by object")
    ((assisted,),) = spp.rehearse(args).values()
    ((own,),) = spp.rehearse(spp.Args(seeds=[1], drive=True, rehearse=1, pace=5.0)).values()
    assert assisted < 0.08 < own, (assisted, own)


@pytest.mark.slow  # Chromium
def test_the_driving_person_takes_the_arm_pushes_and_its_steps_are_marked(tmp_path, monkeypatch):
    why = browser_missing()
    if why:
        if os.environ.get("INFORM_REQUIRE_BROWSER") == "1":
            pytest.fail(why)
        pytest.skip(why)
    import torch

    monkeypatch.setenv("PYTHONPATH", REPO)
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))
    work, out = tmp_path / "work", tmp_path / "out"
    monkeypatch.chdir(tmp_path)  # --work-dir relative: the nights, run in the seed's folder, still find the day
    args = spp.Args(
        seeds=[1],
        out_dir="out",
        work_dir="work",
        steps=300,
        pace=10.0,
        drive=True,
        flags=TINY,
        nights=("bc",),
        page_flags="--takeover-steps 5",
    )  # one night on the saved day (which would refuse the page's flag): the others run as the study's tests run them
    (row,) = spp.main(args)
    (run_dir,) = (work / "seed1" / "runs").glob("*browser_scripted__*")
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "completed" and row["takes"] >= 1 and row["driven steps"] > 50
    with open(run_dir / "answers.jsonl") as f:
        drives = [r for r in map(json.loads, f) if r["event"] == "drive"]
    assert drives[0]["drive"] == "take" and sum(r["drive"] == "target" for r in drives) >= 5
    with open(run_dir / "answers.jsonl") as f:  # the page heard its own flag: each take labelled the steps before it
        labels = [r for r in map(json.loads, f) if r["event"] == "take labels"]
    assert labels and row["steps labelled by the takes"] == sum(len(r["steps"]) for r in labels) > 0
    assert summary["args"]["takeover_steps"] == 5
    day = torch.load(run_dir / "day.pt", weights_only=True)
    driven = day["driven"].nonzero().squeeze(-1)
    assert driven.numel() == summary["feedback/driven_steps"] == row["driven steps"]
    first = int(driven[0])
    assert first <= 20  # taken within the first look and a reaction (a step a 0.1 s)
    # while it drove, the object came nearer the goal than where the episode began it
    start = np.linalg.norm(day["obs"][first, 17:19].numpy() - day["obs"][first, 20:22].numpy())
    reached = np.linalg.norm(
        day["next_obs"][driven][:, 17:19].numpy() - day["next_obs"][driven][:, 20:22].numpy(), axis=1
    )
    assert reached.min() < start - 0.002, (start, reached.min())  # Pusher-v5's contact: millimetres in a short day
    assert (out / "table.md").exists() and "driven steps" in (out / "table.md").read_text()


# the day's run records its id, and this tool gets a SIGTERM once the run has opened its page
SIGTERM_MID_DAY = """
import os, runpy, signal, sys
from inform_utils import scripted_person_browser


class Recorded(scripted_person_browser.Child):
    def wait_for_line(self, prefix, timeout):
        line = super().wait_for_line(prefix, timeout)
        with open("day.pid", "w") as f:
            f.write(str(self.proc.pid))
        os.kill(os.getpid(), signal.SIGTERM)
        return line


scripted_person_browser.Child = Recorded
sys.argv = ["scripted_person_pusher", "--seeds", "1", "--drive", "--steps", "300", "--out-dir", "out"]
runpy.run_module("inform_utils.scripted_person_pusher", run_name="__main__")
"""


@pytest.mark.slow  # Chromium
def test_a_sigterm_mid_day_ends_the_days_run_too(tmp_path):
    """The day's run is in a session of its own (a Ctrl-C at the terminal is the tool's to pass on): a SIGTERM killed
    the tool and left the run, its page and its Pusher going. Now it ends the run as Ctrl-C does: one line, exit 143."""
    why = browser_missing()
    if why:
        pytest.skip(why)
    env = {**os.environ, "PYTHONPATH": REPO, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "OMP_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-c", SIGTERM_MID_DAY], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=300, preexec_fn=default_signals)  # fmt: skip
    pid = int((tmp_path / "day.pid").read_text())
    try:  # (an id used again by another process is not the day's run)
        with open(f"/proc/{pid}/cmdline") as f:
            alive = "inform_utils.browser_pusher" in f.read() and open(f"/proc/{pid}/stat").read().split()[2] != "Z"
    except FileNotFoundError:
        alive = False
    if alive:
        os.kill(pid, signal.SIGKILL)
    assert not alive, "the day's run outlived its tool"
    assert proc.returncode == 143 and proc.stderr.strip().splitlines()[-1] == (
        "interrupted (SIGTERM) before the work was done"
    ), proc.stderr[-2000:]
    assert os.listdir(tmp_path / "out") == []


def test_a_stopped_run_keeps_the_table_of_the_seeds_it_finished(tmp_path, monkeypatch):
    """The table is written after every seed: a run stopped during its second seed leaves the first one's row, saying
    how many of the seeds it holds; a finished run's table says nothing of the kind."""
    row = {"seed": 1, "answers": 3, "yes": 1}
    monkeypatch.setattr(spp, "check_before_writing", lambda args: None)  # (it wants a browser; none is started)
    monkeypatch.setattr(spp, "load_oracle", lambda flags: None)
    monkeypatch.setattr(spp, "run_seed", lambda seed, *rest: {**row, "seed": seed})

    def stopped_after_one(args, prefix, what, run_one):
        os.makedirs(args.out_dir)
        run_one(1, None, None)
        raise KeyboardInterrupt

    monkeypatch.setattr(spp, "each_seed", stopped_after_one)
    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        spp.main(spp.Args(seeds=[1, 2], out_dir=str(out)))
    assert "| 1 | 3 | 1 |" in (out / "table.md").read_text() and "1 of 2 seeds so far" in (out / "table.md").read_text()
    assert json.loads((out / "table.json").read_text()) == [row]
    monkeypatch.setattr(spp, "each_seed", lambda args, p, w, run_one: [os.makedirs(args.out_dir), run_one(1, 0, 0)])
    spp.main(spp.Args(seeds=[1], out_dir=str(tmp_path / "whole")))
    assert "so far" not in (tmp_path / "whole" / "table.md").read_text()


def test_the_table_leaves_a_count_a_seed_lacks_blank_and_out_of_its_mean():
    """A seed whose day had no take has no count of the steps takes labelled: "-" in its cell, and the mean is over
    the seeds that have it (the table was a KeyError, or dropped the column, when seeds differed)."""
    text = spp.markdown([{"seed": 1, "yes": 2, "labelled": 4}, {"seed": 2, "yes": 4}], "cmd")
    assert "| 2 | 4 | - |" in text and "| mean | 3.0 | 4.0 |" in text, text


def test_a_condition_run_in_parts_joins_into_one_table_recounted_from_its_files(tmp_path):
    """--join: the committed five days of results/browser_pusher_takeover_v5/drive, split into two earlier --out-dirs,
    join into one table that gives the run's own table again from the files (the page's counts: the person's tally
    can hold an answer sent as the day ended); a seed given twice, an --out-dir that exists or a folder that does not
    are one line each, and nothing is written."""
    import shutil

    drive = os.path.join(REPO, "results", "browser_pusher_takeover_v5", "drive")
    for part, seeds in (("a", (1, 2)), ("b", (3, 4, 5))):
        for s in seeds:
            shutil.copytree(os.path.join(drive, f"seed{s}"), tmp_path / part / f"seed{s}")
    rows = spp.main(spp.Args(join=(str(tmp_path / "a"), str(tmp_path / "b")), out_dir=str(tmp_path / "all")))
    with open(os.path.join(drive, "table.json")) as f:
        ran = json.load(f)
    assert [r["seed"] for r in rows] == [1, 2, 3, 4, 5] and json.loads(
        (tmp_path / "all" / "table.json").read_text()
    ) == rows
    for got, row in zip(rows, ran, strict=True):
        counts = ("answers", "yes")
        assert {k: v for k, v in got.items() if k not in counts} == {
            k: row[k] for k in row if k not in (*counts, "seconds")
        }
        assert all(0 <= row[k] - got[k] <= 1 for k in counts)  # the person's tally against the page's
    assert sorted(os.listdir(tmp_path / "all" / "seed3")) == sorted(os.listdir(os.path.join(drive, "seed3")))
    for name, kept in (("stopped", ("summary.json", "answers.jsonl")), ("empty", ())):  # a seed stopped mid-night
        os.makedirs(tmp_path / name / "seed6")
        for file in kept:
            shutil.copy(os.path.join(drive, "seed5", file), tmp_path / name / "seed6" / file)
    before = sorted(os.listdir(tmp_path))
    for join, out, phrase in (
        ((tmp_path / "a", tmp_path / "all"), tmp_path / "new", "seed1 is in"),
        ((tmp_path / "a",), tmp_path / "all", "exists; give a new directory"),
        ((tmp_path / "nowhere",), tmp_path / "new", "no such folder"),
        ((tmp_path / "a", tmp_path / "stopped"), tmp_path / "new", "the seeds' nights differ"),
        ((tmp_path / "empty",), tmp_path / "new", "is not a seed's folder of a finished day"),
    ):
        with pytest.raises(spp.BadInput, match=phrase):
            spp.main(spp.Args(join=tuple(map(str, join)), out_dir=str(out)))
    assert sorted(os.listdir(tmp_path)) == before
