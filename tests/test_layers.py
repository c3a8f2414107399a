"""The import graph runs one way: shared primitives <- catalog <- stages <- pipeline <- CLI (and flows),
with no cycle between siteline's packages and modules; and the rules of a stage's anatomy hold (plan,
execute, record: only the catalog touches ORM rows, execute never imports the catalog, no stage
function is long, one store interface)."""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "platform" / "siteline"
PRIMITIVES = {
    "errors", "codes", "tolerances", "hashing", "config", "progress", "stores", "records", "schema",
    "camera", "site", "pointpass",
}  # fmt: skip
STAGES = {"ingest", "register", "tiles", "labels", "labelsets", "views", "render", "pairs", "release"}
TOP = {"pipeline", "trade", "cli", "__main__"}
MAX_STAGE_FUNCTION_LINES = 60


def _modules() -> list[tuple[Path, ast.Module]]:
    return [(p, ast.parse(p.read_text())) for p in sorted(PACKAGE.rglob("*.py"))]


def _imports(tree: ast.Module) -> list[str]:
    """Every module name ``tree`` imports (``from a.b import c`` gives ``a.b`` and ``a.b.c``)."""
    out: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            out.append(node.module)
            out += [f"{node.module}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            out += [a.name for a in node.names]
    return out


def _graph() -> dict[str, set[str]]:
    """component -> components it imports (component: the first name below ``siteline``)."""
    edges: dict[str, set[str]] = defaultdict(set)
    for path, tree in _modules():
        src = path.relative_to(PACKAGE).with_suffix("").parts[0]
        for node in ast.walk(tree):
            names: list[str] = []
            if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "siteline":
                mod = node.module.split(".")
                names = [mod[1]] if len(mod) > 1 else [a.name for a in node.names]
            elif isinstance(node, ast.Import):
                names = [a.name.split(".")[1] for a in node.names if a.name.startswith("siteline.")]
            edges[src].update(n for n in names if n != src and n != "__version__")
    return edges


def test_no_import_cycle_between_components() -> None:
    edges = _graph()
    seen: dict[str, int] = {}

    def visit(node: str, stack: list[str]) -> None:
        seen[node] = 1
        for nxt in edges.get(node, ()):
            assert seen.get(nxt) != 1, f"import cycle: {' -> '.join([*stack, node, nxt])}"
            if nxt not in seen:
                visit(nxt, [*stack, node])
        seen[node] = 2

    for node in list(edges):
        if node not in seen:
            visit(node, [])


def test_primitives_import_no_stage_and_stages_no_pipeline() -> None:
    edges = _graph()
    for prim in PRIMITIVES:
        bad = edges.get(prim, set()) - PRIMITIVES
        assert not bad, f"primitive {prim} imports {sorted(bad)}"
    for comp, targets in edges.items():
        if comp not in TOP:
            assert not targets & TOP, f"{comp} imports {sorted(targets & TOP)}"
        if comp not in TOP | {"ingest"}:
            assert "ingest" not in targets, f"{comp} imports ingest (only the CLI, flows and pipeline may)"


def _rel(path: Path) -> str:
    return path.relative_to(PACKAGE).as_posix()


def test_orm_models_are_imported_only_by_the_catalog() -> None:
    bad = [
        _rel(p) for p, tree in _modules()
        if not _rel(p).startswith("catalog/") and any(m.startswith("siteline.catalog.models") for m in _imports(tree))
    ]  # fmt: skip
    assert not bad, f"only siteline.catalog may import its ORM models: {bad}"


def test_the_library_never_imports_prefect() -> None:
    bad = [_rel(p) for p, tree in _modules() if any(m.split(".")[0] == "prefect" for m in _imports(tree))]
    assert not bad, f"the library imports prefect: {bad} (flows/ orchestrate, the library never does)"


def test_only_the_stores_import_fsspec() -> None:
    """Every read and write of the data stores goes through a Store (or siteline.stores' helpers):
    no module outside siteline.stores imports fsspec, or reaches for its file systems."""
    bad = [
        _rel(p) for p, tree in _modules()
        if not _rel(p).startswith("stores/")
        and any(m.split(".")[0] == "fsspec" or m == "siteline.stores.remote.file_system" for m in _imports(tree))
    ]  # fmt: skip
    assert not bad, f"fsspec outside siteline.stores: {bad}"


def test_only_the_stores_tell_local_from_remote() -> None:
    bad = [
        _rel(p)
        for p in PACKAGE.rglob("*.py")
        if not _rel(p).startswith("stores/") and "is_remote" in p.read_text()
    ]
    assert not bad, f"is_remote outside siteline.stores: {bad} (use a Store's methods)"


# a stage's catalog side: its plan and stage modules, and these, which read the catalog for a command
# (an export of a label set, a release diff, a release's health check); every other module of a stage
# package is its execute side (execute.py, release/build.py, release/publish.py, the writers and readers
# they use), which works from a plan alone
CATALOG_SIDE = {"labelsets/export.py", "release/query.py", "release/repair.py"}


def test_execute_sides_never_import_the_catalog() -> None:
    bad = [
        _rel(p) for p, tree in _modules()
        if _rel(p).split("/")[0] in STAGES and p.name not in ("plan.py", "stage.py", "__init__.py")
        and _rel(p) not in CATALOG_SIDE and any(m.startswith("siteline.catalog") for m in _imports(tree))
    ]  # fmt: skip
    assert not bad, f"a stage's execute side imports the catalog: {bad}"


def _orm_columns() -> set[str]:
    from siteline.catalog import Base

    return {c.name for table in Base.metadata.tables.values() for c in table.columns}


def test_no_orm_attribute_is_set_outside_the_catalog() -> None:
    """Stages hand typed records to ``siteline.catalog`` record functions; they never set a row's
    columns themselves (an assignment ``x.<column> = ...`` on anything but ``self``)."""
    columns = _orm_columns()
    bad = []
    for path, tree in _modules():
        if _rel(path).startswith(("catalog/", "migrations/")):
            continue
        for node in ast.walk(tree):
            targets = (
                node.targets
                if isinstance(node, ast.Assign)
                else [node.target]
                if isinstance(node, ast.AugAssign | ast.AnnAssign)
                else []
            )
            for t in targets:
                if (
                    isinstance(t, ast.Attribute) and t.attr in columns
                    and not (isinstance(t.value, ast.Name) and t.value.id in ("self", "cls"))
                ):  # fmt: skip
                    bad.append(f"{_rel(path)}:{node.lineno} sets .{t.attr}")
    assert not bad, "ORM attributes set outside siteline.catalog:\n" + "\n".join(bad)


def _code_lines(fn: ast.FunctionDef | ast.AsyncFunctionDef, lines: list[str]) -> int:
    body = fn.body
    if body and isinstance(body[0], ast.Expr) and isinstance(getattr(body[0], "value", None), ast.Constant):
        body = body[1:]
    if not body:
        return 0
    text = lines[body[0].lineno - 1 : fn.end_lineno]
    return sum(1 for line in text if line.strip() and not line.strip().startswith("#"))


def test_no_stage_function_is_long() -> None:
    """A stage function does one job: none of the stages' or the pipeline's is over ~60 lines of code
    (its body, without the docstring, blank lines and comments)."""
    long = []
    for path, tree in _modules():
        parts = path.relative_to(PACKAGE).parts
        if parts[0] not in STAGES and parts[0] != "pipeline.py":
            continue
        lines = path.read_text().splitlines()
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                n = _code_lines(node, lines)
                if n > MAX_STAGE_FUNCTION_LINES:
                    long.append(f"{_rel(path)}:{node.lineno} {node.name} ({n} lines)")
    assert not long, "stage functions over 60 lines of code:\n" + "\n".join(long)


def test_every_stage_has_a_plan_an_execute_and_a_record() -> None:
    """The anatomy ARCHITECTURE.md names: each stage's plan and execute functions, and its record
    function under siteline.catalog."""
    import importlib

    anatomy = {
        "ingest": ("siteline.ingest.plan:plan_ingest", "siteline.ingest.execute:execute_ingest", "siteline.catalog.missions:record_ingest"),
        "tile": ("siteline.tiles.plan:plan_tiling", "siteline.tiles.execute:execute_tiling", "siteline.catalog.scenes:record_tiling"),
        "labels import": ("siteline.labelsets.plan:plan_label_import", "siteline.labelsets.execute:execute_label_import", "siteline.catalog.labelsets:record_label_set"),
        "process pair": ("siteline.pairs.plan:plan_pair", "siteline.pairs.execute:execute_pair", "siteline.catalog.pairs:record_pair_outputs"),
        "build release": ("siteline.release.plan:plan_release", "siteline.release.build:execute_build", "siteline.catalog.releases:record_draft"),
        "publish": ("siteline.release.plan:plan_publish", "siteline.release.publish:move_into_place", "siteline.catalog.releases:record_published"),
    }  # fmt: skip
    doc = (PACKAGE.parents[1] / "docs" / "ARCHITECTURE.md").read_text()
    for stage, refs in anatomy.items():
        for ref in refs:
            module, name = ref.split(":")
            assert callable(getattr(importlib.import_module(module), name)), ref
            assert name in doc, f"docs/ARCHITECTURE.md does not name {ref} ({stage})"


MAX_PARAMETERS = 8


def test_no_library_function_takes_more_than_eight_parameters() -> None:
    """Settings travel as typed records (TilingResources, ReleaseOptions, ImportOptions, ...), not as
    long argument lists: no function outside the CLI (whose commands mirror their options) takes
    more than 8 (``self``/``cls`` not counted; ``*args`` and ``**kwargs`` one each)."""
    long = []
    for path, tree in _modules():
        if _rel(path).startswith(("cli/", "migrations/")):
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                a = node.args
                names = [x.arg for x in [*a.posonlyargs, *a.args, *a.kwonlyargs]]
                n = len([x for x in names[:1] if x not in ("self", "cls")]) + len(names[1:])
                n += (a.vararg is not None) + (a.kwarg is not None)
                if n > MAX_PARAMETERS:
                    long.append(f"{_rel(path)}:{node.lineno} {node.name} ({n})")
    assert not long, "functions over 8 parameters:\n" + "\n".join(long)


def test_stage_package_fronts_import_nothing() -> None:
    """A stage package's ``__init__`` is its docstring only: names are imported from their modules, so
    a worker that imports one module (a tile writer, a LAS reader) pulls in no other of its stage."""
    for stage in sorted(STAGES):
        tree = ast.parse((PACKAGE / stage / "__init__.py").read_text())
        body = [n for n in tree.body if not (isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant))]
        assert not body, f"siteline/{stage}/__init__.py holds code: import names from their modules"


