"""The teaching page (browser_teacher.py): the server without a browser (the token, the routes, answers.jsonl, one
person per run, a reload or a retry loses nothing, the end of the day, Ctrl-C, no thread left behind), then a real
browser: Playwright driving Debian's chromium headless, where a scripted person reads the maze off the page and
answers as the oracle would (y when the move is optimal under Q*, else n; space once), through a dropped connection
and a reload; a watcher in a second session; the Pusher's stream with its credit window.

The browser tests skip, saying why, without /usr/bin/chromium (apt-get install chromium) or the pinned playwright;
INFORM_REQUIRE_BROWSER=1 makes them fail instead. INFORM_WRITE_SCREENSHOT=1 saves the page's screenshot to
docs/figures/browser_teacher.png (the README's; the maze script's run mid-day, where the script takes --teacher
browser), else it goes to the test's temporary directory.
"""

import dataclasses
import http.client
import io
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.parse
import urllib.request
from http.cookiejar import CookieJar

import numpy as np
import pytest
from conftest import REPO, WAIT_S, Child, default_signals

import gridworld_env
from browser_teacher import BrowserTeacher, credit_weights, png_bytes
from inform_utils.scripted_person_browser import on_the_page

SCREENSHOT = os.path.join(REPO, "docs", "figures", "browser_teacher.png")
PUSHER_SCREENSHOT = os.path.join(REPO, "docs", "figures", "browser_pusher.png")
MAZE_SCRIPT = os.path.join(REPO, "inform_dqn_gridworld.py")


# ---------------------------------------------------------------------------------------------------------------------
# helpers: a browser session as urllib sees it, a training loop in a thread, the answers file


class Session:
    """One browser session without a browser: its own cookies (the page's session cookie among them)."""

    def __init__(self, teacher: BrowserTeacher, token: str | None = None):
        self.base = f"http://127.0.0.1:{teacher.port}"
        self.token = teacher.token if token is None else token
        self.opener = urllib.request.build_opener(urllib.request.HTTPCookieProcessor(CookieJar()))
        self.page = None  # the id of the page's current load, as the page's script sends it

    def request(self, method: str, path: str, body: dict | None = None, **query) -> tuple[int, bytes, dict]:
        params = {"token": self.token, **query} if self.token else dict(query)
        if self.page is not None:
            params.setdefault("page", self.page)
        address = self.base + path + ("?" + urllib.parse.urlencode(params) if params else "")
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(address, data=data, method=method, headers={"Content-Type": "application/json"})
        try:
            with self.opener.open(req, timeout=WAIT_S + 5) as reply:
                return reply.status, reply.read(), dict(reply.headers)
        except urllib.error.HTTPError as error:
            return error.code, error.read(), dict(error.headers)

    def load(self) -> int:
        self.page = os.urandom(8).hex()  # a new load of the page
        return self.request("GET", "/")[0]

    def state(self, since: int | None = None) -> dict:
        status, body, _ = self.request("GET", "/state", **({} if since is None else {"since": since}))
        assert status == 200, body
        return json.loads(body)

    def open_question(self, number: int) -> dict:
        """Wait (long polls, bounded) until question `number` is open and unanswered."""
        deadline = time.monotonic() + WAIT_S
        state = self.state()
        while not (state["mode"] == "ask" and state["question"]["id"] == number and not state["question"]["answered"]):
            assert time.monotonic() < deadline, f"question {number} never opened: {state}"
            state = self.state(since=state["version"])
        return state

    def answer(self, label: str, question: int | None, nonce: str, seq: int | None = None) -> tuple[int, dict]:
        status, body, _ = self.request(
            "POST", "/answer", {"nonce": nonce, "answer": label, "question": question, "seq": seq}
        )
        return status, json.loads(body) if body.startswith(b"{") else {"text": body.decode()}


class Loop:
    """A training loop's side in a thread: `ask` for each move of a walk in the maze, the answers kept."""

    def __init__(self, teacher: BrowserTeacher, moves: int, seed: int = 0, frames: bool = False):
        self.teacher, self.moves, self.seed, self.frames = teacher, moves, seed, frames
        self.q = gridworld_env.optimal_q()
        self.asked = []  # (step, cell, action, drawing)
        self.returned = []
        self.error = None
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self):
        try:
            env = gridworld_env.KnoxStoneMazeEnv(render_mode="rgb_array")
            rng = np.random.default_rng(self.seed)
            _, info = env.reset(seed=self.seed)
            cell = info["cell"]
            for step in range(1, self.moves + 1):
                # the agent's proposal: the best move half the time, a random one otherwise, so both answers come
                action = int(self.q[cell].argmax()) if rng.random() < 0.5 else int(rng.integers(4))
                drawing = gridworld_env.draw_maze(agent=cell, arrows={cell: action})
                self.asked.append((step, cell, action, drawing))
                frame = env.render() if self.frames else None
                info = {"move": gridworld_env.ACTION_NAMES[action]}
                self.returned.append(self.teacher.ask(step, action, state_text=drawing, frame=frame, info=info))
                if self.teacher.ended:
                    return
                _, _, terminated, _, info = env.step(action)
                cell = info["cell"]
                if terminated:
                    _, info = env.reset()
                    cell = info["cell"]
        except BaseException as error:  # the test reports it
            self.error = error

    def join(self):
        self.thread.join(WAIT_S)
        assert not self.thread.is_alive(), "the loop still waits in ask"
        assert self.error is None, repr(self.error)

    def optimal(self, step: int) -> bool:
        _, cell, action, _ = self.asked[step - 1]
        return bool(self.q[cell, action] >= self.q[cell].max() - 1e-9)


def lines(teacher: BrowserTeacher, event: str = "answer") -> list[dict]:
    with open(teacher.answers_path) as f:
        return [row for row in map(json.loads, f) if row["event"] == event]


def wait_until(condition, what: str, timeout: float = WAIT_S):
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.01)


@pytest.fixture
def teacher(tmp_path):
    """A page served to urllib sessions, which do not long-poll: close() need not wait for them (linger 0)."""
    run_dir = str(tmp_path / "run")
    # urllib sessions are heard only while they request: a teacher silent for a minute could be taken over
    with BrowserTeacher(run_dir, participant="P07", budget=5, quiet=True, close_grace=0.3, linger=0,
                        takeover_after=60.0) as page:  # fmt: skip
        yield page


