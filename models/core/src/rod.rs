//! Rods as a scene describes them: sections with their material, the base
//! clamp, dead tip loads and their time profile, and an optional initial
//! velocity field (free-vibration scenes). SI units throughout.

use crate::{Iso3, Vec3};

/// One piece of a rod with uniform properties, from the previous section's
/// end (or the base) to `until` (arclength from the base clamp, m).
#[derive(Debug, Clone, PartialEq)]
pub struct RodSection {
    /// Arclength where this section ends (m), measured from the clamp.
    pub until: f64,
    /// Cross-section radius (m); the section is a solid circle.
    pub radius: f64,
    /// Young's modulus (Pa).
    pub youngs_modulus: f64,
    /// Poisson ratio; shear modulus `G = E / (2 (1 + nu))`.
    pub poisson_ratio: f64,
    /// Density (kg/m^3).
    pub density: f64,
    /// Natural curvature (1/m): components `(kappa_1, kappa_2)` of the rest
    /// Darboux vector on the material directors `d1`, `d2` (Kirchhoff
    /// convention, `t' = Omega x t`): a positive `kappa_1` turns the tangent
    /// towards `-d2`, a positive `kappa_2` towards `+d1`. A pre-shaped J or
    /// angled tip. Zero for a straight rod. (Bergou et al. 2008 write the
    /// material curvature as `(Omega . d2, -Omega . d1)`; rod models map it.)
    pub rest_curvature: [f64; 2],
}

impl RodSection {
    /// Shear modulus `G = E / (2 (1 + nu))` (Pa).
    pub fn shear_modulus(&self) -> f64 {
        self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))
    }
    /// Area `pi r^2` (m^2).
    pub fn area(&self) -> f64 {
        std::f64::consts::PI * self.radius * self.radius
    }
    /// Second moment of area of a solid circle `pi r^4 / 4` (m^4).
    pub fn second_moment(&self) -> f64 {
        std::f64::consts::PI * self.radius.powi(4) / 4.0
    }
    /// Polar moment `pi r^4 / 2` (m^4).
    pub fn polar_moment(&self) -> f64 {
        2.0 * self.second_moment()
    }
}

/// A rod (guidewire, catheter, needle) clamped at its base.
#[derive(Debug, Clone, PartialEq)]
pub struct RodBody {
    /// Free length at the start of the run (m).
    pub length: f64,
    /// Sections from base to tip; the last one's `until` equals `length`.
    pub sections: Vec<RodSection>,
    /// Base clamp pose: position of the clamp; the rod leaves along its local
    /// +x axis, the material frame starts as (local y, local z).
    pub base: Iso3,
    /// Dead force on the tip node (N, world frame).
    pub tip_force: Vec3,
    /// Dead torque on the tip (N m, world frame).
    pub tip_torque: Vec3,
    /// How the tip loads grow over time: `None` applies them in full from
    /// `t = 0`; a ramp scales both by its value at `t` (so a scene can thread
    /// a wire first and load it after, or raise a pull force slowly).
    pub tip_load_ramp: Option<LoadRamp>,
    /// Velocity field at `t = 0` (`None`: the rod starts at rest). The
    /// free-vibration scenes start a straight rod in a bending mode this way.
    pub initial_velocity: Option<RodVelocity>,
}

/// One sample of a rod's initial velocity field.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VelocitySample {
    /// Arclength from the base clamp (m).
    pub s: f64,
    /// Velocity of the centreline point (m/s, world frame).
    pub velocity: Vec3,
    /// Angular velocity of the cross-section (rad/s, world frame): for a
    /// bending mode, the rate at which the tangent turns.
    pub angular_velocity: Vec3,
}

/// A rod's velocity at `t = 0` as samples along the arclength, interpolated
/// linearly between them (a model reads it at its own nodes and segment
/// midpoints). The clamp stays put whatever the field says at `s = 0`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RodVelocity {
    /// Samples in increasing `s`, the first at `s = 0`, the last at the tip.
    pub samples: Vec<VelocitySample>,
}

