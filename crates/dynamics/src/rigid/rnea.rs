//! Recursive Newton–Euler inverse dynamics (Featherstone, Table 5.1): `τ = M(q) a + C(q, v) v + g(q)`.

use super::{Data, Model};
use nalgebra::DVector;

/// Inverse dynamics; result in `data.tau` (also fills placements, `v`, `a`, `f`).
pub fn rnea<'d>(
    model: &Model,
    data: &'d mut Data,
    q: &[f64],
    v: &[f64],
    a: &[f64],
) -> &'d DVector<f64> {
    assert!(q.len() == model.nv() && v.len() == model.nv() && a.len() == model.nv());
    let a0 = super::Motion::new(-model.gravity, nalgebra::Vector3::zeros());
    // Forward pass: velocities, accelerations and body forces.
    for (i, j) in model.joints.iter().enumerate() {
        let li = j.local_placement(q[i]);
        data.li_m_i[i] = li;
        let s = j.subspace();
        let vj = s.scale(v[i]);
        let (vp, ap, op) = match j.parent {
            Some(p) => (
                li.act_inv_motion(&data.v[p]),
                li.act_inv_motion(&data.a[p]),
                data.o_m_i[p].mul(&li),
            ),
            None => (super::Motion::zero(), li.act_inv_motion(&a0), li),
        };
        data.o_m_i[i] = op;
        let vi = vp + vj;
        let ai = ap + s.scale(a[i]) + vi.cross(&vj);
        let y = &j.inertia;
        let hv = y.mul_motion(&vi);
        data.f[i] = y.mul_motion(&ai) + vi.cross_force(&hv);
        data.hv[i] = hv;
        data.v[i] = vi;
        data.a[i] = ai;
    }
    // Backward pass: project onto the joint axes and accumulate towards the root.
    for i in (0..model.nv()).rev() {
        let j = &model.joints[i];
        data.tau[i] = j.subspace().dot(&data.f[i]) + j.armature * a[i];
        if let Some(p) = j.parent {
            let fp = data.li_m_i[i].act_force(&data.f[i]);
            data.f[p] += fp;
        }
    }
    &data.tau
}

/// Nonlinear effects `C(q, v) v + g(q) = rnea(q, v, 0)`; result in `data.tau`.
pub fn nonlinear_effects<'d>(
    model: &Model,
    data: &'d mut Data,
    q: &[f64],
    v: &[f64],
) -> &'d DVector<f64> {
    let zero = [0.0; 64];
    if model.nv() <= 64 {
        rnea(model, data, q, v, &zero[..model.nv()])
    } else {
        let z = vec![0.0; model.nv()];
        rnea(model, data, q, v, &z)
    }
}

/// Generalized gravity `g(q) = rnea(q, 0, 0)`; result in `data.tau`.
pub fn gravity_torque<'d>(model: &Model, data: &'d mut Data, q: &[f64]) -> &'d DVector<f64> {
    let zero = [0.0; 64];
    if model.nv() <= 64 {
        let z = &zero[..model.nv()];
        rnea(model, data, q, z, z)
    } else {
        let z = vec![0.0; model.nv()];
        rnea(model, data, q, &z, &z)
    }
}