# ---------------------------------------------------------------------------------------------------------------------
# the server, without a browser


def test_a_request_without_the_token_is_refused(teacher):
    loop = Loop(teacher, moves=1)
    for token in ("", "wrong", teacher.token[:-1]):
        anyone = Session(teacher, token=token)
        for method, path in [("GET", "/"), ("GET", "/state"), ("GET", "/frame.png"), ("POST", "/end"),
                             ("POST", "/bye"), ("GET", "/nowhere"), ("GET", "/../etc/passwd")]:  # fmt: skip
            status, body, _ = anyone.request(method, path, body={} if method == "POST" else None)
            assert status == 403, (token, path)
            assert b"token" in body and b"<html" not in body
        assert anyone.answer("yes", 1, "n1")[0] == 403
    assert teacher.ended is None and not lines(teacher)
    person = Session(teacher)
    assert person.load() == 200
    person.open_question(1)
    assert person.answer("yes", 1, "n1") == (200, {"taken": True})
    loop.join()


def test_only_its_own_routes_and_nothing_from_the_file_system(teacher):
    person = Session(teacher)
    assert person.load() == 200
    for path in ["/index.html", "/answers.jsonl", "/run/answers.jsonl", "/favicon.ico", "/static/page.js",
                 "//etc/passwd", "//x/state", "/state/", "/frame.png/..", "/../answers.jsonl",
                 "/%2e%2e/%2e%2e/etc/passwd", "/..%2f..%2fetc%2fpasswd", "/state/../../../../etc/passwd", "/%00",
                 "/./state"]:  # fmt: skip
        # raw, as the client wrote it: http.client does not tidy a path
        connection = http.client.HTTPConnection("127.0.0.1", teacher.port, timeout=WAIT_S)
        connection.request("GET", f"{path}?token={teacher.token}")
        reply = connection.getresponse()
        body = reply.read()
        connection.close()
        assert reply.status == 404, path
        assert b"root:" not in body and b'"event"' not in body
    assert person.request("GET", "/answer")[0] == 405  # a route of its own, the wrong method
    assert person.request("POST", "/state", body={})[0] == 405
    assert person.request("GET", "/frame.png")[0] == 404  # no frame yet
    status, body, headers = person.request("GET", "/")
    assert status == 200 and b"End the day" in body and "default-src 'none'" in headers["Content-Security-Policy"]
    assert headers["Referrer-Policy"] == "no-referrer"  # the token stays out of other sites' logs


def test_answers_reach_the_loop_and_answers_jsonl(teacher):
    loop = Loop(teacher, moves=3, frames=True)
    person = Session(teacher)
    person.load()
    for number, label in enumerate(["yes", "no", "none"], start=1):
        state = person.open_question(number)
        status, png, headers = person.request("GET", "/frame.png", seq=state["question"]["frame_seq"])
        assert status == 200 and png.startswith(b"\x89PNG") and int(headers["X-Frame-Seq"]) == state["frame_seq"]
        assert state["state_text"] == loop.asked[number - 1][3] and state["role"] == "teacher"
        assert person.answer(label, number, f"nonce-{number}") == (200, {"taken": True})
        rows = lines(teacher)  # flushed at once: readable while the run goes on
        assert len(rows) == number and rows[-1]["answer"] == label
    loop.join()
    assert loop.returned == [1.0, 0.0, None]
    rows = lines(teacher)
    assert [row["step"] for row in rows] == [1, 2, 3]
    assert [row["action"] for row in rows] == [action for _, _, action, _ in loop.asked]
    assert [row["state_text"] for row in rows] == [drawing for *_, drawing in loop.asked]
    assert all(
        row["participant"] == "P07" and row["mode"] == "ask" and len(row["frame"]["sha256"]) == 16 for row in rows
    )
    assert [row["frame"]["seq"] for row in rows] == [1, 2, 3]
    assert {"time", "t", "given_s", "value"} <= set(rows[0])
    start = lines(teacher, "start")
    assert start[0]["participant"] == "P07" and start[0]["budget"] == 5 and start[0]["task"] == "maze"
    state = person.state()
    assert (state["answers"], state["yes"], state["no"], state["none"], state["budget"]) == (3, 1, 1, 1, 5)


def test_a_no_can_be_tamers_minus_one_and_is_recorded_so(tmp_path):
    with BrowserTeacher(str(tmp_path / "run"), quiet=True, close_grace=0.3, linger=0, no_value=-1.0) as teacher:
        loop = Loop(teacher, moves=2)
        person = Session(teacher)
        person.load()
        for number, label in enumerate(["no", "yes"], start=1):
            person.open_question(number)
            assert person.answer(label, number, f"nonce-{number}") == (200, {"taken": True})
        loop.join()
        assert loop.returned == [-1.0, 1.0]  # the loop gets TAMER's signed labels
        assert [row["value"] for row in lines(teacher)] == [-1.0, 1.0]
        assert lines(teacher, "start")[0]["no_value"] == -1.0
    with pytest.raises(ValueError, match="no_value"):
        BrowserTeacher(str(tmp_path / "bad"), quiet=True, no_value=0.5)


def test_a_body_nested_thousands_deep_gets_a_400(teacher):
    person = Session(teacher)
    person.load()
    deep = ("[" * 2000 + "]" * 2000).encode()  # within MAX_BODY; json.loads recurses past Python's limit
    req = urllib.request.Request(f"{person.base}/answer?token={teacher.token}", data=deep, method="POST",
                                 headers={"Content-Type": "application/json"})  # fmt: skip
    with pytest.raises(urllib.error.HTTPError) as refused:
        person.opener.open(req, timeout=WAIT_S)
    assert refused.value.code == 400


