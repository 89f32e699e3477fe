//! Building a [`DerRod`] from a scene body: discretization, rest state and masses.

use super::*;
use crate::band::BandMatrix;
use crate::energy::{self, VertexParams, VertexTerms};
use surgbench_core::contact::LaggedFriction;
use surgbench_core::frames::rotate_about;
use surgbench_core::{BuildError, ContactParams, DeviceCommand, RodBody, Vec3};

impl DerRod {
    /// Discretise `body` with `segments` edges over its free length (plus the
    /// ghost edge behind the clamp). Edge properties come from
    /// [`RodBody::section_at`] at the edge midpoint; a vertex uses the average
    /// of its two edges' stiffnesses and the rest curvature of the section at
    /// its arclength, as the exact turning `kappa_bar = 2 tan(k l / 2)` of a
    /// circular arc of curvature `k` (1/m) over the Voronoi length `l`. The
    /// initial configuration is the rest (natural) shape, at rest.
    pub fn from_body(body: &RodBody, segments: usize) -> Result<Self, BuildError> {
        body.validate().map_err(|e| BuildError::bad("rod", e))?;
        if !(2..=1_000_000).contains(&segments) {
            return Err(BuildError::bad(
                "segments",
                format!("need 2..=1e6 rod segments, got {segments}"),
            ));
        }
        Ok(Self::at_rest(body, Discretised::new(body, segments)?))
    }

    /// The rod of `body` at rest in its discretisation `d`.
    fn at_rest(body: &RodBody, d: Discretised) -> Self {
        let (n, ne) = (d.n, d.n - 1);
        let ndof = 4 * n - 1;
        let nfree = ndof - CLAMPED_DOFS;
        let contact_stiffness = 10.0 * (0..ne).map(|j| d.ea[j] / d.rest_len[j]).fold(0.0, f64::max);
        Self {
            params: DerParams::default(),
            gravity: Vec3::zeros(),
            tip_force: body.tip_force,
            tip_torque: body.tip_torque,
            tip_load_ramp: body.tip_load_ramp.clone(),
            load_scale: body.tip_load_scale(0.0),
            vessel: None,
            contact: ContactParams::default(),
            contact_stiffness,
            contact_onset: 1e-5 * body.length,
            n,
            length: body.length,
            base: body.base,
            rest_len: d.rest_len,
            ea: d.ea,
            rot_inertia: d.rot_inertia,
            vparams: d.vparams,
            edge_bend: d.bend,
            bend_len: d.bend_len,
            node_mass: d.node_mass,
            node_forces: vec![Vec3::zeros(); n],
            qdot: vec![0.0; ndof],
            qddot: vec![0.0; ndof],
            accel_valid: false,
            q0: d.q.clone(),
            qtilde: d.q.clone(),
            a1_0: d.a1.clone(),
            tan_0: d.tan.clone(),
            rtwist_0: d.rtwist.clone(),
            q: d.q,
            a1: d.a1,
            tan: d.tan,
            rtwist: d.rtwist,
            grad: vec![0.0; ndof],
            fext: vec![0.0; ndof],
            fext_prev: vec![0.0; ndof],
            res: vec![0.0; nfree],
            dz: vec![0.0; nfree],
            band: BandMatrix::new(nfree, BAND),
            terms: VertexTerms::default(),
            inertia: None,
            lin: vec![0.0; ndof],
            time: 0.0,
            rest: d.x,
            arclength: d.arclength,
            contacts: Vec::new(),
            lag: vec![ContactLag::NONE; n],
            friction: vec![LaggedFriction::NONE; n],
            friction_eps: 0.0,
            line_base: vec![0.0; nfree],
            gap: vec![f64::NEG_INFINITY; n],
            node_len: d.node_len,
            prev_cmd: DeviceCommand::default(),
            snaps: Vec::new(),
            substeps: 0,
            substep_depth: 0,
            flow: None,
            moving: None,
            edge_diam: d.edge_diam,
            drag_flow: vec![Vec3::zeros(); n],
            drag_tan: vec![Vec3::x(); n],
            drag_a: 0.0,
        }
    }
}

