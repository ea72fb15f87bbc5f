"""SphereModel: the canonical bonded-sphere model and its files.

``model.npz`` is the canonical format (every downstream tool reads it):

=====================  ==============  =================================================
key                    shape / dtype   meaning
=====================  ==============  =================================================
centers                (n, 3) f8       sphere centres
radii                  (n,) f8         sphere radii
colour                 (n,) i1         0 intact, 1 red, 2 green, 3 blue
colour_source          (n,) i4         discontinuity that set the colour (-1: intact)
bonds                  (m, 2) i8       touching pairs, i < j, sorted
bonded                 (m,) bool       bond kept by the bond rule
cut_by                 (m,) i4         discontinuity that cut the pair (-1: bonded)
member_sphere          (k,) i8         membership table: sphere index
member_disc            (k,) i4         ... discontinuity index
member_kind            (k,) i1         ... 1 inside (red), 2 green side, 3 blue side
member_offset          (k,) f8         ... signed distance S.(O - M) from the plane
disc_centre/normal     (d, 3) f8       discontinuities (unit normal)
disc_radius/thickness  (d,) f8
disc_name              (d,) str
meta                   () str          JSON: scene name, packing, rules, domain, counts
scene_toml             () str          the scene file text, for reproduction
discontinuity_kind     (d+s,) i1       0 disc, 1 triangulated surface, by discontinuity index
                                       (this and the surf_* keys: only with triangulated
                                       discontinuities, sgim/surfdisc.py)
surf_index             (s,) i4         discontinuity index of each surface (after the discs)
surf_name              (s,) str
surf_thickness         (s,) f8         0: joint (green / blue), > 0: fault (red)
surf_vertices          (nv, 3) f8      the vertices of every surface, one block each
surf_faces             (nf, 3) i8      triangles (indices into surf_vertices), upward normals
surf_vertex_start      (s+1,) i8       surface k owns vertices [start[k], start[k+1])
surf_face_start        (s+1,) i8       ... and faces [start[k], start[k+1])
=====================  ==============  =================================================
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from .common import atomic_npz, atomic_path
from .readback import Arrays, parse_json, read_npz
from .vtu import array, constant, pieces, points_and_lines

COLOUR_NAMES = ("intact", "red", "green", "blue")


@dataclass
class SphereModel:
    centers: np.ndarray
    radii: np.ndarray
    colour: np.ndarray
    colour_source: np.ndarray
    bonds: np.ndarray
    bonded: np.ndarray
    cut_by: np.ndarray
    member_sphere: np.ndarray
    member_disc: np.ndarray
    member_kind: np.ndarray
    member_offset: np.ndarray
    disc_centre: np.ndarray
    disc_normal: np.ndarray
    disc_radius: np.ndarray
    disc_thickness: np.ndarray
    disc_name: list
    meta: dict = field(default_factory=dict)
    scene_toml: str = ""
    surfaces: dict = field(default_factory=dict)  # surf_* arrays (triangulated discontinuities)

    ARRAYS = ("centers", "radii", "colour", "colour_source", "bonds", "bonded", "cut_by", "member_sphere",
              "member_disc", "member_kind", "member_offset", "disc_centre", "disc_normal", "disc_radius",
              "disc_thickness")

    @property
    def n(self):
        return len(self.radii)

    def counts(self):
        cc = np.bincount(self.colour, minlength=4)
        return {
            "spheres": int(self.n),
            **{name: int(cc[k]) for k, name in enumerate(COLOUR_NAMES)},
            "bonds": int(len(self.bonded)),
            "bonded": int(self.bonded.sum()),
            "cut": int(len(self.bonded) - self.bonded.sum()),
            "memberships": int(len(self.member_sphere)),
            "discontinuities": int(len(self.disc_radius) + len(self.surfaces.get("surf_thickness", ()))),
        }

    def joint_pairs(self):
        """(pair index into ``bonds``, discontinuity index, unit normal (k, 3) pointing from sphere i to sphere j)
        of every touching pair cut by a zero-thickness discontinuity (a joint disc or a triangulated joint
        surface): the pairs that slide on the joint plane (smooth joints). Pairs cut by a fault (thickness > 0)
        are not listed."""
        bonds = np.asarray(self.bonds, np.int64).reshape(-1, 2)
        cut_by = np.asarray(self.cut_by)
        nd = len(self.disc_radius)
        surf = self.surfaces or {}
        s_index = np.asarray(surf.get("surf_index", np.zeros(0, int)))
        s_thick = np.asarray(surf.get("surf_thickness", np.zeros(0)))
        thickness = np.full(nd + len(s_index), np.inf)
        thickness[:nd] = self.disc_thickness
        for k, d in enumerate(s_index):
            thickness[int(d)] = s_thick[k]
        cut = np.flatnonzero(~np.asarray(self.bonded, bool) & (cut_by >= 0))
        d = cut_by[cut]
        keep = thickness[d] == 0.0
        cut, d = cut[keep], d[keep]
        normal = np.zeros((len(cut), 3))
        on_disc = d < nd
        normal[on_disc] = np.asarray(self.disc_normal)[d[on_disc]]
        c = np.asarray(self.centers)
        if np.any(~on_disc):
            from .meshquery import TriMesh  # not at the top: numba kernels, loaded only for surface cuts

            vs, fs = surf["surf_vertex_start"], surf["surf_face_start"]
            for k, dk in enumerate(s_index):
                sel = np.flatnonzero(d == dk)
                if not len(sel):
                    continue
                mesh = TriMesh(surf["surf_vertices"][vs[k]:vs[k + 1]], surf["surf_faces"][fs[k]:fs[k + 1]] - vs[k])
                mid = 0.5 * (c[bonds[cut[sel], 0]] + c[bonds[cut[sel], 1]])
                t = mesh.vertices[mesh.faces[mesh.closest(mid)[2]]]
                nrm = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
                normal[sel] = nrm / np.linalg.norm(nrm, axis=1)[:, None]
        dx = c[bonds[cut, 1]] - c[bonds[cut, 0]]
        normal *= np.where(np.einsum("ij,ij->i", normal, dx) < 0, -1.0, 1.0)[:, None]
        return cut, d, normal

    # -- npz ---------------------------------------------------------------
    def save(self, path):
        data = {k: getattr(self, k) for k in self.ARRAYS}
        data["disc_name"] = np.array(self.disc_name, dtype=str)
        data["meta"] = np.array(json.dumps(self.meta))
        data["scene_toml"] = np.array(self.scene_toml)
        data.update({k: np.array(v, dtype=str) if k == "surf_name" else v for k, v in self.surfaces.items()})
        atomic_npz(path, data)

    @classmethod
    def load(cls, path):
        """The model in the model.npz `path`, validated (:func:`check_model`): a file that is not a readable
        model raises sgim.readback.BadFile (a CliError: ``FILE: what is wrong``)."""
        return cls(**check_model(path, read_npz(path, "a model.npz")))

    # -- exports -------------------------------------------------------------
    def save_vtu(self, path):
        """ParaView file of the model (sgim/vtu.py, streamed: no copy of the bond list in memory).

        Points: the sphere centres. Cells: one vertex cell per sphere (cell i is sphere i), then one line cell
        per touching pair (cell n + b is bonds[b]). Point data: ``id`` (row in model.npz), ``radius``,
        ``colour`` (0 intact, 1 red, 2 green, 3 blue), ``colour_source``, ``bonds`` (intact bonds),
        ``member_count`` and, MAX_MEMBERS columns wide (-1 / 0 / NaN padded, the lowest discontinuity indices
        first), ``member_disc``, ``member_kind`` (1 inside, 2 green side, 3 blue side), ``member_offset``.
        Cell data: ``cell_kind`` (0 sphere, 1 bond), ``bonded`` (1 bonded, 0 cut, -1 on sphere cells),
        ``cut_by`` (the discontinuity index that cut the pair; -1 bonded, and on sphere cells)."""
        n, m = self.n, len(self.bonds)
        bonds = np.asarray(self.bonds, np.int64).reshape(-1, 2)
        bonded = np.asarray(self.bonded, bool)
        nb = (np.bincount(bonds[:, 0], weights=bonded, minlength=n)
              + np.bincount(bonds[:, 1], weights=bonded, minlength=n)).astype(np.int32) if m else np.zeros(n, np.int32)
        count, disc, kind, offset = self.membership_columns()
        point_data = [array("id", np.arange(n, dtype=np.int64)), array("radius", np.asarray(self.radii, float)),
                      array("colour", np.asarray(self.colour, np.int32)),
                      array("colour_source", np.asarray(self.colour_source, np.int32)), array("bonds", nb),
                      array("member_count", count), array("member_disc", disc), array("member_kind", kind),
                      array("member_offset", offset)]
        cut_by = np.asarray(self.cut_by, np.int32)
        cell_data = [pieces("cell_kind", np.uint8, [(n, constant(0)), (m, constant(1))]),
                     pieces("bonded", np.int8, [(n, constant(-1)), (m, lambda s, e: bonded[s:e])]),
                     pieces("cut_by", np.int32, [(n, constant(-1)), (m, lambda s, e: cut_by[s:e])])]
        with atomic_path(path) as tmp:
            points_and_lines(tmp, self.centers, bonds, point_data, cell_data)

    MAX_MEMBERS = 8

    def membership_columns(self, width=None):
        """The membership table as per-sphere columns: (count (n,) i4, disc (n, w) i4 padded -1, kind (n, w) i1
        padded 0, offset (n, w) f8 padded NaN), w = min(MAX_MEMBERS, the largest count) (at least 1); each
        sphere's rows by ascending discontinuity index (past w: counted, not listed)."""
        n = self.n
        ms = np.asarray(self.member_sphere, np.int64)
        count = np.bincount(ms, minlength=n).astype(np.int32) if len(ms) else np.zeros(n, np.int32)
        w = int(width or max(1, min(self.MAX_MEMBERS, int(count.max()) if n else 1)))
        disc = np.full((n, w), -1, np.int32)
        kind = np.zeros((n, w), np.int8)
        offset = np.full((n, w), np.nan)
        if len(ms):
            order = np.lexsort((np.asarray(self.member_disc), ms))
            s = ms[order]
            start = np.r_[0, np.cumsum(count)][:-1]
            rank = np.arange(len(s)) - start[s]
            keep = rank < w
            o, s, rank = order[keep], s[keep], rank[keep]
            disc[s, rank] = np.asarray(self.member_disc)[o]
            kind[s, rank] = np.asarray(self.member_kind)[o]
            offset[s, rank] = np.asarray(self.member_offset)[o]
        return count, disc, kind, offset

    def save_text(self, balls_path, bonds_path):
        """PFC-style text: 'id x y z r colour' per ball, 'id1 id2 bonded cut_by' per contact (1-based ids)."""
        with atomic_path(balls_path) as tmp:
            with open(tmp, "w") as fh:
                fh.write("# id x y z radius colour(0 intact,1 red,2 green,3 blue)\n")
                _write_rows(fh, "%d %.17g %.17g %.17g %.17g %d",
                            [np.arange(1, self.n + 1), self.centers[:, 0], self.centers[:, 1], self.centers[:, 2],
                             self.radii, self.colour])
        with atomic_path(bonds_path) as tmp:
            with open(tmp, "w") as fh:
                fh.write("# id1 id2 bonded(1/0) cut_by(discontinuity index, -1 none)\n")
                _write_rows(fh, "%d %d %d %d",
                            [self.bonds[:, 0] + 1, self.bonds[:, 1] + 1, self.bonded.astype(int), self.cut_by])


