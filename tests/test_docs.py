"""The docs name only flags the scripts take. For README.md and every docs/*.md but the history pages (results.md,
teacher_notes.md: their commands ran on the code of their day), each command line `python X.py ...` or
`python -m inform_utils.Y ...` (in a code block, lines joined across `\\`, or in backticks in the prose) passes its
script only flags of that script's Args; the flags after `--` of run_seeds and sleep_study, and --grid's names, are
checked against the script they go to. Every other backticked `--flag` must be a flag of at least one of them. The
flags come from the Args dataclasses themselves, as tyro spells them (a_b: --a-b; a bool also --no-a-b)."""

import dataclasses
import fnmatch
import functools
import glob
import importlib
import importlib.util
import os
import re
import sys
import typing

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
HISTORY = {"results.md", "teacher_notes.md"}  # what ran then, with the flags of then
# a flag a page names as gone on purpose: (page, flag), each with the reason
OLD_NAMES = {
    ("docs/pusher_notes.md", "--tamer-q-lr"): "its list of changes: `--tamer-q-lr` is now `--tamer-h-lr`",
    **{("docs/shape.md", hack): "a hack's flag, made on a copy (tests/test_day_hack.py, tests/test_night_hack.py)"
       for hack in ("--teacher-negative-beta", "--tamer-layer-norm", "--sleep-q-l2-coef")},
}  # fmt: skip
# the programs the docs run: the scripts, the helpers (python -m) and the benchmarks, by how a command names them
MODULES = {
    "inform_sac_pusher.py": "inform_sac_pusher",
    "inform_dqn_gridworld.py": "inform_dqn_gridworld",
    "oracle_train.py": "oracle_train",
    "q_learning_recovered_reward.py": "q_learning_recovered_reward",
    **{
        f"inform_utils.{name}": f"inform_utils.{name}"
        for name in (os.path.basename(p)[:-3] for p in glob.glob(os.path.join(REPO, "inform_utils", "*.py")))
        if name != "__init__"
    },
}
FILES = {"benchmarks/benchmark.py", "benchmarks/compile_sleep.py"}  # tyro scripts, not importable as modules
NO_ARGS = {
    "browser_teacher.py",
    "inform_utils.files",
    "inform_utils.recovered_reward",
    "inform_utils.videos",
    "inform_utils.pusher_contact",  # a measurement with no flags
    "inform_utils.pusher_mpc",  # a library: run by pusher_control --demonstrator mpc
    "inform_utils.demos",  # a library: read by oracle_train --demos
}  # libraries
STOP_TIMES = "benchmarks/stop_times.py"  # stop_times.py N SCRIPT FLAGS...: the flags are SCRIPT's
SHELL_SPLIT = re.compile(r"&&|\|\||[;|()]")
PYTHON = re.compile(r"^(?:\S*/)?python3?(?:\.\d+)?$")
FLAG = re.compile(r"^--(\[no-\])?([a-z0-9][a-z0-9*-]*)")


def flags_of(args_type) -> set[str]:
    """The flags tyro makes of an Args dataclass: --a-b for a_b, --no-a-b too for a bool, none for a positional."""
    hints = typing.get_type_hints(args_type, include_extras=True)
    flags = {"--help", "-h"}
    for f in dataclasses.fields(args_type):
        tp = hints[f.name]
        meta = getattr(tp, "__metadata__", ())
        if any("Positional" in repr(m) for m in meta):
            continue
        name = f.name.replace("_", "-")
        flags.add(f"--{name}")
        if (typing.get_args(tp)[0] if meta else tp) is bool:
            flags.add(f"--no-{name}")
    return flags


@functools.cache
def program_flags(program: str) -> set[str] | None:
    """The flags of a program, set() if it takes none, None if it is not one of the repository's."""
    if program in NO_ARGS:
        return set()
    if program in FILES:
        spec = importlib.util.spec_from_file_location(f"_docs_{os.path.basename(program)[:-3]}", f"{REPO}/{program}")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return flags_of(module.Args)
    if program in MODULES:
        if REPO not in sys.path:
            sys.path.insert(0, REPO)
        module = importlib.import_module(MODULES[program])
        if hasattr(module, "SUBCOMMANDS"):  # python -m inform_utils.evaluate_policy pusher|maze ...: any one's flags
            return set().union(*map(flags_of, module.SUBCOMMANDS.values()))
        return flags_of(module.Args)
    return None


def every_flag() -> set[str]:
    known = set()
    for program in [*MODULES, *FILES]:
        known |= program_flags(program)
    return known


