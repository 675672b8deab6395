"""The web page's reference numbers on the Pusher: a scripted person teaches `python -m inform_utils.browser_pusher`
through the page in Debian's Chromium (headless, driven by Playwright). It answers at a person's rate: it looks at the
step on the screen (at most `--period` seconds apart), judges it as the run's oracle would (Eq. 4 on the state and
action the page was sent, at the day's alpha), and presses y or n after a reaction time drawn uniformly from
`--reaction`. The page credits each answer to what it showed 0.2-4 s before (Deep TAMER's window). The day is the
runner's: `--tamer-total-timesteps` steps at `--pace` steps a second (the defaults: 3,000 steps at 10 a second, five
minutes), then the night. Then, per seed, three more nights on the saved day (inform_utils/sleep_variants_pusher.py
--sleep-from): behaviour cloning (bc), the sham (TAMER's own update) and the core night again. Per seed and their
mean: the answers (yes, no), and TAMER, INFORM and both controls: the final distance and success from the run's start.

    python -m inform_utils.scripted_person_pusher --seeds 1 2 3 4 5 --out-dir results/browser_pusher

With --drive the scripted person also takes the arm (issue 53): at each episode's start, seen on the page's map, it
clicks the map to take the arm and pushes the object to the goal with the target (clicks for big moves, arrow keys for
small ones), a reaction time from each look at the map to what it does, its aim off by --aim-noise; it gives the arm
back when the object is at the goal, and answers y/n as above while the agent drives (DrivingPerson says its rules).
With --take-after-noes N it watches the agent first and takes the arm only after N no's in a row in the episode; with
"--page-flags=--drive-by object" its target is the goal, and the page's planner pushes the object there.
Its rules are a script's: its numbers are the page's reference numbers, not a person's. The table adds its takes, the
steps it drove and the day's episodes and successful ones. With --hold the person keeps its y or n down from one look
to the next (the page answers again every 250 ms while a key is down), and the table adds the page's count.

    python -m inform_utils.scripted_person_pusher --seeds 1 --drive --steps 1200 --out-dir /tmp/drive

{out_dir}/table.md and table.json, and each seed's summary.json (the day's, and each night's as
summary_{bc,sham,core}.json) and answers.jsonl under {out_dir}/seed{S}/; the runs themselves in a temporary directory,
removed, or kept in --work-dir. Neither directory may exist: nothing is overwritten. A condition run in parts (a
seed stopped and run again) is one table with --join: the seed folders of earlier --out-dirs, copied into a new one.

    python -m inform_utils.scripted_person_pusher --join /tmp/drive /tmp/drive_seeds2to5 --out-dir /tmp/drive_all
"""

import contextlib
import json
import math
import os
import random
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import tyro

from inform_utils.files import BadInput, atomic, cut, run_tool, write_json
from inform_utils.scripted_person_browser import Child, check_before_writing, each_seed, new_run, runs_in

POLICIES = ("tamer", "inform", "bc", "sham", "core")  # the day's two, then the nights on the saved day
CONTROLS = ("bc", "sham", "core")  # --sleep-control bc, sham, none


@dataclass
class Args:
    seeds: list[int] = field(default_factory=lambda: [1, 2, 3, 4, 5])
    """seeds of the days taught, one after the other"""
    out_dir: str = "results/browser_pusher"
    """where the table and each seed's summary.json and answers.jsonl go; it must not exist"""
    work_dir: str | None = None
    """keep the runs in {work_dir}/seed{S}/runs/; it must not exist (default: a temporary directory, removed)"""
    steps: int = 3000
    """the day's environment steps (the runner's --tamer-total-timesteps)"""
    pace: float = 10.0
    """steps a second on the page (the runner's --pace)"""
    period: float = 1.0
    """the longest time from one look at the screen to the next (each look gives one answer): after its key press
    the person waits period minus the longest reaction, so at the defaults it looks every 0.5-1.0 s"""
    reaction: tuple[float, float] = (0.3, 0.8)
    """seconds from a look to the key press, uniformly"""
    flags: str = ""
    """extra flags for the day's run and the nights, as one string (e.g. --flags "--obstacle-episodes 20")"""
    page_flags: str = ""
    """flags of the page alone (browser_pusher's), for the day's run and not the nights, as one string (e.g.
    --page-flags "--takeover-steps 5 --no-driven-in-h")"""
    timeout: float = 3600.0
    """seconds a seed may take, day and nights"""
    drive: bool = False
    """the person also takes the arm at an episode's start and pushes the object to the goal through the page's map
    (DrivingPerson), answering y/n while the agent drives; without it, answers only"""
    drive_every: int = 1
    """with --drive: the person drives every N-th episode it sees start and watches the others (1: every one)"""
    aim_noise: float = 0.01
    """with --drive: metres, the standard deviation (per axis) of where the person puts the target from the point
    it means"""
    hold: bool = False
    """hold the answer's key down until the next look instead of pressing it once (the page answers again every
    250 ms while a key is held: GUIDE's continuous feedback); the judgement is made again at each look"""
    nights: tuple[Literal["bc", "sham", "core"], ...] = CONTROLS
    """the nights run on the saved day after the day's own: cloning the success set (bc), the sham, the core night
    again (core)"""
    rehearse: int | None = None
    """with --drive: no page and no browser; the driving person's push rehearsed for this many episodes from each
    seed's fixed start (rehearse() says how), printed per seed; nothing is written"""
    push_lead: float = 0.05
    """with --drive: metres ahead of the object's centre, on its line to the goal, that the person keeps the target
    while pushing"""
    take_after_noes: int = 0
    """with --drive: 0, take the arm at the start of each episode it drives; N, watch the agent first, answering y/n,
    and take the arm once it has said no N times in a row in the episode (a person who takes over when the agent goes
    wrong, as RLIF's do)"""
    join: tuple[str, ...] = ()
    """no day is taught: the seed{S} folders of these --out-dirs of earlier runs are copied into the new --out-dir and
    its table is made from their files (recount says how)"""


