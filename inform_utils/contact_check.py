"""How close is "the 2.3 contact on MuJoCo 4" (contact_as_mujoco23, make_env's default) to MuJoCo 2.3.7 itself?

--record plays Pusher-v4 and Pusher-v5 in the venv it runs in, under each contact that venv has (MuJoCo 4: mujoco-2.3
and gymnasium; 2.3.7: the one), and saves: the object's xy path (obs[17:19]) step by step over RANDOM_EPISODES
episodes of fixed random actions (a numpy Generator seeded by the reset seed, uniform in the action bounds: the same
actions in both venvs); the v4 teacher's deterministic episodes from the held-out starts (reset seeds 1000-1099): its
final distance |info['reward_dist']|, success (< 0.08), return and the object's path (and under 2.3.7 its actions);
with --replay REF, REF's (2.3.7's) teacher actions replayed open-loop from the same starts, the arm-object contact
exercised by the same actions; each compiled model's numeric constants, and each env's body_invweight0. --compare
prints the largest gap of the object's paths between two recordings (and the first step at which a gap exceeds
1 mm), the teacher's results side by side, and the model constants that differ. --table prints
inform_utils/pusher_contact.py's table with contact_as_mujoco23 applied to its model. --disable (MuJoCo flags) and
--geom-margin change the models of --record and --table, to find what else differs.

Measured (results/contact_check/report.txt): random actions never touch the object (no gap). With the 2.3 contact,
MuJoCo 4's paths leave 2.3.7's at the first touch (> 1 mm in 100 of 100 teacher episodes, the median episode's largest
gap 4-5 mm, 337 mm in the one the teacher fails under MuJoCo 4); the teacher succeeds on 98/100 (2.3.7: 100). Three
changes of MuJoCo make the rest: a geom pair's margin is the sum of the two (4 mm) where 2.3.7 took the larger (2 mm),
so contacts start 2 mm earlier; capsule-cylinder collisions use MuJoCo's native CCD (2.3.7: libccd's MPR) with
multi-contact on, which near the object's top rim give other normals (the failed episode: the top face's, and the fork
rides over the object, where 2.3.7's normal tilts sideways and carries it along). With --geom-margin 0.001 --disable
NATIVECCD MULTICCD the paths match 2.3.7's to < 1 um and pusher_contact's table to its last digit. The constants that
differ (dof_invweight0 of the slides, the bounding volumes, geom_aabb) change nothing here.

    .venv-v4/bin/python -m inform_utils.contact_check --record results/contact_check/mujoco237.npz
    .venv/bin/python -m inform_utils.contact_check --record results/contact_check/mujoco4.npz \
        --replay results/contact_check/mujoco237.npz
    .venv/bin/python -m inform_utils.contact_check --compare results/contact_check/mujoco237.npz \
        results/contact_check/mujoco4.npz
    .venv/bin/python -m inform_utils.contact_check --table
"""

import os
import warnings
from dataclasses import dataclass, field

import mujoco
import numpy as np
import torch
import tyro

import inform_sac_pusher as isp
from inform_utils.pusher_contact import HEADER, OBJECT, PUSHERS

ENVS = {"Pusher-v4": "pusher.xml", "Pusher-v5": "pusher_v5.xml"}
REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TEACHER = "oracles/Pusher-v4__sac_oracle.pt"  # under REPO
FIRST_SEED, RANDOM_EPISODES, TEACHER_EPISODES, STEPS = 1000, 20, 100, 100  # STEPS: Pusher's episode
SUCCESS, GAP = 0.08, 1e-3  # the success tag (m); a path gap worth reporting (m)


def episode(env, seed: int, act) -> tuple[np.ndarray, np.ndarray, float, float]:
    """(actions, the object's xy before each step and after the last, final distance, return) of one episode from
    reset seed `seed`; act(obs, step) gives the action."""
    obs, _ = env.reset(seed=seed)
    path, actions, ep_return, done, info = [isp.object_xy(obs)], [], 0.0, False, {}
    while not done:
        actions.append(np.asarray(act(obs, len(actions)), dtype=np.float64))
        obs, reward, terminated, truncated, info = env.step(actions[-1])
        path.append(isp.object_xy(obs))
        ep_return, done = ep_return + float(reward), terminated or truncated
    return np.array(actions), np.array(path), abs(float(info["reward_dist"])), ep_return


