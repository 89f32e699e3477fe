//! Tissue statics: block compression, Lamé tube, volume preservation under
//! squash and twist, the Truth Cube phantom, a spherical catheter tip
//! indenting a vessel-wall sector (frictionless contact) and its bonded
//! flat-punch companion, and a rigid sphere pressed into a block (Hertz).
//!
//! Shared conventions (SI units: m, kg, s, N, Pa, rad):
//! * every scene holds exactly one [`TissueBody`], no gravity, and is static:
//!   the loads (driven displacements, pressures) follow the control
//!   timeline's `insertion`, a load factor ramped 0 -> 1 over `ramp_time` by
//!   a smooth cosine (`(1 - cos(pi t / T)) / 2`, sampled at 16 keys, so the
//!   loading velocity starts and ends near zero and dynamic models are not
//!   kicked), then held; `Scene::settle` asks for equilibrium (every node
//!   slower than `settle_tol`) no earlier than the end of the ramp, and
//!   `duration` bounds the wait. Quasi-static models settle at the end of
//!   the ramp; the static answer does not depend on the ramp;
//! * the mesh depends on the fidelity knob `mesh_level` (0 = coarsest): the
//!   harness calls [`Scenario::instantiate_at`], which builds the mesh at
//!   `fidelity.mesh_level.unwrap_or(DEFAULT_LEVEL)` and rejects levels above
//!   [`MAX_LEVEL`]; models take the mesh they are given;
//! * the model reports the total reaction on the driven nodes as
//!   `Observation::hand_force`: the force the body exerts on whatever drives
//!   them (N);
//! * every score also carries `inverted_elements` and `volume_change_rel`
//!   (`|V/V0 - 1|`), computed here from the observed node positions and the
//!   scene's tets, not taken from the model's own report.
//!
//! Tubes (`lame-tube`, `wall-indentation`, `wall-punch`) have their axis along z through
//! the origin; blocks occupy `[0, L]^3` with the loaded face at `z = L`.

use super::vessel::datasets_dir;
use crate::scenario::{ParamSpec, Params, Range, Scenario, ScenarioRun, UsageError, sweep_of};
use std::collections::{BTreeMap, HashSet};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use surgbench_core::io::truth_cube;
use surgbench_core::mesh;
use surgbench_core::{
    Body, ControlKey, ControlTimeline, Family, Fidelity, Mat3, Observation, Scene, Settle, SolidMaterial, TetMesh,
    TissueBody, TissueObs, Vec3,
};

/// Mesh level used when the fidelity does not set `mesh_level`.
pub const DEFAULT_LEVEL: usize = 1;
/// Finest mesh level: block scenes have `4 * 2^level` cells per edge, so
/// level 3 is 32^3 cells (196,608 tets); level 4 (1.6 M tets) is beyond what
/// a 2-core CI machine or the PBD/FEM models here handle in minutes.
pub const MAX_LEVEL: usize = 3;
/// Every tissue scenario, in report order.
pub fn all() -> Vec<&'static dyn Scenario> {
    vec![
        &BlockCompression,
        &LameTube,
        &VolumePreservation,
        &TruthCube,
        &WallIndentation,
        &WallPunch,
        &SphereIndentation,
    ]
}

const fn p(name: &'static str, default: f64, unit: &'static str, range: Range, doc: &'static str) -> ParamSpec {
    ParamSpec {
        name,
        default,
        unit,
        range,
        doc,
    }
}

const DENSITY: ParamSpec = p(
    "density",
    1000.0,
    "kg/m^3",
    Range::Positive,
    "density (statics: sets only the dynamics of the ramp)",
);
const RAMP: ParamSpec = p(
    "ramp_time",
    0.25,
    "s",
    Range::Positive,
    "time over which the load factor goes 0 -> 1 (smooth cosine ramp)",
);
const DURATION: ParamSpec = p(
    "duration",
    1.5,
    "s",
    Range::Positive,
    "longest simulated time to reach equilibrium (> ramp_time)",
);
const SETTLE: ParamSpec = p(
    "settle_tol",
    1e-5,
    "m/s",
    Range::Positive,
    "static equilibrium when every node is slower than this (after the ramp)",
);

/// Cells per edge of the block meshes at `level`: `4 * 2^level`.
pub fn block_cells(level: usize) -> usize {
    4 << level
}

/// The default sweep of every tissue scenario: mesh levels 0..=[`MAX_LEVEL`].
pub fn level_sweep() -> Vec<Fidelity> {
    let levels: Vec<f64> = (0..=MAX_LEVEL).map(|l| l as f64).collect();
    sweep_of("mesh_level", &levels)
}

/// `fidelity.mesh_level` or [`DEFAULT_LEVEL`], rejected past [`MAX_LEVEL`].
pub fn mesh_level(scenario: &str, fidelity: &Fidelity) -> Result<usize, UsageError> {
    let level = fidelity.mesh_level.unwrap_or(DEFAULT_LEVEL);
    if level > MAX_LEVEL {
        return Err(UsageError(format!(
            "scenario `{scenario}`: mesh_level {level} is past the finest level {MAX_LEVEL} ({} cells per block edge there)",
            block_cells(MAX_LEVEL)
        )));
    }
    Ok(level)
}

/// Smooth load ramp `s(t) = (1 - cos(pi t / ramp)) / 2` for `t <= ramp`,
/// then `s = 1`, as a piecewise-linear timeline (16 segments) of the
/// `insertion` channel (the tissue load factor).
pub fn load_ramp(ramp: f64) -> ControlTimeline {
    const N: usize = 16;
    let mut keys: Vec<ControlKey> = (0..=N)
        .map(|k| ControlKey {
            t: ramp * k as f64 / N as f64,
            insertion: 0.5 * (1.0 - (PI * k as f64 / N as f64).cos()),
            rotation: 0.0,
        })
        .collect();
    keys[N].insertion = 1.0;
    ControlTimeline { keys }
}

/// A static scene with one tissue body: no gravity, the load ramp, and
/// equilibrium read after the ramp.
fn static_scene(name: &str, body: TissueBody, p: &Params) -> Result<Scene, UsageError> {
    let (ramp, duration) = (p.get("ramp_time"), p.get("duration"));
    if !(duration > ramp) {
        return Err(UsageError(format!(
            "{name}: duration {duration} s must exceed ramp_time {ramp} s (equilibrium is read after the ramp)"
        )));
    }
    let mut s = Scene::empty(name);
    s.bodies.push(Body::Tissue(body));
    s.control = load_ramp(ramp);
    s.settle = Some(Settle {
        velocity_tol: p.get("settle_tol"),
        min_time: ramp,
    });
    s.duration = duration;
    Ok(s)
}

/// The first tissue of `obs` if its node count matches `mesh`.
fn tissue_of<'a>(obs: &'a Observation, mesh: &TetMesh) -> Option<&'a TissueObs> {
    obs.tissues.first().filter(|t| t.nodes.len() == mesh.nodes.len())
}

/// Volume statistics of the deformed mesh `x` against the rest mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VolumeStats {
    /// Total deformed volume over rest volume.
    pub ratio: f64,
    /// Largest `|V_e / V_e0 - 1|` over elements.
    pub max_element_change: f64,
    /// Smallest `V_e / V_e0`.
    pub min_element_ratio: f64,
    /// Elements with `V_e / V_e0 <= 0`.
    pub inverted: usize,
}

/// Volumes of the tets of `mesh` at node positions `x` (m) against rest.
pub fn volume_stats(mesh: &TetMesh, x: &[Vec3]) -> VolumeStats {
    let (mut v, mut v0) = (0.0, 0.0);
    let mut s = VolumeStats {
        ratio: 0.0,
        max_element_change: 0.0,
        min_element_ratio: f64::INFINITY,
        inverted: 0,
    };
    for t in &mesh.tets {
        let [a, b, c, d] = t.map(|i| mesh.nodes[i]);
        let e0 = mesh::tet_volume(&a, &b, &c, &d);
        let [a, b, c, d] = t.map(|i| x[i]);
        let e = mesh::tet_volume(&a, &b, &c, &d);
        v += e;
        v0 += e0;
        let r = e / e0;
        s.max_element_change = s.max_element_change.max((r - 1.0).abs());
        s.min_element_ratio = s.min_element_ratio.min(r);
        if !(r > 0.0) {
            s.inverted += 1;
        }
    }
    s.ratio = v / v0;
    s
}

/// Metrics every tissue score carries, from the observed nodes.
fn common_metrics(m: &mut BTreeMap<String, f64>, mesh: &TetMesh, t: &TissueObs) {
    let v = volume_stats(mesh, &t.nodes);
    m.insert("volume_change_rel".into(), (v.ratio - 1.0).abs());
    m.insert("inverted_elements".into(), v.inverted as f64);
}

/// The force scores every indentation scene carries: the model's force `f`
/// against the reference `f_ref` (N).
fn force_metrics(m: &mut BTreeMap<String, f64>, f: f64, f_ref: f64) {
    m.insert("reaction_force_n".into(), f);
    m.insert("reference_force_n".into(), f_ref);
    m.insert("force_error_rel".into(), (f - f_ref).abs() / f_ref);
    m.insert("force_ratio".into(), f / f_ref);
}

/// Rollers on symmetry planes: every node of `mesh` not in `fixed` whose
/// `held(x)` holds any axis, with those axes.
fn rollers(mesh: &TetMesh, fixed: &[usize], held: impl Fn(&Vec3) -> [bool; 3]) -> Vec<(usize, [bool; 3])> {
    let fixed: HashSet<usize> = fixed.iter().copied().collect();
    (0..mesh.nodes.len())
        .filter(|i| !fixed.contains(i))
        .map(|i| (i, held(&mesh.nodes[i])))
        .filter(|(_, a)| a.iter().any(|&b| b))
        .collect()
}

/// Where the scene's sphere is at time `t` (m): its path at the control
/// timeline's load factor.
fn indenter_centre(scene: &Scene, t: f64) -> Option<Vec3> {
    let s = scene.control.command_at(t).insertion;
    scene.tissues().next()?.indenter.map(|i| i.centre_at(s))
}

