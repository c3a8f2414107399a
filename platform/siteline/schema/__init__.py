"""JSON documents: the JSON Schemas of siteline's contracts (the ``*.schema.json`` files beside this
module, shipped inside the package; the repository's top-level ``schema/`` links here), the validation
of documents against them, and :data:`JsonObject`, the type of a JSON object."""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

from siteline.errors import SchemaError

if TYPE_CHECKING:
    from jsonschema.protocols import Validator

SCHEMA_DIR = Path(__file__).resolve().parent

JsonObject = dict[str, Any]
"""A JSON object: a record's JSON form (its ``to_dict``, what its ``from_dict`` reads), a file read or
written as JSON (a manifest, a pair's summary, stats), a catalog JSON column, a store's attributes,
or a command's ``--json`` record. What crosses between stages is a typed record, not one of these."""


def schema_path(name: str) -> Path:
    """Path of ``schema/<name>`` (e.g. ``site.schema.json``)."""
    path = SCHEMA_DIR / name
    if not path.is_file():
        raise SchemaError(
            f"schema file {path} is missing: the siteline installation is incomplete (reinstall it)."
        )
    return path


@cache
def load_schema(name: str) -> JsonObject:
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


def validate(doc: Any, schema_name: str, source: str) -> None:
    """Raise :class:`SchemaError` naming ``source`` (a file or a description) and every violation."""
    errors = sorted(_validator(schema_name).iter_errors(doc), key=lambda e: list(e.absolute_path))
    if errors:
        lines = []
        for err in errors[:10]:
            where = "/".join(str(p) for p in err.absolute_path) or "(top level)"
            lines.append(f"  at {where}: {err.message}")
        more = f"\n  ... and {len(errors) - 10} more" if len(errors) > 10 else ""
        raise SchemaError(f"{source} does not satisfy {schema_name}:\n" + "\n".join(lines) + more)


def load_json(path: Path, what: str) -> Any:
    """Parse the JSON file ``path`` or raise :class:`SchemaError` naming it."""
    try:
        return json.loads(Path(path).read_text())
    except FileNotFoundError as exc:
        raise SchemaError(f"{what} file {path} does not exist.") from exc
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise SchemaError(f"{what} file {path} is not valid JSON: {exc}") from exc