def program_name(token: str, after_m: bool) -> str | None:
    """The program a command runs: `-m inform_utils.x`, or a .py path (./x.py, /tmp/copy/x.py, benchmarks/x.py)."""
    if after_m:
        return token
    token = token.removeprefix("./")
    for name in [*MODULES, *FILES, *NO_ARGS, STOP_TIMES]:
        if name.endswith(".py") and (token == name or token.endswith("/" + name)):
            return name
    if token.startswith("inform_utils/") and token.endswith(".py"):
        return "inform_utils." + token[len("inform_utils/") : -3]
    return token if token.endswith(".py") else None


def find_command(segment: str) -> tuple[str, list[str]] | None:
    """(program, its arguments) of one shell command, or None: `python [-m] PROGRAM ...` anywhere in it (as inside
    sbatch --wrap "..."), or a command that starts with a script of the repository (env assignments before it)."""
    # a quoted --flag=value with spaces in it ("--flags=--a 1 --b 2") is one token: a value, not flags
    segment = re.sub(r"[\"'](--[\w-]+=[^\"']*)[\"']", lambda m: m.group(1).replace(" ", "\x00"), segment)
    tokens = [t.strip("\"'") for t in segment.split()]
    tokens = [t for t in tokens if t]
    for i, token in enumerate(tokens):
        if PYTHON.match(token) and i + 1 < len(tokens):
            after_m = tokens[i + 1] == "-m"
            j = i + 2 if after_m else i + 1
            if j < len(tokens):
                name = program_name(tokens[j], after_m)
                return (name, tokens[j + 1 :]) if name else None
            return None
    while tokens and re.match(r"^[A-Z_][A-Z0-9_]*=", tokens[0]):
        tokens = tokens[1:]
    if tokens:
        name = program_name(tokens[0], False)
        if name and (name in MODULES or name in FILES or name in NO_ARGS or name == STOP_TIMES):
            return name, tokens[1:]
    return None


def flag_names(token: str) -> list[str]:
    """The flags a token names: --a-b, --a-b=v; --[no-]a-b is both; --tamer-* a pattern."""
    m = FLAG.match(token)
    if not m:
        return []
    return [f"--{m.group(2)}", f"--no-{m.group(2)}"] if m.group(1) else [f"--{m.group(2)}"]


def known(flag: str, flags: set[str]) -> bool:
    return any(fnmatch.fnmatchcase(f, flag) for f in flags) if "*" in flag else flag in flags


def value_of(tokens: list[str], flag: str, default: str) -> str:
    for i, token in enumerate(tokens):
        if token == flag and i + 1 < len(tokens):
            return tokens[i + 1]
        if token.startswith(flag + "="):
            return token.split("=", 1)[1]
    return default


def check_command(program: str, tokens: list[str]) -> list[str]:
    """What is wrong with one command line: each flag its program does not take, as "FLAG is not a flag of P"."""
    if program == STOP_TIMES:  # stop_times.py N SCRIPT FLAGS...
        target = find_command(" ".join(tokens[1:]))
        return check_command(*target) if target else []
    flags = program_flags(program)
    if flags is None:
        if re.fullmatch(r"inform_utils\.\w+", program) or (
            program.endswith(".py") and not os.path.isabs(program) and not os.path.exists(os.path.join(REPO, program))
        ):
            return [f"{program} is not in the repository"]
        return []  # pytest, pip, ...: not ours
    own, rest = (tokens[: tokens.index("--")], tokens[tokens.index("--") + 1 :]) if "--" in tokens else (tokens, [])
    wrong = [f"{f} is not a flag of {program}" for t in own for f in flag_names(t) if not known(f, flags)]
    forwarded = None
    if program == "inform_utils.run_seeds":
        default = importlib.import_module(MODULES[program]).Args.script
        forwarded = program_name(value_of(own, "--script", default), False)
        for i, token in enumerate(own):
            spec = own[i + 1] if token == "--grid" and i + 1 < len(own) else token.removeprefix("--grid=")
            if (token == "--grid" or token.startswith("--grid=")) and "=" in spec:
                name = "--" + spec.split("=")[0].removeprefix("--").replace("_", "-")
                if not known(name, program_flags(forwarded) or {name}):
                    wrong.append(f"--grid {name[2:]}: {name} is not a flag of {forwarded}")
    elif program == "inform_utils.sleep_study":
        study = importlib.import_module(MODULES[program])
        forwarded = study.STUDIES[value_of(own, "--script", study.Args.script)].runner
    if rest and forwarded:
        wrong += [f"{m} (after --)" for m in check_command(forwarded, rest)]
    return wrong


