//! Needle-tissue interaction parameters of a scene (the needle seed:
//! Chentanez et al., "Interactive Simulation of Surgical Needle Insertion and
//! Steering", SIGGRAPH 2009, Sec. 3.3-3.5). A scene with a [`NeedleTissue`]
//! couples its one rod (the needle) with its one tissue body; only models with
//! [`crate::Capability::NeedleTissue`] run it. SI units.

/// How the needle's shaft and tip act on the tissue it passes through.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NeedleTissue {
    /// Coulomb friction per unit length of shaft inside the tissue (N/m):
    /// a coupling point with adjacent shaft lengths `l_{i-1}, l_i` holds up
    /// to `f_i = f_perlen (l_{i-1} + l_i) / 2` by static friction and feels
    /// exactly that against its slip when it slides (seed Eq. 9-11).
    pub friction_per_length: f64,
    /// Force the tip needs to cut new tissue (N), opposing the tip's advance
    /// (seed Sec. 3.4).
    pub cutting_force: f64,
    /// Viscous friction per unit length (N s/m^2): force
    /// `eta (l_{i-1} + l_i) / 2 (v_tissue - v_needle)` along the shaft.
    pub viscous_friction: f64,
    /// Bevel angle of the tip (rad); 0 is a symmetric tip (seed Sec. 3.5).
    pub bevel_angle: f64,
}

impl NeedleTissue {
    /// Every parameter finite and in range; the message names the bad one.
    pub fn validate(&self) -> Result<(), String> {
        let checks = [
            ("friction_per_length", self.friction_per_length, "N/m"),
            ("cutting_force", self.cutting_force, "N"),
            ("viscous_friction", self.viscous_friction, "N s/m^2"),
        ];
        for (name, v, unit) in checks {
            if !(v >= 0.0 && v.is_finite()) {
                return Err(format!("needle {name} must be >= 0 {unit} and finite, got {v}"));
            }
        }
        if !(self.bevel_angle >= 0.0 && self.bevel_angle < std::f64::consts::FRAC_PI_2) {
            return Err(format!(
                "needle bevel_angle must be in [0, pi/2) rad, got {}",
                self.bevel_angle
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation_names_the_bad_parameter() {
        let ok = NeedleTissue {
            friction_per_length: 10.0,
            cutting_force: 0.1,
            viscous_friction: 0.0,
            bevel_angle: 0.0,
        };
        assert!(ok.validate().is_ok());
        let bad = NeedleTissue {
            friction_per_length: -1.0,
            ..ok
        };
        assert!(bad.validate().unwrap_err().contains("friction_per_length"));
        let bad = NeedleTissue { bevel_angle: 2.0, ..ok };
        assert!(bad.validate().unwrap_err().contains("bevel_angle"));
    }
}
