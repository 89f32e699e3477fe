//! One line per step of the crate's straight insertion (the test scene of
//! `tests/straight.rs`: 13 mm in at 10 mm/s, held 0.3 s, 10 mm out), to
//! see what a coupling does step by step: the hand's push against the
//! closed form `f_cut + f_perlen d`, where the entry is, how many coupling
//! points slide or stick, the remesher's operations and the elastic energy
//! they took out, and the most compressed tet so far (`V / V0`).
//!
//! ```sh
//! cargo run --release -p surgbench-needle --example trace -- remesh 1 0.5 0.62 [KEY=VALUE...]
//! ```
//! Arguments: coupling (`embedded` or `remesh`), mesh level (the block has
//! `8 * 2^level x 4 * 2^level x 4 * 2^level` cells, as `needle-straight`),
//! the first and last time printed (s), then fidelity knobs.

#[path = "../tests/common/mod.rs"]
mod common;

use std::process::ExitCode;
use surgbench_core::{Fidelity, ModelFactory};
use surgbench_needle::NeedleFactory;

const F_PERLEN: f64 = 20.0;
const F_CUT: f64 = 0.05;
const V: f64 = 0.01;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}\nusage: trace COUPLING LEVEL T0 T1 [KEY=VALUE...]");
            ExitCode::from(2)
        }
    }
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [coupling, level, t0, t1, knobs @ ..] = args.as_slice() else {
        return Err("four arguments and knobs".into());
    };
    let num = |s: &str| s.parse::<f64>().map_err(|e| format!("`{s}`: {e}"));
    let level: u32 = level.parse().map_err(|e| format!("level `{level}`: {e}"))?;
    if level > 2 {
        return Err(format!("level {level}: at most 2"));
    }
    let (t0, t1) = (num(t0)?, num(t1)?);
    let k = 1usize << level;
    let x1 = 13e-3;
    let feed = [(0.0, 0.0), (x1 / V, x1), (x1 / V + 0.3, x1), (x1 / V + 1.3, x1 - 10e-3)];
    let scene = common::scene(&feed, [8 * k, 4 * k, 4 * k], F_PERLEN, F_CUT);
    let mut pairs = vec![format!("coupling={coupling}")];
    pairs.extend(knobs.iter().cloned());
    let f = Fidelity::parse_pairs(&pairs).map_err(|e| e.to_string())?;
    let mut m = NeedleFactory.build(&scene, &f).map_err(|e| e.to_string())?;
    let dt = m.dt();
    let entry = m.observe().tissues[0]
        .nodes
        .iter()
        .position(|p| p.norm() < 1e-12)
        .ok_or("no node at the entry")?;
    let (mut ops, mut released) = (0.0, 0.0);
    println!("t_s push_n closed_n err tip_mm entry_mm points forward backward static ops released_j volume_ratio_min");
    for i in 1..=(scene.duration / dt).round() as usize {
        let t = i as f64 * dt;
        m.step(dt, &scene.control.command_at(t)).map_err(|e| e.to_string())?;
        let d = m.diagnostics();
        let g = |s: &str| d.get(s).copied().unwrap_or(0.0);
        if (t0..=t1).contains(&t) {
            let o = m.observe();
            let tip = o.rods[0].nodes.last().ok_or("a needle without nodes")?.x;
            let ex = o.tissues[0].nodes[entry].x;
            let push = -o.hand_force.x;
            let closed = F_CUT + F_PERLEN * (tip - ex);
            println!(
                "{t:.3} {push:.5} {closed:.5} {:+.4} {:.4} {:.4} {} {} {} {} {} {:+.3e} {:.4}",
                (push - closed) / closed,
                tip * 1e3,
                ex * 1e3,
                g("coupling_points"),
                g("forward_points"),
                g("backward_points"),
                g("static_points"),
                g("remesh_operations") - ops,
                g("remesh_energy_released_j") - released,
                g("tissue_volume_ratio_min"),
            );
        }
        ops = g("remesh_operations");
        released = g("remesh_energy_released_j");
    }
    Ok(())
}