/// Sweep of the sphere-contact scenes: mesh levels 0-3 with
/// [`SPHERE_DT`] (8 quasi-static load steps over the default ramp).
fn contact_sweep() -> Vec<Fidelity> {
    (0..=MAX_LEVEL)
        .map(|l| Fidelity {
            mesh_level: Some(l),
            dt: Some(SPHERE_DT),
            ..Default::default()
        })
        .collect()
}

fn material(p: &Params, nu: f64) -> SolidMaterial {
    SolidMaterial {
        youngs_modulus: p.get("youngs_modulus"),
        poisson_ratio: nu,
        density: p.get("density"),
    }
}

// ---------------------------------------------------------------------------
// block-compression
// ---------------------------------------------------------------------------

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

/// Read `[parameters] key` of a reference `meta.toml`.
fn meta_number(meta: &toml::Table, file: &Path, key: &str) -> Result<f64, UsageError> {
    meta.get("parameters")
        .and_then(|t| t.get(key))
        .and_then(|v| v.as_float().or_else(|| v.as_integer().map(|i| i as f64)))
        .ok_or_else(|| UsageError(format!("{}: no number `parameters.{key}`", file.display())))
}

/// Read and parse `<dir>/meta.toml`; returns the table and its path.
fn read_meta(dir: &Path) -> Result<(toml::Table, PathBuf), UsageError> {
    let path = dir.join("meta.toml");
    let text =
        std::fs::read_to_string(&path).map_err(|e| UsageError(format!("cannot read {}: {e}", path.display())))?;
    let meta = toml::from_str(&text).map_err(|e| UsageError(format!("{}: {}", path.display(), e.message())))?;
    Ok((meta, path))
}

/// The named `columns` of a numeric CSV whose first line is a header, in
/// the order asked, one `Vec` per row; a missing column, a short row or a
/// non-finite number is an error naming file, line and column.
pub fn read_csv_columns(file: &Path, columns: &[&str]) -> Result<Vec<Vec<f64>>, UsageError> {
    let text = std::fs::read_to_string(file).map_err(|e| UsageError(format!("cannot read {}: {e}", file.display())))?;
    let mut lines = text.lines().enumerate();
    let header: Vec<&str> = lines
        .next()
        .map(|(_, h)| h.split(',').map(str::trim).collect())
        .unwrap_or_default();
    let index: Vec<usize> = columns
        .iter()
        .map(|c| {
            header.iter().position(|h| h == c).ok_or_else(|| {
                UsageError(format!(
                    "{}: missing column `{c}` (header: `{}`)",
                    file.display(),
                    header.join(",")
                ))
            })
        })
        .collect::<Result<_, _>>()?;
    let mut rows = Vec::new();
    for (ln, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let row: Vec<f64> = line
            .split(',')
            .map(|c| c.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| UsageError(format!("{}:{}: not a row of numbers: `{line}`", file.display(), ln + 1)))?;
        if row.len() != header.len() || !row.iter().all(|v| v.is_finite()) {
            return Err(UsageError(format!(
                "{}:{}: expected {} finite numbers, got `{line}`",
                file.display(),
                ln + 1,
                header.len()
            )));
        }
        rows.push(index.iter().map(|&i| row[i]).collect());
    }
    Ok(rows)
}

/// Two named columns as `(x, y)` pairs with `x` strictly increasing and at
/// least two rows: a tabulated curve.
fn read_curve(file: &Path, x: &str, y: &str) -> Result<Vec<(f64, f64)>, UsageError> {
    let rows: Vec<(f64, f64)> = read_csv_columns(file, &[x, y])?
        .into_iter()
        .map(|r| (r[0], r[1]))
        .collect();
    if rows.len() < 2 || rows.windows(2).any(|w| !(w[1].0 > w[0].0)) {
        return Err(UsageError(format!(
            "{}: needs >= 2 rows of increasing `{x}`",
            file.display()
        )));
    }
    Ok(rows)
}

/// Linear interpolation of a tabulated curve (increasing `x`); `None`
/// outside its range.
fn interpolate(rows: &[(f64, f64)], x: f64) -> Option<f64> {
    let i = rows.windows(2).position(|w| x >= w[0].0 && x <= w[1].0)?;
    let (a, b) = (rows[i], rows[i + 1]);
    Some(a.1 + (b.1 - a.1) * (x - a.0) / (b.0 - a.0))
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

/// Block between a clamped base and a bonded plate, compressed.
pub struct BlockCompression;

/// Defaults follow `datasets/reference/block-compression/meta.toml`; the
/// Poisson ratio is the reference's (0.3) and not a parameter.
const BLOCK_PARAMS: &[ParamSpec] = &[
    p("edge", 0.01, "m", Range::Positive, "cube edge"),
    p(
        "strain",
        0.02,
        "1",
        Range::Open(0.0, 1.0),
        "nominal compressive strain of the plate, <= 0.2 (the reference's range); 0.02 = small strain, 0.2 = large",
    ),
    p("youngs_modulus", 5e3, "Pa", Range::Positive, "Young's modulus"),
    DENSITY,
    RAMP,
    DURATION,
    SETTLE,
];

struct BlockRun {
    scene: Scene,
    mesh: TetMesh,
    force_ref: f64,
    work: f64,
    edge: f64,
}

impl ScenarioRun for BlockRun {
    fn scene(&self) -> &Scene {
        &self.scene
    }
    fn score(&self, obs: &Observation) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        let Some(t) = tissue_of(obs, &self.mesh) else {
            return m;
        };
        // The body pushes the plate up (+z): compressive force positive.
        let f = obs.hand_force;
        m.insert("reaction_force_n".into(), f.z);
        m.insert("reference_force_n".into(), self.force_ref);
        m.insert("force_error_rel".into(), (f.z - self.force_ref).abs() / self.force_ref);
        m.insert("force_ratio".into(), f.z / self.force_ref);
        m.insert("lateral_force_rel".into(), f.xy().norm() / self.force_ref);
        common_metrics(&mut m, &self.mesh, t);
        m
    }
    fn energy_scale(&self) -> f64 {
        self.work
    }
    fn length_scale(&self) -> f64 {
        self.edge
    }
}

impl Scenario for BlockCompression {
    fn id(&self) -> &'static str {
        "block-compression"
    }
    fn description(&self) -> &'static str {
        "cube clamped at the base, bonded plate on top pushed down to `strain`: plate force"
    }
    fn family(&self) -> Family {
        Family::Tissue
    }
    fn params(&self) -> &'static [ParamSpec] {
        BLOCK_PARAMS
    }
    fn reference(&self) -> &'static str {
        "scikit-fem P2, LINEAR elasticity (datasets/reference/block-compression): exact for small strain; at 20% large-strain laws differ by design"
    }
    fn primary_error(&self) -> &'static str {
        "force_error_rel"
    }
    fn sweep(&self) -> Vec<Fidelity> {
        level_sweep()
    }
    fn instantiate_at(&self, p: &Params, fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        let level = mesh_level(self.id(), fidelity)?;
        let reference = BlockReference::load(&datasets_dir())?;
        let (edge, strain, e) = (p.get("edge"), p.get("strain"), p.get("youngs_modulus"));
        let force_ref = reference.force(strain, edge, e).ok_or_else(|| {
            UsageError(format!(
                "block-compression: strain {strain} is outside the reference's 0..{}",
                reference.max_strain()
            ))
        })?;
        let n = block_cells(level);
        let mesh = mesh::block(Vec3::new(edge, edge, edge), [n, n, n]);
        let tol = 1e-9 * edge;
        let mut body = TissueBody::new(mesh.clone(), material(p, reference.poisson_ratio));
        body.fixed_nodes = mesh::nodes_on_plane(&mesh, 2, 0.0, tol);
        body.driven_nodes = mesh::nodes_on_plane(&mesh, 2, edge, tol)
            .into_iter()
            .map(|i| (i, Vec3::new(0.0, 0.0, -strain * edge)))
            .collect();
        Ok(Box::new(BlockRun {
            scene: static_scene(self.id(), body, p)?,
            mesh,
            force_ref,
            // Twice the linear work F d / 2: room for stiffer large-strain laws.
            work: force_ref * strain * edge,
            edge,
        }))
    }
}

// ---------------------------------------------------------------------------
// lame-tube
// ---------------------------------------------------------------------------

/// Radial displacement (m) at radius `r` of a thick-walled tube (radii
/// `a < b`, m) under internal pressure `p` (Pa), plane strain, linear
/// elasticity (Timoshenko & Goodier, *Theory of Elasticity*, 3rd ed.,
/// Sec. 28, with `E -> E/(1-nu^2)`, `nu -> nu/(1-nu)` for plane strain):
/// `u(r) = p a^2 / (E (b^2 - a^2)) ((1+nu)(1-2nu) r + (1+nu) b^2 / r)`.
pub fn lame_radial_displacement(r: f64, a: f64, b: f64, p: f64, e: f64, nu: f64) -> f64 {
    p * a * a / (e * (b * b - a * a)) * ((1.0 + nu) * (1.0 - 2.0 * nu) * r + (1.0 + nu) * b * b / r)
}

/// Thick-walled tube under internal pressure, plane strain.
pub struct LameTube;

/// Defaults: the geometry and material of `datasets/reference/lame-tube`
/// with a tenth of its pressure, so that `u(a)/a = 1.9e-3`: the follower
/// pressure and large-strain laws depart from the linear closed form by
/// O(u(a)/a) (measured with the `fem` model at mesh level 2: +0.04 % of
/// RMS error at 10 Pa, +0.4 % at 100 Pa), under the P1 mesh error of every
/// level but the finest.
const LAME_PARAMS: &[ParamSpec] = &[
    p("inner_radius", 0.01, "m", Range::Positive, "inner radius a"),
    p("outer_radius", 0.02, "m", Range::Positive, "outer radius b > a"),
    p(
        "height",
        0.005,
        "m",
        Range::Positive,
        "length of the tube segment along z (plane strain: ends held in z)",
    ),
    p(
        "pressure",
        10.0,
        "Pa",
        Range::Positive,
        "internal pressure on the inner wall",
    ),
    p("youngs_modulus", 1e4, "Pa", Range::Positive, "Young's modulus"),
    p("poisson_ratio", 0.3, "1", Range::Open(0.0, 0.5), "Poisson ratio"),
    DENSITY,
    RAMP,
    DURATION,
    SETTLE,
];

