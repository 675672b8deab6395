"""The front page's numbers, recomputed from results/: README.md's headline run as the script prints it, its spread
over seeds, its table of claims and its verdicts on the night, each from the committed runs' summary.json (and the
study's --table). A number edited by hand, or a campaign re-made without the page, fails here."""

import contextlib
import glob
import io
import json
import os
import re
import statistics
import subprocess
import sys

import pytest
from conftest import REPO

import inform_sac_pusher as isp
from inform_utils import pusher_obstacle_stats as pos

HEADLINE = "v5paper_contact23"  # the README's command, at its defaults, seeds 1-5


def readme() -> str:
    with open(os.path.join(REPO, "README.md")) as f:
        return " ".join(f.read().split())  # a number may wrap across lines


def runs(campaign: str) -> list[dict]:
    paths = sorted(glob.glob(os.path.join(REPO, "results", campaign, "*", "summary.json")))
    rows = []
    for path in paths:
        with open(path) as f:
            rows.append(json.load(f))
    assert sorted(r["seed"] for r in rows) == [1, 2, 3, 4, 5], f"results/{campaign}: not seeds 1-5"
    return sorted(rows, key=lambda r: r["seed"])


def spread(rows: list[dict], key: str) -> str:
    values = [r[key] for r in rows]
    return f"{statistics.mean(values):.1f} ± {statistics.stdev(values):.1f}"


def obstacle(campaign: str) -> str:
    """The obstacle row as the page says it: INFORM's margin over TAMER with the boxes and the paired p over seeds."""
    stats = pos.aggregate([pos.load_run(d) for d in sorted(glob.glob(os.path.join(REPO, "results", campaign, "*/")))])
    side = "closer" if stats["margin"] > 0 else "farther"
    noise = " (within noise)" if stats["within_noise"] else ""
    return f"{side} by {abs(stats['margin']):.3f} m{noise}, p = {stats['paired_p_seed_means']:.2f}"


def within(rows: list[dict], share: float) -> int:
    oracle = [r["eval/oracle_return"] for r in rows]
    return sum(abs(r["eval/inform_return"] - o) <= share * abs(o) for r, o in zip(rows, oracle, strict=True))


def test_the_headline_run_prints_what_the_page_shows():
    """The README's block of the command's last lines is what print_results prints from seed 1's summary."""
    (seed1,) = [r for r in runs(HEADLINE) if r["seed"] == 1]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        isp.print_results(seed1, "runs/x")
    for line in out.getvalue().splitlines()[:3]:
        assert " ".join(line.split()) in readme(), line


def test_the_headline_spread_and_time_come_from_the_five_runs():
    rows, text = runs(HEADLINE), readme()
    for p in ("oracle", "tamer", "inform"):
        assert spread(rows, f"eval/{p}_return") in text, p
    successes = [sum(r[f"eval/{p}_success_rate"] >= 1 for r in rows) for p in ("oracle", "tamer", "inform")]
    assert f"succeed at the fixed start on {successes[0]}, {successes[1]} and {successes[2]} of 5" in text
    minutes = sorted(round(r["wall_time_s"] / 60) for r in rows)
    assert f"{minutes[0]}-{minutes[-1]} minutes" in text


@pytest.mark.parametrize("campaign", ["v4paper", HEADLINE])
def test_the_claims_table_comes_from_the_runs(campaign):
    rows, text = runs(campaign), readme()
    for p in ("oracle", "tamer", "inform"):
        assert spread(rows, f"eval/{p}_return") in text, (campaign, p)
    assert obstacle(campaign) in text, campaign
    assert f"{spread(rows, 'eval/inform_return')}, within 15% on {within(rows, 0.15)} of 5 seeds |" in text  # the row


def test_pusher_v4_on_todays_mujoco_is_said_as_it_ran():
    """The contact paragraph's Pusher-v4 on mujoco 4 (the 2.3 contact) beside mujoco 2.3.7's."""
    ours, reference = runs("v4paper_mujoco4"), runs("v4paper")
    for p in ("inform", "oracle"):
        key = f"eval/{p}_return"
        assert f"{spread(ours, key)} against {spread(reference, key)}" in readme(), p


def test_the_maze_rows_come_from_the_runs():
    rows, text = runs("maze_fig3"), readme()
    for key in ("eval/tamer_episode_length", "eval/inform_episode_length", "eval/wall/tamer_episode_length"):
        values = [r[key] for r in rows]
        assert f"{statistics.mean(values):.0f} ± {statistics.stdev(values):.0f}" in text, key
    fig6 = []
    for path in glob.glob(os.path.join(REPO, "results", "maze_fig6", "*", "summary.json")):
        with open(path) as f:
            fig6.append(json.load(f))
    arm = "sampled_bootstrap/{}/steps_to_first_optimum_{}"  # the authors' update (a sampled next action)
    said = {
        (sum(v is not None for v in s[arm.format("recovered_network", "per_agent")]), s["num_agents"],
         s[arm.format("recovered_network", "median")], s[arm.format("env", "median")])
        for s in fig6 if s.get("bootstrap") == "sampled" and s.get("reward_source") == "network"
    }  # fmt: skip
    ((reached, agents, recovered, env),) = said  # the campaign's runs of that arm agree
    assert f"{reached} of {agents} agents, median {recovered / 1000:.1f}k against {env / 1000:.1f}k" in text


