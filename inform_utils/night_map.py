"""Where the night helps: a map of the day's quality (the paper's open question on "the quality and amount of data
for the consolidation to be effective"). Each cell of the map is one sleep_study campaign: the nights on five days of
one quality (on the maze, TAMER's length and teacher; on the Pusher, TAMER's steps). This module judges each cell's
nights against both controls by the map's rule, prints the table and draws the figure. It runs no night.

The map's rule (fixed before the first night of the map; docs/protocol.md, "The map of the day's quality"): per cell
and night (the default IQ-Learn night; on the Pusher also DWBC as released), on a measure with room to gain (the
Pusher: the final distance over the random-start test's held-out starts, deterministic actions; the maze: the success
rate from the ten held-out start cells), the night consolidates if it is better than each control (cloning the
success set at the default night's step size; the sham) with p < 0.05 by the paired t-test over the cell's days, on
all five days, and does not lose the plain task beyond TAMER's spread (the Pusher: the fixed start's sampled return
against TAMER's sampling spread; the maze: the length from S, one step). Beside every p: the paired 95% interval and the
smallest effect detectable at 80% power, "equivalent" where the interval lies within the bar (these tests are
deterministic, so TAMER has no sampling spread on them: the bar is the default night's spread between its sleep
seeds, at least one unit of the measure) and "cannot tell" where it is wider than the room left (the expert's value
on the same starts minus the control's).

    python -m inform_utils.night_map --script inform_dqn_gridworld.py --map-dir results/map_maze
    python -m inform_utils.night_map --map-dir results/map_v4 --figure docs/figures/night_map_v4.png  # .venv-v4
"""

import glob
import os
import re
import statistics
from dataclasses import dataclass, replace
from typing import Literal

import tyro

from inform_utils import sleep_study as ss
from inform_utils.files import BadInput, read_json, run_tool, write_json

MAP_P, MAP_DAYS = 0.05, 5  # the rule: p < MAP_P against each control, over all MAP_DAYS days of a cell
CONTROLS = ("bc", "sham")
NIGHTS = ("default", "dwbc")  # the nights judged (the controls are no candidates)


@dataclass(frozen=True)
class Measure:
    """The map's measure of a script (key with {p}: the policy), the one printed beside it, and the plain task's."""

    name: str
    key: str
    sign: int  # +1: higher is better
    unit: str
    floor: float  # one unit of the measure: the least bar
    beside: tuple[tuple[str, str, int], ...]  # (name, key, sign) of each measure printed beside (not the rule's)
    day_size: tuple[str, str]  # (what the day's success set is counted in, its summary key)
    plain: tuple[str, str, int, float | None]  # (name, key, sign, TAMER's spread on it if a constant, else None)


MEASURES = {
    "inform_sac_pusher.py": Measure(
        name="random-start final distance", key="random_starts/{p}_final_distance", sign=-1, unit=" m", floor=0.0,
        beside=(("random-start success", "random_starts/{p}_success_rate", 1),
                ("random-start final distance, sampled actions", "random_starts/{p}_final_distance_sampled", -1),
                ("fixed start with the boxes, distance", ss.OBSTACLE, -1),
                ("fixed start, the authors' sampled test, distance", "eval/authors_test/{p}_final_distance", -1)),
        day_size=("successful episodes", "sleep/success_episodes"),
        plain=("fixed-start sampled return", ss.SAMPLED, 1, None),
    ),
    "inform_dqn_gridworld.py": Measure(
        name="held-out start cells: success", key="eval/start_set/{p}_success_rate", sign=1, unit="", floor=0.1,
        beside=(("all 29 cells: success", "eval/all_starts/{p}_success_rate", 1),),
        day_size=("success-set transitions", "sleep/expert_transitions"),
        plain=("length from S", "eval/{p}_episode_length", -1, 1.0),
    ),
}  # fmt: skip


@dataclass
class Args:
    map_dir: str = "results/map_maze"
    """the map's folder: one sleep_study campaign a cell in it (--results-dir of the study)"""
    script: Literal["inform_sac_pusher.py", "inform_dqn_gridworld.py"] = "inform_sac_pusher.py"
    """the script that made the days and ran the nights"""
    cells: list[str] | None = None
    """the cells' campaigns, in the figure's order (None: every folder named nights_* in --map-dir)"""
    figure: str | None = None
    """draw the figure into this PNG (it must not exist)"""
    run_expert: bool = True
    """on the Pusher: test the expert on each day's random starts where --map-dir does not hold it yet
    (expert_random_starts/seed{S}.json), as the study tests each night's policies"""


