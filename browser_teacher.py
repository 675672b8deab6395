"""A person teaches INFORM through a web page (`--teacher browser`): the page shows the agent, the person answers Yes or
No to what it does (button or key: y, n; space for no answer), and "End the day" starts the night, whose outcome the
page then shows. A script imports this module only under `--teacher browser`.

One local page, served by the standard library's HTTP server in a daemon thread; one inline HTML page, no build step.
The standard library, not a server package (Flask, aiohttp): seven routes and long polling need nothing more, and no
new pin is needed to run it.
Safe by default: it listens on 127.0.0.1 unless told otherwise; the printed address carries a random token and a
request without it gets 403; only the routes below exist (any other path: 404) and no part of a request reaches the
file system. One person per run, by a session cookie and a tab: loading the page takes no role (a `curl` of the
address, a link preview or a prefetch teaches nothing); the first tab to act (answer, take the arm, or end the day)
teaches, and every other watches read-only, a second tab of the same browser as a second browser does (two tabs would
drive the arm each from its own target). A reload stays the same tab (its id is in the tab's sessionStorage; a
duplicated tab, which copies it, is a tab of its own). If the teaching tab goes silent for `takeover_after` seconds
(no long poll open: a crashed browser, a closed lid), another page holding the token may take over by acting; nothing
answered is lost.

    GET  /            the page
    GET  /state       the page's state as JSON; ?since=VERSION waits (up to 10 s) until it changes (long polling)
    GET  /frame.png   the newest frame as PNG (its sequence number in the X-Frame-Seq header)
    GET  /outcome     the picture of what came of the night (PNG, or an animated GIF)
    POST /answer      {"nonce", "answer": "yes" | "no" | "none", "question": id | null, "seq": frame, "waited_ms"}
    POST /drive       the Pusher: {"drive": "take" | "target" | "release", "target": [x, y]}: the person takes the
                      arm (its fingertip, or with drive_by "object" the object, goes to the target, metres in
                      the table's plane) or gives it back; a target
                      beyond the arm's `reach` is moved onto it, and the page says so
    POST /end         the person ends the day
    POST /bye         the page is being closed or reloaded: the day ends if, `close_grace` s later, no page is open

The page names itself in every request (?page=, one id a load; ?tab=, one id a tab), so a reload (a new page) is told
from a closed one, and a second tab from a reload.

Two ways to teach. `ask` waits for the person's answer about one move (the maze; the Pusher at the person's pace).
`show` streams steps at `pace` steps a second without waiting, and `answers` hands over what the person answered
since, each with the time it was given and the step on the screen; `credit` spreads an answer over the recent steps
as Deep TAMER does (Warnell et al. 2018: a delay uniform over 0.2-4 s), and `labels` turns answers into
{step: label}.

    with BrowserTeacher(run_dir, task="maze", participant="P01") as page:
        h = page.ask(step, action, state_text=gridworld_env.draw_maze(agent=cell, arrows={cell: action}))
        if page.ended:  # the person ended the day, or closed the page
            ...
        page.show_outcome("TAMER: 19 steps from S; INFORM: 19", image=rgb)

Every answer is one line of `answers.jsonl` in the run directory (flushed at once): its time, the step, the action,
the answer and the frame shown (sequence number and SHA-256; a maze's drawing itself); so is every take-over of the
arm, target and giving back (`"event": "drive"`, with the step it came at). While the person holds the arm,
`driving` is True and `target` their point; the script turns it into the arm's action. The page keeps an answer in
the browser's storage until the server has it, so a reload or a dropped connection loses none and the page resumes.
A script adds lines of its own to answers.jsonl with `note` (the Pusher's: the steps a take labelled).
"""

import hashlib
import http.cookies
import io
import itertools
import json
import os
import re
import secrets
import select
import socket
import struct
import threading
import time
import zlib
from collections import deque
from dataclasses import dataclass
from datetime import UTC, datetime
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from urllib.parse import parse_qs

import numpy as np

TASKS = ("maze", "pusher")
LABELS = {"yes": 1.0, "no": 0.0, "none": None}  # the person's answers and the label each gives
DEEP_TAMER_DELAY = (0.2, 4.0)  # seconds between what a person sees and their answer (Warnell et al. 2018)
LONG_POLL_S = 10.0  # a GET /state?since= waits at most this long for a change
MAX_BODY = 4096  # bytes of a POST body
NONCE = re.compile(r"[A-Za-z0-9_-]{1,64}")


@dataclass(frozen=True)
class Answer:
    """One answer of the person."""

    value: float | None
    """1.0 (yes), 0.0 (no) or None (no answer)"""
    label: str
    """"yes", "no" or "none\""""
    time: float
    """when it was given, on this process's time.monotonic() clock (its arrival less the time the page held it)"""
    step: int | None
    """the step on the person's screen when they answered (the question's step under `ask`)"""
    step_at_arrival: int | None
    """the newest step when the answer arrived"""
    question: int | None
    """the question it answers (`ask`), None for a streamed answer (`show`)"""


def credit_weights(
    answer_time: float, shown: list[tuple[int, float]], delay: tuple[float, float] = DEEP_TAMER_DELAY
) -> dict[int, float]:
    """Deep TAMER's credit window: an answer given at `answer_time` is about what was on the screen d seconds before,
    d ~ uniform(delay). `shown` lists (step, time it appeared), oldest first; a step stays on the screen until the
    next one appears. Returns {step: P(d lands in the time that step was on the screen)} for the steps with weight
    above zero (the weights sum to at most 1)."""
    low, high = delay
    weights: dict[int, float] = {}
    for i in range(len(shown) - 1, -1, -1):
        step, start = shown[i]
        end = min(shown[i + 1][1] if i + 1 < len(shown) else answer_time, answer_time)
        if end <= answer_time - high:
            break
        overlap = min(answer_time - start, high) - max(answer_time - end, low)
        if overlap > 0:
            weights[step] = weights.get(step, 0.0) + overlap / (high - low)
    return weights


def is_number(value, bound: float) -> bool:
    """A JSON number smaller than `bound` in size: not a bool (True is an int to Python), not NaN or inf, and a huge
    integer compared as it is (float() of a 4,000-digit one overflows)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and abs(value) < bound


def is_count(value) -> bool:  # a question's id or a frame's sequence number: 0 or more (0: none shown yet)
    return is_number(value, 2**53) and isinstance(value, int) and value >= 0


def clamp_to_reach(target, reach) -> tuple[tuple[float, float], bool]:
    """(the target moved onto the arm's reach if beyond it, whether it was): `reach` is ((x, y) of the arm's base,
    radius), metres in the table's plane; None: no limit."""
    x, y = float(target[0]), float(target[1])
    if reach is None:
        return (x, y), False
    (bx, by), radius = reach
    distance = ((x - bx) ** 2 + (y - by) ** 2) ** 0.5
    if distance <= radius:
        return (x, y), False
    return (bx + (x - bx) * radius / distance, by + (y - by) * radius / distance), True


def host_and_port(address: str) -> tuple[str, int]:
    """--host as (host, port): HOST, HOST:PORT, [IPv6]:PORT or a bare IPv6 address; port 0 takes a free one."""
    if address.startswith("["):
        host, _, port = address[1:].partition("]")
        port = port.removeprefix(":")
    else:
        host, port = address.split(":") if address.count(":") == 1 else (address, "")
    if not host or not (port == "" or port.isdigit() and int(port) < 65536):
        raise ValueError(f"--host must be HOST or HOST:PORT (a port below 65536), e.g. 0.0.0.0:8000; got {address!r}")
    return host, int(port or 0)


def check_address(host: str, port: int) -> None:
    """The page's address is free and ours to take, said before the run starts (nothing is written)."""
    try:
        with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as s:
            s.bind((host, port))
    except OSError as e:
        raise ValueError(f"--host {host}:{port}: cannot listen there ({e.strerror or e}); pick another") from None