def test_loading_takes_no_role_the_first_session_to_act_teaches(teacher):
    """A fetch of the address (a curl, a link preview, a prefetch) and a page that only loads take no role: the
    first session to answer teaches and every other watches read-only; a request without the cookie never teaches."""
    loop = Loop(teacher, moves=2)
    curl, other, person, stranger = Session(teacher), Session(teacher), Session(teacher), Session(teacher)
    assert curl.load() == 200 and other.load() == 200 and person.load() == 200  # the plain fetch came first
    assert person.open_question(1)["role"] == "teacher" and other.state()["role"] == "teacher"  # nobody acted yet
    assert stranger.state()["role"] == "watcher" and stranger.answer("yes", 1, "s1")[0] == 403  # no cookie at all
    assert person.answer("no", 1, "p1") == (200, {"taken": True})
    assert other.open_question(2)["role"] == "watcher" and curl.state()["role"] == "watcher"
    assert other.answer("yes", 2, "o2")[0] == 403 and other.request("POST", "/end", body={})[0] == 403
    assert curl.request("POST", "/end", body={})[0] == 403 and teacher.ended is None
    assert person.answer("yes", 2, "p2") == (200, {"taken": True})
    loop.join()
    assert loop.returned == [0.0, 1.0] and [row["answer"] for row in lines(teacher)] == ["no", "yes"]
    assert other.state()["answers"] == 2 and not lines(teacher, "takeover")


def test_a_silent_teacher_is_taken_over_and_nothing_answered_is_lost(tmp_path):
    """The teaching session's pages heard last takeover_after ago (no request, no long poll open): another session
    may teach, says so, and the takeover is in answers.jsonl beside every answer given before and after it. While
    the owner is heard, nobody else may (its open long poll keeps it heard)."""
    with BrowserTeacher(str(tmp_path / "run"), quiet=True, close_grace=0.3, linger=0, takeover_after=0.5) as teacher:
        loop = Loop(teacher, moves=3)
        first, second = Session(teacher), Session(teacher)
        assert first.load() == 200 and second.load() == 200
        first.open_question(1)
        assert first.answer("yes", 1, "f1") == (200, {"taken": True})
        with teacher._cond:  # the rule itself, at fixed times: heard now, then heard 0.6 s ago
            (page,) = teacher._pages
            teacher._pages[page] = time.monotonic()
            assert teacher._may_teach(teacher._owner) and not teacher._may_teach(second_session(teacher, first))
            teacher._pages[page] = time.monotonic() - 0.6
            assert teacher._may_teach(second_session(teacher, first))
        state = second.open_question(2)
        assert state["role"] == "teacher" and state["takeover"] is True  # urllib's first session polls no more
        assert second.answer("no", 2, "s2") == (200, {"taken": True})
        state = second.open_question(3)
        assert "took over" in state["message"] and state["takeover"] is False
        assert second.answer("none", 3, "s3") == (200, {"taken": True})
        loop.join()
    assert loop.returned == [1.0, 0.0, None]
    assert [row["answer"] for row in lines(teacher)] == ["yes", "no", "none"]
    (takeover,) = lines(teacher, "takeover")
    assert takeover["answers"] == 1 and takeover["step"] == 2


def second_session(teacher: BrowserTeacher, first: Session) -> str:
    """The session id of the other session than `first`'s (the owner's) among the teacher's two."""
    (other,) = teacher._sessions - {teacher._owner}
    return other


def test_a_reload_or_a_retried_answer_loses_nothing(teacher):
    loop = Loop(teacher, moves=3)
    person = Session(teacher)
    person.load()
    person.open_question(1)
    assert person.answer("yes", 1, "a1") == (200, {"taken": True})
    assert person.load() == 200  # the reload: the same session, still the teacher
    state = person.open_question(2)
    assert state["role"] == "teacher" and state["answers"] == 1 and state["yes"] == 1
    assert person.answer("yes", 1, "a1") == (
        200,
        {"taken": False, "why": "already taken"},
    )  # a retry after a lost reply
    assert person.answer("no", 1, "late")[0] == 409  # an answer to a question no longer open
    assert person.answer("no", 2, "a2") == (200, {"taken": True})
    assert person.answer("no", 2, "a2")[1]["taken"] is False
    state = person.open_question(3)
    assert state["answers"] == 2 and state["no"] == 1
    assert person.answer("yes", 3, "a3")[0] == 200
    loop.join()
    assert loop.returned == [1.0, 0.0, 1.0] and len(lines(teacher)) == 3
    for bad in ({"nonce": "x", "answer": "maybe", "question": 1}, {"answer": "yes"}, {"nonce": "a b", "answer": "yes"}):
        assert person.request("POST", "/answer", body=bad)[0] == 400
    assert person.request("POST", "/answer", body={"nonce": "x" * 5000, "answer": "yes"})[0] == 400  # too long


def test_the_day_ends_by_the_button_or_a_closed_page(tmp_path):
    with BrowserTeacher(str(tmp_path / "a"), quiet=True, linger=0) as page:
        loop = Loop(page, moves=5)
        person = Session(page)
        person.load()
        person.open_question(1)
        assert person.request("POST", "/end", body={})[0] == 200
        loop.join()
        assert loop.returned == [None] and page.ended == "end of day"
        assert page.ask(2, 0) is None  # no more questions once the day is over
        assert person.answer("yes", 1, "after")[0] == 409
    with BrowserTeacher(str(tmp_path / "b"), quiet=True, close_grace=0.3, linger=0) as page:
        loop = Loop(page, moves=5)
        person = Session(page)
        person.load()
        person.open_question(1)
        person.request("POST", "/bye", body={})  # a reload says goodbye too, then comes back in time
        person.load()
        person.answer("yes", 1, "b1")
        person.open_question(2)
        old, _ = person.page, person.load()  # a reload whose goodbye comes after the new page's first request
        person.request("POST", "/bye", body={}, page=old)
        wait_until(lambda: page._bye_at is None, "the grace to pass")  # and the day goes on: the new page is open
        assert page.ended is None
        person.answer("yes", 2, "b2")
        person.open_question(3)
        person.request("POST", "/bye", body={})  # closed: it does not come back
        loop.join()
        assert loop.returned == [1.0, 1.0, None] and page.ended == "page closed"
    assert [row["why"] for row in lines(page, "end")] == ["page closed"]


