//! Compliant contact of points on links against a horizontal ground plane.
//!
//! Normal force: a spring-damper on the penetration depth `d = z_ground − z` that only pushes,
//! `f_n = max(0, k d − c ż)` for `d > 0` (zero otherwise), so there is no attraction and no jump
//! at touchdown. Tangential force: Coulomb friction regularized as viscous near zero slip,
//! `f_t = −μ f_n v_t / sqrt(|v_t|² + v_s²)`, smooth enough for RK4 at a 1e-3 s step.
//! The generalized force is `Jᵀ f` with `J` the point's world-frame linear Jacobian.

use crate::rigid::{Data, JointKind, Model};
use nalgebra::{DMatrix, Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// A point rigidly attached to a body of the model.
#[derive(Debug, Clone, PartialEq)]
pub struct ContactPoint {
    /// A name for reports (e.g. `"left_toe"`).
    pub name: String,
    /// Index of the joint whose body carries the point.
    pub joint: usize,
    /// The point in that joint's frame.
    pub point: Vector3<f64>,
}

/// Ground-plane contact parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroundContact {
    /// Height of the ground plane (m, world z).
    pub height: f64,
    /// Normal stiffness `k` (N/m).
    pub stiffness: f64,
    /// Normal damping `c` (N s/m).
    pub damping: f64,
    /// Coulomb friction coefficient `μ`.
    pub friction: f64,
    /// Slip velocity `v_s` below which friction is viscous (m/s).
    pub slip_velocity: f64,
}

impl Default for GroundContact {
    /// Stiff enough that a 2 kg robot sinks about a millimetre standing (`k = 2e4 N/m`), damped
    /// close to critically for a 0.3 kg foot (`c = 150 N s/m`), `μ = 1`, `v_s = 0.01 m/s`.
    fn default() -> Self {
        Self {
            height: 0.0,
            stiffness: 2.0e4,
            damping: 150.0,
            friction: 1.0,
            slip_velocity: 0.01,
        }
    }
}

/// Position and world velocity of a contact point (needs body velocities in `data`, e.g. from
/// [`crate::rigid::forward_kinematics_velocity`]).
#[inline]
pub fn point_state(data: &Data, c: &ContactPoint) -> (Vector3<f64>, Vector3<f64>) {
    let om = &data.o_m_i[c.joint];
    let v = &data.v[c.joint];
    (om.act_point(&c.point), om.rot * (v.v + v.w.cross(&c.point)))
}

impl GroundContact {
    /// World-frame contact force on a point at `p` moving with `v`.
    #[inline]
    pub fn force(&self, p: &Vector3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
        let depth = self.height - p.z;
        if depth <= 0.0 {
            return Vector3::zeros();
        }
        let fnorm = (self.stiffness * depth - self.damping * v.z).max(0.0);
        let vt = Vector3::new(v.x, v.y, 0.0);
        let s = (vt.norm_squared() + self.slip_velocity * self.slip_velocity).sqrt();
        let ft = vt * (-self.friction * fnorm / s);
        Vector3::new(ft.x, ft.y, fnorm)
    }

    /// [`GroundContact::force`] and its Jacobians `(f, ∂f/∂p, ∂f/∂v)`; all zero off the ground or
    /// when the normal spring-damper would pull (the branch where the force is identically zero).
    ///
    /// With `f_n = k d − c ż`, `s = sqrt(|v_t|² + v_s²)` and `f_t = −μ f_n v_t / s`:
    /// `∂f_n/∂p = −k e_z`, `∂f_n/∂v = −c e_z`, and for the tangential rows `a ∈ {x, y}`
    /// `∂f_a/∂v_b = −μ (v_a ∂f_n/∂v_b + f_n (δ_ab − v_a v_b / s²)) / s` (`b ∈ {x, y}`).
    #[inline]
    pub fn force_partials(
        &self,
        p: &Vector3<f64>,
        v: &Vector3<f64>,
    ) -> (Vector3<f64>, Matrix3<f64>, Matrix3<f64>) {
        let zero = (Vector3::zeros(), Matrix3::zeros(), Matrix3::zeros());
        let depth = self.height - p.z;
        if depth <= 0.0 {
            return zero;
        }
        let fnorm = self.stiffness * depth - self.damping * v.z;
        if fnorm <= 0.0 {
            return zero;
        }
        let s2 = v.x * v.x + v.y * v.y + self.slip_velocity * self.slip_velocity;
        let s = s2.sqrt();
        let g = -self.friction / s;
        let vt = [v.x, v.y];
        // Same operations as `force`, so that both give bit-identical forces.
        let c = -self.friction * fnorm / s;
        let f = Vector3::new(v.x * c, v.y * c, fnorm);
        let mut fp = Matrix3::zeros();
        let mut fv = Matrix3::zeros();
        fp[(2, 2)] = -self.stiffness;
        fv[(2, 2)] = -self.damping;
        for a in 0..2 {
            fp[(a, 2)] = -g * vt[a] * self.stiffness;
            fv[(a, 2)] = -g * vt[a] * self.damping;
            for b in 0..2 {
                let delta = if a == b { 1.0 } else { 0.0 };
                fv[(a, b)] = g * fnorm * (delta - vt[a] * vt[b] / s2);
            }
        }
        (f, fp, fv)
    }