def markdown_files() -> list[str]:
    docs = sorted(glob.glob(os.path.join(REPO, "docs", "*.md")))
    return [os.path.join(REPO, "README.md"), *(p for p in docs if os.path.basename(p) not in HISTORY)]


def commands_and_spans(text: str):
    """(line, kind, text): each logical line of a fenced block as "block", each backticked span of the prose as
    "span" (a span may run over a line break)."""
    prose, block, start = [], None, 0
    lines = text.split("\n")
    for n, line in enumerate(lines, 1):
        if line.lstrip().startswith("```"):
            block = [] if block is None else None
            prose.append("")
            continue
        if block is None:
            prose.append(line)
            continue
        prose.append("")
        if not block:
            start = n
        block.append(line)
        if not line.rstrip().endswith("\\"):
            yield start, "block", " ".join(b.rstrip().removesuffix("\\") for b in block)
            block.clear()
    joined = "\n".join(prose)
    for m in re.finditer(r"(?<!`)`([^`]+)`(?!`)", joined):
        yield joined.count("\n", 0, m.start()) + 1, "span", " ".join(m.group(1).split())


def doc_problems(path: str, everything: set[str]) -> list[str]:
    with open(path) as f:
        text = f.read()
    problems = []
    for line, kind, content in commands_and_spans(text):
        where = f"{os.path.relpath(path, REPO)}:{line}"
        commands = [c for c in (find_command(s.split(" #")[0]) for s in SHELL_SPLIT.split(content)) if c]
        for program, tokens in commands:
            problems += [f"{where}: {m}" for m in check_command(program, tokens)]
        if kind == "span" and not commands and content.startswith("--"):
            for flag in (f for t in content.split() for f in flag_names(t)):
                if not known(flag, everything) and (os.path.relpath(path, REPO), flag) not in OLD_NAMES:
                    problems.append(f"{where}: {flag} is a flag of none of the scripts")
    return sorted(problems, key=lambda p: int(p.split(":")[1]))  # by line: the blocks' and the spans' together


def test_the_docs_name_only_flags_the_scripts_take():
    everything = every_flag()
    problems = [p for path in markdown_files() for p in doc_problems(path, everything)]
    assert not problems, "\n" + "\n".join(problems)


def test_the_check_sees_a_wrong_flag():
    everything = every_flag()
    assert check_command("inform_dqn_gridworld.py", ["--seed", "1", "--num-threads", "2"]) == [
        "--num-threads is not a flag of inform_dqn_gridworld.py"
    ]
    assert check_command("inform_utils.run_seeds", ["--seeds", "1", "--", "--no-such-flag"]) == [
        "--no-such-flag is not a flag of inform_dqn_gridworld.py (after --)"
    ]
    assert check_command("inform_utils.run_seeds", ["--script", "inform_sac_pusher.py", "--grid", "tau=0.1"]) == [
        "--grid tau: --tau is not a flag of inform_sac_pusher.py"
    ]
    assert check_command("inform_utils.sleep_study", ["--days", "d", "--", "--sleep-control", "sham"]) == []
    assert check_command(STOP_TIMES, ["5", "inform_dqn_gridworld.py", "--eval-frequency", "500"]) == [
        "--eval-frequency is not a flag of inform_dqn_gridworld.py"
    ]
    assert find_command('sbatch --wrap ".venv/bin/python -m inform_utils.run_seeds --launcher slurm"') == (
        "inform_utils.run_seeds",
        ["--launcher", "slurm"],
    )
    assert known("--obstacle-*", everything) and not known("--oracle-gamma", everything)
    assert check_command("inform_utils.sleep_variant_maze", []) == [
        "inform_utils.sleep_variant_maze is not in the repository"
    ]


def test_the_front_page_stays_short_and_plain():
    """The README a newcomer reads in five minutes: at most 100 lines above its links; the rest lives in docs/. No
    word of the project's own slang ("the card": the scripts' one-file shape)."""
    with open(os.path.join(REPO, "README.md")) as f:
        text = f.read()
    assert len(text.split("\n## Links")[0].splitlines()) <= 100
    assert not re.search(r"\bcard\b", text, re.IGNORECASE)


def test_the_python_version_is_the_same_everywhere():
    """pyproject.toml's requires-python is what README.md and docs/usage.md say."""
    import tomllib

    with open(os.path.join(REPO, "pyproject.toml"), "rb") as f:
        needs = tomllib.load(f)["project"]["requires-python"]
    said = f"Python {needs.removeprefix('>=')} or newer"
    for page in ("README.md", "docs/usage.md"):
        with open(os.path.join(REPO, page)) as f:
            assert said in " ".join(f.read().split()), f"{page} does not say {said!r} ({needs} in pyproject.toml)"
