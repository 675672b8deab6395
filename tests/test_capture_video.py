"""--capture-video: frames rendered headless (MUJOCO_GL, egl by default without a display) and written to files, in
inform_sac_pusher.py, oracle_train.py and inform_dqn_gridworld.py; filming changes no number. Needs a headless
OpenGL for MuJoCo (Debian: libegl1 libegl-mesa0, which .ci/run installs) and imageio-ffmpeg."""

import glob
import json
import os
import subprocess
import sys

import numpy as np
import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

from test_inform_gridworld import TINY as MAZE_TINY  # noqa: E402
from test_pusher import SHIPPED, TINY, mujoco_below_3  # noqa: E402

import gridworld_env as g  # noqa: E402
import inform_dqn_gridworld as maze  # noqa: E402
import inform_sac_pusher as isp  # noqa: E402
import oracle_train  # noqa: E402


@pytest.fixture
def headless(monkeypatch):
    """The scripts' default in this process too: egl when MUJOCO_GL is unset and there is no display."""
    if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
        monkeypatch.setenv("MUJOCO_GL", "egl")


def read_mp4(path) -> np.ndarray:
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(path))
    width, height = next(reader)["size"]
    return np.stack([np.frombuffer(frame, np.uint8).reshape(height, width, 3) for frame in reader])


def blue_pixels(frame: np.ndarray) -> int:  # the boxes (rgba 0.2 0.2 0.8)
    r, g_, b = (frame[..., i].astype(int) for i in range(3))
    return int(((b > r + 60) & (b > g_ + 60)).sum())


def red_pixels(frame: np.ndarray) -> int:  # the goal
    r, g_, b = (frame[..., i].astype(int) for i in range(3))
    return int(((r > g_ + 80) & (r > b + 80)).sum())


def short_pusher_episode(env_id: str, tmp_path, steps: int = 8, size: int = 160):
    """`steps` full-torque steps with and without the boxes, each written to mp4 and read back."""
    boxes = isp.obstacle_positions("bisector", *isp.start_and_goal(env_id, 1))
    videos = {}
    for name, obstacles in (("plain", None), ("obstacle", boxes)):
        env = isp.video_env(env_id, 1, obstacles, size=size)
        env.reset(seed=1)
        for _ in range(steps):
            env.step(env.action_space.high)  # full torque on every joint: the arm moves
        frames = env.render()
        isp.videos().write_video(str(tmp_path / f"{name}.mp4"), frames, env.metadata["render_fps"])
        env.close()
        videos[name] = (frames, read_mp4(tmp_path / f"{name}.mp4"))
    return videos


def check_short_episode(videos, steps: int = 8, size: int = 160):
    for name, (frames, back) in videos.items():
        assert len(frames) == steps + 1 and frames[0].shape == (size, size, 3), name  # the reset, then every step
        assert back.shape == (steps + 1, size, size, 3), name  # the file holds every frame
        assert np.abs(back[-1].astype(int) - back[0]).mean() > 1.0, name  # the arm moved
        assert np.abs(back[0].astype(int) - frames[0]).mean() < 6, name  # H.264 keeps the picture
        assert red_pixels(frames[0]) > 50, name  # the goal is in view
    assert blue_pixels(videos["obstacle"][0][0]) > 20 and blue_pixels(videos["plain"][0][0]) == 0  # and the boxes


def test_a_short_pusher_episode_renders_to_mp4(tmp_path, headless):
    check_short_episode(short_pusher_episode("Pusher-v5", tmp_path))


@pytest.mark.pusher_v4
@pytest.mark.skipif(not mujoco_below_3(), reason="Pusher-v4 needs mujoco<3 (pip install mujoco==2.3.7)")
def test_a_short_pusher_v4_episode_renders_to_mp4(tmp_path, headless):
    check_short_episode(short_pusher_episode("Pusher-v4", tmp_path))


def test_the_teacher_films_as_the_pusher_script_does(headless):
    """oracle_train.py films through the core script's make_env (its camera): the same picture."""
    assert isp.VIDEO_SIZE == oracle_train.VIDEO_SIZE
    frames = []
    for env in (isp.video_env("Pusher-v5", 1, None, size=160), oracle_train.video_env("Pusher-v5", size=160)):
        env.reset(seed=1)
        frames.append(env.render()[-1].astype(int))
        env.close()
    assert frames[1].shape == (160, 160, 3) and red_pixels(frames[1]) > 100  # the goal, seen from above
    assert np.abs(frames[0] - frames[1]).mean() < 1.0  # up to a few pixels' rounding


def run(script, cwd, *flags, env=None):
    return subprocess.run([sys.executable, os.path.join(REPO, script), *flags], cwd=cwd, capture_output=True,
                          text=True, timeout=600, env=env)  # fmt: skip


