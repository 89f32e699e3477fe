//! Vessels: procedural vessel trees with physiological sizes (analytic
//! swept tubes). Blood flow is in [`crate::flow`]; vessels loaded from STL
//! or OBJ files are in [`crate::io`]. SI units (metres).
//!
//! Procedural vessels ([`aortic_arch`], [`coronary_tortuous`],
//! [`y_bifurcation`]) are a trunk [`SweptTube`] plus branch tubes that start
//! on the trunk's centreline, joined as a union of lumens. Sizes:
//! - aorta: inner diameter 25 mm, arch (centreline) radius 35 mm. Adult
//!   thoracic aortic diameters of 25-35 mm are reported by Hager et al.
//!   (2002), "Diameters of the thoracic aorta throughout life as measured
//!   with helical computed tomography", J Thorac Cardiovasc Surg 123:1060;
//!   arch heights/widths of a few centimetres by Redheuil et al. (2011),
//!   "Age-related changes in aortic arch geometry", J Am Coll Cardiol
//!   58:1262. Supra-aortic branches (brachiocephalic 12 mm, left common
//!   carotid 7.5 mm, left subclavian 9 mm diameter) are typical adult values
//!   of the same order as those CT studies, not a specific patient.
//! - coronary: lumen diameter 3 mm, as in proximal coronary segments
//!   (Dodge et al. (1992), "Lumen diameter of normal human coronary
//!   arteries", Circulation 86:232); bends of curvature radius down to 5 mm
//!   stand for a severely tortuous vessel.
//! - Y bifurcation: trunk 4 mm, branches 3 mm diameter at 45 and 70 degrees:
//!   a generic geometry for branch selection, not an anatomical site.
//!
//! ```
//! use surgbench_core::vessel;
//! use surgbench_core::sdf::Sdf;
//! let arch = vessel::aortic_arch();
//! let entry = arch.entry().translation.vector;
//! assert!(arch.distance(&entry) < -0.012); // on the axis, 12.5 mm from the wall
//! ```

use crate::sdf::{CenterlineBuilder, Sdf, SweptTube};
use crate::{Iso3, Vec3};
use std::f64::consts::PI;

// ---------------------------------------------------------------------------
// Procedural vessels.
// ---------------------------------------------------------------------------

/// A named branch of a vessel tree.
#[derive(Debug, Clone)]
pub struct Branch {
    /// Name, e.g. `left-subclavian`.
    pub name: String,
    /// Its lumen.
    pub tube: SweptTube,
}

/// A vessel tree: a trunk and branches whose centrelines start on the trunk's
/// centreline; the lumen is their union (`phi = min`).
#[derive(Debug, Clone)]
pub struct Vessel {
    /// Name.
    pub name: String,
    /// The main lumen; the wire enters at its start.
    pub trunk: SweptTube,
    /// Side branches.
    pub branches: Vec<Branch>,
}

impl Vessel {
    /// Base clamp pose at the trunk's entry: on the centreline, local +x
    /// along the lumen (the harness's rod convention).
    pub fn entry(&self) -> Iso3 {
        self.trunk.frame_at(0.0)
    }

    /// The branch called `name`.
    pub fn branch(&self, name: &str) -> Option<&Branch> {
        self.branches.iter().find(|b| b.name == name)
    }

    /// Which lumen `p` is deepest in: `None` for the trunk, `Some(i)` for
    /// branch `i`, with its signed distance (m).
    pub fn deepest(&self, p: &Vec3) -> (Option<usize>, f64) {
        let mut best = (None, self.trunk.distance(p));
        for (i, b) in self.branches.iter().enumerate() {
            let d = b.tube.distance(p);
            if d < best.1 {
                best = (Some(i), d);
            }
        }
        best
    }
}

impl Sdf for Vessel {
    fn distance(&self, p: &Vec3) -> f64 {
        self.deepest(p).1
    }
    fn gradient(&self, p: &Vec3) -> Vec3 {
        self.distance_gradient(p).1
    }
    fn distance_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        let mut best = self.trunk.distance_gradient(p);
        for b in &self.branches {
            let dg = b.tube.distance_gradient(p);
            if dg.0 < best.0 {
                best = dg;
            }
        }
        best
    }
    /// The Hessian of the lumen `p` is deepest in ([`Vessel::deepest`]),
    /// the same one [`Sdf::gradient`] uses.
    fn hessian(&self, p: &Vec3) -> crate::Mat3 {
        match self.deepest(p).0 {
            None => self.trunk.hessian(p),
            Some(i) => self.branches[i].tube.hessian(p),
        }
    }
}

