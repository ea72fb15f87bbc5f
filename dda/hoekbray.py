"""Analytical factor of safety of a rock wedge (Hoek & Bray, Rock Slope Engineering).

Planes are given as ``(dip, dip_direction)`` in degrees (x east, y north, z up; upward unit normal from
``sgim.geometry.dip_to_normal``). Numbering as in Hoek & Bray: plane 1 = joint A, plane 2 = joint B,
plane 3 = upper slope (top) surface, plane 4 = slope face; lines of intersection 1 = A with the face,
2 = B with the face, 3 = A with the top, 4 = B with the top, 5 = A with B.

Geometry. The toe of the wedge (where line 5 meets the face) is the origin. The slope face passes through
it; the top surface passes through the crest point reached by going up the face's dip line to height
``height`` (so ``height`` is the slope height; with a horizontal top it is also the wedge height). The wedge is
the tetrahedron above A and B (on the side of their upward normals), behind the face and below the top.
Its vertices: the toe O = A.B.face, P5 = A.B.top (top of line 5), P1 = A.face.top, P2 = B.face.top.

Three solutions are given (dry slope, no tension crack, no external load):

1. ``fs_friction_only``, Hoek & Bray's short formula for cohesionless joints,
       FS = A tan(phi_A) + B tan(phi_B),
       A = (cos psi_a - cos psi_b cos theta_na.nb) / (sin psi_5 sin^2 theta_na.nb),
       B = (cos psi_b - cos psi_a cos theta_na.nb) / (sin psi_5 sin^2 theta_na.nb),
   psi_a, psi_b the dips of A and B, psi_5 the plunge of line 5, theta_na.nb the angle between the normals.
2. ``fs_hoek_bray``, Hoek & Bray's formula with cohesion (water terms omitted: dry),
       FS = 3 / (gamma H) (c_A X + c_B Y) + A tan(phi_A) + B tan(phi_B),
       X = sin theta_24 / (sin theta_45 cos theta_2.na),  Y = sin theta_13 / (sin theta_35 cos theta_1.nb),
   theta_ij the angle between lines i and j, theta_2.na between line 2 and the normal of A, H the height of the
   top of line 5 above the toe.
3. ``fs``, the full vector solution from the wedge geometry: the weight W = gamma V is resolved on the two
   planes (normal reactions N_A, N_B perpendicular to line 5), driving force W sin psi_5 along line 5,
       FS = (N_A tan phi_A + N_B tan phi_B + c_A area_A + c_B area_B) / (W sin psi_5);
   when N_A (or N_B) comes out negative, contact on that plane is lost and the wedge slides on the other
   plane alone (FS = (W cos psi tan phi + c area) / (W sin psi)); this is the check the comprehensive Hoek &
   Bray solution makes. With both contacts, 1 and 3 agree for c = 0, and 2 and 3 for any c.

Units: any consistent pair for ``unit_weight`` and ``cohesion`` (kN/m^3 and kPa, or N/m^3 and Pa);
``height`` in metres. The paper's case (joint A 45/005, joint B 55/135, face 65 deg, phi 25 deg) gives
FS = 1.302; the factor of safety with c = 0 does not depend on the face, height or unit weight, as long as
the wedge exists (line 5 daylights in the face below the top).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from sgim.geometry import dip_to_normal
from sgim.portable import det3, matmul, norm, sin_cos_deg

# The explicit 3D-DDA paper's wedge (digest): joint orientations, face dip, height, unit weight, friction.
# Face dip direction 065: the trend of the line of intersection of the two joints (65.3 deg), rounded, so
# that the face strikes square to the sliding direction, the usual textbook set-up.
PAPER_CASE = dict(joint_a=(45.0, 5.0), joint_b=(55.0, 135.0), face=(65.0, 65.0), top=(0.0, 0.0),
                  height=10.0, unit_weight=2.6 * 9.81, friction=25.0)


class WedgeError(ValueError):
    """The planes do not form a wedge that can slide out of the face."""


@dataclass
class WedgeResult:
    fs: float                  # full vector solution (contact lost on a plane handled)
    fs_friction_only: float    # Hoek & Bray short formula, friction only
    fs_hoek_bray: float        # Hoek & Bray formula with cohesion (dry)
    mode: str                  # "both planes", "plane A", "plane B"
    factor_a: float            # Hoek & Bray A
    factor_b: float            # Hoek & Bray B
    vertices: np.ndarray = field(repr=False)  # (4,3): toe O, P5 (A.B.top), P1 (A.face.top), P2 (B.face.top)
    volume: float = 0.0
    weight: float = 0.0
    area_a: float = 0.0
    area_b: float = 0.0
    normal_force_a: float = 0.0
    normal_force_b: float = 0.0
    line_trend: float = 0.0    # trend of line 5, degrees
    line_plunge: float = 0.0   # plunge of line 5, degrees
    wedge_height: float = 0.0  # height of P5 above the toe
    critical_friction: float = 0.0  # friction angle (same on both joints, c = 0) giving FS = 1

    def as_dict(self):
        d = asdict(self)
        d["vertices"] = self.vertices.tolist()
        return d


def _pair(x, what):
    if np.ndim(x) == 0:
        return float(x), float(x)
    a, b = x
    return float(a), float(b)


def _angle(u, v):
    c = np.dot(u, v) / (np.linalg.norm(u) * np.linalg.norm(v))
    return float(np.arccos(np.clip(c, -1.0, 1.0)))


def _meet(n1, d1, n2, d2, n3, d3):
    """The point on three planes (Cramer's rule: the same bits on every CPU, sgim/portable.py)."""
    m = np.array([n1, n2, n3], float)
    det = det3(m)
    if abs(det) < 1e-12:
        raise WedgeError("three of the planes are parallel to one line: no wedge vertex")
    rhs = np.array([d1, d2, d3], float)
    out = np.empty(3)
    for k in range(3):
        mk = m.copy()
        mk[:, k] = rhs
        out[k] = det3(mk) / det
    return out


def wedge_geometry(joint_a, joint_b, face, top=None, height=10.0):
    """Normals a, b, f, t, offset of the top plane and the wedge vertices (O, P5, P1, P2)."""
    a, b = dip_to_normal(*joint_a), dip_to_normal(*joint_b)
    f = dip_to_normal(*face)
    t = dip_to_normal(*(top if top is not None else (0.0, 0.0)))
    if not height > 0:
        raise WedgeError(f"height must be > 0 (got {height})")
    if face[0] <= 0 or face[0] > 90:
        raise WedgeError(f"face dip must be in (0, 90] (got {face[0]})")
    sfd, cfd = sin_cos_deg(face[0])
    sfa, cfa = sin_cos_deg(face[1])
    up_face = -np.array([sfa * cfd, cfa * cfd, -sfd])  # up the dip line
    crest = up_face * height / sfd
    dt = matmul(t, crest)
    if abs(matmul(a, b)) > 1 - 1e-12:
        raise WedgeError("the two joints are parallel")
    o = np.zeros(3)
    p5 = _meet(a, 0.0, b, 0.0, t, dt)
    p1 = _meet(a, 0.0, f, 0.0, t, dt)
    p2 = _meet(b, 0.0, f, 0.0, t, dt)
    ln = np.cross(a, b)
    ln /= norm(ln)
    if ln[2] > 0:
        ln = -ln
    eps = 1e-9 * height
    ok = (matmul(f, p5) < -eps and matmul(b, p1) > eps and matmul(a, p2) > eps and matmul(t, o) < dt - eps
          and ln[2] < -1e-12 and matmul(p5 - o, ln) < 0)
    if not ok:
        raise WedgeError("the line of intersection of the joints does not daylight in the slope face below "
                         "the top surface: no wedge can slide out")
    return a, b, f, t, dt, np.array([o, p5, p1, p2])


def wedge_fs(joint_a, joint_b, face, top=None, friction=25.0, cohesion=0.0, unit_weight=2.6 * 9.81,
             height=10.0) -> WedgeResult:
    """Factor of safety of the wedge (see the module docstring). ``friction`` (degrees) and ``cohesion`` are
    one value for both joints or a pair (A, B)."""
    phia, phib = _pair(friction, "friction")
    ca, cb = _pair(cohesion, "cohesion")
    if not unit_weight > 0:
        raise WedgeError(f"unit weight must be > 0 (got {unit_weight})")
    a, b, f, t, dt, verts = wedge_geometry(joint_a, joint_b, face, top, height)
    o, p5, p1, p2 = verts
    ta, tb = np.tan(np.radians(phia)), np.tan(np.radians(phib))
    # geometry
    vol = abs(np.linalg.det(np.array([p5 - o, p1 - o, p2 - o]))) / 6.0
    w = unit_weight * vol
    area_a = 0.5 * np.linalg.norm(np.cross(p5 - o, p1 - o))
    area_b = 0.5 * np.linalg.norm(np.cross(p5 - o, p2 - o))
    ln = (o - p5) / np.linalg.norm(o - p5)  # down line 5
    psi5 = np.arcsin(-ln[2])
    trend = np.degrees(np.arctan2(ln[0], ln[1])) % 360.0
    cab = float(a @ b)
    # Hoek & Bray short formula (friction only)
    s2 = 1.0 - cab * cab
    fa_ = (a[2] - b[2] * cab) / (np.sin(psi5) * s2)
    fb_ = (b[2] - a[2] * cab) / (np.sin(psi5) * s2)
    fs_short = fa_ * ta + fb_ * tb
    # Hoek & Bray with cohesion: lines 1..5 as direction vectors
    l1, l2 = p1 - o, p2 - o
    th24 = _angle(p5 - p2, o - p2)                                        # angle at P2 between lines 2 and 4
    th45 = _angle(p2 - p5, o - p5)                                        # angle at P5 between lines 4 and 5
    th13 = _angle(p5 - p1, o - p1)                                        # angle at P1 between lines 1 and 3
    th35 = _angle(p1 - p5, o - p5)                                        # angle at P5 between lines 3 and 5
    th2na = _angle(l2, a)
    th1nb = _angle(l1, b)
    x = np.sin(th24) / (np.sin(th45) * np.cos(th2na))
    y = np.sin(th13) / (np.sin(th35) * np.cos(th1nb))
    hw = float(p5[2] - o[2])
    fs_hb = 3.0 / (unit_weight * hw) * (ca * x + cb * y) + fa_ * ta + fb_ * tb
    # full vector solution
    na = w * (a[2] - cab * b[2]) / s2
    nb = w * (b[2] - cab * a[2]) / s2
    if na >= 0 and nb >= 0:
        mode = "both planes"
        fs = (na * ta + nb * tb + ca * area_a + cb * area_b) / (w * np.sin(psi5))
        crit = np.degrees(np.arctan(1.0 / (fa_ + fb_)))
    elif nb >= 0 or na >= 0:
        on_a = na >= 0
        n, tp, c, area = (a, ta, ca, area_a) if on_a else (b, tb, cb, area_b)
        mode = "plane A" if on_a else "plane B"
        na, nb = (w * n[2], 0.0) if on_a else (0.0, w * n[2])
        fs = (w * n[2] * tp + c * area) / (w * np.sqrt(1.0 - n[2] ** 2))
        crit = np.degrees(np.arccos(n[2]))
    else:  # cannot happen under gravity with upward normals, kept for completeness
        mode, fs, crit = "lifts off", 0.0, 90.0
    return WedgeResult(fs=float(fs), fs_friction_only=float(fs_short), fs_hoek_bray=float(fs_hb), mode=mode,
                       factor_a=float(fa_), factor_b=float(fb_), vertices=verts, volume=float(vol), weight=float(w),
                       area_a=float(area_a), area_b=float(area_b), normal_force_a=float(na),
                       normal_force_b=float(nb), line_trend=float(trend), line_plunge=float(np.degrees(psi5)),
                       wedge_height=hw, critical_friction=float(crit))
