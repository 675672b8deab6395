"""No night flag goes unheard: the hack a researcher makes (a new loss term on the core's night, with its flag) is
made on a copy of each core script, and the study module beside it either applies the term (its loss appears in the
summary and the flag in `sleep_variant`) or refuses the flag in one line, exit 2, no run made. Never accepted and
ignored, which is what the study modules did before the night was one object (issue: a flag written into the summary
for a setting that never ran)."""

import glob
import json
import os
import re
import shutil
import subprocess
import sys

import pytest
from conftest import REPO

FLAG = '''    sleep_q_l2_coef: float = 0.0
    """the hack: an L2 penalty on Q(s, a) of the night's batches, with this weight"""

'''
PUSHER_DAY = ["--seed", "3", "--tamer-total-timesteps", "600", "--tamer-learning-starts", "200",
              "--tamer-batch-size", "64", "--feedback-alpha-start", "0.96", "--feedback-alpha-end", "0.98",
              "--success-distance", "1.0"]  # fmt: skip
PUSHER_NIGHT = ["--sleep-gradient-steps", "100", "--sleep-batch-size", "64", "--eval-episodes", "1",
                "--obstacle-episodes", "0", "--authors-test-episodes", "0"]  # fmt: skip
MAZE_DAY = ["--seed", "3", "--tamer-total-timesteps", "2000", "--tamer-learning-starts", "500"]
MAZE_NIGHT = ["--sleep-gradient-steps", "200"]


def patch(text: str, old: str, new: str, regex: bool = False) -> str:
    """One edit of the hack; its anchor must be in the code exactly once (else the hack's recipe is out of date)."""
    found = len(re.findall(old, text, re.S)) if regex else text.count(old)
    assert found == 1, f"the hack's anchor is in the script {found} times, not once: {old!r}"
    return re.sub(old, new, text, flags=re.S) if regex else text.replace(old, new)


LOSS = r"(\n        )return (iq_loss\(self\.q_net, self\.q_target.*?\)  # fmt: skip)"  # the core night's loss
NEW_LOSS = (
    r'\1loss, terms = \2\1terms["q_l2_term"] = self.q_l2_coef * {q}.pow(2).mean()'
    r'\1return loss + terms["q_l2_term"], terms'
)


def hacked(code: str, signature: str, stored: str, q_sa: str) -> str:
    """The hack, in the four places it takes: the flag, the night's settings, the night's constructor, its loss."""
    code = patch(code, "    def night_settings(self) -> dict:", FLAG + "    def night_settings(self) -> dict:")
    settings = '"chi2_coef": self.sleep_chi2_coef'
    code = patch(code, settings, settings + ', "q_l2_coef": self.sleep_q_l2_coef')
    code = patch(code, signature, signature.replace("chi2_coef: float", "chi2_coef: float, q_l2_coef: float"))
    code = patch(code, stored, stored + "\n        self.q_l2_coef = q_l2_coef")
    return patch(code, LOSS, NEW_LOSS.format(q=q_sa), regex=True)


def hacked_pusher(code: str) -> str:
    return hacked(code, "temperature: float, chi2_coef: float,", "self.temperature, self.chi2_coef, self.frequency = "
                  "temperature, chi2_coef, policy_frequency", "self.q_net(obs, actions)")  # fmt: skip


def hacked_maze(code: str) -> str:
    return hacked(code, "temperature: float, chi2_coef: float):", "self.gamma, self.temperature, self.chi2_coef = "
                  "GAMMA, temperature, chi2_coef", "self.q_net(obs).gather(1, actions[:, None])")  # fmt: skip


CASES = {
    "pusher": ("inform_sac_pusher.py", [], hacked_pusher, "sleep_variants_pusher", PUSHER_DAY, PUSHER_NIGHT,
               [[], ["--sleep-loss-rows", "expert"], ["--sleep-twin-critics"], ["--sleep-bc-coef", "1"],
                ["--sleep-holdout-fraction", "0.2"], ["--sleep-control", "bc"], ["--sleep-control", "sham"]]),
    "maze": ("inform_dqn_gridworld.py", ["gridworld_env.py"], hacked_maze, "sleep_variants_maze", MAZE_DAY, MAZE_NIGHT,
             [[], ["--sleep-loss-rows", "expert"], ["--sleep-control", "bc"], ["--sleep-control", "sham"]]),
}  # fmt: skip


def runs(cwd) -> set[str]:
    return set(glob.glob(os.path.join(cwd, "runs", "*")))


def run(cwd, cmd: list[str]) -> tuple[subprocess.CompletedProcess, dict | None]:
    """A command in the hacked copy; its result and the summary of the run it made (None: it made none)."""
    before = runs(cwd)
    env = {**os.environ, "PYTHONPATH": str(cwd)}
    result = subprocess.run([sys.executable, *cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
    made = runs(cwd) - before
    if not made:
        return result, None
    (run_dir,) = made
    with open(os.path.join(run_dir, "summary.json")) as f:
        return result, json.load(f)


@pytest.mark.parametrize("case", CASES)
def test_a_new_term_on_the_core_night_is_applied_by_the_study_or_refused(case, tmp_path):
    script, siblings, hack, study, day_flags, night_flags, variants = CASES[case]
    for name in (script, *siblings):
        shutil.copy(os.path.join(REPO, name), tmp_path)
    os.makedirs(tmp_path / "inform_utils")
    for name in ("__init__.py", f"{study}.py"):
        shutil.copy(os.path.join(REPO, "inform_utils", name), tmp_path / "inform_utils")
    (tmp_path / script).write_text(hack((tmp_path / script).read_text()))
    teacher = ["--oracle-path", os.path.join(REPO, "oracles", "Pusher-v5__sac_oracle.pt")] if case == "pusher" else []

    result, day = run(
        tmp_path, [script, *day_flags, *night_flags, *teacher, "--save-buffer", "--sleep-q-l2-coef", "0.1"]
    )
    assert result.returncode == 0 and day["status"] == "completed", result.stderr[-2000:]
    assert day["losses/q_l2_term"] > 0 and "q_l2_coef=0.1" in day["sleep_variant"]  # the hack works in the core
    day_dir = max(runs(tmp_path), key=os.path.getmtime)

    applied = []
    for variant in variants:
        flags = [
            "-m",
            f"inform_utils.{study}",
            "--sleep-from",
            day_dir,
            *night_flags,
            *variant,
            "--sleep-q-l2-coef",
            "0.1",
        ]
        result, summary = run(tmp_path, flags)
        if result.returncode == 2:  # refused: one line naming the flag, nothing made
            assert summary is None, variant
            assert result.stderr.count("\n") == 1 and "--sleep-q-l2-coef" in result.stderr, result.stderr
            assert result.stderr.startswith("error: "), result.stderr
            continue
        assert result.returncode == 0 and summary["status"] == "completed", (variant, result.stderr[-2000:])
        applied_term = summary.get("losses/q_l2_term", 0) > 0
        assert applied_term, f"{variant}: the study accepted --sleep-q-l2-coef and never applied it"
        assert "q_l2_coef=0.1" in summary["sleep_variant"], variant
        applied.append(variant)
    assert [] in applied  # the study's own night (every switch at its default) hears the core's new flag
