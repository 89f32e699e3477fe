"""`surgbench.Simulation`: step any model by hand and read its state."""

import threading
import time

import numpy as np
import pytest

import surgbench


def test_state_observe_and_hand_force_have_the_documented_shapes():
    sim = surgbench.Simulation("cantilever-gravity", "der", settings={"segments": 20})
    assert sim.state().shape == (22, 3)
    sim.step(n=10)
    assert sim.steps == 10
    assert sim.t == pytest.approx(10 * sim.dt, rel=1e-12)
    o = sim.observe()
    assert o["rods"][0]["nodes"].shape == (22, 3)
    assert o["rods"][0]["arclength"].shape == (22,)
    np.testing.assert_array_equal(o["rods"][0]["nodes"], sim.state())
    assert sim.hand_force.shape == (3,) and sim.hand_torque.shape == (3,)
    assert set(o["energy"]) == {"kinetic", "elastic", "external"}


def test_stepping_by_hand_matches_a_scored_run():
    """The same model, scene and step count give the same final state by
    hand as through `run_one` (the runner adds only the scoring)."""
    r = surgbench.run_one("cantilever-gravity", "der", settings={"segments": 10})
    sim = surgbench.Simulation("cantilever-gravity", "der", settings={"segments": 10})
    sim.step(n=r.steps)
    np.testing.assert_array_equal(sim.state(), r.final_state)


def test_a_tissue_and_a_command_by_hand():
    sim = surgbench.Simulation("block-compression", "fem", settings={"mesh_level": 0})
    n = sim.state().shape[0]
    sim.step(n=5, command={"load": 0.5})
    moved = np.abs(sim.state() - sim.observe()["tissues"][0]["rest"]).max()
    assert sim.state().shape == (n, 3) and moved > 0
    with pytest.raises(surgbench.UsageError, match="unknown command key"):
        sim.step(command={"push": 1.0})


def test_step_releases_the_gil():
    """A Python thread that sleeps 1 ms at a time keeps counting while
    `step` runs. Were the GIL held through `step`, it could count at most
    once or twice (once when `step` returns and the GIL is handed over)."""
    sim = surgbench.Simulation("cantilever-gravity", "der", settings={"segments": 80})
    sim.step(n=1)
    count, stop = [0], threading.Event()

    def tick():
        while not stop.is_set():
            time.sleep(0.001)
            count[0] += 1

    # One call long enough for a 1 ms ticker to count many times (~0.3 s).
    start = time.perf_counter()
    sim.step(n=100)
    per_step = (time.perf_counter() - start) / 100
    steps = max(100, int(0.3 / per_step))
    t = threading.Thread(target=tick)
    t.start()
    time.sleep(0.01)
    before = count[0]
    start = time.perf_counter()
    sim.step(n=steps)
    spent = time.perf_counter() - start
    ticks = count[0] - before
    stop.set()
    t.join()
    assert ticks >= 10, f"{ticks} ticks in {spent:.3f} s of stepping ({steps} steps)"
