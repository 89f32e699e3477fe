"""Python models that misbehave on purpose, for the tests: one raises in
`step`, one refuses every scene, one reports divergence. Each wraps the
mass-spring example so that it builds and observes like a real rod."""

import surgbench
from mass_spring import MassSpringRod


class RaisesInStep(MassSpringRod):
    """Raises an ordinary exception (a bug) at its third step."""

    def build(self, scene):
        super().build(scene)
        self.calls = 0

    def step(self, dt, command):
        self.calls += 1
        if self.calls == 3:
            raise ValueError("boom at step 3")
        return super().step(dt, command)


class RefusesEveryScene(MassSpringRod):
    """Says it cannot run the scene."""

    def build(self, scene):
        raise surgbench.Unsupported("this model runs no scene at all")


class DivergesAtOnce(MassSpringRod):
    """Reports that its state is no longer usable at the first step."""

    def step(self, dt, command):
        raise surgbench.Diverged("the springs tore")


def register_all():
    """Register the three under `py-raises`, `py-refuses`, `py-diverges`."""
    for cls, id in (
        (RaisesInStep, "py-raises"),
        (RefusesEveryScene, "py-refuses"),
        (DivergesAtOnce, "py-diverges"),
    ):
        surgbench.register_model(
            cls,
            id=id,
            description=f"test model: {cls.__doc__.strip()}",
            family="rod",
            capabilities=["rod", "tip-force"],
            defaults={"segments": 10, "dt": 1e-3},
        )