struct LameRun {
    scene: Scene,
    mesh: TetMesh,
    /// `(a, b, p, E, nu)`.
    case: [f64; 5],
    inner: Vec<usize>,
}

impl LameRun {
    fn u(&self, r: f64) -> f64 {
        let [a, b, p, e, nu] = self.case;
        lame_radial_displacement(r, a, b, p, e, nu)
    }
}

impl ScenarioRun for LameRun {
    fn scene(&self) -> &Scene {
        &self.scene
    }
    fn score(&self, obs: &Observation) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        let Some(t) = tissue_of(obs, &self.mesh) else {
            return m;
        };
        let ua = self.u(self.case[0]);
        let (mut r2, mut rmax, mut v2, mut vmax) = (0.0, 0.0f64, 0.0, 0.0f64);
        for (x0, x) in self.mesh.nodes.iter().zip(&t.nodes) {
            let rr = x0.xy().norm();
            let er = Vec3::new(x0.x / rr, x0.y / rr, 0.0);
            let want = er * self.u(rr);
            let d = x - x0;
            let radial = (d.dot(&er) - self.u(rr)).abs();
            let full = (d - want).norm();
            r2 += radial * radial;
            rmax = rmax.max(radial);
            v2 += full * full;
            vmax = vmax.max(full);
        }
        let n = self.mesh.nodes.len() as f64;
        m.insert("rms_radial_error_rel".into(), (r2 / n).sqrt() / ua);
        m.insert("max_radial_error_rel".into(), rmax / ua);
        m.insert("rms_displacement_error_rel".into(), (v2 / n).sqrt() / ua);
        m.insert("max_displacement_error_rel".into(), vmax / ua);
        let inner_mean = self
            .inner
            .iter()
            .map(|&i| {
                let x0 = self.mesh.nodes[i];
                (t.nodes[i] - x0).dot(&Vec3::new(x0.x, x0.y, 0.0).normalize())
            })
            .sum::<f64>()
            / self.inner.len().max(1) as f64;
        m.insert("inner_wall_error_rel".into(), (inner_mean - ua).abs() / ua);
        common_metrics(&mut m, &self.mesh, t);
        m
    }
    fn energy_scale(&self) -> f64 {
        // Twice the work of the pressure on the inner wall of the quarter.
        let [a, _, p, _, _] = self.case;
        let h = self.mesh.nodes.iter().map(|x| x.z).fold(0.0, f64::max);
        p * self.u(a) * (0.5 * PI * a * h)
    }
    fn length_scale(&self) -> f64 {
        self.case[1]
    }
}

impl Scenario for LameTube {
    fn id(&self) -> &'static str {
        "lame-tube"
    }
    fn description(&self) -> &'static str {
        "quarter of a thick-walled tube (axis z) under internal pressure, plane strain: radial displacement"
    }
    fn family(&self) -> Family {
        Family::Tissue
    }
    fn params(&self) -> &'static [ParamSpec] {
        LAME_PARAMS
    }
    fn reference(&self) -> &'static str {
        "Lamé closed form, plane strain (Timoshenko & Goodier Sec. 28); scikit-fem P2 agrees to 6.7e-4 (datasets/reference/lame-tube)"
    }
    fn primary_error(&self) -> &'static str {
        "rms_radial_error_rel"
    }
    fn sweep(&self) -> Vec<Fidelity> {
        level_sweep()
    }
    fn instantiate_at(&self, p: &Params, fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        let level = mesh_level(self.id(), fidelity)?;
        let (a, b, h) = (p.get("inner_radius"), p.get("outer_radius"), p.get("height"));
        if !(b > a) {
            return Err(UsageError(format!(
                "lame-tube: outer_radius {b} m must exceed inner_radius {a} m"
            )));
        }
        let (pressure, e, nu) = (p.get("pressure"), p.get("youngs_modulus"), p.get("poisson_ratio"));
        if pressure / e > 0.05 {
            return Err(UsageError(format!(
                "lame-tube: pressure / youngs_modulus = {:.3} > 0.05 leaves the small-strain range of the closed form",
                pressure / e
            )));
        }
        // 2^(level+1) cells through the wall, three times as many around
        // the quarter, and enough along z to keep cells near cubic.
        let n_r = 2 << level;
        let n_t = 3 * n_r;
        let n_z = ((h / ((b - a) / n_r as f64)).round() as usize).clamp(1, 4 * n_r);
        let mesh = mesh::tube_sector(a, b, h, PI / 2.0, n_t, n_r, n_z);
        let tol = 1e-9 * b;
        let mut axes: BTreeMap<usize, [bool; 3]> = BTreeMap::new();
        let mut hold = |nodes: Vec<usize>, k: usize| {
            for i in nodes {
                axes.entry(i).or_insert([false; 3])[k] = true;
            }
        };
        hold(mesh::nodes_on_plane(&mesh, 1, 0.0, tol), 1);
        hold(mesh::nodes_on_plane(&mesh, 0, 0.0, tol), 0);
        hold(mesh::nodes_on_plane(&mesh, 2, 0.0, tol), 2);
        hold(mesh::nodes_on_plane(&mesh, 2, h, tol), 2);
        let inner = mesh::nodes_on_cylinder(&mesh, a, tol);
        let on_inner: HashSet<usize> = inner.iter().copied().collect();
        let mut body = TissueBody::new(mesh.clone(), material(p, nu));
        body.partial_fixed = axes.into_iter().collect();
        // Boundary faces are ordered with the outward normal: on the inner
        // wall it points towards the axis, the pressure pushes outwards.
        body.pressure_faces = mesh::boundary_faces(&mesh)
            .into_iter()
            .filter(|f| f.iter().all(|i| on_inner.contains(i)))
            .map(|f| (f, pressure))
            .collect();
        Ok(Box::new(LameRun {
            scene: static_scene(self.id(), body, p)?,
            mesh,
            case: [a, b, pressure, e, nu],
            inner,
        }))
    }
}

// ---------------------------------------------------------------------------
// volume-preservation
// ---------------------------------------------------------------------------

/// Block squashed and twisted: nearly incompressible volume preservation.
pub struct VolumePreservation;

const VOLUME_PARAMS: &[ParamSpec] = &[
    p("edge", 0.01, "m", Range::Positive, "cube edge"),
    p(
        "compression",
        0.2,
        "1",
        Range::Open(0.0, 0.6),
        "top face moved down by this fraction of the edge",
    ),
    p(
        "twist",
        PI / 4.0,
        "rad",
        Range::Closed(-PI / 2.0, PI / 2.0),
        "rotation of the top face about the vertical axis through its centre",
    ),
    p("youngs_modulus", 5e3, "Pa", Range::Positive, "Young's modulus"),
    p(
        "poisson_ratio",
        0.49,
        "1",
        Range::Open(0.0, 0.5),
        "Poisson ratio (nearly incompressible by default)",
    ),
    DENSITY,
    RAMP,
    DURATION,
    SETTLE,
];

struct VolumeRun {
    scene: Scene,
    mesh: TetMesh,
    work: f64,
    edge: f64,
}

impl ScenarioRun for VolumeRun {
    fn scene(&self) -> &Scene {
        &self.scene
    }
    fn score(&self, obs: &Observation) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        let Some(t) = tissue_of(obs, &self.mesh) else {
            return m;
        };
        let v = volume_stats(&self.mesh, &t.nodes);
        m.insert("volume_ratio".into(), v.ratio);
        m.insert("max_element_volume_change_rel".into(), v.max_element_change);
        m.insert("min_element_volume_ratio".into(), v.min_element_ratio);
        // Does the model's own volume report agree with its nodes?
        m.insert(
            "reported_volume_mismatch_rel".into(),
            (t.volume_error - (v.ratio - 1.0)).abs(),
        );
        common_metrics(&mut m, &self.mesh, t);
        m
    }
    fn energy_scale(&self) -> f64 {
        self.work
    }
    fn length_scale(&self) -> f64 {
        self.edge
    }
}

/// Displacement of a top-face node `x0` (m) of a cube of edge `edge`:
/// rotation by `twist` about the vertical axis through the face centre,
/// then down by `compression * edge`.
pub fn squash_twist(x0: &Vec3, edge: f64, compression: f64, twist: f64) -> Vec3 {
    let c = Vec3::new(0.5 * edge, 0.5 * edge, x0.z);
    let rot = nalgebra::Rotation3::from_axis_angle(&Vec3::z_axis(), twist);
    c + rot * (x0 - c) - Vec3::new(0.0, 0.0, compression * edge) - x0
}

impl Scenario for VolumePreservation {
    fn id(&self) -> &'static str {
        "volume-preservation"
    }
    fn description(&self) -> &'static str {
        "cube clamped at the base, top face squashed and twisted, nearly incompressible: volume change"
    }
    fn family(&self) -> Family {
        Family::Tissue
    }
    fn params(&self) -> &'static [ParamSpec] {
        VOLUME_PARAMS
    }
    fn reference(&self) -> &'static str {
        "exact volume (V = V0 for an incompressible solid); for nu < 0.5 a property metric, ~(1-2nu) x compression expected"
    }
    fn primary_error(&self) -> &'static str {
        "volume_change_rel"
    }
    fn sweep(&self) -> Vec<Fidelity> {
        level_sweep()
    }
    fn instantiate_at(&self, p: &Params, fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        let level = mesh_level(self.id(), fidelity)?;
        let (edge, c, twist) = (p.get("edge"), p.get("compression"), p.get("twist"));
        let n = block_cells(level);
        let mesh = mesh::block(Vec3::new(edge, edge, edge), [n, n, n]);
        let tol = 1e-9 * edge;
        let mut body = TissueBody::new(mesh.clone(), material(p, p.get("poisson_ratio")));
        body.fixed_nodes = mesh::nodes_on_plane(&mesh, 2, 0.0, tol);
        body.driven_nodes = mesh::nodes_on_plane(&mesh, 2, edge, tol)
            .into_iter()
            .map(|i| (i, squash_twist(&mesh.nodes[i], edge, c, twist)))
            .collect();
        let e = p.get("youngs_modulus");
        Ok(Box::new(VolumeRun {
            scene: static_scene(self.id(), body, p)?,
            mesh,
            // Elastic energy scale E V (strain^2 + shear^2), twice over.
            work: 2.0 * e * edge.powi(3) * (c * c + twist * twist),
            edge,
        }))
    }
}

