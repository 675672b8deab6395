"""No number moves: tiny runs of every script and flag family, and every night of the sleep study, give the values
that the code before the refactor gave (tests/snapshot.py says how they were made), bit for bit.

On a machine whose CPU signature differs from the recorded one, the reference is recomputed with that code from git
(the same machine, so the last bits agree); without git's history the test says so and fails, since a snapshot that
cannot be compared proves nothing. The Pusher-v4 case runs in the mujoco 2.3.7 venv (-m pusher_v4)."""

import json
import subprocess
import sys

import pytest
import snapshot as snap

with open(snap.VALUES) as f:
    RECORDED = json.load(f)


def mujoco_major() -> int:
    import mujoco

    return int(mujoco.__version__.split(".")[0])


def marks(c):
    if c["python"] != "v4":
        return []
    reason = "Pusher-v4 needs mujoco<3: run it in the mujoco 2.3.7 venv (pytest -m pusher_v4)"
    return [pytest.mark.pusher_v4, pytest.mark.skipif(mujoco_major() >= 3, reason=reason)]


@pytest.fixture(scope="session")
def base_code(tmp_path_factory):
    """BASE's code from git, only when the recorded values cannot be used on this CPU."""
    if RECORDED["cpu"] == snap.cpu_signature():
        return None
    out = tmp_path_factory.mktemp("base_code")
    archive = subprocess.run(["git", "-C", snap.REPO, "archive", RECORDED["base"]], capture_output=True)
    if archive.returncode != 0:
        pytest.fail(f"the recorded snapshot is for another CPU ({RECORDED['cpu']}) and git cannot give commit "
                    f"{RECORDED['base']} to recompute it: {archive.stderr.decode().strip()}")  # fmt: skip
    subprocess.run(["tar", "-x", "-C", str(out)], input=archive.stdout, check=True)
    return str(out)


@pytest.fixture(scope="session")
def runs(tmp_path_factory, base_code):
    """Runs each case once (and the cases it needs first), with the current code and, where needed, BASE's."""
    done = {"new": {}, "old": {}}
    cache = {"new": {}, "old": {}}

    def get(name, form):
        if name not in cache[form]:
            c = snap.BY_NAME[name]
            if c["needs"]:
                get(c["needs"], form)
            cwd = tmp_path_factory.mktemp(f"{form}_{name}")
            code = snap.REPO if form == "new" else base_code
            cache[form][name] = snap.run_case(c, code, str(cwd), sys.executable, done[form], form)
        return cache[form][name]

    return get


@pytest.mark.parametrize("c", [pytest.param(c, marks=marks(c), id=c["name"]) for c in snap.CASES])
def test_a_tiny_run_gives_the_numbers_it_gave_before_the_refactor(c, runs, base_code):
    expected = RECORDED["cases"][c["name"]] if base_code is None else runs(c["name"], "old")
    got = runs(c["name"], "new")
    assert got.keys() == expected.keys()
    for part in expected:
        missing = sorted(set(expected[part]) - set(got[part])) if isinstance(expected[part], dict) else []
        assert not missing, f"{c['name']}: {part} lost {missing[:10]}"
        if isinstance(expected[part], dict):
            changed = {k: (v, got[part][k]) for k, v in expected[part].items() if got[part][k] != v}
            assert not changed, f"{c['name']}: {part} changed (before, after): {dict(list(changed.items())[:10])}"
        else:
            assert got[part] == expected[part], f"{c['name']}: {part} changed"


def test_every_case_has_a_recorded_value_and_the_record_says_where_it_came_from():
    assert set(RECORDED["cases"]) == set(snap.BY_NAME)
    assert RECORDED["base"] == snap.BASE and RECORDED["cpu"]
    assert all(RECORDED["cases"][name] for name in snap.BY_NAME)  # no case recorded empty
