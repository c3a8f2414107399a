"""Point-cloud rendering: z-buffer splatting in torch (CPU or CUDA) of site-local points.

Names are imported on first use (PEP 562): ``siteline.render.settings`` (the persisted knobs) and the
commands that only read the catalog do not pull in torch.
"""

from __future__ import annotations

from siteline.lazy import lazy_names

_WHERE = {
    "RenderResult": "siteline.render.zbuffer",
    "RenderSettings": "siteline.render.settings",
    "disk_offsets": "siteline.render.zbuffer",
    "render_georeferenced": "siteline.render.georef",
    "render_points": "siteline.render.zbuffer",
    "to_site_local_f32": "siteline.render.georef",
    "write_render": "siteline.render.outputs",
}

__all__ = sorted(_WHERE)


__getattr__ = lazy_names(__name__, _WHERE)