// ---------------------------------------------------------------------------
// truth-cube
// ---------------------------------------------------------------------------

/// Edge of the Truth Cube (m), Kerdok et al. 2003.
pub const TRUTH_CUBE_EDGE: f64 = 0.08;

/// The Truth Cube data placed in the scene frame: the CT frame rotated so
/// that the loaded face (the one whose bead layer moves most) is at
/// `z = edge`, the fixed face at `z = 0`, the bead cloud centred on the cube.
#[derive(Debug, Clone, PartialEq)]
pub struct CubeFrame {
    /// CT axis of compression (0 = x, 1 = y, 2 = z).
    pub axis: usize,
    /// `+1` if the loaded face is on the CT axis's positive side, else `-1`.
    pub sign: f64,
    /// Centroid of the unloaded beads in the CT frame (m).
    pub center: Vec3,
    /// Rotation CT -> scene (rows: scene axes in CT coordinates); proper.
    pub rotation: Mat3,
    /// Beads in the scene frame, per state (0, 5, 12.5, 18.25 %), file order.
    pub beads: [Vec<Vec3>; 4],
    /// Mean displacement along the compression axis of the loaded-side and
    /// fixed-side bead layers at the largest strain, CT frame (m).
    pub layer_motion: (f64, f64),
}

impl CubeFrame {
    /// Fit the frame of `cube` for a cube of edge `edge` (m): compression
    /// axis = the CT axis along which the bead cloud shrinks most between
    /// the unloaded and the most compressed state; loaded face = the side
    /// whose outermost bead layer (beads within 5 mm of the extreme rest
    /// coordinate) moves most along that axis.
    pub fn fit(cube: &truth_cube::TruthCube, edge: f64) -> Result<Self, String> {
        let beads = &cube.beads;
        if beads.is_empty() {
            return Err("truth cube has no beads".into());
        }
        let last = 3;
        let extent = |s: usize, a: usize| {
            let v = beads.iter().map(|b| b.positions[s][a]);
            v.clone().fold(f64::NEG_INFINITY, f64::max) - v.fold(f64::INFINITY, f64::min)
        };
        let shrink: Vec<f64> = (0..3).map(|a| extent(0, a) - extent(last, a)).collect();
        let axis = (0..3)
            .max_by(|&i, &j| shrink[i].total_cmp(&shrink[j]))
            .expect("three axes");
        if !(shrink[axis] > 0.0) {
            return Err(format!(
                "no axis of compression in the bead data (extent changes {shrink:?} m)"
            ));
        }
        let lo = beads.iter().map(|b| b.positions[0][axis]).fold(f64::INFINITY, f64::min);
        let hi = beads
            .iter()
            .map(|b| b.positions[0][axis])
            .fold(f64::NEG_INFINITY, f64::max);
        let layer_motion = |at: f64| {
            let l: Vec<f64> = beads
                .iter()
                .filter(|b| (b.positions[0][axis] - at).abs() < 5e-3)
                .map(|b| b.positions[last][axis] - b.positions[0][axis])
                .collect();
            l.iter().sum::<f64>() / l.len().max(1) as f64
        };
        let (m_lo, m_hi) = (layer_motion(lo), layer_motion(hi));
        let (sign, loaded, fixed) = if m_hi.abs() > m_lo.abs() {
            (1.0, m_hi, m_lo)
        } else {
            (-1.0, m_lo, m_hi)
        };
        let center = beads.iter().map(|b| b.positions[0]).sum::<Vec3>() / beads.len() as f64;
        let ez = Vec3::ith(axis, sign);
        let ex = Vec3::ith((axis + 1) % 3, 1.0);
        let ey = ez.cross(&ex);
        let rotation = Mat3::from_rows(&[ex.transpose(), ey.transpose(), ez.transpose()]);
        let half = Vec3::repeat(0.5 * edge);
        let place = |s: usize| -> Vec<Vec3> {
            beads
                .iter()
                .map(|b| rotation * (b.positions[s] - center) + half)
                .collect()
        };
        Ok(Self {
            axis,
            sign,
            center,
            rotation,
            beads: [place(0), place(1), place(2), place(3)],
            layer_motion: (loaded, fixed),
        })
    }
}

/// The tet of `mesh` containing `p` and the barycentric weights of `p` in
/// it; for a point outside every tet (by more than round-off), the tet in
/// which its smallest weight is largest (nearest, extrapolating). `None`
/// only for a mesh without tets.
pub fn locate(mesh: &TetMesh, p: &Vec3) -> Option<(usize, [f64; 4])> {
    let mut best: Option<(usize, [f64; 4], f64)> = None;
    for (e, t) in mesh.tets.iter().enumerate() {
        let [a, b, c, d] = t.map(|i| mesh.nodes[i]);
        let m = Mat3::from_columns(&[b - a, c - a, d - a]);
        let Some(inv) = m.try_inverse() else { continue };
        let l = inv * (p - a);
        let w = [1.0 - l.x - l.y - l.z, l.x, l.y, l.z];
        let min = w.iter().copied().fold(f64::INFINITY, f64::min);
        if best.as_ref().is_none_or(|b| min > b.2) {
            best = Some((e, w, min));
            if min >= 0.0 {
                break;
            }
        }
    }
    best.map(|(e, w, _)| (e, w))
}

/// Truth Cube phantom under uniaxial compression between bonded plates.
///
/// Boundary conditions: bonded (no-slip) plates, the base held, the top
/// moved down by the nominal strain times 80 mm; the only plate model the
/// scene types express (a driven node is driven along all three axes). The
/// data show the loaded face slipped: its nearest bead layer bulges about as
/// much as the mid-height layers (0.9 mm at 5 %, 3.0 mm at 18.25 %, where a
/// bonded FEM gives 0.3 and 1.1 mm) and drifts 1.3-1.9 mm sideways, so
/// every model here carries a boundary-condition error of that size.
pub struct TruthCube;

/// Literature material: Kerdok et al. 2003 (RTV6166 gel, 30:70), with the
/// values OpenSurgSim's Truth Cube test takes from that paper: E = 15.3 kPa,
/// nu = 0.499, rho = 980 kg/m^3. With only prescribed displacements and no
/// gravity the static bead positions do not depend on E (stress scales
/// with it, displacements do not), so nothing is calibrated on any level.
const TRUTH_PARAMS: &[ParamSpec] = &[
    p(
        "strain_level",
        1.0,
        "1",
        Range::Closed(1.0, 3.0),
        "1, 2, 3: nominal compression 5 %, 12.5 %, 18.25 % (Kerdok et al. 2003)",
    ),
    p(
        "youngs_modulus",
        15.3e3,
        "Pa",
        Range::Positive,
        "Young's modulus (Kerdok et al. 2003)",
    ),
    p(
        "poisson_ratio",
        0.499,
        "1",
        Range::Open(0.0, 0.5),
        "Poisson ratio (Kerdok et al. 2003: nearly incompressible)",
    ),
    p("density", 980.0, "kg/m^3", Range::Positive, "density of RTV6166"),
    RAMP,
    DURATION,
    p(
        "settle_tol",
        1e-4,
        "m/s",
        Range::Positive,
        "static equilibrium when every node is slower than this (after the ramp; 80 mm cube)",
    ),
];

struct TruthRun {
    scene: Scene,
    mesh: TetMesh,
    /// Containing tet and weights of every bead's rest position.
    cells: Vec<(usize, [f64; 4])>,
    /// Measured bead positions at the scored level, scene frame (m).
    measured: Vec<Vec3>,
    /// Measured bead displacements' RMS at that level (m).
    data_rms: f64,
    work: f64,
}

impl ScenarioRun for TruthRun {
    fn scene(&self) -> &Scene {
        &self.scene
    }
    fn score(&self, obs: &Observation) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        let Some(t) = tissue_of(obs, &self.mesh) else {
            return m;
        };
        let err: Vec<Vec3> = self
            .cells
            .iter()
            .zip(&self.measured)
            .map(|((e, w), want)| {
                let tet = self.mesh.tets[*e];
                (0..4).map(|k| t.nodes[tet[k]] * w[k]).sum::<Vec3>() - want
            })
            .collect();
        let n = err.len() as f64;
        let rms = (err.iter().map(|e| e.norm_squared()).sum::<f64>() / n).sqrt();
        // Best rigid translation (the mean error) removed: frame alignment
        // only, no material parameter involved.
        let mean = err.iter().sum::<Vec3>() / n;
        let rms_aligned = (err.iter().map(|e| (e - mean).norm_squared()).sum::<f64>() / n).sqrt();
        m.insert("rms_bead_error_m".into(), rms);
        m.insert(
            "max_bead_error_m".into(),
            err.iter().map(|e| e.norm()).fold(0.0, f64::max),
        );
        m.insert("rms_bead_error_rel".into(), rms / self.data_rms);
        m.insert("rms_bead_error_aligned_m".into(), rms_aligned);
        common_metrics(&mut m, &self.mesh, t);
        m
    }
    fn energy_scale(&self) -> f64 {
        self.work
    }
    fn length_scale(&self) -> f64 {
        TRUTH_CUBE_EDGE
    }
}

/// Load the Truth Cube data from `<datasets>/phantom/truth-cube/`.
pub fn load_truth_cube(datasets: &Path) -> Result<truth_cube::TruthCube, UsageError> {
    truth_cube::load(datasets.join("phantom/truth-cube/truth-cube-uniaxial.csv")).map_err(UsageError)
}

