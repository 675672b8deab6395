"""The Pusher's page, round two (issue 69): a page a newcomer understands, and the take-over as a signal.

Without a browser: the arm's reach is where the controller gets the fingertip; the server holds a far target on it and
says so; a take labels the agent's last k steps of the episode before it (RLIF's -1, in answers.jsonl) and
--no-driven-in-h keeps the driven rows out of H's batch while the labels reach H; with --drive-by object the planner
pushes the object to the person's target, not to the goal. In Chromium (skipping, saying why,
without it): the page says the task, shows the keys before the first take, and holds a far target on the reach with a
word; a second tab of the same browser only watches, a reload of the teaching tab still teaches, and a watcher shows
one state. INFORM_WRITE_SCREENSHOT=1 saves the page mid-day to docs/figures/browser_pusher_page.png (docs/teachers.md).
"""

import json
import os
import threading

import numpy as np
import pytest
import torch
from conftest import REPO, WAIT_S
from test_browser_teacher import Session, lines, wait_until

import inform_sac_pusher as isp
from browser_teacher import BrowserTeacher, clamp_to_reach
from inform_utils import sleep_variants_pusher as svp
from inform_utils.browser_pusher import Args, DayWithoutDriven, PageTeacher
from inform_utils.pusher_control import FingertipController, arm_reach

SCREENSHOT = os.path.join(REPO, "docs", "figures", "browser_pusher_page.png")


@pytest.fixture(autouse=True)
def headless(monkeypatch):
    """The page renders the arm in this process: EGL where there is no screen, as the scripts pick it (videos.py)."""
    if not os.environ.get("MUJOCO_GL") and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        monkeypatch.setenv("MUJOCO_GL", "egl")


FAR = [0.9, 0.2]  # the map's bottom right corner: 1.2 m from the arm's base, beyond its reach


class PageDay(threading.Thread):
    """The core's day as the page sees it, without TAMER: each step the person's action if they hold the arm (else a
    random one, as the agent's before learning starts); the page shows it, and its labels go into a buffer, as
    forward_phase does. `before(step)` runs first at each step (a test's person acting between two steps); in a
    thread when a browser acts instead."""

    def __init__(self, tmp_path, steps: int, before=None, **flags):
        super().__init__(daemon=True)
        self.args = Args(host="127.0.0.1", tamer_total_timesteps=steps, **flags)
        self.env = isp.make_env(self.args.env_id, 1, contact=self.args.contact)
        self.teacher = PageTeacher(self.args, self.env, str(tmp_path / "run"))
        self.teacher.page.linger = 0  # its close waits for no page
        self.buffer = isp.ReplayBuffer(steps, 23, 7, torch.device("cpu"))
        self.before, self.steps = before, steps

    def run(self):
        obs, _ = self.env.reset(seed=1)
        for step in range(self.steps):
            if self.before is not None:
                self.before(step)
            obs_t = torch.as_tensor(obs, dtype=torch.float32)
            driven = self.teacher.drive(obs_t)
            action = torch.as_tensor(self.env.action_space.sample()) if driven is None else driven
            labels = self.teacher(step, 0.0, action)
            self.buffer.feedback[list(labels)] = torch.tensor(list(labels.values()))
            obs, _, terminated, truncated, _ = self.env.step(action.numpy())
            self.buffer.add(obs_t, action, torch.as_tensor(obs, dtype=torch.float32), terminated, driven is not None)
            if truncated:
                obs, _ = self.env.reset(seed=1)
            if self.teacher.gone:
                break

    def finish(self):
        self.teacher.page.end_day("the test is over")
        self.join(30)
        self.teacher.page.close()


def test_the_reach_is_where_the_controller_gets_the_fingertip_and_a_far_target_is_held_on_it():
    env = isp.make_env("Pusher-v5", 0)
    base, radius = arm_reach(env.unwrapped.model)
    assert np.allclose(base, [0.0, -0.6]) and 0.75 < radius < 0.78, (base, radius)
    controller = FingertipController(env.unwrapped.model)
    for distance, off in ((radius - 0.005, 0.01), (radius + 0.05, 0.02)):  # on the circle; beyond it, short of it
        obs, _ = env.reset(seed=1)
        target = base + distance * np.array([np.cos(0.9), np.sin(0.9)])
        for _ in range(100):
            obs, *_ = env.step(controller(obs, target))
        error = np.linalg.norm(obs[14:16] - target)
        assert error < off if distance < radius else error > off, (distance, error)
    held, clamped = clamp_to_reach(FAR, (base, radius))
    assert clamped and np.isclose(np.linalg.norm(np.array(held) - base), radius)
    assert clamp_to_reach([0.4, -0.3], (base, radius)) == ((0.4, -0.3), False)


