//! The scikit-fem references under `datasets/reference/` (P2 tets, linear
//! elasticity), regenerated and drift-checked by CI: block compression, the
//! spherical catheter tip on a vessel wall, and the bonded flat punch.

use super::tables::{interpolate, meta_number, read_csv_columns, read_curve, read_meta};
use crate::error::UsageError;
use std::f64::consts::PI;
use std::path::Path;
use surgbench_core::Vec3;

/// One profile probe of [`WallReference`]: `(line, coordinate, u_r (m))`,
/// line 0 along z (m) at `theta = 0`, line 1 around theta (rad) at
/// `z = length/2`.
pub type WallProbe = (u8, f64, f64);

/// The scikit-fem block-compression reference
/// (`datasets/reference/block-compression`): a cube of edge `edge` clamped
/// at `z = 0`, bonded to a rigid plate at `z = edge` pushed down by
/// `strain * edge`, sides free; linear (small-strain) elasticity, P2 tets.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockReference {
    /// Cube edge of the reference (m).
    pub edge: f64,
    /// Young's modulus of the reference (Pa).
    pub youngs_modulus: f64,
    /// Poisson ratio of the reference.
    pub poisson_ratio: f64,
    /// `(strain, compressive plate force (N))` rows of the CSV.
    pub rows: Vec<(f64, f64)>,
}

impl BlockReference {
    /// Load from `<datasets>/reference/block-compression/`.
    pub fn load(datasets: &Path) -> Result<Self, UsageError> {
        let dir = datasets.join("reference/block-compression");
        let (meta, meta_path) = read_meta(&dir)?;
        let rows = read_curve(&dir.join("block-compression.csv"), "strain", "force_n")?;
        Ok(Self {
            edge: meta_number(&meta, &meta_path, "edge")?,
            youngs_modulus: meta_number(&meta, &meta_path, "youngs_modulus")?,
            poisson_ratio: meta_number(&meta, &meta_path, "poisson_ratio")?,
            rows,
        })
    }

    /// Largest strain the CSV covers.
    pub fn max_strain(&self) -> f64 {
        self.rows.last().map_or(0.0, |r| r.0)
    }

    /// Compressive plate force (N) at `strain` for a cube of edge `edge` (m)
    /// and modulus `e` (Pa): linear interpolation of the CSV, scaled by
    /// `(e / E_ref) (edge / edge_ref)^2` (linear elasticity with prescribed
    /// displacements `strain * edge`: stress ~ E strain, force ~ stress
    /// edge^2). `None` outside the tabulated strains.
    pub fn force(&self, strain: f64, edge: f64, e: f64) -> Option<f64> {
        let f = interpolate(&self.rows, strain)?;
        Some(f * (e / self.youngs_modulus) * (edge / self.edge).powi(2))
    }
}

/// The scikit-fem wall-indentation reference
/// (`datasets/reference/wall-indentation`): a sector of an artery wall
/// (axis z, `-angle/2 <= theta <= angle/2`, ends and straight edges
/// clamped, outer surface free) indented at `theta = 0, z = length/2` by a
/// rigid frictionless sphere inside the lumen, moved along `+x`; linear
/// (small-strain) elasticity with unilateral contact (exact gap), P2 tets.
/// Geometry, material and the mesh map are the reference's, read from its
/// `meta.toml`.
#[derive(Debug, Clone, PartialEq)]
pub struct WallReference {
    /// Inner radius `a` (m).
    pub inner_radius: f64,
    /// Outer radius `b` (m); wall thickness `b - a`.
    pub outer_radius: f64,
    /// Length of the segment along z (m).
    pub length: f64,
    /// Opening angle of the sector (rad).
    pub sector_angle: f64,
    /// Sphere (catheter tip) radius (m).
    pub tip_radius: f64,
    /// Half-width of the uniformly meshed band around the tip (m).
    pub band: f64,
    /// Radial grading exponent `kappa`: `r = a + t expm1(kappa xi) / expm1(kappa)`.
    pub radial_grading: f64,
    /// Young's modulus of the reference (Pa).
    pub youngs_modulus: f64,
    /// Poisson ratio of the reference.
    pub poisson_ratio: f64,
    /// `(depth (m), force on the sphere along +x (N))`, `wall-indentation.csv`.
    pub curve: Vec<(f64, f64)>,
    /// `(depth (m), axial extent of the contact from the tip centre (m))`.
    pub extent: Vec<(f64, f64)>,
    /// Inner-wall radial displacement per tabulated depth: `(depth (m),
    /// probes)` (`surface-profile.csv`).
    pub profiles: Vec<(f64, Vec<WallProbe>)>,
}

