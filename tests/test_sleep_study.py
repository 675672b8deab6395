"""The sleep study's verdict on hand-made nights: variants are compared with TAMER and the controls day by day, on
the days they ran, and "helps" needs a gain over both controls above the sleep seeds' spread."""

import json
import os

import numpy as np

from inform_utils import sleep_study as ss

KEY = "eval/{p}_return"


def night(day, variant, value, seed=1, tamer=None):
    return {"day": day, "variant": variant, "seed": seed, "eval/inform_return": value, "eval/tamer_return": tamer}


# day A: TAMER 10; day B: TAMER 20. The variant x ran on day A only.
ROWS = [
    night("A", "default", 12.0, 1, 10.0),
    night("A", "default", 13.0, 2, 10.0),
    night("A", "sham", 11.0, 1, 10.0),
    night("A", "bc", 11.5, 1, 10.0),
    night("A", "x", 14.0, 1, 10.0),
    night("B", "default", 21.0, 1, 20.0),
    night("B", "default", 21.5, 2, 20.0),
    night("B", "sham", 21.0, 1, 20.0),
    night("B", "bc", 20.9, 1, 20.0),
]


def test_gains_are_paired_by_day():
    assert ss.paired(ROWS, "default", "tamer", KEY, 1) == [2.5, 1.25]  # 12.5 - 10, 21.25 - 20
    assert ss.paired(ROWS, "x", "sham", KEY, 1) == [3.0]  # day A only: day B's sham (21) is not x's control
    assert ss.paired(ROWS, "x", "bc", KEY, -1) == [-2.5]  # lower is better: the gain changes sign
    assert ss.seed_spread(ROWS, "eval/inform_return") == 0.75  # the default's ranges 1 and 0.5


def test_the_offline_pick_is_compared_with_the_controls_picks():
    rows = [{**r, "eval/inform_selected_return": r["eval/inform_return"] - (5.0 if r["variant"] == "x" else 0.0)}
            for r in ROWS]  # fmt: skip
    assert ss.paired(rows, "x", "sham", KEY, 1, "inform_selected") == [-2.0]  # x's pick: 9 against sham's 11
    assert ss.helps(rows, "x", KEY, 1, 0.75) and not ss.helps(rows, "x", KEY, 1, 0.75, "inform_selected")
    night_without_the_key = {"day": "A", "variant": "x", "seed": 2, "eval/tamer_return": 10.0}
    assert ss.day_means([*rows, night_without_the_key], "x", KEY) == {"A": 14.0}  # a missing value is left out


def test_helps_only_above_the_bar_against_both_controls_on_every_day():
    assert ss.helps(ROWS, "x", KEY, 1, 0.75)  # +3 over sham, +2.5 over bc
    assert not ss.helps(ROWS, "x", KEY, 1, 2.6)  # not by more than the bar over bc
    # the default (12.5 on A, 21.25 on B): over sham 1.5 and 0.25, over bc 1.0 and 0.35; its means (0.875, 0.675)
    # clear 0.6, but day B's 0.25 does not
    assert not ss.helps(ROWS, "default", KEY, 1, 0.6)
    assert ss.helps(ROWS, "default", KEY, 1, 0.2)
    assert not ss.helps(ROWS, "default", KEY, 1, None)  # no second sleep seed: no bar, no claim


def test_a_gain_equal_to_the_bar_does_not_clear_it_despite_rounding():
    rows = [night("A", "x", 0.32, 1, 0.3), night("A", "sham", 0.30, 1, 0.3), night("A", "bc", 0.28, 1, 0.3)]
    assert ss.paired(rows, "x", "sham", KEY, 1)[0] > 0.02  # 0.020000000000000018
    assert not ss.helps(rows, "x", KEY, 1, 0.02)


def test_the_verdict_table_names_each_variant_and_measure():
    columns = (("return", KEY, 1),)
    text = ss.verdict(ROWS, ["default", "sham", "bc", "x"], columns, {"return": 0.75}, ("inform",))
    assert "| x | return | 1 | +4 (1 better, 0 worse) | +3 (1 of 1) | +2.5 (1 of 1) | 0.75 | yes |" in text
    assert (
        "| default | return | 2 | +1.88 (2 better, 0 worse) | +0.875 (1 of 2) | +0.675 (1 of 2) | 0.75 | no |" in text
    )
    assert "| sham |" not in text and "| bc |" not in text  # the controls are what the others are measured against


