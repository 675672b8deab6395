"""No number moves: tiny runs of every script and its main flag families, and every night of the sleep study, reduced
to their numbers, so that a refactor can show it changed none of them, bit for bit.

Each case is a command of one script (or of the sleep study's night runners) with a tiny budget. What a case yields is
every number of its summary.json (times and speeds left out) and, per saved network file, the sorted digests of its
tensors (independent of the tensors' names); or the JSON an evaluation prints (--evaluate at BASE,
inform_utils.evaluate_policy now); or an oracle checkpoint's evaluation and tensors. tests/snapshot_values.json holds
the values that the code of commit BASE gave on a machine whose CPU signature it records:

    python tests/snapshot.py --write --code-dir DIR     # DIR: a checkout of BASE (git archive BASE | tar -x -C DIR)

tests/test_snapshot.py runs the cases with the current code and compares. On a CPU with another signature (another
vector unit gives other last bits after the first gradient step) it recomputes the reference with BASE's code from
git instead of reading the file.
"""

import argparse
import hashlib
import json
import math
import os
import platform
import subprocess

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BASE = "cdfc757"  # the code before the core scripts were cut down to CleanRL's shape
VALUES = os.path.join(REPO, "tests", "snapshot_values.json")
# a flag renamed since BASE: old name -> new name (the value is kept). Filled in by a change that renames a flag.
RENAMED: dict[str, str] = {}
# Pusher-v5's values were recorded under MuJoCo 4's own contact: a flag since the 2.3 contact became the default
GYMNASIUM_CONTACT = ["--contact", "gymnasium"]

PUSHER = "inform_sac_pusher.py"
MAZE = "inform_dqn_gridworld.py"
PUSHER_NIGHT_RUNNER = ["-m", "inform_utils.sleep_variants_pusher"]
MAZE_NIGHT_RUNNER = ["-m", "inform_utils.sleep_variants_maze"]
# every episode counts as a success (--success-distance 1), so the tiny day has an expert set
PUSHER_DAY = ["--tamer-total-timesteps", "600", "--tamer-learning-starts", "300", "--tamer-batch-size", "64",
              "--success-distance", "1.0"]  # fmt: skip
PUSHER_NIGHT = ["--sleep-gradient-steps", "100", "--sleep-batch-size", "64", "--eval-episodes", "1",
                "--obstacle-episodes", "2", "--authors-test-episodes", "2"]  # fmt: skip
# the v5 teacher the values were recorded with (the default teacher since 2026-12-04 is another one)
V5_TEACHER = ["--oracle-path", os.path.join(REPO, "oracles", "Pusher-v5__sac_oracle_890k_below_bar.pt")]
MAZE_TINY = ["--tamer-total-timesteps", "2000", "--tamer-learning-starts", "500", "--sleep-gradient-steps", "200"]
TEACHER = ["--teacher-noise", "0.1", "--teacher-sparsity", "0.7", "--teacher-delay", "2", "--credit-window", "3"]

# the sleep study's variants (inform_utils/sleep_study.py at BASE), each night with the study's 15% hold-out
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
}
# --sleep-protocol authors at BASE forced 100k steps; at a tiny budget it is the flags it set
AUTHORS = ["--no-sleep-init-actor-from-tamer", "--sleep-actor-states", "replay+expert", "--sleep-policy-frequency", "2"]
MAZE_VARIANTS = {
    "default": [],
    "sham": ["--sleep-control", "sham"],
    "bc": ["--sleep-control", "bc"],
    "expert_rows": ["--sleep-loss-rows", "expert"],
    "temperature0.01": ["--sleep-temperature", "0.01"],
}


def case(name, script, *flags, new=None, needs=None, python="main", stdin=None, output="run"):
    """A command; `new` is the command's form since the refactor when it differs (script and flags), `needs` a case
    whose run directory {day} (or file {file}) it uses, `output` what it yields: "run" (a run directory), "json"
    (an evaluation's stdout), or the name of a checkpoint file it writes."""
    old = [script, *flags]
    return {"name": name, "old": old, "new": new or old, "needs": needs, "python": python, "stdin": stdin,
            "output": output}  # fmt: skip