def test_streamed_answers_carry_their_time_and_step_and_the_credit_window(teacher):
    person = Session(teacher)
    person.load()
    frame = np.zeros((8, 8, 3), np.uint8)
    for step in range(10):
        teacher.show(step, frame=frame + step, action=[0.1 * step, -0.5])
    state = person.state()
    assert state["mode"] == "stream" and state["step"] == 9
    before = time.monotonic()
    status, reply = person.answer("yes", None, "s1", seq=4)  # the person saw step 3 (the 4th frame)
    assert (status, reply) == (200, {"taken": True})
    (answer,) = teacher.answers()
    assert answer.value == 1.0 and answer.step == 3 and answer.step_at_arrival == 9 and answer.question is None
    assert before - 1.0 < answer.time <= time.monotonic()
    assert teacher.answers() == []  # each answer is handed over once
    (row,) = lines(teacher)
    assert row["mode"] == "stream" and row["step"] == 3 and row["frame"]["seq"] == 4
    assert row["action"] == pytest.approx([0.3, -0.5])
    assert person.answer("no", 1, "s2")[0] == 409  # no question is open while streaming
    # the window: the steps shown 0.2-4 s before the answer, each weighed by its time on the screen
    shown = [(step, 10.0 + step) for step in range(10)]  # one step a second, from t = 10
    weights = credit_weights(18.5, shown, (0.2, 4.0))
    assert sorted(weights) == [4, 5, 6, 7, 8]
    assert weights[8] == pytest.approx(0.3 / 3.8) and weights[5] == pytest.approx(1 / 3.8)
    assert weights[4] == pytest.approx(0.5 / 3.8) and sum(weights.values()) == pytest.approx(1.0)
    assert credit_weights(10.1, shown) == {}  # too soon after the first step for anyone to have seen it
    assert set(teacher.credit(answer, delay=(0.0, 4.0))) == set(range(10))  # all shown within 4 s before it
    assert teacher.credit(answer) == {}  # it came < 0.2 s after them: quicker than a person, about none of them
    assert teacher.labels([answer], delay=(0.0, 4.0)) == dict.fromkeys(range(10), 1.0)
    no = dataclasses.replace(answer, value=0.0, label="no", time=answer.time + 0.001)
    skipped = dataclasses.replace(answer, value=None, label="none", time=answer.time + 0.002)
    assert teacher.labels([answer, no, skipped], delay=(0.0, 4.0)) == dict.fromkeys(range(10), 0.0)  # the later wins


def test_bad_arguments_and_a_port_in_use_fail_before_any_file(tmp_path, teacher):
    for bad in ({"task": "cartpole"}, {"pace": 0.0}, {"delay": (4.0, 0.2)}):
        with pytest.raises(ValueError):
            BrowserTeacher(str(tmp_path / "bad"), quiet=True, **bad)
    with pytest.raises(OSError):
        BrowserTeacher(str(tmp_path / "busy"), port=teacher.port, quiet=True)
    assert not (tmp_path / "bad").exists() and not (tmp_path / "busy").exists()
    with BrowserTeacher(str(tmp_path / "all"), host="0.0.0.0", quiet=True, linger=0) as everywhere:
        assert everywhere.url.startswith(f"http://{socket.gethostname()}:{everywhere.port}/?token=")
        assert Session(everywhere).load() == 200  # reachable on 127.0.0.1 too


def test_png_frames_decode_to_the_array():
    from PIL import Image

    rgb = np.random.default_rng(0).integers(0, 256, (7, 5, 3), dtype=np.uint8)
    assert np.array_equal(np.asarray(Image.open(io.BytesIO(png_bytes(rgb)))), rgb)
    grey = rgb[:, :, 0]
    assert np.array_equal(np.asarray(Image.open(io.BytesIO(png_bytes(grey)))), grey)


def test_the_outcome_a_picture_or_a_short_video(teacher):
    person = Session(teacher)
    person.load()
    assert person.request("GET", "/outcome")[0] == 404  # none before the night
    frames = [np.full((6, 6, 3), 40 * i, np.uint8) for i in range(3)]
    teacher.show_outcome("TAMER 19 steps, INFORM 19", image=frames)
    status, body, headers = person.request("GET", "/outcome")
    assert status == 200 and headers["Content-Type"] == "image/gif" and body.startswith(b"GIF8")
    state = person.state()
    assert state["mode"] == "outcome" and state["outcome"] == {
        "id": 1,
        "text": "TAMER 19 steps, INFORM 19",
        "image": True,
    }
    assert teacher.ended == "day done"  # the script's own end of the day, said on the page
    teacher.show_outcome("a frame", image=frames[0])
    assert person.request("GET", "/outcome")[2]["Content-Type"] == "image/png"
    with pytest.raises(ValueError):
        teacher.show_outcome("?", image=b"not an image")


CHILD = """
import sys, time
sys.path.insert(0, {repo!r})
from browser_teacher import BrowserTeacher
page = BrowserTeacher({run!r}, quiet=True)
{body}
"""


def run_child(tmp_path, body: str, **popen) -> subprocess.Popen:
    code = CHILD.format(repo=REPO, run=str(tmp_path / "run"), body=body)
    return subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, preexec_fn=default_signals, **popen
    )


def test_no_thread_holds_up_the_exit(tmp_path):
    """A script that never calls close(), with a long poll waiting, exits at once."""
    body = "import urllib.request, threading\n"
    body += "poll = lambda: urllib.request.urlopen(page.url.replace('/?', '/state?') + '&since=0').read()\n"
    body += "threading.Thread(target=poll, daemon=True).start()\ntime.sleep(0.2)\nprint('done', flush=True)"
    child = run_child(tmp_path, body)
    assert child.stdout.readline().strip() == "done"
    done = time.monotonic()
    assert child.wait(timeout=30) == 0
    assert time.monotonic() - done < 5  # not the long poll's 10 s


def test_ctrl_c_while_waiting_ends_the_day_as_interrupted(tmp_path):
    body = "with page:\n    print('asking', flush=True)\n    page.ask(1, 0, state_text='|A> |')\n"
    child = run_child(tmp_path, body, stderr=subprocess.PIPE)
    assert child.stdout.readline().strip() == "asking"
    child.send_signal(signal.SIGINT)
    _, err = child.communicate(timeout=30)
    assert child.returncode != 0 and "KeyboardInterrupt" in err  # raised again: the script stops as it always does
    with open(tmp_path / "run" / "answers.jsonl") as f:
        ends = [row for row in map(json.loads, f) if row["event"] == "end"]
    assert [row["why"] for row in ends] == ["interrupted"]


# ---------------------------------------------------------------------------------------------------------------------
# a real browser: Playwright driving Debian's chromium, headless


def wait_for_question(page, number: int):
    page.wait_for_selector(f'#day[data-open="1"][data-question="{number}"]')


