"""The solver's house in figures: ``python tests/house.py [ROOT]`` (ROOT defaults to this tree).

Prints, for ``solver/``: files and lines, the import graph's depth ("floors": modules on the
longest chain of intra-solver imports, the importing module included), its imports (one per
imported solver module per importing module; ``solver/__init__.py`` left out of both), the
largest modules and functions; and, for the whole project (``solver``, ``softarm_gym``,
``baselines``, ``tests``), the underscored names one module takes from another
(:func:`private_imports`), counted per package. The architecture tests
(``tests/test_architecture.py``) parse imports the same way, with :func:`imports_of`.
"""

from __future__ import annotations

import ast
import functools
import sys
from pathlib import Path

PACKAGES = ("solver", "softarm_gym", "baselines", "tests")


def module_name(path: Path, root: Path) -> str:
    """Dotted module name of ``path`` (a ``.py`` file under ``root``)."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports_of(path: Path, root: Path) -> list[tuple[str, str | None, int]]:
    """``(module, name or None, line)`` for every import in ``path``, relative ones resolved.

    ``from a.b import c`` gives ``("a.b", "c", line)``; ``import a.b`` gives ``("a.b", None,
    line)``. Imports inside functions count too.
    """
    here = module_name(path, root)
    package = here if path.name == "__init__.py" else here.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [(a.name, None, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            out += [(base, a.name, node.lineno) for a in node.names]
    return out


def python_files(root: Path, packages=PACKAGES) -> list[Path]:
    """Every ``.py`` file of ``packages`` under ``root``."""
    return sorted(p for pkg in packages for p in (root / pkg).rglob("*.py")
                  if "__pycache__" not in p.parts)


def solver_graph(root: Path) -> dict[str, set[str]]:
    """Intra-solver import graph: module -> the solver modules it imports. The package's
    ``__init__`` (the lobby that re-exports the public API) is left out."""
    files = [p for p in python_files(root, ("solver",)) if p != root / "solver" / "__init__.py"]
    modules = {module_name(p, root) for p in files}
    graph = {}
    for path in files:
        edges = set()
        for module, name, _ in imports_of(path, root):
            if name and f"{module}.{name}" in modules:  # from solver import rod
                edges.add(f"{module}.{name}")
            elif module in modules:
                edges.add(module)
        here = module_name(path, root)
        edges.discard(here)
        edges.discard("solver")
        graph[here] = edges
    return graph


def floors(graph: dict[str, set[str]]) -> int:
    """Modules on the longest import chain (a cycle-free graph)."""

    @functools.cache
    def depth(module: str) -> int:
        return 1 + max((depth(m) for m in graph[module]), default=0)

    return max(depth(m) for m in graph)


def functions(path: Path) -> list[tuple[int, str]]:
    """(lines, qualified name) of every function in ``path``, nested ones included."""
    out = []

    def walk(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                out.append((child.end_lineno - child.lineno + 1, prefix + child.name))
                walk(child, prefix + child.name + ".")
            elif isinstance(child, ast.ClassDef):
                walk(child, prefix + child.name + ".")

    walk(ast.parse(path.read_text(encoding="utf-8")), "")
    return out


def private_imports(root: Path, packages=PACKAGES) -> list[tuple[str, int, str, str]]:
    """``(file, line, module, name)`` of every underscored name one module of the project takes
    from another: imported (``from solver.solve import _check``), an underscored module
    imported (``from solver import _planar``), or read off an imported module
    (``planar_kernels._follow``). Dunders (``__version__``) are public."""
    out = []
    files = python_files(root, packages)
    modules = {module_name(p, root) for p in files}

    def private(name: str) -> bool:
        return name.startswith("_") and not name.startswith("__")

    for path in files:
        aliases = {}
        for module, name, line in imports_of(path, root):
            if module.split(".")[0] not in PACKAGES:
                continue
            names = [*module.split(".")[1:], *([name] if name else [])]
            if any(private(n) for n in names):
                out.append((str(path.relative_to(root)), line, module, name or ""))
            elif name and f"{module}.{name}" in modules:
                aliases[name] = f"{module}.{name}"
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):  # ``import a.b as c`` and ``from a import b as c``
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                for a in node.names:
                    full = a.name if isinstance(node, ast.Import) else f"{node.module}.{a.name}"
                    if a.asname and full in modules:
                        aliases[a.asname] = full
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                    and node.value.id in aliases and private(node.attr):
                out.append((str(path.relative_to(root)), node.lineno, aliases[node.value.id],
                            node.attr))
    return out


def report(root: Path) -> str:
    files = python_files(root, ("solver",))
    lines = {p: len(p.read_text(encoding="utf-8").splitlines()) for p in files}
    graph = solver_graph(root)
    funcs = sorted(((n, f"{p.relative_to(root)}:{q}") for p in files for n, q in functions(p)),
                   reverse=True)
    private = private_imports(root)
    rows = [f"solver/: {len(files)} files, {sum(lines.values())} lines; without __init__.py: "
            f"{floors(graph)} floors, {sum(len(e) for e in graph.values())} imports",
            "largest modules: " + ", ".join(f"{p.relative_to(root / 'solver')} {n}" for p, n in
                                            sorted(lines.items(), key=lambda kv: -kv[1])[:5]),
            "largest functions: " + ", ".join(f"{q} {n}" for n, q in funcs[:5]),
            f"underscored names imported across modules: {len(private)} in "
            f"{len({f for f, *_ in private})} files"]
    for pkg in PACKAGES:
        mine = [r for r in private if r[0].startswith(pkg + "/")]
        rows.append(f"  {pkg}: {len(mine)} in {len({f for f, *_ in mine})} files")
    return "\n".join(rows)


if __name__ == "__main__":
    print(report(Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).parents[1]).resolve()))