def judge(oracle, state: dict, alpha: tuple[float, float], steps: int) -> bool:
    """The oracle's answer (Eq. 4) about the state and action the page was sent for its current step."""
    import torch

    import inform_sac_pusher as isp

    obs = torch.as_tensor(state["info"]["_obs"], dtype=torch.float32)
    action = torch.as_tensor(state["info"]["_action"], dtype=torch.float32)
    with torch.no_grad():
        q_sa, q_best = isp.oracle_q(*oracle, obs, action)
    return bool(isp.oracle_feedback(q_sa, q_best, isp.linear_schedule(*alpha, steps - 1, state["step"])))


class Keys:
    """The person's y / n key: pressed once, or (hold) kept down from one look to the next, changed when the answer
    changes, let go when the person stops answering."""

    def __init__(self, page, hold: bool):
        self.page, self.hold, self.down = page, hold, None

    def answer(self, key: str) -> None:
        if not self.hold:
            self.page.keyboard.press(key)
        elif key != self.down:
            self.let_go()
            self.page.keyboard.down(key)
            self.down = key

    def let_go(self) -> None:
        if self.down is not None:
            self.page.keyboard.up(self.down)
            self.down = None


def wait_for_stream(page) -> dict:
    """The page's state once the day has started."""
    state, deadline = None, time.monotonic() + 300
    while state is None or state["mode"] not in ("stream", "ended", "outcome", "closed"):  # the day starts
        if time.monotonic() > deadline:
            raise RuntimeError(f"the page did not start streaming within 300 s (its state: {state})")
        time.sleep(0.2)
        state = page.evaluate("typeof state === 'undefined' ? null : state")  # (the page's CSP forbids polling JS)
    return state


def teach_day(page, oracle, seed: int, args: Args, say) -> dict:
    """Look and answer until the page says the day is over; the answers given."""
    rng, given, keys = random.Random(seed), {"yes": 0, "no": 0}, Keys(page, args.hold)
    state = wait_for_stream(page)
    while True:
        state = page.evaluate("state")
        if state["ended"] or state["mode"] != "stream":
            break
        if state["info"].get("_action") is not None:
            yes = judge(oracle, state, (0.99, 0.992), args.steps)
            time.sleep(rng.uniform(*args.reaction))
            keys.answer("y" if yes else "n")
            given["yes" if yes else "no"] += 1
            if sum(given.values()) % 60 == 0:
                say(f"[seed {seed}] day: step {state['step']}, answers yes {given['yes']}, no {given['no']}")
        time.sleep(max(0.0, args.period - args.reaction[1]))
    keys.let_go()
    say(f"[seed {seed}] the day is over ({state['ended'] or state['mode']}): yes {given['yes']}, no {given['no']}")
    return given


# ---------------------------------------------------------------------------------------------------------------------
# ALGO LOGIC: the driving person (--drive): what it sees on the map, and what it does about it
# the page's map, turned as its 3D view: x from top to bottom, y from left to right (metres), pixels a side
MAP_VIEW = ((-0.1, 0.9), (-0.8, 0.2), 240)
ARROW = 0.02  # metres an arrow key moves the target (the page's)
KEYS = {"ArrowRight": (0, 1), "ArrowLeft": (0, -1), "ArrowUp": (-1, 0), "ArrowDown": (1, 0)}  # as the map shows them


