//! The friction-state LCP of the coupling points (the needle seed's
//! Algorithm 3: Chentanez et al. 2009, Sec. 3.3, Eq. 9-11).
//!
//! Every coupling point `i` has a frame (`t_i` along the needle, two normals)
//! and a constraint force `lambda_i` (on the needle, from the tissue; frame
//! components, N). After the step the gap between the needle's point and the
//! tissue's material point is affine in the forces, `g = g_free + W lambda`,
//! with `W` the (symmetric positive definite) Delassus matrix
//! `J_n H^{-1} J_n^T + J_t A^{-1} J_t^T` in frame components. The normal
//! gaps are always held at zero; along `t_i`:
//!
//! * STATIC: the tangential gap is zero and `-f_fwd <= lambda_t <= f_back`;
//! * DYNAMIC+ (the needle slides forward through the tissue): `lambda_t = -f_fwd`
//!   and the tangential gap (the slip) is `>= 0`;
//! * DYNAMIC-: `lambda_t = +f_back` and the slip is `<= 0`.
//!
//! With viscous friction (seed Sec. 3.3: `eta (l_{i-1} + l_i) / 2` times the
//! relative velocity, implicit) a sliding point also feels `-c_i` times its
//! slip `g_t`, `c_i = eta l_i / dt`: its row becomes
//! `(W lambda)_t + lambda_t / c_i = f_s / c_i - g_free_t` (`f_s` its Coulomb
//! force), which adds `1 / c_i` to the diagonal and keeps the system
//! symmetric positive definite; a stuck point does not slip and feels none.
//!
//! The solver guesses the states, solves the equality-constrained system of
//! that guess exactly (dense Cholesky of the active block of `W`), checks
//! the inequalities with the relative tolerance `tau` and flips violated
//! points (STATIC -> DYNAMIC with the sign of its tangential force,
//! DYNAMIC -> STATIC), never retrying a configuration it has tried, up to a
//! trial limit (the seed: `tau = 1e-3`, ten trials).

use nalgebra::{DMatrix, DVector};
use std::collections::BTreeSet;

/// Friction state of a coupling point (seed Sec. 3.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum State {
    /// Stuck: the tissue point moves with the needle's material point.
    Static,
    /// The needle slides forward (`+t`) relative to the tissue.
    DynamicPlus,
    /// The needle slides backward relative to the tissue.
    DynamicMinus,
}

/// Tangential friction bounds of one point (N): static friction holds
/// `-forward <= lambda_t <= backward`; sliding forward the needle feels
/// `-forward`, backward `+backward` (different at a cutting tip).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    /// Bound against the needle advancing (friction, plus the cutting force at the tip).
    pub forward: f64,
    /// Bound against the needle retracting.
    pub backward: f64,
    /// Viscous friction per metre of slip in this step (N/m): `eta l_i / dt`
    /// (seed Sec. 3.3); 0 for Coulomb friction alone.
    pub viscous: f64,
}

/// The result of [`solve`].
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// The states of the last configuration solved.
    pub states: Vec<State>,
    /// Constraint forces in frame components (`[t, n1, n2]` per point, N).
    pub lambda: Vec<f64>,
    /// Gaps after the step in frame components (m).
    pub gap: Vec<f64>,
    /// Configurations solved.
    pub trials: usize,
    /// Whether the returned configuration satisfies every inequality.
    pub consistent: bool,
    /// Which trial (0-based) the returned configuration was solved in.
    pub chosen: usize,
}

/// The known tangential force (N, on the needle) of a point sliding in
/// `state`: `-forward` sliding forward, `+backward` sliding back; `None`
/// for a stuck point, whose force is unknown.
pub fn coulomb(state: State, bounds: &Bounds) -> Option<f64> {
    match state {
        State::Static => None,
        State::DynamicPlus => Some(-bounds.forward),
        State::DynamicMinus => Some(bounds.backward),
    }
}

