"""A streaming VTU writer (VTK XML UnstructuredGrid, raw appended binary data) for large point-and-line meshes.

meshio builds the whole connectivity, offsets and types arrays and their cell data in memory before it writes;
for a model with millions of spheres and bonds that is several times the model's own memory. Here every array
is a sequence of numpy chunks written straight to the file, so the peak stays at one chunk. VTK, ParaView,
pyvista and meshio read the files.

An array is an :class:`Array`: name, numpy dtype, number of components, number of tuples, and a function
returning an iterator of chunks (C-contiguous, any length, in order) that together hold the values.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

VTK_VERTEX, VTK_LINE = 1, 3
CHUNK = 1 << 20
_TYPES = {np.dtype(np.float64): "Float64", np.dtype(np.float32): "Float32", np.dtype(np.int64): "Int64",
          np.dtype(np.int32): "Int32", np.dtype(np.int16): "Int16", np.dtype(np.int8): "Int8",
          np.dtype(np.uint8): "UInt8", np.dtype(np.uint32): "UInt32", np.dtype(np.uint64): "UInt64"}


@dataclass
class Array:
    name: str
    dtype: np.dtype
    components: int
    tuples: int
    chunks: Callable

    @property
    def nbytes(self):
        return int(self.tuples) * int(self.components) * np.dtype(self.dtype).itemsize


def array(name, values, components=None):
    """An Array holding the numpy array `values` (written as it is, in chunks of its rows)."""
    a = np.asarray(values)
    comps = components or (1 if a.ndim == 1 else int(np.prod(a.shape[1:])))
    n = len(a)
    rows = max(1, CHUNK // max(comps, 1))

    def chunks():
        for s in range(0, n, rows):
            yield a[s:s + rows]

    return Array(name, a.dtype, comps, n, chunks)


def pieces(name, dtype, parts):
    """A 1-component Array made of consecutive parts: each (count, fn(start, stop) -> values) whose values for
    rows start..stop of that part are made on demand (e.g. a constant, a range)."""
    dtype = np.dtype(dtype)
    total = sum(int(c) for c, _ in parts)

    def chunks():
        for count, fn in parts:
            for s in range(0, int(count), CHUNK):
                yield np.asarray(fn(s, min(s + CHUNK, int(count))), dtype)

    return Array(name, dtype, 1, total, chunks)


def constant(value):
    return lambda s, e: np.full(e - s, value)


def write_vtu(path, points: Array, n_cells, connectivity: Array, offsets: Array, types: Array, point_data=(),
              cell_data=()):
    """Write the VTU file `path` (a file object opened for binary writing, or a path)."""
    arrays = []  # (section, Array) in the order of the appended block

    def head(a: Array, offset):
        comps = f' NumberOfComponents="{a.components}"' if a.components != 1 else ""
        return (f'<DataArray type="{_TYPES[np.dtype(a.dtype)]}" Name="{a.name}"{comps} format="appended" '
                f'offset="{offset}"/>')

    xml, offset = [], 0

    def add(a):
        nonlocal offset
        xml.append("      " + head(a, offset))
        arrays.append(a)
        offset += 8 + a.nbytes

    xml.append('<?xml version="1.0"?>')
    xml.append('<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64">')
    xml.append("<UnstructuredGrid>")
    xml.append(f'<Piece NumberOfPoints="{points.tuples}" NumberOfCells="{int(n_cells)}">')
    xml.append("<Points>")
    add(points)
    xml.append("</Points>")
    xml.append("<Cells>")
    for a in (connectivity, offsets, types):
        add(a)
    xml.append("</Cells>")
    for tag, data in (("PointData", point_data), ("CellData", cell_data)):
        if data:
            xml.append(f"<{tag}>")
            for a in data:
                add(a)
            xml.append(f"</{tag}>")
    xml.append("</Piece>")
    xml.append("</UnstructuredGrid>")
    xml.append('<AppendedData encoding="raw">')
    text = ("\n".join(xml) + "\n_").encode()
    own = isinstance(path, (str, bytes)) or hasattr(path, "__fspath__")
    fh = open(path, "wb") if own else path
    try:
        fh.write(text)
        for a in arrays:
            fh.write(np.uint64(a.nbytes).tobytes())
            written = 0
            for c in a.chunks():
                c = np.ascontiguousarray(c, dtype=np.dtype(a.dtype).newbyteorder("<"))
                fh.write(memoryview(c).cast("B"))
                written += c.nbytes
            if written != a.nbytes:
                raise ValueError(f"VTU array {a.name}: {written} bytes written, {a.nbytes} announced")
        fh.write(b"\n</AppendedData>\n</VTKFile>\n")
    finally:
        if own:
            fh.close()


def points_and_lines(path, points, lines, point_data=(), cell_data=(), vertex_cells=True):
    """A VTU of `points` (n, 3) with one vertex cell per point (when `vertex_cells`) followed by one line cell
    per row of `lines` (m, 2) (point indices). `cell_data` Arrays hold n + m values (vertex cells first) or m
    without vertex cells."""
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    lines = np.asarray(lines, np.int64).reshape(-1, 2)
    n = len(pts) if vertex_cells else 0
    m = len(lines)
    conn = pieces("connectivity", np.int64, [(n, lambda s, e: np.arange(s, e)),
                                            (m, lambda s, e: lines[s:e].ravel())])
    conn.tuples = n + 2 * m
    conn.chunks = _flat_chunks(n, lines)
    offs = pieces("offsets", np.int64, [(n, lambda s, e: np.arange(s + 1, e + 1)),
                                       (m, lambda s, e: n + 2 * np.arange(s + 1, e + 1))])
    types = pieces("types", np.uint8, [(n, constant(VTK_VERTEX)), (m, constant(VTK_LINE))])
    write_vtu(path, array("Points", pts), n + m, conn, offs, types, point_data, cell_data)


def _flat_chunks(n, lines):
    def chunks():
        for s in range(0, n, CHUNK):
            yield np.arange(s, min(s + CHUNK, n), dtype=np.int64)
        rows = CHUNK // 2
        for s in range(0, len(lines), rows):
            yield lines[s:s + rows]

    return chunks


__all__ = ["Array", "array", "pieces", "constant", "write_vtu", "points_and_lines", "VTK_VERTEX", "VTK_LINE"]
