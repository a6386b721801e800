"""What a report page shows and how large its images are (light: no Open3D, no matplotlib)."""

from __future__ import annotations

from dataclasses import dataclass

#: the directions the mesh is rendered from: name -> (azimuth, elevation) [deg] of the camera
#: around the mesh's centre (azimuth from +x toward +y, elevation above the x-y plane)
MESH_VIEWS: dict[str, tuple[float, float]] = {
    "front": (-90.0, 10.0),  # from -y
    "side": (0.0, 10.0),  # from +x
    "top": (-90.0, 89.0),  # from above
    "oblique": (-45.0, 35.0),
}


@dataclass(frozen=True)
class ReportOptions:
    render: bool = True  # render the mesh (else the page links the PLY files only)
    image_width: int = 480  # [px] of each mesh image (height 3/4 of it)
    views: tuple[str, ...] = tuple(MESH_VIEWS)  # which of MESH_VIEWS, in this order
    thumbnail_width: int = 200  # [px] of the scans' colour thumbnails
