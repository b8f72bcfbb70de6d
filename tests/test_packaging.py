"""Packaging a user can trust: ``python -m build`` makes a wheel and an sdist; the wheel holds every
data file the package reads; installed into a fresh venv, with no checkout in sight, it runs the
README's first snippet and ``softarm solve``.

The wheel test builds, installs numpy, scipy, numba, gymnasium, matplotlib into a new venv and
compiles kernels there: about two minutes, so it is marked ``wheel`` and left out of ``make
test`` (``-m "not wheel"`` in pyproject's pytest options); ``.ci/run`` runs it after the suite
(``pytest -m wheel``).
"""

import os
import re
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest

import softarm_gym

ROOT = Path(__file__).resolve().parents[1]

SHIPPED = [
    *(p.relative_to(ROOT) for p in (ROOT / "baselines" / "hyperparams").rglob("*.yml")),
    *(p.relative_to(ROOT) for p in (ROOT / "baselines" / "trained").iterdir()),
    *(p.relative_to(ROOT) for p in (ROOT / "solver" / "examples").glob("*.json")),
]
"""Every data file the installed package reads."""


def _run(argv, **kwargs):
    proc = subprocess.run(argv, capture_output=True, text=True, **kwargs)
    assert proc.returncode == 0, (argv, proc.stdout[-2000:], proc.stderr[-4000:])
    return proc


@pytest.mark.wheel
def test_wheel_holds_the_data_and_runs_the_readme_without_a_checkout(tmp_path):
    dist = tmp_path / "dist"
    _run([sys.executable, "-m", "build", "--outdir", str(dist), str(ROOT)], timeout=900)
    version = softarm_gym.__version__
    (wheel,) = dist.glob(f"softarm_gym-{version}-*.whl")
    (sdist,) = dist.glob(f"softarm_gym-{version}.tar.gz")
    names = set(zipfile.ZipFile(wheel).namelist())
    assert len(SHIPPED) >= 15
    for path in SHIPPED:
        assert path.as_posix() in names, path
    assert not [n for n in names if n.endswith((".nbi", ".nbc", ".pyc"))]
    with tarfile.open(sdist) as tar:
        members = {m.name.split("/", 1)[1] for m in tar.getmembers() if "/" in m.name}
    assert {"pyproject.toml", "README.md", "LICENSE", "solver/examples/two_section_pneumatic.json"} <= members

    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "NUMBA_CACHE_DIR")}
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", str(venv)], env=env, timeout=300)
    python, softarm = venv / "bin" / "python", venv / "bin" / "softarm"
    _run([str(python), "-m", "pip", "install", "-q", str(wheel)], env=env, timeout=1800)
    work = tmp_path / "elsewhere"  # no checkout here, and none on the path
    work.mkdir()
    snippet = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), re.S)[0]
    (work / "snippet.py").write_text(snippet)
    out = _run([str(python), "snippet.py"], cwd=work, env=env, timeout=900).stdout
    assert "mm from the target" in out
    where = _run([str(python), "-c", "import solver, softarm_gym, baselines; print(solver.__file__, "
                  "softarm_gym.__version__, solver.designs.example_file())"], cwd=work, env=env).stdout
    assert str(venv) in where and version in where and str(ROOT) not in where
    solve = _run([str(softarm), "solve", "--pressures-psi", "30,0,30,0,30,0", "--base-angle", "90",
                  "--payload-kg", "0.25", "--json"], cwd=work, env=env, timeout=600).stdout
    assert '"converged": true' in solve
    example = _run([str(softarm), "solve", "--design-file", where.split()[-1], "--pressures-psi",
                    "50,0,50,0"], cwd=work, env=env, timeout=600).stdout
    assert "two_section_pneumatic tip" in example
