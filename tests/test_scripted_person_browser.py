"""inform_utils/scripted_person_browser.py's table, from hand-made summaries (no browser, no run): the per-seed
numbers come from the right keys, the mean is over the seeds that have a number, and the markdown shows both."""

import pytest

from inform_utils import scripted_person_browser as sp


def day(answers, positives, tamer, inform=None):
    summary = {"status": "completed", "feedback/answers": answers, "feedback/positive": positives,
               "feedback/steps": answers, "feedback/answers_to_tamer_goal": answers - 5,
               "sleep/expert_transitions": 19 if inform else 0, "sleep_skipped": inform is None,
               "eval/tamer_episode_length": tamer, "eval/wall/tamer_episode_length": 200.0,
               "eval/start_set/tamer_success_rate": 0.0, "eval/all_starts/tamer_success_rate": 0.5}  # fmt: skip
    if inform is not None:
        summary |= {"eval/inform_episode_length": inform, "eval/start_set/inform_success_rate": 1.0}
    return summary


def test_the_table_takes_each_key_and_means_over_the_seeds_that_have_it():
    nights = {"bc": {"eval/inform_episode_length": 19.0}, "sham": None, "core": {"eval/inform_episode_length": 21.0}}
    rows = [
        sp.seed_row(1, day(40, 30, 19.0, inform=19.0), nights, walks=1, reached=True),
        sp.seed_row(2, day(61, 41, 19.0), {}, walks=0, reached=True),
        sp.seed_row(3, day(50, 35, 200.0, inform=200.0), nights, walks=2, reached=False),
    ]
    assert rows[0]["answers"] == 40 and rows[0]["+1 given"] == 30 and rows[0]["TAMER: all-starts success"] == 0.5
    assert rows[1]["INFORM: length from S"] is None and rows[1]["bc night: length from S"] is None
    table = sp.build_table(rows)
    mean, n = table["mean"], table["n"]
    assert mean["answers"] == pytest.approx(151 / 3) and n["answers"] == 3
    assert mean["TAMER: length from S"] == pytest.approx(238 / 3)
    assert mean["INFORM: length from S"] == pytest.approx(109.5) and n["INFORM: length from S"] == 2
    assert mean["sham night: length from S"] is None and n["sham night: length from S"] == 0
    assert mean["day ended at 19"] == pytest.approx(2 / 3) and mean["sleep skipped"] == pytest.approx(1 / 3)
    text = sp.markdown(table)
    assert "| | seed 1 | seed 2 | seed 3 | mean |" in text
    assert "| answers | 40 | 61 | 50 | 50.3 |" in text
    assert "| INFORM: length from S | 19 | - | 200 | 109.5 (of 2) |" in text
    assert "| INFORM: start-set success | 1.00 | - | 1.00 | 1.00 (of 2) |" in text
    assert "| day ended at 19 | yes | yes | no | 0.67 |" in text
    assert "| sham night: length from S | - | - | - | - |" in text
