"""A person teaches INFORM on the Pusher through a web page: inform_sac_pusher.py's run, with the person at the page
(browser_teacher.py) in place of the simulated teacher. The page shows the arm, the object and the goal at `--pace`
steps a second; the person answers Yes or No whenever the arm does well or badly (button, or keys y, n). An answer is
about what the page showed 0.2-4 s before it (`--credit-delay`, Deep TAMER's window, which weighs each step by the
chance that the delay fell while it was on the screen). A step's label is the credit-weighted mean of the answers
about it (yes 1, no 0, or -1 with `--no-label -1`, TAMER's signed answer): Deep TAMER trains on each answer with its
weight, and a squared loss on one label a step has the same minimum. A step no answer is about keeps 0, the paper's
"no feedback" (by default also a No's label). "End the day" (or closing
the page, or `--tamer-total-timesteps` steps) starts the night (the day starts when the page is opened); the page then
shows TAMER's and INFORM's episodes from the run's start and the final numbers. Everything else is the core script's
run: the same summary.json, the same flags (a person's day is shorter by default), --save-buffer for nights on the
day.

    python -m inform_utils.browser_pusher --participant P01            # prints the page's address
    python -m inform_utils.browser_pusher --participant P01 --host 0.0.0.0:8000 --pace 5 --save-buffer

The page says the task, shows the table from above turned as the 3D view (the arm's base, its reach, the fingertip,
the object and the goal), the steps and time left in the day and whether it keeps its pace, and the keys. A person who
takes the arm (t, or a click on the map) moves the fingertip's target; one beyond the arm's reach is held on it, and
the page says so. One tab drives: a second tab watches, as a second browser does. With `--drive-by object` (shared
autonomy) the target is where the object should go, and a planner on the true model (MPPI) pushes it there.

The take-over as a signal (RLIF, Luo et al. ICLR 2024: the agent's action before a person takes over earns -1):
`--takeover-steps k` gives the agent's last k actions of the episode before each take the label `--takeover-label`
(-1 by default; 0 steps, the default: off), which stands over any answer about them. `--no-driven-in-h` keeps the
steps the person drove out of H's regression (DayWithoutDriven); they stay in the buffer, marked, for the night.

Every answer is a line of runs/{run}/answers.jsonl (its time, step, action and the frame shown), and so is every
drive of the arm and, with --takeover-steps, every take's labelled steps ("event": "take labels"). The core script
stays within its flag budget; this module holds the page's flags (as inform_utils/sleep_variants_pusher.py holds the
study's), each marked DAY, so a saved day and summary.json record them.
"""

import os
import signal


def stopped_while_starting(signum, frame):  # a stop before the run directory exists: one line, nothing to save
    os.write(2, f"interrupted ({signal.Signals(signum).name}) while starting; no run was made\n".encode())
    os._exit(128 + signum)


if __name__ == "__main__":  # before the slow imports, so that no stop ends in a traceback
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        if signal.getsignal(sig) is not signal.SIG_IGN:
            signal.signal(sig, stopped_while_starting)

import copy  # noqa: E402
import importlib.util  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from typing import Annotated, Literal  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
import tyro  # noqa: E402

import inform_sac_pusher as isp  # noqa: E402

FRAME_SIZE = 320  # pixels, square: the live view
OUTCOME_SIZE = 240  # pixels: each of the two episodes side by side in the outcome's animation
FRAMES_PER_SECOND = 5.0  # at most this many live frames a second reach the page ("a few")
SIMULATED_ONLY = {"teacher_noise": 0.0, "teacher_sparsity": 1.0, "teacher_delay": 0, "credit_window": 1}


