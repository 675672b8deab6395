"""Run one of the INFORM scripts for several seeds (and a grid of flags), locally in parallel worker processes or
on a Slurm cluster as a job array through submitit, then gather their summary.json files into one table per grid
point (mean, std, n per key). Resumable: a run whose summary.json says completed, for the same script, seed and
flags, is not run again; an interrupted, failed or timed-out run is.

In the spirit of CleanRL's benchmark utility.

    python -m inform_utils.run_seeds --script inform_dqn_gridworld.py --exp-name fig3 --seeds 1 2 3 4 5 --workers 2
    python -m inform_utils.run_seeds --script inform_sac_pusher.py --exp-name fig3 --seeds 1 2 3 -- --random-starts
    python -m inform_utils.run_seeds --exp-name noise --grid teacher-noise=0,0.1,0.2 --launcher slurm --slurm-time 30

Stopping: SIGINT or SIGTERM (Ctrl-C, kill, a scheduler) is passed on to the runs, which save what finished and
write summary.json with status interrupted; run_seeds then reports them and exits 130 / 143. With --launcher slurm
it cancels the jobs it submitted (Slurm sends them SIGTERM), so the same command later resumes the sweep instead of
racing jobs still running. A second signal kills the local runs outright.
"""

import contextlib
import fcntl
import glob
import itertools
import json
import math
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Literal

import tyro

if not __package__:  # run as a file (python inform_utils/run_seeds.py): its package is found from the repository
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from inform_utils.files import BadFile, check_writable, read_json  # noqa: E402


@dataclass
class Args:
    script: str = "inform_dqn_gridworld.py"
    """the script to run (it must take --seed and --exp-name; --num-threads is passed if its Args has it)"""
    exp_name: str = "seeds"
    """the experiment name: runs are runs/{env_id}__{exp_name}__{seed}__{time}; it is how finished runs are found"""
    seeds: list[int] = field(default_factory=lambda: [1, 2, 3, 4, 5])
    """the seeds to run"""
    grid: tyro.conf.UseAppendAction[list[str]] = field(default_factory=list)
    """a flag of the script and the values to try, e.g. teacher-noise=0,0.1,0.2; repeat --grid for several flags
    (every combination is run for every seed, and tabulated on its own)"""
    launcher: Literal["local", "slurm"] = "local"
    """local: worker processes on this machine; slurm: one Slurm job per run, submitted as a job array"""
    workers: int = 2
    """runs side by side (local launcher)"""
    threads: int = 1
    """torch threads per run (1: these small networks are fastest on one thread, above all on a busy machine;
    0: local, the machine's cores divided among the workers; slurm, --slurm-cpus-per-task)"""
    slurm_partition: str | None = None
    """Slurm partition (None: the cluster's default partition)"""
    slurm_time: int = 120
    """minutes per run (Slurm's --time); a run still going then is stopped, saves what finished, reported timed out"""
    slurm_cpus_per_task: int = 1
    """CPUs per run (Slurm's --cpus-per-task)"""
    slurm_mem: str | None = None
    """memory per run in Slurm's syntax, e.g. 4G or 500M (None: the partition's default)"""
    poll_seconds: float = 5.0
    """seconds between two looks at the Slurm queue"""
    runs_dir: str = "runs"
    """where the script writes its runs (relative to the working directory)"""
    logs_dir: str = "runs/logs"
    """where each run's stdout and stderr go (Slurm: {logs_dir}/slurm, named by job id)"""
    results_dir: str | None = None
    """keep a copy of each completed run here (e.g. results/v4paper), to commit: its files up to --keep-max-mb each,
    not its subfolders; runs kept here count as finished, so the same command resumes a sweep where it stopped"""
    keep_max_mb: float = 5.0
    """the largest file of a run copied into --results-dir (a Pusher run's summary, obstacle files, events and
    networks are each under 2 MB)"""
    script_args: tyro.conf.Positional[list[str]] = field(default_factory=list)
    """extra flags for every run, after a `--`"""


# A grid point: the (flag, value) pairs of one combination of --grid values, () without a grid.
Point = tuple[tuple[str, str], ...]


@dataclass(frozen=True)
class Run:
    seed: int
    point: Point

    @property
    def label(self) -> str:
        return ",".join(f"{k}={v}" for k, v in self.point)

    def __str__(self) -> str:
        return f"seed {self.seed}" + (f" ({self.label})" if self.point else "")


@dataclass
class Outcome:
    status: str  # completed | interrupted | timeout | cancelled | failed | not started
    detail: str = ""
    stderr_path: str = ""