impl RodVelocity {
    /// `(velocity, angular velocity)` at arclength `s` (m): linear between
    /// samples, the end samples' values beyond them.
    pub fn at(&self, s: f64) -> (Vec3, Vec3) {
        let k = &self.samples;
        let Some(first) = k.first() else {
            return (Vec3::zeros(), Vec3::zeros());
        };
        if s <= first.s {
            return (first.velocity, first.angular_velocity);
        }
        let i = k.partition_point(|p| p.s <= s);
        if i >= k.len() {
            let last = k[k.len() - 1];
            return (last.velocity, last.angular_velocity);
        }
        let (a, b) = (k[i - 1], k[i]);
        let w = (s - a.s) / (b.s - a.s);
        (
            a.velocity.lerp(&b.velocity, w),
            a.angular_velocity.lerp(&b.angular_velocity, w),
        )
    }

    /// Check the samples: at least two, finite, `s` strictly increasing from
    /// the clamp (`s = 0`) to the tip (`length`, m).
    pub fn validate(&self, length: f64) -> Result<(), String> {
        let k = &self.samples;
        if k.len() < 2 {
            return Err(format!("initial velocity has {} samples, needs at least 2", k.len()));
        }
        let finite = |v: &Vec3| v.iter().all(|c| c.is_finite());
        if let Some(p) = k
            .iter()
            .find(|p| !(p.s.is_finite() && finite(&p.velocity) && finite(&p.angular_velocity)))
        {
            return Err(format!("initial velocity sample at s = {} m is not finite", p.s));
        }
        if let Some(w) = k.windows(2).find(|w| !(w[1].s > w[0].s)) {
            return Err(format!(
                "initial velocity sample at s = {} m is not after {} m",
                w[1].s, w[0].s
            ));
        }
        let tol = 1e-9 * length;
        if k[0].s.abs() > tol || (k[k.len() - 1].s - length).abs() > tol {
            return Err(format!(
                "initial velocity samples span [{}, {}] m, the rod [0, {length}] m",
                k[0].s,
                k[k.len() - 1].s
            ));
        }
        Ok(())
    }
}

/// Piecewise-linear scale factor over time (dimensionless, `[0, 1]`); before
/// the first key and after the last the nearest key's value holds.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LoadRamp {
    /// `(t, scale)` pairs: time (s), strictly increasing, and the scale there.
    pub keys: Vec<(f64, f64)>,
}

impl LoadRamp {
    /// Zero until `t0`, rising linearly to 1 at `t1`, 1 after (s).
    pub fn linear(t0: f64, t1: f64) -> Self {
        Self {
            keys: vec![(t0, 0.0), (t1, 1.0)],
        }
    }

    /// The scale at time `t` (s).
    pub fn scale_at(&self, t: f64) -> f64 {
        let k = &self.keys;
        match k.len() {
            0 => 1.0,
            _ if t <= k[0].0 => k[0].1,
            _ if t >= k[k.len() - 1].0 => k[k.len() - 1].1,
            _ => {
                let i = k.partition_point(|key| key.0 <= t) - 1;
                let (a, b) = (k[i], k[i + 1]);
                a.1 + (t - a.0) / (b.0 - a.0) * (b.1 - a.1)
            }
        }
    }

    /// Rate of change of the scale at `t` (1/s), zero on the flat parts and
    /// the right-hand slope at a key.
    pub fn rate_at(&self, t: f64) -> f64 {
        let k = &self.keys;
        if k.len() < 2 || t < k[0].0 || t >= k[k.len() - 1].0 {
            return 0.0;
        }
        let i = k.partition_point(|key| key.0 <= t) - 1;
        (k[i + 1].1 - k[i].1) / (k[i + 1].0 - k[i].0)
    }

