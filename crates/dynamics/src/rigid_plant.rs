//! [`RigidBodyPlant`]: a URDF model plus actuators, joint friction and ground contact, as a
//! [`Plant`].
//!
//! State `x = [q; q̇]` (`2 nv`), action `u` = one component per learned actuator (a voltage for a
//! [`DcMotor`](crate::actuators::DcMotor), a torque for a torque source or a
//! [`TorqueMotor`](crate::actuators::TorqueMotor)), in the order they were added. The continuous
//! dynamics `q̈ = ABA(q, q̇, τ_act + τ_friction + Jᵀ f_contact)` are integrated by RK4 with a fixed
//! internal step; [`Plant::step`] advances one control period with the action held (zero-order
//! hold).
//!
//! Joint position limits (the URDF `<limit lower upper>`) are not enforced unless
//! [`RigidBodyPlant::with_position_limits`] adds a compliant [`LimitSpring`] on every limited
//! joint (off by default, so existing plants keep their results).
//!
//! [`Plant::linearize`] is analytical: the exact Jacobian of the discrete map. At every RK4 stage
//! the partials of the applied torques (motors, PD, friction, contact: diagonal or per contact
//! chain, see [`add_contact_force_partials`]) are chained with the analytical ABA derivatives,
//! `∂q̈/∂x = ∂q̈/∂x|_τ + M⁻¹ ∂τ/∂x`, `∂q̈/∂u = M⁻¹ ∂τ/∂u`, and the sensitivity `∂x/∂(x₀, u)` is
//! carried through the stages exactly as the state is. [`RigidBodyPlant::linearize_fd`] keeps the
//! central-difference twin as the test oracle.
//!
//! An idealized and a true system are two configurations of one model: [`Overrides`] changes a
//! body's mass and the friction coefficients (p0, Table I: Leo's torso mass and joint viscous
//! friction).

use crate::actuators::{Actuator, JointFriction};
use crate::contact::{add_contact_force_partials, point_state, ContactPoint, GroundContact};
use crate::rigid::{
    aba, aba_derivatives, forward_kinematics_velocity, kinetic_energy, potential_energy, Data,
    Model,
};
use crate::Plant;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::sync::Mutex;

/// Timing of a [`RigidBodyPlant`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigidPlantConfig {
    /// Control period `dt` of [`Plant::step`] (s).
    pub control_period: f64,
    /// Internal RK4 step (s); the period is split into `round(dt / step)` equal steps.
    pub internal_step: f64,
}

impl Default for RigidPlantConfig {
    /// Leo's 30 ms control period (33 Hz, as in its RBDL simulation used by p0) and a 1 ms
    /// internal step, stable with the default ground contact.
    fn default() -> Self {
        Self {
            control_period: 0.03,
            internal_step: 1e-3,
        }
    }
}

/// A compliant joint position limit: beyond a joint's URDF range `[lower, upper]` by `d`, a
/// spring-damper pushes back with `max(0, k d + c ḋ)` (never pulls, like the ground contact).
/// Off unless enabled with [`RigidBodyPlant::with_position_limits`], so that plants without it
/// keep their results; continuous joints (infinite range) are never limited.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LimitSpring {
    /// Stiffness `k` (N m/rad or N/m).
    pub stiffness: f64,
    /// Damping `c` while beyond the limit (N m s/rad or N s/m).
    pub damping: f64,
}

impl Default for LimitSpring {
    /// `k = 100 N m/rad`, `c = 1 N m s/rad`: a 0.1 rad overshoot costs 10 N m, several times the
    /// stall torque of Leo's motors, and the joint stays well resolved at a 1 ms RK4 step for
    /// link inertias down to about 1e-3 kg m².
    fn default() -> Self {
        Self {
            stiffness: 100.0,
            damping: 1.0,
        }
    }
}

impl LimitSpring {
    /// Torque on a joint at `(q, q̇)` with range `[lower, upper]` and its partials
    /// `(τ, ∂τ/∂q, ∂τ/∂q̇)`.
    #[inline]
    pub fn torque(&self, lower: f64, upper: f64, q: f64, qdot: f64) -> (f64, f64, f64) {
        let (k, c) = (self.stiffness, self.damping);
        if q > upper {
            let r = k * (q - upper) + c * qdot;
            if r > 0.0 {
                return (-r, -k, -c);
            }
        } else if q < lower {
            let r = k * (lower - q) - c * qdot;
            if r > 0.0 {
                return (r, -k, -c);
            }
        }
        (0.0, 0.0, 0.0)
    }
}