# ---------------------------------------------------------------------------------------------------------------------
# ALGO LOGIC: the map's rule, one cell and night at a time


def expert(args: Args, rows: list[dict], key: str) -> dict:
    """{day: the expert's value of the measure on the day's starts}: on the maze the oracle's, as every night records
    it; on the Pusher its random-start test, made once a seed (the starts are the seed's) and kept in the map."""
    if args.script == "inform_dqn_gridworld.py":
        return ss.day_means(rows, "oracle", key)
    out = {}
    for day, night in ss.first_nights(rows).items():
        path = os.path.join(args.map_dir, "expert_random_starts", f"seed{night['seed']}.json")
        if not os.path.isfile(path) and args.run_expert:
            run = night["args"]
            oracle = run.get("oracle_path") or os.path.join(ss.REPO, "oracles", f"{run['env_id']}__sac_oracle.pt")
            cmd = ss.random_start_command(
                oracle, night["seed"], run["env_id"], night["random_starts/episodes"], night.get("contact")
            )  # the nights' own test, on the expert
            try:
                test = ss.last_json(ss.run_child(cmd, ss.Stop()), f"the expert's random-start test of {oracle}")
            except ss.NightFailed as e:  # e.g. a teacher this venv's MuJoCo cannot run: one line, nothing written
                raise BadInput(f"{e}; run it where the days were made (--no-run-expert: without the ceiling)") from None
            os.makedirs(os.path.dirname(path), exist_ok=True)
            write_json(path, {**{k.replace("policy", "oracle"): v for k, v in test.items()}, "command": cmd[1:]})
        if os.path.isfile(path):
            out[day] = read_json(path)[key.format(p="oracle").replace("random_starts/", "eval/")]
    return out


def against(rows: list[dict], night: str, control: str, measure: Measure, bar: float | None, ceiling: dict) -> dict:
    """The night against one control on the cell's days: the paired gains (the measure's own direction: positive =
    better), their interval (ss.paired_interval), the room left (the expert's value minus the control's, over the
    same days) and the interval's word."""
    mine, theirs = ss.day_means(rows, night, measure.key), ss.day_means(rows, control, measure.key)
    days = [d for d in mine if d in theirs]
    gains = [measure.sign * (mine[d] - theirs[d]) for d in days]
    stats = ss.paired_interval(gains)
    room = statistics.mean(measure.sign * (ceiling[d] - theirs[d]) for d in days) if days and set(days) <= set(
        ceiling) else None  # fmt: skip
    word = ss.interval_verdict(stats, bar, room)
    passes = stats is not None and stats["p"] < MAP_P and stats["mean"] > 0
    return {"days": days, "gains": gains, "stats": stats, "room": room, "word": word, "passes": passes}


def plain_task(args: Args, rows: list[dict], night: str, measure: Measure, campaign: str) -> tuple[str, bool]:
    """The plain task: the night's value minus TAMER's (positive: better), the mean over days, within TAMER's spread
    (the Pusher's: its sampled return's range between streams, which the study measured; the maze's: one step)."""
    name, key, sign, spread = measure.plain
    mine, tamer = ss.day_means(rows, night, key), ss.day_means(rows, "tamer", key)
    days = [d for d in mine if d in tamer]
    if not days:
        return "-", False
    if spread is None:
        spread = ss.return_spread(replace(ss.Args(), results_dir=args.map_dir, campaign=campaign), rows)
    gap = statistics.mean(sign * (mine[d] - tamer[d]) for d in days)
    if spread is None:
        return f"{gap:+.2f} (TAMER's spread not measured)", False
    return f"{gap:+.2f} (spread {spread:.2f})", gap >= -spread - ss.TOLERANCE