def png_bytes(image: np.ndarray) -> bytes:
    """An RGB (H, W, 3), RGBA or grey (H, W) uint8 array as PNG, with zlib alone."""
    image = np.ascontiguousarray(image, dtype=np.uint8)
    if image.ndim == 2:
        image = image[:, :, None]
    height, width, channels = image.shape
    color_type = {1: 0, 3: 2, 4: 6}[channels]
    rows = np.concatenate([np.zeros((height, 1), np.uint8), image.reshape(height, width * channels)], axis=1)

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))

    header = struct.pack(">IIBBBBB", width, height, 8, color_type, 0, 0, 0)
    idat = zlib.compress(rows.tobytes(), 3)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", idat) + chunk(b"IEND", b"")


def gif_bytes(frames, fps: float = 10.0) -> bytes:
    """RGB uint8 frames as an animated GIF (Pillow, imported only here), looping."""
    from PIL import Image

    images = [Image.fromarray(np.ascontiguousarray(frame, dtype=np.uint8)) for frame in frames]
    if not images:
        raise ValueError("a video needs at least one frame")
    out = io.BytesIO()
    images[0].save(out, format="GIF", save_all=True, append_images=images[1:], duration=int(1000 / fps), loop=0)
    return out.getvalue()


def as_json(value):
    """Actions and info values (numpy scalars and arrays included) as plain JSON values."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, dict):
        return {str(k): as_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [as_json(v) for v in value]
    if value is None or isinstance(value, bool | int | float | str):
        return value
    return str(value)


class BrowserTeacher:
    """The page and what a training loop calls: `ask` (wait for an answer), `show` and `answers` (stream at a pace),
    `credit`, `message`, `show_outcome`, `close`. `ended` is None while the day goes on, else why it ended: "end of
    day" (the button), "page closed", "interrupted" (Ctrl-C in the script while it waited) or "closed" (close())."""

    def __init__(
        self,
        run_dir: str,
        task: str = "maze",
        host: str = "127.0.0.1",
        port: int = 0,
        participant: str | None = None,
        budget: int | None = None,
        pace: float | None = None,
        delay: tuple[float, float] = DEEP_TAMER_DELAY,
        close_grace: float = 5.0,
        linger: float = 5.0,
        quiet: bool = False,
        takeover_after: float = 5.0,
        no_value: float = 0.0,
        reach: tuple[tuple[float, float], float] | None = None,
        day_steps: int | None = None,
        drive_by: str = "fingertip",
    ):
        if task not in TASKS:
            raise ValueError(f"task must be one of {TASKS}, got {task!r}")
        if pace is not None and pace <= 0:
            raise ValueError(f"pace must be above 0 steps a second, got {pace}")
        if not 0 <= delay[0] < delay[1]:
            raise ValueError(f"delay must be (low, high) seconds with 0 <= low < high, got {delay}")
        if drive_by not in ("fingertip", "object"):
            raise ValueError(f"drive_by must be fingertip or object (what the person's target moves), got {drive_by!r}")
        if no_value not in (0.0, -1.0):
            raise ValueError(f"no_value must be 0 (the paper's no feedback) or -1 (TAMER's), got {no_value}")
        self.values = {**LABELS, "no": float(no_value)}  # the label each answer gives: a No 0, or TAMER's -1
        self.driving = False  # the person holds the arm (the Pusher), and moves its fingertip's target (x, y)
        self.target: tuple[float, float] | None = None
        self.reach = None if reach is None else ((float(reach[0][0]), float(reach[0][1])), float(reach[1]))
        self.clamped = False  # the newest target was beyond the reach, and moved onto it
        self.drive_by = drive_by  # what a person's target moves: the fingertip, or the object (a planner pushes it)
        self.day_steps = day_steps  # the day's steps at most (the page shows the steps and the time left)
        self.task = task
        self.participant = participant
        self.budget = budget
        self.pace = pace
        self.delay = (float(delay[0]), float(delay[1]))
        self.close_grace = close_grace
        self.linger = linger
        self.takeover_after = takeover_after
        self.token = secrets.token_urlsafe(24)
        self.run_id = hashlib.sha256(self.token.encode()).hexdigest()[:12]  # names the cookie and the page's storage
        self.cookie = f"inform_{self.run_id}"
        self.ended: str | None = None
        self._cond = threading.Condition()  # guards everything below; notified at each change
        self._version = 0
        self._started = time.monotonic()
        self._closed = self._closing = False
        self._sessions: set[str] = set()
        self._owner: str | None = None  # the session that teaches: the first to act, or one that took over
        self._owner_tab: str | None = None  # and its tab that teaches (None: a client that names no tab)
        self._pages: dict[str, float] = {}  # the owner's pages (one a load of the page): when each was last heard
        self._tabs: dict[str, str | None] = {}  # the tab of each of them
        self._pages_gone: set[str] = set()  # the pages that said goodbye (closed, or reloaded)
        self._bye_at: float | None = None
        self._step: int | None = None
        self._counts = dict.fromkeys(LABELS, 0)
        self._nonces: set[str] = set()
        self._question: dict | None = None  # the move `ask` waits on
        self._question_answer: Answer | None = None
        self._questions = 0
        self._mode = "wait"  # ask | wait | stream | ended | outcome | closed
        self._frame_seq = 0
        self._frame: np.ndarray | None = None  # the newest frame (RGB uint8), and its PNG once asked for
        self._frame_png: tuple[int, bytes] | None = None
        self._frames: deque = deque(maxlen=4096)  # (seq, step, action, sha256, state_text) of recent frames
        self._shown: deque = deque(maxlen=4096)  # (step, time) as `show` and `ask` put them on the screen
        self._state_text: str | None = None
        self._info: dict = {}
        self._streamed: list[Answer] = []
        self._next_show = 0.0
        self._message = ""
        self._outcome: dict | None = None
        self._outcome_image: tuple[bytes, str] | None = None  # (bytes, content type)
        self._outcome_fetched = False  # by the person's page
        self._owner_version = -1  # the newest state the person's page was sent
        handler = type("Handler", (_Handler,), {"teacher": self})
        server_class = _Server6 if ":" in host else _Server
        self._server = server_class((host, port), handler)  # first: a port in use is an OSError before any file
        self.host, self.port = host, self._server.server_address[1]
        os.makedirs(run_dir, exist_ok=True)
        self.answers_path = os.path.join(run_dir, "answers.jsonl")
        self._log = open(self.answers_path, "a", encoding="utf-8")
        start = {"event": "start", "task": task, "participant": participant, "budget": budget, "pace": pace}
        start |= {"delay": self.delay, "host": host, "port": self.port, "no_value": self.values["no"]}
        self._record(start | {"reach": self.reach, "day_steps": day_steps, "drive_by": drive_by})
        shown_host = socket.gethostname() if host in ("", "0.0.0.0", "::") else host
        shown_host = f"[{shown_host}]" if ":" in shown_host else shown_host
        self.url = f"http://{shown_host}:{self.port}/?token={self.token}"
        self._thread = threading.Thread(
            target=self._server.serve_forever, kwargs={"poll_interval": 0.1}, name="browser-teacher", daemon=True
        )
        self._thread.start()
        if not quiet:
            print(f"[teacher] open the teaching page in a browser: {self.url}", flush=True)

    # ---- what a training loop calls

    def ask(self, step: int, action, state_text: str | None = None, frame=None, info: dict | None = None):
        """Show the agent's proposed move (a maze drawn as text, and/or an RGB uint8 frame) and wait for the person: 1.0
        (yes), 0.0 (no), or None: no answer, or the day ended (then `ended` says why). Ctrl-C (KeyboardInterrupt)
        while it waits ends the day as "interrupted" and is raised again, for the script to stop as it always does."""
        with self._cond:
            if self.ended is not None:
                return None
            self._questions += 1
            self._put_frame(step, action, state_text, frame)
            self._shown.append((step, time.monotonic()))
            self._question = {
                "id": self._questions,
                "step": step,
                "action": as_json(action),
                "frame_seq": self._frame_seq,
                "info": as_json(info or {}),
                "answered": None,
            }
            self._question_answer = None
            self._mode = "ask"
            self._changed()
            try:
                while self._question_answer is None and self.ended is None:
                    self._cond.wait(0.2)  # short waits: a signal handler runs, and a closed page is noticed
                    self._check_page_closed()
            except KeyboardInterrupt:
                self._end("interrupted")
                raise
            answer = self._question_answer
            self._mode = "wait" if self.ended is None else self._mode
            self._changed()
            return None if answer is None else answer.value

    def show(self, step: int, frame=None, action=None, state_text: str | None = None, info: dict | None = None):
        """Put a step on the screen without waiting for an answer (the Pusher streamed at a person's pace): at most
        `pace` steps a second (it sleeps for the rest), answers arriving meanwhile wait in `answers()`."""
        if self.pace is not None:
            now = time.monotonic()
            if now < self._next_show:
                time.sleep(self._next_show - now)
            self._next_show = max(now, self._next_show) + 1.0 / self.pace
        with self._cond:
            self._check_page_closed()
            if self.ended is not None:
                return
            self._put_frame(step, action, state_text, frame)
            self._shown.append((step, time.monotonic()))
            self._info = as_json(info or {})
            self._question = None
            self._mode = "stream"
            self._changed()

    def person_here(self, timeout: float) -> bool:
        """Whether the person's page has opened (or the day ended), waiting at most `timeout` s for it: a stream
        starts when someone watches. Short waits in a loop let the caller's signal handling run between them."""
        with self._cond:
            return self._cond.wait_for(lambda: bool(self._sessions) or self.ended is not None, timeout)

    def answers(self) -> list[Answer]:
        """The streamed answers that came since the last call, oldest first."""
        with self._cond:
            self._check_page_closed()
            answers, self._streamed = self._streamed, []
            return answers

    def credit(self, answer: Answer, delay: tuple[float, float] | None = None) -> dict[int, float]:
        """{step: weight} of the steps an answer is about: Deep TAMER's window over what was on the screen."""
        with self._cond:
            shown = [(step, t) for step, t in self._shown if t < answer.time]
        return credit_weights(answer.time, shown, delay or self.delay)

    def labels(self, answers: list[Answer], delay: tuple[float, float] | None = None) -> dict[int, float]:
        """{step: label} from streamed answers: each yes (1.0) or no (0.0) on every step of its credit window (a
        weighted loss would use `credit`'s weights instead); no answer labels nothing; a later answer wins on a step
        that two windows cover."""
        labels: dict[int, float] = {}
        for answer in answers:
            if answer.value is not None:
                labels.update(dict.fromkeys(self.credit(answer, delay), answer.value))
        return labels

    def note(self, event: str, **fields) -> None:
        """A line of the script's own in answers.jsonl, with the step on the screen (e.g. the steps a take labelled)."""
        with self._cond:
            self._record({"event": event, "step": self._step, **as_json(fields)})

    def end_day(self, why: str = "day done") -> None:
        """The script ends the day itself (its steps or the budget are spent): the page says so."""
        with self._cond:
            self._end(why)

    def message(self, text: str) -> None:
        """A line under the progress, e.g. how the night goes."""
        with self._cond:
            self._message = str(text)
            self._changed()

    def show_outcome(self, text: str, image=None, fps: float = 10.0) -> None:
        """After the night: the numbers (`text`, monospaced; a maze's drawn paths in colour) and a picture, if any:
        an RGB array, a list of them (a short video, shown as an animated GIF at `fps`), or PNG or GIF bytes."""
        picture = None
        if isinstance(image, bytes | bytearray):
            kind = "image/gif" if image[:4] == b"GIF8" else "image/png" if image[:4] == b"\x89PNG" else None
            if kind is None:
                raise ValueError("image bytes must be a PNG or a GIF")
            picture = (bytes(image), kind)
        elif isinstance(image, list | tuple):
            picture = (gif_bytes(image, fps), "image/gif")
        elif image is not None:
            picture = (png_bytes(image), "image/png")
        with self._cond:
            if self.ended is None:
                self._end("day done")
            number = self._outcome["id"] + 1 if self._outcome else 1
            self._outcome = {"id": number, "text": str(text), "image": picture is not None}
            self._outcome_image = picture
            self._outcome_fetched = False
            self._mode = "outcome"
            self._changed()

    def close(self) -> None:
        """Stop serving (the day ends as "closed" if it had not ended); the page shows that the run is over. An open
        page first gets the newest state and the outcome's picture: close waits for that, at most `linger` s."""
        with self._cond:
            if self._closed or self._closing:
                return
            self._closing = True
            if self.ended is None:
                self._end("closed")
        try:
            with self._cond:
                self._cond.wait_for(self._page_has_all, self.linger)
        finally:
            with self._cond:
                self._closed = True
                self._changed()  # waiting long polls answer with the final state before the server stops
            self._server.shutdown()
            self._server.server_close()
            self._thread.join(5)
            with self._cond:
                self._log.close()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is KeyboardInterrupt and self.ended is None:
            with self._cond:
                self._end("interrupted")
        self.close()

    # ---- inside (the caller holds self._cond)

    def _changed(self) -> None:
        self._version += 1
        self._cond.notify_all()

    def _elapsed(self) -> float:
        return round(time.monotonic() - self._started, 3)

    def _record(self, line: dict) -> None:
        if self._log.closed:
            return
        now = datetime.now(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")
        self._log.write(json.dumps({"time": now, "t": self._elapsed(), **line}) + "\n")
        self._log.flush()

    def _end(self, why: str) -> None:
        if self.ended is not None:
            return
        self.ended = why
        self._mode = "ended"
        self._record({"event": "end", "why": why, "step": self._step, "answers": sum(self._counts.values())})
        self._changed()

    def _live_pages(self) -> list[str]:
        """The person's pages still open: heard from lately (an open page long-polls) and not gone."""
        now = time.monotonic()
        return [page for page, t in self._pages.items() if page not in self._pages_gone and now - t < LONG_POLL_S + 3]

    def _check_page_closed(self) -> None:
        """A page said goodbye (closed or reloaded) close_grace ago, and no page of the person's is open: closed."""
        if self._bye_at is not None and time.monotonic() - self._bye_at > self.close_grace:
            self._bye_at = None
            if not self._live_pages():
                self._end("page closed")

    def _put_frame(self, step, action, state_text, frame) -> None:
        self._step = step
        self._frame_seq += 1
        if frame is not None:
            frame = np.asarray(frame, dtype=np.uint8)
            digest = hashlib.sha256(frame.tobytes()).hexdigest()[:16]
        else:
            digest = hashlib.sha256((state_text or "").encode()).hexdigest()[:16]
        self._frame = frame
        self._frame_png = None
        self._state_text = state_text
        self._frames.append((self._frame_seq, step, as_json(action), digest, state_text))

    def _frame_record(self, seq: int | None):
        """(seq, step, action, sha256, state_text) of frame `seq` if still known, else of the newest."""
        for record in reversed(self._frames):
            if not seq or record[0] <= seq:
                return record
        return self._frames[0] if self._frames else (None, self._step, None, None, None)

    # ---- the routes' logic (called by the handler threads)

    def _rate(self) -> float | None:
        """Steps a second the page was shown over the last 5 s (the pace, unless the loop falls behind it)."""
        if not self._shown:
            return None
        now = time.monotonic()
        recent = sum(1 for _ in itertools.takewhile(lambda shown: shown[1] > now - 5.0, reversed(self._shown)))
        return round(recent / max(min(5.0, now - self._shown[0][1]), 1e-3), 2)

    def _state(self, role: str, takeover: bool = False) -> dict:
        return {
            "version": self._version,
            "mode": "closed" if self._closed else self._mode,
            "role": role,
            "takeover": takeover,
            "task": self.task,
            "participant": self.participant,
            "step": self._step,
            "answers": sum(self._counts.values()),
            "yes": self._counts["yes"],
            "no": self._counts["no"],
            "none": self._counts["none"],
            "budget": self.budget,
            "elapsed": self._elapsed(),
            "question": self._question,
            "frame_seq": self._frame_seq,
            "has_frame": self._frame is not None,
            "state_text": self._state_text,
            "info": self._info,
            "message": self._message,
            "ended": self.ended,
            "outcome": self._outcome,
            "delay": self.delay,
            "pace": self.pace,
            "driving": self.driving,
            "target": self.target,
            "reach": None if self.reach is None else {"base": self.reach[0], "radius": self.reach[1]},
            "clamped": self.clamped,
            "day_steps": self.day_steps,
            "drive_by": self.drive_by,
            "rate": self._rate() if self._mode == "stream" else None,
        }

    def _wait_state(self, since: int | None, role: str, session, page, connected, tab=None) -> dict:
        """The state once it differs from version `since` (at most LONG_POLL_S later). While it waits, an open poll
        of the owner's page keeps it heard; a poll whose browser went away ends at once (`connected()` says so)."""
        with self._cond:
            deadline = time.monotonic() + LONG_POLL_S
            while since is not None and self._version == since and not self._closed:
                if (left := deadline - time.monotonic()) <= 0 or not connected():
                    break
                if (role == "teacher") != self._may_teach(session, tab):  # the owner went silent: say so at once
                    break
                self._cond.wait(min(left, 0.5))
                self._heard(session, page, tab)
            teaches = role == "teacher" and self._may_teach(session, tab)  # it may have changed
            if teaches:
                self._owner_version = self._version
                self._cond.notify_all()  # close() may wait for this
            # another tab than the teaching one may teach only because that one went silent: it takes over by acting
            takeover = teaches and self.ended is None and (session, tab) != (self._owner, self._owner_tab)
            return self._state("teacher" if teaches else "watcher", takeover and self._owner is not None)

    def _outcome_picture(self, role: str) -> tuple[bytes, str] | None:
        with self._cond:
            if role == "teacher" and self._outcome_image is not None:
                self._outcome_fetched = True
                self._cond.notify_all()
            return self._outcome_image

    def _page_has_all(self) -> bool:
        """The person's page has the newest state and the outcome's picture (or no page is open to want them)."""
        gone = not self._live_pages()
        fetched = self._outcome_image is None or self._outcome_fetched
        return gone or (self._owner_version >= self._version and fetched)

    def _png(self) -> tuple[int | None, bytes | None]:
        with self._cond:
            if self._frame is None:
                return None, None
            if self._frame_png is None or self._frame_png[0] != self._frame_seq:
                self._frame_png = (self._frame_seq, png_bytes(self._frame))
            return self._frame_png

    def _take_answer(self, body: dict) -> tuple[int, dict]:
        """A POSTed answer: (HTTP status, reply). A nonce seen before is a retry, and taken once only."""
        nonce, label, question = body.get("nonce"), body.get("answer"), body.get("question")
        seq, waited_ms = body.get("seq"), body.get("waited_ms", 0)
        if not (isinstance(nonce, str) and NONCE.fullmatch(nonce)) or label not in LABELS:
            return 400, {"error": "an answer needs a nonce and one of yes, no, none"}
        if not all(value is None or is_count(value) for value in (question, seq)):  # seq -7 was the oldest frame's
            return 400, {"error": "question and seq are integers, 0 or more"}
        if not is_number(waited_ms, 3.6e6) or waited_ms < 0:
            waited_ms = 0
        with self._cond:
            if nonce in self._nonces:
                return 200, {"taken": False, "why": "already taken"}
            if self.ended is not None:
                return 409, {"taken": False, "why": "the day is over"}
            if question is None and self._mode != "stream":
                return 409, {"taken": False, "why": "the agent is not streaming now"}
            if question is not None and (
                self._question is None or self._question["id"] != question or self._question["answered"]
            ):
                return 409, {"taken": False, "why": "that question is not open"}
            self._nonces.add(nonce)
            arrived = time.monotonic()
            given = max(arrived - waited_ms / 1000.0, self._started)
            if question is not None:
                frame = self._frame_record(self._question["frame_seq"])
                step = self._question["step"]
            else:
                frame = self._frame_record(seq)
                step = frame[1]
            answer = Answer(self.values[label], label, given, step, self._step, question)
            self._counts[label] += 1
            record = {"event": "answer", "participant": self.participant, "mode": "ask" if question else "stream"}
            record |= {"question": question, "step": step, "step_at_arrival": self._step, "action": frame[2]}
            record |= {"answer": label, "value": answer.value, "given_s": round(given - self._started, 3)}
            record |= {"frame": {"seq": frame[0], "sha256": frame[3]}}
            if frame[4] is not None:
                record["state_text"] = frame[4]
            self._record(record)
            if question is not None:
                self._question["answered"] = label
                self._question_answer = answer
            else:
                self._streamed.append(answer)
            self._changed()
            return 200, {"taken": True}

    def _take_drive(self, body: dict) -> tuple[int, dict]:
        """A POSTed take-over of the arm: "take" it (at `target`), move its "target", or "release" it; (HTTP status,
        reply). Each is a line of answers.jsonl with the step it came at."""
        kind, target = body.get("drive"), body.get("target")
        if kind not in ("take", "target", "release"):
            return 400, {"error": "drive is one of take, target, release"}
        if kind != "release" and not (
            isinstance(target, list) and len(target) == 2 and all(is_number(v, 5) for v in target)
        ):
            return 400, {"error": "a take or a target needs target: [x, y], metres in the table's plane"}
        with self._cond:
            if self.ended is not None:
                return 409, {"driving": False, "why": "the day is over"}
            if self.task != "pusher" or self._mode != "stream":
                return 409, {"driving": False, "why": "the arm is not streaming now"}
            if kind != "take" and not self.driving:  # a target or a release of an arm not taken: nothing to log
                return 409, {"driving": False, "why": "take the arm first"}
            self.driving = kind != "release"
            record = {"event": "drive", "participant": self.participant, "drive": kind, "step": self._step}
            if kind != "release":  # beyond the reach the fingertip stops short of the target: it goes to the reach
                self.target, self.clamped = clamp_to_reach(target, self.reach)
                record |= {"asked": [float(v) for v in target]} if self.clamped else {}
            self._record(record | {"target": None if self.target is None else list(self.target)})
            self._changed()
            return 200, {"driving": self.driving, "target": self.target, "clamped": self.clamped}

    def _session(self, cookie_header: str | None, make: bool) -> tuple[str | None, str | None]:
        """(the request's session, a new session id to set as a cookie) for one request."""
        session = None
        if cookie_header:
            try:
                morsel = http.cookies.SimpleCookie(cookie_header).get(self.cookie)
            except http.cookies.CookieError:
                morsel = None
            session = morsel.value if morsel is not None else None
        with self._cond:
            if session in self._sessions:
                return session, None
            if not make:
                return None, None
            session = secrets.token_urlsafe(18)
            self._sessions.add(session)
            return session, session

    def _owner_silent(self) -> bool:  # no page of the teaching tab heard within takeover_after (or all said bye)
        now = time.monotonic()
        return not any(now - t < self.takeover_after for p, t in self._pages.items()
                       if p not in self._pages_gone and self._tabs.get(p) == self._owner_tab)  # fmt: skip

    def _may_teach(self, session: str | None, tab: str | None = None) -> bool:
        """A tab of this run teaches if it owns the role, if nobody has acted yet, or if the owner went silent."""
        owns = self._owner is None or (session, tab) == (self._owner, self._owner_tab)
        return session in self._sessions and (owns or self._owner_silent())

    def _heard(self, session: str | None, page: str | None, tab: str | None) -> None:
        """A page of the teaching session was heard from: its pages still open end no day (`_live_pages`), and its
        teaching tab's keep others from taking over."""
        if session is not None and session == self._owner and page is not None:
            self._pages[page], self._tabs[page] = time.monotonic(), tab

    def _role(self, session: str | None, page: str | None, act: bool = False, tab: str | None = None) -> str:
        """ "teacher" or "watcher" for one request; `act` (an answer, a drive, the end of the day): a tab that may
        teach takes the role, and a takeover is said on every page and in answers.jsonl."""
        with self._cond:
            teaches = self._may_teach(session, tab)
            if teaches and act and (session, tab) != (self._owner, self._owner_tab):
                if self._owner is not None:
                    self._message = "Another page took over teaching: the page that taught had gone silent."
                    self._record({"event": "takeover", "step": self._step, "answers": sum(self._counts.values())})
                    self._pages.clear()
                    self._changed()
                self._owner, self._owner_tab = session, tab
            self._heard(session, page, tab)
            return "teacher" if teaches else "watcher"


class _Server(ThreadingHTTPServer):
    daemon_threads = True  # a waiting long poll never holds up the process's exit
    block_on_close = False

    def handle_error(self, request, client_address):  # a browser that went away mid-reply is no error of ours
        pass


class _Server6(_Server):
    address_family = socket.AF_INET6


class _Handler(BaseHTTPRequestHandler):
    teacher: BrowserTeacher
    server_version = "inform"
    sys_version = ""
    timeout = 60  # a silent client does not hold a thread for ever

    def log_message(self, format, *args):  # the script's terminal stays the script's
        pass

    def do_GET(self):
        self.route("GET")

    def do_POST(self):
        self.route("POST")

    def route(self, method: str):
        path, _, query = self.path.partition("?")  # as sent: no parser's idea of a host or of dots
        query = parse_qs(query.partition("#")[0], max_num_fields=8)
        token = query.get("token", [""])[0]
        if not secrets.compare_digest(token.encode(), self.teacher.token.encode()):
            return self.reply(403, b"403: this address needs the token the script printed\n", "text/plain")
        routes = {
            "/": ("GET", self.page),
            "/state": ("GET", self.state),
            "/frame.png": ("GET", self.frame),
            "/outcome": ("GET", self.outcome),
            "/answer": ("POST", self.answer),
            "/drive": ("POST", self.drive),
            "/end": ("POST", self.end),
            "/bye": ("POST", self.bye),
        }
        if path not in routes:
            return self.reply(404, b"404: not a page of this run\n", "text/plain")
        allowed, handle = routes[path]
        if method != allowed:
            return self.reply(405, b"405\n", "text/plain", {"Allow": allowed})
        session, new = self.teacher._session(self.headers.get("Cookie"), make=path == "/")
        page, tab = (query.get(name, [""])[0] for name in ("page", "tab"))
        page, tab = (value if NONCE.fullmatch(value) else None for value in (page, tab))
        role = self.teacher._role(session, page, act=path in ("/answer", "/drive", "/end"), tab=tab)
        self.session, self.page_id, self.tab = session, page, tab
        handle(query, role, new)

    def connected(self) -> bool:
        """Whether the client still holds the connection: a long poll's socket reads as empty once it has gone."""
        try:
            readable, _, _ = select.select([self.connection], [], [], 0)
            return not readable or bool(self.connection.recv(1, socket.MSG_PEEK))
        except OSError:
            return False

    def reply(self, status: int, body: bytes, content_type: str, headers: dict | None = None):
        try:
            self.send_response(status)
            self.send_header("Content-Type", content_type)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.send_header("X-Content-Type-Options", "nosniff")
            self.send_header("Referrer-Policy", "no-referrer")
            self.send_header("X-Frame-Options", "DENY")
            for name, value in (headers or {}).items():
                self.send_header(name, value)
            self.end_headers()
            self.wfile.write(body)
        except (BrokenPipeError, ConnectionResetError):
            pass

    def reply_json(self, status: int, value: dict):
        self.reply(status, json.dumps(value).encode(), "application/json")

    def body(self) -> dict | None:
        try:
            length = int(self.headers.get("Content-Length", ""))
        except ValueError:
            return None
        if not 0 <= length <= MAX_BODY:
            return None
        try:
            value = json.loads(self.rfile.read(length) or b"{}")
        except (ValueError, UnicodeDecodeError, RecursionError):  # a body nested thousands deep too: 400, not a drop
            return None
        return value if isinstance(value, dict) else None

    def page(self, query, role, new_session):
        nonce = secrets.token_urlsafe(16)  # only the page's own script runs
        headers = {"Content-Security-Policy": CSP.format(nonce=nonce)}
        if new_session:
            headers["Set-Cookie"] = f"{self.teacher.cookie}={new_session}; Path=/; HttpOnly; SameSite=Strict"
        body = PAGE.replace("__RUN_ID__", self.teacher.run_id).replace("<script>", f'<script nonce="{nonce}">')
        body = body.encode()
        self.reply(200, body, "text/html; charset=utf-8", headers)

    def state(self, query, role, new_session):
        since = query.get("since", [""])[0]
        since = int(since) if since.lstrip("-").isdigit() and len(since) < 12 else None
        state = self.teacher._wait_state(since, role, self.session, self.page_id, self.connected, self.tab)
        self.reply_json(200, state)

    def frame(self, query, role, new_session):
        seq, png = self.teacher._png()
        if png is None:
            return self.reply(404, b"404: no frame yet\n", "text/plain")
        self.reply(200, png, "image/png", {"X-Frame-Seq": str(seq)})

    def outcome(self, query, role, new_session):
        picture = self.teacher._outcome_picture(role)
        if picture is None:
            return self.reply(404, b"404: no outcome yet\n", "text/plain")
        self.reply(200, *picture)

    def answer(self, query, role, new_session):
        body = self.body()
        if body is None:
            return self.reply_json(400, {"error": "the body must be a JSON object of at most 4096 bytes"})
        if role != "teacher":
            return self.reply_json(403, {"error": "read-only: another page teaches this run"})
        self.reply_json(*self.teacher._take_answer(body))

    def drive(self, query, role, new_session):
        body = self.body()
        if body is None:
            return self.reply_json(400, {"error": "the body must be a JSON object of at most 4096 bytes"})
        if role != "teacher":
            return self.reply_json(403, {"error": "read-only: another page teaches this run"})
        self.reply_json(*self.teacher._take_drive(body))

    def end(self, query, role, new_session):
        if role != "teacher":
            return self.reply_json(403, {"error": "read-only: another page teaches this run"})
        with self.teacher._cond:
            self.teacher._end("end of day")
        self.reply_json(200, {"ended": self.teacher.ended})

    def bye(self, query, role, new_session):
        page = query.get("page", [""])[0]
        with self.teacher._cond:  # only the teaching session's pages: closing a page that never acted ends nothing
            if role == "teacher" and NONCE.fullmatch(page) and self.session == self.teacher._owner:
                self.teacher._pages_gone.add(page)
                self.teacher._bye_at = time.monotonic()
        self.reply(204, b"", "text/plain")


CSP = (
    "default-src 'none'; script-src 'nonce-{nonce}'; style-src 'unsafe-inline'; img-src blob: data:; "
    "connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
)

PAGE = r"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>INFORM: teach the agent</title>
<meta name="viewport" content="width=device-width, initial-scale=1"><link rel="icon" href="data:,">
<style>
body{font-family:system-ui,sans-serif;margin:1.2rem auto;max-width:54rem;padding:0 1rem;color:#1d1d1d}
h1{font-size:1.35rem;margin:0 0 .4rem} h2{font-size:1.1rem;margin:.4rem 0}
#progress{font-variant-numeric:tabular-nums;color:#333;background:#f1f3f5;padding:.35rem .6rem;border-radius:5px}
#pace{color:#333;font-size:.95rem;margin:.25rem 0;font-variant-numeric:tabular-nums}
#message{color:#555;margin:.3rem 0;min-height:1.2em}
.banner{padding:.45rem .7rem;border-radius:5px;margin:.4rem 0}
.watch{background:#fff3cd} .offline{background:#f8d7da} .over{background:#e7f1ff}
#question{font-size:1.2rem;margin:.5rem 0;min-height:1.5em}
#view{display:flex;gap:1.2rem;align-items:flex-start;flex-wrap:wrap}
pre{font-size:22px;line-height:1.12;background:#f6f8fa;padding:.6rem .9rem;border-radius:6px;margin:0}
#outcome-text{font-size:15px;line-height:1.3}
.agent{color:#c62828;font-weight:bold} .goal{color:#2e7d32;font-weight:bold}
.move{color:#fff;background:#c62828;font-weight:bold}
img{max-width:100%;border-radius:6px}
#info{color:#444;margin:.5rem 0;font-variant-numeric:tabular-nums}
button{font-size:1.05rem;padding:.55rem 1.1rem;margin:.3rem .3rem .3rem 0;border-radius:6px;border:1px solid #777;
  background:#fff;cursor:pointer}
button.yes{background:#e8f5e9;border-color:#2e7d32} button.no{background:#ffebee;border-color:#c62828}
button:disabled{opacity:.4;cursor:default} #end{margin-left:1.2rem}
kbd{border:1px solid #aaa;border-radius:3px;padding:0 .25rem;font-size:.85em;background:#fafafa}
#hint{color:#555;font-size:.95rem}
#map{border:1px solid #bbb;border-radius:6px;background:#f4efe6;cursor:crosshair}
#drive-status{color:#333;margin:.3rem 0} #drive-status.you{color:#1b5e20;font-weight:bold}
#task{font-size:1.1rem;font-weight:bold;margin:.2rem 0 .5rem} #keys{color:#333;font-size:.95rem;margin:.3rem 0}
#mapbox{width:240px} #legend{font-size:.8rem;color:#444} #clamp{color:#b71c1c;font-weight:bold;min-height:1.2em}
</style></head>
<body>
<h1>INFORM: teach the agent</h1>
<div id="task" hidden></div>
<div id="progress">connecting…</div>
<div id="pace"></div>
<div id="message"></div>
<div id="banner" hidden></div>
<div id="day">
<div id="question"></div>
<div id="view"><pre id="maze" hidden></pre><img id="frame" alt="the agent" hidden>
<div id="mapbox" hidden><canvas id="map" width="240" height="240"></canvas>
<div id="legend">The table from above, turned as the view beside it: <b style="color:#e53935">&#9679;</b> goal,
&#9675; object, <b style="color:#1e88e5">&#9679;</b> fingertip, <b>&#9632;</b> the arm's base, the circle its reach,
<b style="color:#2e7d32">+</b> your target.</div><div id="clamp"></div></div></div>
<div id="keys" hidden>Keys: <kbd>y</kbd> yes and <kbd>n</kbd> no (hold one down to keep answering);
<kbd>t</kbd> or a click on the map takes the arm, and <span class="follows"></span>: click again, or move it
with the arrow keys (2 cm a press, as the map is turned); <kbd>g</kbd> gives it back to the agent.</div>
<div id="drive" hidden><button id="take">Take the arm <kbd>t</kbd></button>
<button id="release">Give it back <kbd>g</kbd></button><div id="drive-status"></div></div>
<div id="info"></div>
<div id="buttons">
<button id="yes" class="yes" disabled>Yes <kbd>y</kbd></button>
<button id="no" class="no" disabled>No <kbd>n</kbd></button>
<button id="none" disabled>No answer <kbd>space</kbd></button>
<button id="end" disabled>End the day</button>
</div>
<div id="hint"></div>
</div>
<div id="outcome" hidden><h2>What came of it</h2><pre id="outcome-text"></pre>
<img id="outcome-img" alt="the outcome" hidden></div>
<script>
"use strict";
const TOKEN = new URLSearchParams(location.search).get("token") || "";
const QUEUE = "inform_pending___RUN_ID__";  // answers the server has not confirmed yet: they survive a reload
const $ = (id) => document.getElementById(id);
let state = null, receivedAt = 0, shownSeq = 0, offline = false, endArmed = 0, gone = false;
const answered = new Set();  // the questions this page answered (the state may not say so yet)
let outcomeShown = null;  // the outcome whose picture was fetched
const PAGE = nonce();  // this load of the page: the server tells a reload from a closed page by it
const RELOAD = (performance.getEntriesByType("navigation")[0] || {}).type === "reload";
const TAB = (RELOAD && sessionStorage.getItem("inform_tab")) || nonce();  // this tab, the same after a reload (a
// duplicated tab copies sessionStorage, but is not a reload: a tab of its own): one tab teaches
sessionStorage.setItem("inform_tab", TAB);
const FOLLOWS = {fingertip: "its fingertip follows your target",
  object: "it pushes the object to your target (a planner finds the push)"};
const TASK_LINES = {pusher: "Your task: teach the arm to push the white object onto the red goal."};

function url(path, extra) {
  return path + "?" + new URLSearchParams({token: TOKEN, page: PAGE, tab: TAB, ...(extra || {})});
}
function sleep(ms) { return new Promise((r) => setTimeout(r, ms)); }
function pending() { try { return JSON.parse(localStorage.getItem(QUEUE) || "[]"); } catch (e) { return []; } }
function setPending(list) { localStorage.setItem(QUEUE, JSON.stringify(list)); }
function clock(s) { s = Math.max(0, Math.floor(s)); return Math.floor(s / 60) + ":" + String(s % 60).padStart(2, "0"); }
function nonce() {
  const bytes = new Uint8Array(16);
  crypto.getRandomValues(bytes);
  return Array.from(bytes, (b) => b.toString(16).padStart(2, "0")).join("");
}

function drawMaze(pre, text) {  // a maze's rows (the lines that start with |): the agent, moves and goal in colour
  pre.textContent = "";
  for (const line of text.split(/(?<=\n)/)) {
    if (!line.startsWith("|")) { pre.appendChild(document.createTextNode(line)); continue; }
    for (const c of line) {
      const cls = c === "A" ? "agent" : c === "G" ? "goal" : "^v<>".includes(c) ? "move" : null;
      if (!cls) { pre.appendChild(document.createTextNode(c)); continue; }
      const span = document.createElement("span");
      span.className = cls;
      span.textContent = c;
      pre.appendChild(span);
    }
  }
}

function openQuestion() {  // what the person may answer now: a question's id, "stream", or null
  const s = state;
  if (!s || s.role !== "teacher" || s.ended || gone) return null;
  if (s.mode === "stream") return "stream";
  if (s.mode !== "ask" || !s.question || s.question.answered) return null;
  if (answered.has(s.question.id) || pending().some((a) => a.question === s.question.id)) return null;
  if (s.has_frame && shownSeq < s.question.frame_seq) return null;  // its frame is not on the screen yet
  return s.question.id;
}

function answer(label) {
  const q = openQuestion();
  if (q === null) return;
  if (q !== "stream") answered.add(q);
  const list = pending();
  list.push({nonce: nonce(), answer: label, question: q === "stream" ? null : q, seq: shownSeq, pressed: Date.now()});
  setPending(list);
  render();
  flush();
}

let flushing = false;
async function flush() {  // send the kept answers, oldest first, until the server has each
  if (flushing) return;
  flushing = true;
  try {
    for (let list = pending(); list.length; list = pending()) {
      const a = list[0];
      const waited = Math.max(0, Date.now() - a.pressed);
      const body = JSON.stringify({...a, pressed: undefined, waited_ms: waited});
      let r;
      try {
        r = await fetch(url("/answer"), {method: "POST", headers: {"Content-Type": "application/json"}, body});
      } catch (e) { setOffline(true); setTimeout(flush, 1000); return; }
      if (r.status >= 500) { setTimeout(flush, 1000); return; }
      setPending(pending().filter((x) => x.nonce !== a.nonce));  // taken, a retry of one taken, or refused: done
    }
  } finally { flushing = false; render(); }
}

// the table's plane the map shows, metres, turned as the 3D view (its camera looks down from behind the goal): x runs
// down the map, y to the right
const MAP = {x0: -0.1, x1: 0.9, y0: -0.8, y1: 0.2};
let myTarget = null;  // the target this page last sent, while it holds the arm (a poll's reply may lag behind it)
let myDriving = false;  // whether this page last took the arm or gave it back
let drivesSent = 0, drivesDone = 0;  // this page's drive posts: a poll's reply may predate those not yet answered
let clampedHere = false;  // this page moved its newest target onto the arm's reach
function toMap(p) {
  const c = $("map");
  return [(p[1] - MAP.y0) / (MAP.y1 - MAP.y0) * c.width, (p[0] - MAP.x0) / (MAP.x1 - MAP.x0) * c.height];
}
function fromMap(px, py) {
  const c = $("map");
  return [MAP.x0 + py / c.height * (MAP.x1 - MAP.x0), MAP.y0 + px / c.width * (MAP.y1 - MAP.y0)];
}
function toReach(t) {  // [the target moved onto the arm's reach if beyond it, whether it was] (the server does too)
  const r = state && state.reach;
  if (!r) return [t, false];
  const dx = t[0] - r.base[0], dy = t[1] - r.base[1], d = Math.hypot(dx, dy);
  return d <= r.radius ? [t, false] : [[r.base[0] + dx * r.radius / d, r.base[1] + dy * r.radius / d], true];
}
function tableMap() { return state && state.task === "pusher" && state.info && state.info._map; }
function canDrive() { const s = state; return s && s.role === "teacher" && s.mode === "stream" && !s.ended && !gone; }
function drawMap() {
  const c = $("map"), m = tableMap();
  $("mapbox").hidden = !m;
  if (!m) return;
  const g = c.getContext("2d"), r = state.reach;
  g.clearRect(0, 0, c.width, c.height);
  const dot = (p, size, fill, line) => {
    const [x, y] = toMap(p);
    g.beginPath(); g.arc(x, y, size, 0, 2 * Math.PI); g.fillStyle = fill; g.fill();
    if (line) { g.strokeStyle = line; g.stroke(); }
  };
  if (r) {  // the arm's reach, its base, and the arm from the base to the fingertip
    const [bx, by] = toMap(r.base);
    g.beginPath(); g.arc(bx, by, r.radius / (MAP.y1 - MAP.y0) * c.width, 0, 2 * Math.PI);
    g.setLineDash([5, 4]); g.strokeStyle = "#777"; g.stroke(); g.setLineDash([]);
    g.fillStyle = "#333"; g.fillRect(bx - 6, by - 6, 12, 12);
    const [tx, ty] = toMap(m.tip);
    g.beginPath(); g.moveTo(bx, by); g.lineTo(tx, ty); g.strokeStyle = "#9e9e9e"; g.lineWidth = 4; g.stroke();
    g.lineWidth = 1;
  }
  dot(m.goal, 9, "#e53935");
  dot(m.object, 7, "#ffffff", "#555");
  dot(m.tip, 5, "#1e88e5");
  const t = state.driving ? (myTarget || state.target) : null;
  if (t) {
    const [x, y] = toMap(t);
    g.strokeStyle = "#2e7d32"; g.lineWidth = 2;
    g.beginPath(); g.moveTo(x - 7, y); g.lineTo(x + 7, y); g.moveTo(x, y - 7); g.lineTo(x, y + 7); g.stroke();
    g.lineWidth = 1;
  }
}
let driving = Promise.resolve();
function drive(kind, target) {  // take the arm at `target`, move its target, or give it back
  if (!canDrive() || (kind === "target" && !state.driving)) return;
  const asked = target;  // sent as asked: the server holds it on the reach too, and records both
  if (target) [target, clampedHere] = toReach(target);
  myTarget = kind === "release" ? null : target;
  myDriving = state.driving = kind !== "release";  // shown at once; the server's state follows
  if (target) state.target = target;
  const body = JSON.stringify(kind === "release" ? {drive: kind} : {drive: kind, target: asked});
  const post = () => fetch(url("/drive"), {method: "POST", headers: {"Content-Type": "application/json"}, body});
  const refused = () => { myDriving = false; myTarget = null; };  // the next poll says what the server holds
  drivesSent += 1;
  driving = driving.then(post).then((r) => { if (!r.ok) refused(); })  // in the order given
    .catch(() => setOffline(true)).finally(() => { drivesDone += 1; });
  render();
}
// the arrow keys: the target 2 cm as the map shows it (right: +y; up: -x)
const ARROWS = {ArrowRight: [0, 0.02], ArrowLeft: [0, -0.02], ArrowUp: [-0.02, 0], ArrowDown: [0.02, 0]};
// what a take without a point holds: the fingertip where it is, or with drive_by "object" the object where it is
function here() { const m = tableMap(); return m && (state.drive_by === "object" ? m.object : m.tip); }
function nudge(dx, dy) {
  const t = myTarget || state.target || here();
  if (t) drive("target", [t[0] + dx, t[1] + dy]);
}

function paceLine(s) {  // the steps and time left in the day, and whether the page keeps its pace
  if (s.mode !== "stream" || !s.pace || s.ended) return "";
  const rate = s.rate || s.pace, keeps = rate >= 0.9 * s.pace;
  const left = s.day_steps ? Math.max(0, s.day_steps - 1 - (s.step ?? 0)) : null;
  const time = left === null ? "" : `${left} steps left in the day, about ${clock(left / rate)} · `;
  return time + (keeps ? `the page keeps its pace, ${s.pace} steps a second`
    : `the page falls behind its pace: ${rate.toFixed(1)} of ${s.pace} steps a second`);
}

function setOffline(on) { if (offline !== on) { offline = on; render(); } }

function describe(info) {
  const value = (v) => Array.isArray(v) ? v.map((x) => typeof x === "number" ? x.toFixed(2) : x).join(", ") : v;
  const shown = Object.entries(info || {}).filter(([k]) => !k.startsWith("_"));  // "_" keys: for a script's eyes
  return shown.map(([k, v]) => `${k}: ${value(v)}`).join(" · ");
}

function render() {
  const s = state;
  if (!s) return;
  const elapsed = s.elapsed + (gone ? 0 : (Date.now() - receivedAt) / 1000);
  const budget = s.budget == null ? "no budget" : `budget ${s.yes} of ${s.budget} yes`;
  const who = s.participant ? ` · participant ${s.participant}` : "";
  const counts = `answers ${s.answers} (yes ${s.yes}, no ${s.no}, no answer ${s.none})`;
  const steps = s.day_steps ? `step ${s.step ?? "–"} of ${s.day_steps}` : `step ${s.step ?? "–"}`;
  $("progress").textContent = `${counts} · ${steps} · ${budget} · time ${clock(elapsed)}${who}`;
  $("pace").textContent = paceLine(s);
  $("message").textContent = s.message || "";
  $("task").hidden = !TASK_LINES[s.task];
  $("task").textContent = TASK_LINES[s.task] || "";
  let note = null, cls = "";
  const on = !s.ended;  // who teaches matters while the day is on; after it, the line below says it is over
  if (gone) { note = "The run has finished: this page is no longer served."; cls = "over"; }
  else if (offline) { note = "Reconnecting… your answers are kept, and sent once it is back."; cls = "offline"; }
  else if (on && s.role !== "teacher") {
    note = "You are watching read-only: another page (or tab) teaches this run."; cls = "watch";
  } else if (on && s.takeover) {
    note = "The page that taught has gone silent: answering here takes over."; cls = "watch";
  }
  const banner = $("banner");
  banner.hidden = !note;
  banner.className = "banner " + cls;
  banner.textContent = note || "";
  const maze = $("maze"), text = s.state_text;
  maze.hidden = !text;
  if (text && maze.dataset.text !== text) { drawMaze(maze, text); maze.dataset.text = text; }
  if (text && !s.has_frame) shownSeq = s.frame_seq;
  $("frame").hidden = !s.has_frame;
  const q = openQuestion();
  const asked = s.task === "maze" ? "is this a good move?" : "is the arm doing well?";
  const taken = "Answer taken: the agent learns, and its next move comes next.";
  const mine = s.role === "teacher" && s.question && (s.question.answered || pending().length);
  let line = "The agent is getting ready…";
  if (s.ended && s.outcome) line = "The day is over, and the night has run: what came of it is below.";
  else if (s.ended) line = `The day is over (${s.ended}). The agent sleeps on it now…`;
  else if (s.mode === "stream") line = "Answer whenever the arm does well (y) or badly (n).";
  else if (s.mode === "ask" && q !== null) line = `Step ${s.question.step}: ${asked}`;
  else if (s.mode === "ask" && mine) line = taken;
  else if (s.mode === "ask" && s.question) line = `Step ${s.question.step}: ${asked} (the person is thinking)`;
  else if (s.question) line = taken;
  $("question").textContent = line;
  $("info").textContent = describe(s.mode === "ask" && s.question ? s.question.info : s.info);
  for (const id of ["yes", "no", "none"]) $(id).disabled = q === null;
  $("end").disabled = !(s.role === "teacher" && !s.ended && !gone);
  $("buttons").hidden = Boolean(s.ended);
  $("end").textContent = endArmed > Date.now() ? "Click again to end the day" : "End the day";
  const window = `Your answer applies to what happened ${s.delay[0]}–${s.delay[1]} s before it; hold y or n to ` +
    "keep answering (four times a second).";
  $("hint").textContent = s.mode === "stream" ? window : "";
  const pusher = s.task === "pusher" && !s.ended && !gone;
  $("drive").hidden = !pusher;
  $("keys").hidden = !pusher || s.role !== "teacher";
  $("take").disabled = !canDrive() || s.driving;
  $("release").disabled = !canDrive() || !s.driving;
  const drivingHere = s.driving && s.role === "teacher";
  $("drive-status").className = drivingHere ? "you" : "";
  $("drive-status").textContent = drivingHere
    ? "You drive the arm: click the map or use the arrow keys (2 cm a press); g gives it back."
    : s.driving ? "The page that teaches drives the arm."
    : `The agent drives. t, or a click on the map, takes the arm: ${FOLLOWS[s.drive_by]}.`;
  for (const e of document.querySelectorAll(".follows")) e.textContent = FOLLOWS[s.drive_by];
  if (!s.driving) myTarget = null;
  const clamped = s.driving && (myTarget ? clampedHere : s.clamped);
  $("clamp").textContent = clamped ? "Out of reach: your target is held on the circle, as far as the arm reaches." : "";
  drawMap();
  const day = $("day").dataset;  // for a test (or a study's screen recorder) to read
  day.question = s.question && s.mode === "ask" ? s.question.id : "";
  day.open = q === null ? "0" : "1";
  day.mode = gone ? "closed" : s.mode;
  day.answers = s.answers;
  day.driving = s.driving ? "1" : "0";
  day.clamped = clamped ? "1" : "0";
  if (s.outcome) {
    $("outcome").hidden = false;
    if ($("outcome-text").dataset.text !== s.outcome.text) {
      drawMaze($("outcome-text"), s.outcome.text);
      $("outcome-text").dataset.text = s.outcome.text;
    }
    if (s.outcome.image && outcomeShown !== s.outcome.id) {  // once per outcome (show_outcome may come again)
      outcomeShown = s.outcome.id;
      loadImage($("outcome-img"), url("/outcome")).catch(() => {});
    }
  }
}

async function loadImage(img, address) {
  const r = await fetch(address, {cache: "no-store"});
  if (!r.ok) return null;
  const old = img.src;
  img.src = URL.createObjectURL(await r.blob());
  img.hidden = false;
  if (old.startsWith("blob:")) URL.revokeObjectURL(old);
  return Number(r.headers.get("X-Frame-Seq"));
}

async function frames() {  // the newest frame, a few a second at most
  while (!gone) {
    if (state && state.has_frame && state.frame_seq > shownSeq) {
      const started = Date.now();
      try {
        const seq = await loadImage($("frame"), url("/frame.png", {seq: state.frame_seq}));
        if (seq) { shownSeq = seq; render(); }
      } catch (e) {}
      await sleep(Math.max(0, 200 - (Date.now() - started)));
    } else await sleep(50);
  }
}

async function poll() {  // the state, long-polled: each reply comes when something changed (or after 10 s)
  let version = null;
  while (true) {
    let r;
    const sent = drivesSent, settled = drivesDone === drivesSent;  // this request sees every drive the server answered
    try {
      r = await fetch(url("/state", version === null ? {} : {since: version}), {cache: "no-store"});
    } catch (e) {
      if (state && state.mode === "outcome") { gone = true; render(); return; }
      setOffline(true);
      await sleep(1000);
      continue;
    }
    if (r.status === 403) { $("progress").textContent = "Not this run's address: use the one printed."; return; }
    if (!r.ok) { setOffline(true); await sleep(1000); continue; }
    state = await r.json();
    if (state.role === "teacher" && (!settled || sent !== drivesSent)) {  // it may predate this page's drive
      state.driving = myDriving;
      if (myDriving && myTarget) state.target = myTarget;
    }
    receivedAt = Date.now();
    version = state.version;
    setOffline(false);
    gone = state.mode === "closed";
    render();
    if (gone) return;
    if (pending().length) flush();
    if (state.mode === "stream") await sleep(150);  // a streamed day changes every step: a few updates a second
  }
}

for (const id of ["yes", "no", "none"]) $(id).addEventListener("click", (e) => { e.currentTarget.blur(); answer(id); });
$("end").addEventListener("click", async (e) => {
  e.currentTarget.blur();
  if (endArmed < Date.now()) { endArmed = Date.now() + 4000; render(); setTimeout(render, 4100); return; }
  endArmed = 0;
  try { await fetch(url("/end"), {method: "POST"}); } catch (err) { setOffline(true); }
});
$("take").addEventListener("click", (e) => {
  e.currentTarget.blur();
  if (tableMap()) drive("take", here());
});
$("release").addEventListener("click", (e) => { e.currentTarget.blur(); drive("release"); });
$("map").addEventListener("click", (e) => {
  const box = $("map").getBoundingClientRect(), c = $("map");
  const xy = fromMap((e.clientX - box.left) * c.width / box.width, (e.clientY - box.top) * c.height / box.height);
  drive(state && state.driving ? "target" : "take", xy);
});
document.addEventListener("keydown", (e) => {
  if (e.ctrlKey || e.metaKey || e.altKey) return;
  const step = ARROWS[e.key];
  if (step && state && state.driving) { e.preventDefault(); nudge(...step); return; }
  if (e.repeat) return;
  if ((e.key === "t" || e.key === "T") && tableMap() && !state.driving) { drive("take", here()); return; }
  if ((e.key === "g" || e.key === "G") && state && state.driving) { drive("release"); return; }
  const label = {y: "yes", Y: "yes", n: "no", N: "no", " ": "none"}[e.key];
  if (label) { e.preventDefault(); answer(label); }
  if (label && label !== "none" && openQuestion() === "stream") {  // held while the arm moves: an answer each HOLD_MS
    clearInterval(held.timer);
    held = {key: e.key.toLowerCase(), timer: setInterval(() => answer(label), HOLD_MS)};
  }
});
const HOLD_MS = 250;  // a held y or n answers again every quarter second, each answer a line of its own
let held = {key: null, timer: null};
function letGo() { clearInterval(held.timer); held = {key: null, timer: null}; }
document.addEventListener("keyup", (e) => { if (e.key.toLowerCase() === held.key) letGo(); });
window.addEventListener("blur", letGo);
window.addEventListener("pagehide", () => {  // closed or reloaded: the server waits a few seconds to see which
  if (state && state.role === "teacher" && !state.ended) navigator.sendBeacon(url("/bye"));
});
setInterval(render, 1000);  // the clock
poll();
frames();
flush();
</script>
</body></html>
"""