@dataclass
class Args(isp.Args):
    participant: Annotated[str | None, isp.DAY] = None
    """the person's ID, written with each answer into runs/{run}/answers.jsonl"""
    host: str = "127.0.0.1"
    """where the page listens, HOST or HOST:PORT (0.0.0.0: other machines too; no port: any free one)"""
    pace: Annotated[float, isp.In(0, 100, "(]"), isp.DAY] = 10.0
    """env steps a second: how fast the arm moves on the page (a Pusher episode is 100 steps)"""
    credit_delay: Annotated[tuple[float, float], isp.DAY] = (0.2, 4.0)
    """seconds: an answer is about what the page showed this long before it, uniformly (Deep TAMER's window)"""
    no_label: Annotated[float, isp.DAY] = 0.0
    """the label a No gives: 0 (the paper's "no feedback", as a step nobody judged) or -1 (TAMER's negative)"""
    # a person's day, shorter than the simulated teacher's: 6,000 steps are 10 minutes at 10 steps a second
    tamer_total_timesteps: Annotated[int, isp.In(1)] = 6000
    """environment steps of the day at most (the person may end it sooner)"""
    tamer_learning_starts: Annotated[int, isp.In(1)] = 200
    """random-action steps before H and the actor are trained"""
    budget_ends_forward_phase: bool = True
    """the day ends when the person ends it (or the budget of yes answers is spent)"""
    takeover_steps: Annotated[int, isp.In(0), isp.DAY] = 0
    """the take-over as a signal (RLIF): the agent's last this many actions of the episode before each take of the arm
    get --takeover-label (0: off)"""
    takeover_label: Annotated[float, isp.In(-1, 0, "[]"), isp.DAY] = -1.0
    """the label a take gives the steps before it: -1 (RLIF's reward, TAMER's negative answer) or up to 0"""
    drive_by: Annotated[Literal["fingertip", "object"], isp.DAY] = "fingertip"
    """what the person's target moves while they hold the arm: the fingertip (the operational-space controller of
    inform_utils/pusher_control.py), or the object (shared autonomy: MPPI on the true model, inform_utils/pusher_mpc.py,
    pushes the object to the target; the person says when and where, the planner how)"""
    driven_in_h: Annotated[bool, isp.DAY] = True
    """H hears the steps the person drove as yes answers; --no-driven-in-h keeps them out of H's regression (they stay
    in the buffer, marked, for the night)"""

    def day(self, device, space, obs_dim: int) -> isp.Day:
        learner = isp.Day if self.driven_in_h else DayWithoutDriven
        return learner(self.day_settings(), device, space, obs_dim)


class DayWithoutDriven(isp.Day):
    """The day's learner with --no-driven-in-h: H's regression (and the actor's states with it) never samples a step
    the person drove; those stay in the buffer, marked (buffer.driven), for the night."""

    def update(self, buffer: isp.ReplayBuffer, step: int) -> torch.Tensor:
        kept = (~buffer.driven[: step + 1]).nonzero().squeeze(-1)  # the agent's own steps so far
        if kept.numel() == 0:  # the person drove every step so far: nothing for H to hear yet
            return torch.zeros((), device=buffer.obs.device)
        rows = copy.copy(buffer)  # the same buffer with the agent's rows only: the core's update samples among them
        for name in isp.DAY_TENSORS:
            setattr(rows, name, getattr(buffer, name)[kept])
        rows.size = kept.numel()
        return super().update(rows, kept.numel() - 1)


