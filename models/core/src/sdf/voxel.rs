//! A regular grid of signed distances sampled by trilinear interpolation,
//! with the interpolant's analytic gradient ([`VoxelSdf`]), cacheable to disk.

use super::*;
use crate::Vec3;
use crate::io::TriSurface;
use std::io::{Read, Write};
use std::path::Path;

/// Magic first line of the on-disk voxel format.
const VOXEL_MAGIC: &[u8] = b"SURGBENCH-VOXEL-SDF v1\n";

/// A signed distance sampled on a regular grid, read by trilinear
/// interpolation; the gradient is the interpolant's own (piecewise
/// bilinear in each component), so `distance` and `gradient` are consistent.
///
/// Grid node `(i, j, k)` sits at `origin + spacing (i, j, k)` and stores
/// `values[i + nx (j + ny k)]`. Interpolation error on a smooth field is
/// `<= spacing^2 / 8 (|phi_xx| + |phi_yy| + |phi_zz|)` (tensor-product linear
/// interpolation), i.e. second order away from the medial axis where `phi`
/// has kinks. Outside the box the field is continued by the distance to the
/// box (positive: outside the grid counts as wall).
///
/// On disk (little endian): the magic line `SURGBENCH-VOXEL-SDF v1\n`, then
/// `nx, ny, nz` as u64, `origin` (3 x f64), `spacing` (f64), then the values
/// (f64, x fastest).
#[derive(Debug, Clone, PartialEq)]
pub struct VoxelSdf {
    /// Position of node (0, 0, 0) (m).
    pub origin: Vec3,
    /// Node spacing (m).
    pub spacing: f64,
    /// Nodes along x, y, z (each >= 2).
    pub dims: [usize; 3],
    /// Values (m), x fastest.
    pub values: Vec<f64>,
}

/// Error of a voxel SDF against the exact distance at sample points (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoxelError {
    /// Largest absolute error (m).
    pub max: f64,
    /// Root mean square error (m).
    pub rms: f64,
    /// Points compared.
    pub count: usize,
}

