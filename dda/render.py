"""Block and sphere meshes for output: VTU frames with a .pvd index (ParaView) and an off-screen PNG (pyvista)."""
from __future__ import annotations

import os

import numpy as np

from sgim.render import Frame

# pyvista is imported inside the functions that draw: it takes seconds to load, and only the frames and pictures
# need it
MOVING = np.array([0.80, 0.74, 0.60])  # sandstone
FIXED = np.array([0.55, 0.55, 0.58])


def faces_polydata(pts, face_vert_start, face_verts, face_start, fixed, displacement=None):
    """Polyhedra as one pyvista PolyData: world vertices `pts`, face loops (global vertex indices)
    face_verts[face_vert_start[f]:face_vert_start[f + 1]], faces face_start[i]:face_start[i + 1] of body i;
    cell data block, fixed (and displacement, per body)."""
    import pyvista as pv

    fvs, fv = np.asarray(face_vert_start), np.asarray(face_verts)
    sizes = np.diff(fvs)
    cells = np.empty(len(fv) + len(sizes), np.int64)
    pos = 0
    for f in range(len(sizes)):
        cells[pos] = sizes[f]
        cells[pos + 1:pos + 1 + sizes[f]] = fv[fvs[f]:fvs[f + 1]]
        pos += 1 + sizes[f]
    mesh = pv.PolyData(np.asarray(pts, float).reshape(-1, 3), cells)
    face_block = np.repeat(np.arange(len(face_start) - 1), np.diff(face_start))
    mesh.cell_data["block"] = face_block
    mesh.cell_data["fixed"] = np.asarray(fixed, bool)[face_block].astype(np.uint8)
    disp = np.zeros(len(face_start) - 1) if displacement is None else np.asarray(displacement, float)
    mesh.cell_data["displacement"] = disp[face_block]
    return mesh


def block_polydata(sim):
    """All blocks' faces as one pyvista PolyData with cell data block, fixed."""
    A = sim.A
    pts = np.concatenate([sim.vertices(i) for i in range(A.n)]) if A.n else np.zeros((0, 3))
    disp = np.linalg.norm(sim.pos - sim.pos0, axis=1)
    return faces_polydata(pts, A.face_vert_start, A.face_verts, A.face_start, A.fixed, disp)


def sphere_polydata(x, radii, fixed=None, velocity=None, displacement=None, colour=None):
    """Spheres as a point cloud (one vertex cell per sphere) with point data radius, fixed, velocity,
    displacement and colour (where given)."""
    import pyvista as pv

    x = np.asarray(x, float).reshape(-1, 3)
    mesh = pv.PolyData(x.copy())
    mesh.point_data["radius"] = np.asarray(radii, float)
    if fixed is not None:
        mesh.point_data["fixed"] = np.asarray(fixed).astype(np.uint8)
    if velocity is not None:
        mesh.point_data["velocity"] = np.asarray(velocity, float)
    if displacement is not None:
        mesh.point_data["displacement"] = np.asarray(displacement, float)
    if colour is not None:
        mesh.point_data["colour"] = np.asarray(colour).astype(np.int32)
    return mesh


def save_mesh(mesh, path):
    """A pyvista mesh as a VTU file (written under a temporary name, then renamed)."""
    tmp = f"{path}.tmp{os.getpid()}.vtu"
    mesh.cast_to_unstructured_grid().save(tmp)
    os.replace(tmp, path)


def write_vtu(sim, path):
    save_mesh(block_polydata(sim), path)


def write_pvd(entries, path):
    """entries: list of (time, relative file name) or (time, relative file name, part)."""
    lines = ['<?xml version="1.0"?>', '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
             "  <Collection>"]
    lines += [f'    <DataSet timestep="{e[0]:.9g}" group="" part="{e[2] if len(e) > 2 else 0}" file="{e[1]}"/>'
              for e in entries]
    lines += ["  </Collection>", "</VTKFile>", ""]
    tmp = f"{path}.tmp{os.getpid()}"
    with open(tmp, "w") as fh:
        fh.write("\n".join(lines))
    os.replace(tmp, path)


# sphere colours: intact, then the sgim discontinuity colours red, green, blue
SPHERE_COLOURS = np.array([[0.80, 0.74, 0.60], [0.85, 0.20, 0.20], [0.25, 0.65, 0.30], [0.25, 0.40, 0.85]])


def render_png(sim, path, width=1600, height=1100, title=None):
    """Off-screen PNG of the blocks of a block Simulation (moving blocks coloured by their displacement)."""
    return render_meshes(path, blocks=block_polydata(sim), width=width, height=height, title=title,
                         time=getattr(sim, "time", None))


