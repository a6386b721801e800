"""recon: robot-assisted reconstruction of objects with a robot-held depth camera."""

from recon_cli.lazy import defer_open3d_viewer

defer_open3d_viewer()  # before anything imports Open3D

__version__ = "0.1.0"

#: the distribution's name on the package index ("recon" and "recon-cli" are other projects)
DISTRIBUTION = "recon-scan"


def install_hint(extra: str) -> str:
    """The command that installs one of recon's optional extras (quoted for every shell)."""
    return f"pip install '{DISTRIBUTION}[{extra}]'"