impl VoxelSdf {
    /// Sample `sdf` on the grid covering `[min, max]` (m) with `spacing` (m);
    /// the box is enlarged to a whole number of cells.
    pub fn from_sdf(sdf: &dyn Sdf, min: Vec3, max: Vec3, spacing: f64) -> Result<Self, GeometryError> {
        if !(spacing > 0.0 && spacing.is_finite()) {
            return Err(GeometryError(format!("voxel spacing must be > 0 m, got {spacing}")));
        }
        let ext = max - min;
        if !(ext.iter().all(|e| *e > 0.0 && e.is_finite())) {
            return Err(GeometryError(format!(
                "voxel box {min:?}..{max:?} is empty or not finite"
            )));
        }
        let dims = [0, 1, 2].map(|k| (ext[k] / spacing).ceil() as usize + 1);
        let total = dims[0].saturating_mul(dims[1]).saturating_mul(dims[2]);
        if total > 200_000_000 {
            return Err(GeometryError(format!(
                "voxel grid {dims:?} has {total} nodes (> 2e8): raise the spacing"
            )));
        }
        let mut values = Vec::with_capacity(total);
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let p = min + Vec3::new(i as f64, j as f64, k as f64) * spacing;
                    values.push(sdf.distance(&p));
                }
            }
        }
        Ok(Self {
            origin: min,
            spacing,
            dims,
            values,
        })
    }

    /// Grid over a closed mesh's bounding box grown by `padding` (m), values
    /// from the exact [`MeshSdf`].
    pub fn from_mesh(surface: &TriSurface, spacing: f64, padding: f64) -> Result<Self, GeometryError> {
        let exact = MeshSdf::new(surface)?;
        let (lo, hi) = surface.bounds();
        let pad = Vec3::repeat(padding.max(0.0));
        Self::from_sdf(&exact, lo - pad, hi + pad, spacing)
    }

    /// Upper corner of the grid (m).
    pub fn max_corner(&self) -> Vec3 {
        self.origin
            + Vec3::new(
                (self.dims[0] - 1) as f64,
                (self.dims[1] - 1) as f64,
                (self.dims[2] - 1) as f64,
            ) * self.spacing
    }

    fn at(&self, i: usize, j: usize, k: usize) -> f64 {
        self.values[i + self.dims[0] * (j + self.dims[1] * k)]
    }

    /// The cell holding `p` (clamped into the box) and `p`'s local
    /// coordinates in it, each in [0, 1].
    pub(super) fn cell(&self, p: &Vec3) -> ([usize; 3], [f64; 3]) {
        let g = (p - self.origin) / self.spacing;
        let mut idx = [0usize; 3];
        let mut t = [0.0; 3];
        for a in 0..3 {
            let n = self.dims[a];
            let x = g[a].clamp(0.0, (n - 1) as f64);
            let i = (x.floor() as usize).min(n - 2);
            idx[a] = i;
            t[a] = x - i as f64;
        }
        (idx, t)
    }

    /// Trilinear value and its analytic gradient at `p` inside the box.
    fn interp(&self, p: &Vec3) -> (f64, Vec3) {
        let ([i, j, k], t) = self.cell(p);
        let [x, y, z] = t;
        let c = |a: usize, b: usize, d: usize| self.at(i + a, j + b, k + d);
        let (c000, c100, c010, c110) = (c(0, 0, 0), c(1, 0, 0), c(0, 1, 0), c(1, 1, 0));
        let (c001, c101, c011, c111) = (c(0, 0, 1), c(1, 0, 1), c(0, 1, 1), c(1, 1, 1));
        // Interpolate along x, then y, then z.
        let c00 = c000 + x * (c100 - c000);
        let c10 = c010 + x * (c110 - c010);
        let c01 = c001 + x * (c101 - c001);
        let c11 = c011 + x * (c111 - c011);
        let c0 = c00 + y * (c10 - c00);
        let c1 = c01 + y * (c11 - c01);
        let v = c0 + z * (c1 - c0);
        // Derivatives of the same polynomial.
        let dz = c1 - c0;
        let dy = (1.0 - z) * (c10 - c00) + z * (c11 - c01);
        let dx0 = (1.0 - y) * (c100 - c000) + y * (c110 - c010);
        let dx1 = (1.0 - y) * (c101 - c001) + y * (c111 - c011);
        let dx = (1.0 - z) * dx0 + z * dx1;
        (v, Vec3::new(dx, dy, dz) / self.spacing)
    }

    /// `p` (m) moved to the nearest point of the grid's box.
    pub fn clamp_to_box(&self, p: &Vec3) -> Vec3 {
        let hi = self.max_corner();
        Vec3::new(
            p.x.clamp(self.origin.x, hi.x),
            p.y.clamp(self.origin.y, hi.y),
            p.z.clamp(self.origin.z, hi.z),
        )
    }

    /// Error against `exact` at `count` seeded pseudo-random points of the
    /// box where `|exact| <= band` (m) and `keep(p)` holds (e.g. away from the
    /// medial axis); tries at most `50 count` points.
    pub fn error_against(
        &self,
        exact: &dyn Sdf,
        count: usize,
        seed: u64,
        band: f64,
        keep: impl Fn(&Vec3) -> bool,
    ) -> VoxelError {
        error_in_box(self, self.origin, self.max_corner(), exact, count, seed, band, keep)
    }

    /// Write the grid (format in the type's docs).
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
        f.write_all(VOXEL_MAGIC)?;
        for d in self.dims {
            f.write_all(&(d as u64).to_le_bytes())?;
        }
        for x in [self.origin.x, self.origin.y, self.origin.z, self.spacing] {
            f.write_all(&x.to_le_bytes())?;
        }
        for v in &self.values {
            f.write_all(&v.to_le_bytes())?;
        }
        f.flush()
    }

    /// Read a grid written by [`VoxelSdf::write`]; errors name the file and
    /// what is wrong.
    pub fn read(path: &Path) -> Result<Self, GeometryError> {
        let err = |what: String| GeometryError(format!("{}: {what}", path.display()));
        let mut bytes = Vec::new();
        std::fs::File::open(path)
            .and_then(|mut f| f.read_to_end(&mut bytes))
            .map_err(|e| err(e.to_string()))?;
        if !bytes.starts_with(VOXEL_MAGIC) {
            return Err(err("not a surgbench voxel SDF (bad header line)".into()));
        }
        let head = VOXEL_MAGIC.len();
        if bytes.len() < head + 56 {
            return Err(err(format!("truncated header: {} bytes", bytes.len())));
        }
        let word = |i: usize| -> [u8; 8] { bytes[head + 8 * i..head + 8 * i + 8].try_into().expect("8 bytes") };
        let dims = [0, 1, 2].map(|i| u64::from_le_bytes(word(i)) as usize);
        let f = |i: usize| f64::from_le_bytes(word(i));
        let (origin, spacing) = (Vec3::new(f(3), f(4), f(5)), f(6));
        if dims.iter().any(|&d| d < 2)
            || !(spacing > 0.0 && spacing.is_finite())
            || !origin.iter().all(|x| x.is_finite())
        {
            return Err(err(format!(
                "bad grid header: dims {dims:?}, spacing {spacing}, origin {origin:?}"
            )));
        }
        let n = dims[0]
            .checked_mul(dims[1])
            .and_then(|x| x.checked_mul(dims[2]))
            .ok_or_else(|| err("grid too large".into()))?;
        let body = &bytes[head + 56..];
        if body.len() != n * 8 {
            return Err(err(format!(
                "expected {n} values ({} bytes) after the header, found {} bytes",
                n * 8,
                body.len()
            )));
        }
        let values: Vec<f64> = body
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect();
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(err(format!("value {i} is not finite")));
        }
        Ok(Self {
            origin,
            spacing,
            dims,
            values,
        })
    }
}