    /// Check keys: at least one, finite, times strictly increasing, scales in `[0, 1]`.
    pub fn validate(&self) -> Result<(), String> {
        if self.keys.is_empty() {
            return Err("tip load ramp has no keys".into());
        }
        for (i, &(t, s)) in self.keys.iter().enumerate() {
            if !(t.is_finite() && (0.0..=1.0).contains(&s)) {
                return Err(format!(
                    "tip load ramp key {i} ({t} s, {s}): time must be finite, scale in [0, 1]"
                ));
            }
            if i > 0 && !(t > self.keys[i - 1].0) {
                return Err(format!(
                    "tip load ramp key {i} at {t} s is not after {} s",
                    self.keys[i - 1].0
                ));
            }
        }
        Ok(())
    }
}

impl RodBody {
    /// A straight rod with uniform properties, clamped at the origin along +x.
    pub fn uniform(length: f64, radius: f64, youngs_modulus: f64, poisson_ratio: f64, density: f64) -> Self {
        Self {
            length,
            sections: vec![RodSection {
                until: length,
                radius,
                youngs_modulus,
                poisson_ratio,
                density,
                rest_curvature: [0.0, 0.0],
            }],
            base: Iso3::identity(),
            tip_force: Vec3::zeros(),
            tip_torque: Vec3::zeros(),
            tip_load_ramp: None,
            initial_velocity: None,
        }
    }

    /// Scale of the tip loads at time `t` (s): 1 without a ramp.
    pub fn tip_load_scale(&self, t: f64) -> f64 {
        self.tip_load_ramp.as_ref().map_or(1.0, |r| r.scale_at(t))
    }

    /// Dead tip force at time `t` (N, world frame).
    pub fn tip_force_at(&self, t: f64) -> Vec3 {
        self.tip_load_scale(t) * self.tip_force
    }

    /// Dead tip torque at time `t` (N m, world frame).
    pub fn tip_torque_at(&self, t: f64) -> Vec3 {
        self.tip_load_scale(t) * self.tip_torque
    }

    /// The section at arclength `s` (m from the clamp); past the tip, the last.
    pub fn section_at(&self, s: f64) -> &RodSection {
        self.sections
            .iter()
            .find(|sec| s <= sec.until)
            .unwrap_or_else(|| self.sections.last().expect("validated rod has a section"))
    }

