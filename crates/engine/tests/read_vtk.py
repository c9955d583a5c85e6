#!/usr/bin/env python3
"""Reads back the ParaView output of ballast_engine::output::vtk and checks it.

Usage: read_vtk.py OUTPUT_DIR EXPECTED_JSON

OUTPUT_DIR holds grains.pvd, bodies.pvd, contacts.pvd and vtk/*.vtu; EXPECTED_JSON (written by
crates/engine/tests/vtk.rs) lists, per frame, its time, its files and what they must hold.

Every .vtu is read twice:
  * by meshio (the independent reader), whose points, cells and data are compared with the
    expected values. meshio 5.3 cannot read a grid without cells (IndexError in
    vtk_cells_from_data), so such files (a frame without contacts) are checked through the
    second reader only;
  * by a strict parser of the zlib-compressed appended layout written here (VTK's
    `vtkZLibDataCompressor` blocks: header, offsets, compressed block sizes that must tile the
    data exactly, blocks that inflate to the sizes the header gives), whose arrays must also
    agree with meshio's.
Float32 arrays (points, vector fields) are compared with the expected doubles to float32
rounding: one unit in the last place of the largest expected magnitude.
If the `vtk` Python package happens to be installed, VTK's own XML reader (ParaView's) must read
every file without error too; it is optional, meshio is not.

Exits 0 when everything matches, 1 with a list of mismatches otherwise, 2 on bad usage or a
missing dependency.
"""

import json
import math
import os
import re
import sys
import xml.etree.ElementTree as ET
import zlib

try:
    import numpy as np
    import meshio
except ImportError as e:
    print(f"read_vtk.py: {e}; install it with `pip install meshio` (it brings numpy)", file=sys.stderr)
    sys.exit(2)

SERIES = ("grains", "bodies", "contacts")
VTK_TYPES = {1: "vertex", 7: "polygon"}
NUMPY = {
    "UInt8": np.uint8,
    "Int32": np.int32,
    "Int64": np.int64,
    "Float32": np.float32,
    "Float64": np.float64,
}
TOL = 1e-12
# Float32's unit in the last place, relative: the rounding of a double written as Float32.
TOL32 = 2.0**-23

errors = []


def fail(msg):
    errors.append(msg)


def close(a, b, tol=TOL):
    return abs(a - b) <= tol * max(1.0, abs(a), abs(b))


def compare(where, got, want, tol=TOL):
    """Compares nested lists of numbers; records the first mismatch. Float32 values are
    compared to float32 rounding of the largest expected magnitude."""
    single = np.asarray(got).dtype == np.float32
    got = np.asarray(got, dtype=float)
    want = np.asarray(want, dtype=float)
    if got.size == 0 and want.size == 0:
        return
    if got.shape != want.shape:
        fail(f"{where}: shape {got.shape}, expected {want.shape}")
        return
    atol = tol
    if single:
        tol = max(tol, TOL32)
        atol = tol * max(1.0, float(np.abs(want).max()))
    bad = ~np.isclose(got, want, rtol=tol, atol=atol)
    if bad.any():
        k = np.argwhere(bad)[0]
        fail(f"{where}[{', '.join(map(str, k))}]: got {got[tuple(k)]!r}, expected {want[tuple(k)]!r}")


# ---------------------------------------------------------------- strict raw-appended parser


