"""Heavy third-party libraries, imported when first used.

``pin = lazy_module("pinocchio")`` at the top of a module names its dependency where every
import stands, yet loads the library only when one of its attributes is first read: a
command's ``--help``, shell completion and the commands that never compute kinematics, render
or detect a board start without loading pinocchio, MuJoCo, FCL or OpenCV. Lighter libraries
(numpy, typer, lxml, yaml) and recon's own modules are imported as usual.

The type checker sees the plain import, so that the library's classes can annotate::

    if TYPE_CHECKING:
        import pinocchio as pin
    else:
        pin = lazy_module("pinocchio")
"""

from __future__ import annotations

import importlib.util
import sys
from types import ModuleType


def lazy_module(name: str) -> ModuleType:
    """The module ``name``, loaded on first attribute access (at once when it is loaded
    already); a library that is not installed fails at that first use, as a plain import
    would have failed."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.find_spec(name)
    if spec is None or spec.loader is None:
        raise ModuleNotFoundError(f"No module named {name!r}", name=name)
    loader = importlib.util.LazyLoader(spec.loader)
    spec.loader = loader
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    loader.exec_module(module)
    return module