impl Scenario for TruthCube {
    fn id(&self) -> &'static str {
        "truth-cube"
    }
    fn description(&self) -> &'static str {
        "Truth Cube phantom (80 mm silicone, 343 beads) compressed between bonded plates: bead positions"
    }
    fn family(&self) -> Family {
        Family::Tissue
    }
    fn params(&self) -> &'static [ParamSpec] {
        TRUTH_PARAMS
    }
    fn reference(&self) -> &'static str {
        "phantom data, Kerdok et al. 2003 (datasets/phantom/truth-cube); literature material, nothing fitted; bonded plates"
    }
    fn primary_error(&self) -> &'static str {
        "rms_bead_error_m"
    }
    fn sweep(&self) -> Vec<Fidelity> {
        level_sweep()
    }
    fn instantiate_at(&self, p: &Params, fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        let level_f = p.get("strain_level");
        if level_f.fract() != 0.0 {
            return Err(UsageError(format!(
                "truth-cube: strain_level must be 1, 2 or 3, got {level_f}"
            )));
        }
        let state = level_f as usize;
        let level = mesh_level(self.id(), fidelity)?;
        let cube = load_truth_cube(&datasets_dir())?;
        let frame = CubeFrame::fit(&cube, TRUTH_CUBE_EDGE).map_err(UsageError)?;
        let strain = truth_cube::NOMINAL_STRAINS[state];
        let edge = TRUTH_CUBE_EDGE;
        let n = block_cells(level);
        let mesh = mesh::block(Vec3::new(edge, edge, edge), [n, n, n]);
        let cells = frame.beads[0]
            .iter()
            .map(|b| locate(&mesh, b).expect("block mesh has tets"))
            .collect();
        let measured = frame.beads[state].clone();
        let data_rms = (frame.beads[0]
            .iter()
            .zip(&measured)
            .map(|(a, b)| (b - a).norm_squared())
            .sum::<f64>()
            / measured.len() as f64)
            .sqrt();
        let tol = 1e-9 * edge;
        let mut body = TissueBody::new(mesh.clone(), material(p, p.get("poisson_ratio")));
        body.fixed_nodes = mesh::nodes_on_plane(&mesh, 2, 0.0, tol);
        body.driven_nodes = mesh::nodes_on_plane(&mesh, 2, edge, tol)
            .into_iter()
            .map(|i| (i, Vec3::new(0.0, 0.0, -strain * edge)))
            .collect();
        let e = p.get("youngs_modulus");
        Ok(Box::new(TruthRun {
            scene: static_scene(self.id(), body, p)?,
            mesh,
            cells,
            measured,
            data_rms,
            // Bonded, nearly incompressible: a few times E V strain^2.
            work: 4.0 * e * edge.powi(3) * strain * strain,
        }))
    }
}

// ---------------------------------------------------------------------------
// wall-indentation
// ---------------------------------------------------------------------------

/// One profile probe of [`WallReference`]: `(line, coordinate, u_r (m))`,
/// line 0 along z (m) at `theta = 0`, line 1 around theta (rad) at
/// `z = length/2`.
pub type WallProbe = (u8, f64, f64);

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

/// Cells `(n_r, n_s)` of the quarter wall mesh at `level`: `2^(level+1)`
/// through the wall and twice that along the arc and along z, so each level
/// has 8x the tets of the one before (192, 1,536, 12,288, 98,304) and the
/// band cells are `band / n_r` (0.25, 0.125, 0.0625, 0.031 mm).
pub fn wall_sphere_cells(level: usize) -> (usize, usize) {
    (2 << level, 4 << level)
}

/// The quarter wall (`y >= 0`, `z >= length/2`) at `level`: the structured
/// block on the unit cube, node `(xi_r, xi_s, xi_z)` mapped to `r = a + t
/// expm1(kappa xi_r) / expm1(kappa)`, arc `s = rho(xi_s)` on the inner wall
/// (`theta = s / a`) and `z = length/2 + rho(xi_z)` ([`WallReference::grading`]):
/// the reference's own map with fewer cells.
pub fn wall_sphere_mesh(r: &WallReference, level: usize) -> TetMesh {
    let (n_r, n_s) = wall_sphere_cells(level);
    let mut m = mesh::block(Vec3::new(1.0, 1.0, 1.0), [n_r, n_s, n_s]);
    let t = r.outer_radius - r.inner_radius;
    let k = r.radial_grading;
    let (arc, half) = (0.5 * r.inner_radius * r.sector_angle, 0.5 * r.length);
    for p in &mut m.nodes {
        let rad = r.inner_radius + t * (k * p.x).exp_m1() / k.exp_m1();
        let th = r.grading(p.y, arc) / r.inner_radius;
        *p = Vec3::new(rad * th.cos(), rad * th.sin(), half + r.grading(p.z, half));
    }
    mesh::orient_positive(&mut m);
    m
}

/// A spherical catheter tip indenting a vessel-wall segment.
///
/// The scene: a rigid frictionless sphere of radius `R` (1 mm: a 6F
/// catheter is 2 mm across) inside the lumen touches the inner wall at
/// `theta = 0, z = length/2` and moves radially outward (`+x`) by `depth`
/// along the load ramp ([`TissueBody::indenter`], so it needs
/// `Capability::TissueContact`); the contact footprint grows with the
/// depth. One quarter is modelled (`y >= 0`, `z >= length/2`) with rollers
/// on the symmetry planes (`y` held on `y = 0`, `z` on `z = length/2`), the
/// far end and the straight edge clamped, the outer surface free; the mesh
/// ([`wall_sphere_mesh`]) is the reference's graded map. Geometry and
/// material as [`WallPunch`] (inner radius 4 mm, wall 1 mm, 120 deg sector
/// 8 mm long, `E = 1 MPa`, `nu = 0.45`, Holzapfel, Gasser & Ogden 2000).
///
/// The model reports the force the body exerts on the sphere as
/// `hand_force`; the full force is `-4 hand_force.x`. Scores against the
/// scikit-fem reference ([`WallReference`]): `force_error_rel` (primary)
/// at full depth, `force_curve_error_rel` (RMS over the ramp against the
/// reference at every step's depth `s depth`, accumulated in
/// [`ScenarioRun::observe_step`]), `surface_error_rel` (the inner wall's
/// radial displacement along the axial line through the tip and around the
/// circumferential line through it, RMS error over RMS reference),
/// `penetration_over_depth` (deepest inner-wall node inside the sphere) and
/// `contact_extent_z_m` beside the reference's (the farthest inner-wall
/// node along z touching the sphere: a cell's resolution).
pub struct WallIndentation;

/// Young's modulus of the vessel-wall scenes (`wall-indentation`, `wall-punch`).
const WALL_E: ParamSpec = p(
    "youngs_modulus",
    1e6,
    "Pa",
    Range::Positive,
    "Young's modulus (arterial wall order of magnitude, Holzapfel et al. 2000)",
);
/// Density of the vessel-wall scenes.
const WALL_DENSITY: ParamSpec = p(
    "density",
    1060.0,
    "kg/m^3",
    Range::Positive,
    "density of the vessel wall",
);

/// Geometry, `E`'s reference value and `nu` come from the reference; the
/// depth is bounded by the reference's curve (1-20 % of the wall thickness).
const WALL_PARAMS: &[ParamSpec] = &[
    p(
        "depth",
        1e-4,
        "m",
        Range::Positive,
        "sphere travel into the wall at the end of the ramp, 1e-5..2e-4 (1-20 % of the 1 mm wall, the reference's range)",
    ),
    WALL_E,
    WALL_DENSITY,
    RAMP,
    DURATION,
    p(
        "settle_tol",
        4e-6,
        "m/s",
        Range::Positive,
        "static equilibrium when every node is slower than this (after the ramp; ~1 % of the ramp's mean speed at the default depth)",
    ),
];

struct WallSphereRun {
    scene: Scene,
    mesh: TetMesh,
    depth: f64,
    force_ref: f64,
    extent_ref: f64,
    radius: f64,
    /// Inner-wall nodes (rest positions on `r = a`).
    inner: Vec<usize>,
    /// `(containing tet, weights, radial direction, reference u_r (m))` of
    /// each profile probe.
    probes: Vec<(usize, [f64; 4], Vec3, f64)>,
    reference: WallReference,
    e_scale: f64,
    track: Mutex<CurveTrack>,
}

impl WallSphereRun {
    /// Indentation force on the whole sphere (N): four quarters, the body
    /// pushes the sphere back along `-x`.
    fn force(obs: &Observation) -> f64 {
        -4.0 * obs.hand_force.x
    }
}

impl ScenarioRun for WallSphereRun {
    fn scene(&self) -> &Scene {
        &self.scene
    }
    fn score(&self, obs: &Observation) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        let (Some(t), Some(c)) = (tissue_of(obs, &self.mesh), indenter_centre(&self.scene, obs.time)) else {
            return m;
        };
        let f = Self::force(obs);
        force_metrics(&mut m, f, self.force_ref);
        let (mut pen, mut extent) = (0.0f64, 0.0f64);
        let zc = 0.5 * self.reference.length;
        for &i in &self.inner {
            let gap = (t.nodes[i] - c).norm() - self.radius;
            pen = pen.max(-gap);
            // Touching: inside, or on the sphere to round-off.
            if gap <= 1e-9 * self.radius {
                extent = extent.max(self.mesh.nodes[i].z - zc);
            }
        }
        m.insert("penetration_over_depth".into(), pen / self.depth);
        m.insert("contact_extent_z_m".into(), extent);
        m.insert("reference_contact_extent_z_m".into(), self.extent_ref);
        let (mut e2, mut r2, mut emax) = (0.0, 0.0, 0.0f64);
        for (e, w, dir, want) in &self.probes {
            let tet = self.mesh.tets[*e];
            let u: Vec3 = (0..4).map(|k| (t.nodes[tet[k]] - self.mesh.nodes[tet[k]]) * w[k]).sum();
            let d = u.dot(dir) - want;
            e2 += d * d;
            r2 += want * want;
            emax = emax.max(d.abs());
        }
        if r2 > 0.0 {
            m.insert("surface_error_rel".into(), (e2 / r2).sqrt());
            m.insert("surface_error_max_rel".into(), emax / self.depth);
        }
        if let Some(e) = self.track.lock().unwrap_or_else(|e| e.into_inner()).error_rel() {
            m.insert("force_curve_error_rel".into(), e);
        }
        common_metrics(&mut m, &self.mesh, t);
        m
    }
    fn observe_step(&self, obs: &Observation) {
        let s = self.scene.control.command_at(obs.time).insertion;
        // The reference at this step's depth; none below its first row.
        let Some(want) = self.reference.force(s * self.depth, self.e_scale) else {
            return;
        };
        let mut c = self.track.lock().unwrap_or_else(|e| e.into_inner());
        c.add(obs.time, Self::force(obs), want);
    }
    fn energy_scale(&self) -> f64 {
        // The work is below F depth (the force grows with the depth).
        self.force_ref * self.depth
    }
    fn length_scale(&self) -> f64 {
        self.reference.length
    }
}