/// Solve the equality system of one configuration: returns `(lambda, gap)`,
/// or `None` if the active block of `w` is not positive definite.
fn solve_configuration(
    w: &DMatrix<f64>,
    g_free: &[f64],
    bounds: &[Bounds],
    states: &[State],
) -> Option<(Vec<f64>, Vec<f64>)> {
    let n = g_free.len();
    let mut lambda = vec![0.0; n];
    let mut active = Vec::with_capacity(n);
    // Sliding rows with viscous friction: (row, 1 / c_i, Coulomb force).
    let mut viscous = Vec::new();
    for (i, s) in states.iter().enumerate() {
        match coulomb(*s, &bounds[i]) {
            Some(f) if bounds[i].viscous > 0.0 => {
                viscous.push((active.len(), 1.0 / bounds[i].viscous, f));
                active.push(3 * i);
            }
            Some(f) => lambda[3 * i] = f,
            None => active.push(3 * i),
        }
        active.extend([3 * i + 1, 3 * i + 2]);
    }
    let known = DVector::from_column_slice(&lambda);
    let wk = w * &known;
    let mut a = DMatrix::from_fn(active.len(), active.len(), |r, c| w[(active[r], active[c])]);
    let mut rhs = DVector::from_fn(active.len(), |r, _| -(g_free[active[r]] + wk[active[r]]));
    for &(r, inv_c, f) in &viscous {
        a[(r, r)] += inv_c;
        rhs[r] += f * inv_c;
    }
    let sol = a.cholesky()?.solve(&rhs);
    for (r, &k) in active.iter().enumerate() {
        lambda[k] = sol[r];
    }
    let gap = w * DVector::from_column_slice(&lambda);
    let gap: Vec<f64> = (0..n).map(|k| g_free[k] + gap[k]).collect();
    Some((lambda, gap))
}

/// Violations of a solved configuration, largest first: `(point, state it
/// should flip to, size relative to its tolerance)`.
fn violations(
    sol: &(Vec<f64>, Vec<f64>),
    bounds: &[Bounds],
    states: &[State],
    tau: f64,
    force_scale: f64,
    gap_scale: f64,
) -> Vec<(usize, State, f64)> {
    let (lambda, gap) = sol;
    let mut out = Vec::new();
    for (i, s) in states.iter().enumerate() {
        let (lt, gt) = (lambda[3 * i], gap[3 * i]);
        let b = bounds[i];
        let v = match s {
            State::Static => {
                let ftol = tau * b.forward.max(b.backward).max(force_scale);
                if lt < -(b.forward + ftol) {
                    Some((State::DynamicPlus, (-lt - b.forward) / ftol))
                } else if lt > b.backward + ftol {
                    Some((State::DynamicMinus, (lt - b.backward) / ftol))
                } else {
                    None
                }
            }
            State::DynamicPlus => (gt < -tau * gap_scale).then(|| (State::Static, -gt / (tau * gap_scale))),
            State::DynamicMinus => (gt > tau * gap_scale).then(|| (State::Static, gt / (tau * gap_scale))),
        };
        if let Some((to, size)) = v {
            out.push((i, to, size));
        }
    }
    out.sort_by(|a, b| b.2.total_cmp(&a.2).then(a.0.cmp(&b.0)));
    out
}

/// Find the consistent friction states (module docs). `w`: `3m x 3m`
/// Delassus matrix in frame components; `g_free`: gaps without constraint
/// forces; `guess`: states to start from (the previous step's); `tau`:
/// relative check tolerance; at most `max_trials` configurations. If no
/// consistent configuration is found, the one with the smallest total
/// violation is returned with `consistent = false`.
pub fn solve(
    w: &DMatrix<f64>,
    g_free: &[f64],
    bounds: &[Bounds],
    guess: &[State],
    tau: f64,
    max_trials: usize,
) -> Solution {
    let m = bounds.len();
    assert!(w.nrows() == 3 * m && w.ncols() == 3 * m);
    solve_by(
        |states| solve_configuration(w, g_free, bounds, states),
        g_free,
        bounds,
        guess,
        tau,
        max_trials,
    )
}

