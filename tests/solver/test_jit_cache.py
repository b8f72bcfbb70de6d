"""The numba cache heals: damaged entries are recompiled, a read-only install caches elsewhere.

Each test runs fresh Python processes against a cache directory of its own, so the cache the
rest of the suite uses is never touched.
"""

import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from solver import jit

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = "import solver; print(solver.pressure_from_stretch(1.1, 2e6, 9.3e-3, 14e-3, 78.0))"
"""Compiles two small kernels of solver.actuator (tube_pressure and pressure_and_slope)."""


def _run(env_changes: dict, code: str = SCRIPT, cwd=None, remove=()) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in remove}
    env.update(env_changes)
    proc = subprocess.run([sys.executable, "-c", code], env=env, cwd=cwd, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    return proc


def test_first_compile_says_so_in_one_line_and_a_cached_run_says_nothing(tmp_path):
    env = {"NUMBA_CACHE_DIR": str(tmp_path)}
    first = _run(env)  # two kernels compile: one line for the process, not one per kernel
    lines = first.stderr.splitlines()
    assert len(lines) == 1 and "compiling numba kernels on first use" in lines[0], first.stderr
    assert str(tmp_path) in lines[0]
    second = _run(env)
    assert second.stdout == first.stdout and second.stderr == ""
    quiet = _run({"NUMBA_CACHE_DIR": str(tmp_path / "other")},
                 code="from solver.jit import announce_compiles; announce_compiles(False); " + SCRIPT)
    assert quiet.stderr == "" and quiet.stdout == first.stdout


@pytest.mark.parametrize("damaged", ["actuator.tube_pressure-*.nbi", "actuator.tube_pressure-*.1.nbc"])
def test_damaged_cache_file_is_removed_and_recompiled(tmp_path, damaged):
    env = {"NUMBA_CACHE_DIR": str(tmp_path)}
    first = _run(env)
    assert "CacheWarning" not in first.stderr
    (path,) = tmp_path.glob(f"*/{damaged}")
    path.write_bytes(path.read_bytes()[:20])  # truncated, as by a full disk or a killed writer
    second = _run(env)
    assert second.stdout == first.stdout
    assert "CacheWarning: numba cache of tube_pressure" in second.stderr \
        and "could not be read" in second.stderr
    assert path.stat().st_size > 20  # written afresh
    third = _run(env)
    assert third.stdout == first.stdout and "CacheWarning" not in third.stderr


def test_read_only_install_without_home_caches_in_a_private_temp_dir(tmp_path):
    """No writable ``__pycache__`` next to the sources and no HOME: numba alone fails with
    "cannot cache function 'tube_pressure': no locator available"."""
    package = tmp_path / "site-packages"
    shutil.copytree(ROOT / "solver", package / "solver", ignore=shutil.ignore_patterns("__pycache__"))
    # Unwritable even for root (who ignores permission bits): __pycache__ is a file, HOME is
    # below a file. For other users the copy is read-only as well.
    (package / "solver" / "__pycache__").write_text("")
    (tmp_path / "file").write_text("")
    for path in [package, *package.rglob("*")]:
        path.chmod(path.stat().st_mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))
    temp = tmp_path / "tmp"
    temp.mkdir()
    env = {"PYTHONPATH": str(package), "HOME": str(tmp_path / "file" / "home"), "TMPDIR": str(temp)}
    try:
        first = _run(env, cwd=tmp_path, remove=("NUMBA_CACHE_DIR", "XDG_CACHE_HOME"))
        second = _run(env, cwd=tmp_path, remove=("NUMBA_CACHE_DIR", "XDG_CACHE_HOME"))
    finally:
        for path in [package, *package.rglob("*")]:
            path.chmod(path.stat().st_mode | stat.S_IWUSR)
    assert float(first.stdout) == pytest.approx(319617.2252157, rel=1e-12)
    assert "no writable cache directory" in first.stderr and "CacheWarning" in first.stderr
    assert second.stdout == first.stdout and second.stderr == ""  # said once; the cache is reused
    (cache,) = temp.glob("softarm-numba-*")
    assert stat.S_IMODE(cache.stat().st_mode) == 0o700
    assert list(cache.glob("*/actuator.tube_pressure-*.nbi"))


def test_fallback_dir_that_others_can_write_is_not_used(tmp_path, monkeypatch):
    """Cache files are unpickled: a planted, world-writable directory must not be trusted."""
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    assert jit.fallback_cache_dir() == tmp_path / f"softarm-numba-{os.getuid()}"
    planted = tmp_path / f"softarm-numba-{os.getuid()}"
    planted.chmod(0o777)
    other = jit.fallback_cache_dir()
    assert other != planted and other.parent == tmp_path and stat.S_IMODE(other.stat().st_mode) == 0o700


