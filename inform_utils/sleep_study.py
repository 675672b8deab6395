"""The sleep study: does the night consolidate, and when? Many nights on saved days (inform_sac_pusher.py or
inform_dqn_gridworld.py --save-buffer, then --sleep-from), each variant of the sleep and both controls, then one
table.

Each night runs `python -m inform_utils.sleep_variants_pusher --sleep-from DAY` (the core script's night plus the
study's switches) with the variant's flags, a 15% hold-out (so every night logs the offline criterion on the same
held-out episodes), any flags given after `--`, and a sleep seed; then its INFORM actor (and the one the offline
criterion picked) is tested on 50 random starts by `inform_utils.evaluate_policy pusher`. What a night leaves is
copied at once to {results_dir}/{campaign}/{day}/{variant}__sleep{seed}/ (summary.json, obstacle_distances.npz,
random_starts.json, and night.json: its day by content (content_sha256: every value of day.pt but how long the day
took, so a day re-made by its command is the same day) and by day.pt's sha256 (what records kept before name it by),
the CPU kernels it ran on, and every flag it ran with). A night of the campaign already there is not run again: the
study resumes; a campaign that holds a night of another day or other flags is refused before anything runs. --table
prints the table from the results alone, each night it cannot read named with its cause; --with-campaigns adds other
campaigns (a campaign a budget) to the rule for the methods. --retest-from runs adds the random-start test's sampled
numbers to nights kept before it recorded them, from their own runs, where the test gives the kept numbers again.
Exit 0; 1 if a night failed; 2 for bad input (or a night that refuses its input); 128 + the signal if stopped (the
night in progress saves what finished and is not kept; signals that come within SAME_STOP seconds are one stop).

    python inform_sac_pusher.py --env-id Pusher-v4 --seed 1 --save-buffer          # a day: runs/<day>/day.pt
    python -m inform_utils.sleep_study --days runs/<day> --campaign sleep_study    # the nights on it
    python -m inform_utils.sleep_study --table --campaign sleep_study               # the table
    python -m inform_utils.sleep_study --table --campaign methods --with-campaigns methods_50k   # the methods' rule
                                                                                    # at both budgets
    python -m inform_utils.sleep_study --script inform_dqn_gridworld.py --days runs/<maze day> --campaign maze_sleep \
        --sleep-seeds 1 2 3                                                         # the maze's nights

On the maze, a night has no hold-out and no random-start test (its tests already start from every cell): the
columns are the greedy path from S, the held-out start cells and all 29 cells.
"""

import contextlib
import functools
import glob
import hashlib
import io
import json
import os
import pickle
import re
import shutil
import signal
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field, replace
from typing import Literal

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def stopped_while_starting(signum, frame):
    """A stop before the study has started anything (numpy and tyro take a moment to load): one line."""
    with contextlib.suppress(OSError):
        os.write(2, f"error: stopped by {signal.Signals(signum).name} before any night ran\n".encode())
    os._exit(128 + signum)


if __name__ == "__main__":  # before the slow imports, so that no stop ever ends in a traceback
    for sig in STOP_SIGNALS:
        if signal.getsignal(sig) is not signal.SIG_IGN:  # an ignored SIGINT (nohup, `&`) stays ignored
            signal.signal(sig, stopped_while_starting)

import numpy as np  # noqa: E402
import tyro  # noqa: E402

from inform_utils.files import BadFile, check_writable, copy, read_json, read_npz, sha256, write_json  # noqa: E402

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FOLDER = r"[A-Za-z0-9][A-Za-z0-9._+=-]{0,99}"  # a campaign: one folder under results/ (no / or ..)
# the variants of the sleep (docs/protocol.md, "Saved days and the sleep's variants"), in the order they run: the
# default and the controls first
PUSHER_VARIANTS = {
    "default": [],
    "sham": ["--sleep-control", "sham"],
    "bc": ["--sleep-control", "bc"],
    "scratch": ["--no-sleep-init-actor-from-tamer"],
    "replay+expert_states": ["--sleep-actor-states", "replay+expert"],
    "expert_states": ["--sleep-actor-states", "expert"],
    "policy_frequency2": ["--sleep-policy-frequency", "2"],
    "expert_rows": ["--sleep-loss-rows", "expert"],
    "twin_critics": ["--sleep-twin-critics"],
    "td3bc2.5": ["--sleep-bc-coef", "2.5"],
    "temperature0.1": ["--sleep-temperature", "0.1"],
    "iqlearn_offline": ["--sleep-loss-rows", "expert", "--sleep-actor-states", "expert", "--sleep-policy-lr", "3e-5"],
    # nights of other methods, built for a night's data, and the cloning control at each one's step size
    "dwbc": ["--sleep-method", "dwbc"],  # DWBC at its release's settings (policy lr 1e-4)
    "pu_td3bc": ["--sleep-method", "pu_td3bc"],  # a PU reward learned first, then TD3+BC (lr 3e-4)
    "bc_lr1e-4": ["--sleep-control", "bc", "--sleep-policy-lr", "1e-4"],  # cloning the success set at DWBC's rate
    "bc_lr3e-4": ["--sleep-control", "bc", "--sleep-policy-lr", "3e-4"],  # at pu_td3bc's and the drafts' rate
    # the drafts that the nights committed as `dwbc` and `oril` before 2026-12-05 ran (their folders renamed so)
    "dwbc_draft": ["--sleep-method", "dwbc_draft"],
    "oril_draft": ["--sleep-method", "oril_draft"],
    "authors": ["--sleep-protocol", "authors"],  # last: 100k gradient steps, 20 times the others
}
MAZE_VARIANTS = {
    "default": [],
    "sham": ["--sleep-control", "sham"],
    "bc": ["--sleep-control", "bc"],
    "expert_rows": ["--sleep-loss-rows", "expert"],
    "temperature0.01": ["--sleep-temperature", "0.01"],
}
CONTROLS = ("sham", "bc")
# cloning the success set at other step sizes: controls for the methods that share them (never candidates)
CLONING = ("bc_lr1e-4", "bc_lr3e-4")
# the rule for a new default (fixed before the study): on the days of these seeds, with the boxes closer than TAMER
# at p < RULE_P on at least RULE_CLOSER_DAYS of them, and within RULE_ORACLE_GAP of the oracle on the plain task
RULE_SEEDS, RULE_P, RULE_CLOSER_DAYS, RULE_ORACLE_GAP = (1, 2, 3, 4, 5), 0.01, 4, 0.15
# then it must hold on new days: the same tests on the days of these seeds alone, one day allowed to miss as above
CONFIRM_SEEDS, CONFIRM_CLOSER_DAYS = (6, 7, 8), 2
# the rule for a night built for INFORM's data (docs/results.md, fixed before any of its nights ran): per task, over
# its five days, with the boxes closer than each control (a two-sided paired t-test over the days, p < METHOD_P), and
# on the plain task a sampled return not below TAMER's by more than TAMER's own sampling spread
METHODS, METHOD_P, METHOD_DAYS = ("dwbc", "pu_td3bc", "dwbc_draft", "oril_draft"), 0.05, 5
# the deterministic test beside the rule's (sampled) one: the same boxes and start, the mean action (not the rule's)
OBSTACLE_DETERMINISTIC = "eval/obstacle/{p}_final_distance_deterministic"
# TAMER's own sampling spread on the plain task: its sampled test again in these other streams of sampled actions
STREAMS = (1, 2, 3, 4, 5)
OBSTACLE, SAMPLED = "eval/obstacle/{p}_final_distance", "eval/{p}_return_sampled"
TOLERANCE = 1e-9  # differences of means below this are rounding (0.32 - 0.30 is a little over 0.02 in floating point)
# the smallest difference a measure can show: one episode of the random-start test, one start cell, one step. A
# variant must beat a control by more than this even where the default's sleep seeds happened to agree exactly.
RESOLUTION = {
    "random-start success": None,  # 1 / --random-start-episodes
    "held-out start cells: success": 1 / 10,
    "all 29 cells: success": 1 / 29,
    "length from S": 1.0,
    "wall maze: length from S": 1.0,
}


@dataclass(frozen=True)
class Study:
    """What the study needs to know of a script: the module that runs its nights (the core script's night plus the
    study's switches), its variants, the flags every night gets, the variants with all the sleep seeds, the table's
    columns ((name, summary key, +1 if higher is better)) and the Pusher-only extras."""

    runner: str
    variants: dict
    common: tuple
    all_seeds: tuple
    columns: tuple
    pusher: bool  # the offline pick, the random-start test and the obstacle test


STUDIES = {
    "inform_sac_pusher.py": Study(
        "inform_utils.sleep_variants_pusher",
        PUSHER_VARIANTS,
        ("--sleep-holdout-fraction", "0.15"),  # every night logs the offline criterion on the same held-out episodes
        ("default", "sham", "bc", "authors", *CLONING, *METHODS),
        (
            ("fixed-start return", "eval/{p}_return", 1),
            ("authors' test distance", "eval/authors_test/{p}_final_distance", -1),
            ("random-start success", "random_starts/{p}_success_rate", 1),
            ("obstacle distance", "eval/obstacle/{p}_final_distance", -1),
        ),
        pusher=True,
    ),
    "inform_dqn_gridworld.py": Study(
        "inform_utils.sleep_variants_maze",
        MAZE_VARIANTS,
        (),
        ("default", "sham", "bc"),
        (
            ("length from S", "eval/{p}_episode_length", -1),
            ("held-out start cells: success", "eval/start_set/{p}_success_rate", 1),
            ("all 29 cells: success", "eval/all_starts/{p}_success_rate", 1),
            ("wall maze: length from S", "eval/wall/{p}_episode_length", -1),
        ),
        pusher=False,
    ),
}