/// Parameter overrides that turn an idealized model into a "true" one (or back).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Overrides {
    /// New total mass of a body, keyed by its URDF link name (the child link of a movable joint);
    /// the body's centre of mass is kept and its inertia scaled with the mass.
    pub link_mass: BTreeMap<String, f64>,
    /// Viscous friction coefficient for every actuated joint (N m s/rad).
    pub viscous_friction: Option<f64>,
    /// Coulomb friction torque for every actuated joint (N m).
    pub coulomb_friction: Option<f64>,
    /// Ground friction coefficient μ.
    pub ground_friction: Option<f64>,
}

/// Why a plant could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RigidPlantError {
    /// A joint name that the model does not have.
    #[error("unknown joint '{0}'")]
    UnknownJoint(String),
    /// A link name that is not the child of a movable joint.
    #[error("unknown link '{0}' (overrides address links moved by a joint)")]
    UnknownLink(String),
    /// A bad number in the configuration.
    #[error("invalid configuration: {0}")]
    Config(String),
}

/// Scratch buffers of one evaluation.
#[derive(Debug, Clone)]
struct Work {
    data: Data,
    tau: Vec<f64>,
    x: Vec<f64>,
    k: [Vec<f64>; 4],
}

/// Partial derivatives of the applied generalized force `τ(q, q̇, u)`.
#[derive(Debug, Clone)]
struct ForceJacobian {
    /// `∂τ/∂q` (`nv x nv`).
    tq: DMatrix<f64>,
    /// `∂τ/∂q̇` (`nv x nv`).
    tv: DMatrix<f64>,
    /// `∂τ/∂u` (`nv x m`).
    tu: DMatrix<f64>,
}

/// Buffers of one analytical linearization (allocated once per call, reused by every stage).
struct LinearizeWork {
    jac: ForceJacobian,
    /// `∂q̈/∂x` of one stage (`nv x 2 nv`).
    dx: DMatrix<f64>,
    /// `∂q̈/∂u` of one stage (`nv x m`).
    du: DMatrix<f64>,
    /// Sensitivity `∂x/∂(x₀, u)` at the start of the substep (`2 nv x (2 nv + m)`).
    phi: DMatrix<f64>,
    /// Sensitivity of the current stage's state.
    s: DMatrix<f64>,
    /// Sensitivities of the four stage derivatives.
    dk: [DMatrix<f64>; 4],
}

/// `y += a x` for matrices of one shape.
#[inline]
fn axpy(y: &mut DMatrix<f64>, a: f64, x: &DMatrix<f64>) {
    for (yi, xi) in y.as_mut_slice().iter_mut().zip(x.as_slice()) {
        *yi += a * xi;
    }
}

/// A rigid-body robot as a [`Plant`].
#[derive(Debug)]
pub struct RigidBodyPlant {
    model: Model,
    actuators: Vec<(usize, Actuator)>,
    friction: Vec<JointFriction>,
    contacts: Vec<ContactPoint>,
    ground: Option<GroundContact>,
    limits: Option<LimitSpring>,
    config: RigidPlantConfig,
    substeps: usize,
    work: Mutex<Work>,
}

impl Clone for RigidBodyPlant {
    fn clone(&self) -> Self {
        Self {
            model: self.model.clone(),
            actuators: self.actuators.clone(),
            friction: self.friction.clone(),
            contacts: self.contacts.clone(),
            ground: self.ground,
            limits: self.limits,
            config: self.config,
            substeps: self.substeps,
            work: Mutex::new(Work::new(&self.model)),
        }
    }
}

impl Work {
    fn new(model: &Model) -> Self {
        let n = model.nv();
        Self {
            data: Data::new(model),
            tau: vec![0.0; n],
            x: vec![0.0; 2 * n],
            k: std::array::from_fn(|_| vec![0.0; 2 * n]),
        }
    }
}

/// The most integration steps one control step may take: beyond it a step takes seconds and a
/// run cannot stop promptly, and no rigid system needs it (0.5 ms steps at 1 kHz control are 2).
pub const MAX_SUBSTEPS: usize = 100_000;