class DrivingPerson:
    """A person's push, decided from the page's map alone (the fingertip, the object and the goal, in the table's
    plane) and the target it set itself. At an episode's start (seen on the map: the fingertip back at its start
    pose, or the object back where the last episode began) it takes the arm with a click on the map, moves the target
    round behind the object on the goal's line (a waypoint beside the object first if the straight way there would
    knock it), waits a look there for the arm to settle, then pushes: the target `lead` ahead of the object on its
    line to the goal (a little past the goal at the end), re-aimed at every decision as the object drifts and steered
    back onto the line; round again if the fingertip leaves the line or goes through the object. It gives the arm
    back (g) when the object is at the goal, or at the start of an episode it will not drive. Every point it aims at
    is off by `aim_noise` (metres, Gaussian, per axis) and lands on the map's pixel; a move of less than `small` is
    made by arrow presses (2 cm each, as many as the noisy difference rounds to), a bigger one by a click. It drives
    every `every`-th episode it sees start (1: every one) and watches the others; with `take_after` N > 0 it takes the
    arm in those only after N no answers in a row about the agent (`heard`), and gives it back at each episode's start
    to watch again. With the page's `--drive-by object`
    (a planner pushes the object to the target) it aims the target at the goal itself. Its rules are a script's, tuned
    by nobody: its numbers are the page's reference numbers, not a person's."""

    STANDOFF = 0.11  # metres behind the object's centre where the push starts (0.15 is out of the arm's reach at
    # the table's height at seed 1's fixed start, 0.76 m from the shoulder)
    CLEARANCE = 0.18  # sideways from the object's centre when going round it (the crossbar's half-length + 6 cm)
    KNOCK = 0.12  # a straight way from ahead of the object passing its centre closer than this would knock it
    ON_LINE = 0.07  # the push goes on while the fingertip is this close to the object's line to the goal
    READY = 0.04  # the fingertip this close to the point behind on two looks in a row: push
    AT_GOAL = 0.05  # the object's centre this close to the goal's: done, give the arm back
    PAST = 0.03  # the last aim: this far past the goal
    JUMP = 0.2  # the fingertip this much nearer its start pose than a look before: a reset (no drive is so fast)

    def __init__(self, rng, aim_noise: float = 0.01, lead: float = 0.05, small: float = 0.05, every: int = 1,
                 drive_by: str = "fingertip", take_after: int = 0):  # fmt: skip
        self.rng, self.aim_noise, self.lead, self.small, self.every = rng, aim_noise, lead, small, every
        self.drive_by = drive_by  # the page's --drive-by: what the target moves
        self.take_after, self.noes = take_after, 0  # take after this many no's in a row; the no's so far
        self.tip_start = self.object_start = self.last = None
        self.episodes = 0  # the episodes seen start
        self.mine = self.pushing = False  # this episode is one it drives (until done); it is pushing now
        self.arrived = False  # the fingertip was behind the object at the last look

    def new_episode(self, view: dict) -> bool:
        """Whether the map shows an episode's start: the first look of the day, the fingertip back at its start pose,
        or the object back where the last episode began (from somewhere else)."""
        tip, obj = np.array(view["tip"]), np.array(view["object"])
        if self.last is None:
            self.tip_start, started = tip, True
        else:
            tip_back = np.linalg.norm(self.last[0] - self.tip_start) - np.linalg.norm(tip - self.tip_start) > self.JUMP
            was_away = np.linalg.norm(self.last[1] - self.object_start) > 0.03
            started = tip_back or (was_away and np.linalg.norm(obj - self.object_start) < 0.01)
        self.last = (tip, obj)
        if started:
            self.object_start = obj
        return started

    def decide(self, view: dict, driving: bool, target) -> list:
        """What to do about one look at the map: [] (nothing), [("release",)], or a move: [("click", x, y)] (which
        also takes the arm) or [("arrows", key, presses), ...]."""
        if self.new_episode(view):
            self.episodes += 1
            self.mine, self.pushing, self.noes = (self.episodes - 1) % self.every == 0, False, 0
            if not self.mine or self.take_after:  # not its episode, or it watches the agent first
                return [("release",)] if driving else []
        if not self.mine or (not driving and self.noes < self.take_after):  # not its episode, or the agent's so far
            return []
        tip, obj, goal = (np.array(view[k]) for k in ("tip", "object", "goal"))
        distance = np.linalg.norm(goal - obj)
        if distance < self.AT_GOAL:
            self.mine = False
            return [("release",)] if driving else []
        wanted = goal if self.drive_by == "object" else self.aim(tip, obj, goal, distance)
        return self.move(wanted, target if driving else None)

    def heard(self, yes: bool) -> None:
        """The person's own answer about the agent's step: a yes ends a run of no's."""
        self.noes = 0 if yes else self.noes + 1

    def aim(self, tip, obj, goal, distance) -> np.ndarray:
        """The point the person wants the target at: behind the object, round it, or ahead of it on the push."""
        u = (goal - obj) / distance
        n = np.array([-u[1], u[0]])
        along, lateral = (tip - obj) @ u, (tip - obj) @ n
        behind = obj - self.STANDOFF * u
        if self.pushing and (abs(lateral) > self.ON_LINE or along > 0.0):
            self.pushing = False  # off the line, or through the object: round again
        arrived = np.linalg.norm(tip - behind) < self.READY
        if not self.pushing and arrived and self.arrived:  # there on two looks: settled (and down at the table)
            self.pushing = True
        self.arrived = arrived
        if self.pushing:
            return obj + min(self.lead, distance + self.PAST) * u - lateral * n  # and steer back onto the line
        knocks = along > -self.STANDOFF + 0.03 and distance_to_segment(obj, tip, behind) < self.KNOCK
        if knocks:  # the straight way would knock it: beside it first
            return behind + (np.sign(lateral) or 1.0) * self.CLEARANCE * n
        return behind

    def move(self, wanted: np.ndarray, target) -> list:
        aimed = wanted + self.rng.normal(0.0, self.aim_noise, 2)
        if target is not None and np.linalg.norm(aimed - np.array(target)) < self.small:
            presses = np.rint((aimed - np.array(target)) / ARROW).astype(int)
            keys = [("ArrowDown" if presses[0] > 0 else "ArrowUp", abs(presses[0])),
                    ("ArrowRight" if presses[1] > 0 else "ArrowLeft", abs(presses[1]))]  # fmt: skip
            return [("arrows", key, count) for key, count in keys if count]
        px, py = to_pixel(aimed)
        return [("click", px, py)]


