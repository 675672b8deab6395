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
