"""The test surfaces of the sgim benchmark (cases/bench/sgim.py) and their references, computed here independently
of sgim's kernels: a low pit in the open pit's box (about 90 % of the lattice removed), a benched rectangular pit on
an incline with its solid volume in closed form, the plan-view height of a triangulated surface (matplotlib's
triangle finder) and its midpoint-rule volume, the highest centre that keeps a ball of radius r under a surface,
and the distance of lattice sites to a surface (the "ties" a rule may decide either way).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from matplotlib.tri import LinearTriInterpolator, Triangulation


def low_pit_points(box, z_terrain=14.5):
    """Points of a low surface in the open pit's box: gently undulating terrain at about
    z_terrain with a small conical pit (radius 30 m, 7 m deep), so ~90 % of the box is removed."""
    (x1, y1, _), (x2, y2, _) = box
    pts = []
    gx = np.arange(x1 - 5, x2 + 5.1, 10.0)
    gy = np.arange(y1 - 5, y2 + 5.1, 10.0)
    pcx, pcy, prad, pdepth = 15.0, -10.0, 30.0, 7.0

    def terrain(x, y):
        return z_terrain + 1.0 * np.sin(x / 37.0) * np.cos(y / 29.0)

    for x in gx:
        for y in gy:
            if math.hypot(x - pcx, y - pcy) > prad + 4.0:
                pts.append((x, y, float(terrain(x, y))))
    for frac in (0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0):  # floor centre + 3 rings down the cone
        rr = prad * frac
        n = 1 if rr == 0 else int(8 + 40 * frac)
        for k in range(n):
            th = 2 * math.pi * k / n
            x, y = pcx + rr * math.cos(th), pcy + rr * math.sin(th)
            z = float(terrain(x, y)) - pdepth * (1.0 - frac)
            pts.append((x, y, z))
    return np.round(np.array(pts), 3)


@dataclasses.dataclass
class BenchPit:
    """A rectangular pit with nb benches (planar faces and berms) in terrain at z = top, the whole surface
    sheared by the linear function gx x + gy y (a gentle incline that keeps every facet planar and stops
    horizontal berms from lining up with lattice layers); the solid is the box below the surface."""

    lo: tuple = (-50.0, -40.0, 0.0)
    hi: tuple = (50.0, 40.0, 40.0)
    centre: tuple = (3.7, -2.9)
    a0: float = 14.0  # floor half widths
    b0: float = 9.0
    floor: float = 7.3
    bench_h: float = 8.0
    face_deg: float = 60.0
    berm: float = 4.0
    nb: int = 3
    gx: float = 0.06  # shear: z += gx x + gy y (about 4.3 degrees)
    gy: float = 0.045

    @property
    def run(self):
        return self.bench_h / math.tan(math.radians(self.face_deg))

    @property
    def top(self):
        return self.floor + self.nb * self.bench_h

    def height(self, x, y):
        """Surface height: floor, then per bench a planar face of width `run` and a berm."""
        s = np.maximum(np.abs(x - self.centre[0]) - self.a0, np.abs(y - self.centre[1]) - self.b0)
        p = self.run + self.berm
        k = np.floor(np.maximum(s, 0.0) / p)
        u = np.maximum(s, 0.0) - k * p
        z = self.floor + self.bench_h * k + np.where(u < self.run, self.bench_h * u / self.run, self.bench_h)
        return np.minimum(z, self.top) + self.gx * x + self.gy * y

    def exact_volume(self):
        """Closed form: box volume below the terrain minus the pit (sum of the benches' frustums), plus the
        integral of the shear over the box (area x shear at the box centre)."""
        lx, ly = self.hi[0] - self.lo[0], self.hi[1] - self.lo[1]
        xc, yc = (self.lo[0] + self.hi[0]) / 2, (self.lo[1] + self.hi[1]) / 2
        run, p = self.run, self.run + self.berm
        pit = 0.0
        for k in range(self.nb):
            sk = k * p
            # integral over one bench height of the rectangle 2(a0 + s) x 2(b0 + s), s = sk + run t
            pit += 4.0 * self.bench_h * ((self.a0 + sk) * (self.b0 + sk) + (self.a0 + self.b0 + 2 * sk) * run / 2
                                         + run * run / 3.0)
        return lx * ly * (self.top - self.lo[2]) - pit + lx * ly * (self.gx * xc + self.gy * yc)

    def mesh(self):
        """Vertices and facets: nested rectangles at each toe and crest, joined by planar trapezoids."""
        cx, cy = self.centre
        p = self.run + self.berm
        rings = [(0.0, self.floor)]
        for k in range(self.nb):
            rings.append((k * p + self.run, self.floor + (k + 1) * self.bench_h))  # crest of bench k
            if k + 1 < self.nb:
                rings.append(((k + 1) * p, self.floor + (k + 1) * self.bench_h))  # toe of bench k+1
        verts = []
        for s, z in rings:
            a, b = self.a0 + s, self.b0 + s
            verts += [(cx - a, cy - b, z), (cx + a, cy - b, z), (cx + a, cy + b, z), (cx - a, cy + b, z)]
        pad = 5.0
        verts += [(self.lo[0] - pad, self.lo[1] - pad, self.top), (self.hi[0] + pad, self.lo[1] - pad, self.top),
                  (self.hi[0] + pad, self.hi[1] + pad, self.top), (self.lo[0] - pad, self.hi[1] + pad, self.top)]
        verts = [(x, y, z + self.gx * x + self.gy * y) for x, y, z in verts]
        faces = [(0, 1, 2), (0, 2, 3)]
        nring = len(rings) + 1
        for q in range(nring - 1):
            i0, j0 = 4 * q, 4 * (q + 1)
            for e in range(4):
                a, b = i0 + e, i0 + (e + 1) % 4
                c, d = j0 + (e + 1) % 4, j0 + e
                faces += [(a, b, c), (a, c, d)]
        return np.array(verts, float), np.array(faces, np.int64)


def surface_interpolator(verts, faces):
    """Piecewise-linear height of a plan-view triangulated surface (matplotlib's triangle finder)."""
    tri = Triangulation(verts[:, 0], verts[:, 1], faces)
    return LinearTriInterpolator(tri, verts[:, 2])


def integrate_solid(interp, lo, hi, n):
    """Midpoint rule: volume of the box below the surface, n cells along x (square cells)."""
    d = (hi[0] - lo[0]) / n
    ny = int(round((hi[1] - lo[1]) / d))
    dy = (hi[1] - lo[1]) / ny
    xs = lo[0] + d * (np.arange(n) + 0.5)
    total = 0.0
    for j0 in range(0, ny, 256):
        ys = lo[1] + dy * (np.arange(j0, min(ny, j0 + 256)) + 0.5)
        X, Y = np.meshgrid(xs, ys)
        h = interp(X, Y)
        if np.ma.count_masked(h):
            raise RuntimeError("surface does not cover the box")
        h = np.asarray(h)
        if h.min() < lo[2] or h.max() > hi[2]:
            raise RuntimeError("surface leaves the box's z range (the closed forms assume it does not)")
        total += float((h - lo[2]).sum())
    return total * d * dy


def keep_heights(interp, lo, hi, r, n_ring=12):
    """Per lattice column (x_i = lo + r(2i+1)): highest z whose ball of radius r lies under the surface.

    z <= min over the disc |x' - x| <= r of h(x') - sqrt(r^2 - |x' - x|^2); the disc is sampled on
    n_ring rings (and its centre) with about r/n_ring spacing.  Returns (nx, ny) array.
    """
    nx = int(round((hi[0] - lo[0]) / (2 * r)))
    ny = int(round((hi[1] - lo[1]) / (2 * r)))
    xs = lo[0] + r * (2 * np.arange(nx) + 1)
    ys = lo[1] + r * (2 * np.arange(ny) + 1)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    X, Y = X.ravel(), Y.ravel()
    off = [(0.0, 0.0, r)]
    for k in range(1, n_ring + 1):
        rho = r * k / n_ring
        m = max(8, int(round(2 * math.pi * k)))
        for t in range(m):
            th = 2 * math.pi * (t + 0.5 * (k % 2)) / m
            off.append((rho * math.cos(th), rho * math.sin(th), math.sqrt(max(r * r - rho * rho, 0.0))))
    off = np.array(off)
    best = np.full(len(X), np.inf)
    per = max(1, 2_000_000 // len(X))
    for s in range(0, len(off), per):
        o = off[s:s + per]
        PX = X[None, :] + o[:, 0:1]
        PY = Y[None, :] + o[:, 1:2]
        h = interp(PX, PY)
        v = np.ma.filled(h - o[:, 2:3], np.inf)
        best = np.minimum(best, v.min(0))
    return best.reshape(nx, ny)


def surface_distance(pts, verts, faces, reach):
    """Distance from each point to a triangulated surface (numpy, independent of sgim's kernels).

    Only facets whose plan box lies within `reach` of a point are examined (inf if none).
    """
    pts = np.asarray(pts, float).reshape(-1, 3)
    tri = verts[faces]
    bmin, bmax = tri.min(1), tri.max(1)
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    n = np.cross(b - a, c - a)
    nu = n / np.linalg.norm(n, axis=1)[:, None]
    out = np.full(len(pts), np.inf)
    for s in range(0, len(pts), 2000):
        P = pts[s:s + 2000]
        near = ((P[:, None, 0] >= bmin[None, :, 0] - reach) & (P[:, None, 0] <= bmax[None, :, 0] + reach)
                & (P[:, None, 1] >= bmin[None, :, 1] - reach) & (P[:, None, 1] <= bmax[None, :, 1] + reach))
        ip, jf = np.nonzero(near)
        if not len(ip):
            continue
        p, A, B, C, N, U = P[ip], a[jf], b[jf], c[jf], n[jf], nu[jf]
        h = np.einsum("ij,ij->i", p - A, U)
        q = p - h[:, None] * U
        inside = ((np.einsum("ij,ij->i", np.cross(B - A, q - A), N) >= 0)
                  & (np.einsum("ij,ij->i", np.cross(C - B, q - B), N) >= 0)
                  & (np.einsum("ij,ij->i", np.cross(A - C, q - C), N) >= 0))
        d = np.where(inside, np.abs(h), np.inf)
        for u, v in ((A, B), (B, C), (C, A)):
            e = v - u
            t = np.clip(np.einsum("ij,ij->i", p - u, e) / np.einsum("ij,ij->i", e, e), 0.0, 1.0)
            d = np.minimum(d, np.linalg.norm(p - u - t[:, None] * e, axis=1))
        best = np.full(len(P), np.inf)
        np.minimum.at(best, ip, d)
        out[s:s + 2000] = best
    return out


def tie_split(pts, verts, faces, r):
    """(sites at distance r from the surface within 1e-9 r, the others, min distance/r of the others)."""
    if len(pts) == 0:
        return 0, 0, None
    d = surface_distance(pts, verts, faces, 2 * r)
    tie = np.abs(d - r) <= 1e-9 * r
    rest = d[~tie]
    return int(tie.sum()), int((~tie).sum()), (float(rest.min() / r) if len(rest) else None)