impl Scenario for WallIndentation {
    fn id(&self) -> &'static str {
        "wall-indentation"
    }
    fn description(&self) -> &'static str {
        "vessel-wall sector (r 4-5 mm, quarter) indented by a rigid frictionless sphere (catheter tip, R 1 mm): force-depth curve, deformed inner wall, contact extent"
    }
    fn family(&self) -> Family {
        Family::Tissue
    }
    fn params(&self) -> &'static [ParamSpec] {
        WALL_PARAMS
    }
    fn reference(&self) -> &'static str {
        "scikit-fem P2, LINEAR elasticity, frictionless unilateral contact with the exact gap (datasets/reference/wall-indentation)"
    }
    fn primary_error(&self) -> &'static str {
        "force_error_rel"
    }
    /// Mesh levels 0-3 with 8 quasi-static load steps over the default ramp
    /// ([`SPHERE_DT`]).
    fn sweep(&self) -> Vec<Fidelity> {
        contact_sweep()
    }
    fn quick_sweep(&self) -> Vec<Fidelity> {
        self.sweep().into_iter().take(2).collect()
    }
    fn instantiate_at(&self, p: &Params, fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        let level = mesh_level(self.id(), fidelity)?;
        let r = WallReference::load(&datasets_dir())?;
        let (depth, e) = (p.get("depth"), p.get("youngs_modulus"));
        let (lo, hi) = r.depth_range();
        let (Some(force_ref), Some(extent_ref), Some(profile)) =
            (r.force(depth, e), r.contact_extent(depth), r.profile(depth))
        else {
            return Err(UsageError(format!(
                "wall-indentation: depth {depth} m is outside the reference's [{lo}, {hi}] m"
            )));
        };
        let mesh = wall_sphere_mesh(&r, level);
        let (a, half_angle, zc) = (r.inner_radius, 0.5 * r.sector_angle, 0.5 * r.length);
        let tol = 1e-9 * r.outer_radius;
        let mut body = TissueBody::new(mesh.clone(), material(p, r.poisson_ratio));
        body.fixed_nodes = mesh::nodes_where(&mesh, |x| x.y.atan2(x.x) >= half_angle - 1e-9 || x.z >= r.length - tol);
        body.partial_fixed = rollers(&mesh, &body.fixed_nodes, |x| {
            [false, x.y <= tol, (x.z - zc).abs() <= tol]
        });
        body.indenter = Some(surgbench_core::scene::SphereIndenter {
            centre: Vec3::new(a - r.tip_radius, 0.0, zc),
            radius: r.tip_radius,
            travel: Vec3::new(depth, 0.0, 0.0),
        });
        let inner = mesh::nodes_on_cylinder(&mesh, a, tol);
        // Probes mirrored onto the quarter, a hair inside the wall, the
        // clamped ends pulled in by 1e-9 of their extent (as the script).
        let rp = a * (1.0 + 1e-9);
        let probes = profile
            .iter()
            .map(|&(line, coord, want)| {
                let (x, dir) = if line == 0 {
                    let z = (zc + (coord - zc).abs()).min(r.length * (1.0 - 1e-9));
                    (Vec3::new(rp, 0.0, z), Vec3::x())
                } else {
                    let th = coord.abs().min(half_angle * (1.0 - 1e-9));
                    let dir = Vec3::new(th.cos(), th.sin(), 0.0);
                    (rp * dir + Vec3::new(0.0, 0.0, zc), dir)
                };
                let (e, w) = locate(&mesh, &x).expect("wall mesh has tets");
                (e, w, dir, want)
            })
            .collect();
        Ok(Box::new(WallSphereRun {
            scene: static_scene(self.id(), body, p)?,
            mesh,
            depth,
            force_ref,
            extent_ref,
            radius: r.tip_radius,
            inner,
            probes,
            e_scale: e,
            reference: r,
            track: Mutex::new(CurveTrack::default()),
        }))
    }
}

// ---------------------------------------------------------------------------
// wall-punch
// ---------------------------------------------------------------------------

/// Relative tolerance of the footprint rule `y^2 + (z - L/2)^2 <= r_p^2 (1 +
/// tol)`: inclusive, so nodes exactly on the punch rim count on every level
/// (the scikit-fem script applies the same rule to its DOFs).
pub const FOOTPRINT_TOL: f64 = 1e-6;

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

/// Cells `(n_theta, n_r, n_z)` of the wall mesh at `level`: `2^level`
/// through the wall and as many cells of that size as fit (rounded) around
/// the inner arc and along the segment, so each level has 8x the tets of
/// the one before.
pub fn wall_cells(r: &PunchReference, level: usize) -> (usize, usize, usize) {
    let t = r.outer_radius - r.inner_radius;
    let around = ((r.inner_radius * r.sector_angle / t).round() as usize).max(1);
    let along = ((r.length / t).round() as usize).max(1);
    (around << level, 1 << level, along << level)
}

/// The wall mesh at `level`: [`mesh::tube_sector`] turned about z by
/// `-angle/2`, so the sector spans `-angle/2 <= theta <= angle/2` and the
/// punch sits on the `+x` axis.
pub fn wall_mesh(r: &PunchReference, level: usize) -> TetMesh {
    let (n_t, n_r, n_z) = wall_cells(r, level);
    let m = mesh::tube_sector(r.inner_radius, r.outer_radius, r.length, r.sector_angle, n_t, n_r, n_z);
    let rot = nalgebra::Rotation3::from_axis_angle(&Vec3::z_axis(), -0.5 * r.sector_angle);
    TetMesh {
        nodes: m.nodes.iter().map(|x| rot * x).collect(),
        tets: m.tets,
    }
}

/// Inner-wall nodes of `mesh` inside the punch footprint:
/// `y^2 + (z - length/2)^2 <= r_p^2 (1 + FOOTPRINT_TOL)`, ascending.
pub fn wall_footprint(r: &PunchReference, mesh: &TetMesh) -> Vec<usize> {
    let zc = 0.5 * r.length;
    let rp2 = r.punch_radius * r.punch_radius * (1.0 + FOOTPRINT_TOL);
    mesh::nodes_on_cylinder(mesh, r.inner_radius, 1e-9 * r.outer_radius)
        .into_iter()
        .filter(|&i| {
            let x = mesh.nodes[i];
            x.y * x.y + (x.z - zc) * (x.z - zc) <= rp2
        })
        .collect()
}

/// Clamped nodes of the wall: both ends (`z = 0, length`) and both straight
/// edges (`|theta| = angle/2`), ascending.
pub fn wall_clamped(r: &PunchReference, mesh: &TetMesh) -> Vec<usize> {
    let tol = 1e-9 * r.outer_radius;
    let half = 0.5 * r.sector_angle - 1e-9;
    mesh::nodes_where(mesh, |x| {
        x.z.abs() <= tol || (x.z - r.length).abs() <= tol || x.y.atan2(x.x).abs() >= half
    })
}

/// A catheter tip modelled as a bonded flat punch on a vessel-wall segment.
///
/// The linear companion of [`WallIndentation`] (the sphere in unilateral
/// contact): a rigid flat-ended circular punch of the catheter's radius,
/// bonded to the inner wall (every component of the footprint nodes is
/// prescribed) and pushed radially outward (`+x`) by `depth`. It needs no
/// tissue contact, so every tissue model runs it, and it is the scene of
/// the PBD local-activation study (`comparisons/pbd-hash.toml`).
///
/// Geometry and material (from the reference's `meta.toml`): inner radius
/// 4 mm and wall thickness 1 mm (carotid / femoral artery size), a 120 deg
/// sector 8 mm long, so the punch rim is about 3 wall thicknesses from every
/// clamped boundary; punch radius 1 mm (a 6F catheter is 2 mm across);
/// `E = 1 MPa`, `nu = 0.45`, the order of magnitude of the small-strain
/// modulus of the arterial wall (Holzapfel, Gasser & Ogden 2000, J.
/// Elasticity 61; nearly incompressible), density 1060 kg/m^3.
///
/// Scores: the punch force at the final depth against the reference
/// (`force_error_rel`, primary), the force along the ramp against the linear
/// reference curve `F_ref s(t)` at every step's load factor `s(t)`
/// (`force_curve_error_rel`: RMS error over RMS reference force,
/// accumulated in [`ScenarioRun::observe_step`]; equals the force error for
/// a linear quasi-static model) and the radial displacement of the inner
/// wall along the axial line through the punch centre, outside the footprint
/// (`surface_error_rel`: RMS error over RMS reference displacement).
pub struct WallPunch;

/// Geometry, `E`'s reference value and `nu` come from the reference; the
/// depth is bounded by the reference's curve (20 % of the wall thickness).
const PUNCH_PARAMS: &[ParamSpec] = &[
    p(
        "depth",
        5e-5,
        "m",
        Range::Positive,
        "punch displacement into the wall at the end of the ramp, <= 2e-4 (20 % of the 1 mm wall, the reference's range)",
    ),
    WALL_E,
    WALL_DENSITY,
    RAMP,
    DURATION,
    p(
        "settle_tol",
        2e-6,
        "m/s",
        Range::Positive,
        "static equilibrium when every node is slower than this (after the ramp; ~1 % of the ramp's mean speed at the default depth)",
    ),
];

/// Force-along-the-ramp statistics of one run (deduplicated by time).
#[derive(Debug, Clone, Default)]
struct CurveTrack {
    last_t: Option<f64>,
    /// Sum of `(F - F_ref s)^2` over the steps (N^2).
    err2: f64,
    /// Sum of `(F_ref s)^2` over the same steps (N^2).
    ref2: f64,
}

impl CurveTrack {
    /// Add the force `got` against the reference `want` (N) at time `t`
    /// (s): once per time; an earlier time starts a new run.
    fn add(&mut self, t: f64, got: f64, want: f64) {
        match self.last_t {
            Some(last) if t < last => *self = CurveTrack::default(),
            Some(last) if t == last => return,
            _ => {}
        }
        self.last_t = Some(t);
        self.err2 += (got - want).powi(2);
        self.ref2 += want * want;
    }

    /// RMS force error over the curve relative to the RMS reference, if any
    /// reference force was seen.
    fn error_rel(&self) -> Option<f64> {
        (self.ref2 > 0.0).then(|| (self.err2 / self.ref2).sqrt())
    }
}

