"""Validation of persisted parameter specs (frozen dataclasses with a JSON round trip): a document read
back from JSON, a flow parameter or the catalog is checked field by field before it becomes a spec."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import MISSING, fields
from typing import Any, TypeVar

from siteline.errors import SitelineError

T = TypeVar("T")


def parse_spec(cls: type[T], doc: Any, what: str, error: type[SitelineError]) -> T:
    """The dataclass ``cls`` made from ``doc``: :class:`error` names ``what`` and the fix when it is not
    an object, holds unknown keys, or a value has the wrong type for its field (judged by the field's
    default: bool, int, float, str; a list where the default is a tuple becomes a tuple). Values are
    then checked by ``cls`` itself."""
    if not isinstance(doc, Mapping):
        raise error(f"{what} must be a JSON object, got {type(doc).__name__}.")
    known = {f.name: f for f in fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(doc) - set(known))
    if unknown:
        raise error(f"{what}: unknown parameter(s) {unknown}; known: {sorted(known)}.")
    for name, value in doc.items():
        default = known[name].default
        if default is MISSING or default is None:
            continue
        if isinstance(default, bool):
            ok = isinstance(value, bool)
        elif isinstance(default, int):
            ok = isinstance(value, int) and not isinstance(value, bool)
        elif isinstance(default, float):
            ok = isinstance(value, int | float) and not isinstance(value, bool)
        elif isinstance(default, str):
            ok = isinstance(value, str)
        else:
            ok = True
        if not ok:
            raise error(f"{what}: {name}={value!r} must be a {type(default).__name__}.")
    kwargs = {
        k: tuple(v) if isinstance(known[k].default, tuple) and isinstance(v, list) else v
        for k, v in doc.items()
    }
    return cls(**kwargs)