class PageTeacher:
    """The person at the page, with the simulated Teacher's interface: called once a step with the oracle's perfect
    answer h* (kept for the record only) and the action; shows the step and returns {step: label} of the answers
    that arrived since. `gone`: the person ended the day, closed the page, or spent the budget. `drive`: while the
    person holds the arm, the step's action is theirs (the fingertip controller towards their target, or with
    --drive-by object the planner's, pushing the object towards it), and H hears
    it as a yes: a person's own action is what they would have answered yes to (docs/protocol.md). With
    --takeover-steps, a take also labels the agent's last steps before it (RLIF's signal; `labelled`)."""

    def __init__(self, args: Args, env, run_dir: str):
        import browser_teacher
        from inform_utils.pusher_control import PersonHand, arm_reach

        base, radius = arm_reach(env.unwrapped.model)  # a target beyond it: the fingertip would stop short, above
        host, port = browser_teacher.host_and_port(args.host)
        self.page = browser_teacher.BrowserTeacher(run_dir, "pusher", host, port, participant=args.participant,
                                                   budget=args.feedback_budget, pace=args.pace,
                                                   delay=args.credit_delay, no_value=args.no_label,
                                                   reach=(tuple(base), radius), drive_by=args.drive_by,
                                                   day_steps=args.tamer_total_timesteps)  # fmt: skip
        signal = {k: getattr(args, k) for k in ("takeover_steps", "takeover_label", "driven_in_h")}
        self.page.note("take-over signal", **signal)
        self.env, self.last_step, self.budget = env, args.tamer_total_timesteps - 1, args.feedback_budget
        self.camera = camera_env(args.env_id, FRAME_SIZE, args.contact)
        self.camera.reset(seed=args.seed)
        self.every = max(1, round(args.pace / FRAMES_PER_SECOND))  # steps between two live frames
        self.frame = None
        self.credited: dict[int, tuple[float, float]] = {}  # step: (sum of weight * answer, sum of weights)
        self.positives = self.perfect_positives = 0
        self.hand, self.drove = PersonHand(env, args.drive_by, args.seed), False
        self.takeover_steps, self.takeover_label = args.takeover_steps, args.takeover_label
        # Pusher never terminates: an episode starts every this many steps (forward_phase resets at its TimeLimit)
        self.episode_steps = env.get_wrapper_attr("_max_episode_steps")
        self.last_driven, self.next_step = -1, 0  # the last step the person drove; the step drive() is asked about
        self.labelled: dict[int, float] = {}  # step: the label a take gave it (an answer about it later moves it not)

    def wait_for_person(self) -> None:  # the day starts when the person opens the page (a stop ends the wait)
        while not self.page.person_here(0.2):
            isp.StopSignals.check()

    @property
    def gone(self) -> bool:
        spent = self.budget is not None and self.positives >= self.budget
        return self.page.ended is not None or spent

    def drive(self, obs_t: torch.Tensor) -> torch.Tensor | None:
        """The person's action while they hold the arm: joint torques that bring the fingertip to their target (the
        operational-space controller of inform_utils/pusher_control.py, within the action limits), or with --drive-by
        object the planner's towards the object at their target; None otherwise."""
        target, was = self.page.target, self.drove
        self.drove = self.page.driving and target is not None and not self.gone
        if not self.drove:
            return None
        if not was or self.next_step % self.episode_steps == 0:  # a new take, or a new episode's start under it
            self.hand.take()
        return torch.as_tensor(self.hand(obs_t.cpu().numpy(), target), dtype=torch.float32, device=obs_t.device)

    def __call__(self, step: int, h_star: float, action=None) -> dict[int, float]:
        self.perfect_positives += int(h_star > 0)
        self.next_step = step + 1
        if step % self.every == 0 or self.frame is None:  # the camera's copy of the arm, where the day's arm is
            data = self.env.unwrapped.data
            self.camera.unwrapped.set_state(data.qpos.copy(), data.qvel.copy())
            self.frame = self.camera.render()
        obs = self.env.unwrapped._get_obs()
        info = {"object to goal": f"{np.linalg.norm(obs[17:20] - obs[20:23]):.2f} m"}  # Pusher's observation
        info.update(_obs=obs.tolist(), _action=None if action is None else action.tolist())  # for a script's eyes
        info["_map"] = {"tip": obs[14:16].tolist(), "object": obs[17:19].tolist(), "goal": obs[20:22].tolist()}
        self.page.show(step, self.frame, action=info["_action"], info=info)
        if step == self.last_step:  # first: an answer the page took before the end is among those below
            self.page.end_day("the day's steps are done")
        answers = [a for a in self.page.answers() if a.value is not None]
        self.positives += sum(a.value > 0 for a in answers)
        if self.budget is not None and self.positives >= self.budget:  # the page's record says so, not "day done"
            self.page.end_day("the budget of yes answers is spent")
        labels = weighted_labels(self.credited, [(a.value, self.page.credit(a)) for a in answers])
        if self.drove:  # the person's own step: a yes, weighed with any answer about it
            labels.update(weighted_labels(self.credited, [(1.0, {step: 1.0})]))
            if self.takeover_steps and self.last_driven < step - 1:  # the first step of a take
                labels.update(self.label_take(step))
            self.last_driven = step
        labels.update({t: self.labelled[t] for t in labels.keys() & self.labelled.keys()})
        return {t: h for t, h in labels.items() if t <= step}

    def label_take(self, step: int) -> dict[int, float]:
        """RLIF's signal: the person took the arm at `step`, so the agent's last `takeover_steps` actions of the
        episode before it get `takeover_label` (a line of answers.jsonl says which); {step: label} of those."""
        first = max(step - self.takeover_steps, step - step % self.episode_steps, self.last_driven + 1)
        taken = dict.fromkeys(range(first, step), self.takeover_label)
        self.labelled.update(taken)
        self.page.note("take labels", step=step, label=self.takeover_label, steps=list(taken))
        return taken