def test_the_server_holds_a_far_target_on_the_reach_and_records_what_was_asked(tmp_path):
    reach = ((0.0, -0.6), 0.77)
    with BrowserTeacher(str(tmp_path / "run"), task="pusher", pace=100.0, quiet=True, reach=reach, linger=0) as teacher:
        teacher.show(0, info={"_map": {"tip": [0.4, -0.3], "object": [0.6, -0.2], "goal": [0.45, -0.05]}})
        person = Session(teacher)
        person.load()
        status, body, _ = person.request("POST", "/drive", body={"drive": "take", "target": FAR})
        assert status == 200 and json.loads(body)["clamped"] is True, body
        assert np.isclose(np.hypot(teacher.target[0], teacher.target[1] + 0.6), 0.77)
        assert person.state()["clamped"] is True and person.state()["reach"] == {"base": [0.0, -0.6], "radius": 0.77}
        person.request("POST", "/drive", body={"drive": "target", "target": [0.4, -0.3]})
        assert teacher.target == (0.4, -0.3) and not person.state()["clamped"]
    take, near = lines(teacher, "drive")
    held = np.array([0.0, -0.6]) + 0.77 * np.array([0.9, 0.8]) / np.hypot(0.9, 0.8)  # on the line to FAR
    assert take["asked"] == FAR and np.allclose(take["target"], held)
    assert "asked" not in near


def test_a_take_labels_the_agents_last_k_steps_and_driven_rows_stay_out_of_h(tmp_path):
    """--takeover-steps 5: a take at step 30 labels 25-29 -1; one 2 steps after a release labels only the agent's 2;
    one 3 steps into an episode labels only that episode's 3. In answers.jsonl and the day's settings. With
    --no-driven-in-h H's batch never holds a driven row (their feedback made NaN: H's loss stays finite, where the
    core's Day meets them), and H learns the take's -1 on the labelled rows."""
    drives = {30: "take", 60: "release", 62: "take", 70: "release", 103: "take"}
    person = []

    def before(step):  # the person at the page, between two steps
        if step in drives:
            status, _, _ = person[0].request("POST", "/drive", body={"drive": drives[step], "target": [0.5, -0.3]})
            assert status == 200

    day = PageDay(tmp_path, 120, before, pace=100.0, takeover_steps=5, driven_in_h=False)
    person.append(Session(day.teacher.page))
    person[0].load()
    day.run()  # here: nothing waits on a browser
    day.teacher.page.close()
    buffer, labelled = day.buffer, [*range(25, 30), 60, 61, 100, 101, 102]
    assert buffer.feedback[labelled].tolist() == [-1.0] * 10
    others = [t for t in range(120) if t not in labelled and not buffer.driven[t]]
    assert (buffer.feedback[others] == 0).all() and (buffer.feedback[buffer.driven] == 1).all()
    assert buffer.driven.nonzero().squeeze(-1).tolist() == [*range(30, 60), *range(62, 70), *range(103, 120)]
    takes = lines(day.teacher.page, "take labels")
    assert [(r["step"], r["steps"], r["label"]) for r in takes] == [
        (30, [25, 26, 27, 28, 29], -1.0), (62, [60, 61], -1.0), (103, [100, 101, 102], -1.0)]  # fmt: skip
    (signal,) = lines(day.teacher.page, "take-over signal")
    assert signal["takeover_steps"] == 5 and signal["driven_in_h"] is False
    settings = day.args.day_settings()
    assert settings["takeover_steps"] == 5 and settings["takeover_label"] == -1.0 and not settings["driven_in_h"]

    torch.manual_seed(0)
    learner = day.args.day(torch.device("cpu"), day.env.action_space, 23)
    assert type(learner) is DayWithoutDriven
    nan = isp.ReplayBuffer(120, 23, 7, torch.device("cpu"))
    for name in isp.DAY_TENSORS:
        setattr(nan, name, getattr(buffer, name).clone())
    nan.size, nan.feedback[nan.driven] = buffer.size, float("nan")  # a driven row in H's batch: a NaN loss
    nan.success[:20] = True  # an expert set for the night (the agent's first steps)
    for _ in range(300):
        assert torch.isfinite(learner.update(nan, 119))
    with torch.no_grad():
        h = learner.h_net(buffer.obs, buffer.actions).mean(0)
    assert h[labelled].mean() < -0.5 and abs(h[others].mean()) < 0.25, (h[labelled].mean(), h[others].mean())
    core = isp.Day(settings, torch.device("cpu"), day.env.action_space, 23)
    assert not torch.isfinite(core.update(nan, 119))  # the core's Day samples the driven rows: the check bites
    for heard, finite in ((settings, True), ({**settings, "driven_in_h": True}, False)):  # the sham night goes on
        sham = svp.Args(sleep_control="sham", sleep_batch_size=32).night(learner.actor, torch.device("cpu"), tamer={
            "h_net": learner.h_net, "h_kwargs": learner.h_kwargs, "day_settings": heard, "ent_coef": 0.5})  # fmt: skip
        replay_idx, expert_idx, _ = sham.memories(nan)  # from the H the day left, hearing what it heard
        for step in range(1, 21):
            sham.update(step, isp.sleep_batch(nan, 32, expert_idx, replay_idx))
        assert bool(torch.isfinite(sham.pi_loss)) is finite, heard["driven_in_h"]