def read_raw(path):
    """Parses a zlib-compressed raw-appended .vtu; returns the normalized grid or None after
    recording errors."""
    raw = open(path, "rb").read()
    m = re.search(rb'<AppendedData encoding="raw">\s*_', raw)
    end = raw.rfind(b"</AppendedData>")
    if m is None or end < m.end():
        fail(f"{path}: no raw <AppendedData> block")
        return None
    root = ET.fromstring(raw[: raw.rfind(b"<AppendedData", 0, m.end())] + b"</VTKFile>")
    data = raw[m.end() : end]
    want = {
        "type": "UnstructuredGrid",
        "byte_order": "LittleEndian",
        "header_type": "UInt64",
    }
    for k, v in want.items():
        if root.get(k) != v:
            fail(f"{path}: VTKFile {k}={root.get(k)!r}, expected {v!r}")
    if root.get("compressor") != "vtkZLibDataCompressor":
        fail(f"{path}: compressor {root.get('compressor')!r}, expected 'vtkZLibDataCompressor'")
        return None
    pieces = root.findall("UnstructuredGrid/Piece")
    if len(pieces) != 1:
        fail(f"{path}: {len(pieces)} pieces, expected 1")
        return None
    piece = pieces[0]
    n_points = int(piece.get("NumberOfPoints"))
    n_cells = int(piece.get("NumberOfCells"))

    arrays = []  # (offset, section, name, element)
    for section in ("FieldData", "Piece/PointData", "Piece/CellData", "Piece/Points", "Piece/Cells"):
        for e in root.findall(f"UnstructuredGrid/{section}/DataArray"):
            if e.get("format") != "appended":
                fail(f"{path}: {e.get('Name')} format={e.get('format')!r}")
                return None
            arrays.append((int(e.get("offset")), section.split("/")[-1], e.get("Name"), e))
    arrays.sort(key=lambda a: a[0])

    grid = {"FieldData": {}, "PointData": {}, "CellData": {}, "Points": {}, "Cells": {}}
    pos = 0
    for offset, section, name, e in arrays:
        if offset != pos:
            fail(f"{path}: {name} at offset {offset}, previous block ends at {pos}")
            return None
        nblocks, block, last = (int(x) for x in np.frombuffer(data[pos : pos + 24], "<u8"))
        sizes = [int(x) for x in np.frombuffer(data[pos + 24 : pos + 24 + 8 * nblocks], "<u8")]
        pos += 24 + 8 * nblocks
        raw_bytes = b""
        for k, c in enumerate(sizes):
            chunk = zlib.decompress(data[pos : pos + c])
            want_len = last if (k == nblocks - 1 and last) else block
            if len(chunk) != want_len:
                fail(f"{path}: {name} block {k} inflates to {len(chunk)} bytes, header says {want_len}")
                return None
            raw_bytes += chunk
            pos += c
        dtype = np.dtype(NUMPY[e.get("type")]).newbyteorder("<")
        size = len(raw_bytes)
        if size % dtype.itemsize:
            fail(f"{path}: {name} has {size} bytes, not a multiple of {dtype.itemsize}")
            return None
        values = np.frombuffer(raw_bytes, dtype)
        ncomp = int(e.get("NumberOfComponents", "1"))
        grid[section][name] = values.reshape(-1, ncomp) if ncomp > 1 else values
    if data[pos:].strip():
        fail(f"{path}: {len(data) - pos} stray bytes after the last array")

    points = grid["Points"].get("Points")
    cells = grid["Cells"]
    if points is None or set(cells) != {"connectivity", "offsets", "types"}:
        fail(f"{path}: missing Points or Cells arrays")
        return None
    conn, offs, types = cells["connectivity"], cells["offsets"], cells["types"]
    if points.shape != (n_points, 3) and not (n_points == 0 and points.size == 0):
        fail(f"{path}: Points shape {points.shape}, NumberOfPoints={n_points}")
    if len(offs) != n_cells or len(types) != n_cells:
        fail(f"{path}: {len(offs)} offsets, {len(types)} types, NumberOfCells={n_cells}")
        return None
    if n_cells and (np.any(np.diff(offs) <= 0) or offs[0] <= 0 or offs[-1] != len(conn)):
        fail(f"{path}: offsets not increasing up to the connectivity length {len(conn)}")
        return None
    if len(conn) and (conn.min() < 0 or conn.max() >= n_points):
        fail(f"{path}: connectivity outside 0..{n_points}")
    for section, count in (("PointData", n_points), ("CellData", n_cells)):
        for name, a in grid[section].items():
            if len(a) != count:
                fail(f"{path}: {section} {name} has {len(a)} tuples, expected {count}")
    starts = np.concatenate([[0], offs[:-1]]).astype(int)
    return {
        "points": points.reshape(-1, 3),
        "cells": [list(conn[s:e]) for s, e in zip(starts, offs.astype(int))],
        "types": [VTK_TYPES.get(int(t), f"vtk{int(t)}") for t in types],
        "cell_data": grid["CellData"],
        "point_data": grid["PointData"],
        "field_data": grid["FieldData"],
    }


