"""Point-cloud rendering: z-buffer splatting in torch (CPU or CUDA) of site-local points.

Names are imported on first use (PEP 562): ``siteline.render.settings`` (the persisted knobs) and the
commands that only read the catalog do not pull in torch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from siteline.lazy import lazy_names

if TYPE_CHECKING:  # mypy and editors see the real signatures; nothing is imported at run time
    from siteline.render.georef import render_georeferenced as render_georeferenced
    from siteline.render.georef import to_site_local_f32 as to_site_local_f32
    from siteline.render.outputs import write_render as write_render
    from siteline.render.settings import RenderSettings as RenderSettings
    from siteline.render.splats import disk_offsets as disk_offsets
    from siteline.render.splats import local_spacing as local_spacing
    from siteline.render.zbuffer import RenderResult as RenderResult
    from siteline.render.zbuffer import render_points as render_points

_WHERE = {
    "RenderResult": "siteline.render.zbuffer",
    "RenderSettings": "siteline.render.settings",
    "disk_offsets": "siteline.render.splats",
    "local_spacing": "siteline.render.splats",
    "render_georeferenced": "siteline.render.georef",
    "render_points": "siteline.render.zbuffer",
    "to_site_local_f32": "siteline.render.georef",
    "write_render": "siteline.render.outputs",
}

__all__ = sorted(_WHERE)


__getattr__ = lazy_names(__name__, _WHERE)