def to_pixel(point) -> tuple[int, int]:
    """The map's pixel of a point in the table's plane (as the page's toMap, rounded)."""
    (x0, x1), (y0, y1), size = MAP_VIEW
    px, py = (point[1] - y0) / (y1 - y0) * size, (point[0] - x0) / (x1 - x0) * size
    return int(np.clip(round(px), 0, size - 1)), int(np.clip(round(py), 0, size - 1))


def from_pixel(px: int, py: int) -> np.ndarray:
    """The point a click on the map's pixel sets (as the page's fromMap, before it holds a point beyond the arm's
    reach on it)."""
    (x0, x1), (y0, y1), size = MAP_VIEW
    return np.array([x0 + py / size * (x1 - x0), y0 + px / size * (y1 - y0)])


def distance_to_segment(p, a, b) -> float:
    ab = b - a
    t = np.clip((p - a) @ ab / max(ab @ ab, 1e-12), 0.0, 1.0)
    return float(np.linalg.norm(p - (a + t * ab)))


# what the person sees: the page's state, and the target the page draws (its own last one, or the server's)
LOOK = "[state, state && state.driving ? ((typeof myTarget !== 'undefined' && myTarget) || state.target) : null]"
MAP_BOX = (
    "(() => { const r = document.getElementById('map').getBoundingClientRect(); return [r.left, r.top, r.width]; })()"
)


def drive_day(page, oracle, seed: int, args: Args, say) -> dict:
    """Look at the map and act as DrivingPerson decides, a reaction time after each look, until the page says the day
    is over; while the agent drives, answer y/n as teach_day does. What was given: answers, takes, clicks, arrow
    presses, releases."""
    rng = random.Random(seed)
    person = DrivingPerson(np.random.default_rng(seed), args.aim_noise, args.push_lead, every=args.drive_every,
                           drive_by=page_drive_by(args), take_after=args.take_after_noes)  # fmt: skip
    given = dict.fromkeys(("yes", "no", "takes", "clicks", "arrow presses", "releases"), 0)
    keys, state = Keys(page, args.hold), wait_for_stream(page)
    while True:
        state, target = page.evaluate(LOOK)
        if state["ended"] or state["mode"] != "stream":
            break
        view = state["info"].get("_map")
        acts = [] if view is None else person.decide(view, state["driving"], target)
        if acts or (state["driving"] and person.mine):  # the person drives: one decision each reaction time
            keys.let_go()
            time.sleep(rng.uniform(*args.reaction))
            act(page, acts, state["driving"], given)
            continue
        if state["info"].get("_action") is not None and not state["driving"]:  # the agent drives: judge it
            yes = judge(oracle, state, (0.99, 0.992), args.steps)
            time.sleep(rng.uniform(*args.reaction))
            keys.answer("y" if yes else "n")
            given["yes" if yes else "no"] += 1
            person.heard(yes)
            if (given["yes"] + given["no"]) % 60 == 0:
                say(f"[seed {seed}] day: step {state['step']}, " + ", ".join(f"{k} {v}" for k, v in given.items()))
        time.sleep(max(0.0, args.period - args.reaction[1]))
    keys.let_go()
    say(f"[seed {seed}] the day is over ({state['ended'] or state['mode']}): "
        + ", ".join(f"{k} {v}" for k, v in given.items()))  # fmt: skip
    return given