def open_loop(env, seed: int, actions: np.ndarray) -> np.ndarray:  # the object's path under a fixed action sequence
    return episode(env, seed, lambda obs, step: actions[step])[1]


def random_actions(env, seed: int) -> np.ndarray:  # one episode's fixed random actions, the same in any venv
    low, high = env.action_space.low, env.action_space.high
    return np.random.default_rng(seed).uniform(low, high, size=(STEPS, len(low)))


def adjust(model, disable: list[str], margin: float | None) -> None:
    """--disable's MuJoCo flags (mjDSBL_ + name) and --geom-margin (every geom's margin) applied to the model."""
    for flag in disable:
        model.opt.disableflags |= int(getattr(mujoco.mjtDisableBit, f"mjDSBL_{flag}"))
    if margin is not None:
        model.geom_margin[:] = margin


def constants(model) -> dict:
    """Every numeric array (and number) of the model and of its opt, by name."""
    out = {}
    for obj, prefix in [(model, ""), (model.opt, "opt.")]:
        for name in dir(obj):
            value = getattr(obj, name, None) if not name.startswith("_") else None
            if isinstance(value, np.ndarray | int | float) and np.asarray(value).dtype.kind in "biuf":
                out[prefix + name] = np.asarray(value)
    return out


def pack(consts: dict) -> dict:  # one array of names ("name:shape") and one of values: a small npz
    names = sorted(consts)
    shapes = [",".join(map(str, np.shape(consts[k]))) for k in names]
    values = [np.asarray(consts[k], dtype=np.float64).ravel() for k in names]
    names = [f"{k}:{s}" for k, s in zip(names, shapes, strict=True)]
    return {"names": np.array(names), "values": np.concatenate(values)}


def unpack(names: np.ndarray, values: np.ndarray) -> dict:
    out, start = {}, 0
    for entry in names:
        name, shape = str(entry).split(":")
        shape = tuple(int(n) for n in shape.split(",") if n)
        out[name], start = values[start : start + int(np.prod(shape))].reshape(shape), start + int(np.prod(shape))
    return out


def record(out: str, replay: str | None, disable: list[str], margin: float | None) -> None:
    import gymnasium.envs.mujoco as gym_mujoco

    torch.set_num_threads(1)
    ckpt = torch.load(os.path.join(REPO, TEACHER), weights_only=True)
    actor, _ = isp.oracle_from_checkpoint(ckpt, torch.device("cpu"))
    teacher = torch.no_grad()(lambda obs, step: actor.get_action(torch.as_tensor(obs, dtype=torch.float32)[None])[2][0])
    ref = np.load(replay) if replay else None
    changes = " ".join(disable + ([] if margin is None else [f"geom_margin={margin}"]))
    rec = {"mujoco": np.array(mujoco.__version__), "changes": np.array(changes)}
    contacts = ["mujoco-2.3"] + (["gymnasium"] if isp.mujoco_major() >= 3 else [])
    for env_id, xml in ENVS.items():
        model = mujoco.MjModel.from_xml_path(os.path.join(os.path.dirname(gym_mujoco.__file__), "assets", xml))
        rec |= {f"model/{env_id}/{k}": v for k, v in pack(constants(model)).items()}
        for contact in contacts:
            env, key = isp.make_env(env_id, 0, contact=contact), f"{env_id}/{contact}"
            adjust(env.unwrapped.model, disable, margin)
            rec[f"{key}/body_invweight0"] = env.unwrapped.model.body_invweight0.copy()
            paths = [open_loop(env, s, random_actions(env, s)) for s in range(FIRST_SEED, FIRST_SEED + RANDOM_EPISODES)]
            rec[f"{key}/random_paths"] = np.array(paths, dtype=np.float32)
            teacher_runs = [episode(env, s, teacher) for s in range(FIRST_SEED, FIRST_SEED + TEACHER_EPISODES)]
            for i, part in enumerate(["teacher_actions", "teacher_paths", "teacher_distance", "teacher_return"]):
                rec[f"{key}/{part}"] = np.array([r[i] for r in teacher_runs], dtype=np.float32 if i < 2 else np.float64)
            if isp.mujoco_major() >= 3:  # the actions kept are 2.3.7's (float32 as the actor gave them), to replay
                del rec[f"{key}/teacher_actions"]
            if ref is not None and f"{env_id}/mujoco-2.3/teacher_actions" in ref:
                plays = ref[f"{env_id}/mujoco-2.3/teacher_actions"]
                paths = [open_loop(env, FIRST_SEED + i, actions) for i, actions in enumerate(plays)]
                rec[f"{key}/replay_paths"] = np.array(paths, dtype=np.float32)
            env.close()
            print(f"{key}: recorded", flush=True)
    np.savez_compressed(out, **rec)
    print(f"wrote {out} (mujoco {mujoco.__version__}{'; ' + changes if changes else ''})")


