"""The web page's reference numbers on the maze: a scripted person teaches `inform_dqn_gridworld.py --teacher browser`
through the page in Debian's Chromium (headless, driven by Playwright), as tests/test_browser_teacher.py's end-to-end
test does: it reads where A stands and its arrow off the drawn maze and presses y when the move is optimal under exact
Q* (q[cell, move] >= max q[cell] - 1e-9), n otherwise, and ends the day ("End the day", twice) once the page says
TAMER's own way from S reaches G in 19 steps (with --until walk: and a walk from S has reached G in time, so the night
has a success set). The script's defaults otherwise: the page's pace (one question at a time, answered at once), no
budget, credit window 1, a night of 3000 steps. Then, per seed, three more nights on the saved day
(inform_utils/sleep_variants_maze.py --sleep-from): behaviour cloning (bc), the sham (TAMER's own update), and the core
night again (number for number the day's own). Per seed and their mean: the answers the day needed, and TAMER, INFORM
and both controls from S, on the wall maze, from the start set and from every cell.

    python -m inform_utils.scripted_person_browser --seeds 1 2 3 4 5 --out-dir results/browser_maze

{out_dir}/table.md and table.json, and each seed's summary.json (the day's run, and each night's as
summary_{bc,sham,core}.json) and answers.jsonl under {out_dir}/seed{S}/; the runs themselves (day.pt, networks, logs)
in a temporary directory, removed, or kept in --work-dir. Neither directory may exist: nothing is overwritten.
"""

import json
import math
import os
import queue
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from typing import Literal

import tyro

from inform_utils.files import BadInput, check_writable, run_tool

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--no-sandbox", "--headless", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]  # fmt: skip
CONTROLS = ("bc", "sham", "core")  # the nights on the saved day: --sleep-control bc, sham, none
OWN_WAY = re.compile(r"its own way from S: (?:reaches G in (\d+) steps|does not reach G yet)")
WALKS = re.compile(r"walks to G in time: (\d+)")


@dataclass
class Args:
    seeds: list[int] = field(default_factory=lambda: [1, 2, 3, 4, 5])
    """seeds of the days taught, one after the other"""
    out_dir: str = "results/browser_maze"
    """where the table and each seed's summary.json and answers.jsonl go; it must not exist"""
    work_dir: str | None = None
    """keep the runs (day.pt, networks, logs) in {work_dir}/seed{S}/runs/; it must not exist (default: a temporary
    directory, removed at the end)"""
    until: Literal["19", "walk"] = "19"
    """when the person ends the day: "19" once the page says TAMER's own way from S reaches G in 19 steps (the
    end-to-end test's rule); "walk" once, besides, a walk from S has reached G in time (the night's success set)"""
    max_answers: int = 300
    """the person ends the day after this many answers, whatever the page says"""
    flags: list[str] = field(default_factory=list)
    """extra flags for the day's run (e.g. --flags=--sleep-gradient-steps=300); the script's defaults otherwise"""
    timeout: float = 1800.0
    """seconds a seed may take, day and nights"""
    wait: float = 60.0
    """seconds the person waits for the page to show the next move"""


# ---------------------------------------------------------------------------------------------------------------------
# the table: rows of numbers per seed, and their mean


def slot(summary: dict | None, policy: str) -> dict:
    """A policy's numbers from a summary (None where the run has none, e.g. no INFORM when the sleep was skipped)."""
    summary = summary or {}
    keys = {
        "length from S": f"eval/{policy}_episode_length",
        "length on the wall maze": f"eval/wall/{policy}_episode_length",
        "start-set success": f"eval/start_set/{policy}_success_rate",
        "all-starts success": f"eval/all_starts/{policy}_success_rate",
    }
    return {name: summary.get(key) for name, key in keys.items()}


def seed_row(seed: int, day: dict, nights: dict[str, dict | None], walks: int | None, reached: bool) -> dict:
    """One seed's numbers from its day's summary.json and its nights' (bc, sham, core: INFORM's slot of each)."""
    row = {
        "seed": seed,
        "status": day.get("status"),
        "day ended at 19": reached,
        "answers": day.get("feedback/answers"),
        "+1 given": day.get("feedback/positive"),
        "steps taught": day.get("feedback/steps"),
        "answers when TAMER's way from S first reached G": day.get("feedback/answers_to_tamer_goal"),
        "walks from S to G in time": walks,
        "expert transitions": day.get("sleep/expert_transitions"),
        "sleep skipped": day.get("sleep_skipped"),
    }
    for title, policy, summary in (("TAMER", "tamer", day), ("INFORM", "inform", day),
                                   *((f"{name} night", "inform", nights.get(name)) for name in CONTROLS)):  # fmt: skip
        row |= {f"{title}: {name}": value for name, value in slot(summary, policy).items()}
    return row


