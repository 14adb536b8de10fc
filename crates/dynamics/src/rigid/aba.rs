//! Articulated-body algorithm (Featherstone, Table 7.1): forward dynamics
//! `q̈ = M(q)⁻¹ (τ - C(q, v) v - g(q))` in O(n).

use super::spatial::{Force, Motion};
use super::{Data, Model};
use nalgebra::{DVector, Vector3, Vector6};

#[inline]
fn m6(m: &Motion) -> Vector6<f64> {
    Vector6::new(m.v.x, m.v.y, m.v.z, m.w.x, m.w.y, m.w.z)
}

#[inline]
fn f_of(x: &Vector6<f64>) -> Force {
    Force {
        f: Vector3::new(x[0], x[1], x[2]),
        n: Vector3::new(x[3], x[4], x[5]),
    }
}

#[inline]
fn to6(f: &Force) -> Vector6<f64> {
    Vector6::new(f.f.x, f.f.y, f.f.z, f.n.x, f.n.y, f.n.z)
}

/// Forward dynamics; result in `data.ddq`.
pub fn aba<'d>(
    model: &Model,
    data: &'d mut Data,
    q: &[f64],
    v: &[f64],
    tau: &[f64],
) -> &'d DVector<f64> {
    let n = model.nv();
    assert!(q.len() == n && v.len() == n && tau.len() == n);
    // Pass 1: kinematics, velocity-product accelerations, rigid-body inertias and bias forces.
    for (i, j) in model.joints.iter().enumerate() {
        let li = j.local_placement(q[i]);
        data.li_m_i[i] = li;
        let vj = j.subspace().scale(v[i]);
        let vi = match j.parent {
            Some(p) => {
                data.o_m_i[i] = data.o_m_i[p].mul(&li);
                li.act_inv_motion(&data.v[p]) + vj
            }
            None => {
                data.o_m_i[i] = li;
                vj
            }
        };
        data.v[i] = vi;
        data.c[i] = vi.cross(&vj);
        let y = &j.inertia;
        data.yaba[i] = y.to_matrix6();
        data.pa[i] = to6(&vi.cross_force(&y.mul_motion(&vi)));
    }
    // Pass 2: articulated inertias and bias forces, leaves to root.
    for i in (0..n).rev() {
        let j = &model.joints[i];
        let s = m6(&j.subspace());
        let ia = data.yaba[i];
        let u = ia * s;
        let d_inv = 1.0 / (s.dot(&u) + j.armature);
        let uu = tau[i] - s.dot(&data.pa[i]);
        data.u_vec[i] = u;
        data.d_inv[i] = d_inv;
        data.u_scalar[i] = uu;
        if let Some(p) = j.parent {
            let ia_proj = ia - u * u.transpose() * d_inv;
            let pa = data.pa[i] + ia_proj * m6(&data.c[i]) + u * (d_inv * uu);
            let li = &data.li_m_i[i];
            let yp = li.act_matrix6(&ia_proj);
            data.yaba[p] += yp;
            data.pa[p] += to6(&li.act_force(&f_of(&pa)));
        }
    }
    // Pass 3: accelerations, root to leaves.
    let a0 = Motion::new(-model.gravity, Vector3::zeros());
    for (i, j) in model.joints.iter().enumerate() {
        let ap = match j.parent {
            Some(p) => data.a[p],
            None => a0,
        };
        let ai = data.li_m_i[i].act_inv_motion(&ap) + data.c[i];
        let qdd = data.d_inv[i] * (data.u_scalar[i] - data.u_vec[i].dot(&m6(&ai)));
        data.ddq[i] = qdd;
        data.a[i] = ai + j.subspace().scale(qdd);
    }
    &data.ddq
}
