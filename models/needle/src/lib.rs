//! # surgbench-needle: needle insertion (the needle seed)
//!
//! Chentanez, Alterovitz, Ritchie, Cho, Hauser, Goldberg, Shewchuk, O'Brien,
//! "Interactive Simulation of Surgical Needle Insertion and Steering",
//! SIGGRAPH 2009: the corotational FEM tissue of `surgbench-fem` and the
//! discrete elastic rod of `surgbench-der` as the needle, one linearly
//! implicit step each (the seed's Algorithm 1), coupled monolithically at
//! points along the shaft with stick-slip friction (the friction-state LCP,
//! [`lcp`], the seed's Algorithm 3) and a cutting force at the tip.
//!
//! * Coupling points are tissue material points embedded in the tets that
//!   contain them (barycentric weights, [`coupling`]), held on the needle
//!   at an arclength: always in the two normal directions, along the needle
//!   while STATIC, with the known friction force while sliding. A shaft
//!   point joins every needle edge length of needle inside the tissue; the
//!   tip point is the tissue at the end of the cut channel: it cuts
//!   (`f_cut` against the tip's advance) while it slides forward, and it
//!   cannot pull (retracting, the channel end stays behind until the tip
//!   comes back to it).
//! * The LCP is solved through the Schur complement on the coupling points:
//!   the tissue block's Cholesky factor (one per step, reused while no
//!   Jacobian block changed) and the needle's banded factor give the
//!   Delassus matrix `W` (the tissue's share `Y^T Y` from sparse forward
//!   solves `Y = L^-1 P J^T` along the factor's elimination-tree paths,
//!   the needle's by one banded solve per point and axis), and every
//!   trial is a small dense solve. The tissue's columns `Y` stay while its
//!   factor does (module `gram`: a lazy Jacobian keeps it for many steps, and
//!   only new points are solved), and the tissue's own solve is one
//!   forward sweep, from which the LCP reads the points' uncoupled motion
//!   `Y^T L^-1 P r`, and one backward sweep once the constraint forces are
//!   taken off (`FemModel::forward_half`, `backward_half`).
//! * Or, with `lcp_solver = "cg"`, by the seed's solver: every trial a
//!   projected Jacobi-preconditioned CG over the whole coupled system
//!   ([`pcg`]), with no tissue factorization. The two agree to the CG's
//!   tolerance, step by step (`tests/cg_solver.rs`).
//! * The tissue steps by backward Euler, not the seed's Newmark (see
//!   [`factory`]: measured ringing under the hard constraints).
//! * `Observation::hand_force` is, as for every model, the force the needle
//!   exerts on the hand (N): inserting, it points along -x.
//!
//! * A bevel tip (seed Sec. 3.5) cuts its new channel end `d tan(psi)`
//!   beside the tip along the tip edge's material axis m_2. With embedded
//!   points the tissue around the tip distorts: a new channel end that no
//!   deformed tet contains strictly is found within a quarter tet
//!   ([`model::TIP_SLACK`]); the diagnostics count such cuts and lost tips.
//! * A needle may start inside the tissue (a channel cut before the run).
//! * The control timeline's base rotation twists the needle at its clamp
//!   (the DER rod's torsion carries it to the tip): a bevel tip steers.
//!
//! * Viscous shaft friction (seed Sec. 3.3) is implicit: a sliding point's
//!   row of the LCP gains `1 / c_i` on the diagonal ([`lcp`]).
//!
//! * With `coupling = "remesh"` every coupling point (and the entry) is a
//!   node of the tissue mesh instead, placed by the seed's tip remeshing
//!   (Algorithm 2, [`remesh`]) in material coordinates: the tip's node
//!   moves with the tip (its operation taken back and the best one for
//!   the new point applied), shaft points keep theirs, the needle leaving
//!   the tissue takes every operation back. The tissue continues on each
//!   new mesh with its state interpolated (`FemModel::remeshed`, rebuilt
//!   rather than updated in place: issue 18, item 4, is open).
//! * [`reparam`]: Akima interpolation and the seed's edge resampling rule,
//!   for reparameterizing the needle (not yet used by the model).
//!
//! The tissue's lazy Jacobian is fem's rotation rule (`lazy_threshold`):
//! a tet's warped stiffness is kept until its rotation has turned past the
//! threshold, and the step's factorization while no block changed.
//!
//! Not yet (issues 17 and 18): the seed's own lazy rule (its Eq. 12 error
//! bound), in-place matrix updates on remeshing, the needle's
//! reparameterization.
//!
//! Units are SI: m, kg, s, N, Pa.

pub mod coupling;
pub mod factory;
mod gram;
pub mod lcp;
pub mod model;
pub mod pcg;
pub mod regions;
pub mod remesh;
pub mod reparam;

pub use factory::NeedleFactory;
pub use model::{LcpStats, NeedleModel, Point};