def test_tamer_on_a_day_is_read_from_the_defaults_first_night(tmp_path):
    # the sampled tests share a stream with the night's policies, so TAMER's value differs a little between nights;
    # the night that sorts first by name (the authors' protocol) must not be the one that decides it; sleep seeds
    # sort as numbers
    nights = (
        ("authors__sleep1", 9.0),
        ("default__sleep10", 11.0),
        ("default__sleep2", 10.5),
        ("default__sleep1", 10.0),
    )
    for name, tamer in nights:
        path = tmp_path / "study" / "A" / name
        path.mkdir(parents=True)
        summary = {"status": "completed", "seed": 7, "eval/tamer_return": tamer}  # a summary's seed is the day's
        (path / "summary.json").write_text(json.dumps(summary))
        (path / "random_starts.json").write_text("{}")
    rows = ss.load(ss.Args(results_dir=str(tmp_path), campaign="study"))
    assert [r["dir"] for r in rows] == ["default__sleep1", "default__sleep2", "default__sleep10", "authors__sleep1"]
    assert ss.day_means(rows, "tamer", KEY) == {"A": 10.0}


def make_rule_days(tmp_path, seeds, variants, distance_of, return_of):
    """Nights on the days of `seeds`, TAMER ending at 0.2 m with the boxes and the oracle at -20 on the plain task;
    distance_of(variant, seed) and return_of(variant, seed) give the variant's (None: it did not run that day)."""
    rng = np.random.default_rng(0)
    for seed in seeds:
        for variant in variants:
            distance, ret = distance_of(variant, seed), return_of(variant, seed)
            if distance is None:
                continue
            path = tmp_path / "study" / f"day{seed}" / f"{variant}__sleep1"
            path.mkdir(parents=True)
            summary = {"status": "completed", "seed": seed, "eval/oracle_return": -20.0, "eval/inform_return": ret}
            summary["eval/inform_selected_return"] = ret
            (path / "summary.json").write_text(json.dumps(summary))
            (path / "random_starts.json").write_text("{}")
            noise = rng.normal(0, 0.01, 100)
            np.savez(
                path / "obstacle_distances.npz",
                tamer=0.2 + noise,
                inform=distance + noise,
                inform_selected=distance + noise,
            )
    return ss.Args(results_dir=str(tmp_path), campaign="study")


def rule_rows(text: str, table: int = 0) -> dict:
    """{label: the other cells} of the rule's first (0) or second (1) table."""
    tables = text.split("does it hold on the new days")
    rows = [line.split(" | ") for line in tables[table].splitlines() if line.startswith("| ")][2:]  # no header
    return {cells[0][2:]: [c.rstrip(" |") for c in cells[1:]] for cells in rows}


def test_the_rule_for_a_new_default_reads_the_days_of_seeds_1_to_5_only(tmp_path):
    # x: closer than TAMER with the boxes on 4 of days 1-5 (by 0.05 m, farther by 0.05 on day 5) and within 15% of the
    # oracle on each; day 0 (much worse, and farther with the boxes) is not one of the rule's days. Over the days its
    # margins are 0.05 x 4 and -0.05: mean 0.03, sd sqrt(0.002), t = 0.03 / (sqrt(0.002) / sqrt(5)) = 1.5, p = 0.21,
    # so it passes by the pooled test only. q: closer on all five (0.05 x 4, 0.04): t = 24, it passes by both. y: as
    # close as x, but 20% below the oracle on day 3. z: ran on two days so far, closer on both. The default is farther
    # everywhere.
    def distance(variant, seed):
        if variant == "z" and seed not in (1, 2):
            return None
        if variant == "default":
            return 0.25
        if variant == "q":
            return 0.16 if seed == 5 else 0.15
        return 0.3 if seed == 0 else (0.25 if seed == 5 else 0.15)  # day 5: farther than TAMER

    def ret(variant, seed):
        return -40.0 if seed == 0 else (-24.0 if (variant, seed) == ("y", 3) else -21.0)

    args = make_rule_days(tmp_path, (0, 1, 2, 3, 4, 5), ("default", "x", "q", "y", "z"), distance, ret)
    text = ss.default_rule(args, ss.load(args), ["default", "sham", "bc", "x", "q", "y", "z"])
    rows = rule_rows(text)
    assert rows["x"][0] == "5" and "closer on 4 of 5 days" in rows["x"][1] and rows["x"][2] == "5 of 5"
    assert "closer by 0.0300 m; p = 0.21 over 5 days" in rows["x"][1]
    assert rows["x"][3:] == ["no", "yes, if it holds on seeds 6-8"]  # by the per-day test, then the pooled one
    assert rows["q"][3:] == ["yes, if it holds on seeds 6-8"] * 2
    assert rows["y"][2] == "4 of 5" and rows["y"][3:] == ["no", "no"]  # 20% below the oracle on one day
    assert rows["z"][3:] == ["open: ran on 2 of 5 days"] * 2
    assert rows["x, offline pick"][3:] == rows["x"][3:]
    # only the policies that passed on days 1-5, by either test, go to the new days, where none has run yet; one
    # that passed by one test only is not tried by the other there
    new = rule_rows(text, 1)
    assert set(new) == {"x", "x, offline pick", "q", "q, offline pick"}
    assert new["q"] == ["0", "-", "-", "open: ran on 0 of 3 days", "open: ran on 0 of 3 days"]
    assert new["x"][3:] == ["- (no on seeds 1-5)", "open: ran on 0 of 3 days"]
    assert text.endswith(
        "a new default by the per-day test: none yet (q, q, offline pick still open) (by the pooled test: none yet "
        "(x, x, offline pick, q, q, offline pick still open))"
    )
    day0 = [r for r in ss.load(args) if r["seed"] == 0]
    assert "no day of seeds 1-5" in ss.default_rule(args, day0, ["default", "x"])


