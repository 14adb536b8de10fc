//! Forward kinematics: joint and link placements, body velocities, frame Jacobians.

use super::{Data, Model};
use nalgebra::Vector3;

/// Placements of every joint frame for configuration `q` (fills `li_m_i`, `o_m_i`).
pub fn forward_kinematics(model: &Model, data: &mut Data, q: &[f64]) {
    assert_eq!(q.len(), model.nv(), "q has the wrong length");
    for (i, j) in model.joints.iter().enumerate() {
        let li = j.local_placement(q[i]);
        data.li_m_i[i] = li;
        data.o_m_i[i] = match j.parent {
            Some(p) => data.o_m_i[p].mul(&li),
            None => li,
        };
    }
}

/// Placements and body velocities (fills `li_m_i`, `o_m_i`, `v`).
pub fn forward_kinematics_velocity(model: &Model, data: &mut Data, q: &[f64], v: &[f64]) {
    assert_eq!(v.len(), model.nv(), "v has the wrong length");
    forward_kinematics(model, data, q);
    for (i, j) in model.joints.iter().enumerate() {
        let vj = j.subspace().scale(v[i]);
        data.v[i] = match j.parent {
            Some(p) => data.li_m_i[i].act_inv_motion(&data.v[p]) + vj,
            None => vj,
        };
    }
}

/// World placement of every link frame (`o_m_f`), from the joint placements of the last
/// [`forward_kinematics`].
pub fn update_frame_placements(model: &Model, data: &mut Data) {
    for (k, fr) in model.frames.iter().enumerate() {
        data.o_m_f[k] = match fr.joint {
            Some(i) => data.o_m_i[i].mul(&fr.placement),
            None => fr.placement,
        };
    }
}

/// The 6 x nv Jacobian of link frame `frame` (index into `model.frames`) in Pinocchio's
/// LOCAL_WORLD_ALIGNED convention: `[v_o; ω] = J q̇` with `v_o` the world velocity of the frame
/// origin and `ω` the world angular velocity. Needs [`forward_kinematics`] first; writes
/// `data.jacobian`.
pub fn frame_jacobian(model: &Model, data: &mut Data, frame: usize) {
    data.jacobian.fill(0.0);
    let fr = &model.frames[frame];
    let Some(body) = fr.joint else {
        return;
    };
    let p = data.o_m_i[body].act_point(&fr.placement.trans);
    let mut k = Some(body);
    while let Some(i) = k {
        let j = &model.joints[i];
        let om = &data.o_m_i[i];
        let axis = om.rot * j.axis;
        let (lin, ang) = match j.kind {
            super::JointKind::Revolute => (axis.cross(&(p - om.trans)), axis),
            super::JointKind::Prismatic => (axis, Vector3::zeros()),
        };
        data.jacobian.fixed_view_mut::<3, 1>(0, i).copy_from(&lin);
        data.jacobian.fixed_view_mut::<3, 1>(3, i).copy_from(&ang);
        k = j.parent;
    }
}
