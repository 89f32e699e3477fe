//! The registry: every model variant and every scenario the harness knows.
//!
//! Adding a model variant is one line in [`models`]: the factory and a
//! description come from the crate. From then on every comparison whose
//! scenarios it supports runs it.

use crate::scenario::{Scenario, UsageError};
use crate::scenarios;
use surgbench_core::ModelFactory;

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

/// Every registered model, in report order.
pub fn models() -> Vec<Registered> {
    let mut v = register![
        surgbench_der::DerFactory,
        surgbench_chainmail::ChainmailFactory,
        surgbench_pbd::PbdRodFactory,
        surgbench_pbd::PbdTissueFactory,
        surgbench_fem::FemFactory,
        surgbench_meshless::MeshlessFactory,
        surgbench_needle::NeedleFactory,
    ];
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