def test_a_new_default_must_hold_on_days_6_to_8_alone(tmp_path):
    # x, w and u pass on days 1-5 by both tests (closer by 0.05 m on four days, 0.04 on day 2). On days 6-8, x is
    # closer by 0.05, 0.05 and 0.04: t = 0.04667 / (0.005774 / sqrt(3)) = 14, p = 1 - 14 / sqrt(2 + 14^2) = 0.005 (a
    # t with 2 degrees of freedom), so it holds by both tests; w is as close but 20% below the oracle on day 7; u is
    # farther on days 7 and 8. t is farther on day 2, so it passes days 1-5 by the pooled test only (margins 0.05,
    # -0.03, 0.05 x 3: p = 0.10 over the days); on days 6-8 it is farther on day 8 and holds by the pooled test. v is
    # closer on days 6-8 only, so it never gets there; the default is farther everywhere.
    def distance(variant, seed):
        if variant in ("default", "v"):
            return 0.25 if variant == "default" or seed <= 5 else 0.15
        if variant == "t":
            return 0.23 if seed in (2, 8) else 0.15
        farther = (7, 8) if variant == "u" else ()
        return 0.23 if seed in farther else (0.16 if seed in (2, 8) else 0.15)

    def ret(variant, seed):
        return -24.0 if (variant, seed) == ("w", 7) else -21.0

    variants = ("default", "x", "w", "u", "v", "t")
    args = make_rule_days(tmp_path, range(1, 9), variants, distance, ret)
    text = ss.default_rule(args, ss.load(args), ["sham", "bc", *variants])
    first, new = rule_rows(text), rule_rows(text, 1)
    assert first["v"][3:] == ["no", "no"] and first["default"][3:] == ["no", "no"]
    assert first["t"][3:] == ["no", "yes, if it holds on seeds 6-8"] and "p = 0.1 over 5 days" in first["t"][1]
    assert set(new) == {f"{v}{pick}" for v in ("x", "w", "u", "t") for pick in ("", ", offline pick")}
    assert new["x"][0] == "3" and new["x"][1].startswith("closer by 0.0467 m; p = 0.0051 over 3 days")
    assert new["x"][1].endswith("closer on 3 of 3 days")  # no noise level given: no count beyond it
    assert new["x"][2] == "3 of 3" and new["x"][3:] == ["yes", "yes"]
    assert new["w"][2] == "2 of 3" and new["w"][3:] == ["no", "no"]
    assert "closer on 1 of 3 days" in new["u"][1] and new["u"][3:] == ["no", "no"]
    assert new["t"][3:] == ["- (no on seeds 1-5)", "yes"]
    assert text.endswith(
        "a new default by the per-day test: x, x, offline pick (by the pooled test: x, x, offline pick, t, t, "
        "offline pick)"
    )
    # days still to run keep a policy open until they can no longer change its answer
    rows = ss.load(args)
    day6 = [r for r in rows if r["seed"] <= 6]
    assert {label: cells[4] for label, cells in rule_rows(ss.default_rule(args, day6, variants), 1).items()} == {
        label: "open: ran on 1 of 3 days" for label in new
    }
    day7 = [r for r in rows if r["seed"] != 6 and r["seed"] != 8]
    answers = rule_rows(ss.default_rule(args, day7, variants), 1)
    assert answers["w"][3:] == ["no", "no"] and answers["x"][3] == answers["u"][3] == "open: ran on 1 of 3 days"
    failed = [r for r in rows if r["variant"] in ("default", "u")]
    assert ss.default_rule(args, failed, ["default", "u"]).endswith(
        "a new default by the per-day test: none; the defaults stay (by the pooled test: none)"
    )


