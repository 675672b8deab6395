"""--capture-video's plumbing, shared by inform_sac_pusher.py and oracle_train.py: the check that MuJoCo renders
headless here and that mp4 can be written, and the mp4 writer. The scripts import it only under --capture-video (as
CleanRL imports cleanrl_utils.evals only under --save-model), so their default path runs from a copied file alone;
what a script films, and from which camera, stays in the script.
"""

import contextlib
import gc
import importlib.util
import os
import sys
import warnings
from collections.abc import Callable

import gymnasium as gym
import numpy as np

GL_HINT = "install EGL (Debian: apt-get install libegl1 libegl-mesa0) or OSMesa (libosmesa6, MUJOCO_GL=osmesa)"


def gl_problem(make_env: Callable[[], gym.Env]) -> str | None:
    """None if the env `make_env` makes (rendering 16 x 16 RGB frames) renders headless and imageio-ffmpeg is there;
    else what is wrong and how to fix it, in one line. Picks egl when MUJOCO_GL is unset and there is no display."""
    if not os.environ.get("MUJOCO_GL") and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        os.environ["MUJOCO_GL"] = "egl"  # unset or empty, and no screen
    if os.environ.get("MUJOCO_GL") not in (None, "egl", "osmesa", "glfw"):
        return f"--capture-video: MUJOCO_GL={os.environ['MUJOCO_GL']!r} is none of egl, osmesa, glfw"
    if importlib.util.find_spec("imageio_ffmpeg") is None:
        return "--capture-video writes mp4 with imageio-ffmpeg: pip install imageio-ffmpeg"
    frame, hook = None, sys.unraisablehook
    sys.unraisablehook = lambda unraisable: None  # a viewer that failed to start raises again as it is collected
    try:
        with contextlib.suppress(Exception), warnings.catch_warnings():  # a failing backend warns, then raises
            warnings.simplefilter("ignore")
            env = make_env()
            env.reset(seed=0)
            frame = env.render()  # a frame, or (Gymnasium's RenderCollection) the frames so far
            frame = np.asarray(frame[-1] if isinstance(frame, list) else frame)
            env.close()
        gc.collect()
    finally:
        sys.unraisablehook = hook
    if frame is None or frame.shape != (16, 16, 3):
        return f"--capture-video: MuJoCo cannot render with MUJOCO_GL={os.environ.get('MUJOCO_GL')}; {GL_HINT}"
    return None


def write_video(path: str, frames: list[np.ndarray], fps: float) -> None:
    """H.264 mp4 by imageio-ffmpeg (Gymnasium's RecordVideo needs moviepy), under a temporary name, then renamed: a
    stop or a full disk leaves no half-written video."""
    import imageio_ffmpeg

    tmp = path[: -len(".mp4")] + ".tmp.mp4"  # ffmpeg reads the container from the extension
    try:
        options = {"fps": fps, "codec": "libx264", "quality": 6, "macro_block_size": 16, "ffmpeg_log_level": "error"}
        writer = imageio_ffmpeg.write_frames(tmp, frames[0].shape[1::-1], **options)
        writer.send(None)
        for frame in frames:
            writer.send(np.ascontiguousarray(frame))
        writer.close()
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.remove(tmp)
