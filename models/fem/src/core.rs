//! The discretized solid: elements, lumped mass, per-element state, parallel
//! evaluation of energy, forces and Jacobian, and the lazy Jacobian update.

use crate::FemError;
use crate::assembly::Pattern;
use crate::element::{Elements, Jacobian, QUAD4, UpperBlocks, project_psd, rotation_angle, upper_of};
use crate::material::{Law, M3, Material};
use rayon::prelude::*;
use surgbench_core::{SolidMaterial, TetMesh, Vec3};

/// Per-element state, written by one element only (fixed slot).
#[derive(Clone)]
struct ElemState {
    f: [Vec3; 4],
    energy: f64,
    r: M3,
    j: f64,
    /// Upper blocks of the element Jacobian (`K_ba = K_ab^T`).
    k: UpperBlocks,
    /// Rotation the cached `k` was built with (lazy update).
    r_used: M3,
    has_k: bool,
    updated: bool,
}

/// Result of one evaluation.
#[derive(Debug, Clone, Copy, Default)]
pub struct EvalStats {
    /// Total elastic energy (J).
    pub energy: f64,
    /// Elements with `det F <= 0`.
    pub inverted: usize,
    /// Elements whose Jacobian block was recomputed (lazy update).
    pub updated: usize,
}

/// A tet mesh with a material: what statics and dynamics share.
pub struct Solid {
    /// Rest positions (m).
    pub rest: Vec<Vec3>,
    /// Element rest data.
    pub elems: Elements,
    /// Block sparsity pattern.
    pub pat: Pattern,
    /// Material law and Lamé parameters of the body's own material (the
    /// first of [`Solid::mats`]; every material shares its law).
    pub mat: Material,
    /// Every material: the body's, then its regions' (`TissueBody::regions`).
    mats: Vec<Material>,
    /// Each tet's index into `mats`; empty when every tet is of the first.
    tet_mat: Vec<usize>,
    /// Lumped nodal masses (kg): `rho V / 4` from each tet.
    pub mass: Vec<f64>,
    /// Rest stiffness per element (linear law), for warped / linear Jacobians.
    k0: Vec<UpperBlocks>,
    state: Vec<ElemState>,
    /// Assembled block CSR Jacobian `K = d(-f)/dx`.
    pub kmat: Vec<M3>,
    /// Elastic nodal forces `-dE/dx` (N) from the last evaluation.
    pub forces: Vec<Vec3>,
    /// Which Jacobian `kmat` holds (`None` before the first assembly).
    kmat_kind: Option<Jacobian>,
    pool: rayon::ThreadPool,
}

/// Index of tet `e`'s material under the per-tet indices `tet_material`
/// (empty: every tet is made of the first material).
fn material_index(tet_material: &[usize], e: usize) -> usize {
    tet_material.get(e).copied().unwrap_or(0)
}

impl Solid {
    /// Discretize `mesh` with `law`; `threads` worker threads for assembly.
    pub fn new(mesh: &TetMesh, material: &SolidMaterial, law: Law, threads: usize) -> Result<Self, FemError> {
        Self::with_materials(mesh, std::slice::from_ref(material), &[], law, threads)
    }

