"""`surgbench.run_one` gives what `surgbench run-one` writes: the same
numbers, bit for bit, as attributes and numpy arrays."""

import csv
import json

import numpy as np
import pytest

import surgbench

SERIES = ["t", "tip_x", "tip_y", "tip_z", "hand_fx", "hand_fy", "hand_fz", "hand_tx", "hand_ty", "hand_tz"]


def read_cli_run(folder):
    """summary.json, observables.csv as columns and final_state.csv as rows."""
    summary = json.loads((folder / "summary.json").read_text())
    with open(folder / "observables.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    series = {k: np.array([float(r[k]) if r[k] else np.nan for r in rows]) for k in rows[0]}
    state = np.loadtxt(folder / "final_state.csv", delimiter=",", skiprows=1, ndmin=2)
    return summary, series, state


@pytest.mark.parametrize(
    "scenario, model, params, settings",
    [
        ("cantilever-gravity", "der", {"youngs_modulus": 2e10}, {"segments": 10}),
        ("cantilever-tip-load", "pbd-rod", {}, {"segments": 10, "solver": "direct"}),
        ("block-compression", "fem", {}, {"mesh_level": 0, "material_law": "linear"}),
    ],
)
def test_run_one_equals_the_cli_bit_for_bit(cli, tmp_path, scenario, model, params, settings):
    r = surgbench.run_one(scenario, model, params=params, settings=settings)
    args = ["run-one", "--scenario", scenario, "--model", model, "--out", str(tmp_path / "one")]
    for k, v in params.items():
        args += ["--param", f"{k}={v!r}"]
    for k, v in settings.items():
        args += ["--fidelity", f"{k}={v}"]
    cli(*args)
    summary, series, state = read_cli_run(tmp_path / "one")

    assert r.status == summary["status"] == "ok", (r, summary["reason"])
    # Errors: the same floats (JSON keeps every bit of an f64).
    assert r.errors == summary["errors"]
    assert r.primary == summary["errors"][summary["primary_error"]]
    for key in ("steps", "end", "fidelity", "params", "primary_error", "stable"):
        assert getattr(r, key) == summary[key], key
    # Time series and final state: the same floats (the CSVs print the
    # shortest text that reads back to the same f64).
    for k in SERIES + ["energy", "error", "ref_tip_x", "ref_tip_y", "ref_tip_z", "force", "ref_force", "depth"]:
        np.testing.assert_array_equal(r.observables[k], series[k], err_msg=k)
    np.testing.assert_array_equal(r.final_state, state[:, 5:8])
    np.testing.assert_array_equal(r.final_rest, state[:, 2:5])
    np.testing.assert_array_equal(r.final_body, state[:, 0].astype(np.int64))


def test_arrays_have_the_documented_shapes_and_units():
    r = surgbench.run_one("cantilever-gravity", "der", settings={"segments": 20})
    samples = r.observables["t"].shape
    assert len(samples) == 1 and samples[0] > 1
    for k, a in r.observables.items():
        assert a.dtype == np.float64 and a.shape == samples, (k, a.shape)
    # A 20-edge DER rod has 22 nodes (a ghost node behind the clamp holds
    # its tangent); positions in m.
    assert r.final_state.shape == (22, 3) and r.final_state.dtype == np.float64
    np.testing.assert_allclose(r.final_rest[-1], [r.params["length"], 0.0, 0.0], rtol=0, atol=1e-15)
    # The clamp holds node 0; the tip sags along -z under gravity by the
    # scene's reference (m): tip error is relative to it.
    assert np.all(r.final_state[:2] == r.final_rest[:2])
    assert r.final_state[-1, 2] < 0
    # The hand carries the rod's weight rho A L g (N): the force on the
    # hand points down. The sampled series is in time order (s).
    weight = r.params["density"] * np.pi * r.params["radius"] ** 2 * r.params["length"] * r.params["gravity"]
    assert r.observables["hand_fz"][-1] == pytest.approx(-weight, rel=1e-6)
    assert np.all(np.diff(r.observables["t"]) > 0)


def test_bad_input_is_a_usage_error():
    with pytest.raises(surgbench.UsageError, match="unknown scenario"):
        surgbench.run_one("no-such-scene", "der")
    with pytest.raises(surgbench.UsageError, match="segmentz"):
        surgbench.run_one("cantilever-gravity", "der", settings={"segmentz": 10})
    with pytest.raises(surgbench.UsageError, match="youngs_modulus"):
        surgbench.run_one("cantilever-gravity", "der", params={"youngs_modulus": -1.0})
    with pytest.raises(surgbench.UsageError, match="cg"):
        surgbench.run_one("block-compression", "fem", settings={"solver": "cgg"})


def test_a_model_that_cannot_run_the_scene_is_unsupported_with_the_reason():
    r = surgbench.run_one("block-compression", "der")
    assert r.status == "unsupported", r
    assert "exactly one rod" in r.reason, r.reason
