"""The shape of the scripts, measured: lines, flags, the longest functions, and the share of each file under its
`# ALGO LOGIC` banners (what a researcher changes) against `# TRY NOT TO MODIFY` (plumbing). docs/shape.md keeps
the table this prints.

    python -m inform_utils.shape                       # the card's scripts
    python -m inform_utils.shape --files inform_sac_pusher.py

Counting: every line of the file (as `wc -l`); a section runs from a banner (a comment at column 0 that starts with
`# ALGO LOGIC` or `# TRY NOT TO MODIFY`) to the next banner; lines before the first banner (docstring, imports, Args)
belong to neither. A flag is a field of the script's `Args` dataclass (what `--help` lists); the longest function is
measured from its `def` to its last line, nested functions inside it included. "args enters" lists the functions
outside `Args` that take a parameter named `args` (the flags as a whole), nested ones included; `Args`' own methods
are the flags' and are not counted.
"""

import ast
import os
import sys
from dataclasses import dataclass, field

import tyro

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CARD = ("inform_sac_pusher.py", "inform_dqn_gridworld.py", "oracle_train.py", "q_learning_recovered_reward.py")


@dataclass
class Args:
    files: list[str] = field(default_factory=lambda: list(CARD))
    """the scripts to measure, relative to the repository"""


def measure(path: str) -> dict:
    with open(path) as f:
        source = f.read()
    lines = source.splitlines()
    tree = ast.parse(source)
    flags = next(
        (
            sum(isinstance(node, ast.AnnAssign) for node in cls.body)
            for cls in tree.body
            if isinstance(cls, ast.ClassDef) and cls.name == "Args"
        ),
        0,
    )
    functions = sorted(
        ((node.end_lineno - node.lineno + 1, node.name, node.lineno, node.end_lineno) for node in ast.walk(tree)
         if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)),
        reverse=True,
    )  # fmt: skip
    args_class = [node for node in tree.body if isinstance(node, ast.ClassDef) and node.name == "Args"]
    own = {id(node) for cls in args_class for node in ast.walk(cls)}
    takes_args = sorted(
        node.name
        for node in ast.walk(tree)
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
        and id(node) not in own
        and any(a.arg == "args" for a in node.args.posonlyargs + node.args.args + node.args.kwonlyargs)
    )
    sections, current = [], None
    for number, line in enumerate(lines, 1):
        kind = (
            "algo"
            if line.startswith("# ALGO LOGIC")
            else "plumbing"
            if line.startswith("# TRY NOT TO MODIFY")
            else None
        )
        if kind:
            if current:
                current[2] = number - 1
            current = [kind, number, len(lines), line[2:].split(":")[0] if ":" in line else line[2:]]
            sections.append(current)
    algo = sum(end - start + 1 for kind, start, end, _ in sections if kind == "algo")
    plumbing = sum(end - start + 1 for kind, start, end, _ in sections if kind == "plumbing")
    return {"lines": len(lines), "flags": flags, "functions": functions, "sections": sections, "algo": algo,
            "plumbing": plumbing, "takes_args": takes_args}  # fmt: skip


def main(args: Args) -> None:
    rows = ["| file | lines | flags | ALGO LOGIC lines | plumbing lines | longest function | args enters |",
            "| --- | --- | --- | --- | --- | --- | --- |"]  # fmt: skip
    details = []
    for name in args.files:
        path = os.path.join(REPO, name)
        if not os.path.isfile(path):
            print(f"error: {name}: no such file", file=sys.stderr)
            sys.exit(2)
        m = measure(path)
        length, fname, start, end = m["functions"][0] if m["functions"] else (0, "-", 0, 0)
        share = f"{m['algo']} ({100 * m['algo'] / m['lines']:.0f}%)"
        enters = f"{len(m['takes_args'])}: " + ", ".join(f"`{f}`" for f in m["takes_args"]) if m["takes_args"] else "0"
        rows.append(f"| {name} | {m['lines']} | {m['flags']} | {share} | {m['plumbing']} | "
                    f"`{fname}` {length} (lines {start}-{end}) | {enters} |")  # fmt: skip
        details.append(f"\n{name}:")
        details += [
            f"  {kind:8} lines {start}-{end} ({end - start + 1}): {title}" for kind, start, end, title in m["sections"]
        ]
    print("\n".join(rows + details))


if __name__ == "__main__":
    main(tyro.cli(Args))