    /// [`Solid::new`] for a body of several materials: tet `e` is made of
    /// `materials[tet_material[e]]` (every tet of the first when
    /// `tet_material` is empty), as `TissueBody::tet_materials` gives them.
    pub fn with_materials(
        mesh: &TetMesh,
        materials: &[SolidMaterial],
        tet_material: &[usize],
        law: Law,
        threads: usize,
    ) -> Result<Self, FemError> {
        mesh.validate().map_err(FemError::BadInput)?;
        if materials.is_empty() {
            return Err(FemError::BadInput("no material".into()));
        }
        for m in materials {
            if !(m.youngs_modulus > 0.0 && m.youngs_modulus.is_finite()) {
                return Err(FemError::BadInput(format!(
                    "youngs_modulus must be > 0 Pa, got {}",
                    m.youngs_modulus
                )));
            }
            if !(m.poisson_ratio > -1.0 && m.poisson_ratio < 0.5) {
                return Err(FemError::BadInput(format!(
                    "poisson_ratio must be in (-1, 0.5), got {}",
                    m.poisson_ratio
                )));
            }
            if !(m.density > 0.0 && m.density.is_finite()) {
                return Err(FemError::BadInput(format!(
                    "density must be > 0 kg/m^3, got {}",
                    m.density
                )));
            }
        }
        if mesh.tets.is_empty() {
            return Err(FemError::BadInput("mesh has no tets".into()));
        }
        if !tet_material.is_empty()
            && (tet_material.len() != mesh.tets.len() || tet_material.iter().any(|&k| k >= materials.len()))
        {
            return Err(FemError::BadInput(format!(
                "tet materials: need one index below {} per tet ({} tets), got {} indices",
                materials.len(),
                mesh.tets.len(),
                tet_material.len()
            )));
        }
        let elems = Elements::new(mesh).map_err(FemError::BadInput)?;
        let pat = Pattern::new(&mesh.nodes, &mesh.tets);
        let mats: Vec<Material> = materials
            .iter()
            .map(|m| Material::new(law, m.youngs_modulus, m.poisson_ratio))
            .collect();
        let mat = mats[0];
        let of = |e: usize| material_index(tet_material, e);
        let mut mass = vec![0.0; mesh.nodes.len()];
        for (e, t) in mesh.tets.iter().enumerate() {
            for &i in t {
                mass[i] += materials[of(e)].density * elems.vol[e] / 4.0;
            }
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads.max(1))
            .build()
            .map_err(|e| FemError::BadInput(format!("cannot start {threads} threads: {e}")))?;
        let k0: Vec<UpperBlocks> = pool.install(|| {
            (0..elems.len())
                .into_par_iter()
                .map(|e| {
                    let m = &mats[of(e)];
                    upper_of(&elems.rest_stiffness(m.mu, m.lambda, e))
                })
                .collect()
        });
        let nan = M3::repeat(f64::NAN);
        let state = vec![
            ElemState {
                f: [Vec3::zeros(); 4],
                energy: 0.0,
                r: M3::identity(),
                j: 1.0,
                k: [M3::zeros(); 10],
                r_used: nan,
                has_k: false,
                updated: false,
            };
            elems.len()
        ];
        let nb = pat.nnz_blocks();
        Ok(Self {
            rest: mesh.nodes.clone(),
            elems,
            mat,
            mats,
            tet_mat: tet_material.to_vec(),
            mass,
            k0,
            state,
            kmat: vec![M3::zeros(); nb],
            forces: vec![Vec3::zeros(); pat.n],
            kmat_kind: None,
            pat,
            pool,
        })
    }

    /// Index of tet `e`'s material in the materials the solid was built
    /// with.
    pub fn material_index(&self, e: usize) -> usize {
        material_index(&self.tet_mat, e)
    }

    /// The material of tet `e`.
    pub fn material_of(&self, e: usize) -> &Material {
        &self.mats[self.material_index(e)]
    }

    /// Number of nodes.
    pub fn n_nodes(&self) -> usize {
        self.rest.len()
    }