def mean(values: list) -> float | None:
    """The mean of the numbers among `values` (booleans count as 0/1), None if there are none."""
    numbers = [float(v) for v in values if isinstance(v, (int, float)) and not isinstance(v, str)]
    numbers = [v for v in numbers if math.isfinite(v)]
    return sum(numbers) / len(numbers) if numbers else None


def build_table(rows: list[dict]) -> dict:
    """{"rows": per seed, "mean": per column over the seeds that have it, "n": how many seeds have it}."""
    columns = [k for k in rows[0] if k not in ("seed", "status")] if rows else []
    return {
        "rows": rows,
        "mean": {k: mean([r.get(k) for r in rows]) for k in columns},
        "n": {k: sum(isinstance(r.get(k), (int, float)) for r in rows) for k in columns},
    }


def shown(value, decimals: int | None = None) -> str:
    """A number as the table shows it: yes/no, `decimals` places, or a whole number (one place if it is not)."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if decimals is not None:
        return f"{value:.{decimals}f}"
    return f"{value:.0f}" if float(value).is_integer() else f"{value:.1f}"


def markdown(table: dict) -> str:
    """One line a number, one column a seed and the mean (over the seeds that have it: 'of n' when not all); rates
    and yes/no lines (their mean: the fraction of yes) with two places."""
    rows = table["rows"]
    lines = [
        "| | " + " | ".join(f"seed {r['seed']}" for r in rows) + " | mean |",
        "| --- |" + " --- |" * (len(rows) + 1),
    ]
    for k, m in table["mean"].items():
        rate = "success" in k
        share = rate or any(isinstance(r.get(k), bool) for r in rows)
        m_text = shown(m, 2 if share else 1 if m is not None and not float(m).is_integer() else None)
        if m is not None and table["n"][k] < len(rows):
            m_text += f" (of {table['n'][k]})"
        lines.append(f"| {k} | " + " | ".join(shown(r.get(k), 2 if rate else None) for r in rows) + f" | {m_text} |")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------------------------------------
# a run of the maze script, its output read by a thread (so that every wait is bounded) into a log file


class Child:
    def __init__(self, cmd: list[str], cwd: str, log: str):
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [REPO, os.environ.get("PYTHONPATH")]))}
        env.setdefault("OMP_NUM_THREADS", "1")
        self.log = open(log, "w")
        self.log.write("$ " + " ".join(cmd) + "\n")
        self.proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     text=True, start_new_session=True)  # fmt: skip
        self.lines: queue.Queue = queue.Queue()
        self.tail: list[str] = []
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self):
        for line in self.proc.stdout:
            self.log.write(line)
            self.log.flush()
            self.tail = [*self.tail[-40:], line]
            self.lines.put(line)
        self.lines.put(None)

    def wait_for_line(self, prefix: str, timeout: float) -> str:
        deadline = time.monotonic() + timeout
        while True:
            try:
                line = self.lines.get(timeout=max(deadline - time.monotonic(), 0.01))
            except queue.Empty:
                raise RuntimeError(f"no line starting with {prefix!r} within {timeout:.0f}s") from None
            if line is None:
                raise RuntimeError(f"the run ended (exit {self.proc.wait(30)}) before a line {prefix!r}")
            if line.startswith(prefix):
                return line

    def finish(self, timeout: float) -> int:
        try:
            code = self.proc.wait(max(timeout, 1))
        finally:
            if self.proc.poll() is None:
                self.proc.kill()  # our own child, by its id
                self.proc.wait(30)
            self.thread.join(30)
            self.log.close()
        return code


def new_run(cwd: str, before: set[str]) -> str:
    (run,) = set(os.listdir(os.path.join(cwd, "runs"))) - before
    return os.path.join(cwd, "runs", run)


def runs_in(cwd: str) -> set[str]:
    return set(os.listdir(os.path.join(cwd, "runs"))) if os.path.isdir(os.path.join(cwd, "runs")) else set()


# ---------------------------------------------------------------------------------------------------------------------
# the scripted person at the page


def on_the_page(text: str) -> tuple[int, int]:
    """(cell, move) read off the drawing as a person reads it: where A stands, and its arrow."""
    import gridworld_env

    rows = text.split("\n")
    for r in range(gridworld_env.ROWS):
        for c in range(gridworld_env.COLS):
            content = rows[1 + 2 * r][1 + 4 * c : 4 + 4 * c]
            if content[1] == "A":
                return gridworld_env.CELL_INDEX[(r, c)], gridworld_env.ARROWS.index(content[2])
    raise RuntimeError(f"no agent on the page:\n{text}")


def teach_day(page, q, seed: int, args: Args, say) -> dict:
    """Answer until the page says what the stop rule wants (or the cap), then end the day twice; what the page said."""
    answers, walks, own_way = 0, 0, None
    page.wait_for_selector('#day[data-open="1"]')
    while True:
        info = page.text_content("#info")
        found, walked = OWN_WAY.search(info), WALKS.search(info)
        own_way = int(found.group(1)) if found and found.group(1) else None
        walks = int(walked.group(1)) if walked else 0
        reached = own_way == 19 and (args.until == "19" or walks >= 1)
        if reached or answers >= args.max_answers:
            break
        number = page.get_attribute("#day", "data-question")
        cell, move = on_the_page(page.text_content("#maze"))
        page.keyboard.press("y" if q[cell, move] >= q[cell].max() - 1e-9 else "n")
        answers += 1
        if answers % 10 == 0:
            way = f"reaches G in {own_way} steps" if own_way else "does not reach G yet"
            say(f"[seed {seed}] day: {answers} answers | TAMER's own way from S {way} | walks to G in time {walks}")
        page.wait_for_selector(f'#day[data-open="1"]:not([data-question="{number}"])')
    way = f"reaches G in {own_way} steps" if own_way else "does not reach G yet"
    say(f"[seed {seed}] day ends after {answers} answers ({'the stop rule' if reached else 'the cap'}): TAMER's own "
        f"way from S {way}, walks to G in time {walks}; the night runs")  # fmt: skip
    page.click("#end")
    page.wait_for_selector("#end:text('Click again')")
    page.click("#end")
    return {"answers": answers, "walks": walks, "reached": reached}


def run_seed(seed: int, args: Args, browser, q, work: str, out: str, say) -> dict:
    cwd = os.path.join(work, f"seed{seed}")
    os.makedirs(cwd)
    deadline = time.monotonic() + args.timeout
    t0 = time.monotonic()
    cmd = [sys.executable, os.path.join(REPO, "inform_dqn_gridworld.py"), "--teacher", "browser", "--participant",
           "scripted", "--seed", str(seed), "--save-buffer", "--exp-name", "browser_scripted", *args.flags]  # fmt: skip
    child = Child(cmd, cwd, os.path.join(cwd, "day.log"))
    errors: list[str] = []
    context = None
    try:
        url = child.wait_for_line("[teacher] open the teaching page", timeout=300).split(": ", 1)[1].strip()
        context = browser.new_context(viewport={"width": 900, "height": 720})
        page = context.new_page()
        page.on("pageerror", lambda error: errors.append(str(error)))
        page.set_default_timeout(args.wait * 1000)
        page.goto(url)
        day = teach_day(page, q, seed, args, say)
        page.wait_for_selector("#outcome:visible", timeout=max(deadline - time.monotonic(), 1) * 1000)
        outcome = page.text_content("#outcome-text")
        code = child.finish(deadline - time.monotonic())
    except BaseException:
        child.finish(0)
        say("".join(child.tail[-20:]), err=True)
        raise
    finally:
        if context is not None:
            context.close()
    if code != 0:
        raise RuntimeError(
            f"seed {seed}: the day's run exited {code}; its output: {cwd}/day.log\n{''.join(child.tail)}"
        )
    run = new_run(cwd, set())
    with open(os.path.join(run, "summary.json")) as f:
        summary = json.load(f)
    os.makedirs(os.path.join(out, f"seed{seed}"))
    shutil.copy(os.path.join(run, "summary.json"), os.path.join(out, f"seed{seed}", "summary.json"))
    shutil.copy(os.path.join(run, "answers.jsonl"), os.path.join(out, f"seed{seed}", "answers.jsonl"))
    day_s = time.monotonic() - t0
    say(f"[seed {seed}] day and night done in {day_s:.0f}s: {summary['feedback/answers']} answers; TAMER from S "
        f"{shown(summary.get('eval/tamer_episode_length'))}, INFORM {shown(summary.get('eval/inform_episode_length'))}"
        f"{' (sleep skipped)' if summary.get('sleep_skipped') else ''}")  # fmt: skip

    nights = {}
    for name in CONTROLS:
        before = runs_in(cwd)
        control = "none" if name == "core" else name
        cmd = [sys.executable, "-m", "inform_utils.sleep_variants_maze", "--sleep-from", run, "--sleep-control",
               control, "--exp-name", f"browser_scripted_{name}"]  # fmt: skip
        night = Child(cmd, cwd, os.path.join(cwd, f"night_{name}.log"))
        code = night.finish(deadline - time.monotonic())
        if code != 0:
            raise RuntimeError(f"seed {seed}: the {name} night exited {code}; {cwd}/night_{name}.log\n"
                               f"{''.join(night.tail)}")  # fmt: skip
        with open(os.path.join(new_run(cwd, before), "summary.json")) as f:
            nights[name] = json.load(f)
        shutil.copy(os.path.join(new_run(cwd, before), "summary.json"),
                    os.path.join(out, f"seed{seed}", f"summary_{name}.json"))  # fmt: skip
        say(f"[seed {seed}] {name} night on the saved day: INFORM's slot from S "
            f"{shown(nights[name].get('eval/inform_episode_length'))}")  # fmt: skip
    row = seed_row(seed, summary, nights, day["walks"], day["reached"])
    row["page script errors"] = len(errors)
    row["seconds"] = round(time.monotonic() - t0, 1)
    if "reaches G in 19 steps" not in outcome:
        say(f"[seed {seed}] note: the page's outcome does not say TAMER reaches G in 19 steps")
    return row


def browser_missing() -> str | None:
    if not os.path.exists(CHROMIUM):
        return f"no {CHROMIUM}: apt-get install chromium"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "no playwright: pip install the pin in requirements.txt"
    return None


def say(text: str, err: bool = False) -> None:
    print(text, file=sys.stderr if err else sys.stdout, flush=True)


def check_before_writing(args) -> None:
    """What a scripted person's run needs before it writes anything: a browser, a new --out-dir and --work-dir where
    they can be made (else BadInput, one line), and the repository's modules importable."""
    why = browser_missing()
    if why:
        raise BadInput(f"the scripted person needs a browser: {why}")
    for flag, path in (("--out-dir", args.out_dir), ("--work-dir", args.work_dir)):
        if path is not None and os.path.lexists(path):
            raise BadInput(f"{flag} {path} exists; give a new directory (nothing is overwritten)")
        if path is not None:
            check_writable(path, flag)
    if REPO not in sys.path:
        sys.path.insert(0, REPO)


