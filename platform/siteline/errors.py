"""Every error siteline raises on purpose.

Each leaf also subclasses the builtin a caller would expect (``ValueError`` for bad input,
``FileNotFoundError`` for a missing file, ...), and its message names the file, site, scene or value
at fault and, where there is one, the fix.
"""

from __future__ import annotations


class SitelineError(Exception):
    """Root of every error siteline raises on purpose."""


class ConfigError(SitelineError, ValueError):
    """A setting (environment variable, config file) is missing or malformed."""


class SchemaError(SitelineError, ValueError):
    """A JSON document does not satisfy its schema in ``schema/``."""


class CRSError(SitelineError, ValueError):
    """A coordinate reference system is unknown, malformed or cannot be transformed."""


class GeometryError(SitelineError, ValueError):
    """A geometric input (origin, fence polygon, bounds, camera) is invalid."""


class SiteError(SitelineError, ValueError):
    """A site is unknown, duplicated or inconsistent."""


class SiteNotFoundError(SiteError, LookupError):
    """No site of that name in the catalog."""


class CatalogError(SitelineError, RuntimeError):
    """The catalog database cannot be used as it is."""


class RevisionMismatchError(CatalogError):
    """The catalog database is at another Alembic revision than this siteline expects."""


class ImmutableError(SitelineError, PermissionError):
    """Something published (a release) would be modified."""


class NotFoundError(SitelineError, LookupError):
    """A catalog record (scene, mission, release, ...) does not exist."""


class RenderError(SitelineError, ValueError):
    """Render inputs are inconsistent (shapes, dtypes, device)."""


class CameraError(SitelineError, ValueError):
    """A camera is malformed (non-finite values, non-orthonormal rotation, bad size)."""


class ViewsError(SitelineError, ValueError):
    """Synthetic views cannot be generated from the given inputs."""


class PointCloudError(SitelineError, ValueError):
    """A LAS/LAZ file or point array is unreadable or holds invalid points."""


class MissionError(SitelineError, ValueError):
    """A mission folder is empty, malformed or unsafe."""


class PhotoError(SitelineError, ValueError):
    """A photo carries no usable metadata."""


class RegistrationError(SitelineError, ValueError):
    """A scene cannot be registered (georegistration or alignment failed)."""


class WorkerError(SitelineError, RuntimeError):
    """A worker process died under a command (killed, or out of memory): nothing was stored; the
    command may be run again. The CLI exits 1 (a failure, not a bad request)."""


class TileError(SitelineError, RuntimeError):
    """A tile store is missing, partial or inconsistent."""


class LabelError(SitelineError, ValueError):
    """Label values or label parameters are out of range (a class code, a mask value, a backend)."""


class SynthError(SitelineError, ValueError):
    """A synthetic-site parameter is out of range."""


class PairError(SitelineError, ValueError):
    """A pair cannot be processed (unknown, untiled scenes, no cameras to derive views from)."""


class ReleaseError(SitelineError, ValueError):
    """A release cannot be built, published or verified."""


class StoreError(SitelineError, OSError):
    """The data store (a local folder or an fsspec URL) cannot be read or written as asked; often
    transient on a remote store, so orchestration retries it."""


class LabelSetError(LabelError):
    """A label-set version is unknown, or a corrected labels file cannot be imported as one."""
