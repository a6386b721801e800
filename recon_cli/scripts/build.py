"""From validated script elements to typed commands, for both dialects.

Units are converted here (degrees to radians unless ``unit="rad"``; the thesis dialect is
in radians), and what the XSD cannot say is checked with the element's source line:
angles that cannot be meant in their unit, finite numbers, positive sizes, non-zero
quaternions, output paths inside the output folder, the size of rings.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from recon_cli.config import DEFAULTS as D
from recon_cli.config import SensorConfig
from recon_cli.errors import InputError, ScriptError
from recon_cli.expansion.sandbox import LIMITS
from recon_cli.geometry.view import Frame, View
from recon_cli.planning.options import PLANNERS
from recon_cli.robot.cell_file import load_cell, shipped_cells
from recon_cli.scripts import commands as C


def _cell_safety(kind: str) -> float | None:
    """The default safety distance of a shipped cell (a cell file's is read when the script
    runs, by the script's reading rules)."""
    return load_cell(kind).safety_distance if kind in shipped_cells() else None


def as_bool(text: str | None, default: bool = False) -> bool:
    return default if text is None else text.strip() in ("true", "1")


def _numbers(text: str | None) -> tuple[float, ...]:
    """The numbers of an attribute the schema requires."""
    if text is None:
        raise ValueError("a required attribute is missing: the schema admits no such script")
    return tuple(float(v) for v in text.split())


def _vec3(text: str | None) -> tuple[float, float, float]:
    """A three-number attribute the schema requires (vec3, rgb)."""
    x, y, z = _numbers(text)
    return x, y, z


def _vec(text: str | None) -> tuple[float, float, float] | None:
    """An optional three-number attribute (vec3)."""
    return None if text is None else _vec3(text)


def _angle(value: str | None, unit: str, default: float = 0.0) -> float:
    v = default if value is None else float(value)
    return math.radians(v) if unit == "deg" else v


def _finite(values, src: C.Source, what: str) -> None:
    if not all(math.isfinite(v) for v in values):
        raise ScriptError(f"{src}: {what} has a non-finite number", hint="use finite numbers")


# largest magnitudes of written angles (degrees; the same in radians for radian fields):
# a polar angle beyond half a turn, or an azimuth/roll beyond two turns, is a unit mistake
ANGLE_BOUNDS_DEG = {"theta": 180.0, "phi": 720.0, "alpha": 720.0, "phi_start": 720.0, "phi_step": 360.0}


def check_angles(src: C.Source, tag: str, unit: str, values: dict[str, str | float | None]) -> None:
    """Refuse written angles that cannot be meant in ``unit`` (e.g. degrees in a radians field)."""
    for name, raw in values.items():
        if raw is None:
            continue
        v = float(raw)
        bound = ANGLE_BOUNDS_DEG[name]
        if unit == "rad":
            bound = math.radians(bound)
        if not math.isfinite(v) or abs(v) > bound + 1e-9:
            if unit == "rad":
                hint = (f"this field takes radians; if you meant {v:g} degrees write {math.radians(v):.4f}"
                        + (' or unit="deg"' if tag != "coordinates" else ""))
                text = f"{name} {v:g} rad is beyond +-{bound:.4f} rad (+-{ANGLE_BOUNDS_DEG[name]:g} deg)"
            else:
                hint = "write the angle in degrees within the bound"
                text = f"{name} {v:g} deg is beyond +-{bound:g} deg"
            raise ScriptError(f"{src}: <{tag}> {text}", hint=hint)


def _view(el, src: C.Source, theta: float, phi: float) -> View:
    unit = el.get("unit", "deg")
    focus = _vec3(el.get("focus"))
    radius = float(el.get("radius"))
    check_angles(src, el.tag, unit, {"alpha": el.get("alpha")})
    alpha = _angle(el.get("alpha"), unit)
    _finite((*focus, radius, theta, phi, alpha), src, f"<{el.tag}>")
    return View(focus, radius, theta, phi, alpha, Frame(el.get("frame", "world")))


def relative_output(name: str, src: C.Source, what: str) -> str:
    """An output path of a script: relative, and inside the output folder."""
    p = Path(name)
    depth = 0
    for part in p.parts:
        depth += -1 if part == ".." else (0 if part == "." else 1)
        if depth < 0:
            break
    if p.is_absolute() or depth < 0 or name.startswith("~"):
        raise ScriptError(f"{src}: {what} {name!r} is outside the output folder",
                          hint="scripts write only into the output folder (--out); give a relative path "
                               "such as drill.ply")
    return name


def build_recon(el, src: C.Source) -> list[C.Command]:
    tag, a = el.tag, el.attrib
    if tag == "cell":
        resolution = float(a.get("resolution", D.sensor.resolution))
        try:
            SensorConfig(resolution=resolution)
        except InputError as exc:
            raise ScriptError(f"{src}: <cell resolution> {exc.message}", hint=exc.hint) from None
        return [C.SetCell(src, a.get("kind", D.cell.kind.value),
                          float(a["safety_distance"]) if "safety_distance" in a
                          else _cell_safety(a.get("kind", D.cell.kind.value)), a.get("backend", "sim"),
                          resolution, as_bool(a.get("noise"), D.sensor.noise), a.get("realism", D.realism.name))]
    if tag == "object":
        return [C.SetObject(src, a["name"], float(a.get("scale", D.scene.object_scale)))]
    if tag == "box":
        center, size = _vec(a.get("center")), _vec(a.get("size"))
        if (center is None) != (size is None):
            raise ScriptError(f"{src}: <box> needs both center and size, or neither (box around the object)",
                              hint='e.g. <box center="0 0 0.83" size="0.3 0.3 0.3"/>')
        if size is not None and min(size) <= 0:
            raise ScriptError(f"{src}: <box> sizes must be positive", hint="give edge lengths in metres")
        return [C.SetBox(src, center, size, a.get("frame", "world"), float(a.get("margin", D.scene.box_margin)))]
    if tag == "planner":

        name = a.get("name", D.planner.planner)
        if name not in PLANNERS:
            raise ScriptError(f"{src}: unknown planner {name!r}", hint="one of " + ", ".join(PLANNERS))
        return [C.SetPlanner(src, name, float(a.get("time", D.planner.time_limit)),
                             float(a.get("velocity_scale", D.planner.velocity_scale)),
                             float(a.get("acceleration_scale", D.planner.acceleration_scale)))]
    if tag == "home":
        return [C.MoveHome(src)]
    if tag == "move":
        unit = a.get("unit", "deg")
        check_angles(src, tag, unit, {"theta": a["theta"], "phi": a["phi"]})
        return [C.MoveView(src, _view(el, src, _angle(a["theta"], unit), _angle(a["phi"], unit)))]
    if tag == "pose":
        q = _numbers(a["orientation"])
        if np.linalg.norm(q) < 1e-9:
            raise ScriptError(f"{src}: <pose> orientation quaternion is zero", hint="give x y z w of a rotation")
        return [C.MovePose(src, _vec3(a["position"]), tuple(np.asarray(q) / np.linalg.norm(q)),
                           a.get("frame", "world"))]
    if tag == "joints":
        unit = a.get("unit", "rad")
        values = _numbers(a["values"])
        _finite(values, src, "<joints>")
        return [C.MoveJoints(src, tuple(values), unit)]
    if tag == "ring":
        unit = a.get("unit", "deg")
        check_angles(src, tag, unit, {"theta": a["theta"], "phi_start": a.get("phi_start"),
                                      "phi_step": a.get("phi_step")})
        count = int(a["count"])
        if count > LIMITS.max_ring_count:
            raise ScriptError(f"{src}: <ring> count {count} exceeds the limit of {LIMITS.max_ring_count} views",
                              hint="use several rings or fewer views")
        start = float(a.get("phi_start", 0.0))
        full_turn = 360.0 if unit == "deg" else 2 * math.pi
        step = float(a["phi_step"]) if a.get("phi_step") is not None else full_turn / count
        theta = _angle(a["theta"], unit)
        out: list[C.Command] = []
        for k in range(count):
            out.append(C.MoveView(src, _view(el, src, theta, _angle(str(start + k * step), unit))))
            if as_bool(a.get("scan"), True):
                out.append(C.Scan(src))
        return out
    if tag == "scan":
        return [C.Scan(src, a.get("name"))]
    if tag == "wait":
        return [C.Wait(src, float(a["seconds"]))]
    if tag == "turn_over":
        return [C.TurnOver(src, None if a.get("seed") is None else int(a["seed"]))]
    if tag == "register":
        return [C.Register(src, as_bool(a.get("local"), D.registration.local),
                           as_bool(a.get("board"), D.registration.use_board),
                           a.get("loop_closures", D.registration.multiway.loop_closure_init))]
    if tag == "reconstruct":
        surface = D.registration.surface
        return [C.Reconstruct(src, float(a.get("voxel", surface.voxel)), int(a.get("depth", surface.poisson_depth)),
                              float(a.get("trim", surface.density_quantile)))]
    if tag == "export":
        if not a.get("cloud") and not a.get("mesh"):
            raise ScriptError(f"{src}: <export> needs cloud=... and/or mesh=...",
                              hint='e.g. <export mesh="drill.ply"/>')
        return [C.Export(src, *(None if a.get(k) is None else relative_output(a[k], src, f"<export {k}>")
                                for k in ("cloud", "mesh")))]
    if tag == "evaluate":
        return [C.Evaluate(src, a.get("reference", "ground_truth"), float(a.get("tolerance", C.Evaluate.tolerance)),
                           a.get("align", "none"))]
    raise ScriptError(f"{src}: unexpected element <{tag}>", hint="see schemas/recon_script.xsd")


def _quat_matrix(xyzw: tuple[float, ...]) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    q = np.asarray(xyzw, dtype=float)
    if np.linalg.norm(q) < 1e-9:
        raise ValueError("zero quaternion")
    return Rotation.from_quat(q / np.linalg.norm(q)).as_matrix()


def build_thesis(el, src: C.Source) -> list[C.Command]:
    tag, a = el.tag, el.attrib
    if tag == "move":
        ref = a.get("reference", "world")
        if ref not in ("world", "marker"):
            raise ScriptError(f"{src}: move reference {ref!r} is not a frame recon knows",
                              hint="use reference=\"world\" or \"marker\"")
        children = {c.tag: c for c in el if isinstance(c.tag, str)}
        if "position" in children:
            q = _numbers(children["orientation"].get("xyzw"))
            if np.linalg.norm(q) < 1e-9:
                raise ScriptError(f"{src}: orientation quaternion is zero", hint="give x y z w of a rotation")
            return [C.MovePose(src, _vec3(children["position"].get("xyz")), tuple(np.asarray(q) / np.linalg.norm(q)),
                               ref)]
        sphere, co = children["sphere"], children["coordinates"]
        focus, radius = _vec3(sphere.get("xyz")), float(sphere.get("radius"))
        check_angles(src, "coordinates", "rad", {k: co.get(k) for k in ("theta", "phi", "alpha")})
        theta, phi, alpha = float(co.get("theta")), float(co.get("phi")), float(co.get("alpha", 0.0))
        _finite((*focus, radius, theta, phi, alpha), src, "<move>")
        if radius <= 0:
            raise ScriptError(f"{src}: sphere radius must be positive", hint="the camera distance in metres")
        return [C.MoveView(src, View(focus, radius, theta, phi, alpha, Frame(ref)))]
    if tag == "scan":
        return [C.FragmentScan(src, a["name"], a.get("path_color", ""), a.get("path_depth", ""),
                               a.get("path_pose", ""))]
    if tag == "load":
        return [C.LoadFragment(src, a["name"], a.get("type", "rgbd_image"), a.get("path_color", "/"),
                               a.get("path_depth", "/"), a.get("path_point_cloud", "/"))]
    if tag == "register":
        return [C.PairRegister(src, a["source"], a["target"], a.get("method", "point_to_plane_icp"),
                               float(a["threshold"]))]
    if tag == "multiway":
        return [C.Multiway(src, a.get("method", "point_to_plane_icp"), float(a["threshold"]))]
    if tag == "add":
        return [C.AddFragment(src, a["fragment"], a["target"])]
    if tag == "downsample":
        return [C.Downsample(src, a["fragment"], float(a["voxel_size"]))]
    if tag == "transform":
        children = {c.tag: c for c in el if isinstance(c.tag, str)}
        T: np.ndarray = np.eye(4)
        try:
            T[:3, :3] = _quat_matrix(_numbers(children["rotation"].get("xyzw")))
        except ValueError:
            raise ScriptError(f"{src}: rotation quaternion is zero", hint="give x y z w of a rotation") from None
        T[:3, 3] = _vec3(children["translation"].get("xyz"))
        if not as_bool(a.get("forward"), True):
            T = np.linalg.inv(T)
        return [C.TransformFragment(src, a["fragment"], tuple(map(tuple, T)))]
    if tag == "export":
        path = a["path"]  # the thesis system wrote absolute paths: recon writes them by file name into --out
        if not Path(path).is_absolute():
            relative_output(path, src, "export")
        return [C.ExportFragment(src, a["fragment"], a.get("type", "mesh"), path)]
    if tag == "wait":
        return [C.Wait(src, float(a["duration"]))]
    if tag == "delete":
        return [C.DeleteFragment(src, a["fragment"])]
    if tag in ("show", "hide"):
        return [C.Display(src, tag, a["fragment"])]
    if tag == "color":
        return [C.Display(src, "color", a["fragment"], _vec3(a["rgb"]))]
    raise ScriptError(f"{src}: unexpected element <{tag}>", hint="see schemas/thesis_script.xsd")