/// A rod body cut into edges: per-edge stiffnesses and inertias, per-vertex
/// bending and twisting parameters, and the rest shape with its frames.
struct Discretised {
    /// Vertices, the ghost vertex behind the clamp included.
    n: usize,
    rest_len: Vec<f64>,
    ea: Vec<f64>,
    bend: Vec<[f64; 2]>,
    rot_inertia: Vec<f64>,
    node_mass: Vec<f64>,
    vparams: Vec<VertexParams>,
    bend_len: Vec<f64>,
    x: Vec<Vec3>,
    a1: Vec<Vec3>,
    tan: Vec<Vec3>,
    q: Vec<f64>,
    rtwist: Vec<f64>,
    arclength: Vec<f64>,
    edge_diam: Vec<f64>,
    node_len: Vec<f64>,
}

impl Discretised {
    /// `body` cut into `segments` edges plus the ghost edge.
    fn new(body: &RodBody, segments: usize) -> Result<Self, BuildError> {
        let n = segments + 2;
        let ne = n - 1;
        let delta = body.length / segments as f64;
        let rest_len = vec![delta; ne];
        let edges = EdgeProps::new(body, delta, n);
        let (vparams, bend_len) = vertex_params(body, delta, &rest_len, &edges)?;
        let (x, a1, tan) = rest_shape(body, &vparams, &rest_len, delta);
        let ndof = 4 * n - 1;
        let mut q = vec![0.0; ndof];
        for (k, xk) in x.iter().enumerate() {
            q[4 * k..4 * k + 3].copy_from_slice(xk.as_slice());
        }
        let mut rtwist = vec![0.0; n];
        for i in 1..n - 1 {
            rtwist[i] = energy::reference_twist(&a1[i - 1], &tan[i - 1], &a1[i], &tan[i], 0.0);
        }
        let arclength = (0..n).map(|k| (k as f64 - 1.0) * delta).collect();
        let edge_diam: Vec<f64> = (0..ne)
            .map(|j| 2.0 * body.section_at((j as f64 - 0.5) * delta).radius)
            .collect();
        let node_len: Vec<f64> = (0..n)
            .map(|k| {
                let a = if k > 0 { rest_len[k - 1] } else { f64::INFINITY };
                let b = if k < ne { rest_len[k] } else { f64::INFINITY };
                a.min(b)
            })
            .collect();
        Ok(Self {
            n,
            rest_len,
            ea: edges.ea,
            bend: edges.bend,
            rot_inertia: edges.rot_inertia,
            node_mass: edges.node_mass,
            vparams,
            bend_len,
            x,
            a1,
            tan,
            q,
            rtwist,
            arclength,
            edge_diam,
            node_len,
        })
    }
}

/// Per-edge section properties (from the section at the edge midpoint) and
/// the vertex masses they lump (half of each free edge's mass per end).
struct EdgeProps {
    ea: Vec<f64>,
    bend: Vec<[f64; 2]>,
    gj: Vec<f64>,
    rot_inertia: Vec<f64>,
    node_mass: Vec<f64>,
}

impl EdgeProps {
    /// The `n - 1` edges of length `delta` of `body`.
    fn new(body: &RodBody, delta: f64, n: usize) -> Self {
        let ne = n - 1;
        let mut ea = Vec::with_capacity(ne);
        let mut bend = Vec::with_capacity(ne);
        let mut gj = Vec::with_capacity(ne);
        let mut rot_inertia = Vec::with_capacity(ne);
        let mut node_mass = vec![0.0; n];
        for j in 0..ne {
            let sec = body.section_at((j as f64 - 0.5) * delta);
            ea.push(sec.youngs_modulus * sec.area());
            let ei = sec.youngs_modulus * sec.second_moment();
            bend.push([ei, ei]);
            gj.push(sec.shear_modulus() * sec.polar_moment());
            rot_inertia.push(sec.density * sec.polar_moment() * delta);
            if j >= 1 {
                let m = sec.density * sec.area() * delta;
                node_mass[j] += 0.5 * m;
                node_mass[j + 1] += 0.5 * m;
            }
        }
        Self {
            ea,
            bend,
            gj,
            rot_inertia,
            node_mass,
        }
    }
}