def path_gap(a: np.ndarray, b: np.ndarray, gap: float = GAP) -> dict:
    """The largest distance between the object's xy in paths a and b ([episode, step, 2]) and where it is; the first
    step at which any episode's gap exceeds `gap` (None: none does), how many episodes ever exceed it, the median over
    episodes of each one's largest gap, and how far the object moves from its start in a at most (so that a gap of 0
    where it never moves means nothing)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    dist = np.linalg.norm(a - b, axis=-1)
    episode_, step = np.unravel_index(int(np.argmax(dist)), dist.shape)
    over = dist > gap
    first = int(np.argmax(over.any(axis=0))) if over.any() else None
    moved = float(np.linalg.norm(a - a[:, :1], axis=-1).max())
    return {"largest": float(dist.max()), "episode": int(episode_), "step": int(step), "first_over": first,
            "episodes_over": int(over.any(axis=1).sum()), "episodes": len(dist), "moved": moved,
            "median": float(np.median(dist.max(axis=1)))}  # fmt: skip


def relative_gap(x, y) -> np.ndarray:  # |x - y| / max(|x|, |y|) entrywise, 0 where both are 0
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.nan_to_num(np.abs(x - y) / np.maximum(np.abs(x), np.abs(y)), nan=0.0)


def differing_constants(a: dict, b: dict, rel: float = 1e-9) -> dict:
    """{name: (differing entries, entries, largest relative difference)} of the constants named in both a and b whose
    shapes differ (entries -1) or whose values differ beyond `rel` relative."""
    out = {}
    for name in sorted(set(a) & set(b)):
        if np.shape(a[name]) != np.shape(b[name]):
            out[name] = (-1, np.size(a[name]), np.inf)
        elif (r := relative_gap(a[name], b[name])).size and r.max() > rel:
            out[name] = (int((r > rel).sum()), r.size, float(r.max()))
    return out


def runs(rec) -> list[str]:  # the env/contact pairs of a recording
    return sorted({k.rsplit("/", 1)[0] for k in rec if k.endswith("/random_paths")})


def compare(path_a: str, path_b: str) -> None:
    a, b = np.load(path_a), np.load(path_b)
    for label, path, r in [("A", path_a, a), ("B", path_b, b)]:
        print(f"{label} = {path}: mujoco {r['mujoco']}, model changes: {r['changes'] or '-'}")
    for run_a in runs(a):
        for run_b in (r for r in runs(b) if r.split("/")[0] == run_a.split("/")[0]):
            iw = relative_gap(a[f"{run_a}/body_invweight0"], b[f"{run_b}/body_invweight0"]).max()
            print(f"{run_a} (A) vs {run_b} (B); body_invweight0 differs by up to {iw:.2g} relative")
            for part, label in [("random", "random actions"), ("teacher", "teacher, closed loop"),
                                ("replay", "A's teacher actions replayed")]:  # fmt: skip
                pa, pb = f"{run_a}/{'teacher' if part == 'replay' else part}_paths", f"{run_b}/{part}_paths"
                if pa in a and pb in b:
                    g = path_gap(a[pa], b[pb])
                    print(f"  {label:29s} largest gap {g['largest'] * 1000:8.4f} mm (episode {g['episode']:2d}, step "
                          f"{g['step']:3d}; median episode {g['median'] * 1000:7.4f}), > 1 mm from step "
                          f"{g['first_over']} in {g['episodes_over']:3d}/{g['episodes']} episodes; the object moves up "
                          f"to {g['moved']:.3f} m")  # fmt: skip
    print(f"the v4 teacher, deterministic, reset seeds {FIRST_SEED}-{FIRST_SEED + TEACHER_EPISODES - 1}: "
          "success / mean final distance (m) / mean return")  # fmt: skip
    for label, r in [("A", a), ("B", b)]:
        for run in runs(r):
            d = r[f"{run}/teacher_distance"]
            print(f"  {label} mujoco {str(r['mujoco']):6s} {run:22s} {np.mean(d < SUCCESS):5.2f} / {d.mean():.4f} / "
                  f"{r[f'{run}/teacher_return'].mean():8.3f}")  # fmt: skip
    for env_id in ENVS:
        ca, cb = (unpack(r[f"model/{env_id}/names"], r[f"model/{env_id}/values"]) for r in (a, b))
        print(f"{env_id}'s model as compiled (no contact change): constants that differ beyond 1e-9 relative; named "
              f"only in A: {' '.join(sorted(set(ca) - set(cb)))}; {len(set(cb) - set(ca))} only in B, of opt: "
              f"{' '.join(k for k in sorted(set(cb) - set(ca)) if k.startswith('opt.'))}")  # fmt: skip
        for k, (n, size, r) in differing_constants(ca, cb).items():
            what = f"shape {ca[k].shape} vs {cb[k].shape}" if n < 0 else f"{n}/{size} entries, up to {r:.3g} relative"
            print(f"  {k:18s} {what}")


def push23(pusher: str, speed: float, disable=(), margin=None, seconds: float = 5.0) -> tuple[float, float]:
    """pusher_contact.push with contact_as_mujoco23 (and then `adjust`) applied to its model."""
    xml = f'{HEADER}{OBJECT}<body name="p" mocap="true" pos="-0.2 0 -0.275">{pusher}</body></worldbody></mujoco>'
    model = mujoco.MjModel.from_xml_string(xml)
    isp.contact_as_mujoco23(model)
    adjust(model, list(disable), margin)
    data = mujoco.MjData(model)
    for step in range(round(seconds / model.opt.timestep)):
        data.mocap_pos[0, 0] = -0.2 + speed * step * model.opt.timestep
        mujoco.mj_step(model, data)
    return float(np.linalg.norm(data.qvel[:2])), float(data.xpos[model.body("object").id][0] - data.mocap_pos[0, 0])


def table(disable: list[str], margin: float | None) -> None:
    changes = " ".join(disable + ([] if margin is None else [f"geom_margin={margin}"]))
    print(f"mujoco {mujoco.__version__}, the 2.3 contact{'; ' + changes if changes else ''}: object speed (m/s) / "
          "pusher behind the object's centre (m) after 5 s")  # fmt: skip
    for name, pusher in PUSHERS.items():
        pushes = [(v, *push23(pusher, v, disable, margin)) for v in (0.05, 0.07, 0.08, 0.09, 0.10, 0.11)]
        cells = [f"{v:.2f}: {speed:.3f} / {gap:+.3f}" for v, speed, gap in pushes]
        print(f"  {name:40s} " + "   ".join(cells))


@dataclass
class Args:
    record: str | None = None
    """play the recordings in this venv and write them to this .npz"""
    compare: tuple[str, str] | None = None
    """print the gaps between two recordings (A: 2.3.7's, B: MuJoCo 4's)"""
    table: bool = False
    """print pusher_contact's table under the 2.3 contact"""
    replay: str | None = None
    """with --record: replay this (2.3.7) recording's teacher actions open-loop"""
    disable: list[str] = field(default_factory=list)
    """with --record or --table: MuJoCo flags to set (mjDSBL_ + name), e.g. NATIVECCD MULTICCD"""
    geom_margin: float | None = None
    """with --record or --table: every geom's margin set to this"""


def main(args: Args) -> None:
    if [args.record is not None, args.compare is not None, args.table].count(True) != 1:
        raise SystemExit("contact_check: give one of --record OUT.npz, --compare A.npz B.npz, --table")
    if missing := [f"mjDSBL_{flag}" for flag in args.disable if not hasattr(mujoco.mjtDisableBit, f"mjDSBL_{flag}")]:
        raise SystemExit(f"contact_check: mujoco {mujoco.__version__} has no {' '.join(missing)}")
    warnings.filterwarnings("ignore")  # Gymnasium's deprecation of Pusher-v4
    if args.record:
        record(args.record, args.replay, args.disable, args.geom_margin)
    elif args.compare:
        compare(*args.compare)
    else:
        table(args.disable, args.geom_margin)


if __name__ == "__main__":
    main(tyro.cli(Args))