/// Aortic lumen radius (m): inner diameter 25 mm.
pub const AORTA_RADIUS: f64 = 12.5e-3;
/// Aortic arch centreline radius (m).
pub const ARCH_RADIUS: f64 = 35e-3;
/// Length of the straight descending segment before the arch (m): the
/// thoracic descending aorta is about 20 cm long, and scenes that feed a
/// wire by moving its clamp along this straight need the room (the clamp
/// must stay inside the lumen for the whole push).
pub const ARCH_DESCENDING: f64 = 210e-3;
/// Length of the straight ascending segment after the arch (m).
pub const ARCH_ASCENDING: f64 = 50e-3;
/// Length of each supra-aortic branch (m).
pub const ARCH_BRANCH_LENGTH: f64 = 200e-3;

/// Aortic arch traversed as in a femoral approach: the trunk starts at the
/// origin heading up (+z) the descending aorta (210 mm), turns over the arch
/// (radius 35 mm, 180 degrees, towards -x), and runs down the ascending aorta
/// (50 mm, -z); lumen diameter 25 mm. The supra-aortic branches leave the top
/// of the arch upwards at 60, 90 and 120 degrees along it: `left-subclavian`
/// (9 mm, met first), `left-common-carotid` (7.5 mm), `brachiocephalic`
/// (12 mm), each [`ARCH_BRANCH_LENGTH`] long: long enough that a wire
/// pushed into one keeps going for the whole of `arch-insertion` instead of
/// meeting a closed end no real artery has. (With gravity along -z the
/// patient would be standing: scenes choose their gravity.)
pub fn aortic_arch() -> Vessel {
    let trunk = CenterlineBuilder::new(Vec3::zeros(), Vec3::z())
        .line(ARCH_DESCENDING)
        .arc(ARCH_RADIUS, PI, -Vec3::x())
        .line(ARCH_ASCENDING)
        .build_constant(AORTA_RADIUS)
        .expect("static arch geometry is valid");
    let center = Vec3::new(-ARCH_RADIUS, 0.0, ARCH_DESCENDING);
    let branch = |name: &str, phi_deg: f64, tilt_deg: f64, radius: f64| {
        let phi = phi_deg.to_radians();
        let start = center + Vec3::new(phi.cos(), 0.0, phi.sin()) * ARCH_RADIUS;
        let t = tilt_deg.to_radians();
        let dir = Vec3::new(t.sin(), 0.0, t.cos());
        Branch {
            name: name.to_string(),
            tube: CenterlineBuilder::new(start, dir)
                .line(ARCH_BRANCH_LENGTH)
                .build_constant(radius)
                .expect("static branch geometry is valid"),
        }
    };
    Vessel {
        name: "aortic-arch".into(),
        trunk,
        branches: vec![
            branch("left-subclavian", 60.0, 15.0, 4.5e-3),
            branch("left-common-carotid", 90.0, 0.0, 3.75e-3),
            branch("brachiocephalic", 120.0, -15.0, 6e-3),
        ],
    }
}

/// Coronary lumen radius (m): diameter 3 mm.
pub const CORONARY_RADIUS: f64 = 1.5e-3;
/// Straight entry (guide-catheter) segment of the coronary (m): long enough
/// that a clamp fed along it stays in the straight for `coronary-tortuous`.
pub const CORONARY_ENTRY: f64 = 60e-3;

/// Tortuous coronary-like tube, diameter 3 mm: a 60 mm straight entry along
/// +x (where a guide catheter would sit), then five bends in alternating
/// planes with curvature radii 8, 5, 6, 5 and 10 mm, then 30 mm straight.
pub fn coronary_tortuous() -> Vessel {
    let trunk = CenterlineBuilder::new(Vec3::zeros(), Vec3::x())
        .line(CORONARY_ENTRY)
        .arc(8e-3, PI / 3.0, Vec3::y())
        .arc(5e-3, PI / 2.0, Vec3::z())
        .arc(6e-3, 2.0 * PI / 3.0, -Vec3::y())
        .arc(5e-3, PI / 2.0, -Vec3::z())
        .arc(10e-3, PI / 3.0, Vec3::y())
        .line(30e-3)
        .build_constant(CORONARY_RADIUS)
        .expect("static coronary geometry is valid");
    Vessel {
        name: "coronary-tortuous".into(),
        trunk,
        branches: Vec::new(),
    }
}