/// Bending and twisting parameters and the bending length of every vertex
/// (the two end vertices carry none); a rest curvature that turns too far per
/// segment is an error.
fn vertex_params(
    body: &RodBody,
    delta: f64,
    rest_len: &[f64],
    edges: &EdgeProps,
) -> Result<(Vec<VertexParams>, Vec<f64>), BuildError> {
    let (bend, gj) = (&edges.bend, &edges.gj);
    let n = rest_len.len() + 1;
    let mut vparams = Vec::with_capacity(n);
    let mut bend_len = Vec::with_capacity(n);
    for i in 0..n {
        if i == 0 || i == n - 1 {
            bend_len.push(delta);
            vparams.push(VertexParams {
                bend: [0.0; 2],
                kappa_bar: [0.0; 2],
                twist: 0.0,
                twist_bar: 0.0,
                voronoi: delta,
            });
            continue;
        }
        let l = 0.5 * (rest_len[i - 1] + rest_len[i]);
        // Bending length: the clamp vertex's Voronoi region is only its
        // half inside the free rod (the ghost edge is inside the clamp and
        // does not bend). With the full region the clamp acts at -Delta/2
        // and the cantilever converges at first order only (measured).
        let lb = if i == 1 { 0.5 * rest_len[1] } else { l };
        bend_len.push(lb);
        let k = body.section_at((i as f64 - 1.0) * delta).rest_curvature;
        let km = (k[0] * k[0] + k[1] * k[1]).sqrt();
        if km * lb >= 0.9 * std::f64::consts::PI {
            return Err(BuildError::bad(
                "segments",
                format!(
                    "rest curvature {km} 1/m turns {:.2} rad per segment: use more segments",
                    km * lb
                ),
            ));
        }
        let kb = if km > 0.0 {
            2.0 * (0.5 * km * lb).tan() / km
        } else {
            0.0
        };
        // Energy B (kappa - kappa_bar)^2 / (2 lb), written with the twist's
        // Voronoi length l: stiffness scaled by l / lb.
        let sc = l / lb;
        vparams.push(VertexParams {
            bend: [
                sc * 0.5 * (bend[i - 1][0] + bend[i][0]),
                sc * 0.5 * (bend[i - 1][1] + bend[i][1]),
            ],
            // Scene convention: Darboux components (Omega.d1, Omega.d2);
            // Bergou's material curvature is (Omega.d2, -Omega.d1).
            kappa_bar: [k[1] * kb, -k[0] * kb],
            twist: 0.5 * (gj[i - 1] + gj[i]),
            twist_bar: 0.0,
            voronoi: l,
        });
    }
    Ok((vparams, bend_len))
}

/// The rest shape: vertex positions, first directors and tangents per edge,
/// integrating the rest turning of `vparams` from the clamp frame.
fn rest_shape(
    body: &RodBody,
    vparams: &[VertexParams],
    rest_len: &[f64],
    delta: f64,
) -> (Vec<Vec3>, Vec<Vec3>, Vec<Vec3>) {
    let n = vparams.len();
    let r = body.base.rotation.to_rotation_matrix();
    let (mut t, mut d1, mut d2) = (r * Vec3::x(), r * Vec3::y(), r * Vec3::z());
    let p = body.base.translation.vector;
    let mut x = vec![p - t * delta, p];
    let mut a1 = vec![d1];
    let mut tan = vec![t];
    for i in 1..n - 1 {
        let kbar = vparams[i].kappa_bar;
        let kb = d2 * kbar[0] - d1 * kbar[1];
        let kn = kb.norm();
        if kn > 0.0 {
            let axis = kb / kn;
            let phi = 2.0 * (0.5 * kn).atan();
            t = rotate_about(&t, &axis, phi);
            d1 = rotate_about(&d1, &axis, phi);
            d2 = rotate_about(&d2, &axis, phi);
        }
        x.push(x[i] + t * rest_len[i]);
        a1.push(d1);
        tan.push(t);
    }
    (x, a1, tan)
}
