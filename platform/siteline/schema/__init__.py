"""JSON documents: the JSON Schemas of siteline's contracts (the ``*.schema.json`` files beside this
module, shipped inside the package; the repository's top-level ``schema/`` links here), the validation
of documents against them, :data:`JSON`, the type of a JSON value, and the checked reads of one."""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeAlias, TypeVar, cast

from siteline.errors import SchemaError

if TYPE_CHECKING:
    from jsonschema.protocols import Validator

SCHEMA_DIR = Path(__file__).resolve().parent

JSON: TypeAlias = str | int | float | bool | None | Sequence["JSON"] | Mapping[str, "JSON"]
"""A JSON value (as zarr-python 3 types it; read-only containers, so a ``list[float]`` is one): a
record's JSON form, a file read or written as JSON, a catalog JSON column, a store's attributes, a
command's ``--json`` record. A document of fixed shape has a ``TypedDict`` (siteline.records); what
crosses between stages is a typed record, not one of these. A value read from one is narrowed by the
checked reads below (``json_object``, ``json_list``, ``json_number``, ``json_float``, ``json_numbers``,
``json_int``, ``json_bool``, ``json_str``, ``json_or_none``), each a TypeError naming the key."""


def json_object(value: object, what: str = "value") -> Mapping[str, JSON]:
    """``value`` as a JSON object; TypeError naming ``what`` where it is not one."""
    if not isinstance(value, Mapping):
        raise TypeError(f"{what} is a {type(value).__name__}, not a JSON object")
    return value


def json_list(value: object, what: str = "value") -> Sequence[JSON]:
    """``value`` as a JSON array; TypeError naming ``what`` where it is not one."""
    if isinstance(value, str) or not isinstance(value, Sequence):
        raise TypeError(f"{what} is a {type(value).__name__}, not a JSON array")
    return value


def json_number(value: object, what: str = "value") -> float:
    """``value`` as a number (an int stays an int, as JSON wrote it); TypeError naming ``what`` where
    it is not one."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise TypeError(f"{what} is a {type(value).__name__}, not a number")
    return value


def json_float(value: object, what: str = "value") -> float:
    """``value`` as a float (:func:`json_number`, an int made a float); TypeError naming ``what``."""
    return float(json_number(value, what))


def json_numbers(value: object, what: str = "value") -> list[float]:
    """``value`` as a list of numbers (:func:`json_number` each); TypeError naming ``what`` where not."""
    return [json_number(v, what) for v in json_list(value, what)]


def json_int(value: object, what: str = "value") -> int:
    """``value`` as an int (a JSON number without a fraction); TypeError naming ``what`` where not."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError(f"{what} is a {type(value).__name__}, not an integer")
    return value


def json_bool(value: object, what: str = "value") -> bool:
    """``value`` as a bool; TypeError naming ``what`` where it is not one."""
    if not isinstance(value, bool):
        raise TypeError(f"{what} is a {type(value).__name__}, not true or false")
    return value


def json_str(value: object, what: str = "value") -> str:
    """``value`` as a str; TypeError naming ``what`` where it is not one."""
    if not isinstance(value, str):
        raise TypeError(f"{what} is a {type(value).__name__}, not a string")
    return value


def schema_path(name: str) -> Path:
    """Path of ``schema/<name>`` (e.g. ``site.schema.json``)."""
    path = SCHEMA_DIR / name
    if not path.is_file():
        raise SchemaError(
            f"schema file {path} is missing: the siteline installation is incomplete (reinstall it)."
        )
    return path


@cache
def load_schema(name: str) -> dict[str, JSON]:
    """The parsed schema ``schema/<name>``, with its ``$ref``s resolvable against ``schema/``."""
    return json.loads(schema_path(name).read_text())


@cache
def _validator(name: str) -> Validator:
    import jsonschema
    from referencing import Registry, Resource
    from referencing.jsonschema import DRAFT202012

    resources = []
    for path in sorted(SCHEMA_DIR.glob("*.schema.json")):
        doc = json.loads(path.read_text())
        resources.append((path.name, Resource.from_contents(doc, default_specification=DRAFT202012)))
    registry = Registry().with_resources(resources)
    schema = load_schema(name)
    cls = jsonschema.validators.validator_for(schema)
    return cls(schema, registry=registry)


def validate(doc: object, schema_name: str, source: str) -> None:
    """Raise :class:`SchemaError` naming ``source`` (a file or a description) and every violation."""
    errors = sorted(_validator(schema_name).iter_errors(doc), key=lambda e: list(e.absolute_path))
    if errors:
        lines = []
        for err in errors[:10]:
            where = "/".join(str(p) for p in err.absolute_path) or "(top level)"
            lines.append(f"  at {where}: {err.message}")
        more = f"\n  ... and {len(errors) - 10} more" if len(errors) > 10 else ""
        raise SchemaError(f"{source} does not satisfy {schema_name}:\n" + "\n".join(lines) + more)


T = TypeVar("T")


def json_or_none(read: Callable[[object, str], T], value: object, what: str = "value") -> T | None:
    """``read(value, what)`` (one of the checked reads above), or None where ``value`` is None."""
    return None if value is None else read(value, what)


def json_doc(doc: Mapping[str, object]) -> dict[str, JSON]:
    """A ``TypedDict`` document (siteline.records) as the JSON it is, to store or nest in another: mypy
    takes a TypedDict for a ``Mapping[str, object]``, never for a ``Mapping[str, JSON]``, although every
    TypedDict of siteline holds JSON values only (python/mypy#4976). The same object, not a copy."""
    return cast(dict[str, JSON], doc)


def validated(doc: object, schema_name: str, source: str, shape: type[T]) -> T:
    """``doc`` validated against ``schema_name`` (:func:`validate`), as the ``TypedDict`` ``shape``
    that schema describes."""
    validate(doc, schema_name, source)
    return cast(T, doc)


def load_json(path: Path, what: str) -> Any:
    """Parse the JSON file ``path`` or raise :class:`SchemaError` naming it."""
    try:
        return json.loads(Path(path).read_text())
    except FileNotFoundError as exc:
        raise SchemaError(f"{what} file {path} does not exist.") from exc
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise SchemaError(f"{what} file {path} is not valid JSON: {exc}") from exc