def test_a_scripted_person_teaches_the_maze_through_the_page(new_page, tmp_path):
    """Twelve moves: y/n by key or button as the oracle would answer, one space, a dropped connection and a
    reload in the middle, then "End the day"; nothing is lost and the loop gets each answer."""
    q = gridworld_env.optimal_q()
    with BrowserTeacher(str(tmp_path / "run"), participant="scripted", budget=10, quiet=True) as teacher:
        loop = Loop(teacher, moves=100, seed=3, frames=True)
        page = new_page(teacher.url)
        expected = []
        for number in range(1, 13):
            wait_for_question(page, number)
            cell, move = on_the_page(page.text_content("#maze"))
            assert (cell, move) == loop.asked[number - 1][1:3]  # the page shows the move the loop proposes
            good = q[cell, move] >= q[cell].max() - 1e-9
            if number == 5:
                page.keyboard.press(" ")
                expected.append(None)
                continue
            expected.append(1.0 if good else 0.0)
            if number == 7:  # the connection drops as the answer goes: the page keeps it and says so
                page.route("**/answer?*", lambda route: route.abort())
                page.keyboard.press("y" if good else "n")
                page.wait_for_selector(".banner.offline")
                assert teacher._question_answer is None  # it has not arrived
                page.unroute("**/answer?*")
                page.reload()  # ... and the reloaded page sends it
            elif number in (3, 8):
                page.click("#yes" if good else "#no")
            else:
                page.keyboard.press("y" if good else "n")
            if number == 9:
                wait_for_question(page, 10)
                page.reload()  # a plain reload: the page resumes at the open question
        wait_for_question(page, 13)
        assert page.text_content("#progress").startswith("answers 12 (")
        assert "participant scripted" in page.text_content("#progress")
        screenshot = SCREENSHOT if os.environ.get("INFORM_WRITE_SCREENSHOT") == "1" else str(tmp_path / "page.png")
        page.screenshot(path=screenshot, full_page=True)
        page.click("#end")
        page.wait_for_selector("#end:text('Click again')")
        page.click("#end")
        loop.join()
        assert teacher.ended == "end of day"
        page.wait_for_selector('#day[data-mode="ended"]')
        path = gridworld_env.draw_maze(agent=gridworld_env.START, arrows={4: 2, 3: 2})
        teacher.show_outcome("TAMER, greedy from S:\n" + path + "reaches G in 19 steps", image=np.full((4, 4, 3), 9))
    # as a script does: close() right after the outcome, and the page still gets all of it
    page.wait_for_selector('#day[data-mode="closed"]')  # the page says the run is over
    page.wait_for_selector("#outcome-img:visible")
    assert "reaches G in 19 steps" in page.text_content("#outcome-text")
    assert loop.returned[:12] == expected and loop.returned[12] is None
    rows = lines(teacher)
    assert [row["step"] for row in rows] == list(range(1, 13))  # each answer once, none lost
    assert [row["value"] for row in rows] == expected
    assert all(row["participant"] == "scripted" and row["frame"]["seq"] == row["step"] for row in rows)
    with open(screenshot, "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"


def test_keys_a_watcher_and_a_closed_page(new_page, tmp_path):
    with BrowserTeacher(str(tmp_path / "run"), quiet=True, close_grace=0.5) as teacher:
        loop = Loop(teacher, moves=10)
        person = new_page(teacher.url)
        wait_for_question(person, 1)
        person.keyboard.press("n")  # the first to act teaches
        wait_for_question(person, 2)
        watcher = new_page(teacher.url)  # another browser session
        watcher.wait_for_selector('#day[data-question="2"]')
        assert "read-only" in watcher.text_content("#banner") and watcher.is_disabled("#yes")
        assert watcher.is_disabled("#end")
        watcher.keyboard.press("y")
        person.keyboard.press("y")
        wait_for_question(person, 3)
        person.keyboard.press(" ")
        wait_for_question(person, 4)
        watcher.wait_for_selector('#day[data-answers="3"]')  # the watcher follows
        # two presses before any reply can come: the second is about the same question, and counts not
        person.evaluate(
            "() => { for (const key of ['y', 'y']) document.dispatchEvent(new KeyboardEvent('keydown', {key})); }"
        )
        wait_for_question(person, 5)
        assert loop.returned == [0.0, 1.0, None, 1.0]
        person.close()  # closing the page ends the day
        loop.join()
        assert teacher.ended == "page closed" and loop.returned[-1] is None
        watcher.wait_for_selector('#day[data-mode="ended"]')
    assert [row["answer"] for row in lines(teacher)] == ["no", "yes", "none", "yes"]


def test_a_plain_fetch_takes_no_role_and_a_second_browser_takes_over_from_a_closed_one(new_page, tmp_path):
    """The address fetched by plain HTTP first (a curl, a link preview), then a browser teaches; it goes away
    without its goodbye (offline, then closed: its /bye never arrives), and a second browser with the token takes
    over, answers and ends the day. Nothing answered is lost."""
    with BrowserTeacher(str(tmp_path / "run"), quiet=True, close_grace=0.5, takeover_after=1.0) as teacher:
        loop = Loop(teacher, moves=10)
        with urllib.request.urlopen(teacher.url, timeout=WAIT_S) as reply:
            assert reply.status == 200 and "Set-Cookie" in reply.headers
        first = new_page(teacher.url)
        wait_for_question(first, 1)
        first.keyboard.press("y")
        wait_for_question(first, 2)
        second = new_page(teacher.url)
        second.wait_for_selector('#day[data-question="2"]')
        assert "read-only" in second.text_content("#banner") and second.is_disabled("#yes")
        first.context.set_offline(True)  # the network gone (a lid closed, a crash): no goodbye reaches the server
        first.context.close()
        # its open long poll ends within LONG_POLL_S, then takeover_after passes: the second page may teach
        second.wait_for_selector("#banner:has-text('takes over')", timeout=3 * WAIT_S * 1000)
        wait_for_question(second, 2)
        second.keyboard.press("n")
        wait_for_question(second, 3)
        second.wait_for_selector("#message:has-text('took over')")
        second.click("#end")
        second.wait_for_selector("#end:text('Click again')")
        second.click("#end")
        loop.join()
        assert teacher.ended == "end of day" and loop.returned == [1.0, 0.0, None]
    assert [row["answer"] for row in lines(teacher)] == ["yes", "no"] and len(lines(teacher, "takeover")) == 1


def test_the_pusher_streams_and_answers_arrive_with_their_step(new_page, tmp_path):
    """Frames at a person's pace (20 steps a second, shown at most 5 a second); a y while the arm moves comes back
    with the step then on the screen, and the credit window spreads it over the steps before."""
    with BrowserTeacher(str(tmp_path / "run"), task="pusher", pace=20.0, quiet=True) as teacher:
        got = []

        def simulation():
            for step in range(400):
                frame = np.zeros((48, 64, 3), np.uint8)
                frame[:, (step % 64) :] = (30, 90, 200)
                teacher.show(step, frame=frame, action=np.array([0.1, -0.2]))
                got.extend(teacher.answers())
                if teacher.ended or len(got) == 2:
                    return

        thread = threading.Thread(target=simulation, daemon=True)
        thread.start()
        page = new_page(teacher.url)
        page.wait_for_selector('#day[data-mode="stream"][data-open="1"]')
        page.wait_for_selector("#frame:visible")
        page.wait_for_function("() => document.querySelector('#frame').complete")
        assert "is the arm" not in page.text_content("#question") and "0.2–4" in page.text_content("#hint")
        page.keyboard.press("y")
        page.wait_for_selector('#day[data-answers="1"]')
        page.click("#no")
        thread.join(WAIT_S)
        assert not thread.is_alive()
        first, second = got
        assert (first.label, second.label) == ("yes", "no") and first.time <= second.time
        assert first.step is not None and first.step <= first.step_at_arrival
        assert teacher.credit(first, delay=(0.0, 4.0))  # the steps on the screen before it
    rows = lines(teacher)
    assert [row["mode"] for row in rows] == ["stream", "stream"] and rows[0]["step"] == first.step


def test_a_held_key_answers_four_times_a_second_each_answer_a_line(new_page, tmp_path):
    """GUIDE's continuous feedback at the page: y held down for about 1.1 s while the arm moves answers yes again every
    250 ms, each answer a line of answers.jsonl with the step then on the screen; letting go stops it."""
    with BrowserTeacher(str(tmp_path / "run"), task="pusher", pace=20.0, quiet=True) as teacher:
        got, stop = [], threading.Event()

        def simulation():
            for step in range(100_000):
                teacher.show(step, frame=np.zeros((8, 8, 3), np.uint8), action=np.array([0.1, -0.2]))
                got.extend(teacher.answers())
                if teacher.ended or stop.is_set():
                    return

        thread = threading.Thread(target=simulation, daemon=True)
        thread.start()
        page = new_page(teacher.url)
        page.wait_for_selector('#day[data-mode="stream"][data-open="1"]')
        assert "hold y or n" in page.text_content("#hint")
        page.keyboard.down("y")
        page.wait_for_function("() => +document.querySelector('#day').dataset.answers >= 4")  # a press, 3 repeats
        page.keyboard.up("y")
        held = -1  # answers.jsonl's lines, read until two reads 0.6 s apart agree (the last answers arrived)
        for _ in range(50):
            if held == (held := len(lines(teacher))):
                break
            page.wait_for_timeout(600)
        page.wait_for_timeout(1000)  # four more answers' time, had the key stayed down
        assert len(lines(teacher)) == held
        stop.set()
        thread.join(WAIT_S)
    rows = lines(teacher)
    assert [row["answer"] for row in rows] == ["yes"] * held and held >= 4
    steps = [row["step"] for row in rows]
    # each about what was on the screen then: never an earlier step (under load two answers 250 ms apart may see the
    # same one)
    assert steps == sorted(steps)


def test_through_the_page_the_scripted_person_teaches_tamer_the_19_steps_from_s(new_page, tmp_path):
    """The maze script itself under --teacher browser: the scripted person answers each move as the oracle would
    until the page says the agent's own way from S takes 19 steps, then ends the day; the night runs, the page shows
    the outcome, and the run completes with every answer kept."""
    flags = ["--teacher", "browser", "--participant", "scripted", "--seed", "1", "--tamer-total-timesteps", "300",
             "--sleep-gradient-steps", "300"]  # fmt: skip
    child = Child([sys.executable, MAZE_SCRIPT, *flags], cwd=tmp_path)
    url = child.wait_for_line("[teacher] open the teaching page", timeout=120).split(": ", 1)[1].strip()
    page = new_page(url)
    q = gridworld_env.optimal_q()
    answers = 0
    page.wait_for_selector('#day[data-open="1"]')
    while "its own way from S: reaches G in 19 steps" not in page.text_content("#info"):
        assert answers < 200, "TAMER never reached 19 steps from S"
        number = page.get_attribute("#day", "data-question")
        cell, move = on_the_page(page.text_content("#maze"))
        if answers == 20 and os.environ.get("INFORM_WRITE_SCREENSHOT") == "1":  # the README's: the script mid-day
            page.screenshot(path=SCREENSHOT, full_page=True)
        page.keyboard.press("y" if q[cell, move] >= q[cell].max() - 1e-9 else "n")
        answers += 1
        page.wait_for_selector(f'#day[data-open="1"]:not([data-question="{number}"])')
    page.click("#end")
    page.click("#end")
    page.wait_for_selector("#outcome:visible", timeout=120_000)
    assert "reaches G in 19 steps" in page.text_content("#outcome-text")
    code, out, err = child.finish()
    assert code == 0, err[-2000:]
    (run_dir,) = (tmp_path / "runs").iterdir()
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["eval/tamer_episode_length"] == 19
    assert summary["feedback/answers"] == answers
    with open(run_dir / "answers.jsonl") as f:
        rows = [row for row in map(json.loads, f) if row["event"] == "answer"]
    assert len(rows) == answers and all(row["participant"] == "scripted" for row in rows)


@pytest.mark.parametrize(
    ("flags", "phrase"),
    [
        (["--participant", "P01"], "--participant: the web page's (--teacher browser)"),
        (["--host", "0.0.0.0"], "--host: the web page's (--teacher browser)"),
        (["--teacher", "browser", "--host", "127.0.0.1:99999"], "--host must be HOST or HOST:PORT"),
        (["--teacher", "browser", "--host", "no-such-host.invalid"], "--host no-such-host.invalid:0: cannot listen"),
        (["--teacher", "browser", "--host", "127.0.0.1:{port}"], "cannot listen there"),
        (["--teacher", "browser", "--teacher-noise", "0.1"], "--teacher browser takes the answers as they are"),
        (["--teacher", "browser", "--env-id", "FrozenLake-v1"], "--teacher browser: the maze's only"),
    ],
)
def test_the_maze_scripts_page_flags_are_refused_in_one_line_before_any_file(tmp_path, flags, phrase):
    """The page's flags without the page, a bad or taken address, a distorted person, another task: one line, exit 2,
    no run directory, before the page is opened."""
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        flags = [f.format(port=taken.getsockname()[1]) for f in flags]
        proc = subprocess.run([sys.executable, MAZE_SCRIPT, *flags], cwd=tmp_path, capture_output=True, text=True,
                              timeout=120)  # fmt: skip
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), proc.stderr[-2000:]
    assert phrase in lines[0], lines[0]
    assert not os.listdir(tmp_path), os.listdir(tmp_path)