CASES = [
    case("pusher_day", PUSHER, *PUSHER_DAY, *PUSHER_NIGHT, *V5_TEACHER, "--save-buffer"),
    case(
        "pusher_teachers",
        PUSHER,
        "--seed",
        "2",
        *PUSHER_DAY,
        *PUSHER_NIGHT,
        *TEACHER,
        *V5_TEACHER,
        "--feedback-budget",
        "100",
    ),  # fmt: skip
    case(
        "pusher_budget_ends_random_starts",
        PUSHER,
        "--seed",
        "3",
        *PUSHER_DAY,
        *PUSHER_NIGHT,
        "--random-starts",
        "--feedback-budget",
        "40",
        "--budget-ends-forward-phase",
        *V5_TEACHER,
    ),  # fmt: skip
    case("pusher_night_core", PUSHER, "--sleep-from", "{day}", *PUSHER_NIGHT, "--sleep-seed", "1", needs="pusher_day"),
    case(
        "pusher_night_authors_preset",
        PUSHER,
        "--sleep-from",
        "{day}",
        *PUSHER_NIGHT,
        "--sleep-seed",
        "1",
        *AUTHORS,
        new=[
            PUSHER,
            "--sleep-from",
            "{day}",
            *PUSHER_NIGHT,
            "--sleep-seed",
            "1",
            "--sleep-protocol",
            "authors",
            "--sleep-gradient-steps",
            "100",
        ],
        needs="pusher_day",
    ),  # fmt: skip
    *[
        case(
            f"pusher_study_{variant}",
            PUSHER,
            "--sleep-from",
            "{day}",
            *PUSHER_NIGHT,
            "--sleep-seed",
            "1",
            "--sleep-holdout-fraction",
            "0.15",
            *flags,
            needs="pusher_day",
            new=[
                *PUSHER_NIGHT_RUNNER,
                "--sleep-from",
                "{day}",
                *PUSHER_NIGHT,
                "--sleep-seed",
                "1",
                "--sleep-holdout-fraction",
                "0.15",
                *flags,
            ],
        )  # fmt: skip
        for variant, flags in {**PUSHER_VARIANTS, "authors": AUTHORS}.items()
    ],
    case(
        "pusher_evaluate_random_starts",
        PUSHER,
        "--seed",
        "1",
        "--evaluate",
        "{day}/inform_actor.pt",
        "--random-starts",
        "--eval-episodes",
        "3",
        "--obstacle-episodes",
        "1",
        needs="pusher_day",
        output="json",
        new=[
            "-m",
            "inform_utils.evaluate_policy",
            "pusher",
            "{day}/inform_actor.pt",
            "--seed",
            "1",
            "--random-starts",
            "--eval-episodes",
            "3",
            "--obstacle-episodes",
            "1",
        ],
    ),  # fmt: skip
    case("pusher_v4_day", PUSHER, "--env-id", "Pusher-v4", *PUSHER_DAY, *PUSHER_NIGHT, python="v4"),
    case(
        "reacher_shipped_teacher",
        PUSHER,
        "--env-id",
        "Reacher-v5",
        "--success-distance",
        "0.02",
        "--random-starts",
        *PUSHER_DAY[:6],
        *PUSHER_NIGHT[:6],
    ),  # fmt: skip
    case(
        "pendulum_teacher_trained_here",
        PUSHER,
        "--env-id",
        "InvertedPendulum-v5",
        "--train-oracle",
        "--oracle-total-timesteps",
        "5300",
        "--success-return",
        "0",
        *PUSHER_DAY[:6],
        *PUSHER_NIGHT[:6],
    ),  # fmt: skip
    case("maze_day", MAZE, *MAZE_TINY, "--save-buffer"),
    case("maze_teachers", MAZE, "--seed", "2", *MAZE_TINY, *TEACHER, "--feedback-budget", "60"),
    case("maze_budget_ends", MAZE, "--seed", "3", *MAZE_TINY, "--feedback-budget", "40", "--budget-ends-forward-phase"),
    case(
        "maze_human_scripted",
        MAZE,
        "--teacher",
        "human",
        "--tamer-total-timesteps",
        "60",
        "--sleep-gradient-steps",
        "100",
        stdin="y\n\ny\ny\n\n" * 10 + "q\n",
    ),  # fmt: skip
    case("maze_night_core", MAZE, "--sleep-from", "{day}", *MAZE_TINY, "--sleep-seed", "1", needs="maze_day"),
    *[
        case(
            f"maze_study_{variant}",
            MAZE,
            "--sleep-from",
            "{day}",
            *MAZE_TINY,
            "--sleep-seed",
            "1",
            *flags,
            needs="maze_day",
            new=[*MAZE_NIGHT_RUNNER, "--sleep-from", "{day}", *MAZE_TINY, "--sleep-seed", "1", *flags],
        )  # fmt: skip
        for variant, flags in MAZE_VARIANTS.items()
    ],
    case(
        "maze_evaluate",
        MAZE,
        "--evaluate",
        "{day}/inform_q.pt",
        needs="maze_day",
        output="json",
        new=["-m", "inform_utils.evaluate_policy", "maze", "{day}/inform_q.pt"],
    ),
    case("maze_learned_teacher", MAZE, "--oracle-path", "{file}", *MAZE_TINY, needs="oracle_train_maze_q_learning"),
    case(
        "toy_frozenlake",
        MAZE,
        "--env-id",
        "FrozenLake-v1",
        "--success-max-steps",
        "100",
        "--tamer-total-timesteps",
        "3000",
        "--sleep-gradient-steps",
        "500",
        "--eval-episodes",
        "5",
    ),  # fmt: skip
    case(
        "toy_cliffwalking",
        MAZE,
        "--env-id",
        "CliffWalking-v1",
        "--tamer-total-timesteps",
        "3000",
        "--sleep-gradient-steps",
        "300",
        "--eval-episodes",
        "3",
    ),  # fmt: skip
    case(
        "oracle_train_maze_value_iteration",
        "oracle_train.py",
        "--env-id",
        "KnoxStoneMaze-v0",
        "--output-path",
        "vi.pt",
        output="vi.pt",
    ),  # fmt: skip
    case(
        "oracle_train_maze_q_learning",
        "oracle_train.py",
        "--env-id",
        "KnoxStoneMaze-v0",
        "--method",
        "q-learning",
        "--maze-episodes",
        "20",
        "--output-path",
        "ql.pt",
        output="ql.pt",
    ),  # fmt: skip
    case(
        "oracle_train_maze_dqn",
        "oracle_train.py",
        "--env-id",
        "KnoxStoneMaze-v0",
        "--method",
        "dqn",
        "--maze-dqn-timesteps",
        "3000",
        "--output-path",
        "dqn.pt",
        output="dqn.pt",
    ),  # fmt: skip
    case(
        "oracle_train_pusher_sac",
        "oracle_train.py",
        "--env-id",
        "Pusher-v5",
        "--total-timesteps",
        "5600",
        "--eval-frequency",
        "5500",
        "--eval-episodes",
        "2",
        "--final-eval-episodes",
        "2",
        "--output-path",
        "sac.pt",
        output="sac.pt",
    ),  # fmt: skip
    case(
        "qlearn_recovered_reward",
        "q_learning_recovered_reward.py",
        "--reward-path",
        "{day}",
        "--num-episodes",
        "15",
        "--num-seeds",
        "2",
        "--seed",
        "3",
        needs="maze_day",
    ),  # fmt: skip
    case(
        "qlearn_recovered_reward_max_table",
        "q_learning_recovered_reward.py",
        "--reward-path",
        "{day}",
        "--reward-source",
        "table",
        "--bootstrap",
        "max",
        "--num-episodes",
        "15",
        "--num-seeds",
        "2",
        needs="maze_day",
    ),  # fmt: skip
]
BY_NAME = {c["name"]: c for c in CASES}


