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
from pathlib import Path
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


#: Open3D's Plotly/Dash viewer, which ``open3d.visualization`` imports with the package
#: (Dash, Flask and IPython: about a second of every process's start); recon never draws with it
OPEN3D_VIEWER = "open3d.visualization.draw_plotly"
#: what ``open3d.visualization`` imports from it by name
OPEN3D_VIEWER_NAMES = ("get_plotly_fig", "draw_plotly", "draw_plotly_server")


def defer_open3d_viewer() -> None:
    """Before Open3D is first imported: put a stand-in in the place of its Plotly/Dash viewer
    module whose functions (and any other name) load the real module on first use. Open3D's
    API stays whole; the import costs only what is used. Nothing happens when Open3D is loaded
    already or not installed."""
    if "open3d" in sys.modules or OPEN3D_VIEWER in sys.modules:
        return
    package = importlib.util.find_spec("open3d")  # a top-level package: found, not imported
    if package is None or not package.submodule_search_locations:
        return
    source = Path(next(iter(package.submodule_search_locations))) / "visualization" / "draw_plotly.py"
    if not source.is_file():
        return
    stand_in = ModuleType(OPEN3D_VIEWER, "Open3D's Plotly viewer, loaded on first use (recon_cli.lazy).")
    real: list[ModuleType] = []

    def viewer() -> ModuleType:
        if not real:
            spec = importlib.util.spec_from_file_location(OPEN3D_VIEWER, source)
            assert spec is not None and spec.loader is not None
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            real.append(module)
            sys.modules[OPEN3D_VIEWER] = module
        return real[0]

    def forward(name: str):
        def call(*args, **kwargs):
            return getattr(viewer(), name)(*args, **kwargs)

        call.__name__ = call.__qualname__ = name
        return call

    for name in OPEN3D_VIEWER_NAMES:
        setattr(stand_in, name, forward(name))

    def attribute(name: str):
        if name.startswith("__"):  # the import system's questions (__path__: not a package)
            raise AttributeError(name)
        return getattr(viewer(), name)

    setattr(stand_in, "__getattr__", attribute)  # noqa: B010 (a module-level __getattr__, PEP 562)
    sys.modules[OPEN3D_VIEWER] = stand_in