    /// Run `f` inside this solid's thread pool.
    pub fn install<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        self.pool.install(f)
    }

    /// Evaluate energy and elastic forces at `x`; with `jac`, also assemble
    /// the Jacobian. `lazy_threshold` (rad, warped Jacobian only): keep an
    /// element's cached block while its rotation moved less than this since
    /// the block was built (0 = always rebuild).
    pub fn evaluate(&mut self, x: &[Vec3], jac: Option<Jacobian>, lazy_threshold: f64) -> EvalStats {
        let elems = &self.elems;
        let (mats, tet_mat) = (&self.mats, &self.tet_mat);
        let k0 = &self.k0;
        let state = &mut self.state;
        let pool = &self.pool;
        pool.install(|| {
            state.par_iter_mut().with_min_len(64).enumerate().for_each(|(e, s)| {
                let mat = &mats[tet_mat.get(e).copied().unwrap_or(0)];
                let (en, f, kin) = elems.energy_forces(mat, e, x);
                s.f = f;
                s.energy = en;
                s.r = kin.r;
                s.j = kin.j;
                s.updated = jac.is_some();
                match jac {
                    None => {}
                    Some(Jacobian::Warped) => {
                        let r = if mat.law == Law::Linear { M3::identity() } else { kin.r };
                        // The linear law's K0 never changes: build it once.
                        let stale = s.has_k
                            && (mat.law == Law::Linear
                                || (lazy_threshold > 0.0 && rotation_angle(&s.r_used, &r) <= lazy_threshold));
                        if !stale {
                            if mat.law == Law::Linear {
                                s.k = k0[e];
                            } else {
                                elems.warped_upper(mat.mu, mat.lambda, e, &r, &mut s.k);
                            }
                            s.r_used = r;
                            s.has_k = true;
                        } else {
                            s.updated = false;
                        }
                    }
                    Some(Jacobian::Exact) => {
                        s.k = if mat.law == Law::Linear {
                            k0[e]
                        } else {
                            upper_of(&elems.stiffness(mat, e, &kin))
                        };
                        s.has_k = false;
                    }
                    Some(Jacobian::Projected) => {
                        s.k = if mat.law == Law::Linear {
                            k0[e]
                        } else {
                            upper_of(&project_psd(&elems.stiffness(mat, e, &kin)))
                        };
                        s.has_k = false;
                    }
                }
            });
        });
        let mut stats = EvalStats::default();
        for s in state.iter() {
            stats.energy += s.energy;
            if s.j <= 0.0 {
                stats.inverted += 1;
            }
        }
        stats.updated = state.iter().filter(|s| s.updated).count();
        let st = &self.state;
        let pat = &self.pat;
        let forces = &mut self.forces;
        let kmat = &mut self.kmat;
        let kmat_kind = &self.kmat_kind;
        pool.install(|| {
            pat.reduce_vector(|e, a| st[e].f[a], forces);
            // With the warped Jacobian and no block rebuilt (lazy update),
            // the assembled matrix is what the same sums gave last time.
            if jac.is_some() && !(jac == Some(Jacobian::Warped) && *kmat_kind == jac && stats.updated == 0) {
                pat.reduce_matrix(|e, u| st[e].k[u], kmat);
            }
        });
        self.kmat_kind = jac.or(self.kmat_kind);
        stats
    }

    /// Consistent nodal loads (N) of a body force density `b(X)` (N/m^3)
    /// given in the rest configuration, integrated with the degree-2 rule
    /// [`QUAD4`] against the linear shape functions.
    pub fn body_loads(&self, b: &(dyn Fn(&Vec3) -> Vec3 + Sync)) -> Vec<Vec3> {
        self.body_loads_by_tet(&|x, _| b(x))
    }

    /// [`Solid::body_loads`] of a density `b(X, e)` that also depends on
    /// the tet `e` it is integrated over (gravity on a body of several
    /// materials: `rho_e g`).
    pub fn body_loads_by_tet(&self, b: &(dyn Fn(&Vec3, usize) -> Vec3 + Sync)) -> Vec<Vec3> {
        let mut out = vec![Vec3::zeros(); self.n_nodes()];
        for (e, t) in self.elems.tets.iter().enumerate() {
            let p = t.map(|i| self.rest[i]);
            for q in QUAD4 {
                let xq = p[0] * q[0] + p[1] * q[1] + p[2] * q[2] + p[3] * q[3];
                let bq = b(&xq, e) * (self.elems.vol[e] / 4.0);
                for a in 0..4 {
                    out[t[a]] += bq * q[a];
                }
            }
        }
        out
    }

    /// Energy (J) and elastic forces `-dE/dx` (N) at `x`, sequentially and
    /// without touching the cached state (for the energy probe).
    pub fn energy_forces(&self, x: &[Vec3]) -> (f64, Vec<Vec3>) {
        let mut e_sum = 0.0;
        let mut per: Vec<[Vec3; 4]> = Vec::with_capacity(self.elems.len());
        for e in 0..self.elems.len() {
            let (en, f, _) = self.elems.energy_forces(self.material_of(e), e, x);
            e_sum += en;
            per.push(f);
        }
        let mut out = vec![Vec3::zeros(); self.n_nodes()];
        self.pat.reduce_vector(|e, a| per[e][a], &mut out);
        (e_sum, out)
    }

    /// `K y` with the assembled Jacobian (block CSR), in node order.
    pub fn k_times(&self, y: &[Vec3]) -> Vec<Vec3> {
        let pat = &self.pat;
        let k = &self.kmat;
        let mut out = vec![Vec3::zeros(); self.n_nodes()];
        self.pool.install(|| {
            out.par_iter_mut().with_min_len(256).enumerate().for_each(|(i, o)| {
                let mut s = Vec3::zeros();
                for bi in pat.row_ptr[i]..pat.row_ptr[i + 1] {
                    s += k[bi] * y[pat.col[bi]];
                }
                *o = s;
            });
        });
        out
    }

    /// The smallest current-over-rest volume ratio `J = V / V0` of any tet
    /// (1 at rest, 0 collapsed, negative inverted): how close the most
    /// compressed element is to collapse.
    pub fn min_volume_ratio(&self, x: &[Vec3]) -> f64 {
        self.elems
            .tets
            .iter()
            .zip(&self.elems.vol)
            .map(|(t, v0)| {
                let p = t.map(|i| x[i]);
                surgbench_core::mesh::tet_volume(&p[0], &p[1], &p[2], &p[3]) / v0
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// Current volume over rest volume, minus one.
    pub fn volume_error(&self, x: &[Vec3]) -> f64 {
        let (mut v, mut v0) = (0.0, 0.0);
        for (e, t) in self.elems.tets.iter().enumerate() {
            let p = t.map(|i| x[i]);
            v += surgbench_core::mesh::tet_volume(&p[0], &p[1], &p[2], &p[3]);
            v0 += self.elems.vol[e];
        }
        v / v0 - 1.0
    }
}