@dataclass
class Args:
    days: list[str] = field(default_factory=list)
    """run directories holding a day.pt (made with --save-buffer)"""
    script: Literal["inform_sac_pusher.py", "inform_dqn_gridworld.py"] = "inform_sac_pusher.py"
    """the script that made the days and runs the nights"""
    campaign: str = "sleep_study"
    """{results_dir}/{campaign}/ receives the nights"""
    results_dir: str = "results"
    """where campaigns are kept (relative to the working directory, where runs/ goes too)"""
    variants: list[str] | None = None
    """the variants to run, in this order (names of the script's variants; None: all)"""
    sleep_seeds: list[int] = field(default_factory=lambda: [1, 2])
    """the sleep seeds of the default and the controls (on the Pusher also of the methods, their cloning controls and
    the authors' protocol); the other variants use the first"""
    gradient_steps: int | None = None
    """the budget: every night of the campaign runs this many gradient steps (--sleep-gradient-steps; None: each
    night's own, 5,000, the authors' 100,000). A budget is a variant judged on its own: one campaign per budget"""
    random_start_episodes: int = 50
    """episodes of the random-start test of each night's policies"""
    table: bool = False
    """print the table from results/{campaign} and run nothing"""
    retest_from: str | None = None
    """a folder of runs (runs/): the campaign's Pusher nights kept before their random-start test recorded the sampled
    actions' numbers are tested again on their own runs there, and the numbers added where the test gives the kept
    deterministic ones again; runs no night"""
    with_campaigns: list[str] = field(default_factory=list)
    """with --table: campaigns of the same methods at other budgets (one campaign a budget), whose nights join the rule
    for a night built for the data, a row per task, budget and method"""


def night_dir(args: Args, day_name: str, variant: str, seed: int) -> str:
    return os.path.join(args.results_dir, args.campaign, day_name, f"{variant}__sleep{seed}")


def day_name(day: str) -> str:
    return os.path.basename(os.path.normpath(day))


# ----------------------------------------------------------------------------------------------------------------
# TRY NOT TO MODIFY: a night's identity, the children and the stop, the kept files


class Stopped(Exception):
    """A stop signal came: the study ends after the child it was waiting for, which saved what finished."""


class NightFailed(Exception):
    """A night, or a test of its policies, ended without a result: the study goes on and exits 1 at the end."""


SAME_STOP = 2.0  # seconds after a stop signal in which another is the same stop


class Stop:
    """The first SIGINT/SIGTERM/SIGHUP is remembered and passed on once to the live child (each child runs in its own
    process group, so a terminal's Ctrl-C reaches it only through the study), which then saves what finished. More
    within SAME_STOP seconds are the same stop (`timeout` signals the study, then its process group); one after that
    kills the child. The handler only records and passes on; the study looks at `signum` before each child."""

    def __init__(self):
        self.signum, self.first, self.procs = 0, None, set()

    def handler(self, signum, frame):
        if self.first is not None and time.monotonic() - self.first < SAME_STOP:
            return  # the same stop, signalled again
        kill = self.first is not None
        self.signum, self.first = self.signum or signum, self.first or time.monotonic()
        for proc in list(self.procs):
            with contextlib.suppress(ProcessLookupError):
                proc.send_signal(signal.SIGKILL if kill else signum)

    @contextlib.contextmanager
    def installed(self):
        # a SIGINT ignored at start (nohup, a shell's `&`) stays ignored, as Python itself does
        old = {s: signal.signal(s, self.handler) for s in STOP_SIGNALS if signal.getsignal(s) is not signal.SIG_IGN}
        try:
            yield self
        finally:
            for s, handler in old.items():
                signal.signal(s, handler)


def child_env() -> dict:  # a child finds the repository's modules from any working directory
    return {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [REPO, os.environ.get("PYTHONPATH")]))}


def run_child(cmd: list[str], stop: Stop) -> subprocess.CompletedProcess:
    """A child of the study (a night, a test of its policies) in its own process group. Stopped if a stop came
    before it started or while it ran (it then saved what finished)."""
    if stop.signum:
        raise Stopped
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=child_env(), process_group=0)  # fmt: skip
    stop.procs.add(proc)
    if stop.signum:  # it came between the start and the line above
        proc.send_signal(stop.signum)
    try:
        out, err = proc.communicate()
    finally:
        stop.procs.discard(proc)
    if stop.signum:
        raise Stopped
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def last_json(proc: subprocess.CompletedProcess, what: str) -> dict:
    """The JSON object a test (inform_utils.evaluate_policy) prints last; NightFailed if it failed or printed none."""
    if proc.returncode != 0:
        raise NightFailed(f"{what} failed ({proc.returncode}): {proc.stderr.strip()[-300:]}")
    try:
        return json.loads(proc.stdout[proc.stdout.index("{") :])
    except ValueError:
        raise NightFailed(f"{what} printed no result: {proc.stdout.strip()[-300:]}") from None


def identity(args: Args, extra: list[str], day: dict, night_flags: list[str]) -> dict:
    """What makes a night the campaign's: its script, the flags after `--` every night of the campaign gets, the
    random-start test's episodes (Pusher), its day by content (`day`: day.pt's content_sha256, and the file's sha256,
    which records kept before the content's name them by) and every flag it ran with. Kept beside the night as
    night.json, with the CPU kernels it ran on."""
    pusher = STUDIES[args.script].pusher
    record = {"script": args.script, "flags": list(extra), "random_start_episodes": args.random_start_episodes
              if pusher else None, **day, "night_flags": night_flags, "cpu": cpu_kernels()}  # fmt: skip
    return record | ({"gradient_steps": args.gradient_steps} if args.gradient_steps is not None else {})


CAMPAIGN_KEYS = ("script", "flags", "random_start_episodes", "gradient_steps")  # what every night of a campaign shares
DAY_KEYS = ("day_sha256", "day_content_sha256", "cpu")  # what names a night's day and where it ran, not its flags
# what night.json holds (identity()), by type: a record with another is damaged
RECORD = {"script": str, "flags": list, "random_start_episodes": int | None, "day_sha256": str, "night_flags": list,
          "gradient_steps": int, "day_content_sha256": str | None, "cpu": str | None}  # fmt: skip


def damaged(record: dict) -> str | None:
    """What in a night's record is not of the type identity() writes (flags: lists of strings), or None."""
    for key, kind in RECORD.items():
        value = record.get(key)
        words = isinstance(value, list) and all(isinstance(word, str) for word in value)
        if key in record and (not isinstance(value, kind) or isinstance(value, bool) or kind is list and not words):
            return f"its {key} is {json.dumps(value)[:60]}"
    return None


def cpu_kernels() -> str:
    """The CPU kernels torch runs here (AVX2, AVX512, ...; OPENBLAS_CORETYPE if set): another can move a last bit."""
    import torch

    forced = os.environ.get("OPENBLAS_CORETYPE")
    return torch.backends.cpu.get_cpu_capability() + (f", OPENBLAS_CORETYPE={forced}" if forced else "")


WALL_CLOCK = ("time/", "sps/")  # the saved day's stats that say how long it took: a re-made day does not repeat them
NOT_CONTENT = ("oracle_path",)  # where a Pusher day's teacher was read from (the teacher itself is in the day)


def content_sha256(day_pt: str) -> str | None:
    """A day by its content: the sha256 of every value day.pt holds (tensors by their dtype, shape and bytes), but how
    long the day took (its stats' WALL_CLOCK) and where its teacher was read from, which a day re-made by its command
    does not repeat. None if day.pt is not a day torch reads (its file's sha256 names it then)."""
    import torch  # here only: the study reads a day only to name it by its content

    try:
        day = torch.load(day_pt, weights_only=True, map_location="cpu")
    except Exception:  # not a torch file, or one of another kind: the night that sleeps on it says why
        return None
    day = {k: v for k, v in day.items() if k not in NOT_CONTENT} if isinstance(day, dict) else day
    if isinstance(day, dict) and isinstance(day.get("day_stats"), dict):
        day["day_stats"] = {k: v for k, v in day["day_stats"].items() if not k.startswith(WALL_CLOCK)}
    digest = hashlib.sha256()

    def add(value) -> None:
        if isinstance(value, torch.Tensor):
            digest.update(f"tensor {value.dtype} {tuple(value.shape)}:".encode())
            digest.update(value.contiguous().reshape(-1).view(torch.uint8).numpy().tobytes())
        elif isinstance(value, dict | list | tuple):
            digest.update(f"{type(value).__name__} {len(value)}:".encode())
            for item in value.items() if isinstance(value, dict) else value:
                add(item)
        else:
            digest.update(f"{type(value).__name__} {value!r};".encode())

    add(day)
    return digest.hexdigest()


@functools.lru_cache(maxsize=4)
def sha256_with_clock(day_pt: str, clock: tuple[tuple[str, float], ...]) -> str | None:
    """The sha256 day.pt would have had its day taken as long as `clock` says: its wall-clock stats put back and saved
    as the scripts save it (torch.save gives the same bytes for the same values); None if `clock` lacks one. How a
    record kept before content_sha256 names its day."""
    import torch

    day = torch.load(day_pt, weights_only=True, map_location="cpu")
    clock = dict(clock)
    timings = [key for key in day["day_stats"] if key.startswith(WALL_CLOCK)]
    if any(key not in clock for key in timings):
        return None
    day["day_stats"].update({key: clock[key] for key in timings})
    buffer = io.BytesIO()
    torch.save(day, buffer)
    return hashlib.sha256(buffer.getvalue()).hexdigest()


