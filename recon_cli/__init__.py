"""recon: robot-assisted reconstruction of objects with a robot-held depth camera."""

__version__ = "0.1.0"