def test_with_drive_by_object_the_planner_pushes_the_object_to_the_persons_target(tmp_path):
    """--drive-by object (shared autonomy): a take at the second step with a target 15 cm beside the object, away from
    the goal; after one episode the object is at the person's target (the planner's goal is theirs, not the env's),
    every step driven and heard as a yes, and the day's record and the page's state say what the target moved. Held
    into the next episode, the planner starts afresh at its first step (its last plan was for the old state)."""
    person = []

    def before(step):
        if step == 1:  # once the page streams
            start = day.env.unwrapped._get_obs()[17:19]  # the object, at seed 1's fixed start
            person.append(start + np.array([0.0, -0.15]))
            status, _, _ = session.request("POST", "/drive", body={"drive": "take", "target": person[0].tolist()})
            assert status == 200

    day = PageDay(tmp_path, 102, before, pace=100.0, drive_by="object")
    session = Session(day.teacher.page)
    session.load()
    assert session.state()["drive_by"] == "object"
    takes, take = [], day.teacher.hand.take
    day.teacher.hand.take = lambda: (takes.append(day.buffer.size), take())  # the step about to be taken
    day.run()
    assert takes == [1, 100]
    day.teacher.page.close()
    obs = day.buffer.next_obs[99].numpy()  # the episode's last state (the env has since been reset)
    assert np.linalg.norm(obs[17:19] - person[0]) < 0.03, (obs[17:19], person[0])
    assert np.linalg.norm(obs[17:19] - obs[20:22]) > 0.25  # not the goal's way
    assert day.buffer.driven[1:100].all() and (day.buffer.feedback[1:100] == 1).all()
    (start,) = lines(day.teacher.page, "start")
    assert start["drive_by"] == "object" and day.args.day_settings()["drive_by"] == "object"


# ---------------------------------------------------------------------------------------------------------------------
# in Chromium


def streaming(page):
    wait_until(lambda: page.evaluate("Boolean(typeof state !== 'undefined' && state && state.info._map)"), "the map")


def test_the_page_says_the_task_and_holds_a_far_target_on_the_reach(new_page, tmp_path):
    """A newcomer's page: the task in a line, the keys before any take, the steps left and the pace; a click far
    beyond the arm's reach takes the arm at the reach (at the server too, which records the click as asked: a page that
    sent its own held point left the server unsure whether it was held, and its word went at the next poll), and the
    page says so in words."""
    day = PageDay(tmp_path, 4000, pace=20.0)
    day.start()
    try:
        page = new_page(day.teacher.page.url)
        streaming(page)
        assert "push the white object onto the red goal" in page.text_content("#task") and page.is_visible("#task")
        assert page.is_visible("#keys") and "arrow keys" in page.text_content("#keys")  # before the first take
        assert "its fingertip follows your target" in page.text_content("#keys")
        wait_until(lambda: "steps left in the day" in page.text_content("#pace"), "the steps left")
        assert page.get_attribute("#day", "data-clamped") == "0" and page.text_content("#clamp") == ""
        box = page.locator("#map").bounding_box()
        page.mouse.click(box["x"] + box["width"] - 2, box["y"] + box["height"] - 2)  # FAR, as the map is turned
        wait_until(lambda: day.teacher.page.target is not None, "the take at the server")
        base, radius = day.teacher.page.reach
        assert np.isclose(np.linalg.norm(np.array(day.teacher.page.target) - base), radius)
        page.wait_for_selector('#day[data-clamped="1"]')
        assert "Out of reach" in page.text_content("#clamp") and page.is_visible("#clamp")
        target = np.array(day.teacher.page.target)
        wait_until(lambda: np.linalg.norm(page.evaluate("state.info._map.tip") - target) < 0.03, "the fingertip there")
        screenshot = SCREENSHOT if os.environ.get("INFORM_WRITE_SCREENSHOT") == "1" else str(tmp_path / "page.png")
        page.screenshot(path=screenshot, full_page=True)
    finally:
        day.finish()
    (take,) = lines(day.teacher.page, "drive")
    assert take["drive"] == "take" and np.isclose(np.linalg.norm(np.array(take["target"]) - base), radius)
    assert np.linalg.norm(np.array(take["asked"]) - base) > radius + 0.3  # the click, as asked: the far corner