def run_plain_and_filmed(script, tmp_path, *flags) -> tuple[str, str]:
    """The same tiny run without and with --capture-video, each in its own directory: (plain run dir, filmed one)."""
    (tmp_path / "plain").mkdir()
    (tmp_path / "video").mkdir()
    assert run(script, tmp_path / "plain", *flags).returncode == 0
    proc = run(script, tmp_path / "video", *flags, "--capture-video")
    assert proc.returncode == 0, proc.stderr[-2000:]
    (plain_dir,) = glob.glob(str(tmp_path / "plain" / "runs" / "*"))
    (run_dir,) = glob.glob(str(tmp_path / "video" / "runs" / "*"))
    assert not os.path.exists(os.path.join(plain_dir, "videos"))  # without the flag nothing is rendered
    return plain_dir, run_dir


def summary_numbers(run_dir) -> dict:
    with open(os.path.join(run_dir, "summary.json")) as f:
        summary = json.load(f)
    return {k: v for k, v in summary.items() if k.startswith(("eval/", "feedback/", "losses/", "sleep/", "obstacle/"))}


@pytest.mark.skipif(not os.path.isfile(SHIPPED), reason="shipped oracle missing")
def test_tiny_pusher_run_films_the_evaluation_and_changes_no_number(tmp_path):
    plain_dir, run_dir = run_plain_and_filmed("inform_sac_pusher.py", tmp_path, "--oracle-path", SHIPPED, *TINY)
    numbers = summary_numbers(run_dir)
    assert numbers == summary_numbers(plain_dir) and len(numbers) > 40
    with open(os.path.join(run_dir, "videos", "videos.json")) as f:
        videos = json.load(f)
    assert sorted(videos) == sorted(f"{p}{s}" for p in isp.POLICIES for s in ("", "_obstacle"))
    assert sorted(os.listdir(os.path.join(run_dir, "videos"))) == sorted([*(f"{k}.mp4" for k in videos), "videos.json"])
    for p in isp.POLICIES:  # the filmed episodes are the evaluated ones (fixed start: every episode is the same)
        assert videos[p]["final_distance"] == numbers[f"eval/{p}_final_distance"]
        assert videos[f"{p}_obstacle"]["final_distance"] == numbers[f"eval/obstacle/{p}_final_distance_deterministic"]
        assert videos[p]["frames"] == 101 and videos[p]["size"] == [isp.VIDEO_SIZE, isp.VIDEO_SIZE, 3]
    inform = read_mp4(os.path.join(run_dir, "videos", "inform_obstacle.mp4"))
    assert inform.shape == (101, isp.VIDEO_SIZE, isp.VIDEO_SIZE, 3)
    assert blue_pixels(inform[0]) > 100 and red_pixels(inform[0]) > 100
    # the README's picture from the run's saved actors: named after the run, under ~2 MB, every other frame
    gif = make_gifs(tmp_path, "--pusher-run", run_dir)
    assert os.path.basename(gif) == "Pusher-v5_tamer_vs_inform_seed1_tamer600_sleep200.gif"
    assert os.path.getsize(gif) < 2_000_000 and gif_frames(gif) == 51


def make_gifs(tmp_path, *flags) -> str:
    cmd = [sys.executable, "-m", "inform_utils.make_gifs", *flags, "--out-dir", str(tmp_path / "gifs")]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env={**os.environ, "PYTHONPATH": REPO})
    assert proc.returncode == 0, proc.stderr[-2000:]
    (gif,) = glob.glob(str(tmp_path / "gifs" / "*.gif"))
    return gif


def gif_frames(path) -> int:
    from PIL import Image

    with Image.open(path) as gif:
        return gif.n_frames


def test_oracle_train_films_the_teacher(tmp_path):
    flags = ["--env-id", "Pusher-v5", "--total-timesteps", "200", "--learning-starts", "100", "--batch-size", "32"]
    flags += ["--hidden-size", "32", "--eval-frequency", "200", "--eval-episodes", "1", "--final-eval-episodes", "3"]
    proc = run("oracle_train.py", tmp_path, *flags, "--output-path", "oracle.pt", "--capture-video")
    assert proc.returncode == 0, proc.stderr[-2000:]
    (run_dir,) = glob.glob(str(tmp_path / "runs" / "*"))
    with open(os.path.join(run_dir, "videos", "videos.json")) as f:
        videos = json.load(f)
    with open(os.path.join(run_dir, "oracle_eval.json")) as f:
        held_out = json.load(f)["eval"]
    assert videos["evaluation"] == held_out  # the three filmed episodes are the held-out evaluation's three
    assert videos["frames"] == 303 and videos["size"] == [480, 480, 3]
    assert read_mp4(os.path.join(run_dir, "videos", "oracle.mp4")).shape == (303, 480, 480, 3)
    assert not glob.glob(os.path.join(run_dir, "videos", "*.tmp*"))