def each_seed(args, prefix: str, what: str, run_one) -> list:
    """run_one(seed, browser, work) for each of args.seeds in one headless Chromium, the runs in --work-dir (or a
    temporary directory named `prefix`..., removed at the end); --out-dir is made first."""
    from playwright.sync_api import sync_playwright

    os.makedirs(args.out_dir)
    work = os.path.abspath(args.work_dir or tempfile.mkdtemp(prefix=prefix))  # the nights run in each seed's folder
    os.makedirs(work, exist_ok=args.work_dir is None)
    say(f"{what}; runs in {work}")
    rows = []
    try:
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            try:
                for seed in args.seeds:
                    rows.append(run_one(seed, browser, work))
            finally:
                browser.close()
    finally:
        if args.work_dir is None:
            shutil.rmtree(work, ignore_errors=True)
    return rows


def main(args: Args) -> dict:
    check_before_writing(args)
    import gridworld_env

    q, t0 = gridworld_env.optimal_q(), time.monotonic()
    what = f"the scripted person teaches seeds {args.seeds} at the page (until {args.until})"

    def run_one(seed, browser, work):
        return run_seed(seed, args, browser, q, work, args.out_dir, say)

    rows = each_seed(args, "scripted_person_browser_", what, run_one)
    table = build_table(rows)
    table["command"] = "python -m inform_utils.scripted_person_browser " + " ".join(sys.argv[1:])
    table["seconds"] = round(time.monotonic() - t0, 1)
    text = markdown(table)
    with open(os.path.join(args.out_dir, "table.md"), "w") as f:
        f.write(text)
    with open(os.path.join(args.out_dir, "table.json"), "w") as f:
        json.dump(table, f, indent=1)
    say("\n" + text + f"\n{len(rows)} seeds in {table['seconds']:.0f}s; {args.out_dir}/table.md")
    return table


if __name__ == "__main__":
    run_tool(main, tyro.cli(Args))
