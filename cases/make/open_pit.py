"""Author cases/scenes/open_pit.toml: the SGIM paper's section 4 example at the paper's scale.

Box x -150..150, y -125..125, z 0..140 (r = 0.5: 10.5 million lattice sites).
A hill landform with a benched open pit: seven benches of 15 m, bench faces at
65 degrees, 8 m berms, an elliptical pit floor at z = 45 m and a haul ramp that
spirals down the wall at about 16 % grade.  Two perpendicular sets of
zero-thickness joints and one fault of thickness 4.0.

The excavating surface is given as points along the bench toes and crests, the
ramp edges, the pit rim and a terrain grid; SGIM triangulates them in plan view
(the paper's way of entering excavating faces).

    python -m cases.make.open_pit          # rewrites cases/scenes/open_pit.toml and cases/scenes/open_pit_coarse.toml
"""
from __future__ import annotations

import math

import numpy as np

from cases import SCENES

BOX = ((-150.0, -125.0, 0.0), (150.0, 125.0, 140.0))
PIT_CENTRE = (15.0, -10.0)
FLOOR_AXES = (38.0, 24.0)
FLOOR_Z = 45.0
BENCH_H = 15.0
FACE_DEG = 65.0
BERM = 8.0
RUN = BENCH_H / math.tan(math.radians(FACE_DEG))
RAMP_WIDTH = 12.0
RAMP_THETA = (math.radians(20.0), math.radians(20.0 + 300.0))  # ramp from rim (start) to floor (end)
NTHETA = 120


def terrain(x, y):
    """Hill landform: a broad hill to the north-west and a lower one to the south-east."""
    return (100.0 + 28.0 * np.exp(-((x + 50.0) ** 2 + (y - 55.0) ** 2) / (2 * 75.0 ** 2))
            + 12.0 * np.exp(-((x - 95.0) ** 2 + (y + 70.0) ** 2) / (2 * 45.0 ** 2))
            + 4.0 * np.sin(x / 37.0) * np.cos(y / 29.0))


def ring_xy(s, theta):
    cx, cy = PIT_CENTRE
    return cx + (FLOOR_AXES[0] + s) * np.cos(theta), cy + (FLOOR_AXES[1] + s) * np.sin(theta)


def staircase(s):
    """Pit wall height at plan offset s from the floor outline."""
    s = np.asarray(s, float)
    k = np.floor(s / (RUN + BERM))
    u = s - k * (RUN + BERM)
    z = FLOOR_Z + BENCH_H * k + np.where(u < RUN, BENCH_H * u / RUN, BENCH_H)
    return np.where(s < 0, FLOOR_Z, z)


def ramp_level(theta):
    t0, t1 = RAMP_THETA
    frac = (theta - t0) / (t1 - t0)
    return RAMP_TOP + frac * (FLOOR_Z - RAMP_TOP)


RAMP_TOP = FLOOR_Z + 4 * BENCH_H  # the ramp leaves the wall at the crest of the fourth bench


def ramp_offset(theta):
    """Plan offset of the ramp centre line: in the wall where the staircase reaches the ramp level."""
    z = ramp_level(theta)
    k = (z - FLOOR_Z) / BENCH_H
    return k * (RUN + BERM) + 0.5 * RUN


def in_ramp(s, theta):
    th = np.mod(theta - RAMP_THETA[0], 2 * math.pi) + RAMP_THETA[0]
    inside = (th >= RAMP_THETA[0]) & (th <= RAMP_THETA[1])
    sc = ramp_offset(np.clip(th, *RAMP_THETA))
    return inside & (np.abs(s - sc) <= RAMP_WIDTH / 2 + 2.0)


def rim_offset(theta):
    """Offset where the wall meets the terrain along each ray."""
    s = np.linspace(0, 200, 4001)
    out = np.empty(len(theta))
    for i, th in enumerate(theta):
        x, y = ring_xy(s, th)
        gap = staircase(s) - terrain(x, y)
        k = int(np.argmax(gap >= 0))
        out[i] = s[k]
    return out