/// Error of `approx` against `exact` at `count` seeded pseudo-random points
/// of the box `[lo, hi]` where `|exact| <= band` (m) and `keep(p)` holds;
/// tries at most `50 count` points.
#[allow(clippy::too_many_arguments)]
pub(super) fn error_in_box(
    approx: &dyn Sdf,
    lo: Vec3,
    hi: Vec3,
    exact: &dyn Sdf,
    count: usize,
    seed: u64,
    band: f64,
    keep: impl Fn(&Vec3) -> bool,
) -> VoxelError {
    let mut rng = crate::rng::SplitMix64(seed);
    let (mut max, mut sum2, mut n) = (0.0f64, 0.0, 0usize);
    for _ in 0..count.saturating_mul(50) {
        if n >= count {
            break;
        }
        let p = rng.in_box(lo, hi);
        let e = exact.distance(&p);
        if e.abs() > band || !keep(&p) {
            continue;
        }
        let d = (approx.distance(&p) - e).abs();
        max = max.max(d);
        sum2 += d * d;
        n += 1;
    }
    VoxelError {
        max,
        rms: if n > 0 { (sum2 / n as f64).sqrt() } else { f64::NAN },
        count: n,
    }
}

impl Sdf for VoxelSdf {
    fn distance(&self, p: &Vec3) -> f64 {
        self.distance_gradient(p).0
    }
    fn gradient(&self, p: &Vec3) -> Vec3 {
        self.distance_gradient(p).1
    }
    fn distance_gradient(&self, p: &Vec3) -> (f64, Vec3) {
        let q = self.clamp_to_box(p);
        let d = p - q;
        let n = d.norm();
        let (v, g) = self.interp(&q);
        if n > 0.0 { (v + n, d / n) } else { (v, g) }
    }
    /// Central differences of the interpolant's gradient over one grid
    /// spacing `h`, symmetrised (1/m). The interpolant is linear along each
    /// axis inside a cell, so its own second derivatives miss the curvature
    /// of the field, which lives in the jumps of the gradient from cell to
    /// cell; differences over the default's [`HESSIAN_FD_STEP`] see those
    /// jumps as spikes of order `jump / 1e-6 m` (a Newton contact solve
    /// then stalls). Over one spacing they see the field's curvature with an
    /// O(h) error (second derivatives of a smooth field averaged over the
    /// stencil; the `interpolant_hessian_*` test measures it).
    fn hessian(&self, p: &Vec3) -> Mat3 {
        let h = self.spacing;
        let mut m = Mat3::zeros();
        for k in 0..3 {
            let (mut a, mut b) = (*p, *p);
            a[k] += h;
            b[k] -= h;
            m.set_column(k, &((self.gradient(&a) - self.gradient(&b)) / (2.0 * h)));
        }
        (m + m.transpose()) * 0.5
    }
}
