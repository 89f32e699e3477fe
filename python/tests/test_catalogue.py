"""`surgbench.scenarios()` and `surgbench.models()`: what `surgbench list`
shows, as dicts."""

import surgbench


def test_scenarios_give_parameters_with_units_ranges_and_defaults():
    scenes = {s["id"]: s for s in surgbench.scenarios()}
    cg = scenes["cantilever-gravity"]
    assert cg["family"] == "rod"
    assert cg["primary_error"] == "tip_error_rel"
    params = {p["name"]: p for p in cg["params"]}
    assert params["youngs_modulus"]["unit"] == "Pa"
    assert params["length"]["unit"] == "m"
    assert params["gravity"]["default"] == 9.81
    assert params["gravity"]["range"] == "> 0", params["gravity"]
    assert params["gravity"]["doc"]
    # Every family is listed: the needle's scenes and the rod x tissue pairs too.
    assert scenes["needle-straight"]["family"] == "coupled"
    assert scenes["catheter-compliant-vessel"]["family"] == "pair"
    assert {s["family"] for s in scenes.values()} == {"rod", "tissue", "coupled", "pair"}


def test_models_give_capabilities_and_settings_by_name():
    models = {m["id"]: m for m in surgbench.models()}
    assert {"der", "chainmail", "pbd-rod", "pbd-tissue", "fem", "meshless", "needle", "multibody"} <= models.keys()
    fem = models["fem"]
    assert fem["family"] == "tissue"
    assert "tissue" in fem["capabilities"]
    settings = {k["name"]: k for k in fem["settings"]}
    # A choice lists its names, as `surgbench list` does.
    assert "corotational" in settings["material_law"]["values"], settings["material_law"]
    assert models["der"]["krate"] == "surgbench_der"
