//! The harness factory of the needle model: [`NeedleFactory`] (`id = "needle"`).

use crate::model::{CG_TOLERANCE, LcpSolver, NeedleModel};
use surgbench_core::{
    BuildError, Capability, Choice, Family, Fidelity, FidelityKey, Model, ModelFactory, Scene, Settings, Unsupported,
    model::check_capabilities,
};
use surgbench_der::DerRod;
use surgbench_fem::{DynParams, FemModel, Integrator};

/// Needle edges when the fidelity leaves `segments` unset.
pub const DEFAULT_SEGMENTS: usize = 40;
/// Time step (s) when the fidelity leaves `dt` unset: the seed's 1 kHz haptic rate.
pub const DEFAULT_DT: f64 = 1e-3;

/// The needle's settings beyond the common fidelity knobs.
const KEYS: &[FidelityKey] = &[
    FidelityKey::number(
        "threads",
        "tissue assembly threads (default 2); results are identical for any count",
    )
    .whole(1.0, 64.0),
    FidelityKey::choice(
        "lcp_solver",
        "how each trial of the friction-state LCP is solved",
        &[
            Choice::new(
                "schur",
                "default: tissue and needle factored once per step, each trial a dense solve of the Schur complement on the coupling points",
            ),
            Choice::new(
                "cg",
                "the seed's: projected Jacobi-preconditioned CG over the whole coupled system for every trial, no tissue factorization",
            ),
        ],
    ),
    FidelityKey::choice(
        "coupling",
        "how coupling points sit in the tissue mesh",
        &[
            Choice::new(
                "embedded",
                "default: tissue material points embedded in the tets that hold them (barycentric weights)",
            ),
            Choice::new(
                "remesh",
                "the seed's: every coupling point a mesh node, placed by tip remeshing (Algorithm 2) and taken back on withdrawal; the tissue is rebuilt on each new mesh",
            ),
        ],
    ),
    FidelityKey::number(
        "remesh_max_offset",
        "coupling=remesh: how far a snap may move a node, or an edge or face split put its node off its edge or face, in rms edge lengths of the tet holding the point (default: no limit, the seed's rule; 0 keeps the tissue's field exact: tet splits, and splits of the edge or face the point lies on)",
    )
    .at_least(0.0),
    FidelityKey::number(
        "lazy_threshold",
        "tissue Jacobian: rebuild a tet's warped stiffness R K0 R^T only once its rotation has turned more than this angle (rad) since the block was built; while no block changes the step keeps its factorization (default 0: every tet every step; a rotation rule, not the seed's Eq. 12 error bound)",
    )
    .at_least(0.0),
    FidelityKey::number(
        "cg_tolerance",
        "lcp_solver=cg: relative residual each CG solve stops at (default 1e-8)",
    )
    .between(0.0, 1.0),
];

/// The `needle` model: FEM tissue + DER needle, coupling points embedded
/// in tets or made mesh nodes by tip remeshing, stick-slip friction by the
/// seed's LCP.
pub struct NeedleFactory;