struct PunchRun {
    scene: Scene,
    mesh: TetMesh,
    depth: f64,
    force_ref: f64,
    /// `(containing tet, weights, reference u_r)` of each profile probe (m).
    probes: Vec<(usize, [f64; 4], f64)>,
    length: f64,
    track: Mutex<CurveTrack>,
}

impl PunchRun {
    /// Indentation force (N): the body pushes the punch back along `-x`.
    fn force(obs: &Observation) -> f64 {
        -obs.hand_force.x
    }
}

impl ScenarioRun for PunchRun {
    fn scene(&self) -> &Scene {
        &self.scene
    }
    fn score(&self, obs: &Observation) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        let Some(t) = tissue_of(obs, &self.mesh) else {
            return m;
        };
        let f = Self::force(obs);
        force_metrics(&mut m, f, self.force_ref);
        m.insert("stiffness_n_per_m".into(), f / self.depth);
        m.insert("lateral_force_rel".into(), obs.hand_force.yz().norm() / self.force_ref);
        let (mut e2, mut r2, mut emax) = (0.0, 0.0, 0.0f64);
        for (e, w, want) in &self.probes {
            let tet = self.mesh.tets[*e];
            let u: Vec3 = (0..4).map(|k| (t.nodes[tet[k]] - self.mesh.nodes[tet[k]]) * w[k]).sum();
            // On theta = 0 the radial direction is +x.
            let d = u.x - want;
            e2 += d * d;
            r2 += want * want;
            emax = emax.max(d.abs());
        }
        if r2 > 0.0 {
            m.insert("surface_error_rel".into(), (e2 / r2).sqrt());
            m.insert("surface_error_max_rel".into(), emax / self.depth);
        }
        if let Some(e) = self.track.lock().unwrap_or_else(|e| e.into_inner()).error_rel() {
            m.insert("force_curve_error_rel".into(), e);
        }
        common_metrics(&mut m, &self.mesh, t);
        m
    }
    fn observe_step(&self, obs: &Observation) {
        let s = self.scene.control.command_at(obs.time).insertion;
        // Linear reference: F(t) = F_ref s(t) at load factor s(t).
        let want = self.force_ref * s;
        let mut c = self.track.lock().unwrap_or_else(|e| e.into_inner());
        c.add(obs.time, Self::force(obs), want);
    }
    fn energy_scale(&self) -> f64 {
        // Twice the linear work F d / 2.
        self.force_ref * self.depth
    }
    fn length_scale(&self) -> f64 {
        self.length
    }
}

impl Scenario for WallPunch {
    fn id(&self) -> &'static str {
        "wall-punch"
    }
    fn description(&self) -> &'static str {
        "vessel-wall sector (r 4-5 mm) indented by a 1 mm flat punch BONDED to the inner wall (the linear companion of wall-indentation's sphere): force, deformed surface"
    }
    fn family(&self) -> Family {
        Family::Tissue
    }
    fn params(&self) -> &'static [ParamSpec] {
        PUNCH_PARAMS
    }
    fn reference(&self) -> &'static str {
        "scikit-fem P2, LINEAR elasticity, bonded flat punch (datasets/reference/wall-punch)"
    }
    fn primary_error(&self) -> &'static str {
        "force_error_rel"
    }
    fn sweep(&self) -> Vec<Fidelity> {
        level_sweep()
    }
    fn instantiate_at(&self, p: &Params, fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        let level = mesh_level(self.id(), fidelity)?;
        let r = PunchReference::load(&datasets_dir())?;
        let (depth, e) = (p.get("depth"), p.get("youngs_modulus"));
        let force_ref = r.force(depth, e).filter(|f| *f > 0.0).ok_or_else(|| {
            UsageError(format!(
                "wall-punch: depth {depth} m is outside the reference's (0, {}] m",
                r.max_depth()
            ))
        })?;
        let mesh = wall_mesh(&r, level);
        let foot = wall_footprint(&r, &mesh);
        if foot.is_empty() {
            return Err(UsageError(format!(
                "wall-punch: no node of mesh level {level} lies in the punch footprint"
            )));
        }
        let mut body = TissueBody::new(mesh.clone(), material(p, r.poisson_ratio));
        body.fixed_nodes = wall_clamped(&r, &mesh);
        body.driven_nodes = foot.into_iter().map(|i| (i, Vec3::new(depth, 0.0, 0.0))).collect();
        // Profile probes strictly between the clamped ends and outside the
        // footprint: inside it every model is driven exactly.
        let zc = 0.5 * r.length;
        let probes = r
            .profile
            .iter()
            .filter(|(z, _)| *z > 0.0 && *z < r.length && (z - zc).abs() > r.punch_radius * (1.0 + FOOTPRINT_TOL))
            .map(|&(z, u)| {
                let (e, w) = locate(&mesh, &Vec3::new(r.inner_radius, 0.0, z)).expect("wall mesh has tets");
                (e, w, u * depth)
            })
            .collect();
        Ok(Box::new(PunchRun {
            scene: static_scene(self.id(), body, p)?,
            mesh,
            depth,
            force_ref,
            probes,
            length: r.length,
            track: Mutex::new(CurveTrack::default()),
        }))
    }
}

// ---------------------------------------------------------------------------
// sphere-indentation
// ---------------------------------------------------------------------------

/// Hertz force (N) of a rigid sphere of radius `r` (m) pressed `delta` (m)
/// into an elastic half-space (`E` Pa, `nu`), frictionless:
/// `F = (4/3) E* sqrt(R) delta^(3/2)`, `E* = E / (1 - nu^2)` (Hertz 1882;
/// Johnson, *Contact Mechanics*, 1985, eqs. 4.22-4.23). Small strain, the
/// sphere taken as a paraboloid (`a << R`).
pub fn hertz_force(r: f64, delta: f64, e: f64, nu: f64) -> f64 {
    4.0 / 3.0 * e / (1.0 - nu * nu) * r.sqrt() * delta.max(0.0).powf(1.5)
}

/// Hertz contact radius (m): `a = sqrt(R delta)` (Johnson 1985, eq. 4.22).
pub fn hertz_contact_radius(r: f64, delta: f64) -> f64 {
    (r * delta.max(0.0)).sqrt()
}

