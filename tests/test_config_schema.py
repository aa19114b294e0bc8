"""The JSON Schema of case files (`taichi-sph schema`): the shipped docs/config.schema.json is what the
command prints, and every case file of configs/ validates against it (and through the models)."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from taichi_sph.config.load import load_config, read_yaml
from taichi_sph.config.schema import json_schema
from taichi_sph.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
CASES = [p for p in sorted((ROOT / "configs").glob("*.yaml")) if "config" not in read_yaml(p)]  # no sweep files


def test_shipped_schema_is_current():
    r = subprocess.run([sys.executable, "-m", "taichi_sph.cli", "schema"], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    shipped = (ROOT / "docs" / "config.schema.json").read_text()
    assert r.stdout == shipped, "run: taichi-sph schema --out docs/config.schema.json"
    assert json.loads(shipped) == json_schema()


@pytest.mark.parametrize("path", CASES, ids=[p.stem for p in CASES])
def test_case_files_validate_against_the_schema(path):
    jsonschema = pytest.importorskip("jsonschema")
    validator = jsonschema.Draft202012Validator(json_schema())
    data = read_yaml(path)
    errors = sorted(validator.iter_errors(data), key=lambda e: list(e.path))
    assert not errors, f"{path.name}: {errors[0].message} at {list(errors[0].path)}"
    for variant in [None, *(data.get("variants") or {})]:
        try:
            load_config(path, [], variant)
        except InputError as exc:  # a second stage reads its first stage's run file, not made here
            assert "wcsph.soil.start_from.run" in str(exc)
            load_config(path, ["wcsph.soil.start_from=null"], variant)


def test_schema_rejects_what_the_models_reject():
    jsonschema = pytest.importorskip("jsonschema")
    validator = jsonschema.Draft202012Validator(json_schema())
    good = {"dx": 0.02, "end_time": 0.1, "tank": {"size": [0.2, 0.2]}, "water": [{"min": [0, 0], "max": [0.2, 0.1]}]}
    assert validator.is_valid(good)
    for bad in ({**good, "wave_height": 1}, {**good, "dx": -1}, {**good, "mode": "sph"}, {**good, "dt": "fast"},
                {**good, "isph": {"ppe": {"type": "amg"}}}, {k: v for k, v in good.items() if k != "tank"}):
        assert not validator.is_valid(bad), bad