# ---------------------------------------------------------------- meshio


def read_meshio(path):
    """Reads a .vtu with meshio into the normalized form (cell blocks joined in file order)."""
    mesh = meshio.read(path)
    cells, types = [], []
    for block in mesh.cells:
        for c in block.data:
            cells.append(list(c))
            types.append(block.type)
    cell_data = {name: np.concatenate(blocks) for name, blocks in mesh.cell_data.items()}
    return {
        "points": mesh.points,
        "cells": cells,
        "types": types,
        "cell_data": cell_data,
        "point_data": dict(mesh.point_data),
        "field_data": dict(mesh.field_data),
    }


def read_vtk(path):
    """Reads a .vtu with VTK's XML reader if the vtk package is installed; (points, cells)."""
    try:
        import vtk  # noqa: F401  (optional)
    except ImportError:
        return None
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader

    messages = []
    reader = vtkXMLUnstructuredGridReader()
    for event in ("ErrorEvent", "WarningEvent"):
        reader.AddObserver(event, lambda obj, ev, msgs=messages: msgs.append(ev))
    reader.SetFileName(path)
    reader.Update()
    if messages or reader.GetErrorCode():
        fail(f"{path}: VTK's reader reported {messages or reader.GetErrorCode()}")
    out = reader.GetOutput()
    return out.GetNumberOfPoints(), out.GetNumberOfCells()


def same_grids(path, a, b):
    """The strict parser and meshio must agree."""
    compare(f"{path} points (meshio vs raw)", a["points"], b["points"])
    if a["cells"] != b["cells"] or a["types"] != b["types"]:
        fail(f"{path}: cells differ between meshio and the raw parser")
    for key in ("cell_data", "point_data", "field_data"):
        if set(a[key]) != set(b[key]):
            fail(f"{path}: {key} names {sorted(a[key])} (meshio) vs {sorted(b[key])} (raw)")
            continue
        for name in a[key]:
            compare(f"{path} {key} {name} (meshio vs raw)", a[key][name], b[key][name])


# ---------------------------------------------------------------- expected contents


def check_square(where, pts, sq):
    """A half-space's square: in the plane, centred, of the given side, CCW about the normal."""
    c, n, side = np.array(sq["centre"]), np.array(sq["normal"]), sq["side"]
    # Float32 corners: a few units in the last place of the largest coordinate.
    tol = 4 * TOL32 * max(side, float(np.abs(c).max()), 1.0)
    if len(pts) != 4:
        fail(f"{where}: {len(pts)} corners, expected 4")
        return
    if np.abs((pts - c) @ n).max() > tol:
        fail(f"{where}: corners off the plane")
    if np.linalg.norm(pts.mean(axis=0) - c) > tol:
        fail(f"{where}: centre {pts.mean(axis=0)}, expected {c}")
    for k in range(4):
        e0, e1 = pts[(k + 1) % 4] - pts[k], pts[(k + 2) % 4] - pts[(k + 1) % 4]
        if abs(np.linalg.norm(e0) - side) > tol or abs(e0 @ e1) > tol * side:
            fail(f"{where}: not a square of side {side}")
            return
        if np.cross(e0, e1) @ n <= 0:
            fail(f"{where}: corners not counter-clockwise about the outward normal")
            return


