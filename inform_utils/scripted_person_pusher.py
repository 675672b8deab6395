"""The web page's reference numbers on the Pusher: a scripted person teaches `python -m inform_utils.browser_pusher`
through the page in Debian's Chromium (headless, driven by Playwright). It answers at a person's rate: it looks at the
step on the screen (at most `--period` seconds apart), judges it as the run's oracle would (Eq. 4 on the state and
action the page was sent, at the day's alpha), and presses y or n after a reaction time drawn uniformly from
`--reaction`. The page credits each answer to what it showed 0.2-4 s before (Deep TAMER's window). The day is the
runner's: `--tamer-total-timesteps` steps at `--pace` steps a second (the defaults: 3,000 steps at 10 a second, five
minutes), then the night. Then, per seed, three more nights on the saved day (inform_utils/sleep_variants_pusher.py
--sleep-from): behaviour cloning (bc), the sham (TAMER's own update) and the core night again. Per seed and their
mean: the answers (yes, no), and TAMER, INFORM and both controls: the final distance and success from the run's start.

    python -m inform_utils.scripted_person_pusher --seeds 1 2 3 4 5 --out-dir results/browser_pusher

{out_dir}/table.md and table.json, and each seed's summary.json (the day's, and each night's as
summary_{bc,sham,core}.json) and answers.jsonl under {out_dir}/seed{S}/; the runs themselves in a temporary directory,
removed, or kept in --work-dir. Neither directory may exist: nothing is overwritten.
"""

import contextlib
import json
import os
import random
import shlex
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field

import tyro

from inform_utils.scripted_person_browser import REPO, Child, check_before_writing, each_seed, new_run, runs_in

POLICIES = ("tamer", "inform", "bc", "sham", "core")  # the day's two, then the nights on the saved day
CONTROLS = ("bc", "sham", "core")  # --sleep-control bc, sham, none


@dataclass
class Args:
    seeds: list[int] = field(default_factory=lambda: [1, 2, 3, 4, 5])
    """seeds of the days taught, one after the other"""
    out_dir: str = "results/browser_pusher"
    """where the table and each seed's summary.json and answers.jsonl go; it must not exist"""
    work_dir: str | None = None
    """keep the runs in {work_dir}/seed{S}/runs/; it must not exist (default: a temporary directory, removed)"""
    steps: int = 3000
    """the day's environment steps (the runner's --tamer-total-timesteps)"""
    pace: float = 10.0
    """steps a second on the page (the runner's --pace)"""
    period: float = 1.0
    """the longest time from one look at the screen to the next (each look gives one answer): after its key press
    the person waits period minus the longest reaction, so at the defaults it looks every 0.5-1.0 s"""
    reaction: tuple[float, float] = (0.3, 0.8)
    """seconds from a look to the key press, uniformly"""
    flags: str = ""
    """extra flags for the day's run and the nights, as one string (e.g. --flags "--obstacle-episodes 20")"""
    timeout: float = 3600.0
    """seconds a seed may take, day and nights"""


def judge(oracle, state: dict, alpha: tuple[float, float], steps: int) -> bool:
    """The oracle's answer (Eq. 4) about the state and action the page was sent for its current step."""
    import torch

    import inform_sac_pusher as isp

    obs = torch.as_tensor(state["info"]["_obs"], dtype=torch.float32)
    action = torch.as_tensor(state["info"]["_action"], dtype=torch.float32)
    with torch.no_grad():
        q_sa, q_best = isp.oracle_q(*oracle, obs, action)
    return bool(isp.oracle_feedback(q_sa, q_best, isp.linear_schedule(*alpha, steps - 1, state["step"])))


def teach_day(page, oracle, seed: int, args: Args, say) -> dict:
    """Look and answer until the page says the day is over; the answers given."""
    rng, given = random.Random(seed), {"yes": 0, "no": 0}
    state, deadline = None, time.monotonic() + 300
    while state is None or state["mode"] not in ("stream", "ended", "outcome", "closed"):  # the day starts
        if time.monotonic() > deadline:
            raise RuntimeError(f"the page did not start streaming within 300 s (its state: {state})")
        time.sleep(0.2)
        state = page.evaluate("typeof state === 'undefined' ? null : state")  # (the page's CSP forbids polling JS)
    while True:
        state = page.evaluate("state")
        if state["ended"] or state["mode"] != "stream":
            break
        if state["info"].get("_action") is not None:
            yes = judge(oracle, state, (0.99, 0.992), args.steps)
            time.sleep(rng.uniform(*args.reaction))
            page.keyboard.press("y" if yes else "n")
            given["yes" if yes else "no"] += 1
            if sum(given.values()) % 60 == 0:
                say(f"[seed {seed}] day: step {state['step']}, answers yes {given['yes']}, no {given['no']}")
        time.sleep(max(0.0, args.period - args.reaction[1]))
    say(f"[seed {seed}] the day is over ({state['ended'] or state['mode']}): yes {given['yes']}, no {given['no']}")
    return given


def load_oracle(run_flags: list[str]):
    """The oracle the runs load (the shipped one of the --env-id in `run_flags`), to judge as it does."""
    import torch

    import inform_sac_pusher as isp

    env_id = next((run_flags[i + 1] for i, f in enumerate(run_flags[:-1]) if f == "--env-id"), "Pusher-v5")
    ckpt = isp.read_checkpoint(os.path.join(REPO, "oracles", f"{env_id}__sac_oracle.pt"), "--oracle-path", env_id)
    return isp.oracle_from_checkpoint(ckpt, torch.device("cpu"))