def obstacle_day(tmp_path, day, night, tamer, policy):
    """One night's obstacle distances (TAMER's and the policy's, as the night's last actor and its offline pick)."""
    path = tmp_path / "study" / day / night
    path.mkdir(parents=True, exist_ok=True)
    np.savez(path / "obstacle_distances.npz", tamer=np.array(tamer), inform=np.array(policy),
             inform_selected=np.array(policy))  # fmt: skip
    return {"day": day, "dir": night, "variant": night.split("__")[0]}


def test_the_obstacle_test_is_over_days_with_tamer_counted_once_in_the_pooled_test(tmp_path):
    # three days, two nights of x a day; TAMER's episodes are the same in both nights of a day (one stream). TAMER's
    # day means 0.25, 0.30, 0.35; x's 0.21, 0.25, 0.26 (the mean of its nights): margins 0.04, 0.05, 0.09
    tamer = {"A": [0.20, 0.30], "B": [0.25, 0.35], "C": [0.30, 0.40]}
    x = {"A": ([0.18, 0.22], [0.20, 0.24]), "B": ([0.24, 0.28], [0.22, 0.26]), "C": ([0.25, 0.27], [0.24, 0.28])}
    nights = [obstacle_day(tmp_path, d, f"x__sleep{i + 1}", tamer[d], x[d][i]) for d in tamer for i in range(2)]
    args = ss.Args(results_dir=str(tmp_path), campaign="study")
    test = ss.obstacle_test(args, nights, "inform", noise=0.045)
    assert test["days"] == 3 and np.allclose(test["margins"], [0.04, 0.05, 0.09]) and test["closer_days"] == 3
    assert test["beyond_noise"] == 2  # 0.05 and 0.09 exceed 0.045; 0.04 does not
    # the paired t over days: the margins' mean 0.06, sd sqrt(0.0007), so t = 0.06 / (sqrt(0.0007) / sqrt(3)) =
    # 3.928; with 2 degrees of freedom the two-sided p is 1 - t / sqrt(2 + t^2) = 0.0591
    t = 0.06 / (0.0007**0.5 / 3**0.5)
    assert abs(test["p_day"] - (1 - t / (2 + t**2) ** 0.5)) < 1e-9 and abs(test["p_day"] - 0.0591) < 1e-3
    # the pooled test sees x's 12 episodes against TAMER's 6, not 12: Welch's t by hand
    mine = np.concatenate([np.concatenate(x[d]) for d in x])
    once = np.concatenate([tamer[d] for d in tamer])
    se = (mine.var(ddof=1) / 12 + once.var(ddof=1) / 6) ** 0.5
    welch_t = (mine.mean() - once.mean()) / se
    df = se**4 / ((mine.var(ddof=1) / 12) ** 2 / 11 + (once.var(ddof=1) / 6) ** 2 / 5)
    from scipy.stats import t as student

    assert abs(test["p_pooled"] - 2 * student.sf(abs(welch_t), df)) < 1e-12
    twice = np.concatenate([tamer[d] for d in tamer for _ in range(2)])
    assert abs(test["p_pooled"] - ss_welch(mine, twice)) > 1e-3  # counting TAMER in every night would differ
    text = ss.obstacle_text(test)
    # the margins' 95% interval by hand: sd sqrt(0.0007), se 0.01528, t_0.975 with 2 degrees of freedom 4.303:
    # 0.06 -+ 0.0657; detectable at 80% power (4.303 + t_0.8 = 1.061) x 0.01528 = 0.0819
    interval = "(the margin's 95% interval -0.0057 to +0.1257 m, detectable 0.0819 m)"
    head = f"closer by 0.0600 m; p = 0.059 over 3 days {interval}; pooled p = "
    assert text == f"{head}{test['p_pooled']:.2g}; closer on 3 of 3 days, 2 beyond noise"
    assert "(within noise)" in ss.obstacle_text(ss.obstacle_test(args, nights, "inform", noise=0.07))
    one_day = ss.obstacle_test(args, nights[:2], "inform")
    assert one_day["p_day"] is None and ss.obstacle_text(one_day).startswith("closer by 0.0400 m; one day; pooled p")


