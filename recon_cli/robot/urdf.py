"""Required parts of the expanded URDF: a child element or an attribute that the cell's
xacro always writes. A missing one is a broken robot description (an internal error), named
by tag and attribute."""

from __future__ import annotations

from lxml import etree


def child(element: etree._Element, path: str) -> etree._Element:
    """The first element at ``path`` under ``element``."""
    found = element.find(path)
    if found is None:
        raise ValueError(f"URDF <{element.tag!s} name={element.get('name')!r}> has no <{path}>")
    return found


def attribute(element: etree._Element, name: str) -> str:
    """The value of attribute ``name`` of ``element``."""
    value = element.get(name)
    if value is None:
        raise ValueError(f"URDF <{element.tag!s}> has no attribute {name!r}")
    return value