impl RigidBodyPlant {
    /// A plant with no actuators, URDF joint friction (`<dynamics damping friction>`) and no
    /// contact.
    pub fn new(model: Model, config: RigidPlantConfig) -> Result<Self, RigidPlantError> {
        if !(config.control_period > 0.0
            && config.internal_step > 0.0
            && config.control_period.is_finite())
        {
            return Err(RigidPlantError::Config(format!(
                "control_period {} and internal_step {} must be positive",
                config.control_period, config.internal_step
            )));
        }
        let substeps = (config.control_period / config.internal_step)
            .round()
            .max(1.0);
        if substeps > MAX_SUBSTEPS as f64 {
            return Err(RigidPlantError::Config(format!(
                "internal_step {} makes {substeps:e} integration steps per control step of {} s; \
                 at most {MAX_SUBSTEPS} (raise internal_step)",
                config.internal_step, config.control_period
            )));
        }
        let substeps = substeps as usize;
        let friction = model
            .joints
            .iter()
            .map(|j| JointFriction {
                viscous: j.damping,
                coulomb: j.friction,
                ..JointFriction::default()
            })
            .collect();
        Ok(Self {
            work: Mutex::new(Work::new(&model)),
            model,
            actuators: Vec::new(),
            friction,
            contacts: Vec::new(),
            ground: None,
            limits: None,
            config,
            substeps,
        })
    }

    /// Drives joint `joint` with `actuator` (a motor's armature is added to the joint).
    pub fn with_actuator(
        mut self,
        joint: &str,
        actuator: Actuator,
    ) -> Result<Self, RigidPlantError> {
        let i = self
            .model
            .joint_index(joint)
            .ok_or_else(|| RigidPlantError::UnknownJoint(joint.into()))?;
        if let Actuator::Motor(m) = &actuator {
            self.model.joints[i].armature += m.armature;
        }
        self.actuators.push((i, actuator));
        *self.work.get_mut().unwrap_or_else(|e| e.into_inner()) = Work::new(&self.model);
        Ok(self)
    }

    /// Sets the friction of joint `joint`.
    pub fn with_friction(mut self, joint: &str, f: JointFriction) -> Result<Self, RigidPlantError> {
        let i = self
            .model
            .joint_index(joint)
            .ok_or_else(|| RigidPlantError::UnknownJoint(joint.into()))?;
        self.friction[i] = f;
        Ok(self)
    }

    /// Adds a contact point `point` (in the frame of link `link`) against the ground.
    pub fn with_contact(
        mut self,
        name: &str,
        link: &str,
        point: [f64; 3],
    ) -> Result<Self, RigidPlantError> {
        let k = self
            .model
            .frame_index(link)
            .ok_or_else(|| RigidPlantError::UnknownLink(link.into()))?;
        let fr = &self.model.frames[k];
        let joint = fr
            .joint
            .ok_or_else(|| RigidPlantError::UnknownLink(link.into()))?;
        let p = fr.placement.act_point(&nalgebra::Vector3::from(point));
        self.contacts.push(ContactPoint {
            name: name.into(),
            joint,
            point: p,
        });
        Ok(self)
    }

    /// Sets the ground plane.
    pub fn with_ground(mut self, ground: GroundContact) -> Self {
        self.ground = Some(ground);
        self
    }

    /// Enforces every joint's URDF position range with a compliant [`LimitSpring`] (off by
    /// default).
    pub fn with_position_limits(mut self, spring: LimitSpring) -> Result<Self, RigidPlantError> {
        if !(spring.stiffness >= 0.0
            && spring.damping >= 0.0
            && spring.stiffness.is_finite()
            && spring.damping.is_finite())
        {
            return Err(RigidPlantError::Config(format!(
                "limit stiffness {} and damping {} must be finite and non-negative",
                spring.stiffness, spring.damping
            )));
        }
        self.limits = Some(spring);
        Ok(self)
    }

