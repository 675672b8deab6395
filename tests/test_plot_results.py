import os
import struct
import zipfile

from test_inform_gridworld import SCRIPT, TINY

from inform_utils import plot_results


def test_maze_figures_from_real_runs(run_script, monkeypatch):
    for seed in ("1", "2"):
        assert run_script(SCRIPT, "--seed", seed, "--exp-name", "plots", *TINY).returncode == 0
    monkeypatch.chdir(run_script.cwd)
    plot_results.main(plot_results.Args(maze_exp="plots", out="figs"))
    for name in ("fig3_maze.png", "recovered_reward.png"):
        path = run_script.cwd / "figs" / name
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 10_000
    assert not os.path.exists(run_script.cwd / "figs" / "fig3_pusher.png")  # no Pusher runs: no Pusher figure


def test_no_default_writes_into_the_repository_and_a_skipped_sleep_is_left_out(run_script):
    """Issue 55, item 5: with no flags plot_results overwrote the committed docs/figures; beside a maze run whose
    sleep was skipped it was a KeyError traceback. Without --out the figures go into a fresh folder under runs/, and
    the skipped run is left out, said in the output."""
    assert run_script(SCRIPT, "--seed", "3", "--exp-name", "plots", *TINY).returncode == 0
    skipped = run_script(SCRIPT, "--seed", "2", "--exp-name", "plots", "--tamer-total-timesteps", "600",
                         "--tamer-learning-starts", "500", "--success-max-steps", "5")  # fmt: skip
    assert skipped.returncode == 0 and "the sleep is skipped" in skipped.stderr
    (run_script.cwd / "docs" / "figures").mkdir(parents=True)  # as in the repository
    result = run_script("inform_utils/plot_results.py", "--maze-exp", "plots")
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr and "its sleep was skipped" in result.stdout
    assert os.listdir(run_script.cwd / "docs" / "figures") == []
    (out,) = [p for p in (run_script.cwd / "runs").iterdir() if p.name.startswith("figures__")]
    assert sorted(os.listdir(out)) == ["fig3_maze.png", "recovered_reward.png"]
    again = run_script("inform_utils/plot_results.py", "--maze-exp", "plots")  # a second one: a folder of its own
    assert again.returncode == 0 and len(list((run_script.cwd / "runs").glob("figures__*"))) == 2


def test_a_damaged_recovered_reward_is_refused(run_script):
    """Issue 55, item 2: one byte of recovered_reward.pt flipped (the reward script refuses it): exit 0 and a figure.
    Its CRC-32 is checked first: one line, exit 2, no figure."""
    assert run_script(SCRIPT, "--seed", "3", "--exp-name", "plots", *TINY).returncode == 0
    (path,) = (run_script.cwd / "runs").glob("*/recovered_reward.pt")
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as archive:
        info = next(i for i in archive.infolist() if i.filename.endswith("data/0"))
    name_len, extra_len = struct.unpack("<HH", data[info.header_offset + 26 : info.header_offset + 30])  # local header
    data[info.header_offset + 30 + name_len + extra_len] ^= 0xFF  # the first byte of its data
    path.write_bytes(bytes(data))
    result = run_script("inform_utils/plot_results.py", "--maze-exp", "plots", "--out", "figs")
    assert result.returncode == 2 and result.stderr.startswith("error: ") and "CRC-32" in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and not (run_script.cwd / "figs").exists()


def test_teachers_curves_are_drawn_from_their_csv_and_a_bad_one_is_refused(run_script):
    """--teacher-curves: oracle_train.py's eval_curve.csv, from a run folder or committed under its own name, drawn
    together (no runs needed); each labelled by its file's or its run's name; one that is not such a curve is one line,
    exit 2, nothing written."""
    header = "step,success_rate,final_distance,return\n"
    run = run_script.cwd / "runs" / "Pusher-v5__demo__1__1"
    run.mkdir(parents=True)
    (run / "eval_curve.csv").write_text(header + "10000,0.0,0.25,-40.0\n20000,0.1,0.2,-35.0\n")
    (run_script.cwd / "Pusher-v5__sac_eval_curve.csv").write_text(header + "10000,0.0,0.24,-41.0\n")
    curves = ["runs/Pusher-v5__demo__1__1/eval_curve.csv", "Pusher-v5__sac_eval_curve.csv"]
    assert [plot_results.curve_label(str(run_script.cwd / c)) for c in curves] == ["Pusher-v5__demo__1__1",
                                                                                   "Pusher-v5__sac"]  # fmt: skip
    result = run_script("inform_utils/plot_results.py", "--teacher-curves", *curves, "--out", "figs")
    assert result.returncode == 0, result.stderr
    assert sorted(os.listdir(run_script.cwd / "figs")) == ["teacher_curves.png"]
    assert (run_script.cwd / "figs" / "teacher_curves.png").stat().st_size > 10_000
    (run_script.cwd / "empty_eval_curve.csv").write_text(header)
    for bad in ("empty_eval_curve.csv", "runs"):
        result = run_script("inform_utils/plot_results.py", "--teacher-curves", curves[1], bad, "--out", "figs2")
        assert result.returncode == 2 and result.stderr.strip().splitlines() == [
            f"error: --teacher-curves {bad}: not an eval_curve.csv of oracle_train.py with an evaluation"
        ], result.stderr
        assert not (run_script.cwd / "figs2").exists()
