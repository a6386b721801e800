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
from recon_cli.inputs.meshes import (
    MAX_COORDINATE_M,
    MAX_EXTENT_M,
    MAX_HEADER_BYTES,
    MAX_MESH_FILE_BYTES,
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


NAN = [(float("nan"), 0.0, 0.0), *TRIANGLE[1:]]
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
    ("obj-index-out-of-range", "a.obj", OBJ.replace("f 1 2 3", "f 1 2 9").encode(), "mesh", "has no triangles"),
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
]


def _read(kind: str, path: Path):
    return read_mesh(path) if kind == "mesh" else read_cloud(path)


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
    path.write_bytes(ply([(0, 0, 0), (300.0, 0, 0), (0, 100.0, 0)], [(0, 1, 2)]))  # millimetres
    with pytest.raises(FileError, match=r"is 300 m across.*; pass a scale, e.g. --scale 0.001"):
        load_object(str(path))
    assert load_object(str(path), scale=0.001).extent == pytest.approx([0.3, 0.1, 0.0])
    with pytest.raises(InputError, match="too large for the board"):  # within the reader's limits, not the board's
        load_object(str(path), scale=0.01)


def test_the_limits_are_what_the_docs_say():
    rows = _table(ROOT / "docs" / "inputs.md", "Meshes")
    assert rows == {
        "file size (checked before reading)": f"{MAX_MESH_FILE_BYTES:,} bytes ({MAX_MESH_FILE_BYTES // 2**20} MiB)",
        "mesh formats": "OBJ, PLY, STL",
        "point cloud formats": "PLY, PCD",
        "vertices of a mesh, points of a cloud": f"{MAX_VERTICES:,}",
        "triangles of a mesh": f"{MAX_TRIANGLES:,}",
        "extent along any axis (after `--scale`)": f"{MAX_EXTENT_M:g} m",
        "absolute coordinate (after `--scale`)": f"{MAX_COORDINATE_M:g} m",
        "PLY or PCD header": f"{MAX_HEADER_BYTES:,} bytes",
    }


# ----------------------------------------------------------------------------- measured, in a process of its own
_REFUSE_ALL = """
import sys
from pathlib import Path
from recon_cli.errors import FileError
from recon_cli.inputs.meshes import read_cloud, read_mesh
for line in Path(sys.argv[1]).read_text().splitlines():
    kind, path = line.split(" ", 1)
    try:
        read_mesh(path) if kind == "mesh" else read_cloud(path)
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
