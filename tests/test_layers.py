"""The import graph runs one way: shared primitives <- stages <- pipeline <- CLI (and flows), with no
cycle between siteline's packages and modules."""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "platform" / "siteline"
PRIMITIVES = {
    "errors", "codes", "tolerances", "hashing", "config", "stores", "crs", "lasio", "sitestream",
    "photos", "dji", "cameras", "poses", "specs", "progress", "fence", "site", "taxonomy", "schemas", "metrics",
}  # fmt: skip
STAGES = {"ingest", "register", "tiles", "labels", "labelsets", "views", "render", "pairs", "release"}
TOP = {"pipeline", "cli", "__main__"}


def _graph() -> dict[str, set[str]]:
    """component -> components it imports (component: the first name below ``siteline``)."""
    edges: dict[str, set[str]] = defaultdict(set)
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE).with_suffix("").parts
        src = parts[0]
        for node in ast.walk(ast.parse(path.read_text())):
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