def check_contents(path, grid, exp, time, cell_type):
    n_points, n_cells = len(grid["points"]), len(grid["cells"])
    if n_points != exp["num_points"]:
        fail(f"{path}: {n_points} points, expected {exp['num_points']}")
    if n_cells != exp["num_cells"]:
        fail(f"{path}: {n_cells} cells, expected {exp['num_cells']}")
        return
    wrong = [t for t in grid["types"] if t != cell_type]
    if wrong:
        fail(f"{path}: cell types {sorted(set(wrong))}, expected only {cell_type}")
    tv = grid["field_data"].get("TimeValue")
    if tv is None or len(np.ravel(tv)) != 1 or not close(float(np.ravel(tv)[0]), time):
        fail(f"{path}: TimeValue {tv}, expected {time!r}")

    if "cells" in exp:  # surfaces
        for k, (conn, cell) in enumerate(zip(grid["cells"], exp["cells"])):
            pts = grid["points"][conn]
            if "loop" in cell:
                compare(f"{path} cell {k} corners", pts, cell["loop"])
            else:
                check_square(f"{path} cell {k}", pts, cell["square"])
    else:  # contacts: one vertex per point, in order
        if grid["cells"] != [[k] for k in range(n_cells)]:
            fail(f"{path}: vertex cells are not 0, 1, 2, …")
        compare(f"{path} points", grid["points"], exp["points"])

    for key in ("cell_data", "point_data"):
        for name, want in exp.get(key, {}).items():
            got = grid[key].get(name)
            if got is None:
                fail(f"{path}: no {key} field {name!r} (has {sorted(grid[key])})")
            elif np.asarray(want).dtype.kind in "iu" and len(want):
                if got.dtype.kind not in "iu" or not np.array_equal(got, want):
                    fail(f"{path}: {key} {name} = {got.tolist()}, expected {want}")
            else:
                compare(f"{path} {key} {name}", got, want)


def read_pvd(path):
    root = ET.parse(path).getroot()
    if root.get("type") != "Collection":
        fail(f"{path}: VTKFile type {root.get('type')!r}, expected 'Collection'")
    return [(float(d.get("timestep")), d.get("file")) for d in root.iter("DataSet")]


def main():
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    out_dir, expected_path = sys.argv[1], sys.argv[2]
    frames = json.load(open(expected_path))["frames"]
    vtk_checked = 0
    for series in SERIES:
        pvd = os.path.join(out_dir, f"{series}.pvd")
        if not os.path.isfile(pvd):
            fail(f"{pvd} missing")
            continue
        listed = read_pvd(pvd)
        if len(listed) != len(frames):
            fail(f"{pvd}: {len(listed)} frames, expected {len(frames)}")
        times = [t for t, _ in listed]
        if any(b <= a for a, b in zip(times, times[1:])):
            fail(f"{pvd}: times not strictly increasing: {times}")
        for (time, file), frame in zip(listed, frames):
            exp = frame[series]
            if file != exp["file"] or not close(time, frame["time"]):
                fail(f"{pvd}: lists ({time!r}, {file}), expected ({frame['time']!r}, {exp['file']})")
            path = os.path.join(out_dir, file)
            if not os.path.isfile(path):
                fail(f"{path} missing")
                continue
            raw = read_raw(path)
            if raw is None:
                continue
            cell_type = "vertex" if series == "contacts" else "polygon"
            if exp["expect"]["num_cells"] > 0:
                grid = read_meshio(path)
                same_grids(path, grid, raw)
            else:
                grid = raw
            check_contents(path, grid, exp["expect"], frame["time"], cell_type)
            counts = read_vtk(path)
            if counts is not None:
                vtk_checked += 1
                if counts != (len(raw["points"]), len(raw["cells"])):
                    fail(f"{path}: VTK reads {counts} points/cells")
    if errors:
        print(f"read_vtk.py: {len(errors)} mismatch(es):", file=sys.stderr)
        for e in errors[:30]:
            print("  " + e, file=sys.stderr)
        sys.exit(1)
    extra = f", {vtk_checked} also read by VTK" if vtk_checked else " (vtk not installed: VTK reader not tried)"
    print(f"read_vtk.py: OK, {len(frames)} frames x {len(SERIES)} series read back with meshio {meshio.__version__}{extra}")


if __name__ == "__main__":
    main()
