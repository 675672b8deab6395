"""How fast can anything push Pusher-v5's object? A measurement of the contact, not a controller (issue 54).

Under MuJoCo >= 3 the arm-object contact of Pusher-v5 is very soft. MuJoCo regularises a contact by
R = (1 - d) / d * (body_invweight0[object] + body_invweight0[pusher]) (d = 0.95, solimp's dmax). MuJoCo 4 computes
the object's body_invweight0 from its mass alone (7.85e-6 kg: 1.27e5), where 2.3.7 counted the slide joints' armature
(0.04: 16.7). So R is ~6,700 against 1.9, and a steady contact force is f = k d^2 |r| / ((1 - d) diagApprox), about
0.39 N per metre of penetration r (k = 1 / (dmax timeconst)^2). The object's slides have damping 0.5, so it moves at
v = f / 0.5: one contact pushes it at most ~0.05 m/s before the pusher reaches its axis (r = 0.07) and passes through
it. Two contacts at once (a corner of the fork) double f at the same r.

This script drives a kinematic (mocap) pusher at a constant speed into the object of Pusher's own physics (timestep,
armature, damping, margin, solver) and prints the object's speed and how far the pusher sits behind its centre after
5 s; a pusher that passed through leaves the object behind (speed 0). Measured with MuJoCo 4.0.0 (the v5 venv):

    one capsule (the crossbar, or a vertical bar)        follows at 0.05 m/s, passes through at 0.07
    a fork's inner corner, the object on its bisector    follows at 0.08, passes through at 0.09
    the fork's outer corner (two end caps), leading      follows at 0.10, passes through at 0.11

and under MuJoCo 2.3.7 (Pusher-v4's venv: the same model pushes at any of these speeds). The SAC teacher pushes
with the fork's inner corner, both contacts 5-6 cm deep, at 0.04-0.07 m/s.

    python -m inform_utils.pusher_contact
"""

import mujoco
import numpy as np

OBJECT = """<body name="object" pos="0 0 -0.275"><geom type="cylinder" size="0.05 0.05" density="0.01" contype="1"
conaffinity="0"/><joint type="slide" axis="0 1 0" damping="0.5"/><joint type="slide" axis="1 0 0" damping="0.5"/>
</body>"""
HEADER = """<mujoco><compiler inertiafromgeom="true"/><option timestep="0.01" gravity="0 0 0" iterations="20"
integrator="Euler"/><default><joint armature="0.04" damping="1"/><geom friction=".8 .1 .1" density="300" margin="0.002"
condim="1" contype="0" conaffinity="0"/></default><worldbody><geom type="plane" pos="0 0.5 -0.325" size="1 1 0.1"
contype="1" conaffinity="1"/>"""


def capsule(start: str, end: str) -> str:  # the fork's capsules: radius 0.02, colliding
    return f'<geom type="capsule" fromto="{start} {end}" size="0.02" contype="1" conaffinity="1"/>'


# pushers along +x, each touching the object first at the origin of its body (placed 0.2 m behind the object)
PUSHERS = {
    "one capsule (the crossbar)": capsule("0 -0.1 0", "0 0.1 0"),
    "one vertical capsule": capsule("0 0 -0.04", "0 0 0.1"),
    "inner corner, object on its bisector": capsule("0 0 0", "0.1414 0.1414 0") + capsule("0 0 0", "0.0707 -0.0707 0"),
    "outer corner (two end caps), leading": capsule("0 0 0", "-0.0707 0.0707 0")
    + capsule("0 0 0", "-0.0707 -0.0707 0"),
}


def push(pusher: str, speed: float, seconds: float = 5.0) -> tuple[float, float]:
    """(object's speed, pusher's distance behind the object's centre) after `seconds` of a push at `speed`."""
    xml = f'{HEADER}{OBJECT}<body name="p" mocap="true" pos="-0.2 0 -0.275">{pusher}</body></worldbody></mujoco>'
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    for step in range(round(seconds / model.opt.timestep)):
        data.mocap_pos[0, 0] = -0.2 + speed * step * model.opt.timestep
        mujoco.mj_step(model, data)
    return float(np.linalg.norm(data.qvel[:2])), float(data.xpos[model.body("object").id][0] - data.mocap_pos[0, 0])


def main() -> None:
    print(f"mujoco {mujoco.__version__}: object speed (m/s) / pusher behind the object's centre (m) after 5 s")
    for name, pusher in PUSHERS.items():
        cells = [
            f"{v:.2f}: {s:.3f} / {gap:+.3f}"
            for v in (0.05, 0.07, 0.08, 0.09, 0.10, 0.11)
            for s, gap in [push(pusher, v)]
        ]
        print(f"  {name:40s} " + "   ".join(cells))


if __name__ == "__main__":
    main()
