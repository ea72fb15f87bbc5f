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
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

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
            from .meshquery import TriMesh

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
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in cls.ARRAYS if k not in z.files]
            if missing:
                raise ValueError(f"{path}: not a model file (missing {', '.join(missing)})")
            kw = {k: z[k] for k in cls.ARRAYS}
            kw["disc_name"] = [str(s) for s in z["disc_name"]] if "disc_name" in z.files else []
            kw["meta"] = json.loads(str(z["meta"])) if "meta" in z.files else {}
            kw["scene_toml"] = str(z["scene_toml"]) if "scene_toml" in z.files else ""
            kw["surfaces"] = {k: ([str(x) for x in z[k]] if k == "surf_name" else z[k])
                              for k in z.files if k.startswith("surf_") or k == "discontinuity_kind"}
        return cls(**kw)

    # -- exports -------------------------------------------------------------
    def save_vtu(self, path):
        """Point cloud (one vertex cell per sphere) with radius, colour and bond counts."""
        import meshio

        n = self.n
        nb = np.bincount(self.bonds[self.bonded].ravel(), minlength=n) if len(self.bonds) else np.zeros(n, int)
        mesh = meshio.Mesh(
            self.centers,
            [("vertex", np.arange(n, dtype=np.int64).reshape(-1, 1))],
            point_data={
                "radius": self.radii,
                "colour": self.colour.astype(np.int32),
                "colour_source": self.colour_source.astype(np.int32),
                "bonds": nb.astype(np.int32),
            },
        )
        atomic_vtu(path, mesh)

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


def _write_rows(fh, fmt, cols, chunk=200_000):
    n = len(cols[0])
    line = fmt + "\n"
    for s in range(0, n, chunk):
        rows = zip(*(c[s:s + chunk].tolist() for c in cols))
        fh.write("".join(line % r for r in rows))


def atomic_npz(path, data):
    """np.savez of the dict `data` to `path`, written under a temporary name and renamed into place."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **data)


def atomic_vtu(path, mesh):
    """A meshio Mesh written as binary VTU to `path` under a temporary name and renamed into place."""
    import meshio

    with atomic_path(path) as tmp:
        meshio.write(tmp, mesh, file_format="vtu", binary=True, compression=None)


class atomic_path:
    """Context manager yielding a temporary name that is renamed to ``path`` on success."""

    def __init__(self, path):
        self.path = Path(path)
        self.tmp = self.path.with_name(f".{self.path.name}.part{os.getpid()}")

    def __enter__(self):
        return str(self.tmp)

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            os.replace(self.tmp, self.path)
        else:
            try:
                os.unlink(self.tmp)
            except FileNotFoundError:
                pass
        return False