def grid_points(grid: list[str], script_args: list[str]) -> list[Point]:
    """The cartesian product of the --grid flags' values, in the order given."""
    axes, names = [], set()
    for spec in grid:
        name, sep, values = spec.partition("=")
        name = name.strip().removeprefix("--").replace("_", "-")
        choices = [v.strip() for v in values.split(",")]
        if not sep or not name or not all(choices):
            raise ValueError(f"--grid {spec!r}: expected FLAG=VALUE,VALUE,... (e.g. teacher-noise=0,0.1,0.2)")
        if name in {"seed", "exp-name", "num-threads"}:
            raise ValueError(f"--grid {spec!r}: --{name} is set by run_seeds itself")
        if name in names:
            raise ValueError(f"--grid {name} given twice")
        if name in flag_values(script_args):
            raise ValueError(f"--grid {name} is also among the script's flags after --")
        names.add(name)
        axes.append([(name, v) for v in choices])
    return list(itertools.product(*axes))


def flag_values(tokens: list[str]) -> dict[str, list[str] | bool]:
    """The script's flags as tyro reads them: --name v [v ...] -> values, --name -> True, --no-name -> False
    (names with dashes)."""
    flags: dict[str, list[str] | bool] = {}
    name = None
    for token in tokens:
        if token.startswith("--"):
            name, sep, value = token[2:].partition("=")
            name = name.replace("_", "-")
            flags[name] = [value] if sep else True
            name = None if sep else name
        elif name is not None:
            flags[name] = [*(flags[name] if isinstance(flags[name], list) else []), token]
    for name in [n for n, v in flags.items() if v is True and n.startswith("no-")]:
        del flags[name]
        flags[name.removeprefix("no-")] = False
    return flags


def same_value(recorded, wanted: str) -> bool:
    if recorded is None or isinstance(recorded, str):
        return str(recorded) == wanted
    if isinstance(recorded, bool):
        return wanted.lower() in ({"true", "1"} if recorded else {"false", "0"})
    try:
        return math.isclose(float(wanted), recorded, rel_tol=1e-12, abs_tol=0.0)
    except (TypeError, ValueError):
        return False


def ran_with(recorded_args: dict, flags: dict[str, list[str] | bool]) -> bool:
    """Whether a run's recorded Args (summary.json "args") agree with these command-line flags."""
    for name, wanted in flags.items():
        key = name.replace("-", "_")
        if key not in recorded_args:
            return False
        value = recorded_args[key]
        if isinstance(wanted, bool):
            ok = value is wanted
        elif isinstance(value, list | tuple):
            ok = len(value) == len(wanted) and all(same_value(v, w) for v, w in zip(value, wanted, strict=True))
        else:
            ok = len(wanted) == 1 and same_value(value, wanted[0])
        if not ok:
            return False
    return True


def run_flags(args: Args, run: Run) -> dict[str, list[str] | bool]:
    return {**flag_values(args.script_args), **{name: [value] for name, value in run.point}}


# In a child process (importing a script runs its top level): the script's own Args, parsed from the flags run_seeds
# gives a run and completed as the script completes them (its check_args, the Pusher's sleep preset), and its
# defaults, as JSON (non-finite numbers as null, as the summaries write them). tyro's error, or the check's, for a
# flag or value the script does not take.
CAMPAIGN_ARGS = """
import dataclasses, importlib.util, json, math, os, sys
import tyro
script, tokens = sys.argv[1], sys.argv[2:]
sys.path.insert(0, os.path.dirname(os.path.abspath(script)))
spec = importlib.util.spec_from_file_location("campaign_script", script)
module = sys.modules["campaign_script"] = importlib.util.module_from_spec(spec)  # so tyro finds its docstrings
spec.loader.exec_module(module)
plain = lambda v: None if isinstance(v, float) and not math.isfinite(v) else list(v) if isinstance(v, tuple) else v
fields = lambda a: {k: plain(v) for k, v in dataclasses.asdict(a).items()}
parsed, defaults = tyro.cli(module.Args, args=tokens), tyro.cli(module.Args, args=[])
try:  # the script's own checks, which also fill what a preset leaves to them (the maze's --teacher defaults)
    getattr(module, "check_args", lambda args: None)(parsed)
    if hasattr(parsed, "sleep_recipe"):  # the Pusher's --sleep-protocol preset, which its summary records
        names = {f.name for f in dataclasses.fields(parsed)}
        parsed = dataclasses.replace(parsed, **{k: v for k, v in parsed.sleep_recipe().items() if k in names})
except Exception as e:
    sys.exit(f"error: {e}")
print(json.dumps({"args": fields(parsed), "defaults": fields(defaults)}, default=str))
"""
_campaign_args: dict[tuple, dict | None] = {}