def act(page, acts: list, driving: bool, given: dict) -> None:
    """Do what the person decided, with the page's own inputs: a click on the map's pixel, arrow keys, g."""
    for what, *how in acts:
        if what == "release":
            page.keyboard.press("g")
            given["releases"] += 1
        elif what == "arrows":
            key, presses = how
            for _ in range(presses):
                page.keyboard.press(key)
                time.sleep(0.08)  # a person's presses, about 12 a second
            given["arrow presses"] += presses
        else:  # a click on the map at the pixel (the page's own mapping from the canvas's box to its pixels)
            page.locator("#map").scroll_into_view_if_needed()
            left, top, width = page.evaluate(MAP_BOX)
            px, py = how
            page.mouse.click(left + px * width / MAP_VIEW[2], top + py * width / MAP_VIEW[2])
            given["takes" if not driving else "clicks"] += 1
            driving = True


def run_flag(run_flags: list[str], flag: str, default: str) -> str:
    """A flag's value in the runs' flags, `--flag VALUE` or `--flag=VALUE`, the last one as tyro reads it (`default`,
    the core script's, otherwise)."""
    value = default
    for i, word in enumerate(run_flags):
        if word == flag and i + 1 < len(run_flags):
            value = run_flags[i + 1]
        elif word.startswith(f"{flag}="):
            value = word.split("=", 1)[1]
    return value


def run_env_id(run_flags: list[str]) -> str:
    return run_flag(run_flags, "--env-id", "Pusher-v5")


def page_drive_by(args: Args) -> str:
    """The page's --drive-by in --page-flags: what the person's target moves."""
    return run_flag(shlex.split(args.page_flags), "--drive-by", "fingertip")


def load_oracle(run_flags: list[str]):
    """The oracle the runs load (the shipped one of the --env-id and --contact in `run_flags`), to judge as it does."""
    import torch

    import inform_sac_pusher as isp

    env_id, contact = run_env_id(run_flags), run_flag(run_flags, "--contact", "mujoco-2.3")
    return isp.oracle_from_checkpoint(isp.load_oracle(env_id, contact, None, False, 0), torch.device("cpu"))


def run_seed(seed: int, args: Args, browser, oracle, work: str, out: str, say) -> dict:
    cwd = os.path.join(work, f"seed{seed}")
    os.makedirs(cwd)
    deadline, t0 = time.monotonic() + args.timeout, time.monotonic()
    cmd = [sys.executable, "-m", "inform_utils.browser_pusher", "--participant", "scripted", "--seed", str(seed),
           "--tamer-total-timesteps", str(args.steps), "--pace", str(args.pace), "--save-buffer",
           "--exp-name", "browser_scripted", *shlex.split(args.flags), *shlex.split(args.page_flags)]  # fmt: skip
    child, context = Child(cmd, cwd, os.path.join(cwd, "day.log")), None
    try:
        url = child.wait_for_line("[teacher] open the teaching page", timeout=300).split(": ", 1)[1].strip()
        context = browser.new_context(viewport={"width": 900, "height": 900})
        page = context.new_page()
        page.goto(url)
        given = (drive_day if args.drive else teach_day)(page, oracle, seed, args, say)
        page.wait_for_selector("#outcome:visible", timeout=max(deadline - time.monotonic(), 1) * 1000)
        code = child.finish(deadline - time.monotonic())
    except BaseException:
        with contextlib.suppress(subprocess.TimeoutExpired):
            child.finish(0)  # kills it
        say("".join(child.tail[-20:]))
        raise
    finally:
        if context is not None:
            context.close()
    if code != 0:
        raise RuntimeError(f"seed {seed}: the day's run exited {code}; {cwd}/day.log\n{''.join(child.tail)}")
    run = new_run(cwd, set())
    os.makedirs(os.path.join(out, f"seed{seed}"))
    for name in ("summary.json", "answers.jsonl"):
        shutil.copy(os.path.join(run, name), os.path.join(out, f"seed{seed}", name))
    with open(os.path.join(run, "summary.json")) as f:
        summaries = {"day": json.load(f)}
    for name in args.nights:
        before = runs_in(cwd)
        control = "none" if name == "core" else name
        cmd = [sys.executable, "-m", "inform_utils.sleep_variants_pusher", "--sleep-from", run, "--sleep-control",
               control, "--exp-name", f"browser_scripted_{name}", *shlex.split(args.flags)]  # fmt: skip
        night = Child(cmd, cwd, os.path.join(cwd, f"night_{name}.log"))
        if night.finish(deadline - time.monotonic()) != 0:
            raise RuntimeError(f"seed {seed}: the {name} night failed; {cwd}/night_{name}.log\n{''.join(night.tail)}")
        shutil.copy(os.path.join(new_run(cwd, before), "summary.json"),
                    os.path.join(out, f"seed{seed}", f"summary_{name}.json"))  # fmt: skip
        with open(os.path.join(new_run(cwd, before), "summary.json")) as f:
            summaries[name] = json.load(f)
    with open(os.path.join(out, f"seed{seed}", "answers.jsonl")) as f:
        events = [json.loads(line) for line in f]
    held = sum(e.get("event") == "answer" for e in events) if args.hold else None  # each held key's repeats too
    row = seed_row(seed, given, summaries, held, take_labelled(events))
    row["seconds"] = round(time.monotonic() - t0, 1)
    say(f"[seed {seed}] done in {row['seconds']:.0f}s: " + ", ".join(f"{k} {v}" for k, v in row.items()))
    return row