def points():
    theta = np.linspace(0, 2 * math.pi, NTHETA, endpoint=False)
    rim = rim_offset(theta)
    pts = []
    # floor
    cx, cy = PIT_CENTRE
    for gx in np.arange(-30, 31, 10.0):
        for gy in np.arange(-15, 16, 10.0):
            if (gx / (FLOOR_AXES[0] - 4)) ** 2 + (gy / (FLOOR_AXES[1] - 4)) ** 2 < 1:
                pts.append((cx + gx, cy + gy, FLOOR_Z))
    # bench toe and crest rings, below the terrain and outside the ramp
    offsets = []
    for k in range(12):
        offsets += [(k * (RUN + BERM), FLOOR_Z + k * BENCH_H), (k * (RUN + BERM) + RUN, FLOOR_Z + (k + 1) * BENCH_H)]
    for s, z in offsets:
        for th, sr in zip(theta, rim):
            if s < sr - 1.0 and not in_ramp(s, th):
                x, y = ring_xy(s, th)
                pts.append((x, y, z))
    # ramp edges (inner = downhill edge at the ramp level, outer = uphill edge)
    tr = np.linspace(*RAMP_THETA, 101)
    for th in tr:
        sc = ramp_offset(th)
        z = ramp_level(th)
        for s in (sc - RAMP_WIDTH / 2, sc + RAMP_WIDTH / 2):
            x, y = ring_xy(s, th)
            pts.append((x, y, z))
    # rim on the terrain
    for th, sr in zip(theta, rim):
        x, y = ring_xy(sr, th)
        pts.append((x, y, float(terrain(x, y))))
    # terrain grid outside the rim (extends 5 m past the box so every column is covered)
    (x1, y1, _), (x2, y2, _) = BOX
    for gx in np.arange(x1 - 5, x2 + 5.1, 10.0):
        for gy in np.arange(y1 - 5, y2 + 5.1, 10.0):
            th = math.atan2((gy - cy) / (FLOOR_AXES[1]), (gx - cx) / (FLOOR_AXES[0])) % (2 * math.pi)
            i = int(round(th / (2 * math.pi) * NTHETA)) % NTHETA
            sx, sy = ring_xy(rim[i] + 6.0, theta[i])
            if math.hypot(gx - cx, gy - cy) > math.hypot(sx - cx, sy - cy):
                pts.append((gx, gy, float(terrain(gx, gy))))
    return np.round(np.array(pts), 3)


def discontinuities():
    rng = np.random.default_rng(2013)
    out = []
    # set 1: steep joints, dip 75 / 040; set 2: flat joints, dip 15 / 220 (normals perpendicular)
    for name, dip, dd, n in (("joint set 1", 75.0, 40.0, 9), ("joint set 2", 15.0, 220.0, 9)):
        for i in range(n):
            c = (rng.uniform(-110, 110), rng.uniform(-90, 90), rng.uniform(20, 85))
            out.append(dict(name=f"{name} #{i + 1}", centre=[round(v, 2) for v in c], dip=dip,
                            dip_direction=dd, radius=round(float(rng.uniform(30, 45)), 1), thickness=0.0))
    out.append(dict(name="fault F1", centre=[-20.0, 10.0, 60.0], dip=62.0, dip_direction=300.0, radius=160.0,
                    thickness=4.0))
    return out


COARSE_HEADER = [
    "# The open pit of cases/scenes/open_pit.toml at r = 2.5 m in FCC packing (written by cases/make/open_pit.py):",
    "# about 80 000 spheres, a size YADE and LIGGGHTS run (cases/scenes/open_pit_deck.toml; central-spring bonds",
    "# need a packing that is not a mechanism, hence FCC).",
]


def toml_text(name="open_pit", kind="cubic", radius=0.5, header=None):
    lines = [
        *(header or [
            "# The SGIM paper's section 4 example at the paper's scale (written by cases/make/open_pit.py).",
            "# Open-pit slope in a hill landform: 7 benches of 15 m, faces 65 deg, 8 m berms, a spiral ramp,",
            "# two perpendicular joint sets (zero thickness: green / blue) and a 4 m fault (red).",
        ]),
        f'name = "{name}"',
        "",
        "[domain]",
        f"min = {list(BOX[0])}",
        f"max = {list(BOX[1])}",
        "",
        "[packing]",
        f'kind = "{kind}"',
        f"radius = {radius}",
        "",
        "[bonds]",
        'rule = "colour"',
        "",
        "[output]",
        "# add \"txt\" for the PFC-style ball and bond lists (about 0.7 GB at this size)",
        'formats = ["npz", "vtu", "png"]',
        "",
        "[render]",
        "hide_intact = false",
        "translucent = false",
        'cut_away = []  # e.g. ["y<-10"] to see inside',
        "",
    ]
    for d in discontinuities():
        lines += disc_lines(d)
    lines += excavation_lines()
    return "\n".join(lines)


def disc_lines(d):
    """TOML lines of one [[discontinuity]] disc."""
    return ["[[discontinuity]]", f'name = "{d["name"]}"', f"centre = {d['centre']}",
            f"dip = {d['dip']}", f"dip_direction = {d['dip_direction']}", f"radius = {d['radius']}",
            f"thickness = {d['thickness']}", ""]


def excavation_lines():
    """TOML lines of the pit-and-terrain [[excavation]] surface."""
    return ["[[excavation]]", 'name = "pit and terrain"', 'rule = "paper"', "points = [",
            *(f"  [{x:g}, {y:g}, {z:g}]," for x, y, z in points()), "]", ""]


def main():
    for path, text in ((SCENES / "open_pit.toml", toml_text()),
                       (SCENES / "open_pit_coarse.toml", toml_text("open_pit_coarse", "fcc", 2.5, COARSE_HEADER))):
        path.write_text(text)
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