def campaign_args(args: Args, point: Point) -> dict | None:
    """{"args", "defaults"}: what every run of this campaign at `point` records (but its seed), and the script's
    defaults; None for a script without a tyro `Args` class (then the flags given are compared). ValueError, one
    line, for a flag or value the script refuses: checked before anything runs."""
    key = (os.path.abspath(args.script), tuple(args.script_args), point, args.threads, args.workers, args.launcher)
    if key not in _campaign_args:
        with open(args.script) as f:
            if not re.search(r"^class Args\b", f.read(), re.M):
                _campaign_args[key] = None
                return None
        tokens = command(args, Run(0, point), run_threads(args))[2:]
        proc = subprocess.run([sys.executable, "-c", CAMPAIGN_ARGS, args.script, *tokens], capture_output=True,
                              text=True, cwd=os.getcwd())  # fmt: skip
        if proc.returncode != 0:
            lines = [line.strip(" │╭╰─") for line in proc.stderr.splitlines()]
            why = next((line for line in lines if ":" in line and "--help" not in line), "")  # tyro's box's first
            label = Run(0, point).label or " ".join(args.script_args)
            raise ValueError(f"{args.script} refuses the campaign's flags ({label}): {why[:200]}")
        _campaign_args[key] = json.loads(proc.stdout.strip().splitlines()[-1])
    return _campaign_args[key]


# a setting whose default is not what runs before it ran under: Pusher's contact (Pusher-v4's runs were made on mujoco
# 2.3.7, whose contact the 2.3 one is; Pusher-v5's on mujoco 4's own)
BEFORE_THE_SETTING = {"contact": lambda recorded: {"Pusher-v5": "gymnasium"}.get(recorded.get("env_id"), "mujoco-2.3")}


def is_campaigns(recorded: dict, campaign: dict) -> bool:
    """A run's recorded args against the campaign's: every field both know is equal (but the seed, checked by the
    caller); a field the run does not record (added to the script later) must be at the script's default, as it was
    then (or at BEFORE_THE_SETTING's value); one the script no longer has is passed over."""
    for name, value in campaign["args"].items():
        if name == "seed":
            continue
        if name in recorded:
            if recorded[name] != value:
                return False
        elif value != (
            BEFORE_THE_SETTING[name](recorded) if name in BEFORE_THE_SETTING else campaign["defaults"].get(name)
        ):
            return False
    return True


_unreadable: set[str] = set()  # the summaries newest_summary() has warned about


def newest_summary(args: Args, run: Run, completed: bool = True, since: float = 0.0) -> tuple[str, dict] | None:
    """The newest summary.json of this campaign's run: this script, experiment name and seed, and every other flag
    the campaign's (completed only, unless told otherwise; two scripts may share an experiment name: each
    summary.json names the script that wrote it)."""
    paths = []
    for folder in filter(None, (args.runs_dir, args.results_dir)):
        paths += glob.glob(os.path.join(folder, f"*__{args.exp_name}__{run.seed}__*", "summary.json"))
    flags = run_flags(args, run)
    for path in sorted(paths, key=lambda p: os.lstat(p).st_mtime, reverse=True):
        if os.lstat(path).st_mtime < since:
            break
        if os.path.dirname(path).endswith(".tmp"):  # a run half-copied into --results-dir never counts
            continue
        try:  # unreadable, half-written, a dangling link: not a finished run (said once), so it is run again
            summary = read_json(path)
        except BadFile as e:
            if path not in _unreadable:
                _unreadable.add(path)
                print(f"warning: {e}; not counted as a finished run", file=sys.stderr, flush=True)
            continue
        recorded = summary.get("args", {})
        recorded = recorded if isinstance(recorded, dict) else {}
        if (
            summary.get("script") == os.path.basename(args.script)
            and (not completed or summary.get("status") == "completed")
            and recorded.get("exp_name") == args.exp_name
            and recorded.get("seed") == run.seed
            and ran_with(recorded, flags)
            and ((campaign := campaign_args(args, run.point)) is None or is_campaigns(recorded, campaign))
        ):
            return path, summary
    return None


