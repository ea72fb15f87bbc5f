"""Block and sphere meshes for output: VTU frames with a .pvd index (ParaView) and an off-screen PNG (pyvista)."""
from __future__ import annotations

import os

import numpy as np

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
    """Off-screen PNG of the blocks of a block Simulation."""
    render_meshes(path, blocks=block_polydata(sim), width=width, height=height, title=title)


def render_meshes(path, blocks=None, spheres=None, width=1600, height=1100, title=None):
    """Off-screen PNG: `blocks` (faces_polydata) drawn as polyhedra, `spheres` (sphere_polydata) drawn as
    spheres of their radius, coloured by their `colour` point data where present."""
    import pyvista as pv

    from sgim.render import offscreen_vtk

    pv.OFF_SCREEN = True
    with offscreen_vtk():  # no X server tried, no warning on the terminal
        pl = pv.Plotter(off_screen=True, window_size=(int(width), int(height)))
    pl.set_background("white")
    bounds = []
    if blocks is not None and blocks.n_points:
        mesh = blocks.copy()
        colours = np.where(mesh.cell_data["fixed"][:, None] == 1, FIXED, MOVING)
        mesh.cell_data["rgb"] = (colours * 255).astype(np.uint8)
        pl.add_mesh(mesh, scalars="rgb", rgb=True, show_edges=True, edge_color="black", line_width=0.5)
        bounds.append(np.asarray(mesh.bounds))
    if spheres is not None and spheres.n_points:
        pts = spheres.copy()
        col = pts.point_data["colour"] if "colour" in pts.point_data else np.zeros(pts.n_points, int)
        rgb = SPHERE_COLOURS[np.clip(col, 0, len(SPHERE_COLOURS) - 1)]
        if "fixed" in pts.point_data:
            rgb = np.where(pts.point_data["fixed"][:, None] == 1, 0.6 * rgb, rgb)
        pts.point_data["rgb"] = (rgb * 255).astype(np.uint8)
        pts.point_data["diameter"] = 2.0 * pts.point_data["radius"]
        glyphs = pts.glyph(scale="diameter", orient=False, geom=pv.Sphere(radius=0.5, theta_resolution=16,
                                                                          phi_resolution=12))
        pl.add_mesh(glyphs, scalars="rgb", rgb=True)
        bounds.append(np.asarray(glyphs.bounds))
    if title:
        pl.add_text(title, font_size=10, color="black")
    if bounds:
        b = np.array(bounds)
        lo, hi = b[:, 0::2].min(0), b[:, 1::2].max(0)
    else:
        lo, hi = np.zeros(3), np.ones(3)
    centre = (lo + hi) / 2
    span = float(np.max(hi - lo)) or 1.0
    az, el = np.radians(-60.0), np.radians(25.0)
    eye = centre + 2.2 * span * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    pl.camera_position = [tuple(eye), tuple(centre), (0.0, 0.0, 1.0)]
    pl.reset_camera()
    tmp = f"{path}.tmp{os.getpid()}.png"
    pl.screenshot(tmp)
    pl.close()
    os.replace(tmp, path)
