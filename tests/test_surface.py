"""inform_utils/ uses only the names each script's docstring declares for other code: a script stays free to change
everything else."""

import ast
import glob
import os
import re

from conftest import REPO

SCRIPTS = {"inform_sac_pusher", "inform_dqn_gridworld", "oracle_train"}


def declared(module: str) -> set[str]:
    doc = " ".join(ast.get_docstring(ast.parse(open(os.path.join(REPO, module + ".py")).read())).split())
    match = re.search(
        r"Imported by inform_utils/, the only names other code may use \(a test holds it to them\): (.*?)\.", doc, re.S
    )
    assert match, f"{module}.py's docstring declares no surface"
    return {name.strip() for name in match.group(1).split(",")}


def used(path: str) -> dict[str, set[str]]:
    """{script: names} that one helper takes from the scripts: `from script import x` and `alias.x`."""
    tree = ast.parse(open(path).read())
    aliases = {}
    names = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name in SCRIPTS:
                    aliases[alias.asname or alias.name] = alias.name
        elif isinstance(node, ast.ImportFrom) and node.module in SCRIPTS:
            names.setdefault(node.module, set()).update(alias.name for alias in node.names)
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases:
            names.setdefault(aliases[node.value.id], set()).add(node.attr)
    return names


def test_inform_utils_uses_only_the_declared_names():
    seen = set()
    for path in sorted(glob.glob(os.path.join(REPO, "inform_utils", "*.py"))):
        for script, names in used(path).items():
            seen.add(script)
            extra = names - declared(script)
            assert not extra, f"{os.path.basename(path)} uses {sorted(extra)} of {script}.py, which it does not declare"
    assert seen == SCRIPTS  # the check saw every script's imports (a rename would not slip by unseen)
