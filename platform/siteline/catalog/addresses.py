"""Store addresses as the catalog records them: relative to the data-store root or to SITELINE_HOME.

A tile store, a label set, a release folder is recorded as ``store:tiles/scene-3-...zarr`` or
``home:releases/site/1.0.0``, never as an absolute path, so a home copied or restored elsewhere
(``cp -a home home2``) reads and writes its own stores, not the original's. The roots come from the
settings the catalog was opened with (:class:`Roots`) and are in force for each of its transactions;
an address outside both roots (a mission read in place from the user's folder) is kept absolute.
Catalog rows written before this rule (absolute addresses) still read as they were written.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path

import sqlalchemy as sa

from siteline.errors import CatalogError
from siteline.stores.base import join

STORE = "store:"
HOME = "home:"


@dataclass(frozen=True)
class Roots:
    """The data-store root (a folder or an fsspec URL) and the home folder, as absolute addresses."""

    store: str
    home: str

    @classmethod
    def of(cls, store_url: str, home: Path) -> Roots:
        return cls(store_url.rstrip("/"), str(Path(home).resolve()).rstrip("/"))


_roots: ContextVar[Roots | None] = ContextVar("siteline_catalog_roots", default=None)


@contextmanager
def rooted(roots: Roots | None) -> Iterator[None]:
    """Addresses are recorded and read against ``roots`` for the block (None: recorded as given)."""
    token = _roots.set(roots)
    try:
        yield
    finally:
        _roots.reset(token)


def _under(address: str, root: str) -> str | None:
    if address == root:
        return ""
    return address[len(root) + 1 :] if address.startswith(root + "/") else None


def to_record(address: str) -> str:
    """``address`` as the catalog records it: relative to the store root (tried first: it may lie in
    the home) or the home, or unchanged when it lies under neither or no roots are in force."""
    roots = _roots.get()
    if roots is None or address.startswith((STORE, HOME)):
        return address
    for prefix, root in ((STORE, roots.store), (HOME, roots.home)):
        rest = _under(address, root)
        if rest is not None:
            return prefix + rest
    return address


def from_record(value: str) -> str:
    """The absolute address of a recorded ``value`` under the roots in force; an absolute value is
    returned as it is. :class:`CatalogError` when a relative value is read with no roots."""
    if not value.startswith((STORE, HOME)):
        return value
    roots = _roots.get()
    if roots is None:
        raise CatalogError(
            f"the catalog records {value!r} relative to a SITELINE_HOME or store, but it was opened "
            "from a bare database URL: open it from the settings (open_catalog(load_settings()))."
        )
    root, rest = (
        (roots.store, value[len(STORE) :]) if value.startswith(STORE) else (roots.home, value[len(HOME) :])
    )
    return join(root, rest) if rest else root


class StoreAddresses(sa.types.TypeDecorator):
    """A JSON column holding a mapping of names to store addresses (a render's files), each recorded
    relative to the roots in force."""

    impl = sa.JSON
    cache_ok = True

    def process_bind_param(self, value: dict[str, str] | None, dialect: sa.Dialect) -> dict[str, str] | None:
        return None if value is None else {k: to_record(str(v)) for k, v in value.items()}

    def process_result_value(
        self, value: dict[str, str] | None, dialect: sa.Dialect
    ) -> dict[str, str] | None:
        return None if value is None else {k: from_record(v) for k, v in value.items()}


class StoreAddress(sa.types.TypeDecorator):
    """A text column holding a store address, recorded relative to the roots in force."""

    impl = sa.Text
    cache_ok = True

    def process_bind_param(self, value: str | None, dialect: sa.Dialect) -> str | None:
        return None if value is None else to_record(str(value))

    def process_result_value(self, value: str | None, dialect: sa.Dialect) -> str | None:
        return None if value is None else from_record(value)


def current_roots() -> Roots | None:
    """The roots in force (None outside a catalog opened from settings or a migration given them)."""
    return _roots.get()