def ss_welch(a, b):
    from scipy.stats import ttest_ind

    return float(ttest_ind(a, b, equal_var=False).pvalue)


def test_tamers_sampling_spread_is_the_largest_range_between_one_days_streams(tmp_path):
    # day A: two nights sharing TAMER's stream (mean 0.25) and the day's own run (0.26): range 0.01. Day B: nights in
    # two streams, 0.30 and 0.32: range 0.02. Day C: one stream only, no spread.
    rows = [
        obstacle_day(tmp_path, "A", "default__sleep1", [0.20, 0.30], [0.2, 0.2]),
        obstacle_day(tmp_path, "A", "sham__sleep1", [0.20, 0.30], [0.2, 0.2]),
        obstacle_day(tmp_path, "A", "day", [0.21, 0.31], [0.2, 0.2]),
        obstacle_day(tmp_path, "B", "default__sleep1", [0.25, 0.35], [0.2, 0.2]),
        obstacle_day(tmp_path, "B", "sham__sleep1", [0.27, 0.37], [0.2, 0.2]),
        obstacle_day(tmp_path, "C", "default__sleep1", [0.25, 0.35], [0.2, 0.2]),
    ]
    args = ss.Args(results_dir=str(tmp_path), campaign="study")
    nights = [r for r in rows if r["dir"] != "day"]
    assert abs(ss.tamer_spread(args, nights) - 0.02) < 1e-12
    assert abs(ss.tamer_spread(args, [r for r in nights if r["day"] == "A"]) - 0.01) < 1e-12
    assert ss.tamer_spread(args, [r for r in nights if r["day"] == "C"]) is None


def test_the_claim_rows_test_over_seeds_with_the_pooled_test_beside_it():
    from inform_utils import pusher_obstacle_stats as pos

    def run(seed, tamer, inform):
        distances = {"tamer": np.array(tamer), "inform": np.array(inform)}
        return {"seed": seed, "distances": distances, "success_distance": 0.08, "layout": "bisector",
                "min_box_distance_to_path": None}  # fmt: skip

    out = pos.aggregate([run(1, [0.2, 0.4], [0.1, 0.3]), run(2, [0.3, 0.5], [0.4, 0.4])])
    # margins 0.1 and 0.0: mean 0.05, sd sqrt(0.005), t = 0.05 / (sqrt(0.005) / sqrt(2)) = 1; with 1 degree of
    # freedom the two-sided p is 1 - 2 atan(t) / pi = 0.5
    assert np.allclose(out["margins"], [0.1, 0.0]) and abs(out["margin"] - 0.05) < 1e-12
    assert abs(out["paired_t_seed_means"] - 1) < 1e-9 and abs(out["paired_p_seed_means"] - 0.5) < 1e-9
    # TAMER's spread: 2 sd / sqrt(2) with sd = sqrt(0.02) on each seed, 0.2; the margin 0.05 is within it
    assert abs(out["tamer_sampling_spread"] - 0.2) < 1e-12 and out["within_noise"]
    assert out["inform_closer_seeds"] == 1 and out["inform_closer_seeds_beyond_noise"] == 0
    pooled = ss_welch([0.2, 0.4, 0.3, 0.5], [0.1, 0.3, 0.4, 0.4])
    assert abs(out["welch_p_episodes"] - pooled) < 1e-12
    assert "paired_p_seed_means" not in pos.aggregate([run(1, [0.2, 0.4], [0.1, 0.3])])  # one seed: no test


