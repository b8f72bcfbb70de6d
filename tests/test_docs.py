"""The front door: the README fits on a screen and runs, the generated tables match the registry and
the benchmark JSON, the documentation site builds with every warning an error, versions agree."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

import softarm_gym
from softarm_gym import docs_tables

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def test_generated_tables_and_env_pages_are_what_the_registry_and_json_say(capsys):
    assert docs_tables.main(["--check"]) == 0, capsys.readouterr().err


def test_a_stale_table_is_caught(tmp_path, monkeypatch):
    page = tmp_path / "page.md"
    page.write_text("<!-- generated: ids_table -->\n| stale |\n<!-- end generated: ids_table -->\n")
    filled = docs_tables.fill(page.read_text(), {})
    assert "| stale |" not in filled and "`SoftArm/OctArmReach-v1`" in filled
    with pytest.raises(ValueError, match="unknown generated section 'nope'"):
        docs_tables.fill("<!-- generated: nope -->\n<!-- end generated: nope -->", {})


def test_readme_fits_on_a_screen_and_carries_no_run_history():
    lines = README.splitlines()
    assert len(lines) <= 150
    assert not re.search(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b", README)  # commit hashes
    assert not re.search(r"\b20\d\d-\d\d-\d\d\b", README)  # dated runs
    assert "-v0\"" not in README and "-v0 " not in README.split("## Registered environments")[0]


def test_readme_links_point_at_files_that_exist():
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", README):
        if not target.startswith(("http://", "https://")):
            assert (ROOT / target).exists(), target


def test_readme_python_snippets_run(monkeypatch, capsys):
    monkeypatch.chdir(ROOT)
    blocks = re.findall(r"```python\n(.*?)```", README, re.S)
    assert len(blocks) == 2  # an environment, the solver
    for block in blocks:
        exec(compile(block, "README.md", "exec"), {})
    out = capsys.readouterr().out
    assert "mm from the target" in out and "True True" in out


def test_version_is_one_number_everywhere():
    version = softarm_gym.__version__
    assert re.search(rf'^version = "{re.escape(version)}"$', (ROOT / "pyproject.toml").read_text(), re.M)
    assert re.search(rf"^version: {re.escape(version)}$", (ROOT / "CITATION.cff").read_text(), re.M)
    released = re.findall(r"^## \[(\d+\.\d+\.\d+)\]", (ROOT / "CHANGELOG.md").read_text(), re.M)
    assert released and released[0] == version


def test_documentation_site_builds_with_every_warning_an_error(tmp_path):
    """``make docs`` in strict mode: a broken link, a missing page or anchor, a docstring that
    does not parse, a page outside the table of contents all fail the build."""
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
                           "-d", str(tmp_path / "doctrees"), str(ROOT / "docs"), str(tmp_path / "html")],
                          capture_output=True, text=True, timeout=900, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-5000:]
    for page in ("index", "getting_started", "envs/reach", "envs/wrap", "benchmarks", "api/solver"):
        assert (tmp_path / "html" / f"{page}.html").is_file(), page
    api = (tmp_path / "html" / "api" / "softarm_gym.html").read_text()
    assert "ReachEnv" in api and "Action Space" in api  # env cards rendered from the docstrings