SURFACE_KEYS = ("discontinuity_kind", "surf_index", "surf_name", "surf_thickness", "surf_vertices", "surf_faces",
                "surf_vertex_start", "surf_face_start")


def check_model(path, arrays, kind="a model.npz"):
    """The SphereModel keywords of the arrays `arrays` read from the model.npz `path`, each checked against the
    layout of the module docstring: every array present, of its dtype kind and shape, lengths agreeing (n spheres,
    m pairs, k memberships, d discs, s surfaces), centres, radii and disc geometry finite, radii > 0, colour and
    membership codes valid, every sphere, pair, discontinuity and vertex index in range; meta a JSON object.
    Raises sgim.readback.BadFile naming the file and the first defect. Used by every reader of a model
    (SphereModel.load)."""
    A = Arrays(path, arrays, kind)
    A.missing(SphereModel.ARRAYS)
    kw = {}
    c = kw["centers"] = A.real("centers", (None, 3))
    n = len(c)
    sph = f"the model has {n} spheres"
    kw["radii"] = A.real("radii", (n,), positive=True, per="one per sphere of centers")
    kw["colour"] = A.integer("colour", (n,), lo=0, hi=4, why="colour codes 0 intact, 1 red, 2 green, 3 blue",
                             per="one per sphere", dtype=np.int8)
    kw["disc_radius"] = A.real("disc_radius", (None,), positive=True)
    d = len(kw["disc_radius"])
    kw["disc_centre"] = A.real("disc_centre", (d, 3), per="one per disc")
    dn = kw["disc_normal"] = A.real("disc_normal", (d, 3), per="one per disc")
    off = np.abs(np.linalg.norm(dn, axis=1) - 1.0) > 1e-6
    if off.any():
        A.fail(f"disc_normal[{int(np.argmax(off))}] = {dn[int(np.argmax(off))].tolist()}: must be a unit vector")
    kw["disc_thickness"] = A.real("disc_thickness", (d,), nonneg=True, per="one per disc")
    kw["disc_name"] = A.strings("disc_name", (d,), per="one per disc") if A.has("disc_name") else []
    surfaces = {}
    if any(A.has(k) for k in SURFACE_KEYS):
        A.missing(SURFACE_KEYS)
        si = A.integer("surf_index", (None,), dtype=np.int32)
        s = len(si)
        if not np.array_equal(si, np.arange(d, d + s)):
            A.fail(f"surf_index = {si.tolist()[:8]}: expected the discontinuity indices {d} .. {d + s - 1} "
                   f"(after the {d} discs)")
        nd = d + s
        surfaces["discontinuity_kind"] = A.integer("discontinuity_kind", (nd,), lo=0, hi=2,
                                                   why="0 disc, 1 surface", per="one per discontinuity",
                                                   dtype=np.int8)
        surfaces["surf_index"] = si
        surfaces["surf_name"] = A.strings("surf_name", (s,), per="one per surface")
        surfaces["surf_thickness"] = A.real("surf_thickness", (s,), nonneg=True, per="one per surface")
        sv = surfaces["surf_vertices"] = A.real("surf_vertices", (None, 3))
        vs = surfaces["surf_vertex_start"] = A.integer("surf_vertex_start", (s + 1,), lo=0, hi=len(sv) + 1,
                                                       per="one more than the surfaces")
        sf = A.integer("surf_faces", (None, 3), lo=0, hi=len(sv), why=f"{len(sv)} surface vertices")
        fs = surfaces["surf_face_start"] = A.integer("surf_face_start", (s + 1,), lo=0, hi=len(sf) + 1,
                                                     per="one more than the surfaces")
        for name, st, total in (("surf_vertex_start", vs, len(sv)), ("surf_face_start", fs, len(sf))):
            if st[0] != 0 or st[-1] != total or np.any(np.diff(st) < 0):
                A.fail(f"{name} = {st.tolist()[:8]}: must rise from 0 to {total}")
        owner = np.repeat(np.arange(s), np.diff(fs))
        outside = (sf < vs[owner, None]) | (sf >= vs[owner + 1, None])
        if outside.any():
            f = int(np.argmax(outside.any(1)))
            A.fail(f"surf_faces[{f}] = {sf[f].tolist()}: refers to a vertex outside its surface's block "
                   f"{int(vs[owner[f]])} .. {int(vs[owner[f] + 1]) - 1}")
        surfaces["surf_faces"] = sf
    else:
        nd = d
    disc = f"the model has {nd} discontinuities"
    kw["colour_source"] = A.integer("colour_source", (n,), lo=-1, hi=nd, why=disc, per="one per sphere",
                                    dtype=np.int32)
    b = kw["bonds"] = A.integer("bonds", (None, 2), lo=0, hi=n, why=sph)
    m = len(b)
    same = b[:, 0] == b[:, 1]
    if same.any():
        A.fail(f"bonds[{int(np.argmax(same))}] = {b[int(np.argmax(same))].tolist()}: a sphere paired with itself")
    kw["bonded"] = A.boolean("bonded", (m,), per="one per pair of bonds")
    kw["cut_by"] = A.integer("cut_by", (m,), lo=-1, hi=nd, why=disc, per="one per pair of bonds", dtype=np.int32)
    kw["member_sphere"] = A.integer("member_sphere", (None,), lo=0, hi=n, why=sph)
    k = len(kw["member_sphere"])
    kw["member_disc"] = A.integer("member_disc", (k,), lo=0, hi=nd, why=disc, per="one per membership",
                                  dtype=np.int32)
    kw["member_kind"] = A.integer("member_kind", (k,), lo=1, hi=4, why="1 inside, 2 green side, 3 blue side",
                                  per="one per membership", dtype=np.int8)
    kw["member_offset"] = A.real("member_offset", (k,), per="one per membership")
    meta = A.text("meta") if A.has("meta") else "{}"
    kw["meta"] = parse_json(path, meta, where="meta")
    kw["scene_toml"] = A.text("scene_toml") if A.has("scene_toml") else ""
    kw["surfaces"] = surfaces
    return kw


def _write_rows(fh, fmt, cols, chunk=200_000):
    n = len(cols[0])
    line = fmt + "\n"
    for s in range(0, n, chunk):
        rows = zip(*(c[s:s + chunk].tolist() for c in cols))
        fh.write("".join(line % r for r in rows))