def takes_num_threads(script: str) -> bool:
    """Whether the script's Args has a num_threads flag (the maze, single-threaded by design, has none)."""
    with open(script) as f:
        return re.search(r"^    num_threads\s*:", f.read(), re.M) is not None


def command(args: Args, run: Run, threads: int) -> list[str]:
    cmd = [sys.executable, os.path.abspath(args.script), "--seed", str(run.seed), "--exp-name", args.exp_name]
    cmd += ["--num-threads", str(threads)] if takes_num_threads(args.script) else []
    cmd += args.script_args
    for name, value in run.point:
        cmd += [f"--{name}", value]
    return cmd


def outcome_from_run(args: Args, run: Run, code: int | None, since: float) -> Outcome:
    """What became of a run, from its exit code and the summary.json it wrote."""
    found = newest_summary(args, run, completed=False, since=since)
    summary = found[1] if found else {}
    if summary.get("status") == "completed" and code in (0, None):
        return Outcome("completed")
    if summary.get("status") == "interrupted":
        how = f" by {summary['signal']}" if summary.get("signal") else ""
        return Outcome("interrupted", f"stopped{how} during the {summary.get('phase', '?')} phase; saved what finished")
    if code in (-signal.SIGINT, -signal.SIGTERM):
        return Outcome("interrupted", f"killed by {signal.Signals(-code).name} before it could save")
    if code is not None and code < 0:
        return Outcome("failed", f"killed by {signal.Signals(-code).name}, no summary.json")
    if summary.get("status"):
        return Outcome("failed", f"exit {code}, status {summary['status']}")
    return Outcome("failed", f"exit {code}, no summary.json" if code is not None else "no summary.json")


def keep(args: Args, run: Run, since: float) -> None:
    """Copy a completed run's files into --results-dir/{run name}/ (all at once: a half-copied run never counts)."""
    found = newest_summary(args, run, since=since)
    if args.results_dir is None or found is None:
        return
    run_dir = os.path.dirname(found[0])
    dest = os.path.join(args.results_dir, os.path.basename(run_dir))
    if os.path.abspath(run_dir) == os.path.abspath(dest) or os.path.exists(dest):
        return
    tmp, skipped = dest + ".tmp", []
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        os.makedirs(tmp)
        for name in sorted(os.listdir(run_dir)):
            path = os.path.join(run_dir, name)
            if not os.path.isfile(path):
                continue
            if os.path.getsize(path) > args.keep_max_mb * 2**20:
                skipped.append(f"{name} ({os.path.getsize(path) / 2**20:.0f} MB)")
                continue
            shutil.copy2(path, tmp)
        os.replace(tmp, dest)
    except OSError as e:  # a full or read-only disk: the run stays in runs/, the table still comes
        shutil.rmtree(tmp, ignore_errors=True)
        print(f"warning: {run}: not kept in {dest} ({e.strerror or e}); it stays in {run_dir}", file=sys.stderr,
              flush=True)  # fmt: skip
        return
    print(f"{run}: kept in {dest}" + (f" (not copied, over --keep-max-mb: {', '.join(skipped)})" if skipped else ""),
          flush=True)  # fmt: skip


def tail(path: str, n: int = 8) -> list[str]:
    try:
        with open(path, errors="replace") as f:
            return f.read().splitlines()[-n:]
    except OSError:
        return []


# --------------------------------------------------------------------------------------------------------------
# The local launcher: worker threads, each running one script process at a time.


class Stop:
    """The first SIGINT/SIGTERM: remember it and pass it on once to every live run (each in its own process group,
    so a terminal's Ctrl-C reaches them only through us); a second one kills them."""

    def __init__(self):
        self.signum = 0
        self.count = 0
        self.lock = threading.Lock()
        self.procs: set[subprocess.Popen] = set()

    def handler(self, signum, frame):
        with self.lock:  # only worker threads take this lock, briefly; the handler runs in the main thread
            again, self.signum = self.signum != 0, self.signum or signum
            self.count += 1
            for p in self.procs:
                with contextlib.suppress(ProcessLookupError):
                    p.send_signal(signal.SIGKILL if again else signum)
        # os.write, not print: the main thread may be inside a print when the signal lands
        os.write(1, f"\n{signal.Signals(signum).name}: {'killing' if again else 'stopping'} the runs\n".encode())

    @contextlib.contextmanager
    def installed(self):
        # a SIGINT ignored at start (a background job of a script) stays ignored, as Python itself does
        signals = [s for s in (signal.SIGINT, signal.SIGTERM) if signal.getsignal(s) is not signal.SIG_IGN]
        old = {s: signal.signal(s, self.handler) for s in signals}
        try:
            yield self
        finally:
            for s, h in old.items():
                signal.signal(s, h)