/// Trunk length of the Y bifurcation (m).
pub const Y_TRUNK: f64 = 40e-3;
/// Trunk lumen radius of the Y bifurcation (m).
pub const Y_TRUNK_RADIUS: f64 = 2e-3;
/// Branch lumen radius of the Y bifurcation (m).
pub const Y_BRANCH_RADIUS: f64 = 1.5e-3;

/// Y bifurcation in the x-y plane: trunk (4 mm diameter, 40 mm) along +x from
/// the origin, then `branch-45` leaving at 45 degrees towards +y and
/// `branch-70` at 70 degrees towards -y, both 3 mm diameter and 30 mm long,
/// starting at the trunk's end point.
pub fn y_bifurcation() -> Vessel {
    let trunk = CenterlineBuilder::new(Vec3::zeros(), Vec3::x())
        .line(Y_TRUNK)
        .build_constant(Y_TRUNK_RADIUS)
        .expect("static trunk geometry is valid");
    let end = Vec3::new(Y_TRUNK, 0.0, 0.0);
    let branch = |name: &str, deg: f64| {
        let a = deg.to_radians();
        Branch {
            name: name.to_string(),
            tube: CenterlineBuilder::new(end, Vec3::new(a.cos(), a.sin(), 0.0))
                .line(30e-3)
                .build_constant(Y_BRANCH_RADIUS)
                .expect("static branch geometry is valid"),
        }
    };
    Vessel {
        name: "y-bifurcation".into(),
        trunk,
        branches: vec![branch("branch-45", 45.0), branch("branch-70", -70.0)],
    }
}

#[cfg(test)]
mod hessian_tests {
    use super::*;
    use crate::Mat3;

    /// The vessels' Hessian (the deepest lumen's) against central
    /// differences of their gradient, at seeded points near the trunk and
    /// branches whose difference stencil stays in one lumen and on one piece
    /// of its centreline (no kink of the gradient inside it).
    #[test]
    fn vessel_hessian_matches_differences_of_the_gradient() {
        // Step and the smallest distance from a centreline kept (m); the
        // relative truncation error of central differences is about
        // (h / rho)^2 = 4e-6 (see the sdf tests); rounding adds ~1e-10.
        let (h, rho_min) = (1e-6, 5e-4);
        let tol = (h / rho_min) * (h / rho_min);
        for (vessel, seed) in [(y_bifurcation(), 7u64), (coronary_tortuous(), 8)] {
            let tubes: Vec<&SweptTube> = std::iter::once(&vessel.trunk)
                .chain(vessel.branches.iter().map(|b| &b.tube))
                .collect();
            // Which lumen and which piece of its centreline `p` belongs to.
            let key = |p: &Vec3| {
                let (lumen, _) = vessel.deepest(p);
                let tube = tubes[lumen.map_or(0, |i| i + 1)];
                let pr = tube.project(p);
                let end = pr.s <= 0.0 || pr.s >= tube.length();
                (lumen, pr.piece, end, pr.radial >= rho_min)
            };
            let mut rng = crate::rng::SplitMix64(seed);
            let (mut worst, mut n) = (0.0f64, 0usize);
            while n < 300 {
                let tube = tubes[(rng.unit() * tubes.len() as f64) as usize];
                let c = tube.point_at(rng.unit() * tube.length());
                let p = c + Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5) * 4e-3;
                let k0 = key(&p);
                let mut fd = Mat3::zeros();
                let mut smooth = k0.3;
                for k in 0..3 {
                    let (mut a, mut b) = (p, p);
                    a[k] += h;
                    b[k] -= h;
                    smooth &= key(&a) == k0 && key(&b) == k0;
                    fd.set_column(k, &((vessel.gradient(&a) - vessel.gradient(&b)) / (a[k] - b[k])));
                }
                if !smooth {
                    continue;
                }
                let got = vessel.hessian(&p);
                let err = (got - fd).norm() / got.norm();
                assert!(
                    err < tol,
                    "{}: hessian at {p:?} {got} vs differences {fd} (rel {err:e}, tol {tol:e})",
                    vessel.name
                );
                worst = worst.max(err);
                n += 1;
            }
            eprintln!("{}: worst rel err {worst:.2e} over {n} points", vessel.name);
        }
    }
}