# ---------------------------------------------------------------------------------------------------------------------
# the Pusher at the page: python -m inform_utils.browser_pusher

PUSHER_TINY = ["--tamer-total-timesteps", "3000", "--tamer-learning-starts", "50", "--tamer-batch-size", "32",
               "--sleep-batch-size", "32", "--sleep-gradient-steps", "100", "--eval-episodes", "1",
               "--obstacle-episodes", "1", "--authors-test-episodes", "1"]  # fmt: skip


def test_each_step_is_labelled_by_the_weighted_mean_of_the_answers_about_it():
    from inform_utils.browser_pusher import weighted_labels

    credited = {}
    assert weighted_labels(credited, [(1.0, {4: 0.25, 5: 0.5})]) == {4: 1.0, 5: 1.0}
    # a No about steps 5 and 6: step 5 is (0.5 * 1 + 0.25 * 0) / 0.75; step 4 is not touched again
    labels = weighted_labels(credited, [(0.0, {5: 0.25, 6: 0.75})])
    assert labels == {5: pytest.approx(2 / 3), 6: 0.0}
    assert credited == {4: (0.25, 0.25), 5: (0.5, 0.75), 6: (0.0, 0.75)}


def test_a_person_teaches_the_pusher_through_the_page_and_sees_the_night(new_page, tmp_path, monkeypatch):
    """The Pusher's page: the day waits for the page, the arm streams, three Yes and one No by key, then "End the
    day"; the night runs, the page shows its outcome (numbers and TAMER's and INFORM's episodes), and the run
    completes: every answer in answers.jsonl, the yes answers counted, their credit window labelling the saved day."""
    monkeypatch.setenv("PYTHONPATH", REPO)
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))
    flags = ["--participant", "T1", "--pace", "40", "--save-buffer", *PUSHER_TINY]
    child = Child([sys.executable, "-m", "inform_utils.browser_pusher", *flags], cwd=tmp_path)
    url = child.wait_for_line("[teacher] open the teaching page", timeout=180).split(": ", 1)[1].strip()
    time.sleep(1.0)
    (run_dir,) = (tmp_path / "runs").iterdir()
    assert not any(line.startswith("[tamer]") for line in child.out), "the day began before the page was opened"
    page = new_page(url)
    wait_until(lambda: page.evaluate("typeof state !== 'undefined' && state && state.mode") == "stream", "streaming")
    wait_until(lambda: page.evaluate("document.getElementById('frame').naturalWidth") == 320, "the arm's frame")
    for key in ("y", "y", "y", "n"):
        page.keyboard.press(key)
        time.sleep(0.3)
    wait_until(lambda: page.evaluate("state.answers") == 4, "four answers taken")
    if os.environ.get("INFORM_WRITE_SCREENSHOT") == "1":  # docs/teachers.md's: the Pusher's day at the page
        page.screenshot(path=PUSHER_SCREENSHOT, full_page=True)
    page.click("#end")
    page.click("#end")
    page.wait_for_selector("#outcome:visible", timeout=180_000)
    text = page.text_content("#outcome-text")
    assert "TAMER (left) and INFORM (right)" in text and "3 yes answers" in text, text
    code, out, err = child.finish(timeout=180)
    assert code == 0, err[-2000:]
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["args"]["participant"] == "T1"
    assert summary["feedback/positive"] == 3 and 0 < summary["feedback/steps"] < 3000  # the person ended the day
    with open(run_dir / "answers.jsonl") as f:
        rows = [row for row in map(json.loads, f) if row["event"] == "answer"]
    assert [row["answer"] for row in rows] == ["yes", "yes", "yes", "no"]
    assert all(row["mode"] == "stream" and len(row["action"]) == 7 and row["frame"]["sha256"] for row in rows)
    import torch

    feedback = torch.load(run_dir / "day.pt", weights_only=True)["feedback"]
    labelled = feedback.nonzero().squeeze(-1)
    assert labelled.numel() > 0 and float(feedback.max()) <= 1.0  # the yes answers' windows, at most 1
    assert int(labelled.max()) <= max(row["step_at_arrival"] for row in rows)  # an answer is about what came before