def run_threads(args: Args) -> int:
    """--num-threads of each run: --threads, or 0: the machine's cores among the workers (Slurm: its CPUs a task)."""
    if args.launcher == "slurm":
        return args.threads or args.slurm_cpus_per_task
    return args.threads or max(1, (os.cpu_count() or 1) // args.workers)


def run_local(args: Args, todo: list[Run], stop: Stop) -> dict[Run, Outcome]:
    threads = run_threads(args)
    print(f"running {args.script} for {len(todo)} run(s): {args.workers} workers, {threads} thread(s) each", flush=True)
    os.makedirs(args.logs_dir, exist_ok=True)
    outcomes: dict[Run, Outcome] = {}

    def one(run: Run) -> None:
        if stop.signum:  # checked again under the lock below; this one keeps an earlier attempt's log
            outcomes[run] = Outcome("not started")
            return
        cmd = command(args, run, threads)
        name = "__".join([args.exp_name, *([run.label.replace("/", "_")] if run.point else []), str(run.seed)])
        log = os.path.join(args.logs_dir, f"{name}.log")
        start = time.time()
        with open(log, "a") as f:
            try:  # a second campaign of the same name and seed finds the log locked: it leaves this run alone
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                outcomes[run] = Outcome("not started", f"another run_seeds is running it (its log {log} is locked)")
                print(f"{run}: not started: another run_seeds is running it (log {log})", flush=True)
                return
            f.truncate(0)
            f.write(shlex.join(cmd) + "\n")
            f.flush()
            with stop.lock:
                if stop.signum:
                    outcomes[run] = Outcome("not started")
                    return
                p = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, process_group=0)
                stop.procs.add(p)
            code = p.wait()
            with stop.lock:
                stop.procs.discard(p)
        outcomes[run] = outcome = outcome_from_run(args, run, code, start)
        outcome.stderr_path = log
        if outcome.status == "completed":
            keep(args, run, start)
        counts = {s: sum(o.status == s for o in outcomes.values()) for s in ("completed", "interrupted", "failed")}
        print(f"{run}: {outcome.status} (exit {code}) after {time.time() - start:.0f}s (log: {log}) "
              f"[{len(outcomes)}/{len(todo)} finished: {counts['completed']} done, {counts['failed']} failed, "
              f"{counts['interrupted']} interrupted]", flush=True)  # fmt: skip

    with ThreadPoolExecutor(args.workers) as pool:
        list(pool.map(one, todo))
    return outcomes


# --------------------------------------------------------------------------------------------------------------
# The Slurm launcher: submitit writes the sbatch array and runs slurm_job on the nodes; squeue says what is pending
# or running; a job that left the queue is judged by its run's summary.json and its stderr (a single-node Slurm
# has no accounting database, so sacct cannot be relied on).


def slurm_job(cmd: list[str], cwd: str) -> int:
    """What each array task runs on its node: the script, in the submission directory."""
    import shlex
    import signal
    import subprocess
    import sys

    # submitit asks Slurm for SIGUSR2 before the time limit, to checkpoint and requeue: a run has nothing to requeue,
    # and the signal's default action would kill it unsaved. Ignore it here and in the run (an ignored signal stays
    # ignored across exec). SIGTERM (time limit, scancel) reaches the run from Slurm; it saves what finished.
    signal.signal(signal.SIGUSR2, signal.SIG_IGN)
    print(f"run_seeds: {shlex.join(cmd)}", file=sys.stderr, flush=True)
    code = subprocess.call(cmd, cwd=cwd, stdin=subprocess.DEVNULL)
    print(f"run_seeds: the run exited with code {code}", file=sys.stderr, flush=True)
    return code


