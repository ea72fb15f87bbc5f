"""Block meshes for output: VTU frames with a .pvd index (ParaView) and an off-screen PNG (pyvista)."""
from __future__ import annotations

import os

import numpy as np

MOVING = np.array([0.80, 0.74, 0.60])  # sandstone
FIXED = np.array([0.55, 0.55, 0.58])


def block_polydata(sim):
    """All blocks' faces as one pyvista PolyData with cell data block, fixed."""
    import pyvista as pv

    A = sim.A
    pts = np.concatenate([sim.vertices(i) for i in range(A.n)]) if A.n else np.zeros((0, 3))
    fvs, fv = A.face_vert_start, A.face_verts
    sizes = np.diff(fvs)
    cells = np.empty(len(fv) + len(sizes), np.int64)
    pos = 0
    for f in range(len(sizes)):
        cells[pos] = sizes[f]
        cells[pos + 1:pos + 1 + sizes[f]] = fv[fvs[f]:fvs[f + 1]]
        pos += 1 + sizes[f]
    mesh = pv.PolyData(pts, cells)
    face_block = np.repeat(np.arange(A.n), np.diff(A.face_start))
    mesh.cell_data["block"] = face_block
    mesh.cell_data["fixed"] = A.fixed[face_block].astype(np.uint8)
    disp = np.linalg.norm(sim.pos - sim.pos0, axis=1)
    mesh.cell_data["displacement"] = disp[face_block]
    return mesh


def write_vtu(sim, path):
    mesh = block_polydata(sim).cast_to_unstructured_grid()
    tmp = f"{path}.tmp{os.getpid()}.vtu"
    mesh.save(tmp)
    os.replace(tmp, path)


def write_pvd(entries, path):
    """entries: list of (time, relative file name)."""
    lines = ['<?xml version="1.0"?>', '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
             "  <Collection>"]
    lines += [f'    <DataSet timestep="{t:.9g}" group="" part="0" file="{f}"/>' for t, f in entries]
    lines += ["  </Collection>", "</VTKFile>", ""]
    tmp = f"{path}.tmp{os.getpid()}"
    with open(tmp, "w") as fh:
        fh.write("\n".join(lines))
    os.replace(tmp, path)


def render_png(sim, path, width=1600, height=1100, title=None):
    import pyvista as pv

    pv.OFF_SCREEN = True
    mesh = block_polydata(sim)
    colours = np.where(mesh.cell_data["fixed"][:, None] == 1, FIXED, MOVING)
    mesh.cell_data["rgb"] = (colours * 255).astype(np.uint8)
    pl = pv.Plotter(off_screen=True, window_size=(int(width), int(height)))
    pl.set_background("white")
    pl.add_mesh(mesh, scalars="rgb", rgb=True, show_edges=True, edge_color="black", line_width=0.5)
    if title:
        pl.add_text(title, font_size=10, color="black")
    lo, hi = np.asarray(mesh.bounds[0::2]), np.asarray(mesh.bounds[1::2])
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
