"""Author cases/scenes/open_pit_dfn.toml: the open pit of cases/scenes/open_pit.toml in a Monte-Carlo joint network.

Same box, packing, pit surface and fault F1 as cases/make/open_pit.py; the hand-written joints are
replaced by three Fisher joint sets with truncated power-law radii and P32 targets (a few thousand
fractures), sampled from [dfn] seed by sgim:

* J1  steep joints  dip 75 / 040, kappa 30
* J2  flat joints   dip 15 / 220, kappa 25
* J3  cross joints  dip 80 / 310, kappa 20

    python -m cases.make.open_pit_dfn      # rewrites cases/scenes/open_pit_dfn.toml
    sgim dfn cases/scenes/open_pit_dfn.toml -o out/open_pit_dfn_network
    sgim build cases/scenes/open_pit_dfn.toml -o out/open_pit_dfn
"""
from __future__ import annotations

from cases import SCENES
from cases.make.open_pit import BOX, disc_lines, discontinuities, excavation_lines

SETS = (
    # name, dip, dip direction, kappa, P32 (1/m)
    ("J1", 75.0, 40.0, 30.0, 0.045),
    ("J2", 15.0, 220.0, 25.0, 0.03),
    ("J3", 80.0, 310.0, 20.0, 0.025),
)
RADIUS = {"law": "power", "exponent": 2.7, "min": 3.0, "max": 40.0}


def toml_text():
    lines = [
        "# The open pit of cases/scenes/open_pit.toml in a Monte-Carlo joint network (written by cases/make/open_pit_dfn.py).",
        "# Three Fisher joint sets (truncated power-law radii, P32 targets) replace the hand-written joints;",
        "# the fault F1 (4 m, red) stays.  `sgim dfn` writes the network alone; `sgim build` applies it.",
        'name = "open_pit_dfn"',
        "",
        "[domain]",
        f"min = {list(BOX[0])}",
        f"max = {list(BOX[1])}",
        "",
        "[packing]",
        'kind = "cubic"',
        "radius = 0.5",
        "",
        "[bonds]",
        'rule = "colour"',
        "",
        "[output]",
        'formats = ["npz", "vtu", "png"]',
        "",
        "[render]",
        "hide_intact = false",
        "translucent = false",
        "cut_away = []",
        "",
        "[dfn]",
        "seed = 2013",
        "max_fractures = 200000",
        "",
    ]
    for name, dip, dd, kappa, p32 in SETS:
        lines += ["[[joint_set]]", f'name = "{name}"', f"dip = {dip}", f"dip_direction = {dd}", f"kappa = {kappa}",
                  f"p32 = {p32}", "thickness = 0.0", "[joint_set.radius]",
                  *(f'{k} = "{v}"' if isinstance(v, str) else f"{k} = {v}" for k, v in RADIUS.items()), ""]
    for d in discontinuities():
        if d["thickness"] > 0:
            lines += disc_lines(d)
    lines += excavation_lines()
    return "\n".join(lines)


def main():
    path = SCENES / "open_pit_dfn.toml"
    path.write_text(toml_text())
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