def check_slurm(args: Args) -> None:
    """Before anything is written: Slurm is here, answers, and has the partition."""
    if shutil.which("sbatch") is None:
        raise ValueError("--launcher slurm: no sbatch on PATH (this machine has no Slurm; use --launcher local)")
    try:
        out = subprocess.run(["sinfo", "-h", "-o", "%R"], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired) as e:
        raise ValueError(f"--launcher slurm: sinfo failed ({e})") from None
    if out.returncode != 0:
        first = (out.stderr.strip().splitlines() or ["no message"])[0]
        raise ValueError(f"--launcher slurm: Slurm does not answer (sinfo: {first})")
    partitions = sorted(set(out.stdout.split()))
    if args.slurm_partition is not None and args.slurm_partition not in partitions:
        raise ValueError(f"--slurm-partition {args.slurm_partition}: no such partition (this cluster has: "
                         f"{', '.join(partitions) or 'none'})")  # fmt: skip
    # Slurm itself judges time, CPUs and memory against the partition and its nodes, submitting nothing
    test = ["sbatch", "--test-only", "--time", str(args.slurm_time), "--cpus-per-task", str(args.slurm_cpus_per_task)]
    test += ["--partition", args.slurm_partition] if args.slurm_partition else []
    test += ["--mem", args.slurm_mem] if args.slurm_mem else []
    out = subprocess.run([*test, "--wrap", "true"], capture_output=True, text=True, timeout=60)
    if out.returncode != 0:
        reason = " ".join(line.strip() for line in out.stderr.splitlines() if line.strip())
        raise ValueError(f"--launcher slurm: Slurm refuses a job of --slurm-time {args.slurm_time} "
                         f"--slurm-cpus-per-task {args.slurm_cpus_per_task}"
                         + (f" --slurm-mem {args.slurm_mem}" if args.slurm_mem else "") + f" ({reason})")  # fmt: skip


def squeue_states(job_ids: list[str]) -> dict[str, str] | None:
    """The queue state (PENDING, RUNNING, ...) of each of these array tasks still in the queue; None if squeue
    failed."""
    arrays = sorted({j.split("_")[0] for j in job_ids})
    out = subprocess.run(["squeue", "-h", "-r", "-o", "%i %T", "-j", ",".join(arrays)], capture_output=True,
                         text=True, timeout=60)  # fmt: skip
    if out.returncode != 0:
        return None
    return dict(line.split(maxsplit=1) for line in out.stdout.splitlines() if line.strip())


def slurm_outcome(args: Args, run: Run, job, since: float) -> Outcome:
    """A job that left the queue: timed out (Slurm's message on its stderr), cancelled, or as its run says."""
    path = str(job.paths.stderr)
    try:
        with open(path, errors="replace") as f:
            text = f.read()
    except OSError:
        text = ""
    codes = re.findall(r"^run_seeds: the run exited with code (-?\d+)$", text, re.M)
    outcome = outcome_from_run(args, run, int(codes[-1]) if codes else None, since)
    outcome.stderr_path = path
    saved = f"; the run {outcome.detail}" if outcome.status == "interrupted" else ""
    if "DUE TO TIME LIMIT" in text:
        return Outcome("timeout", f"job {job.job_id} exceeded --slurm-time {args.slurm_time} min{saved}", path)
    if re.search(r"CANCELLED AT .* \*\*\*", text) and outcome.status != "completed":
        status = "interrupted" if outcome.status == "interrupted" else "cancelled"
        return Outcome(status, f"job {job.job_id} was cancelled{saved}", path)
    if outcome.status == "failed" and not codes:
        outcome.detail = f"job {job.job_id} ended before its run did ({outcome.detail})"
    return outcome