def weighted_labels(credited: dict, answers: list[tuple[float, dict]]) -> dict[int, float]:
    """{step: label} of the steps that `answers` ((value, {step: credit weight}) each) are about: the weighted mean
    of every answer about the step so far; `credited` keeps (sum of weight * value, sum of weights) per step."""
    labels = {}
    for value, weights in answers:
        for t, weight in weights.items():
            total, seen = credited.get(t, (0.0, 0.0))
            credited[t] = (total + weight * value, seen + weight)
            labels[t] = credited[t][0] / credited[t][1]
    return labels


def camera_env(env_id: str, size: int, contact: str) -> gym.Env:
    """The env, rendering from the videos' camera (the core's, v4 and v5 alike: it looks down on the table from
    behind the goal, image up is -x): the day's state is copied in (set_state) to film it."""
    return isp.make_env(env_id, 0, contact=contact, render_mode="rgb_array", width=size, height=size)


def outcome(run_dir: str, args: Args, summary: dict, labelled: int = 0) -> tuple[str, list]:
    """The night's outcome for the page: the final numbers (`labelled`: the steps the takes labelled), and TAMER's and
    INFORM's deterministic episodes from the run's start, side by side."""
    if summary.get("status") != "completed":
        return f"the run ended: {summary.get('status')} ({summary.get('error', '')})", []
    yes, perfect, steps = (summary[f"feedback/{k}"] for k in ("positive", "perfect_positive", "steps"))
    driven = summary.get("feedback/driven_steps", 0)
    heard = "H heard each as a yes" if args.driven_in_h else "kept out of H, for the night"
    lines = [f"{yes} yes answers and {driven} steps you drove ({heard}) over the day's {steps} steps (the oracle, "
             f"Eq. 4, would have said yes on {perfect})"]  # fmt: skip
    if args.takeover_steps:
        lines.append(f"{labelled} of the agent's steps labelled {args.takeover_label:g} by your takes of the arm")
    lines.append("below, from the run's start: TAMER (left) and INFORM (right)")
    for p in ("tamer", "inform"):
        distance, success = summary[f"eval/{p}_final_distance"], summary[f"eval/{p}_success_rate"]
        lines.append(f"{p.upper():>6}: object {distance:.3f} m from the goal at the end, success {success:.2f}")
    films = []
    for p in ("tamer", "inform"):
        actor = isp.actor_from_checkpoint(torch.load(f"{run_dir}/{p}_actor.pt", weights_only=True))
        env = gym.wrappers.RenderCollection(camera_env(args.env_id, OUTCOME_SIZE, args.contact))
        isp.evaluate(actor, env, 1, lambda ep: args.seed, True, torch.Generator(), args.outcome())
        films.append(env.render()[::2])  # every second frame: 10 a second at 20 steps a second
        env.close()
    n = min(map(len, films))
    return "\n".join(lines), [np.concatenate([films[0][i], films[1][i]], axis=1) for i in range(n)]


