"""Every mesh and point cloud read through the one reader: hostile and careless files
(NaN vertices, zero-area faces, headers claiming 10^11 vertices, triangle counts that do
not match the file, polygons that crash Open3D's splitter) are refused with one line
before Open3D loads them or right after, within bounded memory and time, through the
reader and through the CLI; fuzzed files never give anything but geometry or that line."""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np
import open3d as o3d
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from recon_cli.errors import FileError, InputError
from recon_cli.inputs import meshes
from recon_cli.inputs.meshes import (
    MAX_COORDINATE_M,
    MAX_EXTENT_M,
    MAX_HEADER_BYTES,
    MAX_MESH_FILE_BYTES,
    MAX_OBJ_LINES,
    MAX_PCD_UNCOMPRESSED_BYTES,
    MAX_STL_TEXT_BYTES,
    MAX_STL_TRIANGLES,
    MAX_TEXT_TRIANGLES,
    MAX_TEXT_VERTICES,
    MAX_TRIANGLES,
    MAX_VERTICES,
    read_cloud,
    read_mesh,
)

from .measure import run_cli, run_python
from .test_images import _table, png_claiming

ROOT = Path(__file__).resolve().parents[2]
TRIANGLE = [(0.0, 0.0, 0.0), (0.1, 0.0, 0.0), (0.0, 0.1, 0.0)]


def ply(vertices, faces=(), fmt="binary_little_endian", count_type="uchar", header_extra="", nv=None, nf=None):
    """A PLY with float x, y, z and a face list; ``nv``/``nf`` override the declared counts."""
    nv = len(vertices) if nv is None else nv
    nf = len(faces) if nf is None else nf
    head = (f"ply\nformat {fmt} 1.0\n{header_extra}element vertex {nv}\nproperty float x\nproperty float y\n"
            f"property float z\nelement face {nf}\nproperty list {count_type} int vertex_indices\nend_header\n")
    if fmt == "ascii":
        body = "".join(" ".join(f"{c:g}" for c in v) + "\n" for v in vertices)
        body += "".join(f"{len(f)} " + " ".join(map(str, f)) + "\n" for f in faces)
        return head.encode() + body.encode()
    code = {"uchar": "B", "int": "i"}[count_type]
    body = b"".join(struct.pack("<3f", *v) for v in vertices)
    body += b"".join(struct.pack(f"<{code}{len(f)}i", len(f), *f) for f in faces)
    return head.encode() + body


def binary_stl(triangles, declared=None) -> bytes:
    body = b"".join(struct.pack("<12fH", 0, 0, 1, *[c for v in t for c in v], 0) for t in triangles)
    return b"binary stl".ljust(80, b" ") + struct.pack("<I", len(triangles) if declared is None else declared) + body


def pcd(fields="x y z", size="4 4 4", typ="F F F", count="1 1 1", points=3, data="ascii", body=None,
        order=None) -> bytes:
    lines = {"VERSION": "VERSION 0.7", "FIELDS": f"FIELDS {fields}", "SIZE": f"SIZE {size}", "TYPE": f"TYPE {typ}",
             "COUNT": f"COUNT {count}", "WIDTH": f"WIDTH {points}", "HEIGHT": "HEIGHT 1",
             "VIEWPOINT": "VIEWPOINT 0 0 0 1 0 0 0", "POINTS": f"POINTS {points}", "DATA": f"DATA {data}"}
    head = "\n".join(lines[k] for k in (order or lines)) + "\n"
    if body is None:
        body = "".join(" ".join(f"{c:g}" for c in v) + "\n" for v in TRIANGLE).encode()
    return head.encode() + body


def ply_records(vertex_props: list[tuple[str, str]], rows: np.ndarray, faces=None, count_type="u1") -> bytes:
    """A binary little-endian PLY of vertex records (``vertex_props``: (PLY type, name);
    ``rows``: a structured or plain array with one column per property) and triangles."""
    codes = {"float": "<f4", "double": "<f8", "uchar": "u1", "int": "<i4"}
    record = np.dtype([(name, codes[t]) for t, name in vertex_props])
    table = np.zeros(len(rows), record)
    for k, (_, name) in enumerate(vertex_props):
        table[name] = rows[:, k]
    head = f"ply\nformat binary_little_endian 1.0\nelement vertex {len(rows)}\n"
    head += "".join(f"property {t} {name}\n" for t, name in vertex_props)
    body = table.tobytes()
    if faces is not None:
        head += f"element face {len(faces)}\nproperty list uchar int vertex_indices\n"
        face = np.zeros(len(faces), np.dtype([("n", count_type), ("i", "<i4", 3)]))
        face["n"], face["i"] = 3, faces
        body += face.tobytes()
    return (head + "end_header\n").encode() + body


XYZ = [("float", "x"), ("float", "y"), ("float", "z")]
NAN = [(float("nan"), 0.0, 0.0), *TRIANGLE[1:]]
TETRA = [*TRIANGLE, (0.0, 0.0, 0.1)]
TETRA_FACES = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
ASCII_TETRA = ply(TETRA, TETRA_FACES, "ascii")

LINE = [(0.0, 0.0, 0.0), (0.1, 0.0, 0.0), (0.2, 0.0, 0.0)]
OBJ = "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nf 1 2 3\n"