def run_slurm(args: Args, todo: list[Run], stop: Stop) -> dict[Run, Outcome]:
    import cloudpickle
    import submitit

    threads = run_threads(args)
    if __name__ != "__main__":  # imported (tests): ship slurm_job itself, the nodes need not import this module
        cloudpickle.register_pickle_by_value(sys.modules[__name__])
    executor = submitit.SlurmExecutor(folder=os.path.join(args.logs_dir, "slurm"))
    executor.update_parameters(
        job_name=args.exp_name,
        time=args.slurm_time,
        cpus_per_task=args.slurm_cpus_per_task,
        partition=args.slurm_partition,
        use_srun=False,  # the python runs in the batch step itself, with all the job's CPUs
        additional_parameters={"mem": args.slurm_mem} if args.slurm_mem else {},
    )
    cwd = os.getcwd()
    since = time.time()
    try:
        with executor.batch():
            submitted = [executor.submit(slurm_job, command(args, run, threads), cwd) for run in todo]
    except submitit.core.utils.FailedJobError as e:
        lines = [line for line in str(e).splitlines() if line.strip()]
        print(f"error: sbatch refused the job array: {lines[-1] if lines else e}", file=sys.stderr)
        sys.exit(1)
    jobs = dict(zip(todo, submitted, strict=True))
    array_id = next(iter(jobs.values())).job_id.split("_")[0]
    print(f"submitted {len(jobs)} run(s) of {args.script} as Slurm job array {array_id} "
          f"(partition {args.slurm_partition or 'default'}, {args.slurm_time} min, {args.slurm_cpus_per_task} CPU(s) "
          f"each); logs in {executor.folder}", flush=True)  # fmt: skip

    outcomes: dict[Run, Outcome] = {}
    cancelled, last, gone_since = 0.0, "", {}
    while len(outcomes) < len(jobs):
        if stop.signum and not cancelled:
            print(f"cancelling Slurm job array {array_id}", flush=True)
            subprocess.run(["scancel", array_id], check=False)
            cancelled = time.time()
        if cancelled and (stop.count > 1 or time.time() - cancelled > 300):  # a second signal, or Slurm is stuck
            for run, job in jobs.items():
                outcomes.setdefault(run, Outcome("cancelled", f"job {job.job_id}: not waited for after scancel"))
            break
        states = squeue_states([j.job_id for j in jobs.values()])
        if states is None:
            print("warning: squeue failed; trying again", file=sys.stderr, flush=True)
        else:
            for run, job in jobs.items():
                if run in outcomes or job.job_id in states:
                    continue
                # left the queue: give slurmstepd's last lines and the run's summary a moment to land
                gone_since.setdefault(run, time.time())
                if time.time() - gone_since[run] >= min(args.poll_seconds, 2.0):
                    outcome = slurm_outcome(args, run, job, since)
                    if cancelled and outcome.status == "failed" and "ended before" in outcome.detail:
                        outcome = Outcome("not started", f"job {job.job_id} cancelled", outcome.stderr_path)
                    outcomes[run] = outcome
                    print(f"{run}: {outcome.status} (job {job.job_id}, stderr: {outcome.stderr_path})", flush=True)
                    if outcome.status == "completed":
                        keep(args, run, since)
            pending = sum(states.get(job.job_id) == "PENDING" for job in jobs.values())
            completed = sum(o.status == "completed" for o in outcomes.values())
            progress = (
                f"slurm {array_id}: {pending} pending, {len(jobs) - len(outcomes) - pending} running, "
                f"{completed} done, {len(outcomes) - completed} failed or stopped"
            )
            if progress != last:
                print(f"[{time.strftime('%H:%M:%S')}] {progress}", flush=True)
                last = progress
        if len(outcomes) < len(jobs):
            time.sleep(args.poll_seconds)
    return outcomes


# --------------------------------------------------------------------------------------------------------------
# The table.


def aggregate(summaries: list[dict]) -> dict[str, dict]:
    """Mean, sample std and n of every numeric key the summaries share."""
    table = {}
    for key in sorted(summaries[0]):
        values = [s[key] for s in summaries if isinstance(s.get(key), int | float) and not isinstance(s[key], bool)]
        values = [v for v in values if math.isfinite(v)]
        if not values or key == "seed":
            continue
        mean = sum(values) / len(values)
        std = math.sqrt(sum((v - mean) ** 2 for v in values) / (len(values) - 1)) if len(values) > 1 else 0.0
        table[key] = {"mean": mean, "std": std, "n": len(values), "values": values}
    return table


