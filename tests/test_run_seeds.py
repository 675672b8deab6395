import json
import os

import pytest

import run_seeds

FAKE_SCRIPT = """
import json, os, sys, time
seed = int(sys.argv[sys.argv.index("--seed") + 1])
exp = sys.argv[sys.argv.index("--exp-name") + 1]
with open("calls.txt", "a") as f:
    f.write(f"{seed}\\n")
d = f"runs/Fake-v0__{exp}__{seed}__{time.time_ns()}"
os.makedirs(d)
json.dump({"status": "completed", "script": os.path.basename(sys.argv[0]), "seed": seed, "eval/x": seed * 2.0,
           "args": {}}, open(f"{d}/summary.json", "w"))
"""


def test_aggregate_mean_std_n():
    table = run_seeds.aggregate([{"a": 1.0, "b": "x", "seed": 1}, {"a": 3.0, "b": "y", "seed": 2}])
    assert set(table) == {"a"}
    assert table["a"]["mean"] == 2.0 and table["a"]["std"] == pytest.approx(2**0.5) and table["a"]["n"] == 2


def test_runs_seeds_once_and_resumes(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "fake.py").write_text(FAKE_SCRIPT)
    args = run_seeds.Args(script="fake.py", exp_name="t", seeds=[1, 2, 3], workers=2)
    table = run_seeds.main(args)[""]
    assert table["eval/x"]["mean"] == 4.0 and table["eval/x"]["n"] == 3
    run_seeds.main(run_seeds.Args(script="fake.py", exp_name="t", seeds=[1, 2, 3, 4], workers=2))
    calls = sorted(int(x) for x in (tmp_path / "calls.txt").read_text().split())
    assert calls == [1, 2, 3, 4]  # finished seeds were not run again
    saved = json.load(open(os.path.join("runs", "t__table.json")))
    assert saved["table"]["eval/x"]["n"] == 4


def test_a_run_of_another_script_with_the_same_exp_name_does_not_count(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "fake.py").write_text(FAKE_SCRIPT)
    (tmp_path / "other.py").write_text(FAKE_SCRIPT)
    run_seeds.main(run_seeds.Args(script="other.py", exp_name="t", seeds=[1], workers=1))
    table = run_seeds.main(run_seeds.Args(script="fake.py", exp_name="t", seeds=[1], workers=1))[""]
    assert (tmp_path / "calls.txt").read_text().split() == ["1", "1"]  # fake.py ran although other.py had seed 1
    assert table["eval/x"]["n"] == 1