def test_the_per_seed_table_reads_each_runs_summary():
    from inform_utils import pusher_obstacle_stats as pos

    def run(seed, oracle, tamer, inform):
        summary = {"wall_time_s": 3095.9, "sleep/success_episodes": 137, "sleep/episodes": 2000}
        for p, (ret, dist, succ) in (("oracle", oracle), ("tamer", tamer), ("inform", inform)):
            summary |= {f"eval/{p}_return": ret, f"eval/{p}_final_distance": dist, f"eval/{p}_success_rate": succ}
            summary[f"eval/authors_test/{p}_success_rate"] = succ / 2
        distances = {"tamer": np.array([0.1, 0.2]), "inform": np.array([0.3, 0.3])}
        return {"seed": seed, "summary": summary, "distances": distances}

    first = run(1, (-20.0, 0.05, 1.0), (-25.0, 0.09, 0.0), (-30.0, 0.2, 0.0))
    text = pos.per_seed_table([first, run(2, (-20.0, 0.05, 1.0), (-21.0, 0.06, 0.5), (-22.0, 0.07, 0.9))])
    rows = text.splitlines()
    # seed 1: INFORM (-30) is 50.0% below the oracle (-20), TAMER (-25) 25.0%; obstacle means 0.150 and 0.300
    assert rows[2] == (
        "| 1 | -20.00 | -25.00 | -30.00 | 50.0% | 25.0% | 0.050 / 0.090 / 0.200 | 1 / 0 / 0 | 0.00 / 0.00 | "
        "0.150 / 0.300 | 137 of 2,000 | 3,096 s |"
    )
    assert "| 1.00 / 0.50 / 0.90 |" in rows[3]  # a rate that is not 0 or 1: every success of the row as a rate
    # the returns' mean and sd over the seeds: TAMER -23 ± sqrt(8) = 2.83, INFORM -26 ± sqrt(32) = 5.66
    assert rows[4].startswith("| mean ± std | -20.00 ± 0.00 | -23.00 ± 2.83 | -26.00 ± 5.66 |")


def method_night(task, day, variant, seed, distance, ret, tamer_ret, lr=5e-6, steps=5000):
    return {"day": day, "variant": variant, "sleep_seed": seed, "dir": f"{variant}__sleep{seed}",
            "args": {"env_id": task, "sleep_gradient_steps": steps},
            "sleep_variant": f"method=x control=x policy_lr={lr}", "eval/obstacle/inform_final_distance": distance,
            "eval/obstacle/inform_final_distance_deterministic": distance - 0.05, "eval/inform_return_sampled": ret,
            "eval/tamer_return_sampled": tamer_ret}  # fmt: skip


def write_streams(results, day, returns):
    os.makedirs(results / "c" / day, exist_ok=True)
    with open(results / "c" / day / "tamer_streams.json", "w") as f:
        json.dump({"eval/tamer_return_sampled": {str(i + 1): r for i, r in enumerate(returns)}}, f)


