"""A site as the catalog hands it out."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import Protocol

from siteline.records.params.release import ReleaseKnobs
from siteline.site.spec import SiteSpec


class SiteKey(Protocol):
    """Anything that names a site by its catalog id (a :class:`SiteView`)."""

    @property
    def id(self) -> int: ...


@dataclass(frozen=True)
class SiteView:
    """A site: its catalog id, its spec (name, CRS, origin, fence, taxonomy, tile size, version), its
    stored release settings (a layer of knobs over the defaults, siteline.release.knobs) and when it was created (UTC)."""

    id: int
    spec: SiteSpec
    release_settings: ReleaseKnobs
    created_at: datetime | None = None

    @property
    def name(self) -> str:
        return self.spec.name