def judge(args: Args, campaign: str) -> dict | None:
    """One cell: its rows, the day's quality (TAMER's and the expert's value of the measure, the days' successful
    episodes) and, per night, each control's comparison, the plain task and the verdict."""
    study = ss.Args(script=args.script, results_dir=args.map_dir, campaign=campaign)
    rows = ss.scan(study)[0]
    if not rows:
        return None
    measure = MEASURES[args.script]
    ceiling = expert(args, rows, measure.key)
    bar = ss.seed_spread(rows, measure.key.format(p="inform"))
    bar = max(bar or 0.0, measure.floor) or None
    first = ss.first_nights(rows)
    successes = [r.get(measure.day_size[1]) for r in first.values()]
    cell = {"campaign": campaign, "label": campaign.removeprefix("nights_").replace("_", " "), "days": len(first),
            "tamer": ss.day_means(rows, "tamer", measure.key), "expert": ceiling, "successes": successes,
            "bar": bar, "nights": {}}  # fmt: skip
    for night in [n for n in NIGHTS if any(r["variant"] == n for r in rows)]:
        tests = {c: against(rows, night, c, measure, bar, ceiling) for c in CONTROLS}
        plain = plain_task(args, rows, night, measure, campaign)
        beside = [[ss.paired(rows, night, c, key, sign) for c in CONTROLS] for _, key, sign in measure.beside]
        n = min(len(t["days"]) for t in tests.values())
        if all(t["passes"] for t in tests.values()) and plain[1] and n >= MAP_DAYS:
            verdict = "yes"
        elif n < MAP_DAYS:
            verdict = f"no: it ran beside both controls on {n} of {MAP_DAYS} days"
        else:
            words = {t["word"] for t in tests.values()}
            verdict = "no" + (f" ({' and '.join(sorted(w for w in words if w))})" if words - {""} else "")
        value = ss.day_means(rows, night, measure.key)
        tamer = {d: cell["tamer"][d] for d in value if d in cell["tamer"]}  # TAMER on the days this night ran
        cell["nights"][night] = {"tests": tests, "plain": plain, "beside": beside, "verdict": verdict,
                                 "value": value, "tamer": tamer}  # fmt: skip
    return cell


# ---------------------------------------------------------------------------------------------------------------------
# TRY NOT TO MODIFY: the table and the figure


def mean_of(values) -> str:
    values = list(values.values()) if isinstance(values, dict) else [v for v in values if v is not None]
    return f"{statistics.mean(values):.3f}" if values else "-"


def value_text(cell: dict, judged: dict) -> str:
    """The night's value; where it ran on fewer days than the cell holds, TAMER's on those same days beside it (the
    TAMER column is over every day)."""
    text = mean_of(judged["value"])
    if judged["tamer"] and set(judged["tamer"]) != set(cell["tamer"]):
        n = len(judged["tamer"])
        text += f" (TAMER {mean_of(judged['tamer'])} on its {n} day{'s' * (n > 1)})"
    return text


def beside_text(gains: list[float]) -> str:
    """A measure beside the rule's: the mean paired gain over the days, with its p where there are two days or more."""
    stats = ss.paired_interval(gains)
    return "-" if not gains else f"{statistics.mean(gains):+.3f}" + (f" (p = {stats['p']:.2g})" if stats else "")


def comparison_text(test: dict, unit: str) -> str:
    if not test["days"]:
        return "-"
    stats, mean = test["stats"], statistics.mean(test["gains"])
    if stats is None:
        return f"{mean:+.4f}{unit} (one day)"
    words = [f"{mean:+.4f}{unit}, p = {stats['p']:.2g}", ss.interval_text(stats, unit)]
    words += [f"room {test['room']:.3f}{unit}" if test["room"] is not None else "room -"]
    return "; ".join([*words, *([test["word"]] if test["word"] else [])])


def table(args: Args, cells: list[dict]) -> str:
    measure = MEASURES[args.script]
    lines = [f"the map's measure: {measure.name} (gains in its own direction: positive = better); the night "
             f"consolidates if better than each control with p < {MAP_P} over {MAP_DAYS} days and the plain task "
             f"({measure.plain[0]}) within TAMER's spread", ""]  # fmt: skip
    head = ["cell", "days", f"{measure.day_size[0]} a day", "expert", "TAMER", "night", "night's value",
            *(f"vs {c}" for c in CONTROLS), *(f"{name} vs bc, vs sham" for name, _, _ in measure.beside),
            "plain task vs TAMER",
            "consolidates?", "bar"]  # fmt: skip
    lines += ss.table_head(head)
    for cell in cells:
        for night, judged in cell["nights"].items():
            beside = [", ".join(beside_text(g) for g in pair) for pair in judged["beside"]]
            ok = [s for s in cell["successes"] if s is not None]
            lines.append(ss.table_row([
                cell["label"], str(cell["days"]), f"{min(ok)}-{max(ok)}" if ok else "-", mean_of(cell["expert"]),
                mean_of(cell["tamer"]), night, value_text(cell, judged),
                *(comparison_text(judged["tests"][c], measure.unit) for c in CONTROLS), *beside, judged["plain"][0],
                judged["verdict"], "-" if cell["bar"] is None else f"{cell['bar']:.3g}",
            ]))  # fmt: skip
    rules_out = []
    for cell in cells:
        for night, judged in cell["nights"].items():
            highs = [t["stats"]["high"] for t in judged["tests"].values() if t["stats"]]
            if highs:
                rules_out.append(f"{cell['label']}, {night}: {min(highs):+.3f}{measure.unit}")
    lines += ["", "the gain over both controls each cell rules out (95%; a larger gain over both is outside the "
              "smaller upper end of the two intervals): "
              + ("; ".join(rules_out) or "-")]  # fmt: skip
    return "\n".join(lines)