def _magnitude(a):
    a = np.asarray(a, float)
    return np.linalg.norm(a, axis=1) if a.ndim == 2 else np.abs(a)


def render_meshes(path, blocks=None, spheres=None, width=1600, height=1100, title=None, cmap="viridis", time=None):
    """Off-screen PNG of the state: `blocks` (faces_polydata) drawn as polyhedra, `spheres` (sphere_polydata)
    drawn as spheres of their radius. What moves is coloured by its displacement from the start (cell data
    ``displacement`` of the blocks, point data of the spheres) on one scale with a colour bar in metres; fixed
    blocks and spheres are grey. Legend, axes in metres, scale bar and a camera fitted to everything drawn as
    for sgim pictures (sgim.render.Frame); `time` [s], when given, follows the title. Returns the picture's facts
    (legend, colour range, scale bar)."""
    import pyvista as pv

    if time is not None:
        title = f"{title + '   ' if title else ''}t = {float(time):.4g} s"
    frame = Frame(width, height, title)
    pl = frame.pl
    parts, bounds = [], []
    if blocks is not None and blocks.n_points:
        mesh = blocks.copy()
        fixed = np.asarray(mesh.cell_data["fixed"]) == 1
        disp = _magnitude(mesh.cell_data["displacement"]) if "displacement" in mesh.cell_data \
            else np.zeros(mesh.n_cells)
        mesh.cell_data["displacement_m"] = disp
        parts.append(("block", mesh, fixed, disp))
        bounds.append(np.asarray(mesh.bounds))
    if spheres is not None and spheres.n_points:
        pts = spheres.copy()
        fixed = (np.asarray(pts.point_data["fixed"]) == 1) if "fixed" in pts.point_data else np.zeros(pts.n_points,
                                                                                                       bool)
        disp = _magnitude(pts.point_data["displacement"]) if "displacement" in pts.point_data \
            else np.zeros(pts.n_points)
        pts.point_data["displacement_m"] = disp
        pts.point_data["diameter"] = 2.0 * np.asarray(pts.point_data["radius"], float)
        r = float(np.max(pts.point_data["radius"]))
        b = np.asarray(pts.bounds, float)
        bounds.append(b + np.array([-r, r, -r, r, -r, r]))
        parts.append(("sphere", pts, fixed, disp))
    if bounds:
        b = np.array(bounds)
        lo, hi = b[:, 0::2].min(0), b[:, 1::2].max(0)
    else:
        lo, hi = np.zeros(3), np.ones(3)
    frame.fit(lo, hi, azimuth=-60.0, elevation=25.0)
    frame.axes(lo, hi)
    moving = [d[~f] for _, _, f, d in parts if np.any(~f)]
    dmax = float(max((m.max() for m in moving), default=0.0))
    clim = (0.0, dmax if dmax > 0 else 1e-9)
    bar_mapper = None
    sphere_geom = pv.Sphere(radius=0.5, theta_resolution=16, phi_resolution=12)
    for kind, mesh, fixed, disp in parts:
        sub_fixed = sub_moving = None
        if kind == "block":
            if fixed.any():
                sub_fixed = mesh.extract_cells(np.flatnonzero(fixed)).extract_surface(algorithm=None)
            if (~fixed).any():
                sub_moving = mesh.extract_cells(np.flatnonzero(~fixed)).extract_surface(algorithm=None)
            style = dict(show_edges=True, edge_color="black", line_width=0.5)
        else:
            glyphs = {}
            for name, sel in (("fixed", fixed), ("moving", ~fixed)):
                if sel.any():
                    cloud = pv.PolyData(np.asarray(mesh.points)[sel])
                    cloud.point_data["diameter"] = np.asarray(mesh.point_data["diameter"])[sel]
                    cloud.point_data["displacement_m"] = disp[sel]
                    glyphs[name] = cloud.glyph(scale="diameter", orient=False, geom=sphere_geom)
            sub_fixed, sub_moving = glyphs.get("fixed"), glyphs.get("moving")
            style = {}
        if sub_fixed is not None:
            pl.add_mesh(sub_fixed, color=FIXED, **style)
            frame.add_legend_entry(f"fixed {kind}", FIXED)
        if sub_moving is not None:
            act = pl.add_mesh(sub_moving, scalars="displacement_m", cmap=cmap, clim=clim, show_scalar_bar=False,
                              **style)
            bar_mapper = act.mapper
    if bar_mapper is not None:
        frame.colour_bar("displacement [m]", bar_mapper)
    frame.save(path)
    info = {"legend": [label for label, _ in frame.legend], "displacement_max_m": dmax,
            "scale_bar_m": frame.scale_bar_m}
    frame.close()
    return info
