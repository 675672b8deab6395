"""Saved days in inform_sac_pusher.py and the sleep's variants in inform_utils/sleep_variants_pusher.py: --save-buffer
writes the day, --sleep-from sleeps on it again (bit for bit the original night with the same flags), the variants and
controls run and name themselves, the offline criterion picks a checkpoint on held-out episodes. Tiny budgets; one
day is shared by the module."""

import json
import math
import os
import shutil
import subprocess
import sys

import pytest
import torch

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

import inform_sac_pusher as isp  # noqa: E402
from inform_utils import sleep_variants_pusher as variants  # noqa: E402

SCRIPT = os.path.join(REPO, "inform_sac_pusher.py")
# every episode counts as a success (--success-distance 1), so the tiny day has an expert set and held-out successes
DAY = [
    "--tamer-total-timesteps", "600",
    "--tamer-learning-starts", "300",
    "--tamer-batch-size", "64",
    "--success-distance", "1.0",
]  # fmt: skip
NIGHT = [
    "--sleep-gradient-steps", "100",
    "--sleep-batch-size", "64",
    "--eval-episodes", "1",
    "--obstacle-episodes", "2",
    "--authors-test-episodes", "2",
]  # fmt: skip
COMPARED = ("eval/", "losses/", "sleep/", "feedback/", "holdout/")


def run(cwd, *flags, study=False):
    cmd = [sys.executable, "-m", "inform_utils.sleep_variants_pusher"] if study else [sys.executable, SCRIPT]
    env = {**os.environ, "PYTHONPATH": REPO}
    return subprocess.run([*cmd, *flags], cwd=cwd, env=env, capture_output=True, text=True, timeout=300)


def summary_of(proc, cwd) -> tuple[str, dict]:
    assert proc.returncode == 0, proc.stderr[-3000:]
    line = next(line for line in proc.stdout.splitlines() if line.startswith("run directory:"))
    run_dir = os.path.join(cwd, line.split(": ", 1)[1])
    with open(os.path.join(run_dir, "summary.json")) as f:
        return run_dir, json.load(f)


@pytest.fixture(scope="module")
def day(tmp_path_factory):
    """One tiny run that saves its day: (cwd, its run directory, its summary)."""
    cwd = tmp_path_factory.mktemp("days")
    run_dir, summary = summary_of(run(cwd, *DAY, *NIGHT, "--save-buffer"), cwd)
    return cwd, run_dir, summary


def night(day, *flags, study=False):
    cwd, run_dir, _ = day
    return summary_of(run(cwd, *NIGHT, "--sleep-from", run_dir, *flags, study=study), cwd)[1]


def test_a_night_on_a_saved_day_gives_the_runs_own_numbers(day):
    _, run_dir, original = day
    again = night(day)
    keys = [k for k in original if k.startswith(COMPARED)]
    assert len(keys) > 40
    assert {k: again[k] for k in keys} == {k: original[k] for k in keys}
    assert again["sleep_from"] == os.path.abspath(run_dir) and original["sleep_from"] is None
    assert again["sps/tamer"] == original["sps/tamer"]  # the day's own time, not the restore's
    assert again["args"]["tamer_total_timesteps"] == 600  # the day's flags, though this command did not pass them


def test_the_study_module_with_no_study_flag_gives_the_cores_night(day):
    core, study = night(day), night(day, study=True)
    keys = [k for k in core if k.startswith(COMPARED)]
    assert {k: study[k] for k in keys} == {k: core[k] for k in keys} and len(keys) > 40
    assert study["args"]["sleep_control"] == "none" and "sleep_control" not in core["args"]
    assert "control=none" in study["sleep_variant"] and "control=" not in core["sleep_variant"]


def test_a_day_saved_in_the_first_format_gives_the_same_night(day, tmp_path):
    """Days saved before other tasks (format inform-day-1) kept Pusher's final distances as `episode_final_distance`;
    --sleep-from still reads them, and the night is the same."""
    cwd, run_dir, original = day
    old = tmp_path / "old_day"
    old.mkdir()
    saved = torch.load(os.path.join(run_dir, "day.pt"), weights_only=True)
    saved["episode_final_distance"] = saved.pop("episode_shortfall")  # float64 then too
    saved["format"] = "inform-day-1"
    for flag in ("success_info_key", "success_return"):  # not day flags then
        del saved["day_args"][flag]
    torch.save(saved, old / "day.pt")
    again = summary_of(run(cwd, *NIGHT, "--sleep-from", str(old), "--success-return", "-30"), cwd)[1]
    keys = [k for k in original if k.startswith(COMPARED)]
    assert {k: again[k] for k in keys} == {k: original[k] for k in keys}
    assert again["args"]["success_return"] is None  # the old day's rule, not this command's