@pytest.mark.parametrize(
    ("script", "flags"),
    [
        ("inform_sac_pusher.py", ["--oracle-path", SHIPPED, *TINY]),
        ("oracle_train.py", ["--total-timesteps", "200", "--learning-starts", "100", "--batch-size", "32"]),
    ],
)
def test_no_backend_is_one_line_and_leaves_nothing(tmp_path, script, flags):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    proc = run(script, tmp_path, *flags, "--capture-video", env={**env, "MUJOCO_GL": "glfw"})  # no display: no GLFW
    assert proc.returncode == 2
    assert proc.stderr.startswith("error: --capture-video") and len(proc.stderr.strip().splitlines()) == 1
    assert "apt-get install libegl1 libegl-mesa0" in proc.stderr
    assert not os.path.exists(tmp_path / "runs") and os.listdir(tmp_path) == []


@pytest.mark.parametrize("gl", ["osmesa", "bogus"])
def test_a_gl_backend_that_cannot_load_is_named_not_the_env(tmp_path, gl):
    """Without OSMesa installed (or with no such backend), the error names MUJOCO_GL and how to fix it, not --env-id."""
    if gl == "osmesa" and glob.glob("/usr/lib/*/libOSMesa.so*"):
        pytest.skip("OSMesa is installed here")
    flags = ["--oracle-path", SHIPPED, *TINY, "--capture-video"]
    proc = run("inform_sac_pusher.py", tmp_path, *flags, env={**os.environ, "MUJOCO_GL": gl})
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and f"MUJOCO_GL={gl}" in lines[0], proc.stderr
    assert "--env-id" not in lines[0] and (gl == "bogus" or "apt-get install" in lines[0]), lines[0]
    assert os.listdir(tmp_path) == []


def test_an_empty_mujoco_gl_is_unset_and_no_viewer_complains(headless, monkeypatch, capfd):
    """MUJOCO_GL= (empty) printed eight lines of 'Exception ignored' from a viewer that never started: now it means
    unset, and the headless default (egl) renders."""
    monkeypatch.setenv("MUJOCO_GL", "")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    isp.check_video("Pusher-v5")
    assert os.environ["MUJOCO_GL"] == "egl" and "Exception ignored" not in capfd.readouterr().err


def test_a_maze_episode_draws_to_gif(tmp_path):
    """The maze's own rgb_array frames, collected by Gymnasium's RenderCollection, as a GIF: one frame a step."""
    from PIL import Image, ImageSequence

    optimal, up = g.optimal_q("plain").argmax(1), np.zeros(g.N_CELLS, dtype=int)  # up: it bumps into the border
    record = maze.record_videos(str(tmp_path), {"optimal": optimal, "up": up})
    assert record[f"optimal_plain_{g.START}"] == {"file": "optimal_plain.gif", "variant": "plain",
                                                  "start_cell": g.START, "episode_length": 19, "reached_goal": True,
                                                  "frames": 20}  # fmt: skip
    gif = Image.open(tmp_path / "videos" / "optimal_plain.gif")
    back = [np.asarray(frame.convert("RGB")) for frame in ImageSequence.Iterator(gif)]
    assert len(back) == 20 and back[0].shape[2] == 3
    assert all(np.abs(a.astype(int) - b).sum() > 0 for a, b in zip(back, back[1:], strict=False))  # it moves
    bumped = record[f"up_plain_{g.START}"]
    assert (bumped["episode_length"], bumped["reached_goal"]) == (200, False)


def test_tiny_maze_run_draws_the_greedy_episodes_and_changes_no_number(tmp_path):
    plain_dir, run_dir = run_plain_and_filmed("inform_dqn_gridworld.py", tmp_path, *MAZE_TINY)
    numbers = summary_numbers(run_dir)
    assert numbers == summary_numbers(plain_dir) and len(numbers) > 20
    with open(os.path.join(run_dir, "videos", "videos.json")) as f:
        videos = json.load(f)
    files = {f"{p}_{clip}.gif" for p in ("tamer", "inform") for clip in ("plain", "wall", "starts")}
    assert set(os.listdir(os.path.join(run_dir, "videos"))) == files | {"videos.json"}
    for p in ("tamer", "inform"):  # the drawn episodes are the evaluated ones
        assert videos[f"{p}_plain_{g.START}"]["episode_length"] == numbers[f"eval/{p}_episode_length"]
        assert videos[f"{p}_wall_{g.START}"]["episode_length"] == numbers[f"eval/wall/{p}_episode_length"]
        assert {v["start_cell"] for k, v in videos.items() if k.startswith(f"{p}_starts")} == set(g.START_SET[::3])
    for p in ("tamer", "inform"):  # a frame a step, from the reset on (GIF merges the frames of a bump in place)
        frames = gif_frames(os.path.join(run_dir, "videos", f"{p}_plain.gif"))
        assert 2 <= frames <= videos[f"{p}_plain_{g.START}"]["frames"]


def test_the_filmed_start_cells_are_every_third_of_the_start_set():
    """The maze script names its filmed start cells as numbers (so a copy without gridworld_env.py still starts);
    they must stay the start set's every third cell."""
    import gridworld_env
    import inform_dqn_gridworld

    assert inform_dqn_gridworld.VIDEO_START_CELLS == tuple(gridworld_env.START_SET[::3])
