"""``dda wedge``: the friction search, the command line, and the DDA factor of safety against Hoek & Bray.

References: synthetic sliding thresholds for the search; the Hoek & Bray short formula transcribed here for
the analytical output; for the DDA runs, the analytical factor of safety (target: within 0.5 %).
"""

import json
import math

import numpy as np
import pytest

from dda import wedge as W


def hb_short(ja, jb, phi):
    """Hoek & Bray friction-only wedge FS, written out from the textbook formula."""
    def n(dip, dd):
        d, a = math.radians(dip), math.radians(dd)
        return np.array([math.sin(d) * math.sin(a), math.sin(d) * math.cos(a), math.cos(d)])

    na, nb = n(*ja), n(*jb)
    c = float(na @ nb)
    line = np.cross(na, nb)
    psi5 = math.asin(abs(line[2]) / np.linalg.norm(line))
    a = (math.cos(math.radians(ja[0])) - math.cos(math.radians(jb[0])) * c) / (math.sin(psi5) * (1 - c * c))
    b = (math.cos(math.radians(jb[0])) - math.cos(math.radians(ja[0])) * c) / (math.sin(psi5) * (1 - c * c))
    return (a + b) * math.tan(math.radians(phi))


@pytest.mark.parametrize("threshold,start", [(19.707, 25.0), (33.3, 40.0), (31.0, 25.0), (3.3, 25.0)])
def test_bracket_and_bisect(threshold, start):
    calls = []

    def slides(phi):
        calls.append(phi)
        return phi < threshold

    phi, trials = W.bracket_and_bisect(slides, start, step=2.0, tol=0.05)
    assert abs(phi - threshold) <= 0.025 + 1e-12
    assert [p for p, _ in trials] == calls and all(s == (p < threshold) for p, s in trials)
    # bracketing goes in steps of 2 degrees from the start, as the paper lowers friction step by step
    k = 0
    while k + 1 < len(calls) and abs(abs(calls[k + 1] - calls[k]) - 2.0) < 1e-12:
        k += 1
    assert k >= 1 and calls[0] == start


def test_parse_orientation():
    assert W.parse_orientation("45/005", "--joint") == (45.0, 5.0)
    assert W.parse_orientation("90/360", "--face") == (90.0, 0.0)
    for bad in ("45", "45/5x", "95/10", "-1/10", "45/400", "a/b"):
        with pytest.raises(W.WedgeInputError):
            W.parse_orientation(bad, "--joint")


def test_cli_analytical_json(capsys):
    rc = W.main(["wedge", "--joint", "45/005", "--joint", "55/135", "--face", "65/065", "--height", "10",
                 "--friction", "25", "--analytical-only", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["fs_hoek_bray"] == pytest.approx(hb_short((45, 5), (55, 135), 25), rel=1e-12)
    assert round(out["fs_hoek_bray"], 3) == 1.302
    assert math.tan(math.radians(25)) / math.tan(math.radians(out["phi_crit_hoek_bray"])) == pytest.approx(
        out["fs_hoek_bray"], rel=1e-12)


@pytest.mark.parametrize("argv", [
    ["--joint", "45/005", "--face", "65/065"],                       # one joint only
    ["--joint", "45/5x", "--joint", "55/135", "--face", "65/065"],  # unreadable
    ["--joint", "45/005", "--joint", "55/135", "--face", "20/065"],  # no daylight
    ["--joint", "45/005", "--joint", "45/005", "--face", "65/065"],  # parallel joints
])
def test_cli_bad_input(argv, capsys):
    rc = W.main(["wedge", *argv, "--height", "10", "--friction", "25", "--analytical-only"])
    cap = capsys.readouterr()
    assert rc == 2 and cap.out == ""
    assert len(cap.err.strip().splitlines()) == 1 and cap.err.startswith("dda wedge: ")


# ---------------------------------------------------------------------------------------------------------
# DDA runs (explicit engine): kept short, coarse stiffness and short trials

FAST = dict(penetration=1e-4, duration=1.0)


def test_dda_wedge_holds_and_slides():
    m = W.WedgeModel((45, 5), (55, 135), (65, 65), height=10.0, **FAST)
    assert not m.slides(30.0)
    assert m.slides(12.0)
    # a wedge that slides accelerates along the line of intersection at g sin(psi5) (1 - FS)
    s_half, s_3q, s_end = m.runs[-1][1]
    fs = hb_short((45, 5), (55, 135), 12.0)
    a = 9.81 * math.sin(math.radians(m.geom.line_plunge)) * (1 - fs)
    assert (s_end - s_half) == pytest.approx(0.5 * a * (1.0 - 0.25), rel=0.05)


@pytest.mark.parametrize("ja,jb,face,phi", [((45, 5), (55, 135), (65, 65), 25.0),       # the paper's case
                                            ((40, 160), (60, 260), (75, 200), 35.0),
                                            ((50, 100), (65, 210), (75, 150), 35.0),
                                            ((35, 20), (70, 130), (70, 70), 30.0),
                                            ((60, 300), (45, 60), (70, 0), 40.0)])
def test_dda_fs_matches_hoek_bray(ja, jb, face, phi):
    res = W.dda_critical_friction(ja, jb, face, height=10.0, friction=phi, tol=0.05, **FAST)
    ref = hb_short(ja, jb, phi)
    assert res["fs_dda"] == pytest.approx(ref, rel=0.005)