def how_the_day_ended(summary: dict) -> str:
    """Why the day ended, for answers.jsonl, when the page had not ended it itself (the button, a closed page, the
    day's steps, the budget): the run's status, "interrupted (SIGINT) during the tamer phase" and the like."""
    status = summary.get("status")
    if status == "interrupted":
        return f"interrupted ({summary.get('signal')}) during the {summary.get('phase')} phase"
    return "day done" if status == "completed" else f"the run {status} during the {summary.get('phase')} phase"


def check_page_args(args: Args) -> None:
    """What the core's check_args does not know: the page's flags, and the simulated teacher's that do not apply."""
    if importlib.util.find_spec("browser_teacher") is None:
        raise isp.InputError("the web page needs browser_teacher.py: run from the repository (python -m ...)")
    import browser_teacher

    low, high = args.credit_delay
    if not (0 <= low < high and math.isfinite(high)):
        raise isp.InputError(f"--credit-delay must be LOW HIGH seconds with 0 <= LOW < HIGH, got {low} {high}")
    if args.no_label not in (0.0, -1.0):
        raise isp.InputError(f"--no-label must be 0 (no feedback) or -1 (TAMER's negative answer), got {args.no_label}")
    changed = [f"--{k.replace('_', '-')}" for k, v in SIMULATED_ONLY.items() if getattr(args, k) != v]
    if changed:
        raise isp.InputError(f"{', '.join(changed)}: the simulated teacher's; the page takes the person's answers as "
                             "they are (--credit-delay sets their window)")  # fmt: skip
    if args.env_id not in isp.PUSHER_IDS:
        raise isp.InputError(f"--env-id {args.env_id}: the page shows the Pusher only ({', '.join(isp.PUSHER_IDS)})")
    if args.sleep_from is not None:
        raise isp.InputError("--sleep-from: a night on a saved day needs no person; run inform_sac_pusher.py")
    try:
        browser_teacher.check_address(*browser_teacher.host_and_port(args.host))
    except ValueError as e:
        raise isp.InputError(str(e)) from None


def main() -> int:
    args = tyro.cli(Args)
    try:
        check_page_args(args)
        isp.check_video(args.env_id)  # the page shows rendered frames: the same headless GL check
    except isp.InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    teachers = []

    def make_teacher(run_args, env, run_dir):
        teachers.append((PageTeacher(run_args, env, run_dir), run_dir))  # first: the page is closed at the end
        teachers[-1][0].wait_for_person()
        return teachers[-1][0]

    code = isp.cli(args, make_teacher=make_teacher)
    if teachers:  # the page shows what came of the night, then stops
        teacher, run_dir = teachers[0]
        try:
            with open(f"{run_dir}/summary.json") as f:
                summary = json.load(f)
            teacher.page.end_day(how_the_day_ended(summary))  # if the day was still on (a stop, a failure)
            text, frames = outcome(run_dir, args, summary, len(teacher.labelled))
            teacher.page.show_outcome(text, image=frames or None)
        except (OSError, ValueError, KeyboardInterrupt) as e:  # no summary (a stop at once), or a second stop
            teacher.page.end_day(f"the run ended without a summary ({type(e).__name__})")
            teacher.page.show_outcome(f"the run ended without an outcome to show ({type(e).__name__})")
        finally:
            teacher.page.close()
    return code


if __name__ == "__main__":
    sys.exit(main())