def cpu_signature() -> str:
    """What decides the last bits of a float computation here: the machine, torch's vector unit, the CPU model."""
    import torch

    model = ""
    if os.path.isfile("/proc/cpuinfo"):
        with open("/proc/cpuinfo") as f:
            model = next((line.split(":", 1)[1].strip() for line in f if line.startswith("model name")), "")
    return f"{platform.machine()} {torch.backends.cpu.get_cpu_capability()} {model}"


def number(value):
    """A JSON number as an exact string (NaN and infinities too); None for what is not a number."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return repr(float(value)) if isinstance(value, float) and not math.isfinite(value) else repr(value)


def numbers(data: dict, skip=("time/", "sps/", "wall_time_s", "charts/SPS", "args", "seed_streams")) -> dict:
    return {k: number(v) for k, v in sorted(data.items()) if not k.startswith(skip) and number(v) is not None}


def tensor_digests(path: str) -> list[str]:
    """The sorted sha256 digests of every tensor in a weights-only checkpoint (names play no part)."""
    import torch

    digests = []

    def walk(obj):
        if isinstance(obj, torch.Tensor):
            t = obj.detach().cpu().contiguous()
            digests.append(hashlib.sha256(str(t.dtype).encode() + str(tuple(t.shape)).encode() +
                                          t.view(-1).view(torch.uint8).numpy().tobytes()).hexdigest()[:16])  # fmt: skip
        elif isinstance(obj, dict):
            for value in obj.values():
                walk(value)
        elif isinstance(obj, list | tuple):
            for value in obj:
                walk(value)

    walk(torch.load(path, weights_only=True))
    return sorted(digests)


NETWORK_FILES = ("tamer_actor.pt", "tamer_h.pt", "inform_actor.pt", "inform_q.pt", "tamer_q.pt", "recovered_reward.pt",
                 "inform_selected_actor.pt", "oracle.pt")  # fmt: skip


def run_case(c: dict, code_dir: str, cwd: str, python: str, done: dict, form: str) -> dict:
    """Run case c with the code in code_dir, in the working directory cwd; `done` maps a case's name to its run
    directory or file (for the cases that need it). Returns the case's values."""
    needed = done.get(c["needs"], "")
    cmd = [arg.replace("{day}", needed).replace("{file}", needed) for arg in c[form]]
    if form == "new":
        pusher = c["name"].startswith("pusher_") or "Pusher-v5" in cmd
        cmd = [RENAMED.get(arg, arg) for arg in cmd] + (GYMNASIUM_CONTACT if pusher else [])
    if cmd[0] != "-m":
        cmd[0] = os.path.join(code_dir, cmd[0])
    env = {**os.environ, "PYTHONPATH": code_dir, "OMP_NUM_THREADS": "1"}
    env.setdefault("MUJOCO_GL", "egl")
    proc = subprocess.run([python, *cmd], cwd=cwd, env=env, input=c["stdin"], capture_output=True, text=True,
                          timeout=900)  # fmt: skip
    if proc.returncode != 0:
        raise RuntimeError(f"{c['name']} ({' '.join(cmd)}) exited {proc.returncode}: {proc.stderr[-2000:]}")
    if c["output"] == "json":
        return numbers(json.loads(proc.stdout[proc.stdout.index("{") :]))
    if c["output"] != "run":
        path = os.path.join(cwd, c["output"])
        done[c["name"]] = path
        import torch

        evaluation = torch.load(path, weights_only=True).get("evaluation", {})
        return {"evaluation": numbers(evaluation), "tensors": tensor_digests(path)}
    line = next(x for x in proc.stdout.splitlines() if x.startswith("run directory:"))
    run_dir = os.path.join(cwd, line.split(": ", 1)[1])
    done[c["name"]] = run_dir
    with open(os.path.join(run_dir, "summary.json")) as f:
        summary = json.load(f)
    assert summary.get("status", "completed") == "completed", (c["name"], summary.get("status"))
    files = {name: tensor_digests(os.path.join(run_dir, name)) for name in NETWORK_FILES
             if os.path.isfile(os.path.join(run_dir, name))}  # fmt: skip
    return {"summary": numbers(summary), "files": files}