/// The same contact with the exact spherical profile instead of Hertz's
/// paraboloid, still linear elasticity on a half-space (Segedin 1957,
/// Mathematika 4; Maugis, *Contact, Adhesion and Rupture of Elastic
/// Solids*, 2000, eq. 3.103): with `L = ln((R + a)/(R - a))`,
/// `delta = (a/2) L` and `F = (E*/2) ((a^2 + R^2) L - 2 a R)`. Returns
/// `(F (N), a (m))` at `delta` (solved for `a` by bisection; `delta < R`).
/// Its ratio to [`hertz_force`] is the paraboloid bias of the Hertz
/// reference: expanding both in `a / R`, `1 - delta / (10 R) + O((delta/R)^2)`
/// (the sphere is softer: less material under it than under the paraboloid).
pub fn sphere_force_exact(r: f64, delta: f64, e: f64, nu: f64) -> (f64, f64) {
    let depth = |a: f64| 0.5 * a * ((r + a) / (r - a)).ln();
    let (mut lo, mut hi) = (0.0, r * (1.0 - 1e-12));
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if depth(mid) < delta {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let a = 0.5 * (lo + hi);
    let l = ((r + a) / (r - a)).ln();
    (0.5 * e / (1.0 - nu * nu) * ((a * a + r * r) * l - 2.0 * a * r), a)
}

/// Where the contact radius sits in the graded mesh's reference coordinate
/// `s` (0..1): it spans `3 n / 8` cells of a mesh with `n` cells per edge.
const SPHERE_A_AT: f64 = 0.375;
/// End of the uniform inner zone of the grading (reference coordinate).
const SPHERE_UNIFORM_TO: f64 = 0.5;

/// The grading map of the quarter block (see [`sphere_block_mesh`]): radius
/// `rho(s)` (m) of the cube shell at reference max-norm `s` in `[0, 1]`:
/// `rho = c s` for `s <= 1/2` (uniform cells of size `c / n`), then
/// `c s + (W - c) ((s - 1/2) / (1/2))^2` up to `rho(1) = W`; `c = a / (3/8)`
/// puts the Hertz contact radius `a` at `s = 3/8`.
pub fn sphere_grading(s: f64, a: f64, half_width: f64) -> f64 {
    let c = a / SPHERE_A_AT;
    let t = ((s - SPHERE_UNIFORM_TO) / (1.0 - SPHERE_UNIFORM_TO)).max(0.0);
    c * s + (half_width - c) * t * t
}

/// Quarter block `[0, W]^2 x [-W, 0]` (m) for a sphere pressed into its top
/// face `z = 0` at the corner `x = y = 0` (the symmetry axis), with
/// `n` cells per edge graded towards the contact: the structured block on
/// the unit cube, node `xi` (depth `zeta = xi_z`) moved to
/// `(xi_x, xi_y, -zeta) rho(s) / s` with `s = max(xi_x, xi_y, zeta)` and
/// `rho` = [`sphere_grading`]. Cube shells `s = const` map to cube shells,
/// so faces stay planar; cells are cubes of size `a / (3 n / 8)` inside
/// `s <= 1/2` (twice the contact radius) and grow outside, radially up to
/// `rho'(1) / rho(1) < 4 + c / W` times their tangential size. The map's
/// kinks (`xi_i = xi_j`) are planes of the Kuhn split, so every tet is the
/// image of one smooth piece.
pub fn sphere_block_mesh(a: f64, half_width: f64, n: usize) -> TetMesh {
    let mut m = mesh::block(Vec3::new(1.0, 1.0, 1.0), [n, n, n]);
    for p in &mut m.nodes {
        let s = p.x.max(p.y).max(p.z);
        let f = if s > 0.0 {
            sphere_grading(s, a, half_width) / s
        } else {
            0.0
        };
        *p = Vec3::new(p.x * f, p.y * f, -p.z * f);
    }
    mesh::orient_positive(&mut m);
    m
}

/// A rigid sphere pressed into the flat top of a large block: Hertz.
///
/// The catheter tip, in its textbook form: a rigid frictionless
/// sphere of radius `R` (the scene's [`surgbench_core::scene::SphereIndenter`],
/// so it needs `Capability::TissueContact`) touches the top face `z = 0` of
/// a block at the origin and moves down by `depth` (`delta`) along the
/// ramp. One quarter is modelled: the block is `[0, W]^2 x [-W, 0]` with
/// `W = size_ratio a` (`a = sqrt(R delta)` the Hertz contact radius),
/// rollers on the symmetry planes `x = 0` (x held) and `y = 0` (y held),
/// the bottom `z = -W` fixed, the outer sides free. The mesh
/// ([`sphere_block_mesh`]) is graded: uniform cubes of size `a / (3 n / 8)`
/// out to `2a` (the contact radius spans 1.5, 3, 6, 12 cells at mesh levels
/// 0-3), growing outside.
///
/// The model reports the force the body exerts on the sphere as
/// `hand_force`; the scene is a quarter, so the full force is
/// `4 hand_force.z`. Scores: `force_error_rel` (primary) at full depth
/// against Hertz ([`hertz_force`]), `force_curve_error_rel` (RMS over the
/// ramp against `F_H(s delta)` at every step's load factor `s`, accumulated
/// in [`ScenarioRun::observe_step`]), `contact_radius_error_rel` (the
/// contact edge located between the last touching and first free surface
/// node on the `y = 0` line, so resolved to half a cell:
/// `contact_radius_resolution_rel` says how much), `penetration_over_depth`
/// (deepest surface node inside the sphere), and
/// `paraboloid_bias_rel` (the exact-sphere force of
/// [`sphere_force_exact`] over Hertz, minus one: the part of the error that
/// is Hertz's, not the model's).
///
/// Expected biases of Hertz against an exact solution of this scene (all
/// make the block stiffer than Hertz, except the free sides and the
/// sphere): the paraboloid, `-delta / (10 R)` to first order (`-0.1 %` at
/// the default `delta / R = 0.01`); the finite depth, a layer bonded to a rigid base is
/// stiffer by `1 + 0.88 a / h + ...` at `nu = 0.3` (Dimitriadis et al.
/// 2002, Biophys. J. 82, eq. 12, with `h = W`: `+1.8 %` at `W = 50 a`);
/// finite strain (the default corotational law; strains ~ `a / R`): of
/// order `a / R = 10 %` times a small constant — the linear law
/// (`material_law = 1`) removes it. Measured values are in
/// `comparisons/tests/sphere_indentation.rs`.
pub struct SphereIndentation;

const SPHERE_PARAMS: &[ParamSpec] = &[
    p(
        "sphere_radius",
        1e-3,
        "m",
        Range::Positive,
        "indenter radius (a 6F catheter tip is 1 mm in radius)",
    ),
    p(
        "depth",
        1e-5,
        "m",
        Range::Positive,
        "indentation at the end of the ramp, <= 0.05 sphere_radius (Hertz is a small-strain theory; default delta/R = 0.01)",
    ),
    p(
        "youngs_modulus",
        1e4,
        "Pa",
        Range::Positive,
        "Young's modulus (soft tissue, 10 kPa)",
    ),
    p(
        "poisson_ratio",
        0.3,
        "1",
        Range::Closed(0.0, 0.45),
        "Poisson ratio (linear tets lock as it nears 1/2)",
    ),
    p(
        "size_ratio",
        50.0,
        "1",
        Range::Closed(5.0, 500.0),
        "block half-width and depth over the Hertz contact radius sqrt(R delta)",
    ),
    DENSITY,
    RAMP,
    DURATION,
    SETTLE,
];

struct SphereRun {
    scene: Scene,
    mesh: TetMesh,
    radius: f64,
    depth: f64,
    /// Hertz force on the whole sphere at full depth (N).
    force_ref: f64,
    contact_radius: f64,
    paraboloid_bias: f64,
    /// Top-surface nodes on the `y = 0` line, by rest `x`.
    line: Vec<usize>,
    top: Vec<usize>,
    half_width: f64,
    track: Mutex<CurveTrack>,
}

impl SphereRun {
    /// Force on the whole sphere (N): four quarters, the body pushes up.
    fn force(obs: &Observation) -> f64 {
        4.0 * obs.hand_force.z
    }
}

impl ScenarioRun for SphereRun {
    fn scene(&self) -> &Scene {
        &self.scene
    }
    fn score(&self, obs: &Observation) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        let Some(t) = tissue_of(obs, &self.mesh) else {
            return m;
        };
        let Some(c) = indenter_centre(&self.scene, obs.time) else {
            return m;
        };
        let f = Self::force(obs);
        force_metrics(&mut m, f, self.force_ref);
        m.insert("paraboloid_bias_rel".into(), self.paraboloid_bias);
        let pen = self
            .top
            .iter()
            .map(|&i| self.radius - (t.nodes[i] - c).norm())
            .fold(0.0, f64::max);
        m.insert("penetration_over_depth".into(), pen / self.depth);
        // Contact edge on the y = 0 line: between the last node inside (or
        // on) the sphere and the next one, by deformed distance from the axis.
        let inside: Vec<bool> = self
            .line
            .iter()
            .map(|&i| (t.nodes[i] - c).norm() <= self.radius)
            .collect();
        if let Some(k) = inside.iter().rposition(|&b| b)
            && k + 1 < self.line.len()
        {
            let (x0, x1) = (t.nodes[self.line[k]].x, t.nodes[self.line[k + 1]].x);
            let a_h = 0.5 * (x0 + x1);
            m.insert(
                "contact_radius_error_rel".into(),
                (a_h - self.contact_radius).abs() / self.contact_radius,
            );
            m.insert(
                "contact_radius_resolution_rel".into(),
                0.5 * (x1 - x0) / self.contact_radius,
            );
        }
        if let Some(e) = self.track.lock().unwrap_or_else(|e| e.into_inner()).error_rel() {
            m.insert("force_curve_error_rel".into(), e);
        }
        common_metrics(&mut m, &self.mesh, t);
        m
    }
    fn observe_step(&self, obs: &Observation) {
        let s = self.scene.control.command_at(obs.time).insertion;
        // Hertz along the ramp: F(s) = F_ref s^(3/2) at depth s delta.
        let want = self.force_ref * s.max(0.0).powf(1.5);
        let mut c = self.track.lock().unwrap_or_else(|e| e.into_inner());
        c.add(obs.time, Self::force(obs), want);
    }
    fn energy_scale(&self) -> f64 {
        // Hertz work (2/5) F delta on the quarter, with a factor 10 of room.
        self.force_ref * self.depth
    }
    fn length_scale(&self) -> f64 {
        self.half_width
    }
}

impl Scenario for SphereIndentation {
    fn id(&self) -> &'static str {
        "sphere-indentation"
    }
    fn description(&self) -> &'static str {
        "rigid frictionless sphere (R 1 mm) pressed into a large block (quarter, graded mesh): contact force and radius"
    }
    fn family(&self) -> Family {
        Family::Tissue
    }
    fn params(&self) -> &'static [ParamSpec] {
        SPHERE_PARAMS
    }
    fn reference(&self) -> &'static str {
        "Hertz 1882 (Johnson 1985 eq. 4.22-4.23): F = 4/3 E* sqrt(R) delta^1.5, a = sqrt(R delta); biased by the finite block (+~2 %) and the paraboloid (-0.1 %)"
    }
    fn primary_error(&self) -> &'static str {
        "force_error_rel"
    }
    /// Mesh levels 0-3 with 8 quasi-static load steps over the default ramp
    /// (`dt = ramp / 8`). Level 3 (32^3 cells) costs `fem` about 10 min and
    /// 2 GB per run (2 cores): the comparisons' TOML sweeps stop at 2.
    fn sweep(&self) -> Vec<Fidelity> {
        contact_sweep()
    }
    fn quick_sweep(&self) -> Vec<Fidelity> {
        self.sweep().into_iter().take(2).collect()
    }
    fn instantiate_at(&self, p: &Params, fidelity: &Fidelity) -> Result<Box<dyn ScenarioRun>, UsageError> {
        let level = mesh_level(self.id(), fidelity)?;
        let (radius, depth, e, nu) = (
            p.get("sphere_radius"),
            p.get("depth"),
            p.get("youngs_modulus"),
            p.get("poisson_ratio"),
        );
        if depth > 0.05 * radius {
            return Err(UsageError(format!(
                "sphere-indentation: depth {depth} m is past 0.05 sphere_radius ({} m): Hertz is a small-strain theory",
                0.05 * radius
            )));
        }
        let a = hertz_contact_radius(radius, depth);
        let w = p.get("size_ratio") * a;
        let n = block_cells(level);
        let mesh = sphere_block_mesh(a, w, n);
        let tol = 1e-9 * w;
        let mut body = TissueBody::new(mesh.clone(), material(p, nu));
        body.fixed_nodes = mesh::nodes_on_plane(&mesh, 2, -w, tol);
        body.partial_fixed = rollers(&mesh, &body.fixed_nodes, |x| {
            [x.x.abs() <= tol, x.y.abs() <= tol, false]
        });
        body.indenter = Some(surgbench_core::scene::SphereIndenter {
            centre: Vec3::new(0.0, 0.0, radius),
            radius,
            travel: Vec3::new(0.0, 0.0, -depth),
        });
        let top = mesh::nodes_on_plane(&mesh, 2, 0.0, tol);
        let mut line: Vec<usize> = top.iter().copied().filter(|&i| mesh.nodes[i].y.abs() <= tol).collect();
        line.sort_by(|&i, &j| mesh.nodes[i].x.total_cmp(&mesh.nodes[j].x));
        let force_ref = hertz_force(radius, depth, e, nu);
        let paraboloid_bias = sphere_force_exact(radius, depth, e, nu).0 / force_ref - 1.0;
        Ok(Box::new(SphereRun {
            scene: static_scene(self.id(), body, p)?,
            mesh,
            radius,
            depth,
            force_ref,
            contact_radius: a,
            paraboloid_bias,
            line,
            top,
            half_width: w,
            track: Mutex::new(CurveTrack::default()),
        }))
    }
}

/// Time step of the sphere-indentation sweep (s): 8 quasi-static load
/// increments over the default 0.25 s ramp (the load factor is sampled at
/// the steps; the force curve is scored at each).
pub const SPHERE_DT: f64 = 1.0 / 32.0;
