//! # surgbench-chainmail: the generalized 3D chain-mail guidewire
//!
//! The spatially varying six-DOF guidewire of the chain-mail seed paper
//! ("generalized 3D chain-mails", after Gibson 1997, *3D ChainMail*, and
//! Li & Brodlie 2003, *Soft object modelling with generalised ChainMail*),
//! implemented as written: a geometric model with no mass, no forces and no
//! energy, only valid boxes between neighbours ([`rules::valid_box`]),
//! propagation of moves along the chain, relaxation towards the
//! shape-preserving position, SDF collision with the paper's friction
//! factor, a per-step blood-flow displacement and the paper's haptic force.
//! SI units throughout (m, s, N, Pa, kg, rad).
//!
//! The harness calls [`ChainmailFactory`] (id `chainmail`). What the model
//! is and is not:
//! - the paper writes the boxes axis-aligned in **world axes** (`frame=world`);
//!   that rule is not rotation-invariant (rigidly moving a scene changes the
//!   answer, by 1.4 mm in the test) and keeps every link within about
//!   `atan(beta)` of its rest direction, so the wire cannot follow a curved
//!   vessel. The default `frame=clamp` aligns the boxes with the base clamp: the
//!   paper's rule exactly on scenes whose rod starts along +x (every rod
//!   statics scene), and it moves rigidly with the scene, as the harness's
//!   conformance suite requires of every model;
//! - `frame=link` ([`BoxFrame::Link`], the default for a rod with rest
//!   curvature) puts the boxes and rest offsets in each sponsor link's body
//!   frame turned by the rest curvature, resolves wall contact inside the
//!   relaxation iterations and holds a pre-curved (J) rest shape exactly.
//!   Its boxes still bound each link's bend by about `atan(beta)`; with the
//!   weight-calibrated `beta` the default nitinol body may bend by ~0.2 deg
//!   per 5 mm link, so it cannot follow a 35 mm aortic arch: the wall then
//!   compresses/stretches links past the harness's 5 % watchdog;
//!   After friction, one length-restoring pass (boxes swept from the clamp,
//!   then the wall) keeps friction from compressing links; on
//!   `coronary-tortuous` (`beta_mapping=navigation`, 40 segments) the stretch
//!   watchdog still trips at 43.7 s: the tip meets the wall ~25 deg head-on
//!   while its box lets it turn ~6 deg from its neighbour, so no position
//!   of the tip satisfies both box and wall and the wall wins (tip link
//!   -7.9 %);
//! - gravity is a displacement `g dt^2` per step, so a sag is an equilibrium
//!   of that displacement against the boxes and the relaxation: it depends
//!   on `dt`, `iterations` and `segments`, not only on the material;
//! - `beta` comes from the material by [`mapping`]: by default
//!   (`beta_mapping=weight`) with one constant calibrated on a 0.1 m gravity
//!   cantilever that no comparison scores ([`calibration::calibration_scene`]); `beta_mapping=navigation` bounds
//!   each link's bend by `Delta eps_y / r`, the largest elastic curvature of
//!   the core (nothing fitted): it can follow a vessel but no longer sags
//!   like the cantilever (see [`mapping`] for both and their trade-off);
//! - no twist dynamics: a base rotation turns the first tip element about the
//!   clamp axis and the frames carry the rotation rigidly; dead tip forces
//!   and torques have no meaning here and are refused;
//! - the hand force is the paper's `F_feedback = k (F_friction + F_internal)`
//!   with `k = E A / Delta` by default (extra `haptic_k`), on the hand along
//!   the friction corrections and `k (l_t - l_{t-1})` along the first link
//!   (a compressed first link pushes the hand back). A sticking contact
//!   removes a whole step's motion, so with the default `k` it gives
//!   forces of kN: the paper's formula has no physical scale.
//!
//! Measured (tests in `tests/rules.rs`): on the calibration cantilever,
//! settled gravity sag over Euler–Bernoulli is 1.000 at the calibration
//! fidelity (segments 20, dt 0.01 s, 10 sweeps), 0.138 at 40 segments,
//! 0.685 at dt 1 ms, 0.782 at 40 sweeps: the fit holds at the fidelity it
//! was made at and nowhere else (resolution-bound); a rigid motion of a scene changes the world-axis answer by
//! 1.4 mm and the base-axis answer by 2e-16 m.
//!
//! ```
//! use surgbench_chainmail::ChainmailFactory;
//! use surgbench_core::{DeviceCommand, Fidelity, ModelFactory, RodBody, Scene, Vec3};
//! let mut scene = Scene::empty("sag");
//! scene.bodies.push(RodBody::uniform(0.2, 5e-4, 5e10, 0.3, 6450.0).into());
//! scene.gravity = Vec3::new(0.0, 0.0, -9.81);
//! let mut model = ChainmailFactory.build(&scene, &Fidelity::default()).unwrap();
//! model.step(0.01, &DeviceCommand::default()).unwrap();
//! assert!(model.observe().rods[0].tip().z < 0.0);
//! ```

pub mod calibration;
mod factory;
pub mod mapping;
pub mod rules;
pub mod volume;
pub mod wire;

pub use factory::{
    ChainmailFactory, DEFAULT_DT, DEFAULT_ITERATIONS, DEFAULT_SEGMENTS, DEFAULT_VESSEL_BETA, DEFAULT_VESSEL_SLACK,
    DEFAULT_VESSEL_SPACING,
};
pub use rules::LinkParams;
pub use wire::{BoxFrame, ChainmailWire, WireConfig};