def test_the_day_file_is_plain_tensors_and_its_table_adds_up(day):
    _, run_dir, summary = day
    saved = torch.load(os.path.join(run_dir, "day.pt"), weights_only=True)
    n = saved["obs"].shape[0]
    assert n == summary["feedback/steps"] == 600
    for key in ("actions", "next_obs", "feedback", "terminated", "success"):
        assert saved[key].shape[0] == n, key
    assert saved["feedback"].sum().item() == summary["feedback/positive"]
    starts, ends = saved["episode_start"], saved["episode_end"]
    assert starts[0] == 0 and ends[-1] == n and torch.equal(starts[1:], ends[:-1])  # episodes tile the buffer
    assert len(starts) == summary["sleep/episodes"]
    assert torch.equal(saved["episode_success"], saved["episode_shortfall"] < 1.0)  # the final distance, here
    assert torch.equal(saved["episode_success"], saved["success"][starts])  # each episode's tag, on its transitions
    assert saved["day_args"]["seed"] == 1 and saved["format"] == isp.DAY_FORMAT


@pytest.mark.parametrize(
    "flags",
    [
        ["--sleep-control", "sham"],
        ["--sleep-control", "bc"],
        [
            "--sleep-twin-critics", "--sleep-loss-rows", "expert", "--sleep-actor-states", "replay+expert",
            "--sleep-bc-coef", "2.5", "--sleep-policy-frequency", "2", "--no-sleep-init-actor-from-tamer",
            "--sleep-holdout-fraction", "0.34", "--sleep-temperature", "0.1",
        ],
    ],
    ids=["sham", "bc", "variants+holdout"],
)  # fmt: skip
def test_the_variants_and_controls_run_on_a_day_and_name_themselves(day, flags):
    summary = night(day, *flags, study=True)
    variant = summary["sleep_variant"]
    for flag, value in zip(flags, flags[1:] + [""], strict=True):
        if flag.startswith("--sleep-") and not value.startswith("--"):
            name = flag.removeprefix("--sleep-").replace("-", "_")
            assert f"{name}={value}" in variant, (name, variant)
    assert math.isfinite(summary["eval/inform_return"]) and math.isfinite(summary["losses/iq_loss"])
    if "--sleep-holdout-fraction" in flags:
        assert "twin_critics=True" in variant and "init_actor_from_tamer=False" in variant
        assert summary["holdout/episodes"] == 2 and summary["holdout/transitions"] == 200  # 0.34 of 6 episodes
        assert summary["holdout/selected_step"] == 100  # the one evaluation of a 100-step night
        assert math.isfinite(summary["eval/inform_selected_return"])
        assert summary["sleep/expert_transitions"] == 400  # the held-out episodes never reach the sleep


def test_another_sleep_seed_gives_another_night_on_the_same_day(day):
    _, _, original = day
    other = night(day, "--sleep-seed", "7")
    assert other["losses/iq_loss"] != original["losses/iq_loss"]
    assert other["feedback/positive"] == original["feedback/positive"]


