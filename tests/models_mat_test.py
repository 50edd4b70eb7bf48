"""MODELS.mat (docs/file-formats.md) from ``heliquad fit --mat`` and ``heliquad identify
--mat``: a MATLAB struct array holding what MODELS.json holds, read back with scipy."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
import scipy.io

from heliquad.host.estimate.fit import TfModel
from heliquad.host.records import paper
from heliquad.host.records.models import (ModelsFile, StoredModel, write_models_json,
                                           write_models_mat)

ROLL = paper.MODELS["roll"][(0, 2)]
FIXED_FIELDS = ("order", "num", "den", "delay_s", "stable", "degenerate")


def heliquad(*args):
    return subprocess.run([sys.executable, "-m", "heliquad.host.cli.parser", *map(str, args)],
                          capture_output=True, text=True, timeout=300)


def _same(mat_value, json_value):
    """A number of the .mat against MODELS.json, where null stands for a value that is not
    finite."""
    value = float(mat_value)
    if json_value is None:
        return not math.isfinite(value)
    return value == json_value


def assert_mat_matches_json(mat_path, json_path):
    doc = json.loads(json_path.read_text())
    n = len(doc["models"])
    # a struct array (not a cell array of structs), and a double index
    assert scipy.io.whosmat(mat_path) == [("models", (1, n), "struct"),
                                          ("recommended", (1, 1), "double")]
    raw = scipy.io.loadmat(mat_path, mat_dtype=True)
    metrics = tuple(doc["models"][0]["metrics"])
    assert raw["models"].dtype.names == FIXED_FIELDS + metrics + ("dc_gain",)
    rec = doc["recommended"]
    assert raw["recommended"][0, 0] == (0 if rec is None else rec + 1)
    for i in range(n):
        element = raw["models"][0, i]
        assert element["stable"].dtype == bool and element["degenerate"].dtype == bool
        assert element["num"].shape == (1, len(doc["models"][i]["num"]))     # row vectors
        assert element["order"].dtype == np.float64 and element["order"].shape == (1, 2)
    models = np.atleast_1d(scipy.io.loadmat(mat_path, squeeze_me=True,
                                            struct_as_record=False)["models"])
    assert len(models) == n
    for m, entry in zip(models, doc["models"]):
        assert list(np.atleast_1d(m.order)) == entry["order"]
        assert list(np.atleast_1d(m.num)) == entry["num"]
        assert list(np.atleast_1d(m.den)) == entry["den"]
        assert m.delay_s == entry["delay_s"]
        assert bool(m.stable) is entry["stable"] and bool(m.degenerate) is entry["degenerate"]
        for name, value in entry["metrics"].items():
            assert _same(getattr(m, name), value), name
        assert _same(m.dc_gain, entry["dc_gain"])
    return doc


def roll_points(path, delay_s=0.0, n=12):
    omega = 2 * np.pi * np.logspace(math.log10(0.5), math.log10(4.5), n)
    F = np.polyval(ROLL[0], 1j * omega) / np.polyval(ROLL[1], 1j * omega) * np.exp(-1j * omega * delay_s)
    np.savetxt(path, np.column_stack([omega, np.abs(F), np.unwrap(np.angle(F)), 0.01 * np.abs(F)]),
               delimiter=",", header="omega_rad_s,magnitude,phase_rad,sigma", comments="")
    return path


def test_fit_mat_holds_the_models_of_the_json(tmp_path):
    points = roll_points(tmp_path / "points.csv", delay_s=0.02)
    models, mat = tmp_path / "models.json", tmp_path / "models.mat"
    res = heliquad("fit", points, "--order", "0/2", "--order", "0/3", "--order", "2/4",
                   "--delay", "--json", models, "--mat", mat)
    assert res.returncode == 0, res.stderr
    assert f"wrote {mat}" in res.stdout
    doc = assert_mat_matches_json(mat, models)
    assert len(doc["models"]) == 3 and doc["recommended"] == 0
    loaded = scipy.io.loadmat(mat, squeeze_me=True, struct_as_record=False)
    best = loaded["models"][int(loaded["recommended"]) - 1]
    assert best.delay_s == pytest.approx(0.02, rel=1e-3)
    np.testing.assert_allclose(best.den, ROLL[1], rtol=1e-4)


def test_one_model_and_values_json_writes_as_null(tmp_path):
    # A pole at the origin (dc_gain infinite), an infinite AICc, and no recommendation.
    model = TfModel(order=(0, 2), num=np.array([2.0]), den=np.array([1.0, 3.0, 0.0]),
                    stable=False, metrics={"rms": 0.1, "J": 12.0, "aicc": math.inf,
                                           "n_parameters": 3})
    json_path, mat = tmp_path / "m.json", tmp_path / "m.mat"
    stored = ModelsFile(models=[StoredModel.of(model)], recommended=None, reason="none stable")
    write_models_json(json_path, stored)
    write_models_mat(mat, stored)
    doc = assert_mat_matches_json(mat, json_path)
    assert doc["models"][0]["dc_gain"] is None and doc["models"][0]["metrics"]["aicc"] is None
    one = scipy.io.loadmat(mat, squeeze_me=True, struct_as_record=False)["models"]
    assert one.dc_gain == math.inf and one.order.tolist() == [0, 2]     # one model: one struct


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("mat") / "roll"
    res = heliquad("sweep", "--axis", "roll", "--sil", "--plant", "tf", "--freqs-hz", 0.7, 1.5,
                   3, "--cycles", 4, "--out", out)
    assert res.returncode == 0, res.stdout + res.stderr
    return out


def test_identify_mat_holds_the_models_of_its_json(sweep, tmp_path):
    mat = tmp_path / "roll.mat"
    res = heliquad("identify", sweep, "--order", "0/2", "--order", "0/3", "--mat", mat)
    assert res.returncode == 0, res.stderr
    assert f"wrote {mat}" in res.stdout
    doc = assert_mat_matches_json(mat, sweep / "models.json")
    assert [m["order"] for m in doc["models"]] == [[0, 2], [0, 3]]


def test_identify_writes_no_mat_unless_asked(sweep):
    res = heliquad("identify", sweep, "--order", "0/2")
    assert res.returncode == 0, res.stderr
    assert not list(sweep.glob("*.mat")) and ".mat" not in res.stdout
