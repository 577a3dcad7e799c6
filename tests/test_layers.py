"""drivewm's modules form layers: no import cycle, and nothing in the wheel imports tests or studies.

The graph is read from the source (ast), not from an import: every ``import`` and ``from ... import``
counts, at module level and inside functions alike (an import moved into a function defers a cycle,
it does not remove it), and so do a package's lazy exports (``_EXPORTS`` of drivewm.lazy), which
import their modules on first use.
"""

from __future__ import annotations

import ast
from pathlib import Path

import drivewm

PACKAGE = Path(drivewm.__file__).resolve().parent
#: Top-level names that are the repository's, not the wheel's.
OUTSIDE = ("tests", "studies", "benchmarks", "scripts")


def module_names(root: Path = PACKAGE) -> dict[str, Path]:
    """Dotted name -> file of every module under ``root`` (a package's name is its ``__init__.py``)."""
    names = {}
    for path in sorted(root.rglob("*.py")):
        parts = path.relative_to(root.parent).with_suffix("").parts
        names[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return names


def lazy_exports(path: Path) -> dict[str, str]:
    """A package's lazy exports (``_EXPORTS = {name: module}``, drivewm.lazy): imported on first use."""
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "_EXPORTS" for t in node.targets):
            value = node.value
            if isinstance(value, ast.DictComp):  # {name: "module" for name in (...)}: one module, many names
                return dict.fromkeys(ast.literal_eval(value.generators[0].iter), ast.literal_eval(value.value))
            return ast.literal_eval(value)
    return {}


def imported_names(name: str, path: Path, exports: dict[str, dict[str, str]]) -> list[str]:
    """The dotted names module ``name`` (at ``path``) imports: relative imports resolved, and a name
    from a package's lazy exports (``exports``: package -> {name: module}) as the module it comes from."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.rsplit(".", node.level - 1)[0]
                base = f"{parent}.{base}".rstrip(".")
            lazy = exports.get(base, {})
            found += [lazy.get(alias.name, f"{base}.{alias.name}") for alias in node.names]
    return found


def import_graph(root: Path = PACKAGE) -> tuple[dict[str, set[str]], dict[str, set[str]]]:
    """(module -> modules under ``root`` it imports, module -> outside top-level names it imports)."""
    names = module_names(root)
    exports = {name: lazy_exports(path) for name, path in names.items() if path.name == "__init__.py"}
    graph, outside = {}, {}
    for name, path in names.items():
        imported = imported_names(name, path, exports)
        graph[name] = {target for n in imported if (target := _module_of(n, names)) not in (None, name)}
        outside[name] = {n.split(".")[0] for n in imported} & set(OUTSIDE)
    return graph, outside


def _module_of(dotted: str, names: dict[str, Path]) -> str | None:
    """The module under the root that ``dotted`` names (``pkg.mod.func`` is ``pkg.mod``); None outside it."""
    while dotted and dotted not in names:
        dotted = dotted.rpartition(".")[0]
    return dotted or None


def find_cycle(graph: dict[str, set[str]]) -> list[str]:
    """One import cycle of ``graph`` as [a, b, ..., a], or [] when there is none (depth-first search)."""
    state: dict[str, int] = {}  # 1: on the current path, 2: finished
    path: list[str] = []

    def visit(node: str) -> list[str]:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return path[path.index(nxt) :] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        state[node] = 2
        path.pop()
        return []

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return []


def test_drivewm_has_no_import_cycle():
    graph, _ = import_graph()
    assert len(graph) > 100 and "drivewm.cli" in graph  # the whole package was read
    cycle = find_cycle(graph)
    assert not cycle, "import cycle: " + " -> ".join(cycle)


#: Packages that drivewm.views (view geometry shared by eval, transfer and generation) sits below.
ABOVE_VIEWS = ("diffusion", "multiview", "transfer", "generate", "tokenizer", "eval", "product")


def test_view_geometry_sits_below_the_model_packages():
    graph, _ = import_graph()
    views = {name: found for name, found in graph.items() if name.startswith("drivewm.views")}
    assert len(views) >= 6  # rays, warp, blend, reshade, grid, reproject
    above = {n: sorted(f for f in found if f.split(".")[1] in ABOVE_VIEWS) for n, found in views.items()}
    assert not any(above.values()), above


def test_no_drivewm_module_imports_tests_or_studies():
    _, outside = import_graph()
    offenders = {name: sorted(found) for name, found in outside.items() if found}
    assert not offenders, f"modules of the wheel importing repository-only code: {offenders}"


def test_the_checks_see_cycles_through_function_imports_and_lazy_exports(tmp_path):
    """The checks themselves, on a small package: a cycle closed by an import inside a function,
    another by a name from a package's lazy exports, and an import of tests."""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text('_EXPORTS = {name: "pkg.d" for name in ("run", "walk")}\n')
    (pkg / "a.py").write_text("from pkg.b import f\n")
    (pkg / "b.py").write_text("def f():\n    from . import a\n")
    (pkg / "c.py").write_text("from pkg import run\nimport tests.helpers\n")
    (pkg / "d.py").write_text("import pkg.c\n")
    graph, outside = import_graph(pkg)
    assert graph == {"pkg": set(), "pkg.a": {"pkg.b"}, "pkg.b": {"pkg.a"}, "pkg.c": {"pkg.d"}, "pkg.d": {"pkg.c"}}
    assert find_cycle(graph) == ["pkg.a", "pkg.b", "pkg.a"]
    assert find_cycle({**graph, "pkg.b": set()}) == ["pkg.c", "pkg.d", "pkg.c"]
    assert find_cycle({**graph, "pkg.b": set(), "pkg.d": set()}) == []
    assert outside == {"pkg": set(), "pkg.a": set(), "pkg.b": set(), "pkg.c": {"tests"}, "pkg.d": set()}