def take_labelled(events: list[dict]) -> int | None:
    """The page's --takeover-steps: the agent's steps its takes labelled, from answers.jsonl (None: no take did)."""
    labels = [len(e["steps"]) for e in events if e.get("event") == "take labels"]
    return sum(labels) if labels else None


def write_table(folder: str, rows: list[dict], note: str = "") -> str:
    """{folder}/table.md (the command that made it, the rows, their mean, then `note`) and table.json; the markdown."""
    text = markdown(rows, "python -m inform_utils.scripted_person_pusher " + " ".join(sys.argv[1:])) + note
    with atomic(os.path.join(folder, "table.md")) as f:
        f.write(text)
    write_json(os.path.join(folder, "table.json"), rows)
    return text


def seed_row(seed: int, given: dict, summaries: dict, held: int | None = None, labelled: int | None = None) -> dict:
    day = summaries["day"]
    row = {"seed": seed, "answers": given["yes"] + given["no"], "yes": given["yes"]}
    if held is not None:  # --hold: each look's answer repeated while its key was down; the page's count
        row["answers with the key held"] = held
    if labelled is not None:  # the page's --takeover-steps: the agent's steps its takes labelled
        row["steps labelled by the takes"] = labelled
    row.update({"steps": day["feedback/steps"], "yes labels reaching TAMER": day["feedback/positive"]})
    if "takes" in given:  # the driving person (--drive)
        row.update({"takes": given["takes"], "driven steps": day["feedback/driven_steps"]})
        row.update({"day's episodes": day["sleep/episodes"], "day's success episodes": day["sleep/success_episodes"]})
    for p in [p for p in POLICIES if p in ("tamer", "inform") or p in summaries]:
        s, slot = (day, p) if p in ("tamer", "inform") else (summaries[p], "inform")
        row[f"{p} distance"] = round(s[f"eval/{slot}_final_distance"], 4)
        row[f"{p} success"] = s[f"eval/{slot}_success_rate"]
        for test, short in (("obstacle", "boxes"), ("authors_test", "authors'")):  # the two tests, when they ran
            if f"eval/{test}/{slot}_final_distance" in s:
                row[f"{p} {short} distance"] = round(s[f"eval/{test}/{slot}_final_distance"], 4)
                row[f"{p} {short} success"] = s[f"eval/{test}/{slot}_success_rate"]
    row["oracle distance"] = round(day["eval/oracle_final_distance"], 4)
    return row


def markdown(rows: list[dict], command: str) -> str:
    """The table; a column some seeds lack (a count of what did not happen that day) is "-" there, out of its mean."""
    keys = list(dict.fromkeys(k for r in rows for k in r))
    mean = {k: round(float(np.mean([r[k] for r in rows if k in r])), 4) for k in keys if k != "seed"}
    lines = [f"`{command}`", "", "| " + " | ".join(keys) + " |", "|" + " --- |" * len(keys)]
    lines += ["| " + " | ".join(str(r.get(k, "-")) for k in keys) + " |" for r in rows]
    lines.append("| mean | " + " | ".join(str(mean[k]) for k in keys[1:]) + " |")
    return "\n".join(lines) + "\n"


