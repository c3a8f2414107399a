"""Point-cloud rendering: z-buffer splatting in torch (CPU or CUDA) of site-local points."""

from siteline.render.georef import render_georeferenced, to_site_local_f32
from siteline.render.outputs import write_render
from siteline.render.settings import RenderSettings
from siteline.render.zbuffer import RenderResult, disk_offsets, render_points

__all__ = [
    "RenderResult",
    "RenderSettings",
    "disk_offsets",
    "render_georeferenced",
    "render_points",
    "to_site_local_f32",
    "write_render",
]