    /// Applies parameter overrides.
    pub fn with_overrides(mut self, o: &Overrides) -> Result<Self, RigidPlantError> {
        for (link, &mass) in &o.link_mass {
            let joint = self
                .model
                .joints
                .iter()
                .find(|j| &j.child_link == link)
                .map(|j| j.name.clone())
                .ok_or_else(|| RigidPlantError::UnknownLink(link.clone()))?;
            if !self.model.scale_body_mass(&joint, mass) {
                return Err(RigidPlantError::Config(format!(
                    "mass {mass} for link '{link}' must be positive and finite"
                )));
            }
        }
        for &(i, _) in &self.actuators {
            if let Some(b) = o.viscous_friction {
                self.friction[i].viscous = b;
            }
            if let Some(c) = o.coulomb_friction {
                self.friction[i].coulomb = c;
            }
        }
        if let (Some(mu), Some(g)) = (o.ground_friction, self.ground.as_mut()) {
            g.friction = mu;
        }
        Ok(self)
    }

    /// The model (with armature and mass overrides applied).
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// Actuated joints in action order (learned actuators only).
    pub fn action_joints(&self) -> Vec<String> {
        self.actuators
            .iter()
            .filter(|(_, a)| a.is_learned())
            .map(|(i, _)| self.model.joints[*i].name.clone())
            .collect()
    }

    /// The actuators (joint index, actuator), PD ones included.
    pub fn actuators(&self) -> &[(usize, Actuator)] {
        &self.actuators
    }

    /// The contact points.
    pub fn contacts(&self) -> &[ContactPoint] {
        &self.contacts
    }

    /// The ground, if any.
    pub fn ground(&self) -> Option<&GroundContact> {
        self.ground.as_ref()
    }

    /// Mechanical energy (kinetic + potential) of state `x`.
    pub fn energy(&self, x: &[f64]) -> f64 {
        let n = self.model.nv();
        let mut w = self.lock();
        kinetic_energy(&self.model, &mut w.data, &x[..n], &x[n..])
            + potential_energy(&self.model, &mut w.data, &x[..n])
    }

    /// [`RigidBodyPlant::energy`] plus the energy stored in the PD controllers' virtual springs
    /// (`½ kp (q − q*)²`), in the compressed contact springs and in the joint-limit springs
    /// (`½ k d²`): the quantity that passive motion (motors off) must not increase.
    pub fn total_energy(&self, x: &[f64]) -> f64 {
        let mut e = self.energy(x);
        for (i, a) in &self.actuators {
            if let Actuator::Pd(pd) = a {
                let d = x[*i] - pd.target;
                e += 0.5 * pd.kp * d * d;
            }
        }
        if let Some(l) = &self.limits {
            for (j, q) in self.model.joints.iter().zip(x) {
                let d = (q - j.upper).max(j.lower - q).max(0.0);
                e += 0.5 * l.stiffness * d * d;
            }
        }
        if let Some(g) = &self.ground {
            for h in self.contact_heights(x) {
                let d = (g.height - h).max(0.0);
                e += 0.5 * g.stiffness * d * d;
            }
        }
        e
    }

