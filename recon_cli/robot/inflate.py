"""Collision primitives of a description inflated by the safety distance (thesis 2.2.4).

recon's own xacro descriptions inflate every collision shape themselves (xacro argument
``sd``, robot/parts/shapes.xacro). A user's URDF, or a xacro that takes no such argument
(its cell file names no ``description.settings.safety_distance``), gets the same inflation
here, by the same rule: boxes grow by sd on every face (edges + 2 sd), cylinders get radius
+ sd and length + 2 sd, spheres radius + sd; a capsule written as a ``X_capsule`` cylinder
with ``X_capsule_end_a/b`` spheres gets radius + sd on all three pieces and keeps its segment
(the end spheres already cover the ends). Meshes are left to :mod:`.capsule_fit`, which
inflates the capsules it fits. Visuals keep their real sizes.
"""

from __future__ import annotations

import functools

from lxml import etree


def _grow(values: str, by: float) -> str:
    return " ".join(repr(float(v) + by) for v in values.split())


@functools.lru_cache(maxsize=16)
def inflate_primitives(urdf: str, safety_distance: float) -> str:
    """URDF text with every collision primitive inflated by ``safety_distance`` [m]."""
    sd = float(safety_distance)
    if sd == 0.0:
        return urdf
    root = etree.fromstring(urdf.encode())
    for collision in root.iter("collision"):
        geometry = collision.find("geometry")
        if geometry is None or len(geometry) == 0:
            continue
        shape = geometry[0]
        name = collision.get("name") or ""
        if shape.tag == "box" and shape.get("size") is not None:
            shape.set("size", _grow(str(shape.get("size")), 2.0 * sd))
        elif shape.tag == "sphere" and shape.get("radius") is not None:
            shape.set("radius", _grow(str(shape.get("radius")), sd))
        elif shape.tag == "cylinder" and shape.get("radius") is not None:
            shape.set("radius", _grow(str(shape.get("radius")), sd))
            if not name.endswith("_capsule") and shape.get("length") is not None:
                shape.set("length", _grow(str(shape.get("length")), 2.0 * sd))
    text: str = etree.tostring(root, encoding="unicode")
    return text