impl WallReference {
    /// Load from `<datasets>/reference/wall-indentation/`.
    pub fn load(datasets: &Path) -> Result<Self, UsageError> {
        let dir = datasets.join("reference/wall-indentation");
        let (meta, path) = read_meta(&dir)?;
        let num = |k: &str| meta_number(&meta, &path, k);
        let curve_file = dir.join("wall-indentation.csv");
        let rows = read_csv_columns(&curve_file, &["depth_m", "force_n", "contact_extent_z_m"])?;
        let curve: Vec<(f64, f64)> = rows.iter().map(|r| (r[0], r[1])).collect();
        let extent = rows.iter().map(|r| (r[0], r[2])).collect();
        let increasing =
            curve.len() >= 3 && curve[0] == (0.0, 0.0) && curve.windows(2).all(|w| w[1].0 > w[0].0 && w[1].1 > w[0].1);
        if !increasing {
            return Err(UsageError(format!(
                "{}: needs rows from (0, 0) with increasing depth and force",
                curve_file.display()
            )));
        }
        let prof_file = dir.join("surface-profile.csv");
        let mut profiles: Vec<(f64, Vec<WallProbe>)> = Vec::new();
        for r in read_csv_columns(&prof_file, &["depth_m", "line", "coordinate", "u_r_m"])? {
            let line = match r[1] {
                0.0 => 0,
                1.0 => 1,
                x => return Err(UsageError(format!("{}: line {x} is not 0 or 1", prof_file.display()))),
            };
            match profiles.last_mut() {
                Some((d, v)) if *d == r[0] => v.push((line, r[2], r[3])),
                Some((d, _)) if *d > r[0] => {
                    return Err(UsageError(format!("{}: depths must increase", prof_file.display())));
                }
                _ => profiles.push((r[0], vec![(line, r[2], r[3])])),
            }
        }
        let same_probes = profiles
            .windows(2)
            .all(|w| w[0].1.len() == w[1].1.len() && w[0].1.iter().zip(&w[1].1).all(|(p, q)| (p.0, p.1) == (q.0, q.1)));
        if profiles.len() < 2 || !same_probes {
            return Err(UsageError(format!(
                "{}: needs >= 2 depths, each with the same probes",
                prof_file.display()
            )));
        }
        let r = Self {
            inner_radius: num("inner_radius")?,
            outer_radius: num("outer_radius")?,
            length: num("length")?,
            sector_angle: num("sector_angle")?,
            tip_radius: num("tip_radius")?,
            band: num("band")?,
            radial_grading: num("radial_grading")?,
            youngs_modulus: num("youngs_modulus")?,
            poisson_ratio: num("poisson_ratio")?,
            curve,
            extent,
            profiles,
        };
        let ok = r.inner_radius > 0.0
            && r.outer_radius > r.inner_radius
            && r.length > 0.0
            && r.sector_angle > 0.0
            && r.sector_angle < 2.0 * PI
            && r.tip_radius > 0.0
            && r.tip_radius < r.inner_radius
            && r.band > 0.0
            && 2.0 * r.band < (0.5 * r.length).min(0.5 * r.inner_radius * r.sector_angle)
            && r.radial_grading > 0.0
            && r.youngs_modulus > 0.0;
        if !ok {
            return Err(UsageError(format!("{}: inconsistent geometry {r:?}", path.display())));
        }
        Ok(r)
    }

    /// Depths (m) the force curve covers: from its first nonzero row to its last.
    pub fn depth_range(&self) -> (f64, f64) {
        (self.curve[1].0, self.curve[self.curve.len() - 1].0)
    }

    /// Force on the sphere (N) at `depth` (m) for Young's modulus `e` (Pa):
    /// the curve interpolated linearly in `(ln depth, ln force)` (a local
    /// power law, exact for `F ~ depth^p` between rows), times `e / E_ref`
    /// (the displacement field of a prescribed rigid indenter does not
    /// depend on `E`, so force scales with it). `None` outside
    /// [`Self::depth_range`].
    pub fn force(&self, depth: f64, e: f64) -> Option<f64> {
        let logs: Vec<(f64, f64)> = self.curve[1..].iter().map(|(d, f)| (d.ln(), f.ln())).collect();
        Some(interpolate(&logs, depth.ln())?.exp() * e / self.youngs_modulus)
    }

    /// Axial contact extent (m) at `depth` (linear interpolation).
    pub fn contact_extent(&self, depth: f64) -> Option<f64> {
        interpolate(&self.extent, depth)
    }