    /// World heights of the contact points at state `x` (for penetration checks).
    pub fn contact_heights(&self, x: &[f64]) -> Vec<f64> {
        let n = self.model.nv();
        let mut w = self.lock();
        forward_kinematics_velocity(&self.model, &mut w.data, &x[..n], &x[n..]);
        self.contacts
            .iter()
            .map(|c| point_state(&w.data, c).0.z)
            .collect()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Work> {
        self.work.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The applied generalized force (friction, joint limits, actuators, contact) into `tau`; with `jac`, also
    /// its partial derivatives. Leaves placements and body velocities in `data` when there are
    /// contacts.
    #[allow(clippy::too_many_arguments)]
    fn applied_torque(
        &self,
        data: &mut Data,
        tau: &mut [f64],
        q: &[f64],
        v: &[f64],
        u: &[f64],
        mut jac: Option<&mut ForceJacobian>,
    ) {
        for ((t, f), vi) in tau.iter_mut().zip(&self.friction).zip(v) {
            *t = f.torque(*vi);
        }
        if let Some(j) = jac.as_deref_mut() {
            j.tq.fill(0.0);
            j.tv.fill(0.0);
            j.tu.fill(0.0);
            for (i, (f, vi)) in self.friction.iter().zip(v).enumerate() {
                j.tv[(i, i)] = f.torque_derivative(*vi);
            }
        }
        if let Some(l) = &self.limits {
            for (i, j) in self.model.joints.iter().enumerate() {
                let (t, dq, dv) = l.torque(j.lower, j.upper, q[i], v[i]);
                tau[i] += t;
                if let Some(jac) = jac.as_deref_mut() {
                    jac.tq[(i, i)] += dq;
                    jac.tv[(i, i)] += dv;
                }
            }
        }
        let mut k = 0;
        for (i, act) in &self.actuators {
            let learned = act.is_learned();
            let ui = if learned { u[k] } else { 0.0 };
            match jac.as_deref_mut() {
                None => tau[*i] += act.torque(ui, q[*i], v[*i]),
                Some(j) => {
                    let (t, du, dq, dv) = act.torque_partials(ui, q[*i], v[*i]);
                    tau[*i] += t;
                    if learned {
                        j.tu[(*i, k)] += du;
                    }
                    j.tq[(*i, *i)] += dq;
                    j.tv[(*i, *i)] += dv;
                }
            }
            if learned {
                k += 1;
            }
        }
        if let Some(g) = &self.ground {
            if !self.contacts.is_empty() {
                forward_kinematics_velocity(&self.model, data, q, v);
                match jac {
                    None => g.add_generalized_forces(&self.model, data, &self.contacts, tau),
                    Some(j) => add_contact_force_partials(
                        g,
                        &self.model,
                        data,
                        &self.contacts,
                        v,
                        tau,
                        &mut j.tq,
                        &mut j.tv,
                    ),
                }
            }
        }
    }

    /// Continuous dynamics `ẋ = f(x, u)` into `out` (length `2 nv`).
    fn derivative(&self, w: &mut Work, x: &[f64], u: &[f64], out: &mut [f64]) {
        let n = self.model.nv();
        let (q, v) = x.split_at(n);
        self.applied_torque(&mut w.data, &mut w.tau, q, v, u, None);
        let ddq = aba(&self.model, &mut w.data, q, v, &w.tau);
        out[..n].copy_from_slice(v);
        out[n..].copy_from_slice(ddq.as_slice());
    }

    /// [`RigidBodyPlant::derivative`] at a stage state `x` whose sensitivity is `lw.s`; writes
    /// `ẋ` into `out` and its sensitivity `A S + [0 B]` into `dk`, with
    /// `A = [[0, I], [∂q̈/∂q, ∂q̈/∂q̇]]`, `B = [[0], [∂q̈/∂u]]`.
    fn derivative_sensitivity(
        &self,
        w: &mut Work,
        lw: &mut LinearizeWork,
        stage: usize,
        x: &[f64],
        u: &[f64],
        out: &mut [f64],
    ) {
        let n = self.model.nv();
        let (q, v) = x.split_at(n);
        self.applied_torque(&mut w.data, &mut w.tau, q, v, u, Some(&mut lw.jac));
        let d = &mut w.data;
        aba_derivatives(&self.model, d, q, v, &w.tau);
        out[..n].copy_from_slice(v);
        out[n..].copy_from_slice(d.ddq.as_slice());
        let mut dq = lw.dx.columns_mut(0, n);
        dq.copy_from(&d.ddq_dq);
        dq.gemm(1.0, &d.minv, &lw.jac.tq, 1.0);
        let mut dv = lw.dx.columns_mut(n, n);
        dv.copy_from(&d.ddq_dv);
        dv.gemm(1.0, &d.minv, &lw.jac.tv, 1.0);
        lw.du.gemm(1.0, &d.minv, &lw.jac.tu, 0.0);
        let s = if stage == 0 { &lw.phi } else { &lw.s };
        let dk = &mut lw.dk[stage];
        dk.rows_mut(0, n).copy_from(&s.rows(n, n));
        dk.rows_mut(n, n).gemm(1.0, &lw.dx, s, 0.0);
        let m = lw.du.ncols();
        let mut b = dk.view_mut((n, 2 * n), (n, m));
        b += &lw.du;
    }

    /// The exact Jacobians `(∂step/∂x, ∂step/∂u)` of one control period, by chaining the
    /// analytical ABA derivatives with the actuator and contact partials through every RK4 stage
    /// (what [`Plant::linearize`] returns). At a clipping or contact switch it is the derivative
    /// of the branch the trajectory is on.
    pub fn linearize_analytic(&self, x: &[f64], u: &[f64]) -> (DMatrix<f64>, DMatrix<f64>) {
        let n = self.model.nv();
        let nx = 2 * n;
        let m = self.action_dim();
        let cols = nx + m;
        let mut lw = LinearizeWork {
            jac: ForceJacobian {
                tq: DMatrix::zeros(n, n),
                tv: DMatrix::zeros(n, n),
                tu: DMatrix::zeros(n, m),
            },
            dx: DMatrix::zeros(n, nx),
            du: DMatrix::zeros(n, m),
            phi: DMatrix::identity(nx, cols),
            s: DMatrix::zeros(nx, cols),
            dk: std::array::from_fn(|_| DMatrix::zeros(nx, cols)),
        };
        let mut guard = self.lock();
        let w = &mut *guard;
        let h = self.config.control_period / self.substeps as f64;
        let mut xc = x.to_vec();
        let mut k = std::mem::take(&mut w.k);
        let mut xs = std::mem::take(&mut w.x);
        for _ in 0..self.substeps {
            self.derivative_sensitivity(w, &mut lw, 0, &xc, u, &mut k[0]);
            for (stage, frac) in [(1, 0.5), (2, 0.5), (3, 1.0)] {
                for i in 0..nx {
                    xs[i] = xc[i] + frac * h * k[stage - 1][i];
                }
                lw.s.copy_from(&lw.phi);
                axpy(&mut lw.s, frac * h, &lw.dk[stage - 1]);
                let (_, rest) = k.split_at_mut(stage);
                self.derivative_sensitivity(w, &mut lw, stage, &xs, u, &mut rest[0]);
            }
            for i in 0..nx {
                xc[i] += h / 6.0 * (k[0][i] + 2.0 * k[1][i] + 2.0 * k[2][i] + k[3][i]);
            }
            let [d1, d2, d3, d4] = &lw.dk;
            axpy(&mut lw.phi, h / 6.0, d1);
            axpy(&mut lw.phi, h / 3.0, d2);
            axpy(&mut lw.phi, h / 3.0, d3);
            axpy(&mut lw.phi, h / 6.0, d4);
        }
        w.k = k;
        w.x = xs;
        (
            lw.phi.columns(0, nx).into_owned(),
            lw.phi.columns(nx, m).into_owned(),
        )
    }

    /// The central-difference twin of [`Plant::linearize`] ([`crate::linearize_fd`]): the test
    /// oracle of [`RigidBodyPlant::linearize_analytic`].
    pub fn linearize_fd(&self, x: &DVector<f64>, u: &DVector<f64>) -> (DMatrix<f64>, DMatrix<f64>) {
        crate::linearize_fd(self, x, u)
    }

    /// Integrates one control period from `x` under action `u`, in place.
    pub fn step_in_place(&self, x: &mut [f64], u: &[f64]) {
        let mut guard = self.lock();
        let w = &mut *guard;
        let h = self.config.control_period / self.substeps as f64;
        let m = x.len();
        for _ in 0..self.substeps {
            let mut k = std::mem::take(&mut w.k);
            let mut xs = std::mem::take(&mut w.x);
            self.derivative(w, x, u, &mut k[0]);
            for (stage, frac) in [(1, 0.5), (2, 0.5), (3, 1.0)] {
                for i in 0..m {
                    xs[i] = x[i] + frac * h * k[stage - 1][i];
                }
                let (_, rest) = k.split_at_mut(stage);
                self.derivative(w, &xs, u, &mut rest[0]);
            }
            for i in 0..m {
                x[i] += h / 6.0 * (k[0][i] + 2.0 * k[1][i] + 2.0 * k[2][i] + k[3][i]);
            }
            w.k = k;
            w.x = xs;
        }
    }
}

impl Plant for RigidBodyPlant {
    fn state_dim(&self) -> usize {
        2 * self.model.nv()
    }

    fn action_dim(&self) -> usize {
        self.actuators
            .iter()
            .filter(|(_, a)| a.is_learned())
            .count()
    }

    fn dt(&self) -> f64 {
        self.config.control_period
    }

    fn step(&self, x: &DVector<f64>, u: &DVector<f64>) -> DVector<f64> {
        let mut y = x.clone();
        self.step_in_place(y.as_mut_slice(), u.as_slice());
        y
    }

    /// Analytical: [`RigidBodyPlant::linearize_analytic`].
    fn linearize(&self, x: &DVector<f64>, u: &DVector<f64>) -> (DMatrix<f64>, DMatrix<f64>) {
        self.linearize_analytic(x.as_slice(), u.as_slice())
    }
}
