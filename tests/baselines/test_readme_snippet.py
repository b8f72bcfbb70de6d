"""The documented plain-SB3 snippet (docs/baselines.md) reproduces the shipped policies' success
rates on ``gym.make(id)``."""

import contextlib
import io
import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _snippet() -> str:
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "baselines.md").read_text(), re.S)
    (block,) = [b for b in blocks if "SAC.load" in b]
    return block


@pytest.mark.parametrize("env", ["OctArmReach", "CTReach"])
def test_readme_snippet_reproduces_the_shipped_success_rate(env, monkeypatch):
    code = _snippet().replace("OctArmReach", env)
    assert 'gym.make("SoftArm/' + env + '-v1")' in code  # the registered id, no extra kwargs
    meta = json.loads((ROOT / "baselines" / "trained" / f"sac_{env}-v1.json").read_text())
    assert meta["env_id"] == f"SoftArm/{env}-v1" and meta["env_kwargs"] == {}
    # The evaluation RESULTS.md reports for the run that was shipped (episode i seeded i).
    recorded = json.loads((ROOT / "baselines" / "results" / "eval"
                           / f"{meta['selected_from']}__main.json").read_text())
    assert recorded["episodes"] == 100
    monkeypatch.chdir(ROOT)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, "docs/baselines.md", "exec"), {})
    assert float(out.getvalue().split()[-1]) == pytest.approx(recorded["success_rate"], abs=1e-12)