def remade(day_pt: str, night: str, record: dict) -> bool:
    """Is `day_pt` the day a kept night ran on, re-made by its command, by a record kept before content_sha256? A day
    is deterministic but for how long it took, which day.pt keeps (day_stats' time/ and sps/) and every night copies
    into its summary: with the night's put back, the re-made day.pt is byte for byte the night's (its day_sha256)."""
    try:
        summary = read_json(os.path.join(night, "summary.json"))
        clock = tuple(sorted((k, v) for k, v in summary.items() if k.startswith(WALL_CLOCK)))
        return sha256_with_clock(day_pt, clock) == record.get("day_sha256")
    except (BadFile, OSError, RuntimeError, KeyError, TypeError, pickle.UnpicklingError):  # not a day this reads
        return False


def ran_on(day_pt: str, night: str) -> bool:
    """Did the kept night run on this very day.pt? Its summary holds its day's stats, the clock too, to the bit."""
    import torch

    try:
        stats = torch.load(day_pt, weights_only=True, map_location="cpu")["day_stats"]
        summary = read_json(os.path.join(night, "summary.json"))
        return bool(stats) and all(k in summary and summary[k] == v for k, v in stats.items())
    except (BadFile, OSError, RuntimeError, KeyError, TypeError, AttributeError, pickle.UnpicklingError):
        return False


def conflicts(args: Args, planned: dict[str, dict]) -> list[str]:
    """The nights already kept in the campaign that are not its own: kept by an older study (no night.json) or one
    whose record is damaged, run with other flags after `--` (or another script or random-start test), on another
    day in a folder of the same name (by content: a day re-made by its command is the same day; by `remade` for a
    record kept before content_sha256), or with other flags of their own. `planned`: {night folder: its identity}."""
    mine = next(iter(planned.values()), None)
    days = {os.path.dirname(path): record for path, record in planned.items()}
    day_files = {os.path.join(args.results_dir, args.campaign, day_name(day)): day for day in args.days}
    flags_of = lambda record: {k: v for k, v in record.items() if k not in DAY_KEYS}  # noqa: E731
    found, told = [], set()
    for path in night_dirs(args):
        try:
            record = read_json(os.path.join(path, "night.json"))
        except BadFile as e:
            found.append(f"{path} has no readable record of its day and flags ({str(e).rsplit('(', 1)[-1]}")
            continue
        if problem := damaged(record):
            found.append(f"{path} has a damaged record of its day and flags ({problem} in its night.json)")
            continue
        if mine is not None and any(record.get(k) != mine.get(k) for k in CAMPAIGN_KEYS):
            ran = " ".join(record.get("flags") or []) or "none"
            found.append(f"{path} ran with other flags after -- ({ran}) or another script or --random-start-episodes")
            continue
        folder = os.path.dirname(path)
        day, day_pt = days.get(folder, record), os.path.join(day_files.get(folder, folder), "day.pt")
        same_file = record.get("day_sha256") == day["day_sha256"]
        if same_file or record.get("day_content_sha256") is not None:
            same_day = same_file or record["day_content_sha256"] == day.get("day_content_sha256")
        else:  # a record kept before content_sha256: the re-made file with the night's clock put back
            same_day = remade(day_pt, path, record)
        if same_day and not same_file and folder not in told:
            told.add(folder)
            print(f"[study] {day_files[folder]}: re-made; its day.pt is the kept nights' but for how long the day took",
                  flush=True)  # fmt: skip
        if not same_day:
            why = other_day(day_pt, path, record)
            found.append(f"{path} is a night on another day.pt kept in a folder of the same name ({why})")
        elif path in planned and flags_of(record) != flags_of(planned[path]):
            found.append(f"{path} ran with other flags ({' '.join(record.get('night_flags') or [])})")
    return found


def other_day(day_pt: str, night: str, record: dict) -> str:
    """Why a kept night's record names another day than day.pt, as far as the files tell."""
    if ran_on(day_pt, night):  # its summary holds this day.pt's stats to the bit: the record, not the day, changed
        return "yet its summary.json holds this day.pt's stats to the bit: its night.json was changed since it was kept"
    where = f"; that night ran on {record['cpu']}, this machine is {cpu_kernels()}" if record.get("cpu") else ""
    return (f"re-made on another CPU{where}? OpenBLAS's kernels can change the last bit of its final distances: "
            "re-make it with OPENBLAS_CORETYPE as where it was made: Haswell for the committed v4 days")  # fmt: skip


def read_night(path: str, pusher: bool) -> tuple[dict | None, str]:
    """A night kept in a campaign: (its summary with its random-start test, "") if it completed and its files are
    whole; else (None, why it is left out)."""
    try:
        summary = read_json(os.path.join(path, "summary.json"))
        if summary.get("status") != "completed":
            cause = summary.get("signal") or summary.get("error")
            return None, f"{summary.get('status')} in its {summary.get('phase')} phase ({cause})"
        summary.update(read_json(os.path.join(path, "random_starts.json")))
        if pusher and os.path.lexists(os.path.join(path, "obstacle_distances.npz")):  # whole, if it is there
            read_npz(os.path.join(path, "obstacle_distances.npz"), ("tamer", "inform"))
    except BadFile as e:
        return None, str(e)
    if problem := unreadable(summary):
        return None, problem
    if not re.fullmatch(r".+__sleep\d+", os.path.basename(path)):
        return None, "not named {variant}__sleep{seed}"
    return summary, ""


def unreadable(summary: dict) -> str | None:
    """What keeps a completed night from the table, or None: a measure (eval/, random_starts/) that is not a number
    or null, no seed (an integer: its day's), or settings that are not what a run writes."""
    for key, value in summary.items():
        if key.startswith(("eval/", "random_starts/")) and not (value is None or number(value)):
            file = "random_starts.json" if key.startswith("random_starts/") else "summary.json"
            return f"its {file} holds {json.dumps(value)[:60]} as {key[:100]}, not a number"
    kinds = {"seed": int, "args": dict, "sleep_variant": str}
    wrong = [k for k, kind in kinds.items() if (k == "seed" or k in summary) and not isinstance(summary.get(k), kind)]
    return f"its summary.json's {wrong[0]} is {json.dumps(summary.get(wrong[0]))[:60]}, not a run's" if wrong else None