def test_a_tile_worker_imports_neither_the_catalog_nor_the_renderer() -> None:
    """What a tile-writing worker process imports (siteline.tiles.batches) stays clear of the catalog
    (SQLAlchemy), the stage's entries and torch."""
    import subprocess
    import sys

    code = (
        "import sys, siteline.tiles.batches, siteline.pointpass.lasio\n"
        "print(sorted(m for m in ('sqlalchemy', 'torch', 'siteline.catalog', 'siteline.tiles.stage') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", out.stdout


def test_the_engine_surface_is_what_architecture_names_and_laspy_stays_inside() -> None:
    """``siteline.pointpass`` exports exactly the surface docs/ARCHITECTURE.md lists, and what the type
    checker sees of it is what it serves; nothing outside the engine (library, flows, deploy, bench,
    tests but the engine's own) imports a module behind the front, nor the library laspy; ingest and
    tiling each call ``pass_file`` once."""
    import re

    import siteline.pointpass as engine

    doc = (ROOT / "docs" / "ARCHITECTURE.md").read_text()
    para = doc[doc.index("The engine's surface") :].split("\n\n")[0]
    listed = set(re.findall(r"`([A-Za-z_]+)`", para.split("):", 1)[1].split(".\n")[0]))
    assert listed == set(engine.__all__), sorted(listed ^ set(engine.__all__))
    front = ast.parse((PACKAGE / "pointpass" / "__init__.py").read_text())
    typed = {
        (node.module.removeprefix("siteline.pointpass."), a.name)
        for node in ast.walk(front) if isinstance(node, ast.ImportFrom) and node.module for a in node.names
        if node.module.startswith("siteline.pointpass.")
    }  # fmt: skip
    assert typed == {(m, n) for n, m in engine._FRONT.items()}
    for name in engine.__all__:
        assert getattr(engine, name) is not None
    outside = []
    scripts = [p for d in ("flows", "deploy", "bench", "tests") for p in (ROOT / d).rglob("*.py")]
    for path in [p for p, _ in _modules()] + scripts:
        if path.is_relative_to(PACKAGE / "pointpass") or path.is_relative_to(ROOT / "tests" / "pointpass"):
            continue
        for name in _imports(ast.parse(path.read_text())):
            # tests write their fixtures and the ingest bench measures its baseline with laspy itself
            if (
                name.split(".")[0] == "laspy"
                and not path.is_relative_to(ROOT / "tests")
                and path.parent.name != "bench"
            ):
                outside.append(f"{path.relative_to(ROOT)} imports laspy")
            parts = name.split(".")
            if parts[:2] == ["siteline", "pointpass"] and len(parts) > 2 and parts[2] not in engine._FRONT:
                outside.append(
                    f"{path.relative_to(ROOT)} imports {name}: use the engine's front, siteline.pointpass"
                )
    assert not outside, outside
    for stage in ("ingest/pointcloud.py", "tiles/writer.py"):
        assert (PACKAGE / stage).read_text().count("pass_file(") == 1, stage


def test_scene_and_site_rows_stay_inside_the_catalog() -> None:
    """Outside ``siteline/catalog/`` a scene or site is a record (SceneView, SiteView): the functions
    that hand out or read ORM rows of them are not imported there."""
    rows = {"scene_row", "scene_rows_of", "site_row", "scene_statistics", "scene_registration", "site_spec"}
    bad = []
    for path, tree in _modules():
        if path.relative_to(PACKAGE).parts[0] == "catalog":
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("siteline.catalog"):
                bad += [f"{_rel(path)} imports {a.name}" for a in node.names if a.name in rows]
    assert not bad, bad


def test_no_sys_path_edit_anywhere() -> None:
    """The library, the service (flows, deploy), the benchmarks and the tests import by package names
    (the service and benchmarks run from the repository root; pytest's pythonpath is that root)."""
    root = PACKAGE.parents[1]
    edits = ("sys.path." + "insert", "sys.path." + "append", "sys.path" + "[", "sys.path +" + "=")
    found = [
        f"{p.relative_to(root)}:{n}"
        for folder in ("platform", "flows", "deploy", "bench", "tests")
        for p in sorted((root / folder).rglob("*.py"))
        for n, line in enumerate(p.read_text().splitlines(), 1)
        if any(e in line for e in edits)
    ]
    assert not found, found


_JSON_TYPES = ("JSON", "dict[str, Any]", "Mapping[str, Any]")


def test_no_json_dict_crosses_between_packages() -> None:
    """What one package of the library hands another is a record, never a JSON dict: no public function
    or method that another package calls (the CLI, which prints documents, and the catalog, which stores
    them, aside) takes a JSON dict, but a record's parser (``from_*``), nor returns one, but a record's
    JSON form (``to_*``) or a document made to be stored or written (``*record``, ``details``); the
    JSON type's own module (siteline.schema: its checked reads) is the third edge. Fixed-shape
    documents that cross are ``TypedDict``s (siteline.records.release, PairSummary, ...)."""
    defs: dict[tuple[str, str], tuple[str, ast.FunctionDef]] = {}
    uses: list[tuple[str, str, str]] = []
    for path, tree in _modules():
        rel = path.relative_to(PACKAGE).with_suffix("").parts
        module = ".".join(("siteline", *rel)).removesuffix(".__init__")
        for node in tree.body:
            if isinstance(node, ast.FunctionDef) and not node.name.startswith("_"):
                defs[(module, node.name)] = (rel[0], node)
            elif isinstance(node, ast.ClassDef):
                for sub in node.body:
                    if isinstance(sub, ast.FunctionDef) and not sub.name.startswith("_"):
                        defs[(module, f"{node.name}.{sub.name}")] = (rel[0], sub)
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("siteline."):
                uses += [(rel[0], str(node.module), a.name) for a in node.names]
    bad = set()
    for user, module, name in uses:
        called = [(module, name)] + [k for k in defs if k[0] == module and k[1].startswith(f"{name}.")]
        for key in called:
            if key not in defs or user in ("cli", "catalog"):
                continue
            owner, fn = defs[key]
            last = key[1].split(".")[-1]
            if owner in ("cli", "catalog", "schema", user):  # schema: the JSON type and its checked reads
                continue
            params = [a for a in fn.args.args + fn.args.kwonlyargs if a.annotation is not None]
            if not last.startswith("from_"):
                bad |= {
                    f"{key[0]}.{key[1]}({a.arg}: {ast.unparse(a.annotation)}) called by {user}"  # type: ignore[arg-type]
                    for a in params
                    if any(t in ast.unparse(a.annotation) for t in _JSON_TYPES)  # type: ignore[arg-type]
                }
            documents = last.startswith("to_") or last.endswith("record") or last == "details"
            if (
                fn.returns is not None
                and not documents
                and any(t in ast.unparse(fn.returns) for t in _JSON_TYPES)
            ):
                bad.add(f"{key[0]}.{key[1]} returns {ast.unparse(fn.returns)} to {user}")
    assert not bad, sorted(bad)