def figure(args: Args, cells: list[dict], path: str) -> None:
    """Each night's gain over each control (mean over the days, the 95% interval) against the day's quality (TAMER's
    value of the measure), one panel a control, the room left (the expert's ceiling) as a dash above each point."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    from inform_utils.plot_results import save

    measure = MEASURES[args.script]
    fig = Figure(figsize=(5.5 * len(CONTROLS), 4.2), layout="constrained")
    qualities = [statistics.mean(c["tamer"].values()) for c in cells if c["tamer"]]
    step = 0.015 * ((max(qualities) - min(qualities) if qualities else 0.0) or 1.0)  # a second night's points
    for ax, control in zip(fig.subplots(1, len(CONTROLS), sharey=True), CONTROLS, strict=True):
        for n, night in enumerate(NIGHTS):
            points = [(c, c["nights"][night]["tests"][control]) for c in cells if night in c["nights"]]
            points = [(c, t) for c, t in points if t["stats"] and c["tamer"]]
            if not points:
                continue
            x = [statistics.mean(c["tamer"].values()) + step * n for c, _ in points]
            y = [t["stats"]["mean"] for _, t in points]
            err = [[t["stats"]["mean"] - t["stats"]["low"] for _, t in points],
                   [t["stats"]["high"] - t["stats"]["mean"] for _, t in points]]  # fmt: skip
            ax.errorbar(x, y, yerr=err, fmt="os"[n], capsize=3, label=f"{night} night")
            for xi, (c, t) in zip(x, points, strict=True):
                if n == 0 or NIGHTS[0] not in c["nights"]:  # a cell named once, over its first night's points
                    ax.annotate(c["label"], (xi, t["stats"]["high"]), fontsize=6, rotation=60, xytext=(2, 2),
                                textcoords="offset points")  # fmt: skip
                if t["room"] is not None:
                    ax.plot(xi, t["room"], marker="_", markersize=14, color="grey", linestyle="none")
        ax.axhline(0.0, color="black", lw=0.8)
        ax.set_title(f"the night's gain over {control} (grey dash: the room left to the expert)", fontsize=8)
        ax.set_xlabel(f"the day's quality: TAMER's {measure.name}{measure.unit}")
    fig.axes[0].set_ylabel(f"gain{measure.unit} (+ = better), 95% interval over days")
    fig.suptitle(f"{measure.name}: the night against each control, cell by cell", fontsize=9)
    fig.axes[0].legend(fontsize=7)
    save(fig, path)


def main(args: Args) -> list[dict]:
    if not os.path.isdir(args.map_dir):
        raise BadInput(f"--map-dir {args.map_dir}: no such folder (the map's campaigns, sleep_study's --results-dir)")
    if args.figure is not None and os.path.lexists(args.figure):
        raise BadInput(f"--figure {args.figure} exists: name a new file")
    found = [os.path.basename(p) for p in glob.glob(os.path.join(args.map_dir, "nights_*"))]
    names = args.cells or sorted(found, key=lambda n: [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", n)])
    cells = [c for c in (judge(args, name) for name in names) if c is not None]
    if not cells:
        raise BadInput(f"--map-dir {args.map_dir}: no completed nights in {', '.join(names) or 'any nights_* folder'}")
    print(table(args, cells))
    if args.figure is not None:
        figure(args, cells, args.figure)
        print(f"figure: {args.figure}")
    return cells


if __name__ == "__main__":
    run_tool(main, tyro.cli(Args))