def number(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def completed(path: str, pusher: bool = False) -> bool:
    return read_night(path, pusher)[0] is not None


def random_start_command(path: str, seed: int, env_id: str, episodes: int, contact: str | None) -> list[str]:
    """The random-start test of one saved actor (a night's policy, or a teacher): inform_utils.evaluate_policy on the
    seed's random starts (deterministic actions; a short obstacle part), under the Pusher `contact`."""
    cmd = [sys.executable, "-m", "inform_utils.evaluate_policy", "pusher", path, "--env-id", env_id]
    cmd += ["--seed", str(seed), "--random-starts", "--eval-episodes", str(episodes), "--obstacle-episodes", "1"]
    return cmd + (["--contact", contact] if contact else [])


def random_starts(run_dir: str, seed: int, env_id: str, episodes: int, stop: Stop, contact: str | None) -> dict:
    """The random-start test of each saved policy of a night, under the night's Pusher contact, as its summary
    records it."""
    out = {}
    for name in ("tamer", "inform", "inform_selected"):
        path = os.path.join(run_dir, f"{name}_actor.pt")
        if not os.path.isfile(path):
            continue
        cmd = random_start_command(path, seed, env_id, episodes, contact)
        metrics = last_json(run_child(cmd, stop), f"the random-start test of {path}")
        for key in ("return", "final_distance", "success_rate"):
            out[f"random_starts/{name}_{key}"] = metrics[f"eval/policy_{key}"]
            out[f"random_starts/{name}_{key}_sampled"] = metrics[f"eval/policy_{key}_sampled"]
    return {**out, "random_starts/episodes": episodes} if out else out


def retest(args: Args, stop: Stop) -> list[str]:
    """--retest-from: each kept Pusher night of the campaign whose random-start test has no sampled numbers (kept
    before the test recorded them) is tested again on its own run in `args.retest_from` (the run whose summary.json
    has the kept one's bytes), and its random_starts.json replaced only if the test gives the kept deterministic
    numbers again, exactly. Returns what it could not retest, with why."""
    if not (nights := night_dirs(args)):
        where = os.path.join(args.results_dir, args.campaign)
        raise ValueError(f"--campaign {args.campaign}: no kept nights in {where}")
    found = glob.glob(os.path.join(args.retest_from, "*", "summary.json"))
    runs = {sha256(path): os.path.dirname(path) for path in found}  # every run's, hashed once
    failed, added = [], 0
    for path in nights:
        file = os.path.join(path, "random_starts.json")
        try:
            kept = read_json(file) if os.path.isfile(file) else {}
            if not kept or any(key.endswith("_sampled") for key in kept):
                continue  # no test (a night that did not complete), or the test already has them
            run_dir = runs.get(sha256(os.path.join(path, "summary.json")))
            if run_dir is None:
                failed.append(f"{path}: no run in {args.retest_from} with its summary.json")
                continue
            summary = read_json(os.path.join(path, "summary.json"))
            tested = random_starts(run_dir, summary["seed"], summary["args"]["env_id"], kept["random_starts/episodes"],
                                   stop, summary.get("contact"))  # fmt: skip
        except (NightFailed, BadFile, OSError) as e:
            failed.append(f"{path}: {e}")
            continue
        except KeyError as e:
            failed.append(f"{path}: its kept files name no {e}")
            continue
        again = {key: value for key, value in tested.items() if not key.endswith("_sampled")}
        if differ := sorted(key for key in kept.keys() | again.keys() if again.get(key) != kept.get(key)):
            key = differ[0]  # a number the test no longer gives, gives otherwise, or gives without a kept one
            failed.append(f"{path}: tested again, {key} is {again.get(key, 'missing')}, not the kept "
                          f"{kept.get(key, 'none')}")  # fmt: skip
            continue
        write_json(file, tested)
        added += 1
        print(f"[study] {path}: the sampled test added ({run_dir})", flush=True)
    print(f"[study] the sampled test added to {added} of {len(nights)} night(s); {len(failed)} could not be retested")
    return failed


def night_command(args: Args, day: str, variant: str, seed: int, extra: list[str]) -> list[str]:
    study = STUDIES[args.script]
    flags = ["--exp-name", f"night_{variant}", "--sleep-seed", str(seed), *study.common, *extra]
    flags += ["--sleep-gradient-steps", str(args.gradient_steps)] if args.gradient_steps is not None else []
    return [sys.executable, "-m", study.runner, "--sleep-from", day, *flags, *study.variants[variant]]


def run_night(args: Args, day: str, variant: str, seed: int, record: dict, stop: Stop) -> bool:
    """One night, kept in {results_dir}/{campaign}/{day}/{variant}__sleep{seed}/ with its record (night.json), all at
    once: False if it failed. A night of the campaign already there is not run again. ValueError if the night refused
    its input (exit 2: every night would)."""
    study = STUDIES[args.script]
    dest = night_dir(args, day_name(day), variant, seed)
    if os.path.isdir(dest) and completed(dest, study.pusher):  # conflicts() has checked that it is the campaign's
        return True
    cmd = night_command(args, day, variant, seed, record["flags"])
    t0 = time.time()
    print(f"[study] {day_name(day)} {variant} sleep seed {seed}: {' '.join(cmd[1:])}", flush=True)
    try:
        proc = run_child(cmd, stop)
        line = next((x for x in proc.stdout.splitlines() if x.startswith("run directory:")), None)
        if proc.returncode == 2:
            said = proc.stderr.strip().splitlines()[-1:] or ["no message"]
            raise ValueError(f"the {variant} night on {day} refuses its input: {said[0].removeprefix('error: ')}")
        if proc.returncode != 0 or line is None:
            raise NightFailed(f"exit {proc.returncode}: {proc.stderr.strip()[-500:]}")
        run_dir = line.split(": ", 1)[1]
        summary = read_json(os.path.join(run_dir, "summary.json"))
        tested = {}
        if study.pusher:
            tested = random_starts(run_dir, summary["seed"], summary["args"]["env_id"], args.random_start_episodes,
                                   stop, summary.get("contact"))  # fmt: skip
        keep(dest, run_dir, tested, record, study.pusher)
    except (NightFailed, BadFile) as e:
        print(f"[study] failed ({e})", flush=True)
        return False
    print(f"[study] done in {time.time() - t0:.0f}s: {dest}", flush=True)
    return True


def keep(dest: str, run_dir: str, tested: dict, record: dict, pusher: bool) -> None:
    """The night's files into `dest` at once: copied into a hidden folder beside it, which then takes its place (a
    night of the campaign that did not complete, run again, is replaced). NightFailed, naming the file, if the night
    left one of them out; nothing is made then."""
    files = ("summary.json", "obstacle_distances.npz") if pusher else ("summary.json",)
    if missing := [file for file in files if not os.path.isfile(os.path.join(run_dir, file))]:
        raise NightFailed(f"the night in {run_dir} left no {' or '.join(missing)}")
    parent, name = os.path.split(dest)
    tmp, old = os.path.join(parent, f".{name}.tmp"), os.path.join(parent, f".{name}.old")
    for path in (tmp, old):
        shutil.rmtree(path, ignore_errors=True)
    try:
        os.makedirs(tmp)
        for file in files:
            copy(os.path.join(run_dir, file), os.path.join(tmp, file))
        write_json(os.path.join(tmp, "random_starts.json"), tested)
        write_json(os.path.join(tmp, "night.json"), record)
        if os.path.lexists(dest):
            os.replace(dest, old)
        os.replace(tmp, dest)
    except OSError as e:
        shutil.rmtree(tmp, ignore_errors=True)
        raise OSError(f"cannot keep the night in {dest} ({e.strerror or e}); nothing half-written is left there") from e
    shutil.rmtree(old, ignore_errors=True)


def night_dirs(args: Args) -> list[str]:
    return sorted(glob.glob(os.path.join(args.results_dir, args.campaign, "*", "*__sleep*")))


def scan(args: Args) -> tuple[list[dict], list[tuple[str, str]]]:
    """The campaign's completed nights as rows of the table, and the night folders left out, with why."""
    rows, left_out = [], []
    for path in night_dirs(args):
        summary, why = read_night(path, STUDIES[args.script].pusher)
        if summary is None:
            left_out.append((path, why))
            continue
        variant, seed = os.path.basename(path).rsplit("__sleep", 1)
        day = os.path.basename(os.path.dirname(path))  # the summary's own "seed" is the day's
        rows.append({**summary, "day": day, "dir": os.path.basename(path), "variant": variant, "sleep_seed": int(seed),
                     "campaign": args.campaign})  # fmt: skip
    rows.sort(key=lambda r: (r["day"], r["variant"] != "default", r["variant"], r["sleep_seed"]))
    return rows, left_out


def load(args: Args) -> list[dict]:
    return scan(args)[0]


def first_nights(rows: list[dict]) -> dict:
    """{day: the night TAMER's and the oracle's values on that day are read from}: its first, which load() makes the
    default's first sleep seed. Their sampled tests share a random stream with the night's own policies, so TAMER's
    value differs slightly between the nights of a day."""
    out = {}
    for r in rows:
        out.setdefault(r["day"], r)
    return out


def mean_sd(values: list[float]) -> str:
    values = [v for v in values if v is not None]
    if not values:
        return "-"
    sd = statistics.stdev(values) if len(values) > 1 else 0.0
    return f"{statistics.mean(values):.3f} ± {sd:.3f}"


def seed_spread(rows: list[dict], key: str) -> float | None:
    """The mean over days of the range between the default's sleep seeds: how much a night differs by chance."""
    spreads = []
    for day in {r["day"] for r in rows}:
        values = [r[key] for r in rows if r["day"] == day and r["variant"] == "default" and r.get(key) is not None]
        if len(values) > 1:
            spreads.append(max(values) - min(values))
    return statistics.mean(spreads) if spreads else None


def day_means(rows: list[dict], variant: str, key: str, policy: str = "inform") -> dict:
    """{day: the mean of the variant's `policy` (inform: the night's last actor; inform_selected: the offline pick)
    over its nights on that day}; variant "tamer" or "oracle": that policy's value on the day (first_nights())."""
    out = {}
    first = first_nights(rows)
    for day in sorted(first):
        if variant in ("tamer", "oracle"):
            values = [first[day].get(key.format(p=variant))]
        else:
            values = [r.get(key.format(p=policy)) for r in rows if r["day"] == day and r["variant"] == variant]
        values = [v for v in values if v is not None]
        if values:
            out[day] = statistics.mean(values)
    return out


def paired(rows: list[dict], variant: str, other: str, key: str, sign: int, policy: str = "inform") -> list[float]:
    """Per day on which both ran: how much better the variant's nights are than `other` (a variant, or tamer), in
    the measure's own direction (positive: better); the same `policy` of both. Comparing day by day keeps a variant
    that ran on fewer days from being judged against other days' controls."""
    mine, theirs = day_means(rows, variant, key, policy), day_means(rows, other, key, policy)
    return [sign * (mine[d] - theirs[d]) for d in mine if d in theirs]


def tamer_spread(args: Args, rows: list[dict]) -> float | None:
    """TAMER's own sampling spread with the boxes: the largest range, over the days, of TAMER's mean obstacle distance
    between one day's sampling streams (every night tests TAMER again in its own stream, and so did the day's run,
    kept as <day>/day/). A margin smaller than this is within noise. None where every day had one stream."""
    spreads = []
    for campaign, day in sorted({(r.get("campaign", args.campaign), r["day"]) for r in rows}):
        nights = [r["dir"] for r in rows if r["day"] == day and r.get("campaign", args.campaign) == campaign]
        means = []
        for path in (os.path.join(args.results_dir, campaign, day, name) for name in (*nights, "day")):
            if os.path.isfile(os.path.join(path, "obstacle_distances.npz")):
                tamer = read_npz(os.path.join(path, "obstacle_distances.npz"), ("tamer",))["tamer"]
                means.append(float(np.mean(tamer)))
        if len(set(means)) > 1:  # nights that share a stream repeat its mean to the bit: one stream is no spread
            spreads.append(max(means) - min(means))
    return max(spreads) if spreads else None


def obstacle_test(args: Args, nights: list[dict], policy: str, noise: float | None = None) -> dict | None:
    """The policy's obstacle final distances against TAMER's, on the days its nights ran. A day's margin is TAMER's
    mean minus the policy's mean over its nights that day (positive: closer), TAMER read from the variant's first night
    of the day. The headline test is over days: a paired t-test of the days' means (p_day; None on one day). Beside it
    the pooled-episode Welch test (p_pooled), with TAMER's episodes counted once a day (they would repeat in every
    night), which treats episodes of one night, sharing a policy and a start, as independent. Margins are "beyond
    noise" where they exceed `noise` (tamer_spread())."""
    from scipy.stats import ttest_ind

    mine, by_day = [], {}
    for r in nights:
        path = os.path.join(args.results_dir, args.campaign, r["day"], r["dir"], "obstacle_distances.npz")
        d = read_npz(path) if os.path.lexists(path) else {}
        if policy not in d:  # a night without the test or the policy (a tiny night's offline criterion picked none)
            continue
        mine.extend(d[policy])
        by_day.setdefault(r["day"], (np.array(d["tamer"]), []))[1].append(float(np.mean(d[policy])))
    if not by_day:
        return None
    tamer = [float(np.mean(t)) for t, _ in by_day.values()]
    means = [statistics.mean(m) for _, m in by_day.values()]
    margins = [t - m for t, m in zip(tamer, means, strict=True)]
    pooled = float(ttest_ind(mine, np.concatenate([t for t, _ in by_day.values()]), equal_var=False).pvalue)
    interval = paired_interval(margins)  # the paired t-test over days, its interval and detectable effect
    return {
        "days": len(by_day),
        "margins": margins,
        "margin": statistics.mean(margins),
        "closer_days": sum(m > 0 for m in margins),
        "beyond_noise": None if noise is None else sum(m > noise + TOLERANCE for m in margins),
        "noise": noise,
        "p_day": None if interval is None else interval["p"],
        "interval": interval,
        "p_pooled": pooled,
    }


def paired_interval(diffs: list[float]) -> dict | None:
    """What paired differences over days can say: their mean, its 95% interval (Student's t on the n - 1 degrees of
    freedom of the days' differences: paired, so what varies from day to day cancels), the two-sided p of a mean of 0,
    and the smallest true difference the test detects at 80% power (p < 0.05), (t_0.975 + t_0.8) standard errors, the
    usual approximation of the noncentral t's. None on one day."""
    from scipy.stats import t

    n = len(diffs)
    if n < 2:
        return None
    mean, se, df = statistics.mean(diffs), statistics.stdev(diffs) / n**0.5, n - 1
    crit = float(t.ppf(0.975, df))
    p = (0.0 if mean else 1.0) if se == 0 else float(2 * t.sf(abs(mean) / se, df))  # se 0: the same every day
    detectable = (crit + float(t.ppf(0.8, df))) * se
    return {"mean": mean, "low": mean - crit * se, "high": mean + crit * se, "p": p, "detectable": detectable}


def interval_text(stats: dict | None, unit: str = "", digits: int = 4) -> str:
    """paired_interval() in words: the 95% interval and the smallest effect detectable at 80% power."""
    if stats is None:
        return ""
    return (f"95% interval {stats['low']:+.{digits}f} to {stats['high']:+.{digits}f}{unit}, detectable "
            f"{stats['detectable']:.{digits}f}{unit}")  # fmt: skip


def interval_verdict(stats: dict | None, spread: float | None, headroom: float | None) -> str:
    """A difference too small or too uncertain to call: 'equivalent' where the whole 95% interval lies within
    +-`spread` (TAMER's own sampling spread), 'cannot tell' where the interval is wider than `headroom` (the room a
    night has to gain: the control's value minus the expert's); else ''."""
    if stats is None:
        return ""
    if spread is not None and -spread <= stats["low"] and stats["high"] <= spread:
        return "equivalent"
    if headroom is not None and stats["high"] - stats["low"] > headroom:
        return "cannot tell"
    return ""


def obstacle_text(test: dict) -> str:
    """A test of obstacle_test() in words: the mean margin (within noise or not), both tests, the days closer."""
    side = "closer" if test["margin"] > 0 else "farther"
    noise = test["noise"] is not None and abs(test["margin"]) < test["noise"]
    per_day = "one day" if test["p_day"] is None else f"p = {test['p_day']:.2g} over {test['days']} days"
    per_day += f" (the margin's {interval_text(test['interval'], ' m')})" if test.get("interval") else ""
    beyond = "" if test["beyond_noise"] is None else f", {test['beyond_noise']} beyond noise"
    return (
        f"{side} by {abs(test['margin']):.4f} m{' (within noise)' if noise else ''}; {per_day}; pooled p = "
        f"{test['p_pooled']:.2g}; closer on {test['closer_days']} of {test['days']} days{beyond}"
    )


def obstacle_p(args: Args, nights: list[dict], policy: str, noise: float | None = None) -> str:
    test = obstacle_test(args, nights, policy, noise)
    return "-" if test is None else obstacle_text(test)


def table_row(cells: list[str]) -> str:
    return "| " + " | ".join(cells) + " |"


def table_head(head: list[str]) -> list[str]:
    """A Markdown table's header and rule lines."""
    return [table_row(head), "|" + " --- |" * len(head)]


def table(args: Args) -> str:
    """Each variant's INFORM (and the checkpoint the offline criterion picked) against TAMER and the controls: mean +-
    sd over days and sleep seeds; 'beats both controls on' lists the measures where the variant is better than each
    control by more than the default's spread between sleep seeds on every day it ran (compared day by day). Then the
    verdict, one row per variant, policy and measure."""
    study = STUDIES[args.script]
    columns = study.columns
    rows, left_out = scan(args)
    notes = [f"\nnot in the table: {os.path.relpath(path, args.results_dir)}, {why}" for path, why in left_out]
    if not rows:  # kept for their curves, left out of the table: say so
        return "\n".join([f"no completed nights under {args.results_dir}/{args.campaign}", *notes])
    days = sorted({r["day"] for r in rows})
    spread = {name: seed_spread(rows, key.format(p="inform")) for name, key, _ in columns}
    lines = [f"{len(rows)} nights on {len(days)} day(s): {', '.join(days)}"]
    measured = ", ".join(f"{k} {v:.3g}" for k, v in spread.items() if v is not None)
    lines += [f"spread between the default's sleep seeds: {measured or 'none (one sleep seed)'}"]
    noise = tamer_spread(args, rows) if study.pusher else None
    if study.pusher:
        measured = "not measured, one stream a day" if noise is None else f"{noise:.4f} m"
        lines += [
            "TAMER's sampling spread with the boxes (the largest range of its mean between one day's sampling "
            f"streams): {measured}; a margin below it is within noise",
            "obstacle vs TAMER: the mean of the days' margins; the headline test is over days (a paired t-test of the "
            "days' means), the pooled-episode Welch test (TAMER's episodes counted once a day) beside it",
        ]
    episodes = {r.get("random_starts/episodes", args.random_start_episodes) for r in rows}  # as the nights ran it
    for name in spread:  # the bar a gain must clear: that spread, and never less than the measure's resolution
        floor = 1 / min(episodes) if name == "random-start success" else RESOLUTION.get(name, 0.0)
        spread[name] = None if spread[name] is None else max(spread[name], floor)
    head = ["policy", "nights", *(name for name, _, _ in columns)]
    head += ["obstacle vs TAMER (per day; pooled episodes)"] if study.pusher else []
    head += ["beats both controls on"]
    lines += ["", *table_head(head)]
    by_day = first_nights(rows)  # TAMER and the oracle: one row per day
    for p in ("oracle", "tamer"):
        cells = [mean_sd([r.get(key.format(p=p)) for r in by_day.values()]) for _, key, _ in columns]
        lines.append(table_row([p, f"{len(by_day)} days", *cells, *["-"] * (len(head) - len(cells) - 2)]))
    ran = [v for v in study.variants if any(r["variant"] == v for r in rows)]
    for variant in ran:
        mine = [r for r in rows if r["variant"] == variant]
        for p in ("inform", "inform_selected") if study.pusher else ("inform",):
            if not any(key.format(p=p) in r for r in mine for _, key, _ in columns):
                continue  # a policy none of its nights has (tiny nights: the offline criterion picked none)
            cells = [mean_sd([r.get(key.format(p=p)) for r in mine]) for _, key, _ in columns]
            beats = "-"
            if variant not in CONTROLS + CLONING:
                wins = [name for name, key, sign in columns if helps(rows, variant, key, sign, spread[name], p)]
                beats = ", ".join(wins) or "none"
            name = variant if p == "inform" else f"{variant}, offline pick"
            row = [name, str(len(mine)), *cells, *([obstacle_p(args, mine, p, noise)] if study.pusher else []), beats]
            lines.append(table_row(row))
    lines += fewer_days(rows, ran, columns, by_day)
    lines += ["", verdict(rows, ran, columns, spread, ("inform", "inform_selected") if study.pusher else ("inform",))]
    lines += ["", default_rule(args, rows, ran, noise)] if study.pusher else []
    if study.pusher:  # the methods at every budget: this campaign's nights and those of --with-campaigns
        every = budgets(args, rows)
        judged = [v for v in study.variants if v in ("default", *METHODS) and any(r["variant"] == v for r in every)]
        lines += ["", method_rule(args, every, judged)]
    lines += ["", per_day(rows, ran)] if study.pusher else []
    return "\n".join([*lines, *notes])  # kept for their curves, left out of the table: say so


def fewer_days(rows: list[dict], variants: list[str], columns: tuple, by_day: dict) -> list[str]:
    """TAMER's means over the days a variant's values stand on, where those are fewer than TAMER's (a day without a
    successful episode gives its night nothing to sleep on): the rows above average over different days."""
    groups = {}
    for variant in variants:
        days = {r["day"] for r in rows if r["variant"] == variant
                and any(r.get(key.format(p="inform")) is not None for _, key, _ in columns)}  # fmt: skip
        if days and len(days) < len(by_day):
            groups.setdefault(tuple(sorted(days)), []).append(variant)
    lines = []
    for days, names in groups.items():
        tamer = [f"{name} {mean_sd([by_day[d].get(key.format(p='tamer')) for d in days])}" for name, key, _ in columns]
        lines.append(f"{', '.join(names)}: values on {len(days)} of {len(by_day)} days; TAMER on those days: "
                     f"{', '.join(tamer)}")  # fmt: skip
    return ["", *lines] if lines else []


def per_day(rows: list[dict], variants: list[str]) -> str:
    """Day by day (the day's seed): TAMER and each variant's last actor, over the variant's nights on the day: the mean
    fixed-start return, the nights that end the fixed start in success, and the mean distance with the boxes."""
    first, keys = first_nights(rows), ("eval/{p}_return", "eval/{p}_success_rate", "eval/obstacle/{p}_final_distance")

    def cell(nights: list[dict], p: str) -> str:
        ret, ok, boxes = ([r[k] for r in nights if r.get(k) is not None] for k in (key.format(p=p) for key in keys))
        if not (ret and ok and boxes):  # none of the nights has them (a test that did not run)
            return "-"
        return f"{statistics.mean(ret):.2f} ({sum(v >= 1 for v in ok)}/{len(nights)}), {statistics.mean(boxes):.3f} m"

    lines = ["per day: fixed-start return (nights that succeed at the fixed start), distance with the boxes"]
    lines += table_head(["day (seed)", "tamer", *variants])
    for day in sorted(first, key=lambda d: first[d]["seed"]):
        cells = [cell([r for r in rows if r["day"] == day and r["variant"] == v], "inform") for v in variants]
        lines.append(table_row([str(first[day]["seed"]), cell([first[day]], "tamer"), *cells]))
    return "\n".join(lines)


def clears(gains: list[float], bar: float | None) -> int:
    """On how many days a gain is more than the bar (none without a bar)."""
    return 0 if bar is None else sum(g > bar + TOLERANCE for g in gains)


def helps(rows: list[dict], variant: str, key: str, sign: int, bar: float | None, policy: str = "inform") -> bool:
    """Consolidation helps on a measure only where the variant beats both controls by more than the bar (the spread
    between sleep seeds) on every day it ran, compared day by day."""
    gains = [paired(rows, variant, control, key, sign, policy) for control in CONTROLS]
    return all(g and clears(g, bar) == len(g) for g in gains)


def verdict(rows: list[dict], variants: list[str], columns: tuple, bar: dict, policies: tuple) -> str:
    """One row per variant, policy and measure: its gain over TAMER and over each control (positive: better), the
    mean over the days it ran, compared on the same days; on how many days it beat TAMER, and on how many it beat each
    control by more than the bar; and whether it helps (beats both by more than the bar on every day)."""
    head = ["variant", "measure", "days", "vs TAMER (days better, worse)"]
    head += [f"vs {c} (days above the bar)" for c in CONTROLS] + ["bar (seed spread, at least one unit)", "helps"]
    lines = ["verdict (paired by day; gains are in the measure's own direction: positive = better)", ""]
    lines += table_head(head)
    for variant in [v for v in variants if v not in CONTROLS + CLONING]:
        for policy in policies:
            for name, key, sign in columns:
                tamer = paired(rows, variant, "tamer", key, sign, policy)
                if not tamer:
                    continue
                label = variant if policy == "inform" else f"{variant}, offline pick"
                better, worse = sum(g > TOLERANCE for g in tamer), sum(g < -TOLERANCE for g in tamer)
                cells = [
                    label,
                    name,
                    str(len(tamer)),
                    f"{statistics.mean(tamer):+.3g} ({better} better, {worse} worse)",
                ]
                for control in CONTROLS:
                    gains = paired(rows, variant, control, key, sign, policy)
                    cells.append(
                        f"{statistics.mean(gains):+.3g} ({clears(gains, bar[name])} of {len(gains)})" if gains else "-"
                    )
                cells.append(f"{bar[name]:.3g}" if bar[name] is not None else "-")
                cells.append("yes" if helps(rows, variant, key, sign, bar[name], policy) else "no")
                lines.append(table_row(cells))
    return "\n".join(lines)


TESTS = ("per day", "pooled")  # the rule's obstacle test: over days (the headline), or on the pooled episodes


def rule_test(
    args: Args, rows: list[dict], variant: str, policy: str, seeds: tuple, need: int, noise: float | None = None
) -> tuple[list, dict]:
    """The rule's tests for one variant's policy on the days of `seeds`: with the boxes closer than TAMER (p < RULE_P)
    and closer on at least `need` of the days, and on the plain task within RULE_ORACLE_GAP of the oracle's
    fixed-start return on every day. The p is each of obstacle_test()'s two: over days (the headline) and on the
    pooled episodes. Returns the table's cells and {test: "yes", "no", or "open: ran on n of k days" while days are
    missing ("no" as soon as the missing days cannot change the answer)}."""
    rows = [r for r in rows if r.get("seed") in seeds]  # the summary's seed is the day's
    nights = [r for r in rows if r["variant"] == variant]
    if not nights:
        return ["0", "-", "-"], {t: f"open: ran on 0 of {len(seeds)} days" for t in TESTS}
    oracle = day_means(rows, "oracle", "eval/{p}_return")
    test = obstacle_test(args, nights, policy, noise)
    if test is None:  # none of its nights has this policy
        return ["0", "-", "-"], {t: "no: none of its nights has this policy" for t in TESTS}
    mine = day_means(rows, variant, "eval/{p}_return", policy)
    within = sum(oracle[d] - v <= RULE_ORACLE_GAP * abs(oracle[d]) for d, v in mine.items())
    n, left = test["days"], len(seeds) - test["days"]  # days run, days still to run
    answers = {}
    for name, p in zip(TESTS, (test["p_day"], test["p_pooled"]), strict=True):
        significant = p is not None and p < RULE_P and test["margin"] > 0
        if within < len(mine) or test["closer_days"] + left < need or (not left and not significant):
            answers[name] = "no"
        else:
            answers[name] = f"open: ran on {n} of {len(seeds)} days" if left else "yes"
    return [str(n), obstacle_text(test), f"{within} of {len(mine)}"], answers


def default_rule(args: Args, rows: list[dict], variants: list[str], noise: float | None = None) -> str:
    """The rule, fixed before the study, for a variant to become the default: on the days of seeds 1-5 it passes
    rule_test() (closer than TAMER with the boxes on 4 of 5 days, p < 0.01; within 15% of the oracle every day), and
    then it passes it again on three new days (seeds 6-8) alone, closer on 2 of 3. The rule was written with the
    pooled-episode p; it is decided with the per-day p (the headline) and the pooled one side by side. Only a policy
    picked without the environment can pass: the night's last actor or the offline criterion's pick. The controls are
    no candidates."""
    first = f"seeds {RULE_SEEDS[0]}-{RULE_SEEDS[-1]}"
    if not any(r.get("seed") in RULE_SEEDS for r in rows):
        return f"the rule for a new default: no day of {first} in this campaign"
    candidates = [v for v in variants if v not in CONTROLS + CLONING]
    head = ["variant", "days", "with the boxes vs TAMER", f"within {RULE_ORACLE_GAP:.0%} of the oracle"]
    then = f"seeds {CONFIRM_SEEDS[0]}-{CONFIRM_SEEDS[-1]}"
    lines = [f"the rule for a new default (days of {first}; then {then}; p < {RULE_P} by each test)", ""]
    lines += table_head([*head, "a new default? per-day test", "pooled test"])
    passed = {}  # label: (variant, policy, the tests it passed by)
    for variant, policy in [(v, p) for v in candidates for p in ("inform", "inform_selected")]:
        mine = [r for r in rows if r["variant"] == variant and r.get("seed") in RULE_SEEDS]
        if not any(f"eval/{policy}_return" in r for r in mine):  # not run, or no such policy (no offline pick)
            continue
        cells, answers = rule_test(args, rows, variant, policy, RULE_SEEDS, RULE_CLOSER_DAYS, noise)
        label = variant if policy == "inform" else f"{variant}, offline pick"
        tests = [t for t in TESTS if answers[t] == "yes"]
        passed.update({label: (variant, policy, tests)} if tests else {})
        shown = [f"yes, if it holds on {then}" if answers[t] == "yes" else answers[t] for t in TESTS]
        lines.append(table_row([label, *cells, *shown]))
    final = {t: ([], []) for t in TESTS}  # test: (labels that hold, labels still open)
    if passed:
        lines += ["", f"does it hold on the new days ({then}, closer on at least {CONFIRM_CLOSER_DAYS} of them)?", ""]
        lines += table_head([*head, "holds? per-day test", "pooled test"])
        for label, (variant, policy, tests) in passed.items():
            cells, answers = rule_test(args, rows, variant, policy, CONFIRM_SEEDS, CONFIRM_CLOSER_DAYS, noise)
            shown = [answers[t] if t in tests else f"- (no on {first})" for t in TESTS]
            lines.append(table_row([label, *cells, *shown]))
            for t in tests:
                if answers[t] == "yes":
                    final[t][0].append(label)
                elif answers[t] != "no":
                    final[t][1].append(label)
    said = []
    for t in TESTS:
        holds, still = final[t]
        said.append(", ".join(holds) if holds else (f"none yet ({', '.join(still)} still open)" if still else "none"))
    stay = "; the defaults stay" if said[0] == "none" else ""
    verdict_line = f"a new default by the per-day test: {said[0]}{stay} (by the pooled test: {said[1]})"
    return "\n".join([*lines, "", verdict_line])


def tamer_streams(args: Args, day: str, stop: Stop) -> bool:
    """The day's TAMER actor under its run's sampled test (the fixed start, --eval-episodes episodes) in each of
    STREAMS, other streams of sampled actions than the run's own: {results_dir}/{campaign}/<day>/tamer_streams.json.
    Every night of a day tests TAMER in the same stream, so the nights alone show no spread. False if a test failed."""
    dest = os.path.join(args.results_dir, args.campaign, day_name(day), "tamer_streams.json")
    if os.path.isfile(dest):
        return True
    run = read_json(os.path.join(day, "summary.json"))
    cmd = [sys.executable, "-m", "inform_utils.evaluate_policy", "pusher", os.path.join(day, "tamer_actor.pt")]
    cmd += ["--env-id", run["args"]["env_id"], "--seed", str(run["seed"]), "--obstacle-episodes", "0"]
    cmd += ["--eval-episodes", str(run["args"]["eval_episodes"])]
    returns = {}
    for stream in STREAMS:
        try:
            test = last_json(run_child([*cmd, "--stream", str(stream)], stop), f"TAMER's test in stream {stream}")
        except NightFailed as e:
            print(f"[study] failed ({e})", flush=True)
            return False
        returns[str(stream)] = test["eval/policy_return_sampled"]
    os.makedirs(os.path.dirname(dest), exist_ok=True)
    write_json(dest, {"eval/tamer_return_sampled": returns, "command": " ".join(cmd[1:])})
    return True


def return_spread(args: Args, rows: list[dict]) -> float | None:
    """TAMER's own sampling spread on the plain task: the largest range, over the days, of its sampled return between
    the day's streams (the run's own, which every night repeats, and tamer_streams()); None if a day has none."""
    spreads = []
    for campaign, day in sorted({(r.get("campaign", args.campaign), r["day"]) for r in rows}):
        path = os.path.join(args.results_dir, campaign, day, "tamer_streams.json")
        if not os.path.isfile(path):
            return None
        values = list(read_json(path).get("eval/tamer_return_sampled", {}).values())
        values += [r[SAMPLED.format(p="tamer")] for r in rows if r["day"] == day and SAMPLED.format(p="tamer") in r]
        if not values:
            return None
        spreads.append(max(values) - min(values))
    return max(spreads) if spreads else None


def versus(mine: dict, theirs: dict, days: list[str], spread=None, headroom=None) -> tuple[str, bool]:
    """One control of the rule for a night built for the data: the mean of the method's day means minus the
    control's (negative: closer), the paired t-test over the days (two-sided) with its 95% interval and the smallest
    effect it detects at 80% power, the days closer, and 'equivalent' or 'cannot tell' (interval_verdict(): `spread`,
    TAMER's own; `headroom`, the control's distance minus the expert's); and whether it passes (p < METHOD_P, closer on
    average)."""
    diffs = [mine[d] - theirs[d] for d in days]
    stats = paired_interval(diffs)
    p = None if stats is None else stats["p"]
    closer = sum(mine[d] < theirs[d] - TOLERANCE for d in days)
    text = f"{statistics.mean(diffs):+.4f} m, p = {'-' if p is None else f'{p:.2g}'}, closer on {closer} of {len(days)}"
    said = ", ".join(w for w in (interval_text(stats, " m"), interval_verdict(stats, spread, headroom)) if w)
    return text + (f"; {said}" if said else ""), p is not None and p < METHOD_P and statistics.mean(diffs) < 0


def step_size(row: dict) -> str | None:
    """The actor's learning rate a night ran with, as its summary's sleep_variant records it (a method's own)."""
    words = dict(w.split("=", 1) for w in row.get("sleep_variant", "").split() if "=" in w)
    return words.get("policy_lr")


def budget(row: dict) -> int | None:  # the night's gradient steps
    return row.get("args", {}).get("sleep_gradient_steps")


def budgets(args: Args, rows: list[dict]) -> list[dict]:
    """This campaign's nights (rows) and those of --with-campaigns, one campaign a budget: ValueError if a campaign
    holds none, or a budget of nights another campaign holds too (their days would be pooled)."""
    every, owner = list(rows), {budget(r): args.campaign for r in rows}
    for other in args.with_campaigns:
        theirs = scan(replace(args, campaign=other))[0]
        if not theirs:
            raise ValueError(f"--with-campaigns {other}: no completed nights under {args.results_dir}/{other}")
        for steps in sorted({budget(r) for r in theirs}, key=str):
            if owner.setdefault(steps, other) != other:
                raise ValueError(f"--with-campaigns {other}: its nights of {steps} gradient steps are a budget of "
                                 f"--campaign {owner[steps]} too; name one campaign a budget")  # fmt: skip
        every += theirs
    return every


def matched_cloning(rows: list[dict], method: str) -> tuple[str, str | None]:
    """The cloning control that shares the method's step size (rows: one task and budget): (its step size, the
    control's variant name, None if none of the cloning controls ran at it)."""
    lr = next((step_size(r) for r in rows if r["variant"] == method), None)
    for control in ("bc", *CLONING):
        if any(r["variant"] == control and step_size(r) == lr for r in rows):
            return lr, control
    return lr, None


def method_rule(args: Args, rows: list[dict], methods: list[str]) -> str:
    """The rule for a night built for the data, per task (env id), budget (gradient steps) and method, on the days
    that hold the method and the controls: versus() each control with the boxes, the plain task's sampled return
    against TAMER's in the same nights with TAMER's sampling spread, and the verdict: yes, no, or open while fewer than
    METHOD_DAYS days ran. Twice: as the rule was committed (bc at the night's 5e-6 and the sham), and with the cloning
    control at the method's own step size in bc's place (issue 56). Then the same comparisons in the deterministic
    test (the mean action; not the rule's)."""
    if not methods:
        return "the rule for a night built for the data: no night of a method (--sleep-method) in this campaign"
    rule = (
        f"the rule for a night built for the data (per task and budget: with the boxes closer than each control, "
        f"paired t-test over the days p < {METHOD_P}; on the plain task not below TAMER by more than its spread); "
        "'as committed' against bc (cloning at 5e-6) and the sham, 'matched' against cloning at the method's own "
        "step size and the sham"
    )
    lines = [rule, ""]
    head = ["task", "budget", "method (step size)", "days", "with the boxes vs bc", "vs bc at its step size",
            "vs sham", "plain task vs TAMER", "consolidates? as committed", "matched"]  # fmt: skip
    lines += table_head(head)
    deterministic = table_head(["task", "budget", "method", "days", "vs bc", "vs bc at its step size", "vs sham"])
    task_of = lambda r: r.get("args", {}).get("env_id", "?")  # noqa: E731
    rule_days = {}  # (task, budget): the days every method shares with bc and the sham
    for task, steps in sorted({(task_of(r), budget(r)) for r in rows}, key=str):
        on_task = [r for r in rows if task_of(r) == task and budget(r) == steps]
        for method in methods:
            lr, matched = matched_cloning(on_task, method)
            mine = day_means(on_task, method, OBSTACLE)
            controls = {c: day_means(on_task, c, OBSTACLE) for c in ("bc", "sham") + ((matched,) if matched else ())}
            ret, tamer = day_means(on_task, method, SAMPLED), day_means(on_task, method, SAMPLED, "tamer")
            days = [d for d in mine if all(d in controls[c] for c in ("bc", "sham")) and d in ret and d in tamer]
            if not days:
                continue
            noise = tamer_spread(args, [r for r in on_task if r["day"] in days])  # TAMER's, with the boxes
            oracle = day_means(on_task, "oracle", OBSTACLE)  # the expert's distance with the boxes: the floor
            matched_days = [d for d in days if matched and d in controls[matched]]
            tests = {"matched": ("not run", False)}
            for name, control, on in (("bc", "bc", days), ("sham", "sham", days), ("matched", matched, matched_days)):
                if on:  # the room a night has to gain: the control's distance minus the expert's
                    room = (
                        statistics.mean(controls[control][d] - oracle[d] for d in on)
                        if set(on) <= set(oracle)
                        else None
                    )
                    tests[name] = versus(mine, controls[control], on, noise, room)
            spread = return_spread(args, [r for r in on_task if r["day"] in days])  # over the rule's days only
            gap = statistics.mean(ret[d] - tamer[d] for d in days)
            spread_text = "no tamer_streams.json" if spread is None else f"{spread:.2f}"
            plain = (f"{gap:+.2f} (spread {spread_text})", spread is not None and gap >= -spread - TOLERANCE)
            answers = []
            for against, n in ((("bc", "sham"), len(days)), (("matched", "sham"), len(matched_days))):
                answer = "yes" if all(tests[c][1] for c in against) and plain[1] else "no"
                answer = answer if n >= METHOD_DAYS else f"open: {n} of {METHOD_DAYS} days"
                answers.append(answer if spread is not None else "open: TAMER's streams not run")
            if not matched:
                answers[1] = f"open: no cloning control at {lr}"
            lines.append(table_row([task, str(steps), f"{method} ({lr})", str(len(days)), tests["bc"][0],
                                    f"{matched or '-'}: {tests['matched'][0]}" if matched else "not run",
                                    tests["sham"][0], plain[0], *answers]))  # fmt: skip
            cells = []
            for control in ("bc", matched, "sham"):
                mine_det = day_means(on_task, method, OBSTACLE_DETERMINISTIC)
                theirs = day_means(on_task, control, OBSTACLE_DETERMINISTIC) if control else {}
                both = [d for d in days if d in mine_det and d in theirs]
                cells.append(versus(mine_det, theirs, both)[0] if both else "-")
            deterministic.append(table_row([task, str(steps), method, str(len(days)), *cells]))
            rule_days[(task, steps)] = rule_days.get((task, steps), set(days)) & set(days)
    lines += [
        "",
        "the deterministic test beside it (not the rule's: the mean action, one episode a night from the "
        "same start with the same boxes, eval/obstacle/inform_final_distance_deterministic):",
        "",
        *deterministic,
    ]
    for (task, steps), days in sorted(rule_days.items(), key=str):
        on_days = [r for r in rows if task_of(r) == task and budget(r) == steps and r["day"] in days]
        lines += ["", f"{task}, {steps} gradient steps, the means over the {len(days)} days the methods and both "
                  "controls share:", ""]  # fmt: skip
        lines += rule_means(on_days, list(dict.fromkeys([*methods, "bc", *CLONING, "sham", "default"])))
    return "\n".join(lines)


def rule_means(rows: list[dict], variants: list[str]) -> list[str]:
    """One row a policy on these rows' days: the mean over the days of its day means (day_means()) on the fixed start,
    with the boxes and in the plain task's sampled test, and how many of its nights (TAMER: of the days) end the
    fixed start in success. A variant that did not run on every day is left out."""
    days, measures = {r["day"] for r in rows}, ("eval/{p}_return", OBSTACLE, SAMPLED)
    lines = table_head(["policy", "fixed-start return", "fixed-start successes", "with the boxes", "sampled return"])
    for variant in ("tamer", *variants):
        if variant == "tamer":
            nights, p = list(first_nights(rows).values()), "tamer"
        else:
            nights, p = [r for r in rows if r["variant"] == variant], "inform"
        means = [day_means(rows, variant, key) for key in measures]
        if any(set(m) != days for m in means):  # day_means() holds only the days the variant ran
            continue
        ret, boxes, sampled = (statistics.mean(m.values()) for m in means)
        ok = sum((r.get(f"eval/{p}_success_rate") or 0) >= 1 for r in nights)
        what = "days" if variant == "tamer" else "nights"
        cells = [f"{ret:.2f}", f"{ok} of {len(nights)} {what}", f"{boxes:.3f} m", f"{sampled:.2f}"]
        lines.append(table_row([variant, *cells]))
    return lines


def validate(args: Args, extra: list[str] = ()) -> dict[str, dict]:
    """Bad input, before anything runs (`extra`: the flags after --): ValueError, one line. Returns {day: its name in
    a night's record, by content and by day.pt's sha256}."""
    if not re.fullmatch(FOLDER, args.campaign):
        raise ValueError(f"--campaign {args.campaign[:100]!r}: one folder name under {args.results_dir}/ (letters, "
                         "digits and ._+=-, no / or ..)")  # fmt: skip
    study = STUDIES[args.script]
    unknown = [v for v in args.variants or [] if v not in study.variants]
    if unknown:
        raise ValueError(f"unknown variant(s) {', '.join(unknown)}; choose from {', '.join(study.variants)}")
    named = [args.campaign, *args.with_campaigns]
    for other in args.with_campaigns:
        if not args.table or not re.fullmatch(FOLDER, other) or named.count(other) > 1:
            raise ValueError(f"--with-campaigns {other[:100]!r}: campaigns (folder names under {args.results_dir}/) "
                             "beside --table's, for the table only, each named once")  # fmt: skip
    if args.retest_from is not None and (not study.pusher or args.table or args.days or args.variants or extra):
        raise ValueError("--retest-from: for a campaign of Pusher nights already kept, without --days, --variants, "
                         "--table or flags after --")  # fmt: skip
    if args.retest_from is not None and not os.path.isdir(args.retest_from):
        raise ValueError(f"--retest-from {args.retest_from[:100]}: no such folder (the runs of the nights, runs/)")
    if args.table:  # a campaign that is a file (or a dangling link) holds no nights: not an empty table
        for flag, where in [("--results-dir", args.results_dir)] + [("--campaign", c) for c in named]:
            path = where if flag == "--results-dir" else os.path.join(args.results_dir, where)
            if os.path.lexists(path) and not os.path.isdir(path):
                raise ValueError(f"{flag} {where[:100]}: {path[:200]} is not a folder of nights")
        return {}
    steps = args.gradient_steps if args.gradient_steps is not None else 1
    if not args.sleep_seeds or args.random_start_episodes < 1 or steps < 1:
        raise ValueError("--sleep-seeds must name at least one seed, --random-start-episodes and --gradient-steps "
                         "be >= 1")  # fmt: skip
    if study.pusher and any(zero(value) for value in given(extra, "--obstacle-episodes")):
        raise ValueError("--obstacle-episodes 0 after --: the Pusher study's table needs every night's obstacle test "
                         "(obstacle_distances.npz); leave it out, or give at least 1")  # fmt: skip
    for day in args.days:
        if not os.path.isfile(os.path.join(day, "day.pt")):
            raise ValueError(f"{day} holds no day.pt; make one with {args.script} --save-buffer")
    check_writable(os.path.join(args.results_dir, args.campaign), "--results-dir")
    days = {day: {"day_sha256": sha256(os.path.join(day, "day.pt")),
                  "day_content_sha256": content_sha256(os.path.join(day, "day.pt"))} for day in args.days}  # fmt: skip
    by_name = {}
    for day, names in days.items():  # the campaign keeps a day's nights under its folder's name
        other, known = by_name.setdefault(day_name(day), (day, names))
        content = names["day_content_sha256"]
        if known["day_sha256"] != names["day_sha256"] and (content is None or content != known["day_content_sha256"]):
            raise ValueError(f"--days {other} and {day}: two different days in folders of one name; give one of "
                             "them another folder name (or run it in another --campaign)")  # fmt: skip
    return days


def given(flags: list[str], name: str) -> list[str]:
    """The values `flags` give the flag `name` (as `name value` or `name=value`)."""
    pairs = zip(flags, [*flags[1:], ""], strict=False)  # each flag and the word after it
    return [value if flag == name else flag.split("=", 1)[1] for flag, value in pairs if flag.split("=")[0] == name]


def zero(text: str) -> bool:
    try:
        return int(text) == 0
    except ValueError:
        return False


def study_main(args: Args, extra: list[str]) -> int:
    """Run the campaign's nights that are not kept yet, then print the table. Exit 0, 1 if a night failed, 2 for bad
    input (ValueError, raised before anything runs, or by a night that refuses its input), 128 + the signal if
    stopped."""
    days = validate(args, extra)
    if args.table:
        print(table(args))
        return 0
    if args.retest_from is not None:
        with Stop().installed() as stop:
            try:
                failed = retest(args, stop)
            except Stopped:
                print(f"error: stopped by {signal.Signals(stop.signum).name}; the nights retested are kept, run the "
                      "same command again to resume", file=sys.stderr)  # fmt: skip
                return 128 + stop.signum
        for why in failed:
            print(f"error: {why}", file=sys.stderr)
        return 1 if failed else 0
    study = STUDIES[args.script]
    plan = [(day, variant, seed) for variant in args.variants or list(study.variants)
            for seed in (args.sleep_seeds if variant in study.all_seeds else args.sleep_seeds[:1])
            for day in args.days]  # fmt: skip
    records = {}
    for day, variant, seed in plan:
        night_flags = night_command(args, day, variant, seed, extra)[5:]  # after `-m runner --sleep-from DAY`
        records[night_dir(args, day_name(day), variant, seed)] = identity(args, extra, days[day], night_flags)
    found = conflicts(args, records)
    if found:
        more = f" (and {len(found) - 1} more)" if found[1:] else ""
        raise ValueError(f"--campaign {args.campaign}: {found[0]}{more}; a campaign keeps only its own nights: name "
                         "another --campaign, or move those away")  # fmt: skip
    failed = []
    with Stop().installed() as stop:
        try:
            for day, variant, seed in plan:
                if stop.signum:
                    raise Stopped
                if not run_night(args, day, variant, seed, records[night_dir(args, day_name(day), variant, seed)],
                                 stop):  # fmt: skip
                    failed.append(f"{variant} sleep seed {seed} on {day_name(day)}")
            for day in args.days if study.pusher else ():
                if not tamer_streams(args, day, stop):
                    failed.append(f"TAMER's streams on {day_name(day)}")
            text = table(args)
        except Stopped:
            text = None
        if stop.signum:  # a stop while the table was made, too: the study did not finish
            where = os.path.join(args.results_dir, args.campaign)
            print(f"error: stopped by {signal.Signals(stop.signum).name}; the nights that finished are kept in "
                  f"{where}, run the same command again to resume", file=sys.stderr)  # fmt: skip
            return 128 + stop.signum
    print(text)
    if failed:
        print(f"error: {len(failed)} of {len(plan)} night(s) or tests failed ({'; '.join(failed)}); run the same "
              "command again to retry them", file=sys.stderr)  # fmt: skip
        return 1
    return 0


if __name__ == "__main__":
    argv = sys.argv[1:]
    extra = argv[argv.index("--") + 1 :] if "--" in argv else []  # flags after -- go to every night
    args = tyro.cli(Args, args=argv[: argv.index("--")] if "--" in argv else argv)  # a malformed flag: tyro, exit 2
    try:
        sys.exit(study_main(args, extra))
    except (ValueError, OSError) as e:  # BadFile is a ValueError; an OSError: results/ could not take a night
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2 if isinstance(e, ValueError) else 1)
