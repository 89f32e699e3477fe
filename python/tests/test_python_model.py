"""A model written in Python runs through the same scenarios, scoring,
watchdogs and report as the Rust models."""

import csv

import numpy as np
import pytest

import mass_spring
import models_for_tests
import surgbench

mass_spring.register()
models_for_tests.register_all()


def test_the_example_model_is_listed_as_python():
    models = {m["id"]: m for m in surgbench.models()}
    m = models["py-mass-spring"]
    assert m["krate"] == "python"
    assert m["description"].startswith("(Python)")
    assert m["family"] == "rod" and set(m["capabilities"]) == {"rod", "tip-force"}


def test_the_example_model_meets_euler_bernoulli_at_second_order():
    """The mass-spring rod against the scene's references. Its bending
    energy is a second-order discretisation of int EI kappa^2/2 ds (the
    clamp's half edge included) and its loads are lumped at nodes, so the
    tip error falls as h^2 (measured: 1.0e-2, 2.5e-3, 6.2e-4 at 10, 20, 40
    segments, orders 2.00 and 2.01)."""
    errors = {}
    for n in (10, 20, 40):
        r = surgbench.run_one("cantilever-gravity", "py-mass-spring", settings={"segments": n})
        assert r.status == "ok", r
        assert r.end == "settled", r
        errors[n] = r.errors["tip_error_vs_euler_bernoulli_rel"]
        # Scored against the elastica too, like every rod model.
        assert r.errors["tip_error_rel"] > 0
    orders = [np.log2(errors[a] / errors[b]) for a, b in ((10, 20), (20, 40))]
    # Second order: the fitted orders are 2 to within 10 % (measured 2.00, 2.01).
    assert all(1.8 < p < 2.2 for p in orders), (errors, orders)
    # At 40 segments the tip is within 0.1 % of w(L) = q L^4 / (8 EI) (measured 6.2e-4).
    assert errors[40] < 1e-3, errors


def test_a_python_model_that_raises_is_a_failed_run_with_its_message():
    r = surgbench.run_one("cantilever-gravity", "py-raises")
    assert r.status == "failed", r
    assert "boom at step 3" in r.reason, r.reason
    assert "py-raises" in r.reason


def test_unsupported_and_diverged_from_python():
    r = surgbench.run_one("cantilever-gravity", "py-refuses")
    assert r.status == "unsupported", r
    assert r.reason.endswith("this model runs no scene at all"), r.reason
    r = surgbench.run_one("cantilever-gravity", "py-diverges")
    assert r.status == "unstable", r
    assert "the springs tore" in r.reason, r.reason
    # A scene needing what the model lacks is refused before it is built.
    r = surgbench.run_one("block-compression", "py-mass-spring")
    assert r.status == "unsupported", r
    assert "tissue" in r.reason, r.reason


def test_python_models_run_in_a_comparison_and_the_report_says_python(tmp_path):
    comparison = tmp_path / "py.toml"
    comparison.write_text(
        'name = "py"\n'
        'description = "Python models beside DER"\n'
        'models = ["der", "py-mass-spring", "py-raises"]\n'
        "repeats = 1\n"
        "timeout_s = 120\n"
        "[[scenario]]\n"
        'id = "cantilever-gravity"\n'
        "sweep = { segments = [10, 20] }\n"
        "quick_sweep = { segments = [10] }\n"
    )
    out = tmp_path / "report"
    assert surgbench.run(str(comparison), quick=True, out=out) == out
    with open(out / "results.csv", newline="") as f:
        rows = {r["model"]: r for r in csv.DictReader(f)}
    assert set(rows) == {"der", "py-mass-spring", "py-raises"}
    assert rows["der"]["status"] == "ok"
    assert rows["py-mass-spring"]["status"] == "ok"
    # The same number as run in this process (the child is the same code).
    here = surgbench.run_one("cantilever-gravity", "py-mass-spring", settings={"segments": 10})
    assert float(rows["py-mass-spring"]["tip_error_rel"]) == here.errors["tip_error_rel"]
    assert rows["py-raises"]["status"] == "failed"
    assert "boom at step 3" in rows["py-raises"]["reason"]
    page = (out / "index.html").read_text()
    assert "models written in Python" in page
    assert "py-mass-spring: (Python) quasi-static mass-spring rod" in page
    # Registered in this process but not in the comparison: not listed.
    assert "py-diverges" not in page


def test_bad_registrations_are_usage_errors():
    with pytest.raises(surgbench.UsageError, match="already registered"):
        surgbench.register_model(models_for_tests.RaisesInStep, id="der", description="x", defaults={"dt": 1e-3})
    with pytest.raises(surgbench.UsageError, match="unknown capability"):
        surgbench.register_model(
            models_for_tests.RaisesInStep, id="py-x", description="x", capabilities=["wings"], defaults={"dt": 1e-3}
        )
    with pytest.raises(surgbench.UsageError, match="dt"):
        surgbench.register_model(models_for_tests.RaisesInStep, id="py-y", description="x", defaults={})