def study_table(*flags: str) -> str:
    cmd = [sys.executable, "-m", "inform_utils.sleep_study", "--table", *flags]
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout


def test_the_verdicts_on_the_night_are_the_studys_tables():
    """Each number of the front page's verdict on the night is printed by the study's own --table."""
    text = readme()
    nine_days = study_table("--campaign", "sleep_study")
    said = re.search(r"ends (\d\.\d+) m closer than TAMER \(p = ([\d.]+) over 9 days\)", text)
    assert said and f"closer by {said[1]} m (within noise); p = {said[2]} over 9 days" in nine_days
    methods = study_table("--campaign", "methods56_v4", "--with-campaigns", "methods56_v4_50k")
    said = re.search(r"DWBC, as its authors release it, ends (\d\.\d+) m farther than cloning at its step size \(p = "
                     r"([\d.]+)\)", text)  # fmt: skip
    assert said and "| dwbc (0.0001) | 5 |" in methods and f"bc_lr1e-4: +{said[1]} m, p = {said[2]}," in methods
    v5 = study_table("--campaign", "sleep_study_v5_contact23")
    said = re.search(r"succeeds at the fixed start in (\d+) of 10 nights, as cloning does \(TAMER on (\d) of 5 days\); "
                     r"with the boxes it ends (\d\.\d+) m farther than cloning \(p = ([\d.]+)\)", text)  # fmt: skip
    for policy, count in (("default", f"{said[1]} of 10 nights"), ("bc", f"{said[1]} of 10 nights"),
                          ("tamer", f"{said[2]} of 5 days")):  # fmt: skip
        assert re.search(rf"\| {policy} \| [-\d.]+ \| {count} \|", v5), (policy, count)
    assert f"| Pusher-v5 | 5000 | default (5e-06) | 5 | +{said[3]} m, p = {said[4]}," in v5


def judged(map_dir: str, **flags) -> tuple[list[dict], int]:
    """night_map's own judgement of a map's committed cells, and how many nights the cells hold."""
    from inform_utils import night_map

    args = night_map.Args(map_dir=os.path.join(REPO, "results", map_dir), **flags)
    names = sorted(os.path.basename(p) for p in glob.glob(os.path.join(args.map_dir, "nights_*")))
    nights = len(glob.glob(os.path.join(args.map_dir, "nights_*", "*", "*__sleep*", "summary.json")))
    return [night_map.judge(args, name) for name in names], nights


def test_the_map_and_the_persons_arm_day_are_said_as_they_ran():
    """The maps' bullet, from night_map's own judgement of the committed cells (the Pusher's expert from its cached
    tests); the person's count, from the five days of results/browser_pusher_takeover_v5/drive, and the planner's days
    beside them."""
    text = readme()
    said = re.search(r"the maze: (\d+) qualities of day, (\d+) nights; .*? the night beats cloning from held-out start "
                     r"cells in (\d+) cells \(p < 0\.05\), TAMER's update continued in none", text)  # fmt: skip
    cells, nights = judged("map_maze", script="inform_dqn_gridworld.py")
    passed = {c: sum(cell["nights"]["default"]["tests"][c]["passes"] for cell in cells) for c in ("bc", "sham")}
    assert said and (int(said[1]), int(said[2]), int(said[3]), passed["sham"]) == (len(cells), nights, passed["bc"], 0)
    said = re.search(r"the paper's Pusher-v4: (\d+) lengths of day and (\d+) from random starts, (\d+) nights; .*? on "
                     r"the Pusher neither the night nor DWBC beats either control in any cell", text)  # fmt: skip
    cells, nights = judged("map_v4", run_expert=False)
    tests = [test for cell in cells for night in cell["nights"].values() for test in night["tests"].values()]
    random = sum(cell["campaign"].endswith("_random") for cell in cells)
    assert said and (int(said[1]), int(said[2]), int(said[3])) == (len(cells) - random, random, nights)
    assert sum(t["passes"] for t in tests) == 0
    assert all(set(cell["nights"]) == {"default", "dwbc"} for cell in cells)
    count = sum(d["eval/inform_success_rate"] >= 1 for d in runs("browser_pusher_takeover_v5/drive"))  # seeds 1-5
    assert f"INFORM succeeds at the fixed start on {count} of 5 seeds, the goal 4" in text
    counts = [  # --drive-by object: the person at each episode's start, then after three no's (-1), then out of H
        sum(d["eval/inform_success_rate"] >= 1 for d in runs(f"browser_pusher_takeover_v5/{condition}"))
        for condition in ("drive_by_object", "drive_by_object_takeover", "drive_by_object_takeover_no_driven_in_h")
    ]
    assert (
        f"and on {counts[0]} of 5 when a planner pushes where the person points, {counts[1]} and {counts[2]} of 5 "
        "when the person takes over after three no's, heard as -1 (and with the driven steps out of H)"
    ) in text