impl ModelFactory for NeedleFactory {
    fn id(&self) -> &'static str {
        "needle"
    }
    fn description(&self) -> &'static str {
        "needle insertion (Chentanez 2009): corotational FEM tissue + DER needle, coupling points embedded in tets (or mesh nodes by the seed's tip remeshing), stick-slip LCP by Schur complement (or the seed's CG)"
    }
    fn family(&self) -> Family {
        Family::Coupled
    }
    fn capabilities(&self) -> &'static [Capability] {
        &[
            Capability::Rod,
            Capability::Tissue,
            Capability::NeedleTissue,
            Capability::Insertion,
            Capability::Twist,
            Capability::PressureLoad,
            Capability::MaterialRegions,
        ]
    }
    fn fidelity_keys(&self) -> &'static [FidelityKey] {
        KEYS
    }
    /// 40 needle edges, `dt = 1 ms`, one Newton iteration per step (the
    /// seed's linearly implicit step).
    fn default_fidelity(&self, _scene: &Scene) -> Fidelity {
        Fidelity {
            segments: Some(DEFAULT_SEGMENTS),
            dt: Some(DEFAULT_DT),
            iterations: Some(1),
            ..Default::default()
        }
    }
    /// Needle scenes only (one rod, one tissue, a needle-tissue interaction).
    fn check(&self, scene: &Scene) -> Result<(), Unsupported> {
        check_capabilities(self.id(), self.capabilities(), scene)?;
        if scene.needle.is_none() {
            return Err(Unsupported::new("needle runs needle-insertion scenes only"));
        }
        Ok(())
    }
    fn build_resolved(&self, scene: &Scene, settings: &Settings) -> Result<Box<dyn Model>, BuildError> {
        let f = settings.fidelity();
        if f.iterations != Some(1) {
            return Err(BuildError::bad(
                "iterations",
                "the coupled step is linearly implicit: iterations = 1",
            ));
        }
        let dt = f.dt.unwrap_or(DEFAULT_DT);
        let needle = scene.needle.expect("checked");
        let body = scene.rods().next().expect("validated: one rod");
        let tissue = scene.tissues().next().expect("validated: one tissue");
        let segments = f.segments.unwrap_or(DEFAULT_SEGMENTS);
        let mut rod = DerRod::from_body(body, segments)?;
        rod.gravity = scene.gravity;
        // Backward Euler, not the seed's Newmark (beta = 1/4): the average
        // acceleration rule does not damp the highest modes, and under the
        // hard coupling constraints it rings. Measured on `needle-straight`
        // (defaults): with Newmark the constraint forces alternate step to
        // step and the energy watchdog trips at t = 1.70 s; with backward
        // Euler the run completes, 1.03 LCP trials per step.
        let params = DynParams {
            integrator: Integrator::BackwardEuler,
            // Range declared on the key (KEYS), checked by `resolve`.
            threads: settings.number_or("threads", 2.0) as usize,
            lazy_threshold: settings.number_or("lazy_threshold", 0.0),
            ..DynParams::default()
        };
        let fem =
            FemModel::new(tissue, scene.gravity, dt, params).map_err(|e| BuildError::bad("tissue", e.to_string()))?;
        // A needle may start inside the tissue (pre-inserted), its guide
        // sleeve may not: the clamp point (node 1, arclength 0) is outside.
        if crate::coupling::locate(&tissue.mesh.tets, &tissue.mesh.nodes, &rod.node(1)).is_some() {
            return Err(BuildError::bad(
                "needle",
                "the needle's base (guide sleeve) starts inside the tissue; it must stay outside",
            ));
        }
        let spacing = body.length / segments as f64;
        let cg = settings.pick("lcp_solver", &[("schur", false), ("cg", true)], false)?;
        if !cg && settings.number("cg_tolerance").is_some() {
            return Err(BuildError::bad(
                "cg_tolerance",
                "applies to lcp_solver=cg only; the Schur complement solves each trial directly",
            ));
        }
        let solver = match cg {
            false => LcpSolver::Schur,
            true => LcpSolver::Cg {
                tolerance: settings.number_or("cg_tolerance", CG_TOLERANCE),
            },
        };
        let remesh = settings.pick("coupling", &[("embedded", false), ("remesh", true)], false)?;
        let max_offset = settings.number("remesh_max_offset");
        if !remesh && max_offset.is_some() {
            return Err(BuildError::bad(
                "remesh_max_offset",
                "applies to coupling=remesh only; embedded points change no mesh",
            ));
        }
        let mut model = NeedleModel::new(fem, rod, tissue.mesh.tets.clone(), needle, spacing, dt).with_solver(solver);
        if !tissue.regions.is_empty() {
            model = model.with_layers(tissue);
        }
        if !remesh {
            return Ok(Box::new(model));
        }
        // 0 means exact up to round-off: a point computed on a face or edge
        // lies off it by ~1e-16 of the edge length.
        let max_offset = max_offset.map_or(f64::INFINITY, |f| f.max(1e-9));
        let model = model
            .with_remeshing(tissue.clone(), scene.gravity, max_offset)
            .map_err(|e| BuildError::bad("coupling", e.to_string()))?;
        Ok(Box::new(model))
    }
}