def test_the_sleep_study_runs_a_night_tests_it_on_random_starts_and_tabulates_it(day):
    if "sleep_variants_pusher" not in open(os.path.join(REPO, "inform_utils", "sleep_study.py")).read():
        pytest.skip("inform_utils/sleep_study.py still runs the study's flags through the core script")
    cwd, run_dir, _ = day
    cmd = [sys.executable, "-m", "inform_utils.sleep_study", "--days", run_dir, "--campaign", "c", "--variants"]
    cmd += ["default", "--sleep-seeds", "3", "--random-start-episodes", "2", "--", *NIGHT]
    env = {**os.environ, "PYTHONPATH": REPO}
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    night_dir = cwd / "results" / "c" / os.path.basename(run_dir) / "default__sleep3"
    summary = json.loads((night_dir / "summary.json").read_text())
    assert summary["args"]["sleep_seed"] == 3 and summary["args"]["sleep_holdout_fraction"] == 0.15
    random_starts = json.loads((night_dir / "random_starts.json").read_text())
    assert random_starts["random_starts/inform_success_rate"] in (0.0, 0.5, 1.0)  # a mean over the 2 episodes
    assert "random_starts/tamer_return" in random_starts
    assert random_starts["random_starts/inform_success_rate_sampled"] in (0.0, 0.5, 1.0)  # the sampled test beside it
    assert "| default | 1 |" in proc.stdout and "| tamer | 1 days |" in proc.stdout
    again = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)  # resumes: nothing runs
    assert again.returncode == 0 and "[study]" not in again.stdout
    # a night kept before the test recorded the sampled numbers gets them from its own run, the same test again
    old = {k: v for k, v in random_starts.items() if not k.endswith("_sampled")}
    retest = [sys.executable, "-m", "inform_utils.sleep_study", "--campaign", "c", "--retest-from", "runs"]
    fewer = {k: v for k, v in old.items() if k != "random_starts/tamer_return"}
    for kept, said in (
        (old, None),
        ({**old, "random_starts/tamer_return": 1.5}, "not the kept 1.5"),  # a number the test does not give again
        (fewer, "not the kept none"),  # one it gives that was never kept: unchecked, so not written
    ):
        (night_dir / "random_starts.json").write_text(json.dumps(kept))
        proc = subprocess.run(retest, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
        assert proc.returncode == (0 if said is None else 1), proc.stderr[-2000:]
        now = json.loads((night_dir / "random_starts.json").read_text())
        assert now == (random_starts if said is None else kept)
        assert said is None or ("random_starts/tamer_return is" in proc.stderr and said in proc.stderr), proc.stderr
    assert "the sampled test added to 0 of 1 night(s); 1 could not be retested" in proc.stdout


def test_sleep_from_refuses_what_is_not_a_day(tmp_path):
    (tmp_path / "empty").mkdir()
    proc = run(tmp_path, "--sleep-from", str(tmp_path / "empty"))
    assert proc.returncode == 2 and proc.stderr.strip().count("\n") == 0 and "no day.pt" in proc.stderr
    (tmp_path / "empty" / "day.pt").write_bytes(b"not a checkpoint")
    proc = run(tmp_path, "--sleep-from", str(tmp_path / "empty"))
    assert proc.returncode == 2 and "day.pt: not a complete torch checkpoint" in proc.stderr  # its archive is checked
    proc = run(tmp_path, "--sleep-from", str(tmp_path / "empty"), "--save-buffer")
    assert proc.returncode == 2
    assert not (tmp_path / "runs").exists()


def test_the_authors_protocol_is_one_flag_and_what_was_typed_wins():
    authors = isp.Args(sleep_protocol="authors").sleep_recipe()
    assert authors == {"sleep_gradient_steps": 100000, "sleep_init_actor_from_tamer": False,
                       "sleep_actor_states": "replay+expert", "sleep_policy_frequency": 2}  # fmt: skip
    assert isp.Args().sleep_recipe()["sleep_gradient_steps"] == 5000
    assert isp.Args(sleep_protocol="authors", sleep_gradient_steps=200).sleep_recipe()["sleep_gradient_steps"] == 200
    typed = variants.untyped_to_protocol(variants.Args(sleep_protocol="authors", sleep_actor_states="expert"), [])
    assert typed.sleep_recipe()["sleep_actor_states"] == "expert"  # typed: kept
    assert typed.sleep_recipe()["sleep_init_actor_from_tamer"] is False  # untyped: the preset's
    typed = variants.untyped_to_protocol(variants.Args(sleep_protocol="authors"), ["--sleep-init-actor-from-tamer"])
    assert typed.sleep_recipe()["sleep_init_actor_from_tamer"] is True


def test_the_preset_records_what_ran(day):
    summary = night(day, "--sleep-protocol", "authors", "--sleep-gradient-steps", "30")
    assert summary["args"]["sleep_protocol"] == "authors" and summary["args"]["sleep_gradient_steps"] == 30
    assert "init_actor_from_tamer=False" in summary["sleep_variant"] and "gradient_steps=30" in summary["sleep_variant"]


def test_auc_by_hand():
    scores = torch.tensor([0.1, 0.4, 0.5, 0.8])
    positive = torch.tensor([False, True, False, True])
    assert variants.auc(scores, positive) == 0.75  # 0.4 beats 0.1 but not 0.5, 0.8 beats both: 3 of 4 pairs
    assert variants.auc(torch.tensor([1.0, 1.0]), torch.tensor([True, False])) == 0.5  # a tie counts half
    assert math.isnan(variants.auc(scores, torch.ones(4, dtype=torch.bool)))


def test_log_prob_of_given_actions_matches_the_sampled_ones():
    torch.manual_seed(0)
    actor = isp.Actor(5, 3, 16, -2 * torch.ones(3), 2 * torch.ones(3))
    obs = torch.randn(8, 5)
    with torch.no_grad():
        action, log_prob, _ = actor.get_action(obs)
        assert torch.allclose(actor.log_prob(obs, action), log_prob, atol=1e-3)


def test_iq_loss_on_expert_rows_only_by_hand():
    """With Q = 0 everywhere the TD error is -y = -gamma V_target(s'); rows=expert keeps the value and chi2 terms to
    the expert rows."""
    q_net = isp.QEnsemble(2, 1, 4, n=2)
    target = isp.QEnsemble(2, 1, 4, n=2)
    for net in (q_net, target):
        for p in net.parameters():
            torch.nn.init.zeros_(p)
    with torch.no_grad():
        target.fc3.bias.fill_(1.0)  # V_target(s') = 1 - temp * log pi: gamma, temp = 0 makes y = gamma = 0.5
    actor = isp.Actor(2, 1, 4)
    obs = torch.randn(4, 2)
    is_expert = torch.tensor([False, False, True, True])
    terminated = torch.tensor([0.0, 0.0, 0.0, 1.0])  # y = 0.5, 0.5, 0.5, 0
    args = (q_net, target, obs, torch.zeros(4, 1), obs, terminated, is_expert, 0.5, 0.0, 0.5, actor)
    expert, value, chi2 = isp.iq_loss(*args)[1].values()
    expert_e, value_e, chi2_e = isp.iq_loss(*args, is_expert)[1].values()
    assert expert.item() == expert_e.item() == pytest.approx(2 * 0.25)  # -(0 - y) over expert rows, twice (twins)
    assert value.item() == pytest.approx(-(0.5 * 3) / 4) and value_e.item() == pytest.approx(-0.25)
    assert chi2.item() == pytest.approx(2 * 0.5 * 0.75 / 4) and chi2_e.item() == pytest.approx(2 * 0.5 * 0.25 / 2)


@pytest.mark.parametrize(
    ("method", "probability"), [("dwbc", "dwbc_d"), ("pu_td3bc", "pu_reward"), ("oril_draft", "oril_reward")]
)
def test_a_method_night_runs_on_a_saved_day_and_records_what_ran(day, method, probability):
    """--sleep-method dwbc / pu_td3bc / oril_draft: the night completes, its own model's loss and outputs are logged
    (DWBC's discriminator, the PU reward, each a probability on the success rows and on the others), the summary
    records the method and the learning rate it fixes, and the IQ critic still sleeps (its loss)."""
    summary = night(day, "--sleep-method", method, "--sleep-holdout-fraction", "0.2", study=True)
    assert summary["status"] == "completed"
    assert summary["args"]["sleep_method"] == method and f"method={method}" in summary["sleep_variant"]
    assert f"policy_lr={variants.METHODS[method].fixed['policy_lr']}" in summary["sleep_variant"]
    for rows in ("expert", "other"):
        assert 0 <= summary[f"losses/{probability}_{rows}"] <= 1
    assert math.isfinite(summary["losses/iq_loss"])


@pytest.mark.parametrize("flags", [["--sleep-control", "bc"], ["--sleep-policy-lr", "1e-3"], ["--sleep-bc-coef", "1"]],
                         ids=["a_control_too", "its_own_lr", "a_bc_term"])  # fmt: skip
def test_a_flag_dwbc_would_not_hear_is_refused_in_one_line(day, flags):
    cwd, run_dir, _ = day
    before = set(os.listdir(os.path.join(cwd, "runs")))
    proc = run(cwd, *NIGHT, "--sleep-from", run_dir, "--sleep-method", "dwbc", *flags, study=True)
    assert proc.returncode == 2 and proc.stderr.startswith("error: ") and proc.stderr.count("\n") == 1, proc.stderr
    assert flags[0] in proc.stderr
    assert set(os.listdir(os.path.join(cwd, "runs"))) == before  # nothing made


def test_a_copy_under_another_name_reads_the_originals_days_and_the_original_reads_the_copys(day, tmp_path):
    """A researcher's copy (my_night.py, in a folder of its own inside a repository) sleeps on a day the original
    saved, with the original's numbers, and finds the repository's teacher by looking above itself; the original
    sleeps on a day the copy saved."""
    _, run_dir, original = day
    repo = tmp_path / "repo"
    (repo / "experiments").mkdir(parents=True)
    (repo / "oracles").mkdir()
    shutil.copy(os.path.join(REPO, "oracles", "Pusher-v5__sac_oracle.pt"), repo / "oracles")
    copy = repo / "experiments" / "my_night.py"
    shutil.copy(SCRIPT, copy)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()

    def by(script, *flags):
        proc = subprocess.run([sys.executable, str(script), *NIGHT, *flags], cwd=elsewhere, capture_output=True,
                              text=True, timeout=300)  # fmt: skip
        return summary_of(proc, elsewhere)

    _, again = by(copy, "--sleep-from", run_dir)
    keys = [k for k in original if k.startswith(COMPARED)]
    assert {k: again[k] for k in keys} == {k: original[k] for k in keys}
    copys_dir, copys_day = by(copy, *DAY, "--save-buffer")  # its teacher: the repository's, found above the copy
    assert copys_day["oracle_path"] == str(repo / "oracles" / "Pusher-v5__sac_oracle.pt")
    _, by_original = by(SCRIPT, "--sleep-from", copys_dir)
    assert {k: by_original[k] for k in keys} == {k: copys_day[k] for k in keys}


def test_clonable_fits_a_function_of_the_state_and_not_noise_on_held_out_episodes():
    """inform_utils/clonable.py's measure: R^2 by hand; a demonstrator whose action is a function of the observation
    is learnt on episodes never seen (R^2 near 1), one whose action is noise is not (near 0 or below), though both
    are fitted where they were seen."""
    from inform_utils import clonable

    target = torch.tensor([[1.0, 0.0], [3.0, 2.0]])  # the mean (2, 1): deviations' squares sum to 4
    assert clonable.r_squared(target, target) == 1.0
    assert clonable.r_squared(torch.tensor([[2.0, 1.0], [2.0, 1.0]]), target) == 0.0
    assert clonable.r_squared(torch.tensor([[1.0, 0.0], [3.0, 0.0]]), target) == 0.0  # an error of 2: 1 - 4/4
    gen = torch.Generator().manual_seed(0)
    obs = torch.randn(2000, 23, generator=gen)
    held = (torch.arange(2000) // 100) % clonable.HELD_OUT == 0  # 20 episodes of 100 steps
    train, test = (~held).nonzero().squeeze(-1), held.nonzero().squeeze(-1)
    function = torch.tanh(obs @ torch.randn(23, 7, generator=gen) / 3)
    noise = torch.randn(2000, 7, generator=gen)
    fitted, held_out = clonable.fit(obs, function, train, test, steps=300, seed=0)
    assert fitted > 0.85 and held_out > 0.8, (fitted, held_out)
    fitted, held_out = clonable.fit(obs, noise, train, test, steps=300, seed=0)
    assert fitted > held_out + 0.1 and held_out < 0.05, (fitted, held_out)


def test_clonable_runs_on_a_saved_day_and_refuses_in_one_line(day, tmp_path):
    cwd, run_dir, _ = day
    out = tmp_path / "clonable.json"
    cmd = [sys.executable, "-m", "inform_utils.clonable", run_dir, "--rows", "all", "--steps", "200", "--out", str(out)]
    proc = subprocess.run(cmd, cwd=cwd, env={**os.environ, "PYTHONPATH": REPO}, capture_output=True, text=True,
                          timeout=300)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    (row,) = json.loads(out.read_text())
    assert (row["fitted rows"], row["held-out rows"]) == (400, 200)  # 6 episodes of 100: the first and sixth held out
    assert row["expert R2 fitted"] > 0.5
    for flags, phrase in (([run_dir, "--out", str(out)], "give a new file"),
                          ([str(tmp_path)], "no day.pt there"),
                          ([run_dir, "--rows", "driven"], "0 driven rows to fit")):  # fmt: skip
        proc = subprocess.run([*cmd[:3], *flags], cwd=cwd, env={**os.environ, "PYTHONPATH": REPO},
                              capture_output=True, text=True, timeout=300)  # fmt: skip
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1 and phrase in lines[0], proc.stderr[-2000:]