# the page's first drive post waits until the test lets it go; meanwhile the page's polls are counted: the second one
# is sent only after the first one's reply (from a server that has not seen the take) was taken in
HOLD_THE_FIRST_DRIVE = """() => {
  const send = window.fetch;
  let held = false, go = null;
  window.polledSinceHeld = 0;
  window.letTheDriveGo = () => { if (go) go(); };
  window.fetch = (address, options) => {
    if (String(address).includes("/drive") && !held) {
      held = true;
      return new Promise((resolve) => { go = resolve; }).then(() => send(address, options));
    }
    if (String(address).includes("/state") && held) window.polledSinceHeld += 1;
    return send(address, options);
  };
}"""


def test_a_person_takes_the_arm_drives_its_fingertip_by_keys_and_gives_it_back(new_page, tmp_path, monkeypatch):
    """Take control at the Pusher's page (issue 53): t takes the arm, the arrow keys move the fingertip's target 2 cm
    a press, the arm gets there (the operational-space controller, within the action limits), g gives it back. The
    person's steps are marked in the saved day and in answers.jsonl, and H hears each as a yes. The take's post is
    held back until a poll's reply that predates it has come: the page keeps its own take, and no press is lost."""
    import torch

    monkeypatch.setenv("PYTHONPATH", REPO)
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))
    flags = ["--participant", "D1", "--pace", "40", "--save-buffer", *PUSHER_TINY]
    child = Child([sys.executable, "-m", "inform_utils.browser_pusher", *flags], cwd=tmp_path)
    url = child.wait_for_line("[teacher] open the teaching page", timeout=180).split(": ", 1)[1].strip()
    (run_dir,) = (tmp_path / "runs").iterdir()
    page = new_page(url)
    wait_until(lambda: page.evaluate("Boolean(state && state.info && state.info._map)"), "the table's map")
    assert page.is_visible("#map") and page.get_attribute("#day", "data-driving") == "0"
    page.evaluate(HOLD_THE_FIRST_DRIVE)
    page.keyboard.press("t")
    wait_until(lambda: page.get_attribute("#day", "data-driving") == "1", "the arm taken")
    wait_until(lambda: page.evaluate("window.polledSinceHeld >= 2"), "a poll's reply from before the take")
    assert page.evaluate("state.driving") and page.get_attribute("#day", "data-driving") == "1"
    start = page.evaluate("state.target")
    for key, presses in (("ArrowUp", 14), ("ArrowRight", 8)):  # as the map is turned: 28 cm in x, 16 cm in y
        for _ in range(presses):
            page.keyboard.press(key)
            time.sleep(0.02)
        page.evaluate("window.letTheDriveGo()")  # the take reaches the server while the presses go on
    target = [start[0] - 0.28, start[1] + 0.16]
    wait_until(lambda: np.allclose(page.evaluate("state.target"), target, atol=1e-9), "the target at the server")

    def tip_distance():
        return float(np.linalg.norm(np.array(page.evaluate("state.info._map.tip")) - target))

    wait_until(lambda: tip_distance() < 0.02, "the fingertip at the target", timeout=60)
    time.sleep(0.5)  # a few more steps held there
    assert tip_distance() < 0.02
    page.keyboard.press("g")
    wait_until(lambda: page.get_attribute("#day", "data-driving") == "0", "the arm given back")
    time.sleep(0.5)
    page.click("#end")
    page.click("#end")
    code, out, err = child.finish(timeout=300)
    assert code == 0, err[-2000:]

    with open(run_dir / "answers.jsonl") as f:
        drives = [row for row in map(json.loads, f) if row["event"] == "drive"]
    assert [row["drive"] for row in drives] == ["take", *["target"] * 22, "release"]
    assert np.allclose(drives[-2]["target"], target) and all(row["participant"] == "D1" for row in drives)
    taken, released = drives[0]["step"], drives[-1]["step"]
    day = torch.load(run_dir / "day.pt", weights_only=True)
    driven = day["driven"].nonzero().squeeze(-1)
    assert driven.numel() > 10 and bool((driven[1:] - driven[:-1] == 1).all())  # one stretch of the person's steps
    # a drive is recorded with the step on the screen; the steps after it (the next one may be on its way) are driven
    assert 0 < int(driven[0]) - taken <= 2 and 0 <= int(driven[-1]) - released <= 2
    assert bool((day["feedback"][driven] > 0.99).all())  # H hears the person's own steps as yes
    assert bool((day["actions"][driven].abs() <= 2.0).all())
    tip = day["next_obs"][int(driven[-1]), 14:17].numpy()  # where the person left the fingertip
    assert np.linalg.norm(tip - np.array([*target, -0.275])) < 0.02, tip
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["feedback/driven_steps"] == driven.numel()