def test_the_rule_for_a_night_built_for_the_data_per_task_and_budget_against_the_controls(tmp_path):
    """Five Pusher-v4 days, two sleep seeds a night. bc (cloning at 5e-6) ends at 0.20 m with the boxes, the sham at
    0.19 (0.15 on day 5), cloning at 3e-4 (bc_lr3e-4) at 0.18 (0.14 on day 5). dwbc (its step size 1e-4, no cloning
    control at it): 0.18 (0.181 on day 3), closer than bc on every day (p tiny), but closer than the sham by 0.01 on
    four days and farther by 0.03 on day 5: mean -0.0018, so no, and 'matched' open. oril (3e-4): 0.17 (0.171 on day 2,
    0.13 on day 5), closer than all three on every day, and on the plain task 0.5 below TAMER, whose own streams differ
    by up to 1.0 (day 4: -29 in one other stream against the nights' -30): yes, as committed and matched; x, as oril but
    1.5 below TAMER: no. dwbc at a second budget (50,000 steps) on one day, with its controls: its own row, open. On
    Pusher-v5, two days so far: open. The deterministic test (every night 0.05 closer than its sampled one) sits in a
    table of its own. Without TAMER's other streams the plain-task part cannot be judged: open."""
    rows = []
    for day in range(1, 6):
        write_streams(tmp_path, f"d{day}", [-30.0, -29.0 if day == 4 else -29.8, -29.9])
        for seed in (1, 2):
            rows.append(method_night("Pusher-v4", f"d{day}", "bc", seed, 0.20, -30.0, -30.0))
            rows.append(method_night("Pusher-v4", f"d{day}", "bc_lr3e-4", seed, 0.18 if day < 5 else 0.14, -30.0, -30.0,
                                     lr=3e-4))  # fmt: skip
            rows.append(method_night("Pusher-v4", f"d{day}", "sham", seed, 0.19 if day < 5 else 0.15, -30.0, -30.0))
            rows.append(method_night("Pusher-v4", f"d{day}", "dwbc", seed, 0.181 if day == 3 else 0.18, -30.0, -30.0,
                                     lr=1e-4))  # fmt: skip
            oril = {2: 0.171, 5: 0.13}.get(day, 0.17)
            rows.append(method_night("Pusher-v4", f"d{day}", "oril", seed, oril, -30.5, -30.0, lr=3e-4))
            rows.append(method_night("Pusher-v4", f"d{day}", "x", seed, oril, -31.5, -30.0, lr=3e-4))  # 1.5 below
    for variant, lr in (("bc", 5e-6), ("sham", 5e-6), ("dwbc", 1e-4)):  # a second budget: one day so far
        rows.append(method_night("Pusher-v4", "d1", variant, 1, 0.1, -30.0, -30.0, lr=lr, steps=50000))
    for day in (1, 2):
        write_streams(tmp_path, f"v5d{day}", [-40.0])
        for variant in ("bc", "sham", "dwbc"):
            rows.append(method_night("Pusher-v5", f"v5d{day}", variant, 1, 0.3, -40.0, -40.0))
    for variant in ("bc", "sham"):  # a day of the controls alone, without TAMER's streams: not one of the rule's days
        rows.append(method_night("Pusher-v4", "d9", variant, 1, 0.5, -50.0, -30.0))
    args = ss.Args(results_dir=str(tmp_path), campaign="c")
    text = ss.method_rule(args, rows, ["dwbc", "oril", "x"])
    rule, deterministic = text.split("the deterministic test beside it")
    table = {tuple(c.strip() for c in line.strip("| ").split(" | ")[:3]): line.strip("| ").split(" | ")
             for line in rule.splitlines() if line.startswith("| Pusher")}  # fmt: skip
    dwbc, oril = table[("Pusher-v4", "5000", "dwbc (0.0001)")], table[("Pusher-v4", "5000", "oril (0.0003)")]
    assert dwbc[4].startswith("-0.0198 m") and "closer on 5 of 5" in dwbc[4] and dwbc[5] == "not run"
    assert dwbc[6].startswith("-0.0018 m") and "closer on 4 of 5" in dwbc[6] and dwbc[8] == "no"
    assert dwbc[9] == "open: no cloning control at 0.0001"
    assert oril[5].startswith("bc_lr3e-4: -0.0098 m") and "closer on 5 of 5" in oril[5]
    assert oril[7] == "-0.50 (spread 1.00)" and oril[8:] == ["yes", "yes"]
    assert table[("Pusher-v4", "5000", "x (0.0003)")][7:] == ["-1.50 (spread 1.00)", "no", "no"]  # loses the task
    longer = table[("Pusher-v4", "50000", "dwbc (0.0001)")]
    assert longer[3] == "1" and longer[8] == "open: 1 of 5 days"
    v5 = table[("Pusher-v5", "5000", "dwbc (5e-06)")]
    assert v5[3] == "2" and v5[8] == "open: 2 of 5 days" and v5[5].startswith("bc: ")  # bc shares its step size
    # oril's deterministic distances minus bc's: -0.03, -0.029, -0.03, -0.03, -0.07: mean -0.0378, sd 0.0180, se
    # 0.00805; t_0.975 with 4 degrees of freedom 2.776: -0.0378 -+ 0.0224; detectable (2.776 + 0.941) x se = 0.0299
    oril_vs_bc = "-0.0378 m, p = 0.0093, closer on 5 of 5; 95% interval -0.0602 to -0.0154 m, detectable 0.0299 m"
    assert f"| Pusher-v4 | 5000 | oril | 5 | {oril_vs_bc} | -0.0098 m" in deterministic
    assert "Pusher-v4, 5000 gradient steps, the means over the 5 days" in text
    assert "Pusher-v5, 5000 gradient steps, the means over the 2 days" in text
    os.remove(tmp_path / "c" / "d3" / "tamer_streams.json")
    without = ss.method_rule(args, rows, ["oril"])
    assert "(spread no tamer_streams.json) | open: TAMER's streams not run | open: TAMER's streams not run |" in without
    assert "no night of a method" in ss.method_rule(args, rows, [])