def pythons(code_dir: str) -> dict:
    return {"main": os.path.join(REPO, ".venv", "bin", "python"), "v4": os.path.join(REPO, ".venv-v4", "bin", "python")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--write", action="store_true", help="write tests/snapshot_values.json")
    parser.add_argument("--code-dir", required=True, help="a checkout of BASE's code")
    parser.add_argument("--work-dir", default="/tmp/snapshot_work", help="where the runs go")
    parser.add_argument("--only", nargs="*", help="case names (default: all)")
    args = parser.parse_args()
    os.makedirs(args.work_dir, exist_ok=True)
    values, done = {}, {}
    if os.path.isfile(VALUES):
        with open(VALUES) as f:
            values = json.load(f).get("cases", {})

    def record(c: dict) -> None:  # the case it needs first (a case may need one listed after it)
        if c["needs"] and c["needs"] not in done:
            record(BY_NAME[c["needs"]])
        cwd = os.path.join(args.work_dir, c["name"])
        os.makedirs(cwd, exist_ok=True)
        print(f"[snapshot] {c['name']}", flush=True)
        values[c["name"]] = run_case(c, args.code_dir, cwd, pythons(args.code_dir)[c["python"]], done, "old")

    for c in CASES:
        if not args.only or c["name"] in args.only:
            record(c)
    if args.write:
        out = {"base": BASE, "cpu": cpu_signature(), "cases": values}
        with open(VALUES + ".tmp", "w") as f:
            json.dump(out, f, indent=1, sort_keys=True)
        os.replace(VALUES + ".tmp", VALUES)
        print(f"wrote {VALUES}: {len(values)} cases")


if __name__ == "__main__":
    main()
