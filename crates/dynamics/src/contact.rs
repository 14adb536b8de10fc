//! Compliant contact of points on links against a horizontal ground plane.
//!
//! Normal force: a spring-damper on the penetration depth `d = z_ground − z` that only pushes,
//! `f_n = max(0, k d − c ż)` for `d > 0` (zero otherwise), so there is no attraction and no jump
//! at touchdown. Tangential force: Coulomb friction regularized as viscous near zero slip,
//! `f_t = −μ f_n v_t / sqrt(|v_t|² + v_s²)`, smooth enough for RK4 at a 1e-3 s step.
//! The generalized force is `Jᵀ f` with `J` the point's world-frame linear Jacobian.

use crate::rigid::{Data, JointKind, Model};
use nalgebra::Vector3;
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
