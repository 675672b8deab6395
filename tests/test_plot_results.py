import os

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
