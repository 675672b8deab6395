"""The README's two pictures, as the authors' repository opens with TAMER.gif and INFORM.gif: TAMER and INFORM side by
side, from the networks a finished run saved (read with torch.load(weights_only=True)).

- Pusher (--pusher-run, a run directory of inform_sac_pusher.py): tamer_actor.pt and inform_actor.pt push the object
  from the run's start past the boxes of its robustness test (on the path), deterministic actions: the episode the
  run's eval/obstacle/{p}_final_distance_deterministic measured; its object path must match the run's
  obstacle_paths.npz, or nothing is written. Pusher-v4 runs need the mujoco 2.3.7 venv.
- Maze (--maze-run, a run directory of inform_dqn_gridworld.py): the greedy policies of tamer_h.pt and inform_q.pt
  from S on the plain maze, then on the wall maze.

Each GIF is named after what it shows (env, seed, budgets) and written to --out-dir:

    python -m inform_utils.make_gifs --pusher-run runs/Pusher-v4__inform_sac_pusher__1__<time> \
        --maze-run runs/KnoxStoneMaze-v0__inform_dqn_gridworld__1__<time> --out-dir docs/figures
"""

import contextlib
import io
import json
import os
import sys
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
import torch
import tyro
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle
from PIL import Image, ImageDraw, ImageFont

import gridworld_env
import inform_dqn_gridworld as maze
import inform_sac_pusher as isp
from inform_utils.evaluate_policy import load_q_network

POLICIES = ("tamer", "inform")


@dataclass
class Args:
    pusher_run: str | None = None
    """run directory of inform_sac_pusher.py (tamer_actor.pt, inform_actor.pt, summary.json, obstacle_paths.npz)"""
    maze_run: str | None = None
    """run directory of inform_dqn_gridworld.py (tamer_h.pt, inform_q.pt, summary.json)"""
    out_dir: str = "docs/figures"
    """where the GIFs are written (named after the env, seed and budgets of the run)"""
    pusher_size: int = 256
    """pixels of each Pusher panel (square)"""
    pusher_frame_step: int = 2
    """keep every this many Pusher frames (the env runs at 20 frames/s; 2 gives 10 frames/s, still real time)"""


def budget(n: int) -> str:
    return f"{n // 1000}k" if n % 1000 == 0 else str(n)


def read_summary(run_dir: str, script: str) -> dict:
    path = os.path.join(run_dir, "summary.json")
    try:
        with open(path) as f:
            summary = json.load(f)
    except (OSError, ValueError) as e:
        raise ValueError(f"{run_dir}: no readable summary.json ({type(e).__name__}); did the run finish?") from None
    if not isinstance(summary, dict) or summary.get("script") != script or summary.get("status") != "completed":
        raise ValueError(f"{run_dir}: not a completed run of {script}")
    return summary


def font(size: int):
    return ImageFont.load_default(size=size)


def label(width: int, lines: list[str], size: int = 14) -> np.ndarray:
    """White text lines on a dark strip `width` pixels wide."""
    image = Image.new("RGB", (width, (size + 6) * len(lines) + 6), (30, 30, 30))
    draw = ImageDraw.Draw(image)
    for i, line in enumerate(lines):
        draw.text((8, 4 + i * (size + 6)), line, fill=(240, 240, 240), font=font(size))
    return np.asarray(image)


def side_by_side(panels: list[list[np.ndarray]], gap: int = 4) -> list[np.ndarray]:
    """Frame t of each panel next to each other, a dark gap between; a panel that has ended shows its last frame."""
    n, line = max(len(p) for p in panels), np.full((panels[0][0].shape[0], gap, 3), 30, np.uint8)
    return [np.concatenate([x for p in panels for x in (line, p[min(t, len(p) - 1)])][1:], axis=1) for t in range(n)]