def test_the_rules_means_average_the_day_means_and_count_the_nights_that_succeed():
    """TAMER on d1: -30, a success, 0.20 m, -31 sampled; on d2: -40, no success, 0.30 m, -41. dwbc's nights on d1:
    (-20, success, 0.10 m, -21) and (-22, none, 0.12 m, -23); on d2 one night: (-24, success, 0.14 m, -25). Day means
    -21 and -24, so -22.50 (the nights' mean would be -22.00); 0.11 and 0.14, so 0.125 m; -22 and -25, so -23.50; 2
    of 3 nights. bc ran on d1 alone: left out."""
    keys = ("eval/{p}_return", "eval/{p}_success_rate", "eval/obstacle/{p}_final_distance", "eval/{p}_return_sampled")
    tamer = {"d1": (-30.0, 1.0, 0.20, -31.0), "d2": (-40.0, 0.0, 0.30, -41.0)}

    def row(day, variant, seed, values):
        r = {"day": day, "variant": variant, "sleep_seed": seed}
        r.update({key.format(p="tamer"): value for key, value in zip(keys, tamer[day], strict=True)})
        return {**r, **{key.format(p="inform"): value for key, value in zip(keys, values, strict=True)}}

    rows = [row("d1", "dwbc", 1, (-20.0, 1.0, 0.10, -21.0)), row("d1", "dwbc", 2, (-22.0, 0.0, 0.12, -23.0)),
            row("d2", "dwbc", 1, (-24.0, 1.0, 0.14, -25.0)),
            row("d1", "bc", 1, (-10.0, 1.0, 0.05, -11.0))]  # fmt: skip
    lines = ss.rule_means(rows, ["dwbc", "bc"])
    assert lines[2:] == ["| tamer | -35.00 | 1 of 2 days | 0.250 m | -36.00 |",
                         "| dwbc | -22.50 | 2 of 3 nights | 0.125 m | -23.50 |"]  # fmt: skip


def test_the_per_day_table_averages_a_variants_nights_and_counts_their_successes():
    keys = ("eval/{p}_return", "eval/{p}_success_rate", "eval/obstacle/{p}_final_distance")

    def row(day, seed, variant, values, sleep_seed=1):
        r = {"day": day, "seed": seed, "variant": variant, "sleep_seed": sleep_seed}
        r.update({key.format(p="inform"): value for key, value in zip(keys, values, strict=True)})
        return {**r, **{key.format(p="tamer"): value for key, value in zip(keys, (-30.0, 0.0, 0.2), strict=True)}}

    rows = [row("d7", 7, "default", (-40.0, 0.0, 0.3)), row("d7", 7, "bc", (-26.0, 1.0, 0.1)),
            row("d7", 7, "bc", (-28.0, 0.0, 0.2), 2), row("d2", 2, "default", (-20.0, 1.0, 0.05))]  # fmt: skip
    lines = ss.per_day(rows, ["default", "bc"]).splitlines()
    assert lines[3] == "| 2 | -30.00 (0/1), 0.200 m | -20.00 (1/1), 0.050 m | - |"  # days by seed; no bc on day 2
    assert lines[4] == "| 7 | -30.00 (0/1), 0.200 m | -40.00 (0/1), 0.300 m | -27.00 (1/2), 0.150 m |"


def test_the_interval_beside_each_p_is_paired_over_the_days():
    """Issue 70: beside each p, the 95% interval and the smallest effect detectable at 80% power, both from the days'
    paired differences. Days far apart (the control at 0.10, 0.20 and 0.30 m) with the night 0.010, 0.012 and 0.011 m
    closer each day: paired, mean -0.011, sd 0.001, se 0.000577, t_0.975 with 2 degrees of freedom 4.303, so the
    interval is -0.0135 to -0.0085 and the detectable effect (4.303 + t_0.8 = 1.061) x se = 0.0031; on the two sets
    unpaired the interval would span +-0.25 m and include 0. Then the words: 'equivalent' when the interval lies within
    TAMER's spread, 'cannot tell' when it is wider than the room left."""
    theirs = {"a": 0.10, "b": 0.20, "c": 0.30}
    mine = {"a": 0.090, "b": 0.188, "c": 0.289}
    text, passes = ss.versus(mine, theirs, ["a", "b", "c"])
    assert text == "-0.0110 m, p = 0.0027, closer on 3 of 3; 95% interval -0.0135 to -0.0085 m, detectable 0.0031 m"
    assert passes
    stats = ss.paired_interval([mine[d] - theirs[d] for d in theirs])
    from scipy.stats import ttest_ind

    unpaired = ttest_ind(list(mine.values()), list(theirs.values()))
    assert unpaired.pvalue > 0.8 and stats["high"] < 0  # what pairing keeps: the interval excludes 0
    assert ss.interval_verdict(stats, spread=0.02, headroom=None) == "equivalent"
    assert ss.interval_verdict(stats, spread=0.005, headroom=0.004) == "cannot tell"
    assert ss.interval_verdict(stats, spread=0.005, headroom=0.01) == ""
    assert ss.versus(mine, theirs, ["a", "b", "c"], 0.02, None)[0].endswith("detectable 0.0031 m, equivalent")
    assert ss.paired_interval([0.01]) is None
    assert ss.versus(mine, theirs, ["a"])[0] == "-0.0100 m, p = -, closer on 1 of 1"  # one day: no interval
