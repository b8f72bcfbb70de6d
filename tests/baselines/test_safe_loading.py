"""Crafted model files: loading one never runs code (issue #19, item 1).

Every payload, if it ran, would create a marker file. Each test checks the marker is absent
after the safe load; where the old loader is available (``trust_pickle=True``) a test also
shows that the same file *does* run its payload that way, so the payloads are real.
"""

import base64
import contextlib
import io
import json
import pickle
import shutil
import zipfile

import gymnasium as gym
import numpy as np
import pytest
import torch

from baselines import config
from baselines.config import load_policy
from baselines.evaluate import evaluate, main


class Payload:
    """Unpickling this calls ``open(marker, "w")``: the marker file appears."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return open, (self.marker, "w")


@pytest.fixture
def model(tiny_sac_run, tmp_path):
    """A copy of the tiny SAC run's final model with its sidecars, as ``tmp/model.zip``."""
    for suffix in (".zip", ".json", "_vecnormalize.json"):
        shutil.copy(tiny_sac_run / f"final_model{suffix}", tmp_path / f"model{suffix}")
    return tmp_path / "model.zip"


@pytest.fixture
def marker(tmp_path):
    return tmp_path / "PAYLOAD_RAN"


def _rewrite_zip(path, replace: dict):
    """Rewrite the zip at ``path`` with some members' bytes replaced."""
    with zipfile.ZipFile(path) as src:
        members = {name: src.read(name) for name in src.namelist()}
    members.update(replace)
    with zipfile.ZipFile(path, "w") as dst:
        for name, data in members.items():
            dst.writestr(name, data)


def _trusted_load(model):
    """The old way; the payload runs while loading, whatever SB3 then makes of its result."""
    with contextlib.suppress(Exception):
        load_policy(model, trust_pickle=True)


def _edit_metadata(model, **changes):
    path = model.with_suffix(".json")
    path.write_text(json.dumps({**json.loads(path.read_text()), **changes}))


def test_cloudpickle_payload_in_the_zip_is_never_unpickled(model, marker, capsys):
    """SB3 stores objects such as the observation space cloudpickled in the zip's ``data``."""
    with zipfile.ZipFile(model) as archive:
        data = json.loads(archive.read("data"))
    data["observation_space"][":serialized:"] = base64.b64encode(pickle.dumps(Payload(marker))).decode()
    _rewrite_zip(model, {"data": json.dumps(data)})
    assert main(["--model", str(model), "--episodes", "1", "--no-progress", "--json"]) == 0
    assert "success_rate" in json.loads(capsys.readouterr().out)
    assert not marker.exists()
    _trusted_load(model)
    assert marker.exists()


def test_pickled_object_in_policy_weights_is_refused(model, marker):
    buffer = io.BytesIO()
    torch.save({"actor.latent_pi.0.weight": Payload(marker)}, buffer)
    _rewrite_zip(model, {"policy.pth": buffer.getvalue()})
    with pytest.raises(ValueError, match=r"policy.pth is not plain weights \(refused by torch.load"):
        load_policy(model)
    assert not marker.exists()
    with zipfile.ZipFile(model) as archive:  # what a full unpickle of that entry would do
        torch.load(io.BytesIO(archive.read("policy.pth")), weights_only=False)
    assert marker.exists()