    /// Adds `Jᵀ f` of every contact point's force to `tau` (length `nv`). Needs placements and
    /// body velocities in `data`.
    pub fn add_generalized_forces(
        &self,
        model: &Model,
        data: &Data,
        points: &[ContactPoint],
        tau: &mut [f64],
    ) {
        for c in points {
            let (p, v) = point_state(data, c);
            let f = self.force(&p, &v);
            if f == Vector3::zeros() {
                continue;
            }
            add_point_force(model, data, c.joint, &p, &f, tau);
        }
    }
}

/// The contact forces' generalized force `Σ Jᵀ f` added to `tau` (as
/// [`GroundContact::add_generalized_forces`]) and its partial derivatives added to `tq = ∂τ/∂q`
/// and `tv = ∂τ/∂q̇` (`nv x nv`). Needs placements and body velocities in `data`; `v` is the joint
/// velocity vector.
///
/// World frame, for one point `p` on the chain of joints `j` from the root (1-DoF each, axis
/// `a_j` through `o_j`): the point Jacobian column is `J_j = a_j × (p − o_j)` (revolute) or `a_j`
/// (prismatic), `τ_i = J_i · f`, `ṗ = Σ_j J_j q̇_j`. Moving `q_k` rotates everything beyond joint `k`
/// about `a_k` (`ω_k = a_k`; `0` for a prismatic joint) and moves `p` by `J_k`, so
/// `∂J_j/∂q_k = ω_k × J_j` when `k ⪯ j` and `ω_j × J_k` when `j ≺ k`; with running sums along the
/// chain, `∂ṗ/∂q_k = ω_k × Σ_{j ⪰ k} J_j q̇_j + (Σ_{j ≺ k} ω_j q̇_j) × J_k` costs O(1) per `k`. Then `∂τ_i/∂q_k = ∂J_i/∂q_k · f + J_i · (F_p J_k + F_v Σ_j ∂J_j/∂q_k q̇_j)` and
/// `∂τ_i/∂q̇_k = J_i · F_v J_k`, with `(F_p, F_v)` from [`GroundContact::force_partials`].
#[allow(clippy::too_many_arguments)] // the generalized force and its two Jacobians
pub fn add_contact_force_partials(
    ground: &GroundContact,
    model: &Model,
    data: &Data,
    points: &[ContactPoint],
    v: &[f64],
    tau: &mut [f64],
    tq: &mut DMatrix<f64>,
    tv: &mut DMatrix<f64>,
) {
    const MAX_DEPTH: usize = 32;
    // Per chain member, root first: joint index, Jacobian column, rotation rate.
    let mut stack = [(0usize, Vector3::zeros(), Vector3::zeros()); MAX_DEPTH];
    let mut heap = Vec::new();
    for c in points {
        let (p, pv) = point_state(data, c);
        let (f, fp, fv) = ground.force_partials(&p, &pv);
        if f == Vector3::zeros() {
            continue;
        }
        add_point_force(model, data, c.joint, &p, &f, tau);
        let mut depth = 0;
        let mut k = Some(c.joint);
        while let Some(kk) = k {
            depth += 1;
            k = model.joints[kk].parent;
        }
        let chain: &mut [(usize, Vector3<f64>, Vector3<f64>)] = if depth <= MAX_DEPTH {
            &mut stack[..depth]
        } else {
            heap.resize(depth, stack[0]);
            &mut heap[..]
        };
        let mut k = Some(c.joint);
        for slot in chain.iter_mut().rev() {
            let j = k.expect("chain length counted above");
            let om = &data.o_m_i[j];
            let a = om.rot * model.joints[j].axis;
            *slot = match model.joints[j].kind {
                JointKind::Revolute => (j, a.cross(&(p - om.trans)), a),
                JointKind::Prismatic => (j, a, Vector3::zeros()),
            };
            k = model.joints[j].parent;
        }
        // ∂ṗ/∂q_k = ω_k × Σ_{j ⪰ k} J_j q̇_j + (Σ_{j ≺ k} ω_j q̇_j) × J_k.
        let mut below: Vector3<f64> = chain.iter().map(|(j, jc, _)| jc * v[*j]).sum();
        let mut above = Vector3::zeros();
        for (ck, &(kk, jk, wk)) in chain.iter().enumerate() {
            let dpv = wk.cross(&below) + above.cross(&jk);
            let df = fp * jk + fv * dpv;
            let fvk = fv * jk;
            for (ci, &(ii, ji, wi)) in chain.iter().enumerate() {
                // ∂J_i/∂q_k: `ω_k × J_i` if k ⪯ i, else `ω_i × J_k` (zero for prismatic i).
                let dji = if ck <= ci {
                    wk.cross(&ji)
                } else {
                    wi.cross(&jk)
                };
                tq[(ii, kk)] += dji.dot(&f) + ji.dot(&df);
                tv[(ii, kk)] += ji.dot(&fvk);
            }
            below -= jk * v[kk];
            above += wk * v[kk];
        }
    }
}