# (name, file name, bytes, reader, expected part of the message)
HOSTILE = [
    ("ply-nan", "a.ply", ply(NAN, [(0, 1, 2)]), "mesh",
     "has 1 vertex with NaN or infinite values (vertex 0: (nan, 0, 0))"),
    ("ply-ascii-nan", "a.ply", ply(NAN, [(0, 1, 2)], "ascii"), "mesh", "1 vertex with NaN or infinite values"),
    ("ply-zero-area", "a.ply", ply(LINE, [(0, 1, 2), (0, 0, 1)]), "mesh", "is degenerate: the total area of its 2 "
     "triangles is 0"),
    ("ply-10^11-vertices", "a.ply", ply(TRIANGLE, [(0, 1, 2)], nv=10**11), "mesh",
     f"declares 100000000000 vertices, more than the {MAX_VERTICES} recon reads"),
    ("ply-10^11-vertices-cloud", "a.ply", ply(TRIANGLE, nv=10**11), "cloud", "declares 100000000000 vertices"),
    ("ply-counts-beyond-the-file", "a.ply", ply(TRIANGLE, [(0, 1, 2)], nv=1_000_000), "mesh",
     "declares 1000000 vertex, 1 face, which need at least 12000001 bytes"),
    ("ply-quad-out-of-range", "a.ply", ply(TRIANGLE, [(0, 1, 2, 2_000_000_000)]), "mesh",
     "has a face of 4 vertices (face 0); recon reads triangle meshes only"),
    ("ply-empty-face", "a.ply", ply(TRIANGLE, [()]), "mesh", "has a face of 0 vertices"),
    ("ply-mixed-faces", "a.ply", ply(TRIANGLE, [(0, 1, 2), (0, 1, 2, 0)]), "mesh",
     "faces of different sizes (face 1: 4 entries"),
    ("ply-ascii-quad", "a.ply", ply(TRIANGLE, [(0, 1, 2, 0)], "ascii"), "mesh",
     "has a face that is not a triangle (face 0"),
    ("ply-index-out-of-range", "a.ply", ply(TRIANGLE, [(0, 1, 7)]), "mesh",
     "has triangles with vertex index 7, outside 0 to 2"),
    ("ply-space-after-end-header", "a.ply", ply(TRIANGLE, [(0, 1, 2)]).replace(b"end_header\n", b"end_header \n"),
     "mesh", "no line 'end_header'"),
    ("ply-comment-without-text", "a.ply", ply(TRIANGLE, [(0, 1, 2)], header_extra="comment\n"), "mesh",
     "is a 'comment' without text"),
    ("ply-long-header", "a.ply", b"ply\nformat ascii 1.0\n" + b"comment x\n" * (MAX_HEADER_BYTES // 10), "mesh",
     "no line 'end_header' in its first 64 KiB"),
    ("ply-not-ply", "a.ply", b"this is not a mesh", "mesh", "has no triangles recon can read: it is not a PLY file"),
    ("ply-no-faces", "a.ply", ply(TRIANGLE), "mesh", "has no triangles (3 vertices only)"),
    ("ply-far-away", "a.ply", ply([(5000.0, 0, 0), (5000.1, 0, 0), (5000, 0.1, 0)], [(0, 1, 2)]), "mesh",
     f"has a coordinate of 5000 m (after scale 1), outside ±{MAX_COORDINATE_M:g} m (is the file in metres?)"),
    ("ply-in-millimetres", "a.ply", ply([(0, 0, 0), (300.0, 0, 0), (0, 100.0, 0)], [(0, 1, 2)]), "mesh",
     f"is 300 m across (after scale 1), more than the {MAX_EXTENT_M:g} m recon reads"),
    ("stl-count-mismatch", "a.stl", binary_stl([TRIANGLE] * 2, declared=4_000_000_000), "mesh",
     "as binary STL it declares 4000000000 triangles, which take 84 + 50 x 4000000000 = 200000000084 bytes, but "
     "the file has 184 bytes"),
    ("stl-count-one-off", "a.stl", binary_stl([TRIANGLE] * 2, declared=3), "mesh", "declares 3 triangles"),
    ("stl-too-short", "a.stl", b"solid\x00\x01", "mesh", "too short for an STL file"),
    ("stl-zero-area", "a.stl", binary_stl([LINE]), "mesh", "is degenerate"),
    ("obj-nan", "a.obj", OBJ.replace("v 0 0 0", "v nan 0 0").encode(), "mesh", "1 vertex with NaN or infinite values"),
    ("obj-inf", "a.obj", OBJ.replace("v 0 0 0", "v 1e999 0 0").encode(), "mesh", "NaN or infinite values"),
    ("obj-quad", "a.obj", (OBJ + "v 0.1 0.1 0\nf 1 2 4 3\n").encode(), "mesh",
     "has faces of more than three vertices"),
    ("obj-nul", "a.obj", OBJ.encode() + b"\x00", "mesh", "holds NUL bytes"),
    ("obj-endless-line", "a.obj", OBJ.encode() + b"# " + b"x" * (5 * 2**20), "mesh", "has a line longer than 4 MiB"),
    ("obj-zero-area", "a.obj", b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "mesh", "is degenerate"),
    ("obj-index-out-of-range", "a.obj", OBJ.replace("f 1 2 3", "f 1 2 9").encode(), "mesh",
     "cannot be read (assimp: OBJ: vertex index out of range)"),
    ("empty-ply", "a.ply", b"", "mesh", "is empty (0 bytes)"),
    ("empty-obj", "a.obj", b"", "mesh", "is empty (0 bytes)"),
    ("empty-pcd", "a.pcd", b"", "cloud", "is empty (0 bytes)"),
    ("off", "a.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "mesh", "has the type '.off', recon reads OBJ, "
     "PLY and STL meshes"),
    ("gltf", "a.gltf", b"{}", "mesh", "has the type '.gltf'"),
    ("xyz-cloud", "a.xyz", b"0 0 0\n", "cloud", "has the type '.xyz', recon reads PLY and PCD point clouds"),
    ("cloud-nan", "a.ply", ply(NAN), "cloud", "has 1 point with NaN or infinite values"),
    ("pcd-10^11-points", "a.pcd", pcd(points=10**11), "cloud", "declares 100000000000 points"),
    ("pcd-points-beyond-the-file", "a.pcd", pcd(points=100_000, data="binary", body=b"\0" * 36), "cloud",
     "declares 100000 points, which need at least 1200000 bytes"),
    ("pcd-compressed-size-lie", "a.pcd", pcd(data="binary_compressed", body=struct.pack("<II", 10, 4_000_000_000)
                                             + b"\0" * 10), "cloud", "declares 4000000000 bytes of uncompressed data"),
    ("pcd-partial-normals", "a.pcd", pcd("x y z normal_x normal_z", "4 4 4 4 4", "F F F F F", "1 1 1 1 1"), "cloud",
     "has some of the fields normal_x, normal_y, normal_z but not all three"),
    ("pcd-double-xyz", "a.pcd", pcd(size="8 8 8"), "cloud", "stores x in 8 bytes"),
    ("pcd-out-of-order", "a.pcd", pcd(order=("FIELDS", "POINTS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "DATA")),
     "cloud", "has its header line SIZE out of PCD order"),
    ("pcd-nan", "a.pcd", pcd(body=b"nan 0 0\n0 0 0\n0 1 0\n"), "cloud", "1 point with NaN or infinite values"),
    # values Open3D's readers cannot parse: rply leaves the rest of the array uninitialised, assimp and the PCD
    # reader read a word as 0 or part of a number, the PCD reader skips a short line
    ("ply-ascii-word-for-a-float", "a.ply", ASCII_TETRA.replace(b"\n0 0 0\n", b"\nabc 0 0\n"), "vertices",
     "reconstruction cannot be read (rply: Error reading 'x' of 'vertex' number 0: a value that is not a number"),
    ("ply-ascii-inf-for-a-float", "a.ply", ASCII_TETRA.replace(b"\n0 0 0\n", b"\ninf 0 0\n"), "cloud",
     "cannot be read (rply: Error reading 'x' of 'vertex' number 0"),
    ("ply-ascii-1e39-for-a-float", "a.ply", ASCII_TETRA.replace(b"\n0 0 0.1\n", b"\n0 0 1e39\n"), "vertices",
     "cannot be read (rply: Error reading 'z' of 'vertex' number 3"),
    ("ply-ascii-word-for-an-index", "a.ply", ASCII_TETRA.replace(b"3 1 2 3", b"3 1 2 x"), "mesh",
     "cannot be read (rply: Error reading value number 3 of 'vertex_indices' of 'face' number 3"),
    ("ply-ascii-missing-value", "a.ply", ply(TRIANGLE, fmt="ascii").replace(b"0 0.1 0\n", b"0 0.1\n"), "cloud",
     "cannot be read (rply: Unexpected end of file; Error reading 'z' of 'vertex' number 2"),
    ("obj-word", "a.obj", OBJ.replace("v 0 0 0", "v abc 0 0").encode(), "vertices",
     "has a 'v' line whose values are not all numbers (line 1: 'v abc 0 0')"),
    ("obj-hexadecimal", "a.obj", OBJ.replace("v 0.1 0 0", "v 0x10 0 0").encode(), "mesh",
     "has a 'v' line whose values are not all numbers (line 2: 'v 0x10 0 0')"),
    ("obj-decimal-comma", "a.obj",
     ("# part\r\n" + OBJ.replace("\n", "\r\n").replace("v 0 0.1 0", "v 0 0,1 0")).encode(), "mesh",
     "(line 4: 'v 0 0,1 0')"),
    ("obj-underscore", "a.obj", OBJ.replace("v 0.1 0 0", "v 1_0 0 0").encode(), "mesh", "(line 2: 'v 1_0 0 0')"),
    ("obj-normal-word", "a.obj", (OBJ + "vn 0 0 one\n").encode(), "mesh",
     "has a 'vn' line whose values are not all numbers (line 5: 'vn 0 0 one')"),
    ("stl-ascii-word", "a.stl", b"solid t\nfacet normal 0 0 1\nouter loop\nvertex abc 0 0\nvertex 0.1 0 0\n"
     b"vertex 0 0.1 0\nendloop\nendfacet\nendsolid t\n", "mesh", 'cannot be read (assimp: Cannot parse string "abc'),
    ("pcd-word", "a.pcd", pcd(body=b"abc 0 0\n0.1 0 0\n0 0.1 0\n"), "cloud",
     "has a data line that is not 3 numbers (line 11: 'abc 0 0'"),
    ("pcd-short-line", "a.pcd", pcd(body=b"0 0\n0.1 0 0\n0 0.1 0\n"), "cloud", "(line 11: '0 0'"),
    ("pcd-two-points-on-a-line", "a.pcd", pcd(body=b"0 0 0 0.1 0 0\n0 0.1 0\n"), "cloud",
     "(line 11: '0 0 0 0.1 0 0'"),
    ("pcd-too-few-lines", "a.pcd", pcd(body=b"0 0 0\n\n\n\n0.1 0 0\n\n\n"), "cloud",
     "has 2 lines of point values, but POINTS declares 3"),
    # the limits of formats Open3D loads before recon can check them
    ("ply-ascii-over-the-text-limit", "a.ply", ply(TRIANGLE, [(0, 1, 2)], "ascii", nv=MAX_TEXT_VERTICES + 1), "mesh",
     f"declares {MAX_TEXT_VERTICES + 1} vertices, more than the {MAX_TEXT_VERTICES} recon reads from ASCII PLY"),
    ("pcd-ascii-over-the-text-limit", "a.pcd", pcd(points=MAX_TEXT_VERTICES + 1), "cloud",
     f"more than the {MAX_TEXT_VERTICES} recon reads from ASCII or compressed PCD"),
    # binary records checked before loading
    ("ply-nan-normal", "a.ply", ply_records([*XYZ, ("float", "nx"), ("float", "ny"), ("float", "nz")],
                                            np.array([[0, 0, 0, 0, 0, 1], [0.1, 0, 0, np.inf, 0, 1],
                                                      [0, 0.1, 0, 0, 0, 1]])), "cloud",
     "has 1 normal with NaN or infinite values (normal 1: (inf, 0, 1))"),
    ("pcd-binary-nan-normal", "a.pcd", pcd("x y z normal_x normal_y normal_z", "4 4 4 4 4 4", "F F F F F F",
                                           "1 1 1 1 1 1", data="binary",
                                           body=np.array([[0, 0, 0, 0, 0, 1], [0.1, 0, 0, 0, 0, 1],
                                                          [0, 0.1, 0, 0, np.nan, 1]], "<f4").tobytes()), "cloud",
     "has 1 normal with NaN or infinite values (normal 2: (0, nan, 1))"),
]


def _read(kind: str, path: Path):
    """``kind``: "mesh", "vertices" (a mesh file whose triangles are optional, as
    ``recon evaluate`` reads a reconstruction) or "cloud"."""
    if kind == "cloud":
        return read_cloud(path)
    return read_mesh(path, "reconstruction", triangles=False) if kind == "vertices" else read_mesh(path)


@pytest.mark.parametrize("name, filename, data, kind, message", HOSTILE, ids=[h[0] for h in HOSTILE])
def test_hostile_meshes_and_clouds_are_one_line(tmp_path, capfd, name, filename, data, kind, message):
    path = tmp_path / filename
    path.write_bytes(data)
    with pytest.raises(FileError) as info:
        _read(kind, path)
    line = info.value.one_line()
    assert message in line and str(path) in line and "\n" not in line, line
    out, err = capfd.readouterr()
    assert out == "" and err == "", (out, err)  # Open3D's and rply's own messages stay off the terminal


def test_files_that_are_not_regular_files_or_too_large(tmp_path):
    with pytest.raises(FileError, match="mesh does not exist"):
        read_mesh(tmp_path / "missing.ply")
    (tmp_path / "dir.ply").mkdir()
    with pytest.raises(FileError, match="is not a regular file"):
        read_mesh(tmp_path / "dir.ply")
    os.mkfifo(tmp_path / "fifo.obj")
    with pytest.raises(FileError, match="is not a regular file"):  # never opened: a FIFO would block
        read_mesh(tmp_path / "fifo.obj")
    big = tmp_path / "big.stl"
    with big.open("wb") as f:  # sparse: no disk space
        f.truncate(MAX_MESH_FILE_BYTES + 1)
    with pytest.raises(FileError, match="is 512.0 MiB, more than the 512 MiB recon reads"):
        read_mesh(big)


def test_valid_files_read(tmp_path):
    box = o3d.geometry.TriangleMesh.create_box(0.1, 0.05, 0.02)
    box.compute_triangle_normals()
    for name, kw in (("b.ply", {}), ("a.ply", {"write_ascii": True}), ("b.stl", {}), ("b.obj", {})):
        o3d.io.write_triangle_mesh(str(tmp_path / name), box, **kw)
        mesh = read_mesh(tmp_path / name)
        assert len(mesh.triangles) == 12 and np.allclose(np.asarray(mesh.vertices).max(axis=0), (0.1, 0.05, 0.02))
    (tmp_path / "a.stl").write_text("solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 0.1 0 0\n"
                                    "vertex 0 0.1 0\nendloop\nendfacet\nendsolid t\n")
    assert len(read_mesh(tmp_path / "a.stl").triangles) == 1
    cloud = box.sample_points_uniformly(500)
    for name, kw in (("c.ply", {}), ("c.pcd", {}), ("a.pcd", {"write_ascii": True}), ("z.pcd", {"compressed": True})):
        o3d.io.write_point_cloud(str(tmp_path / name), cloud, **kw)
        assert len(read_cloud(tmp_path / name).points) == 500
    assert len(read_mesh(tmp_path / "c.ply", triangles=False).vertices) == 500  # vertices only, when asked
    o3d.io.write_point_cloud(str(tmp_path / "n.ply"), o3d.geometry.PointCloud())
    (tmp_path / "n.ply").write_bytes(ply([]))
    assert len(read_cloud(tmp_path / "n.ply", points=False).points) == 0
    with pytest.raises(FileError, match="holds no points"):
        read_cloud(tmp_path / "n.ply")


def test_binary_records_are_checked_in_chunks_before_open3d_loads(tmp_path, monkeypatch):
    """Binary PLY and PCD files are refused before Open3D reads them (it would first hold
    the whole file), what is wrong found in any chunk and counted over all of them."""
    monkeypatch.setattr(meshes.limits, "SCAN_BYTES", 100)  # 8 vertices, 7 faces a chunk

    def loaded(*args, **kwargs):
        raise AssertionError("Open3D loaded a file the guard refuses")

    readers = o3d.io.read_triangle_mesh, o3d.io.read_point_cloud
    monkeypatch.setattr(o3d.io, "read_triangle_mesh", loaded)
    monkeypatch.setattr(o3d.io, "read_point_cloud", loaded)
    n = 1000
    line = np.zeros((n, 3))
    line[:, 0] = np.arange(n) * 1e-4
    surface = line.copy()
    surface[1::2, 1] = 1e-3
    faces = np.stack([np.arange(n - 2), np.arange(1, n - 1), np.arange(2, n)], axis=1)
    normals = np.tile([0.0, 0.0, 1.0], (n, 1))

    def refused(data: bytes, kind: str = "cloud", **kw) -> str:
        path = tmp_path / ("a.pcd" if data.startswith(b"VERSION") else "a.ply")
        path.write_bytes(data)
        with pytest.raises(FileError) as info:
            read_cloud(path) if kind == "cloud" else read_mesh(path, **kw)
        return info.value.one_line()

    rows = surface.copy()
    rows[[997, 998], 2] = [np.nan, -np.inf]
    assert "has 2 points with NaN or infinite values (point 997: (0.0997, 0.001, nan))" in refused(
        ply_records(XYZ, rows))
    rows = np.hstack([surface, normals])
    rows[[3, 900], 3] = np.nan
    props = [*XYZ, ("double", "nx"), ("double", "ny"), ("double", "nz")]
    assert "has 2 normals with NaN or infinite values (normal 3: (nan, 0, 1))" in refused(ply_records(props, rows))
    rows = surface.copy()
    rows[999, 0] = 150.0  # the extent spans the chunks
    assert "is 150 m across (after scale 1)" in refused(ply_records(XYZ, rows))
    assert refused(ply_records(XYZ, rows, faces), "mesh", scale=10, units_hint="pass --scale").endswith(
        "has a coordinate of 1500 m (after scale 10), outside ±1000 m (is the file in metres?); pass --scale")
    assert "is degenerate: the total area of its 998 triangles is 0" in refused(ply_records(XYZ, line, faces), "mesh")
    assert "is degenerate" in refused(ply_records(XYZ, line, faces), "mesh", triangles=False)
    bad = faces.copy()
    bad[990, 2] = n
    assert f"has triangles with vertex index {n}, outside 0 to {n - 1}" in refused(ply_records(XYZ, surface, bad),
                                                                                    "mesh")
    assert f"has no triangles ({n} vertices only)" in refused(ply_records(XYZ, surface), "mesh")
    far = surface.copy()
    far[500] = (-5000.0, 0, 0)
    assert "has a coordinate of 5000 m (after scale 1)" in refused(ply_records(XYZ, far))
    rows = np.hstack([surface, normals]).astype("<f4")
    rows[999, 1] = np.nan
    data = pcd("x y z normal_x normal_y normal_z", "4 4 4 4 4 4", "F F F F F F", "1 1 1 1 1 1", points=n,
               data="binary", body=rows.tobytes())
    assert "has 1 point with NaN or infinite values (point 999: (0.0999, nan, 0))" in refused(data)
    monkeypatch.setattr(o3d.io, "read_triangle_mesh", readers[0])
    monkeypatch.setattr(o3d.io, "read_point_cloud", readers[1])
    (tmp_path / "ok.ply").write_bytes(ply_records([*XYZ, ("float", "nx"), ("float", "ny"), ("float", "nz")],
                                                  np.hstack([surface, normals]), faces))
    assert len(read_mesh(tmp_path / "ok.ply").triangles) == n - 2


def test_limits_of_the_formats_open3d_loads_first(tmp_path, monkeypatch):
    stl = tmp_path / "a.stl"
    with stl.open("wb") as f:  # sparse
        f.write(b"binary stl".ljust(80, b" ") + struct.pack("<I", MAX_STL_TRIANGLES + 1))
        f.truncate(84 + 50 * (MAX_STL_TRIANGLES + 1))
    with pytest.raises(FileError, match=f"declares {MAX_STL_TRIANGLES + 1} triangles, more than the "
                                        f"{MAX_STL_TRIANGLES} recon reads from STL"):
        read_mesh(stl)
    with stl.open("wb") as f:
        f.write(b"solid t\n" + b" " * 4096)
        f.truncate(MAX_STL_TEXT_BYTES + 1)
    with pytest.raises(FileError, match="is an ASCII STL of 128.0 MiB, more than the 128 MiB recon reads"):
        read_mesh(stl)
    monkeypatch.setattr(meshes.obj, "MAX_OBJ_LINES", 3)
    for extra, noun in (("v 0 0 0.1\n", "vertex"), ("vn 0 0 1\n" * 4, "normal"), ("vt 0 0\n" * 4, "texture coordinate"),
                        ("f 1 2 3\n" * 3, "face")):
        (tmp_path / "a.obj").write_text(OBJ + extra)
        with pytest.raises(FileError, match=f"has more than 3 {noun} lines, more than recon reads from OBJ"):
            read_mesh(tmp_path / "a.obj")
    points = MAX_PCD_UNCOMPRESSED_BYTES // 92 + 1  # x, y, z and 20 values of 4 bytes
    body = struct.pack("<II", 10, points * 92) + b"\0" * 10
    (tmp_path / "a.pcd").write_bytes(pcd("x y z f", "4 4 4 4", "F F F F", "1 1 1 20", points=points,
                                         data="binary_compressed", body=body))
    with pytest.raises(FileError, match="would decompress to 128.0 MiB, more than the 128 MiB recon reads"):
        read_cloud(tmp_path / "a.pcd")


def test_an_obj_material_library_is_not_opened(tmp_path):
    """The texture a material library names could claim gigapixels (Open3D would decode it
    unguarded) or the library could be a FIFO: the mesh is read without it."""
    (tmp_path / "huge.png").write_bytes(png_claiming(60000, 60000))
    (tmp_path / "m.mtl").write_text("newmtl m\nmap_Kd huge.png\n")
    os.mkfifo(tmp_path / "fifo.mtl")
    (tmp_path / "a.obj").write_text("mtllib m.mtl\nmtllib fifo.mtl\nusemtl m\n" + OBJ)
    mesh = read_mesh(tmp_path / "a.obj")
    assert len(mesh.triangles) == 1 and all(t.is_empty() for t in mesh.textures)
    assert not list(Path(os.environ.get("TMPDIR", "/tmp")).glob("recon-mesh-*.obj"))  # the copy is removed


def test_object_files_are_checked_after_their_scale(tmp_path):
    from recon_cli.objects import load_object

    path = tmp_path / "part.ply"
    path.write_bytes(ply([(0, 0, 0), (300.0, 0, 0), (0, 100.0, 0), (0, 0, 20.0)], TETRA_FACES))  # millimetres
    with pytest.raises(FileError, match=r"is 300 m across.*; pass a scale, e.g. --scale 0.001"):
        load_object(str(path))
    assert load_object(str(path), scale=0.001).extent == pytest.approx([0.3, 0.1, 0.02])
    with pytest.raises(InputError, match="too large for the board"):  # within the reader's limits, not the board's
        load_object(str(path), scale=0.01)


TILTED_SQUARE = [(0, 0, 0), (0.1, 0, 0.1), (0, 0.1, 0), (0.1, 0.1, 0.1)]


@pytest.mark.parametrize("vertices, faces, message", [
    (TRIANGLE, [(0, 1, 2)], "has only 3 vertices: an object to scan must enclose a volume (4 vertices at least)"),
    ([*TRIANGLE, TRIANGLE[0]], [(0, 1, 2), (3, 2, 1)], "is flat: its vertices lie in one plane (0 mm thick"),
    ([(0, 0, 0), (0.1, 0, 0), (0, 0.1, 0), (0.1, 0.1, 0)], [(0, 1, 2), (1, 3, 2)], "is flat"),
    (TILTED_SQUARE, [(0, 1, 2), (1, 3, 2)], "is flat: its vertices lie in one plane"),
])
def test_an_object_mesh_must_enclose_a_volume(tmp_path, vertices, faces, message):
    """MuJoCo, which renders the object, refuses a mesh of fewer than 4 vertices or without
    volume; the mesh is refused with one line when it is loaded."""
    from recon_cli.objects import load_object

    path = tmp_path / "part.ply"
    path.write_bytes(ply(vertices, faces))
    with pytest.raises(InputError) as info:
        load_object(str(path))
    assert message in info.value.one_line() and info.value.hint, info.value.one_line()
    path.write_bytes(ply([*vertices, (0.05, 0.05, 0.001)], faces))  # 1 mm off the plane
    assert len(load_object(str(path)).vertices) == len(vertices) + 1


def test_a_mesh_mujoco_refuses_is_one_line(gantry):
    from recon_cli.backends.sim.scene import build_scene
    from recon_cli.objects import SceneObject

    flat = SceneObject("sheet", "a sheet", np.array(TILTED_SQUARE), np.array([(0, 1, 2), (1, 3, 2)]), np.eye(4))
    with pytest.raises(InputError, match=r"^the object 'sheet' cannot be simulated: MuJoCo refuses its mesh \(mesh "
                                         r"volume is too small"):
        build_scene(gantry.config, flat)


def test_the_limits_are_what_the_docs_say():
    rows = _table(ROOT / "docs" / "inputs.md", "Meshes")
    assert rows == {
        "file size (checked before reading)": f"{MAX_MESH_FILE_BYTES:,} bytes ({MAX_MESH_FILE_BYTES // 2**20} MiB)",
        "mesh formats": "OBJ, PLY, STL",
        "point cloud formats": "PLY, PCD",
        "vertices of a binary PLY, points of a binary PCD": f"{MAX_VERTICES:,}",
        "triangles of a binary PLY": f"{MAX_TRIANGLES:,}",
        "vertices and faces of an ASCII PLY, points of an ASCII or compressed PCD": f"{MAX_TEXT_VERTICES:,}",
        "vertex, normal, texture coordinate and face lines of an OBJ (each)": f"{MAX_OBJ_LINES:,}",
        "triangles of an STL": f"{MAX_STL_TRIANGLES:,}",
        "ASCII STL file": f"{MAX_STL_TEXT_BYTES:,} bytes ({MAX_STL_TEXT_BYTES // 2**20} MiB)",
        "data of a compressed PCD (compressed and uncompressed)":
            f"{MAX_PCD_UNCOMPRESSED_BYTES:,} bytes ({MAX_PCD_UNCOMPRESSED_BYTES // 2**20} MiB)",
        "extent along any axis (after `--scale`)": f"{MAX_EXTENT_M:g} m",
        "absolute coordinate (after `--scale`)": f"{MAX_COORDINATE_M:g} m",
        "PLY or PCD header": f"{MAX_HEADER_BYTES:,} bytes",
    }
    assert MAX_TEXT_TRIANGLES == MAX_TEXT_VERTICES


# ----------------------------------------------------------------------------- measured, in a process of its own
_REFUSE_ALL = """
import sys
from pathlib import Path
from recon_cli.errors import FileError
from recon_cli.inputs.meshes import read_cloud, read_mesh
for line in Path(sys.argv[1]).read_text().splitlines():
    kind, path = line.split(" ", 1)
    try:
        read_cloud(path) if kind == "cloud" else read_mesh(path, triangles=kind == "mesh")
    except FileError:
        continue
    raise SystemExit(f"{path} was read")
_peak()
"""


def test_every_refusal_in_bounded_time_and_memory(tmp_path):
    listing = []
    for i, (_, filename, data, kind, _) in enumerate(HOSTILE):
        folder = tmp_path / str(i)
        folder.mkdir()
        (folder / filename).write_bytes(data)
        listing.append(f"{kind} {folder / filename}")
    (tmp_path / "list.txt").write_text("\n".join(listing))
    run = run_python(_REFUSE_ALL, [str(tmp_path / "list.txt")], tmp_path)
    assert run.code == 0 and run.err == "" and run.out == "", (run.out, run.err)
    assert run.seconds < 20 and run.peak_gb < 1.0, (run.seconds, run.peak_gb)


_REFUSE_ONE = """
import sys
from recon_cli.errors import FileError
from recon_cli.inputs.meshes import read_mesh
try:
    read_mesh(sys.argv[1], "reconstruction", triangles=False)
except FileError as exc:
    print(exc.one_line())
print("open3d loaded" if "open3d" in sys.modules else "open3d not loaded")
_peak()
"""


def test_a_large_binary_ply_is_refused_without_loading_it(tmp_path):
    """2 million vertices with normals and colours (102 MB), the last one NaN: refused from
    chunks of its records, without Open3D (which would hold them all: 0.5 GB)."""
    n = 2_000_000
    axes = ("x", "y", "z", "nx", "ny", "nz")
    record = np.dtype([(a, "<f8") for a in axes] + [(c, "u1") for c in ("red", "green", "blue")])
    table = np.zeros(n, record)
    table["x"] = np.linspace(0.0, 0.1, n)
    table["nz"] = 1.0
    table["x"][-1] = np.nan
    head = f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\n"
    head += "".join(f"property double {a}\n" for a in axes) + "property uchar red\nproperty uchar green\n"
    head += "property uchar blue\nend_header\n"
    path = tmp_path / "big.ply"
    with path.open("wb") as f:
        f.write(head.encode())
        table.tofile(f)
    del table
    run = run_python(_REFUSE_ONE, [str(path)], tmp_path)
    assert run.out.splitlines() == [f"{path}: reconstruction has 1 vertex with NaN or infinite values (vertex "
                                    f"{n - 1}: (nan, 0, 0)); check the file with a mesh viewer", "open3d not loaded"]
    assert run.peak_gb < 0.25 and run.seconds < 20, (run.peak_gb, run.seconds)


def _one_line(run) -> str:
    lines = [ln for ln in run.err.splitlines() if ln.strip()]
    assert run.code == 1 and len(lines) == 1 and "Traceback" not in run.err, run.err
    assert run.seconds < 20 and run.peak_gb < 1.0, (run.seconds, run.peak_gb)
    return lines[0]


def test_evaluate_refuses_a_hostile_reference_and_reconstruction(tmp_path):
    sphere = o3d.geometry.TriangleMesh.create_sphere(0.05)
    o3d.io.write_point_cloud(str(tmp_path / "cloud.ply"), sphere.sample_points_uniformly(2000))
    o3d.io.write_triangle_mesh(str(tmp_path / "sphere.ply"), sphere)
    (tmp_path / "huge.ply").write_bytes(ply(TRIANGLE, [(0, 1, 2)], nv=10**11))
    (tmp_path / "nan.ply").write_bytes(ply(NAN))
    line = _one_line(run_cli(["evaluate", "cloud.ply", "--reference", "huge.ply", "--out", "out"], tmp_path))
    assert line.startswith("error: huge.ply: reference mesh declares 100000000000 vertices"), line
    line = _one_line(run_cli(["evaluate", "nan.ply", "--reference", "sphere.ply", "--out", "out"], tmp_path))
    assert line.startswith("error: nan.ply: reconstruction has 1 vertex with NaN"), line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("command", ["capture", "autoscan"])
def test_an_object_file_is_refused_before_any_scan(tmp_path, command):
    (tmp_path / "part.stl").write_bytes(binary_stl([TRIANGLE] * 2, declared=4_000_000_000))
    line = _one_line(run_cli([command, "--object", "part.stl", "--out", "out"], tmp_path))
    assert line.startswith("error: part.stl: mesh file is not a valid STL file: as binary STL it declares "
                           "4000000000 triangles"), line
    assert not any((tmp_path / "out").rglob("*"))


def test_capture_refuses_an_object_of_one_triangle(tmp_path):
    (tmp_path / "tri.obj").write_text(OBJ)
    line = _one_line(run_cli(["capture", "--object", "tri.obj", "--out", "out"], tmp_path))
    assert line.startswith("error: mesh tri.obj has only 3 vertices: an object to scan must enclose a volume"), line


# ----------------------------------------------------------------------------- fuzz
_fuzz = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                          HealthCheck.function_scoped_fixture])


def _valid_files() -> dict[str, bytes]:
    box = o3d.geometry.TriangleMesh.create_box(0.1, 0.05, 0.02)
    box.compute_vertex_normals()
    return {"b.ply": ply(TRIANGLE, [(0, 1, 2)]), "a.ply": ply(TRIANGLE, [(0, 1, 2)], "ascii"),
            "b.stl": binary_stl([TRIANGLE, TRIANGLE[::-1]]), "a.obj": (OBJ + "vn 0 0 1\nvt 0 0\n").encode(),
            "a.stl": b"solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 0.1 0 0\nvertex 0 0.1 0\n"
                     b"endloop\nendfacet\nendsolid t\n",
            "a.pcd": pcd(), "b.pcd": pcd(data="binary", body=struct.pack("<9f", *[c for v in TRIANGLE for c in v])),
            "n.pcd": pcd("x y z normal_x normal_y normal_z", "4 4 4 4 4 4", "F F F F F F", "1 1 1 1 1 1",
                         body=b"0 0 0 0 0 1\n0.1 0 0 0 0 1\n0 0.1 0 0 0 1\n")}


VALID = _valid_files()


def _outcome(path: Path) -> None:
    """Each reader either returns what it promises or raises the one-line FileError."""
    for reader in (read_mesh, read_cloud):
        try:
            geometry = reader(path)
        except FileError as exc:
            assert "\n" not in exc.one_line() and str(path) in exc.one_line()
            continue
        points = np.asarray(geometry.vertices if reader is read_mesh else geometry.points)
        assert len(points) and np.isfinite(points).all() and np.abs(points).max() <= MAX_COORDINATE_M
        if reader is read_mesh:
            tris = np.asarray(geometry.triangles)
            assert len(tris) and tris.min() >= 0 and tris.max() < len(points)


@_fuzz
@given(suffix=st.sampled_from([".ply", ".stl", ".obj", ".pcd"]), data=st.binary(max_size=400),
       magic=st.sampled_from([b"", b"ply\n", b"ply\nformat ascii 1.0\n", b"solid ", b"v ", b"VERSION 0.7\n"]))
def test_fuzz_random_bytes(tmp_path, suffix, data, magic):
    path = tmp_path / f"f{suffix}"
    path.write_bytes(magic + data)
    _outcome(path)


@_fuzz
@given(name=st.sampled_from(sorted(VALID)), flips=st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 255)),
                                                            min_size=1, max_size=6),
       head=st.booleans(), cut=st.one_of(st.none(), st.integers(0, 10**6)))
def test_fuzz_mutated_valid_files(tmp_path, name, flips, head, cut):
    data = bytearray(VALID[name])
    for at, value in flips:  # half of the examples flip bytes of the header
        data[at % (min(len(data), 200) if head else len(data))] = value
    if cut is not None:
        data = data[: cut % (len(data) + 1)]
    path = tmp_path / f"f.{name.split('.')[1]}"
    path.write_bytes(bytes(data))
    _outcome(path)