def test_pickled_normalisation_statistics_are_refused_without_trust_pickle(model, marker, capsys):
    model.with_name("model_vecnormalize.json").unlink()
    model.with_name("model_vecnormalize.pkl").write_bytes(pickle.dumps(Payload(marker)))
    assert main(["--model", str(model), "--episodes", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "can run code when loaded" in err and "--trust-pickle" in err
    assert not marker.exists()
    _trusted_load(model)
    assert marker.exists()


@pytest.mark.parametrize("trust_pickle", [False, True])
def test_metadata_env_id_cannot_import_a_module(model, marker, tmp_path, monkeypatch, trust_pickle):
    """``gym.make("evil:Env")`` would import ``evil.py`` from the path; metadata may not name it."""
    module = f"evil_env_{trust_pickle}"  # one name per case: a module is imported only once
    (tmp_path / f"{module}.py").write_text(f"open({str(marker)!r}, 'w')\nclass Env: pass\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    _edit_metadata(model, env_id=f"{module}:Env")
    with pytest.raises(ValueError, match=r"model.json: environment id must be a registered SoftArm/\* id"):
        load_policy(model, trust_pickle=trust_pickle)
    assert not marker.exists()
    with pytest.raises(ValueError, match="registered SoftArm"):  # an explicit --env neither
        evaluate(controller="jacobian", env_id=f"{module}:Env", episodes=1)
    assert not marker.exists()
    with contextlib.suppress(Exception):  # what gym.make does with such an id
        gym.make(f"{module}:Env")
    assert marker.exists()


@pytest.mark.parametrize(("changes", "match"), [
    ({"policy": "stable_baselines3.sac.policies.SACPolicy"}, "policy must be one of MlpPolicy"),
    ({"policy": ["MlpPolicy"]}, "policy must be one of"),
    ({"policy_kwargs": {"activation_fn": "os.system"}}, "may not set"),
    ({"policy_kwargs": {"net_arch": [10**9]}}, "layer sizes in 1..4096"),
    ({"policy_kwargs": {"net_arch": [8], "n_critics": 10**6}}, "n_critics"),
    ({"algo": {"sac": 1}}, "unknown algo"),
    ({"env_kwargs": "design=octarm_v"}, "env_kwargs must be a mapping"),
    ({"policy_kwargs": {"net_arch": [16]}}, "weights do not fit"),
])
def test_malformed_metadata_is_refused(model, changes, match):
    _edit_metadata(model, **changes)
    with pytest.raises(ValueError, match=match):
        load_policy(model)


@pytest.mark.parametrize(("stats", "match"), [
    ("{", "not valid JSON"),
    ('{"format": "vecnormalize-1"}', "norm_obs must be true or false"),
    (None, "finite means"),  # NaN mean
    (1, "finite means"),  # wrong size
])
def test_bad_normalisation_statistics_are_refused(model, stats, match):
    path = model.with_name("model_vecnormalize.json")
    if stats is None or stats == 1:
        data = json.loads(path.read_text())
        data["obs_rms"]["mean"] = data["obs_rms"]["mean"][:-1] if stats == 1 else \
            [float("nan")] + data["obs_rms"]["mean"][1:]
        stats = json.dumps(data)
    path.write_text(stats)
    with pytest.raises(ValueError, match=match):
        load_policy(model)


def test_not_a_zip_and_oversized_weights_are_refused(model, monkeypatch):
    monkeypatch.setattr(config, "_MAX_WEIGHTS_BYTES", 100)
    with pytest.raises(ValueError, match="policy.pth is .* bytes; at most 100 are read"):
        load_policy(model)
    model.write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(ValueError, match="is not a zip file"):
        load_policy(model)


def test_safe_and_trusted_loading_act_identically(tiny_sac_run):
    model = tiny_sac_run / "final_model.zip"
    safe, meta, norm = load_policy(model)
    trusted, _, _ = load_policy(model, trust_pickle=True)
    obs = np.random.default_rng(0).normal(size=(32, *norm.observation_space.shape)).astype(np.float32)
    np.testing.assert_array_equal(safe.predict(obs, deterministic=True)[0],
                                  trusted.predict(obs, deterministic=True)[0])
    assert meta["policy"] == "MlpPolicy" and meta["normalized"] is True


def test_shipped_models_load_safely():
    """The trained policies in baselines/trained come without pickled sidecars."""
    trained = config.HYPERPARAMS_DIR.parent / "trained"
    assert not list(trained.glob("*.pkl"))
    for path in sorted(trained.glob("*.zip")):
        policy, meta, norm = load_policy(path)
        # Statistics ship with the policies trained normalised, and only with them.
        assert meta["env_id"].startswith("SoftArm/") and (norm is not None) == meta["normalized"]


def test_convert_turns_a_trusted_legacy_model_into_the_safe_format(tiny_sac_run, tmp_path, capsys):
    """A model as saved before the safe format: pickled VecNormalize, no policy description."""
    from baselines.convert import main as convert_main

    trusted, meta, norm = load_policy(tiny_sac_run / "final_model.zip", trust_pickle=True)
    legacy = tmp_path / "legacy.zip"
    shutil.copy(tiny_sac_run / "final_model.zip", legacy)
    norm.save(str(tmp_path / "legacy_vecnormalize.pkl"))
    (tmp_path / "legacy.json").write_text(json.dumps(
        {k: v for k, v in meta.items() if k not in ("policy", "policy_kwargs", "normalized")}))
    with pytest.raises(ValueError, match="policy must be one of"):
        load_policy(legacy)
    assert convert_main([str(legacy), "--check-episodes", "1", "--remove-pickle"]) == 0
    assert "actions identical on 100 observations (max difference 0)" in capsys.readouterr().out
    assert not (tmp_path / "legacy_vecnormalize.pkl").exists()
    policy, converted, safe_norm = load_policy(legacy)
    np.testing.assert_array_equal(safe_norm.obs_rms.mean, norm.obs_rms.mean)
    assert converted["policy"] == "MlpPolicy" and converted["normalized"] is True