def rehearse(args: Args) -> dict[int, list[float]]:
    """The driving person's push without the page: DrivingPerson sees the positions the map would show and acts a
    reaction time later (uniform over --reaction, in steps at --pace), then looks again; the page's controller follows
    its target. Per seed, `--rehearse` episodes from the run's fixed start (reset with the seed), the person driving
    each from its first look (the agent's steps before the take are idle here, not TAMER's) and, as at the page,
    letting go once the object is at the goal. What it leaves out: the page's frames and timing, arrow presses taking
    time. The page holds a target beyond the arm's reach on it, and so does the rehearsal. With `--drive-by object` in
    --page-flags the planner (MPPI, seeded with the seed) pushes the object to the target, as at the page. Returns
    {seed: final distances}."""
    import inform_sac_pusher as isp
    from browser_teacher import clamp_to_reach
    from inform_utils.pusher_control import PersonHand, arm_reach

    env_id = run_env_id(shlex.split(args.flags))
    env = isp.make_env(env_id, 0, contact=run_flag(shlex.split(args.flags), "--contact", "mujoco-2.3"))
    reach, drive_by, finals = arm_reach(env.unwrapped.model), page_drive_by(args), {}
    for seed in args.seeds:
        rng, finals[seed] = np.random.default_rng(seed), []
        person = DrivingPerson(np.random.default_rng(seed), args.aim_noise, args.push_lead, drive_by=drive_by)
        hand = PersonHand(env, drive_by, seed)
        for _ in range(args.rehearse):
            obs, _ = env.reset(seed=seed)
            target, driving, acts, due, info = None, False, None, 0, {}
            for step in range(env.spec.max_episode_steps):
                if acts is not None and step >= due:  # the reaction time is over: do it
                    for what, *how in acts:
                        if what == "release":
                            driving = False
                        elif what == "arrows":  # (the page moves the target a press at a time, each held to the reach)
                            key, presses = how
                            for _ in range(presses):
                                target = clamp_to_reach(np.array(target) + ARROW * np.array(KEYS[key]), reach)[0]
                        else:
                            if not driving:  # a take, as the page's
                                hand.take()
                            target, driving = clamp_to_reach(from_pixel(*how), reach)[0], True
                    acts = None
                if acts is None:  # look
                    view = {"tip": obs[14:16], "object": obs[17:19], "goal": obs[20:22]}
                    acts = person.decide(view, driving, None if target is None else list(target))
                    due = step + round(rng.uniform(*args.reaction) * args.pace)
                action = hand(obs, target) if driving else np.zeros(env.action_space.shape)
                obs, _, _, _, info = env.step(action)
            finals[seed].append(abs(float(info["reward_dist"])))
        d = np.array(finals[seed])
        say(f"seed {seed}: {int((d < 0.08).sum())} of {len(d)} episodes succeed, final distance {d.mean():.3f} m "
            f"(best {d.min():.3f}) on {env_id} at {args.pace:g} steps a second")  # fmt: skip
    env.close()
    return finals


def say(text: str) -> None:
    print(text, flush=True)


def check_args(args: Args) -> None:
    """Before the rehearsal or the page: every flag's range and the runs' flags; BadInput, one line."""
    import inform_sac_pusher as isp

    if args.rehearse is not None and not args.drive:
        raise BadInput("--rehearse rehearses the driving person's push: it needs --drive")
    if args.take_after_noes < 0 or (args.take_after_noes and (not args.drive or args.rehearse is not None)):
        raise BadInput(f"--take-after-noes must be >= 0, and is when the driving person takes the arm at the page: it "
                       f"needs --drive and no --rehearse, got {args.take_after_noes}")  # fmt: skip
    if args.rehearse is not None and args.rehearse < 1:
        raise BadInput(f"--rehearse must be >= 1 episode, got {args.rehearse}")
    if not args.seeds or min(args.seeds) < 0:
        raise BadInput(f"--seeds must be one or more seeds >= 0, got {' '.join(map(str, args.seeds)) or 'none'}")
    if min(args.steps, args.drive_every) < 1:
        raise BadInput(f"--steps and --drive-every must be >= 1, got {args.steps} and {args.drive_every}")
    if not (0 < args.pace <= 100 and 0 < args.period < math.inf and 0 < args.timeout < math.inf):  # the page's pace
        raise BadInput(f"--pace must be in (0, 100] steps a second, --period and --timeout above 0 seconds, got "
                       f"{args.pace}, {args.period}, {args.timeout}")  # fmt: skip
    low, high = args.reaction
    if not 0 <= low <= high < math.inf:
        raise BadInput(f"--reaction must be LOW HIGH seconds with 0 <= LOW <= HIGH, got {low} {high}")
    if not (0 <= args.aim_noise < math.inf and math.isfinite(args.push_lead)):
        raise BadInput(f"--aim-noise must be 0 or more and --push-lead finite, got {args.aim_noise}, {args.push_lead}")
    for name, flags in (("--flags", args.flags), ("--page-flags", args.page_flags)):
        try:
            shlex.split(flags)
        except ValueError as e:  # an unclosed quote
            raise BadInput(f"{name} {cut(repr(flags), 200)}: {e} (one string of a command line's words)") from None
    drive_by = page_drive_by(args)
    if drive_by not in ("fingertip", "object") or "--drive-by" in " ".join(shlex.split(args.flags)):
        raise BadInput(f"--page-flags: --drive-by must be fingertip or object, got {cut(drive_by, 40)} (a page flag: "
                       "in --page-flags, not --flags)")  # fmt: skip
    env_id = run_env_id(shlex.split(args.flags))
    if env_id not in isp.PUSHER_IDS:
        raise BadInput(f"--flags: --env-id {cut(env_id, 80)}: the person pushes Pusher's object at the page; pass one "
                       f"of {', '.join(isp.PUSHER_IDS)}")  # fmt: skip