    /// Check that the rod is physically meaningful.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.length > 0.0 && self.length.is_finite()) {
            return Err(format!("rod length must be > 0 m, got {}", self.length));
        }
        if self.sections.is_empty() {
            return Err("rod has no sections".into());
        }
        let mut prev = 0.0;
        for (i, s) in self.sections.iter().enumerate() {
            if !(s.until > prev) {
                return Err(format!("rod section {i} ends at {} m, not after {prev} m", s.until));
            }
            prev = s.until;
            if !(s.radius > 0.0 && s.radius.is_finite()) {
                return Err(format!("radius must be > 0 m, got {}", s.radius));
            }
            if !(s.youngs_modulus > 0.0 && s.youngs_modulus.is_finite()) {
                return Err(format!("youngs_modulus must be > 0 Pa, got {}", s.youngs_modulus));
            }
            if !(s.poisson_ratio > -1.0 && s.poisson_ratio < 0.5) {
                return Err(format!("poisson_ratio must be in (-1, 0.5), got {}", s.poisson_ratio));
            }
            if !(s.density > 0.0 && s.density.is_finite()) {
                return Err(format!("density must be > 0 kg/m^3, got {}", s.density));
            }
            if !s.rest_curvature.iter().all(|k| k.is_finite()) {
                return Err("rest_curvature must be finite".into());
            }
        }
        if (prev - self.length).abs() > 1e-12 * self.length {
            return Err(format!(
                "last rod section ends at {prev} m but the rod is {} m long",
                self.length
            ));
        }
        if !(self.tip_force.iter().all(|x| x.is_finite()) && self.tip_torque.iter().all(|x| x.is_finite())) {
            return Err("tip loads must be finite".into());
        }
        if let Some(r) = &self.tip_load_ramp {
            r.validate()?;
        }
        if let Some(v) = &self.initial_velocity {
            v.validate(self.length)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The ramp interpolates linearly, holds its end values, and its rate is
    /// the slope of the segment the time falls in (exact arithmetic on these
    /// dyadic values, so equality is exact).
    #[test]
    fn load_ramp_interpolates_and_holds() {
        let r = LoadRamp {
            keys: vec![(0.5, 0.0), (1.0, 1.0), (2.0, 0.5)],
        };
        assert_eq!(r.scale_at(0.0), 0.0);
        assert_eq!(r.scale_at(0.75), 0.5);
        assert_eq!(r.scale_at(1.5), 0.75);
        assert_eq!(r.scale_at(3.0), 0.5);
        assert_eq!(r.rate_at(0.25), 0.0);
        assert_eq!(r.rate_at(0.75), 2.0);
        assert_eq!(r.rate_at(1.5), -0.5);
        assert_eq!(r.rate_at(2.5), 0.0);
        let mut rod = RodBody::uniform(0.1, 1e-3, 1e9, 0.3, 1000.0);
        rod.tip_force = Vec3::new(0.0, 2.0, 0.0);
        assert_eq!(rod.tip_force_at(0.0), rod.tip_force, "no ramp: full load");
        rod.tip_load_ramp = Some(r);
        assert_eq!(rod.tip_force_at(0.75), Vec3::new(0.0, 1.0, 0.0));
        assert!(rod.validate().is_ok());
    }

    /// Bad ramps are refused with a message naming the key.
    #[test]
    fn bad_load_ramps_are_refused() {
        let mut rod = RodBody::uniform(0.1, 1e-3, 1e9, 0.3, 1000.0);
        for (keys, needle) in [
            (vec![], "no keys"),
            (vec![(0.0, 0.0), (0.0, 1.0)], "not after"),
            (vec![(0.0, 1.5)], "scale in [0, 1]"),
            (vec![(f64::NAN, 0.5)], "must be finite"),
        ] {
            rod.tip_load_ramp = Some(LoadRamp { keys });
            let err = rod.validate().unwrap_err();
            assert!(err.contains(needle), "{err:?} should mention {needle:?}");
        }
    }

    /// The field interpolates linearly, holds its end values, and a field
    /// that does not span the rod is refused (dyadic values: exact).
    #[test]
    fn initial_velocity_interpolates_and_validates() {
        let sample = |s: f64, vz: f64| VelocitySample {
            s,
            velocity: Vec3::new(0.0, 0.0, vz),
            angular_velocity: Vec3::new(0.0, -vz, 0.0),
        };
        let mut rod = RodBody::uniform(1.0, 1e-3, 1e9, 0.3, 1000.0);
        let field = RodVelocity {
            samples: vec![sample(0.0, 0.0), sample(0.5, 1.0), sample(1.0, 3.0)],
        };
        assert_eq!(field.at(0.25).0.z, 0.5);
        assert_eq!(field.at(0.75), (Vec3::new(0.0, 0.0, 2.0), Vec3::new(0.0, -2.0, 0.0)));
        assert_eq!(field.at(2.0).0.z, 3.0);
        assert_eq!(field.at(-1.0).0.z, 0.0);
        rod.initial_velocity = Some(field);
        assert!(rod.validate().is_ok());
        rod.initial_velocity = Some(RodVelocity {
            samples: vec![sample(0.0, 0.0), sample(0.5, 1.0)],
        });
        assert!(rod.validate().unwrap_err().contains("span"));
        rod.initial_velocity = Some(RodVelocity {
            samples: vec![sample(0.0, 0.0), sample(0.0, 1.0), sample(1.0, 1.0)],
        });
        assert!(rod.validate().unwrap_err().contains("not after"));
    }
}