    /// The profile probes `(line, coordinate, u_r (m))` at `depth` (m),
    /// interpolated linearly in depth between the two tabulated depths
    /// around it (exact at a tabulated depth). `None` outside the table.
    pub fn profile(&self, depth: f64) -> Option<Vec<WallProbe>> {
        let i = self
            .profiles
            .windows(2)
            .position(|w| depth >= w[0].0 && depth <= w[1].0)?;
        let ((d0, p0), (d1, p1)) = (&self.profiles[i], &self.profiles[i + 1]);
        let w = (depth - d0) / (d1 - d0);
        Some(
            p0.iter()
                .zip(p1)
                .map(|(a, b)| (a.0, a.1, a.2 + w * (b.2 - a.2)))
                .collect(),
        )
    }

    /// The reference's graded map along the arc or the axis: `rho(xi)` (m)
    /// for `xi` in `[0, 1]`, uniform (`2 band xi`) over the first half,
    /// then `c xi + (len - c) ((xi - 1/2) / (1/2))^2` with `c = 2 band`,
    /// reaching `len` at `xi = 1` (`grading` in the script).
    pub fn grading(&self, xi: f64, len: f64) -> f64 {
        let c = 2.0 * self.band;
        let t = ((xi - 0.5) / 0.5).max(0.0);
        c * xi + (len - c) * t * t
    }
}

/// The scikit-fem wall-punch reference
/// (`datasets/reference/wall-punch`): a sector of an artery wall
/// (axis z, `-angle/2 <= theta <= angle/2`, ends and straight edges clamped,
/// outer surface free) indented at `theta = 0, z = length/2` by a rigid
/// flat-ended circular punch bonded to the inner wall and moved along `+x`;
/// linear (small-strain) elasticity, P2 tets. Geometry and material are the
/// reference's and are read from its `meta.toml`.
#[derive(Debug, Clone, PartialEq)]
pub struct PunchReference {
    /// Inner radius `a` (m).
    pub inner_radius: f64,
    /// Outer radius `b` (m); wall thickness `b - a`.
    pub outer_radius: f64,
    /// Length of the segment along z (m).
    pub length: f64,
    /// Opening angle of the sector (rad).
    pub sector_angle: f64,
    /// Punch (catheter tip) radius (m).
    pub punch_radius: f64,
    /// Young's modulus of the reference (Pa).
    pub youngs_modulus: f64,
    /// Poisson ratio of the reference.
    pub poisson_ratio: f64,
    /// `(depth (m), punch force (N))` rows of `wall-punch.csv`.
    pub curve: Vec<(f64, f64)>,
    /// `(z (m), u_r / depth)` of the inner wall along `theta = 0`
    /// (`surface-profile.csv`).
    pub profile: Vec<(f64, f64)>,
}

impl PunchReference {
    /// Load from `<datasets>/reference/wall-punch/`.
    pub fn load(datasets: &Path) -> Result<Self, UsageError> {
        let dir = datasets.join("reference/wall-punch");
        let (meta, path) = read_meta(&dir)?;
        let num = |k: &str| meta_number(&meta, &path, k);
        let r = Self {
            inner_radius: num("inner_radius")?,
            outer_radius: num("outer_radius")?,
            length: num("length")?,
            sector_angle: num("sector_angle")?,
            punch_radius: num("punch_radius")?,
            youngs_modulus: num("youngs_modulus")?,
            poisson_ratio: num("poisson_ratio")?,
            curve: read_curve(&dir.join("wall-punch.csv"), "depth_m", "force_n")?,
            profile: read_curve(&dir.join("surface-profile.csv"), "z_m", "u_r_over_depth")?,
        };
        let ok = r.inner_radius > 0.0
            && r.outer_radius > r.inner_radius
            && r.length > 0.0
            && r.sector_angle > 0.0
            && r.sector_angle < 2.0 * PI
            && r.punch_radius > 0.0
            && r.youngs_modulus > 0.0;
        if !ok {
            return Err(UsageError(format!("{}: inconsistent geometry {r:?}", path.display())));
        }
        Ok(r)
    }

    /// Largest depth the curve covers (m).
    pub fn max_depth(&self) -> f64 {
        self.curve.last().map_or(0.0, |r| r.0)
    }

    /// Punch force (N) at `depth` (m) for Young's modulus `e` (Pa): the
    /// curve interpolated, times `e / E_ref` (linear elasticity with
    /// prescribed displacements: stress and force scale with E). `None`
    /// outside the tabulated depths.
    pub fn force(&self, depth: f64, e: f64) -> Option<f64> {
        Some(interpolate(&self.curve, depth)? * e / self.youngs_modulus)
    }
}