def recount(folder: str) -> dict:
    """A seed's row of the table from its folder's files: the runs' summaries, and answers.jsonl for the counts the
    person's own tally gave (the page's count of the answers, yes and takes that reached it: an answer or a take sent
    as the day ended is not there; with --hold each repeat is an answer, and a --drive day without a take has no
    takes column). No seconds: the files do not say. BadInput if a file is missing or not a run's."""
    try:
        with open(os.path.join(folder, "answers.jsonl")) as f:
            events = [json.loads(line) for line in f]
        answers = [e["answer"] for e in events if e.get("event") == "answer"]
        given = {"yes": answers.count("yes"), "no": answers.count("no")}
        if drives := [e["drive"] for e in events if e.get("event") == "drive"]:
            given["takes"] = drives.count("take")
        summaries = {}
        for name, file in (("day", "summary.json"), *((n, f"summary_{n}.json") for n in CONTROLS)):
            if name == "day" or os.path.exists(os.path.join(folder, file)):
                with open(os.path.join(folder, file)) as f:
                    summaries[name] = json.load(f)
        return seed_row(int(os.path.basename(folder)[4:]), given, summaries, None, take_labelled(events))
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as e:
        raise BadInput(f"--join: {cut(folder, 200)} is not a seed's folder of a finished day ({type(e).__name__}: "
                       f"{cut(e, 100)})") from None  # fmt: skip


def join(args: Args) -> list[dict]:
    """--join: every seed's row read before anything is written, then the new --out-dir made whole or not at all."""
    found = {}
    for out in args.join:
        if not os.path.isdir(out):
            raise BadInput(f"--join {cut(out, 200)}: no such folder (give --out-dirs of earlier runs)")
        for name in filter(re.compile(r"seed\d+").fullmatch, os.listdir(out)):
            if name in found:
                raise BadInput(f"--join: {name} is in {cut(found[name], 100)} and in {cut(out, 100)}; give a seed "
                               "once")  # fmt: skip
            found[name] = out
    if not found:
        raise BadInput(f"--join: no seed{{S}} folder in {cut(' '.join(args.join), 200)}")
    if os.path.lexists(args.out_dir):
        raise BadInput(f"--out-dir {args.out_dir} exists; give a new directory (nothing is overwritten)")
    names = sorted(found, key=lambda n: int(n[4:]))
    rows = [recount(os.path.join(found[n], n)) for n in names]
    nights = {n: sorted(f for f in os.listdir(os.path.join(found[n], n)) if f.startswith("summary_")) for n in names}
    if len({tuple(v) for v in nights.values()}) > 1:  # the folder is made before the nights: one may have stopped
        said = "; ".join(f"{n}: {' '.join(v) or 'none'}" for n, v in nights.items())
        raise BadInput(f"--join: the seeds' nights differ ({cut(said, 300)}); join seeds whose nights all ran")
    parent = os.path.dirname(os.path.abspath(args.out_dir))
    os.makedirs(parent, exist_ok=True)
    staging = tempfile.mkdtemp(prefix=".join_", dir=parent)
    os.chmod(staging, 0o755)  # as a folder made by makedirs (mkdtemp's is the owner's alone)
    try:
        for n in names:
            shutil.copytree(os.path.join(found[n], n), os.path.join(staging, n))
        text = write_table(staging, rows)
        os.rename(staging, args.out_dir)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    say(text + f"\n{len(rows)} seeds joined into {args.out_dir}")
    return rows


def main(args: Args) -> list[dict] | dict:
    if args.join:
        return join(args)
    check_args(args)
    if args.rehearse is not None:
        return rehearse(args)
    check_before_writing(args)
    oracle = load_oracle(shlex.split(args.flags))
    what = f"the scripted person teaches the Pusher, seeds {args.seeds}, at the page"

    rows = []

    def run_one(seed, browser, work):  # the table after every seed: a stopped run keeps the seeds it finished
        rows.append(run_seed(seed, args, browser, oracle, work, args.out_dir, say))
        return write_table(args.out_dir, rows, "" if len(rows) == len(args.seeds) else
                           f"\n{len(rows)} of {len(args.seeds)} seeds so far\n")  # fmt: skip

    say("\n" + each_seed(args, "scripted_person_pusher_", what, run_one)[-1])
    return rows


if __name__ == "__main__":
    run_tool(main, tyro.cli(Args))
