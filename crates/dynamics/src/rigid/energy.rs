//! Centre of mass and energies.

use super::kinematics::forward_kinematics_velocity;
use super::{Data, Model};
use nalgebra::Vector3;

/// Whole-body centre of mass and its velocity (world frame), in `data.com` and
/// `data.com_velocity`. Massless models give zeros.
///
/// Only moving bodies count: mass rigidly attached to the world (the root link and links fixed
/// to it, [`Model::world_mass`]) is left out, as Pinocchio's `centerOfMass` and
/// `computeTotalMass` leave out the universe's inertia (their sums start at joint 1 with
/// `data.mass[0] = 0`), so `com` matches Pinocchio's `data.com[0]`.
pub fn center_of_mass(model: &Model, data: &mut Data, q: &[f64], v: &[f64]) {
    forward_kinematics_velocity(model, data, q, v);
    let mut mc = Vector3::zeros();
    let mut mv = Vector3::zeros();
    let mut m = 0.0;
    for (i, j) in model.joints.iter().enumerate() {
        let y = &j.inertia;
        let om = &data.o_m_i[i];
        let c = y.com();
        mc += om.act_point(&c) * y.mass;
        let vi = &data.v[i];
        mv += om.rot * (vi.v + vi.w.cross(&c)) * y.mass;
        m += y.mass;
    }
    if m > 0.0 {
        data.com = mc / m;
        data.com_velocity = mv / m;
    } else {
        data.com = Vector3::zeros();
        data.com_velocity = Vector3::zeros();
    }
}

/// Kinetic energy `½ vᵀ M(q) v`, summed body by body (joint armatures included).
pub fn kinetic_energy(model: &Model, data: &mut Data, q: &[f64], v: &[f64]) -> f64 {
    forward_kinematics_velocity(model, data, q, v);
    model
        .joints
        .iter()
        .enumerate()
        .map(|(i, j)| j.inertia.kinetic_energy(&data.v[i]) + 0.5 * j.armature * v[i] * v[i])
        .sum()
}

/// Potential energy `Σ m_i (-g · c_i)` of the moving bodies (zero at the world origin's height;
/// mass fixed to the world is a constant and left out, as in Pinocchio).
pub fn potential_energy(model: &Model, data: &mut Data, q: &[f64]) -> f64 {
    super::kinematics::forward_kinematics(model, data, q);
    model
        .joints
        .iter()
        .enumerate()
        .map(|(i, j)| {
            let c = data.o_m_i[i].act_point(&j.inertia.com());
            -j.inertia.mass * model.gravity.dot(&c)
        })
        .sum()
}