def test_a_second_tab_of_the_same_browser_only_watches(new_page, tmp_path):
    """Two tabs of one browser (one session cookie): the first to take the arm teaches; the second cannot take it (its
    keys, its clicks and its own requests are refused), and says it watches. The teaching tab reloaded still drives.
    When the day is over, the watcher says that alone."""
    day = PageDay(tmp_path, 4000, pace=20.0)
    day.start()
    try:
        first = new_page(day.teacher.page.url)
        second = first.context.new_page()
        second.set_default_timeout(WAIT_S * 1000)
        second.goto(day.teacher.page.url)
        streaming(first)
        streaming(second)
        first.keyboard.press("t")
        wait_until(lambda: day.teacher.page.driving, "the first tab's take")
        target = day.teacher.page.target
        second.wait_for_selector("#banner:has-text('watching read-only')")
        assert second.is_disabled("#take") and not second.is_visible("#keys")
        second.keyboard.press("t")
        second.keyboard.press("ArrowUp")
        box = second.locator("#map").bounding_box()
        second.mouse.click(box["x"] + 60, box["y"] + 60)
        status = second.evaluate("""fetch(url("/drive"), {method: "POST", headers: {"Content-Type": "application/json"},
            body: JSON.stringify({drive: "target", target: [0.4, -0.3]})}).then((r) => r.status)""")
        assert status == 403 and day.teacher.page.target == target
        tab = first.evaluate("TAB")  # a duplicated tab: the teaching tab's sessionStorage, copied, then a new load
        third = first.context.new_page()
        third.set_default_timeout(WAIT_S * 1000)
        third.add_init_script(f"sessionStorage.setItem('inform_tab', {json.dumps(tab)})")
        third.goto(day.teacher.page.url)
        streaming(third)
        third.wait_for_selector("#banner:has-text('watching read-only')")
        assert third.evaluate("TAB") != tab and third.is_disabled("#take")
        first.reload()  # the same tab: it still teaches
        streaming(first)
        first.wait_for_selector('#day[data-driving="1"]')
        first.keyboard.press("ArrowUp")  # up the map: -x
        moved = [target[0] - 0.02, target[1]]
        wait_until(lambda: np.allclose(day.teacher.page.target, moved), "the reloaded tab's move")
        assert first.evaluate("state.role") == "teacher" and first.is_hidden("#banner")
        day.teacher.page.end_day("the test is over")
        second.wait_for_selector('#day[data-mode="ended"]')
        assert second.is_hidden("#banner") and second.text_content("#question").startswith("The day is over")
    finally:
        day.finish()
    assert [r["drive"] for r in lines(day.teacher.page, "drive")] == ["take", "target"]
    assert not lines(day.teacher.page, "takeover")


def test_with_drive_by_object_the_page_says_the_target_is_the_objects(new_page, tmp_path):
    """With --drive-by object the page says a target is where the object goes, and `t` takes the arm with the target
    on the object (the planner holds it there), not on the fingertip (it would push the object towards the arm)."""
    day = PageDay(tmp_path, 4000, pace=20.0, drive_by="object")
    day.start()
    try:
        page = new_page(day.teacher.page.url)
        streaming(page)
        assert "it pushes the object to your target" in page.text_content("#keys")
        assert "it pushes the object to your target" in page.text_content("#drive-status")
        seen = page.evaluate("state.info._map")
        page.keyboard.press("t")
        wait_until(lambda: day.teacher.page.target is not None, "the take at the server")
        target = np.array(day.teacher.page.target)
        assert np.linalg.norm(target - seen["object"]) < 0.02, (target, seen)
    finally:
        day.finish()