def write_gif(path: str, frames: list[np.ndarray], durations_ms: list[int], colors: int = 96) -> int:
    """One palette for the whole GIF (fewer bytes, no flicker), looping; temporary name, then renamed. Returns bytes."""
    sample = np.concatenate(frames[:: max(1, len(frames) // 8)], axis=0)
    palette = Image.fromarray(sample).quantize(colors=colors, method=Image.Quantize.MEDIANCUT)
    images = [Image.fromarray(f).quantize(palette=palette, dither=Image.Dither.NONE) for f in frames]
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    images[0].save(path + ".tmp", format="GIF", save_all=True, append_images=images[1:], loop=0,
                   duration=durations_ms)  # fmt: skip
    os.replace(path + ".tmp", path)
    return os.path.getsize(path)


def pusher_gif(run_dir: str, out_dir: str, size: int, frame_step: int) -> str:
    summary = read_summary(run_dir, "inform_sac_pusher.py")
    a = summary["args"]
    env_id, seed = a["env_id"], summary["seed"]
    if env_id == "Pusher-v4" and isp.mujoco_major() >= 3:
        raise ValueError(f"{run_dir} is a Pusher-v4 run, which needs mujoco<3: run this in the mujoco 2.3.7 venv")
    try:
        isp.check_video(env_id)  # the headless GL backend (MUJOCO_GL, egl without a display), or one line
        checkpoints = {p: os.path.join(run_dir, f"{p}_actor.pt") for p in POLICIES}
        actors = {p: isp.actor_from_checkpoint(isp.read_checkpoint(path, "--pusher-run", env_id))
                  for p, path in checkpoints.items()}  # fmt: skip
    except isp.InputError as e:
        raise ValueError(str(e)) from None
    try:
        with np.load(os.path.join(run_dir, "obstacle_paths.npz")) as saved:
            boxes, paths = saved["boxes"], {p: saved[f"{p}_obstacle"] for p in POLICIES}
    except (OSError, ValueError, KeyError) as e:
        raise ValueError(
            f"{run_dir}: no readable obstacle_paths.npz with the boxes and paths ({type(e).__name__})"
        ) from None
    panels = []
    for p, actor in actors.items():
        env = isp.video_env(env_id, seed, boxes, size=size)
        outcome = isp.Outcome(a.get("success_info_key", "reward_dist"), a["success_distance"], a.get("success_return"))
        res = isp.evaluate(actor, env, 1, lambda ep: seed, True, torch.Generator(), outcome)
        frames = env.render()
        env.close()
        path = isp.object_xy(res["trajectories"][0])
        if not np.allclose(path, paths[p], atol=1e-6):  # the GIF must show the episode the run measured
            raise ValueError(f"{run_dir}: {p}'s episode here differs from the run's (obstacle_paths.npz); make the "
                             "GIF with the mujoco and gymnasium versions the run used")  # fmt: skip
        distance = res["final_distance"]
        frames = frames[::frame_step] + ([frames[-1]] if (len(frames) - 1) % frame_step else [])
        head = label(size, [p.upper(), ""])
        done = label(size, [p.upper(), f"final distance {distance:.3f}"])
        panels.append([np.concatenate([head if t < len(frames) - 1 else done, f]) for t, f in enumerate(frames)])
    frames = side_by_side(panels)
    caption = label(frames[0].shape[1], [f"{env_id}, seed {seed}, {'random' if a['random_starts'] else 'fixed'} "
                                         f"start, boxes on the path ({a['obstacle_layout']})",
                                         f"TAMER {budget(a['tamer_total_timesteps'])} env steps, sleep "
                                         f"{budget(a['sleep_gradient_steps'])} gradient steps"], size=12)  # fmt: skip
    frames = [np.concatenate([f, caption]) for f in frames]
    name = (f"{env_id}_tamer_vs_inform_seed{seed}_tamer{budget(a['tamer_total_timesteps'])}_"
            f"sleep{budget(a['sleep_gradient_steps'])}.gif")  # fmt: skip
    ms = int(1000 * frame_step / 20)  # Pusher steps 0.05 s of simulated time: real time
    nbytes = write_gif(os.path.join(out_dir, name), frames, [ms] * (len(frames) - 1) + [2500])
    print(f"{os.path.join(out_dir, name)}: {len(frames)} frames, {nbytes / 1e6:.2f} MB; obstacle final distance "
          + ", ".join(f"{p} {summary[f'eval/obstacle/{p}_final_distance_deterministic']:.3f}" for p in POLICIES)
          + " (the run's, deterministic)", flush=True)  # fmt: skip
    return os.path.join(out_dir, name)


MAZE_IDS = {"plain": "KnoxStoneMaze-v0", "wall": "KnoxStoneMazeWall-v0"}  # gridworld_env registers both


def greedy_episode(policy: np.ndarray, variant: str, start: int) -> tuple[list[int], int, bool]:
    """One greedy episode in the registered maze, as `evaluate` runs it: the cells to draw (the start, then each
    step's, up to G or the first cell seen before: a deterministic policy then loops until the time limit), the
    episode length, and whether G was reached."""
    env = gym.make(MAZE_IDS[variant])
    obs, _ = env.reset(options={"start_cell": start})
    cells = [start]
    length = 0
    terminated = False
    truncated = False
    while not (terminated or truncated):
        obs, _, terminated, truncated, info = env.step(policy[int(obs.argmax())])
        length += 1
        if cells[-1] != gridworld_env.GOAL and cells.count(cells[-1]) == 1:  # no loop yet: draw this step too
            cells.append(info["cell"])
    env.close()
    return cells, length, bool(terminated)


def maze_frames(cells: list[int], variant: str, title: str, length: int, reached: bool) -> list[np.ndarray]:
    """RGB frames of the agent walking `cells` (its path so far as a line); the last frame says how it ended."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = Figure(figsize=(3.2, 3.4), dpi=80)
    canvas = FigureCanvasAgg(fig)
    ax = fig.subplots()
    fig.subplots_adjust(0.02, 0.02, 0.98, 0.86)
    for r, c in gridworld_env.CELLS:
        ax.add_patch(Rectangle((c, r), 1, 1, facecolor="white", edgecolor="0.85"))
    for r, c in gridworld_env.BLOCKED:
        ax.add_patch(Rectangle((c, r), 1, 1, facecolor="0.25"))
    for wall in gridworld_env.VARIANT_WALLS[variant]:
        (r1, c1), (r2, c2) = sorted(wall)
        xs, ys = ([c2, c2], [r1, r1 + 1]) if r1 == r2 else ([c1, c1 + 1], [r2, r2])
        ax.plot(xs, ys, color="black", lw=3)
    for cell, label in ((gridworld_env.START, "S"), (gridworld_env.GOAL, "G")):
        r, c = gridworld_env.CELLS[cell]
        ax.text(c + 0.5, r + 0.5, label, ha="center", va="center", fontsize=12, weight="bold", color="0.55")
    ax.set(xlim=(0, gridworld_env.COLS), ylim=(gridworld_env.ROWS, 0), aspect="equal", xticks=[], yticks=[])
    (path,) = ax.plot([], [], color="tab:blue", lw=2, alpha=0.6)
    (agent,) = ax.plot([], [], "o", color="tab:red", ms=14)
    heading = ax.set_title("", fontsize=9)
    frames = []
    for t in range(len(cells)):
        xs = [gridworld_env.CELLS[cell][1] + 0.5 for cell in cells[: t + 1]]
        ys = [gridworld_env.CELLS[cell][0] + 0.5 for cell in cells[: t + 1]]
        path.set_data(xs, ys)
        agent.set_data(xs[-1:], ys[-1:])
        ending = f"reaches G in {length} steps" if reached else f"loops: never reaches G ({length} steps)"
        heading.set_text(f"{title}\n" + (ending if t == len(cells) - 1 else f"step {t}"))
        canvas.draw()
        frames.append(np.asarray(canvas.buffer_rgba())[..., :3].copy())
    return frames


def maze_gif(run_dir: str, out_dir: str) -> str:
    summary = read_summary(run_dir, "inform_dqn_gridworld.py")
    a = summary["args"]
    try:
        nets = {"tamer": load_q_network(os.path.join(run_dir, "tamer_h.pt"), flag="--maze-run"),
                "inform": load_q_network(os.path.join(run_dir, "inform_q.pt"), flag="--maze-run")}  # fmt: skip
    except maze.InputError as e:
        raise ValueError(str(e)) from None
    policies = {p: maze.greedy_actions(net, torch.device("cpu")) for p, net in nets.items()}
    frames, durations = [], []
    for variant in ("plain", "wall"):
        panels = []
        for p, policy in policies.items():
            cells, length, reached = greedy_episode(policy, variant, gridworld_env.START)
            title = f"{p.upper()}, {'wall maze' if variant == 'wall' else 'maze'}, from S"
            panels.append(maze_frames(cells, variant, title, length, reached))
        episode = side_by_side(panels)
        frames += episode
        durations += [250] * (len(episode) - 1) + [2000]
    caption = label(frames[0].shape[1], [f"{a['env_id']}, seed {summary['seed']}",
                                         f"TAMER {budget(a['tamer_total_timesteps'])} env steps, sleep "
                                         f"{budget(a['sleep_gradient_steps'])} gradient steps"], size=12)  # fmt: skip
    frames = [np.concatenate([f, caption]) for f in frames]
    name = (f"{a['env_id']}_tamer_vs_inform_seed{summary['seed']}_tamer{budget(a['tamer_total_timesteps'])}_"
            f"sleep{budget(a['sleep_gradient_steps'])}.gif")  # fmt: skip
    nbytes = write_gif(os.path.join(out_dir, name), frames, durations, colors=32)
    lengths = [f"{p} {summary[f'eval/{p}_episode_length']:.0f} (wall {summary[f'eval/wall/{p}_episode_length']:.0f})"
               for p in POLICIES]  # fmt: skip
    print(f"{os.path.join(out_dir, name)}: {len(frames)} frames, {nbytes / 1e6:.2f} MB; greedy episode length "
          f"{', '.join(lengths)} (the run's)", flush=True)  # fmt: skip
    return os.path.join(out_dir, name)


def main(args: Args) -> list[str]:
    written = []
    if args.pusher_run is not None:
        written.append(pusher_gif(args.pusher_run, args.out_dir, args.pusher_size, args.pusher_frame_step))
    if args.maze_run is not None:
        written.append(maze_gif(args.maze_run, args.out_dir))
    return written


def parse_args() -> Args:
    """tyro's command line, with tyro's multi-line error box shortened to one line."""
    captured = io.StringIO()
    try:
        with contextlib.redirect_stderr(captured):
            return tyro.cli(Args)
    except SystemExit as e:
        if e.code == 0:  # --help
            raise
        message = []
        for line in captured.getvalue().splitlines()[1:]:  # the first line is the box's title bar
            text = line.strip().strip("│╰╯").strip()
            if not text or set(text) <= set("─"):
                if message:
                    break
                continue
            message.append(text)
        raise ValueError(" ".join(message) + " (see --help)") from None


if __name__ == "__main__":
    try:
        args = parse_args()
        if args.pusher_run is None and args.maze_run is None:
            raise ValueError("pass --pusher-run and/or --maze-run (a run directory)")
        if args.pusher_size < 32 or args.pusher_frame_step < 1:
            raise ValueError("--pusher-size must be >= 32 pixels and --pusher-frame-step >= 1")
        main(args)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
