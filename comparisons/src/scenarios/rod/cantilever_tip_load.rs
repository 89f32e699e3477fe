//! `cantilever-tip-load`: a clamped rod bent far by a dead tip force,
//! scored against the elastica (shooting, checked against Bisshopp &
//! Drucker 1945).

use super::cantilever_gravity::CantileverRun;
use super::{DENSITY, DURATION, LENGTH, POISSON, RADIUS, RodCase, SEGMENTS, SETTLE, YOUNG, rod_case};
use crate::params;
use crate::references::elastica;
use crate::scenario::{Declared, Inputs, ParamSet, ParamSpec, Range, ScenarioInfo, ScenarioRun, UsageError};
use surgbench_core::{Family, Vec3};

/// Large deflection under a dead tip force (tip angle up to ~70 degrees).
pub const CANTILEVER_TIP_LOAD: Declared<TipLoadParams> = Declared {
    info: ScenarioInfo {
        id: "cantilever-tip-load",
        description: "clamped rod, large deflection under a dead tip force",
        family: Family::Rod,
        reference: "elastica by shooting (1e-10), checked against Bisshopp & Drucker (1945)",
        primary_error: "tip_error_rel",
        target: crate::scenario::Target::new(
            0.02,
            "2 % of the closed-form tip deflection: a static closed form a rod model should reproduce",
        ),
        params: TipLoadParams::SPECS,
        sweep: SEGMENTS,
        quick: 3,
        mesh: None,
    },
    datasets: None,
    build,
};

params! {
    /// Parameters of `cantilever-tip-load`.
    pub struct TipLoadParams {
        length: LENGTH,
        radius: RADIUS,
        youngs_modulus: YOUNG,
        poisson_ratio: POISSON,
        density: DENSITY,
        tip_force: ParamSpec::new(
            "tip_force",
            0.49,
            "N",
            Range::NonNegative,
            "dead tip force along -z (default: P L^2/(EI) = 2, tip angle 45 deg)",
        ),
        gravity: ParamSpec::new("gravity", 0.0, "m/s^2", Range::NonNegative, "gravity along -z"),
        settle_tol: SETTLE,
        duration: DURATION,
    }
}

fn build(p: &TipLoadParams, _: &Inputs) -> Result<ScenarioRun, UsageError> {
    let c = rod_case!(p);
    let q = c.weight_per_length(p.gravity);
    let force = p.tip_force;
    if q == 0.0 && force == 0.0 {
        return Err(UsageError(
            "cantilever-tip-load needs tip_force > 0 or gravity > 0".into(),
        ));
    }
    let alpha = force * c.length * c.length / c.ei();
    if alpha > 10.0 {
        return Err(UsageError(format!(
            "tip load P L^2/(EI) = {alpha:.3} exceeds 10, past the tabulated elastica range this scenario is checked on"
        )));
    }
    let reference = elastica::solve(c.length, c.ei(), q, force, 4000).map_err(|e| UsageError(e.to_string()))?;
    let mut scene = c.scene(CANTILEVER_TIP_LOAD.info.id, p.duration, p.settle_tol);
    scene.gravity = Vec3::new(0.0, 0.0, -p.gravity);
    let mut body = c.body();
    body.tip_force = Vec3::new(0.0, 0.0, -force);
    scene.bodies.push(body.into());
    Ok(CantileverRun {
        eb_tip: elastica::eb_tip_force(force, c.length, c.ei(), c.length)
            + elastica::eb_uniform_tip(q, c.length, c.ei()),
        reference,
        load: q * c.length + force,
    }
    .into_run(scene))
}