def test_warmup_clear_deletes_the_cache_and_compiles_it_again(tmp_path):
    """``--clear`` empties the cache, then the warm-up compiles into it again: the command line
    end to end in a fresh process, its groups' work cut to the two kernels of ``SCRIPT`` (what
    ``--clear`` removes does not depend on the groups; compiling every group is ``make test``'s
    own first step, which fails the run if a group does not compile)."""
    env = {"NUMBA_CACHE_DIR": str(tmp_path)}
    _run(env)  # a cache with two kernels in it
    (folder,) = tmp_path.glob("solver_*")
    stale = folder / "removed_kernel-1.py311.nbi"
    stale.write_bytes(b"\x80junk")
    kernels = sorted(p.name for p in folder.iterdir())
    code = ("from softarm_gym.commands import warmup\n"
            "def small_group(group):\n"
            f"    {SCRIPT}\n"
            "    return 0.0\n"
            "warmup.warm_group = small_group\n"
            "from softarm_gym.cli import main\n"
            "raise SystemExit(main(['warmup', '--clear', '--only', 'solver', '--jobs', '1']))")
    proc = _run(env, code=code)
    removed = int(proc.stdout.split("removed ")[1].split()[0])
    assert removed == len(kernels) and not stale.exists()  # 2 kernels × (index + data) + the stale index
    assert "numba kernels ready" in proc.stdout
    assert sorted(p.name for p in folder.iterdir()) == [k for k in kernels if k != stale.name]


def test_an_edit_of_the_rod_equations_makes_every_cached_kernel_stale(tmp_path):
    """numba stamps a cached kernel with its own module's file; kernels inline the rod
    equations of solver/rod.py, so an edit there must not leave their old machine code in
    use. On a copy of the package: a second run loads the cache; after an edit of rod.py
    the kernels of solver.actuator (a module that did not change) are compiled again; an
    edit of a module without kernels (solver/scene.py) leaves them cached; an edit of a kernel
    module in the subpackage solver/kernels/ recompiles them too."""
    shutil.copytree(ROOT / "solver", tmp_path / "solver",
                    ignore=shutil.ignore_patterns("__pycache__", "*.nb[ic]"))
    cache = tmp_path / "cache"
    env = {"NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(tmp_path)}

    def index():
        (path,) = cache.glob("*/actuator.tube_pressure-*.nbi")
        return path.read_bytes()

    first = _run(env, cwd=tmp_path)
    compiled = index()
    assert _run(env, cwd=tmp_path).stdout == first.stdout and index() == compiled
    with open(tmp_path / "solver" / "scene.py", "a") as f:
        f.write("\n# no kernels here\n")
    _run(env, cwd=tmp_path)
    assert index() == compiled
    with open(tmp_path / "solver" / "rod.py", "a") as f:
        f.write("\n# an edit\n")
    assert _run(env, cwd=tmp_path).stdout == first.stdout
    assert index() != compiled  # the stamp stored with the recompiled entry is new
    # A kernel module in the subpackage solver/kernels/ counts too.
    compiled = index()
    with open(tmp_path / "solver" / "kernels" / "obstacles.py", "a") as f:
        f.write("\n# an edit\n")
    assert _run(env, cwd=tmp_path).stdout == first.stdout
    assert index() != compiled



def test_a_kernel_that_takes_a_kernel_is_compiled_again_in_every_process(tmp_path):
    """Why the kernels repeat their RK4 and continuation loops per integrand instead of
    taking the right-hand side as an argument (docs/design.md §13): numba keys the cache entry
    of a function with a dispatcher argument by the dispatcher's address, so each process
    misses it and compiles again (numba issues #2956, #9237). If this test fails, numba caches
    such functions now, and the repeated loops listed in §13 can share one helper."""
    (tmp_path / "takes_kernel.py").write_text(
        "import numba\n"
        "@numba.njit(cache=True)\n"
        "def rhs(x):\n"
        "    return -x\n"
        "@numba.njit(cache=True)\n"
        "def step(f, x, h):\n"
        "    return x + h * f(x + 0.5 * h * f(x))\n")
    code = ("import takes_kernel as m; m.step(m.rhs, 1.0, 0.1); m.rhs(1.0); "
            "print(sum(m.step.stats.cache_hits.values()), sum(m.rhs.stats.cache_hits.values()))")
    env = {"NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(tmp_path)}
    assert _run(env, code, cwd=tmp_path).stdout.split() == ["0", "0"]  # first process: compiled
    # The second process loads rhs (a plain kernel) from the cache, but compiles step again.
    assert _run(env, code, cwd=tmp_path).stdout.split() == ["0", "1"]


def test_record_compiles_times_each_kernel_less_the_kernels_it_compiles_in_turn():
    """A kernel that compiles its callee on first call has two rows: the callee's, and its own
    whose exclusive time leaves the callee's out; a call that loads nothing new adds none."""
    import numba

    @numba.njit
    def callee(x):
        return x * 2.0

    @numba.njit
    def caller(x):
        return callee(x) + 1.0

    with jit.record_compiles() as rows:
        assert caller(1.0) == 3.0
        before = len(rows)
        caller(2.0)
    caller(3)  # a new argument type outside the context: not recorded
    by_name = {row["kernel"].rsplit(".", 1)[-1]: row for row in rows}
    assert before == len(rows) == 2 and set(by_name) == {"callee", "caller"}
    outer, inner = by_name["caller"], by_name["callee"]
    assert outer["seconds"] >= inner["seconds"] > 0.0
    assert outer["exclusive_seconds"] == pytest.approx(outer["seconds"] - inner["seconds"])
    assert inner["exclusive_seconds"] == inner["seconds"]
