"""The rules of the house, read from the source with ``ast`` (docs/design.md §13).

* :mod:`solver.kernels` never imports :mod:`solver.paths` (kernels are the bottom floor);
* nothing outside :mod:`solver` imports either, except the solver's own white-box tests
  (``tests/solver/``), which test the kernels and paths directly;
* no underscored name is taken from another module anywhere in the project, tests included:
  not imported, not read off an imported module, and no underscored module imported;
* :mod:`solver` imports numpy, scipy and numba only (and llvmlite and threadpoolctl beneath
  them), never gymnasium nor the project's other packages, in any module and any function
  (``tests/solver/test_validation.py`` checks the same at run time).
"""

import sys
from pathlib import Path

from tests.house import imports_of, module_name, private_imports, python_files

ROOT = Path(__file__).resolve().parents[1]
# numpy, scipy and numba, and the layers beneath them the solver reaches into: llvmlite
# (numba's IR, for an intrinsic in solver.rod) and threadpoolctl (the BLAS threads under
# numpy and scipy, solver.blas).
THIRD_PARTY_OF_SOLVER = {"numpy", "scipy", "numba", "llvmlite", "threadpoolctl"}


def _imports(packages):
    """(file, line, imported module) of every import in ``packages`` (``from a import b``
    gives ``a.b``: b may be a module)."""
    return [(path.relative_to(ROOT).as_posix(), line, f"{module}.{name}" if name else module)
            for path in python_files(ROOT, packages) for module, name, line in imports_of(path, ROOT)]


def _within(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def test_kernels_never_import_paths():
    bad = [(f, line, m) for f, line, m in _imports(("solver",))
           if f.startswith("solver/kernels/") and _within(m, "solver.paths")]
    assert not bad, f"solver/kernels/ imports solver.paths: {bad}"


def test_nothing_outside_the_solver_imports_its_internal_packages():
    bad = [(f, line, m) for f, line, m in _imports(("softarm_gym", "baselines", "tests"))
           if not f.startswith("tests/solver/")
           and any(_within(m, p) for p in ("solver.kernels", "solver.paths"))]
    assert not bad, f"solver.kernels / solver.paths imported outside solver/: {bad}"


def test_no_underscored_name_crosses_a_module():
    bad = private_imports(ROOT)
    assert not bad, "underscored names taken from another module:\n" + "\n".join(
        f"{f}:{line}: {m} {n}" for f, line, m, n in bad)


def test_solver_imports_numpy_scipy_and_numba_only():
    stdlib = set(sys.stdlib_module_names) | {"__future__"}
    bad = [(f, line, m) for f, line, m in _imports(("solver",))
           if m.split(".")[0] not in stdlib | THIRD_PARTY_OF_SOLVER | {"solver"}]
    assert not bad, f"solver/ imports beyond numpy, scipy, numba: {bad}"


def test_the_checks_see_what_they_look_for(tmp_path):
    """The parsers find each kind of breach in a planted file (so the tests above cannot pass
    by seeing nothing)."""
    package = tmp_path / "softarm_gym"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "planted.py").write_text(
        "import gymnasium\n"
        "from solver import _planar\n"
        "from solver.solve import _check\n"
        "from solver.kernels import planar as planar_kernels\n"
        "def f():\n"
        "    from solver.paths.dispatch import dispatch\n"
        "    return planar_kernels._follow, dispatch\n")
    (tmp_path / "solver" / "kernels").mkdir(parents=True)
    for init in ("solver/__init__.py", "solver/kernels/__init__.py"):
        (tmp_path / init).write_text("")
    (tmp_path / "solver" / "kernels" / "planar.py").write_text("def _follow():\n    pass\n")
    found = {(m, n) for _, _, m, n in private_imports(tmp_path, ("softarm_gym", "solver"))}
    assert found == {("solver", "_planar"), ("solver.solve", "_check"),
                     ("solver.kernels.planar", "_follow")}
    planted = package / "planted.py"
    imported = {f"{m}.{n}" if n else m for m, n, _ in imports_of(planted, tmp_path)}
    assert {"gymnasium", "solver.paths.dispatch.dispatch", "solver.kernels.planar"} <= imported
    assert module_name(planted, tmp_path) == "softarm_gym.planted"