/// `tau += Jᵀ f` for a world force `f` applied at world point `p` on the body of `joint`.
pub fn add_point_force(
    model: &Model,
    data: &Data,
    joint: usize,
    p: &Vector3<f64>,
    f: &Vector3<f64>,
    tau: &mut [f64],
) {
    let mut k = Some(joint);
    while let Some(i) = k {
        let j = &model.joints[i];
        let om = &data.o_m_i[i];
        let axis = om.rot * j.axis;
        tau[i] += match j.kind {
            JointKind::Revolute => axis.dot(&(p - om.trans).cross(f)),
            JointKind::Prismatic => axis.dot(f),
        };
        k = j.parent;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn force_partials_match_finite_differences() {
        let g = GroundContact::default();
        let cases = [
            (
                Vector3::new(0.1, 0.0, -0.002),
                Vector3::new(0.004, -0.003, 0.01),
            ),
            (
                Vector3::new(0.0, 0.2, -0.001),
                Vector3::new(0.5, 0.2, -0.05),
            ),
            (Vector3::new(0.0, 0.0, 0.01), Vector3::new(0.5, 0.2, -0.05)),
        ];
        for (p, v) in cases {
            let (f, fp, fv) = g.force_partials(&p, &v);
            assert_eq!(f, g.force(&p, &v));
            for k in 0..3 {
                let h = 1e-7;
                let mut e = Vector3::zeros();
                e[k] = h;
                let dp = (g.force(&(p + e), &v) - g.force(&(p - e), &v)) / (2.0 * h);
                let dv = (g.force(&p, &(v + e)) - g.force(&p, &(v - e))) / (2.0 * h);
                assert!((dp - fp.column(k)).norm() < 1e-5 * fp.norm().max(1.0));
                assert!((dv - fv.column(k)).norm() < 1e-5 * fv.norm().max(1.0));
            }
        }
    }

    #[test]
    fn normal_force_only_pushes_and_friction_is_bounded() {
        let g = GroundContact::default();
        assert_eq!(
            g.force(&Vector3::new(0.0, 0.0, 0.01), &Vector3::zeros()),
            Vector3::zeros()
        );
        let f = g.force(&Vector3::new(0.0, 0.0, -0.001), &Vector3::zeros());
        assert!((f.z - 20.0).abs() < 1e-9 && f.x == 0.0);
        // Leaving the ground fast: no pulling force.
        let f = g.force(
            &Vector3::new(0.0, 0.0, -0.001),
            &Vector3::new(0.0, 0.0, 10.0),
        );
        assert_eq!(f, Vector3::zeros());
        // Sliding: friction opposes slip and never exceeds μ f_n.
        let f = g.force(
            &Vector3::new(0.0, 0.0, -0.002),
            &Vector3::new(1.0, -0.5, 0.0),
        );
        assert!(f.x < 0.0 && f.y > 0.0);
        let ft = (f.x * f.x + f.y * f.y).sqrt();
        assert!(ft <= g.friction * f.z + 1e-12 && ft > 0.99 * g.friction * f.z);
    }
}
