//! The registry: every model variant and every scenario the harness knows.
//!
//! Adding a model variant is one line in [`models`]: the factory and a
//! description come from the crate. From then on every comparison whose
//! scenarios it supports runs it.

use crate::scenario::{Scenario, UsageError};
use crate::scenarios;
use surgbench_core::ModelFactory;
use surgbench_core::coupling::PairFactory;

/// A registered model factory and the crate it lives in.
pub struct Registered {
    /// The factory.
    pub factory: &'static dyn ModelFactory,
    /// Crate name as a Rust path (`surgbench_der`): the conformance test
    /// checks every crate under `models/` appears here.
    pub krate: &'static str,
}

macro_rules! register {
    ($($krate:ident :: $factory:ident),* $(,)?) => {
        vec![$(Registered { factory: &$krate::$factory, krate: stringify!($krate) }),*]
    };
}

/// Every rod model x every tissue model, composed by the harness's
/// coupling (an instrument in a deformable vessel): id `rod+tissue`. A pair
/// whose halves lack the coupling hooks is registered all the same and
/// refuses its scenes with the reason, so the report's pair matrix shows it.
static PAIRS: [PairFactory; 9] = {
    use surgbench_chainmail::ChainmailFactory as Chainmail;
    use surgbench_der::DerFactory as Der;
    use surgbench_fem::FemFactory as Fem;
    use surgbench_meshless::MeshlessFactory as Meshless;
    use surgbench_pbd::{PbdRodFactory as PbdRod, PbdTissueFactory as PbdTissue};
    [
        PairFactory::new("der+fem", &Der, &Fem),
        PairFactory::new("der+pbd-tissue", &Der, &PbdTissue),
        PairFactory::new("der+meshless", &Der, &Meshless),
        PairFactory::new("chainmail+fem", &Chainmail, &Fem),
        PairFactory::new("chainmail+pbd-tissue", &Chainmail, &PbdTissue),
        PairFactory::new("chainmail+meshless", &Chainmail, &Meshless),
        PairFactory::new("pbd-rod+fem", &PbdRod, &Fem),
        PairFactory::new("pbd-rod+pbd-tissue", &PbdRod, &PbdTissue),
        PairFactory::new("pbd-rod+meshless", &PbdRod, &Meshless),
    ]
};

/// Every registered model, in report order: the single models, then the
/// rod x tissue pairs.
pub fn models() -> Vec<Registered> {
    let mut v = register![
        surgbench_der::DerFactory,
        surgbench_chainmail::ChainmailFactory,
        surgbench_pbd::PbdRodFactory,
        surgbench_pbd::PbdTissueFactory,
        surgbench_fem::FemFactory,
        surgbench_meshless::MeshlessFactory,
        surgbench_needle::NeedleFactory,
        surgbench_multibody::MultibodyFactory,
    ];
    v.extend(PAIRS.iter().map(|p| Registered {
        factory: p,
        krate: "surgbench_core::coupling",
    }));
    v.extend(added().iter().map(|r| Registered {
        factory: r.factory,
        krate: r.krate,
    }));
    if std::env::var("SURGBENCH_FAULTY_MODELS").as_deref() == Ok("1") {
        use crate::faulty;
        for f in [&faulty::PANIC, &faulty::ABORT, &faulty::HANG, &faulty::NONFINITE] {
            v.push(Registered {
                factory: f,
                krate: "faulty",
            });
        }
    }
    v
}

/// The `krate` of a model written in Python ([`register`]).
pub const PYTHON: &str = "python";

/// Models registered while the process runs (the Python bindings'
/// `register_model`), after the built-in ones.
static ADDED: std::sync::RwLock<Vec<Registered>> = std::sync::RwLock::new(Vec::new());

fn added() -> std::sync::RwLockReadGuard<'static, Vec<Registered>> {
    ADDED.read().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Add a model to this process's registry from then on (a model written in
/// Python, `krate` naming where it lives). Its id must be new and a name
/// of lowercase letters, digits and `-`, as every model id.
pub fn register(factory: &'static dyn ModelFactory, krate: &'static str) -> Result<(), UsageError> {
    let id = factory.id();
    let well_formed = id.starts_with(|c: char| c.is_ascii_lowercase())
        && id
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-');
    if !well_formed {
        return Err(UsageError(format!(
            "model id `{id}` must be lowercase letters, digits and `-`, starting with a letter"
        )));
    }
    if models().iter().any(|r| r.factory.id() == id) {
        return Err(UsageError(format!("a model `{id}` is already registered")));
    }
    ADDED
        .write()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .push(Registered { factory, krate });
    Ok(())
}

/// Every scenario, in report order.
pub fn scenarios() -> Vec<&'static dyn Scenario> {
    scenarios::all()
}

/// Look a model up by id.
pub fn model(id: &str) -> Result<&'static dyn ModelFactory, UsageError> {
    let all = models();
    all.iter()
        .find(|r| r.factory.id() == id)
        .map(|r| r.factory)
        .ok_or_else(|| {
            let ids: Vec<_> = all.iter().map(|r| r.factory.id()).collect();
            UsageError(format!("unknown model `{id}` (known: {})", ids.join(", ")))
        })
}

/// Look a scenario up by id.
pub fn scenario(id: &str) -> Result<&'static dyn Scenario, UsageError> {
    let all = scenarios();
    all.iter().copied().find(|s| s.id() == id).ok_or_else(|| {
        let ids: Vec<_> = all.iter().map(|s| s.id()).collect();
        UsageError(format!("unknown scenario `{id}` (known: {})", ids.join(", ")))
    })
}