def main(args: Args) -> dict[str, dict]:
    """Run what has not finished, print and save one table per grid point; returns {grid point label: table}
    ("" without a grid). Exits 1 if a run did not finish, 128 + the signal if stopped by one."""
    points = grid_points(args.grid, args.script_args)
    runs = [Run(seed, point) for point in points for seed in args.seeds]
    todo = [run for run in runs if newest_summary(args, run) is None]
    done = [run for run in runs if run not in todo]
    if done:
        print(f"already finished, not run again: {', '.join(map(str, done))}", flush=True)

    outcomes: dict[Run, Outcome] = {}
    stop = Stop()
    with stop.installed():
        if todo:
            outcomes = (run_slurm if args.launcher == "slurm" else run_local)(args, todo, stop)

    not_done = {run: o for run, o in outcomes.items() if o.status != "completed"}
    for run, outcome in not_done.items():
        print(f"{run}: {outcome.status}" + (f": {outcome.detail}" if outcome.detail else ""))
        if outcome.status == "failed" and outcome.stderr_path:
            print(f"  last lines of {outcome.stderr_path}:")
            for line in tail(outcome.stderr_path):
                print(f"    {line}")

    tables, saved = {}, []
    for point in points:
        paths = {}
        for seed in args.seeds:
            found = newest_summary(args, Run(seed, point))
            paths[seed] = found[0] if found else None
        summaries = [read_json(path) for path in filter(None, paths.values())]
        label = Run(0, point).label
        missing = [s for s, p in paths.items() if p is None]
        if not summaries:
            print(f"\n{args.exp_name}{f' [{label}]' if label else ''}: no run finished")
            continue
        tables[label] = table = aggregate(summaries)
        print(
            f"\n{args.exp_name}{f' [{label}]' if label else ''}: {len(summaries)} of {len(args.seeds)} seeds finished"
            + (f", missing {missing}" if missing else "")
        )
        print("| key | mean | std | n |\n| --- | --- | --- | --- |")
        for key, row in table.items():
            print(f"| {key} | {row['mean']:.4g} | {row['std']:.3g} | {row['n']} |")
        saved.append({"point": dict(point), "runs": paths, "table": table})

    if saved:
        out = os.path.join(args.runs_dir, f"{args.exp_name}__table.json")
        record = {"script": args.script, "seeds": args.seeds, "grid": args.grid, "points": saved}
        if not args.grid:
            record.update(runs=saved[0]["runs"], table=saved[0]["table"])
        with open(out + ".tmp", "w") as f:
            json.dump(record, f, indent=2)
        os.replace(out + ".tmp", out)
        print(f"table written to {out}")

    if stop.signum:
        print(f"error: stopped by {signal.Signals(stop.signum).name}; {len(not_done)} run(s) not finished, run the "
              "same command again to resume them", file=sys.stderr)  # fmt: skip
        sys.exit(128 + stop.signum)
    if not_done:
        by_status = {}
        for run, outcome in not_done.items():
            by_status.setdefault(outcome.status, []).append(str(run))
        print(f"error: {len(not_done)} of {len(runs)} run(s) did not finish ("
              + "; ".join(f"{s}: {', '.join(r)}" for s, r in by_status.items())
              + "); run the same command again to rerun them", file=sys.stderr)  # fmt: skip
        sys.exit(1)
    if not saved:
        print(f"error: no run of {args.exp_name} finished; see the logs in {args.logs_dir}", file=sys.stderr)
        sys.exit(1)
    return tables


# an experiment name is part of each run's directory name: one path component, short enough for any file system
EXP_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._+=-]{0,99}")


def validate(args: Args) -> None:
    if not EXP_NAME.fullmatch(args.exp_name):
        raise ValueError(f"--exp-name {args.exp_name[:120]!r}: use 1-100 letters, digits and ._+=- (no / or ..), "
                         "starting with a letter or digit")  # fmt: skip
    if args.workers < 1 or args.threads < 0 or not args.seeds:
        raise ValueError("--workers must be >= 1, --threads >= 0, and --seeds non-empty")
    if not args.keep_max_mb > 0:
        raise ValueError(f"--keep-max-mb must be > 0, got {args.keep_max_mb}")
    if args.results_dir is not None and os.path.exists(args.results_dir) and not os.path.isdir(args.results_dir):
        raise ValueError(f"--results-dir {args.results_dir}: exists and is not a directory")
    if args.results_dir is not None:
        check_writable(args.results_dir, "--results-dir")
    if not os.path.isfile(args.script):
        raise ValueError(f"{args.script}: no such script")
    given = set(flag_values(args.script_args))
    if given & {"seed", "exp-name", "num-threads"}:
        raise ValueError(f"--{sorted(given & {'seed', 'exp-name', 'num-threads'})[0]} after -- is set by run_seeds "
                         "itself (--seeds, --exp-name, --threads)")  # fmt: skip
    if os.path.realpath(args.runs_dir) != os.path.realpath("runs"):
        raise ValueError(f"--runs-dir {args.runs_dir}: the scripts write their runs to runs/ in the working directory; "
                         "run run_seeds from the directory whose runs/ you mean")  # fmt: skip
    for point in grid_points(args.grid, args.script_args):  # each flag and value the script takes, before any run
        campaign_args(args, point)
    if args.launcher == "slurm":
        if args.slurm_time < 1 or args.slurm_cpus_per_task < 1 or not args.poll_seconds > 0:
            raise ValueError("--slurm-time and --slurm-cpus-per-task must be >= 1, --poll-seconds > 0")
        if args.slurm_mem is not None and not re.fullmatch(r"\d+[KMGT]?", args.slurm_mem):
            raise ValueError(f"--slurm-mem {args.slurm_mem!r}: expected a size like 4G or 500M")
        check_slurm(args)


if __name__ == "__main__":
    try:
        args = tyro.cli(Args)  # a malformed flag: tyro's own message, exit 2
        validate(args)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    main(args)