/// [`solve`] with the equality system of each configuration solved by
/// `configuration(states) -> (lambda, gap)` (`None`: not solvable), e.g.
/// an iterative solver of the whole coupled system instead of the dense
/// Delassus matrix; the trial logic, checks and scales are the same.
pub fn solve_by(
    mut configuration: impl FnMut(&[State]) -> Option<(Vec<f64>, Vec<f64>)>,
    g_free: &[f64],
    bounds: &[Bounds],
    guess: &[State],
    tau: f64,
    max_trials: usize,
) -> Solution {
    let m = bounds.len();
    assert!(g_free.len() == 3 * m && guess.len() == m);
    // Scales of the checks: forces against the largest bound, slips against
    // the largest unconstrained tangential gap (the slip a free needle would make).
    let force_scale = bounds
        .iter()
        .map(|b| b.forward.max(b.backward))
        .fold(0.0, f64::max)
        .max(1e-300);
    let gap_scale = (0..m).map(|i| g_free[3 * i].abs()).fold(0.0, f64::max).max(1e-300);
    let mut tried: BTreeSet<Vec<State>> = BTreeSet::new();
    let mut states = guess.to_vec();
    let mut best: Option<(f64, Solution)> = None;
    let mut trials = 0;
    while trials < max_trials.max(1) {
        trials += 1;
        tried.insert(states.clone());
        let Some(sol) = configuration(&states) else {
            break;
        };
        let viol = violations(&sol, bounds, &states, tau, force_scale, gap_scale);
        let total: f64 = viol.iter().map(|v| v.2).sum();
        let current = Solution {
            states: states.clone(),
            lambda: sol.0,
            gap: sol.1,
            trials,
            consistent: viol.is_empty(),
            chosen: trials - 1,
        };
        if viol.is_empty() {
            return current;
        }
        if best.as_ref().is_none_or(|b| total < b.0) {
            best = Some((total, current));
        }
        // Flip every violated point; if that configuration was tried, flip
        // single points, largest violation first.
        let mut next = states.clone();
        for &(i, to, _) in &viol {
            next[i] = to;
        }
        if tried.contains(&next) {
            let single = viol.iter().map(|&(i, to, _)| {
                let mut s = states.clone();
                s[i] = to;
                s
            });
            match single.into_iter().find(|s| !tried.contains(s)) {
                Some(s) => next = s,
                None => break,
            }
        }
        states = next;
    }
    let (_, mut sol) = best.unwrap_or_else(|| {
        (
            f64::INFINITY,
            Solution {
                states: states.clone(),
                lambda: vec![0.0; 3 * m],
                gap: g_free.to_vec(),
                trials,
                consistent: false,
                chosen: trials,
            },
        )
    });
    sol.trials = trials;
    sol
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two points, each with unit compliance per component and no coupling
    /// between them (`W = I`): every case solvable by hand.
    fn two_points(g_t: [f64; 2], f: f64) -> Solution {
        let w = DMatrix::identity(6, 6);
        let g = [g_t[0], 1e-4, 0.0, g_t[1], 0.0, -2e-4];
        let b = [Bounds {
            forward: f,
            backward: f,
            viscous: 0.0,
        }; 2];
        solve(&w, &g, &b, &[State::Static; 2], 1e-3, 10)
    }

    #[test]
    fn both_static_below_the_bound() {
        // Holding the points needs lambda_t = -g_t (W = I): 0.3 and -0.2 N, below 0.5 N.
        let s = two_points([0.3, -0.2], 0.5);
        assert!(s.consistent);
        assert_eq!(s.states, vec![State::Static; 2]);
        assert_eq!(s.trials, 1);
        // Exact up to rounding: the system is the identity.
        assert!((s.lambda[0] + 0.3).abs() < 1e-15 && (s.lambda[3] - 0.2).abs() < 1e-15);
        // Normal gaps closed by normal forces.
        assert!((s.lambda[1] + 1e-4).abs() < 1e-18 && (s.lambda[5] - 2e-4).abs() < 1e-18);
        assert!(s.gap.iter().all(|g| g.abs() < 1e-15));
    }

    #[test]
    fn one_point_slides_forward() {
        // Point 0 would need 0.8 N > 0.5 N: it slides, lambda_t = -0.5 N,
        // slip 0.8 - 0.5 = 0.3 m (W = I); point 1 stays stuck.
        let s = two_points([0.8, -0.2], 0.5);
        assert!(s.consistent);
        assert_eq!(s.states, vec![State::DynamicPlus, State::Static]);
        assert_eq!(s.trials, 2);
        assert!((s.lambda[0] + 0.5).abs() < 1e-15);
        assert!((s.gap[0] - 0.3).abs() < 1e-15);
        assert!((s.lambda[3] - 0.2).abs() < 1e-15);
    }

    #[test]
    fn both_slide_in_opposite_directions() {
        let s = two_points([0.8, -0.9], 0.5);
        assert!(s.consistent);
        assert_eq!(s.states, vec![State::DynamicPlus, State::DynamicMinus]);
        assert!((s.lambda[0] + 0.5).abs() < 1e-15 && (s.lambda[3] - 0.5).abs() < 1e-15);
        assert!((s.gap[0] - 0.3).abs() < 1e-15 && (s.gap[3] + 0.4).abs() < 1e-15);
    }

    #[test]
    fn a_wrong_sliding_guess_is_flipped_back_to_static() {
        // Guessed DYNAMIC+ but the free slip is negative: friction -f would
        // push the slip further negative, so the point must stick.
        let w = DMatrix::identity(3, 3);
        let b = [Bounds {
            forward: 0.5,
            backward: 0.5,
            viscous: 0.0,
        }];
        let s = solve(&w, &[-0.1, 0.0, 0.0], &b, &[State::DynamicPlus], 1e-3, 10);
        assert!(s.consistent);
        assert_eq!(s.states, vec![State::Static]);
        assert!((s.lambda[0] - 0.1).abs() < 1e-15);
    }

    #[test]
    fn coupled_points_need_the_schur_system() {
        // Two points whose tangential compliances couple (off-diagonal 0.5):
        // by hand, with both sliding forward at 1 N, g_t = g_free - W [1, 1]
        // = [3 - 1.5, 2 - 1.5] = [1.5, 0.5] > 0: consistent.
        let mut w = DMatrix::identity(6, 6);
        w[(0, 3)] = 0.5;
        w[(3, 0)] = 0.5;
        let b = [Bounds {
            forward: 1.0,
            backward: 1.0,
            viscous: 0.0,
        }; 2];
        let s = solve(&w, &[3.0, 0.0, 0.0, 2.0, 0.0, 0.0], &b, &[State::Static; 2], 1e-3, 10);
        assert!(s.consistent);
        assert_eq!(s.states, vec![State::DynamicPlus; 2]);
        assert!((s.gap[0] - 1.5).abs() < 1e-14 && (s.gap[3] - 0.5).abs() < 1e-14);
    }

    #[test]
    fn asymmetric_bounds_of_a_cutting_tip() {
        // Forward bound 1.0 (friction + cutting), backward 0.2: a pull of
        // 0.5 N backward makes it slide back, a push of 0.5 N forward does not.
        let w = DMatrix::identity(3, 3);
        let b = [Bounds {
            forward: 1.0,
            backward: 0.2,
            viscous: 0.0,
        }];
        let fwd = solve(&w, &[0.5, 0.0, 0.0], &b, &[State::Static], 1e-3, 10);
        assert_eq!(fwd.states, vec![State::Static]);
        let back = solve(&w, &[-0.5, 0.0, 0.0], &b, &[State::Static], 1e-3, 10);
        assert_eq!(back.states, vec![State::DynamicMinus]);
        assert!((back.gap[0] + 0.3).abs() < 1e-15);
    }

    #[test]
    fn viscous_friction_adds_to_the_sliding_force() {
        // One point, unit compliance: sliding forward it feels the Coulomb
        // force f and c times its slip g, g = g_free + lambda_t with
        // lambda_t = -f - c g, so g = (g_free - f) / (1 + c) by hand.
        let w = DMatrix::identity(3, 3);
        let (g_free, f, c) = (2.0, 0.5, 3.0);
        let b = [Bounds {
            forward: f,
            backward: f,
            viscous: c,
        }];
        let s = solve(&w, &[g_free, 0.0, 0.0], &b, &[State::Static], 1e-3, 10);
        assert!(s.consistent);
        assert_eq!(s.states, vec![State::DynamicPlus]);
        let g = (g_free - f) / (1.0 + c);
        // Rounding only: a 1 x 1 system of O(1) entries.
        assert!((s.gap[0] - g).abs() < 1e-15, "slip {} vs {g}", s.gap[0]);
        assert!((s.lambda[0] - (-f - c * g)).abs() < 1e-15, "force {}", s.lambda[0]);
    }
}
