"""The map of the day's quality (inform_utils/night_map.py): its rule on hand-computed cells of the maze."""

import json
import statistics
from dataclasses import replace

import pytest

from inform_utils import night_map
from inform_utils.files import BadInput

CONTROL = [0.2, 0.3, 0.4, 0.5, 0.6]  # both controls' held-out success, days 1-5
GAINS = [0.1, 0.2, 0.1, 0.2, 0.1]  # the night's over them, day by day


def night(path, seed, variant, success, length=19.0, tamer=0.3):
    path.mkdir(parents=True)
    summary = {"status": "completed", "seed": seed, "args": {"env_id": "KnoxStoneMaze-v0"},
               "eval/start_set/inform_success_rate": success, "eval/start_set/tamer_success_rate": tamer,
               "eval/start_set/oracle_success_rate": 1.0, "eval/all_starts/inform_success_rate": success,
               "eval/inform_episode_length": length, "eval/tamer_episode_length": 19.0,
               "sleep/expert_transitions": 100 * seed}  # fmt: skip
    (path / "summary.json").write_text(json.dumps(summary))
    (path / "random_starts.json").write_text("{}")


def cell(root, name, night_values, skip_day=None, length=19.0, tamer=None):
    for day in range(1, 6):
        base = root / name / f"KnoxStoneMaze-v0__mazemap__{day}__1"
        for variant, values in (("bc", CONTROL), ("sham", CONTROL), ("default", night_values)):
            if variant == "default" and day == skip_day:
                continue  # a day without a successful episode: no night to judge
            night(base / f"{variant}__sleep1", day, variant, values[day - 1], length, tamer[day - 1] if tamer else 0.3)


def args(root, **kw):
    return night_map.Args(map_dir=str(root), script="inform_dqn_gridworld.py", **kw)


def test_a_night_better_than_both_controls_on_every_day_consolidates_with_the_hand_computed_interval(tmp_path):
    cell(tmp_path, "nights_500_perfect", [c + g for c, g in zip(CONTROL, GAINS, strict=True)])
    (judged,) = night_map.main(args(tmp_path))
    tests = judged["nights"]["default"]["tests"]
    mean, se = 0.14, statistics.stdev(GAINS) / 5**0.5  # 0.0245; t_0.975 on 4 degrees of freedom is 2.7764
    for control in ("bc", "sham"):
        stats = tests[control]["stats"]
        assert stats["mean"] == pytest.approx(mean)
        assert (stats["low"], stats["high"]) == pytest.approx((mean - 2.7764 * se, mean + 2.7764 * se), abs=1e-4)
        assert stats["p"] == pytest.approx(0.0046, abs=2e-4)  # t = 5.72 on 4 degrees of freedom
        assert tests[control]["room"] == pytest.approx(1.0 - statistics.mean(CONTROL))
    assert judged["nights"]["default"]["verdict"] == "yes"
    assert judged["label"] == "500 perfect" and judged["successes"] == [100, 200, 300, 400, 500]
    row = night_map.table(args(tmp_path), [judged]).splitlines()[-3]  # all 29 cells beside it: the same gains here
    assert "| +0.140 (p = 0.0046), +0.140 (p = 0.0046) |" in row


def test_a_night_that_loses_the_plain_task_or_misses_a_day_does_not_consolidate(tmp_path):
    better = [c + g for c, g in zip(CONTROL, GAINS, strict=True)]
    cell(tmp_path, "nights_a", better, length=21.0)  # two steps longer from S than TAMER: beyond its one step
    cell(tmp_path, "nights_b", better, skip_day=3)
    cell(tmp_path, "nights_c", CONTROL)  # no gain at all: the interval is a point at 0
    a, b, c = night_map.main(args(tmp_path))
    assert a["nights"]["default"]["verdict"] == "no" and a["nights"]["default"]["plain"][1] is False
    assert b["nights"]["default"]["verdict"] == "no: it ran beside both controls on 4 of 5 days"
    assert c["nights"]["default"]["verdict"] == "no (equivalent)"  # within the bar: one tenth of the start cells


def test_a_night_run_on_fewer_days_is_shown_beside_tamer_on_those_days(tmp_path):
    """TAMER's column is over every day of the cell; a night that ran on days 1-4 only is read beside TAMER's value
    on days 1-4 (0.25 here, against 0.30 over all five), not beside the cell's."""
    cell(tmp_path, "nights_a", [0.9] * 5, skip_day=5, tamer=[0.1, 0.2, 0.3, 0.4, 0.5])
    (judged,) = night_map.main(args(tmp_path))
    row = next(line for line in night_map.table(args(tmp_path), [judged]).splitlines() if line.startswith("| a |"))
    assert "| 0.300 | default | 0.900 (TAMER 0.250 on its 4 days) |" in row
    cell(tmp_path, "nights_b", [0.9] * 5, tamer=[0.1, 0.2, 0.3, 0.4, 0.5])  # every day: nothing beside the value
    text = night_map.table(args(tmp_path), [night_map.judge(args(tmp_path), "nights_b")])
    row = next(line for line in text.splitlines() if line.startswith("| b |"))
    assert "| 0.300 | default | 0.900 |" in row


def test_the_studys_table_gives_tamer_on_the_days_a_night_stands_on(tmp_path):
    """sleep_study --table: TAMER's row is over all five days; a night that ran on days 1-4 only gets TAMER's mean over
    days 1-4 beside it (0.25, not 0.30), and a cell whose nights ran every day no such line."""
    from inform_utils import sleep_study

    cell(tmp_path, "nights_a", [0.9] * 5, skip_day=5, tamer=[0.1, 0.2, 0.3, 0.4, 0.5])
    study = sleep_study.Args(script="inform_dqn_gridworld.py", results_dir=str(tmp_path), campaign="nights_a")
    assert "default: values on 4 of 5 days; TAMER on those days: " in (text := sleep_study.table(study))
    assert "held-out start cells: success 0.250 ± 0.129," in text.split("values on 4 of 5 days")[1].splitlines()[0]
    cell(tmp_path, "nights_b", [0.9] * 5, tamer=[0.1, 0.2, 0.3, 0.4, 0.5])
    assert "values on" not in sleep_study.table(replace(study, campaign="nights_b"))


def test_the_figure_is_drawn_and_bad_input_is_one_line(tmp_path):
    cell(tmp_path, "nights_500_perfect", [c + g for c, g in zip(CONTROL, GAINS, strict=True)])
    night_map.main(args(tmp_path, figure=str(tmp_path / "map.png")))
    assert (tmp_path / "map.png").stat().st_size > 10_000
    with pytest.raises(BadInput, match="exists: name a new file"):
        night_map.main(args(tmp_path, figure=str(tmp_path / "map.png")))
    with pytest.raises(BadInput, match="no such folder"):
        night_map.main(args(tmp_path / "nowhere"))