/// The scikit-fem free-vibration reference
/// (`datasets/reference/block-vibration`): a box `[0, size]` clamped at
/// `z = 0`, every other face free, linear elasticity, P2 tets, consistent
/// mass: its first angular frequency and mode shape (a sway along x).
#[derive(Debug, Clone, PartialEq)]
pub struct VibrationReference {
    /// Box size (m).
    pub size: Vec3,
    /// Young's modulus of the reference (Pa).
    pub youngs_modulus: f64,
    /// Poisson ratio of the reference.
    pub poisson_ratio: f64,
    /// Density of the reference (kg/m^3).
    pub density: f64,
    /// First angular frequency on the finest mesh (rad/s).
    pub omega: f64,
    /// Intervals of the mode's grid along x, y, z.
    pub grid: [usize; 3],
    /// The first mode at the grid nodes, x fastest, `phi_x = 1` at the top
    /// centre (dimensionless).
    pub mode: Vec<Vec3>,
}

impl VibrationReference {
    /// Load from `<datasets>/reference/block-vibration/`.
    pub fn load(datasets: &Path) -> Result<Self, UsageError> {
        let dir = datasets.join("reference/block-vibration");
        let (meta, meta_path) = read_meta(&dir)?;
        let num = |k: &str| meta_number(&meta, &meta_path, k);
        let count = |k: &str| -> Result<usize, UsageError> {
            let v = num(k)?;
            if v >= 1.0 && v.fract() == 0.0 {
                Ok(v as usize)
            } else {
                Err(UsageError(format!(
                    "{}: `{k}` must be a positive integer",
                    meta_path.display()
                )))
            }
        };
        let grid = [count("grid_x")?, count("grid_y")?, count("grid_z")?];
        let file = dir.join("frequencies.csv");
        let omega = read_csv_columns(&file, &["k", "omega_1_rad_s"])?
            .into_iter()
            .max_by(|a, b| a[0].total_cmp(&b[0]))
            .map(|r| r[1])
            .ok_or_else(|| UsageError(format!("{}: no rows", file.display())))?;
        let file = dir.join("mode.csv");
        let mode: Vec<Vec3> = read_csv_columns(&file, &["phi_x", "phi_y", "phi_z"])?
            .into_iter()
            .map(|r| Vec3::new(r[0], r[1], r[2]))
            .collect();
        let nodes = grid.iter().map(|g| g + 1).product::<usize>();
        if mode.len() != nodes {
            return Err(UsageError(format!(
                "{}: {} rows, the {}x{}x{} grid has {nodes} nodes",
                file.display(),
                mode.len(),
                grid[0],
                grid[1],
                grid[2]
            )));
        }
        Ok(Self {
            size: Vec3::new(num("size_x")?, num("size_y")?, num("size_z")?),
            youngs_modulus: num("youngs_modulus")?,
            poisson_ratio: num("poisson_ratio")?,
            density: num("density")?,
            omega,
            grid,
            mode,
        })
    }

    /// The first angular frequency (rad/s) at modulus `e` (Pa) and density
    /// `rho` (kg/m^3): for linear elasticity at a fixed geometry and Poisson
    /// ratio `K` scales with `E` and `M` with `rho`, so `omega^2` scales
    /// with `E / rho`.
    pub fn omega_at(&self, e: f64, rho: f64) -> f64 {
        self.omega * ((e / self.youngs_modulus) * (self.density / rho)).sqrt()
    }

    /// The mode at `p` (m, inside the box): trilinear interpolation of the
    /// grid, exact at its nodes (where every block mesh of the scene has
    /// its nodes). `None` outside the box.
    pub fn mode_at(&self, p: &Vec3) -> Option<Vec3> {
        let mut cell = [0usize; 3];
        let mut frac = [0.0; 3];
        for a in 0..3 {
            let s = p[a] / self.size[a] * self.grid[a] as f64;
            let tol = 1e-9 * self.grid[a] as f64;
            if !(s >= -tol && s <= self.grid[a] as f64 + tol) {
                return None;
            }
            let s = s.clamp(0.0, self.grid[a] as f64);
            let nearest = s.round();
            // A node within round-off of the grid is the node itself.
            let s = if (s - nearest).abs() < tol { nearest } else { s };
            let i = (s.floor() as usize).min(self.grid[a] - 1);
            cell[a] = i;
            frac[a] = s - i as f64;
        }
        let (nx, ny) = (self.grid[0] + 1, self.grid[1] + 1);
        let mut v = Vec3::zeros();
        for corner in 0..8 {
            let d = [corner & 1, (corner >> 1) & 1, (corner >> 2) & 1];
            let w: f64 = (0..3)
                .map(|a| if d[a] == 1 { frac[a] } else { 1.0 - frac[a] })
                .product();
            if w != 0.0 {
                let idx = (cell[0] + d[0]) + nx * ((cell[1] + d[1]) + ny * (cell[2] + d[2]));
                v += self.mode[idx] * w;
            }
        }
        Some(v)
    }
}