def run_seed(seed: int, args: Args, browser, oracle, work: str, out: str, say) -> dict:
    cwd = os.path.join(work, f"seed{seed}")
    os.makedirs(cwd)
    deadline, t0 = time.monotonic() + args.timeout, time.monotonic()
    cmd = [sys.executable, "-m", "inform_utils.browser_pusher", "--participant", "scripted", "--seed", str(seed),
           "--tamer-total-timesteps", str(args.steps), "--pace", str(args.pace), "--save-buffer",
           "--exp-name", "browser_scripted", *shlex.split(args.flags)]  # fmt: skip
    child, context = Child(cmd, cwd, os.path.join(cwd, "day.log")), None
    try:
        url = child.wait_for_line("[teacher] open the teaching page", timeout=300).split(": ", 1)[1].strip()
        context = browser.new_context(viewport={"width": 900, "height": 900})
        page = context.new_page()
        page.goto(url)
        given = teach_day(page, oracle, seed, args, say)
        page.wait_for_selector("#outcome:visible", timeout=max(deadline - time.monotonic(), 1) * 1000)
        code = child.finish(deadline - time.monotonic())
    except BaseException:
        with contextlib.suppress(subprocess.TimeoutExpired):
            child.finish(0)  # kills it
        say("".join(child.tail[-20:]))
        raise
    finally:
        if context is not None:
            context.close()
    if code != 0:
        raise RuntimeError(f"seed {seed}: the day's run exited {code}; {cwd}/day.log\n{''.join(child.tail)}")
    run = new_run(cwd, set())
    os.makedirs(os.path.join(out, f"seed{seed}"))
    for name in ("summary.json", "answers.jsonl"):
        shutil.copy(os.path.join(run, name), os.path.join(out, f"seed{seed}", name))
    with open(os.path.join(run, "summary.json")) as f:
        summaries = {"day": json.load(f)}
    for name in CONTROLS:
        before = runs_in(cwd)
        control = "none" if name == "core" else name
        cmd = [sys.executable, "-m", "inform_utils.sleep_variants_pusher", "--sleep-from", run, "--sleep-control",
               control, "--exp-name", f"browser_scripted_{name}", *shlex.split(args.flags)]  # fmt: skip
        night = Child(cmd, cwd, os.path.join(cwd, f"night_{name}.log"))
        if night.finish(deadline - time.monotonic()) != 0:
            raise RuntimeError(f"seed {seed}: the {name} night failed; {cwd}/night_{name}.log\n{''.join(night.tail)}")
        shutil.copy(os.path.join(new_run(cwd, before), "summary.json"),
                    os.path.join(out, f"seed{seed}", f"summary_{name}.json"))  # fmt: skip
        with open(os.path.join(new_run(cwd, before), "summary.json")) as f:
            summaries[name] = json.load(f)
    row = seed_row(seed, given, summaries)
    row["seconds"] = round(time.monotonic() - t0, 1)
    say(f"[seed {seed}] done in {row['seconds']:.0f}s: " + ", ".join(f"{k} {v}" for k, v in row.items()))
    return row


def seed_row(seed: int, given: dict, summaries: dict) -> dict:
    day = summaries["day"]
    row = {"seed": seed, "answers": given["yes"] + given["no"], "yes": given["yes"]}
    row.update({"steps": day["feedback/steps"], "yes labels reaching TAMER": day["feedback/positive"]})
    for p in POLICIES:
        s, slot = (day, p) if p in ("tamer", "inform") else (summaries[p], "inform")
        row[f"{p} distance"] = round(s[f"eval/{slot}_final_distance"], 4)
        row[f"{p} success"] = s[f"eval/{slot}_success_rate"]
    row["oracle distance"] = round(day["eval/oracle_final_distance"], 4)
    return row


def markdown(rows: list[dict], command: str) -> str:
    keys = list(rows[0])
    mean = {k: round(sum(r[k] for r in rows) / len(rows), 4) for k in keys if k != "seed"}
    lines = [f"`{command}`", "", "| " + " | ".join(keys) + " |", "|" + " --- |" * len(keys)]
    lines += ["| " + " | ".join(str(r[k]) for k in keys) + " |" for r in rows]
    lines.append("| mean | " + " | ".join(str(mean[k]) for k in keys[1:]) + " |")
    return "\n".join(lines) + "\n"


def say(text: str) -> None:
    print(text, flush=True)


def main(args: Args) -> list[dict]:
    check_before_writing(args)
    oracle = load_oracle(shlex.split(args.flags))
    what = f"the scripted person teaches the Pusher, seeds {args.seeds}, at the page"

    def run_one(seed, browser, work):
        return run_seed(seed, args, browser, oracle, work, args.out_dir, say)

    rows = each_seed(args, "scripted_person_pusher_", what, run_one)
    text = markdown(rows, "python -m inform_utils.scripted_person_pusher " + " ".join(sys.argv[1:]))
    with open(os.path.join(args.out_dir, "table.md"), "w") as f:
        f.write(text)
    with open(os.path.join(args.out_dir, "table.json"), "w") as f:
        json.dump(rows, f, indent=1)
    say("\n" + text)
    return rows


if __name__ == "__main__":
    main(tyro.cli(Args))