@pytest.mark.parametrize(
    ("values", "phrase"),
    [
        ({"credit_delay": (4.0, 0.2)}, "--credit-delay must be LOW HIGH seconds"),
        ({"credit_delay": (0.2, float("inf"))}, "--credit-delay must be LOW HIGH seconds"),
        ({"teacher_noise": 0.1}, "--teacher-noise: the simulated teacher's"),
        ({"env_id": "Reacher-v5"}, "the page shows the Pusher only"),
        ({"host": "127.0.0.1:99999"}, "--host must be HOST or HOST:PORT"),
        ({"pace": 0.0}, r"--pace must be in \(0, 100\]"),
        ({"no_label": 0.5}, "--no-label must be 0"),
    ],
)
def test_the_pusher_pages_flags_are_checked(values, phrase):
    import inform_sac_pusher as isp
    from inform_utils.browser_pusher import Args, check_page_args

    args = Args(**values)
    with pytest.raises(isp.InputError, match=phrase):
        check_page_args(args)
        isp.check_args(args)


def test_a_bad_flag_of_the_pusher_page_is_one_line_before_any_file(run_script):
    proc = run_script("inform_utils/browser_pusher.py", "--credit-delay", "4", "0.2", timeout=120)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), proc.stderr[-2000:]
    assert "--credit-delay must be LOW HIGH seconds" in lines[0], lines[0]
    assert not os.listdir(run_script.cwd), os.listdir(run_script.cwd)


@pytest.mark.parametrize("when", ["teaching", "before the page opens"])
def test_ctrl_c_ends_the_pushers_day_with_a_summary(tmp_path, monkeypatch, when):
    """Ctrl-C in the terminal while the person teaches, or while the run waits for the page: the run stops as every
    run does (summary.json, status interrupted, exit 130), and the page's record ends."""
    monkeypatch.setenv("PYTHONPATH", REPO)
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))
    child = Child([sys.executable, "-m", "inform_utils.browser_pusher", "--pace", "20", *PUSHER_TINY], cwd=tmp_path)
    url = child.wait_for_line("[teacher] open the teaching page", timeout=180).split(": ", 1)[1].strip()
    if when == "teaching":
        with urllib.request.urlopen(url, timeout=WAIT_S) as reply:  # the person's page opens: the day starts
            assert reply.status == 200
        child.wait_for_line("[tamer] 3000 env steps", timeout=60)
    child.proc.send_signal(signal.SIGINT)
    code, out, err = child.finish(timeout=120)
    assert code == 130 and "Traceback" not in err, err[-2000:]
    (run_dir,) = (tmp_path / "runs").iterdir()
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["phase"] == "tamer"
    with open(run_dir / "answers.jsonl") as f:
        ends = [row for row in map(json.loads, f) if row["event"] == "end"]
    assert len(ends) == 1, ends
