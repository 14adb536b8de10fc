//! The reusable workspace that the algorithms fill ([`Data`]).

use super::model::Model;
use super::spatial::{Force, Inertia, Motion, Se3};
use nalgebra::{DMatrix, DVector, Matrix6, Vector3, Vector6};

/// Scratch space and results of the algorithms for one [`Model`]. Created once
/// ([`Data::new`]); the algorithms never allocate.
///
/// Per-joint vectors are indexed by joint (`nv` entries); body quantities are in the body's
/// (joint's) frame unless the name starts with `o` (world frame).
#[derive(Debug, Clone)]
pub struct Data {
    /// Joint frame in its parent joint's frame, `placement * X_J(q)`.
    pub li_m_i: Vec<Se3>,
    /// Joint frame in the world.
    pub o_m_i: Vec<Se3>,
    /// Every link frame in the world (after [`super::update_frame_placements`]).
    pub o_m_f: Vec<Se3>,
    /// Body spatial velocities.
    pub v: Vec<Motion>,
    /// Body spatial accelerations (gravity included as a fictitious base acceleration).
    pub a: Vec<Motion>,
    /// Body forces (RNEA) accumulated towards the root.
    pub f: Vec<Force>,
    /// Output of [`super::rnea`] (also nle / gravity torques).
    pub tau: DVector<f64>,
    /// Output of [`super::crba`]: the full symmetric mass matrix.
    pub mass_matrix: DMatrix<f64>,
    /// Output of [`super::aba`]: joint accelerations.
    pub ddq: DVector<f64>,
    /// Composite rigid-body inertias (CRBA).
    pub ycrb: Vec<Inertia>,
    /// Articulated-body inertias (ABA).
    pub yaba: Vec<Matrix6<f64>>,
    /// Articulated bias forces (ABA).
    pub pa: Vec<Vector6<f64>>,
    /// Velocity-product accelerations `v × S q̇` (ABA).
    pub c: Vec<Motion>,
    /// `U = I^A S` (ABA).
    pub u_vec: Vec<Vector6<f64>>,
    /// `1 / (Sᵀ U)` (ABA).
    pub d_inv: Vec<f64>,
    /// `τ - Sᵀ p^A` (ABA).
    pub u_scalar: Vec<f64>,
    /// Whole-body centre of mass (world).
    pub com: Vector3<f64>,
    /// Whole-body centre-of-mass velocity (world).
    pub com_velocity: Vector3<f64>,
    /// A 6 x nv frame Jacobian (rows: linear, angular), see [`super::frame_jacobian`].
    pub jacobian: DMatrix<f64>,
    /// ∂τ/∂q of inverse dynamics ([`super::rnea_derivatives`]).
    pub dtau_dq: DMatrix<f64>,
    /// ∂τ/∂v of inverse dynamics.
    pub dtau_dv: DMatrix<f64>,
    /// ∂q̈/∂q of forward dynamics ([`super::aba_derivatives`]).
    pub ddq_dq: DMatrix<f64>,
    /// ∂q̈/∂v of forward dynamics.
    pub ddq_dv: DMatrix<f64>,
    /// ∂q̈/∂τ = M⁻¹.
    pub minv: DMatrix<f64>,
    /// Body momenta `Y v` (RNEA; reused by the derivatives).
    pub(crate) hv: Vec<Force>,
    /// World-frame joint axes, velocities, accelerations, composite inertias, momenta, inertia
    /// variations, forces and the per-joint `u`, `w` vectors of [`super::rnea_derivatives`].
    pub(crate) jw: Vec<Motion>,
    pub(crate) ov: Vec<Motion>,
    pub(crate) oa: Vec<Motion>,
    pub(crate) oycrb: Vec<Inertia>,
    pub(crate) oh: Vec<Force>,
    pub(crate) doycrb: Vec<Matrix6<f64>>,
    pub(crate) of: Vec<Force>,
    pub(crate) du: Vec<Motion>,
    pub(crate) dw: Vec<Motion>,
    /// Tangent velocities (derivatives scratch).
    pub(crate) dv: Vec<Motion>,
    /// Tangent accelerations (derivatives scratch).
    pub(crate) da: Vec<Motion>,
    /// Tangent forces (derivatives scratch).
    pub(crate) df: Vec<Force>,
    /// Cholesky scratch (nv x nv).
    pub(crate) chol: DMatrix<f64>,
    /// CRBA: the forces `F_c = Ycrb_c S_c` of a subtree's joints as six rows of `nv` columns
    /// (linear x, y, z, then angular), each column in the frame of the joint being processed.
    pub(crate) fcrb: [Vec<f64>; 6],
    /// CRBA: one past the last joint of each joint's subtree (joints are in depth-first order).
    pub(crate) subtree_end: Vec<usize>,
}

impl Data {
    /// A workspace sized for `model`.
    pub fn new(model: &Model) -> Self {
        let n = model.nv();
        let nf = model.frames.len();
        Self {
            li_m_i: vec![Se3::identity(); n],
            o_m_i: vec![Se3::identity(); n],
            o_m_f: vec![Se3::identity(); nf],
            v: vec![Motion::zero(); n],
            a: vec![Motion::zero(); n],
            f: vec![Force::zero(); n],
            tau: DVector::zeros(n),
            mass_matrix: DMatrix::zeros(n, n),
            ddq: DVector::zeros(n),
            ycrb: vec![Inertia::zero(); n],
            yaba: vec![Matrix6::zeros(); n],
            pa: vec![Vector6::zeros(); n],
            c: vec![Motion::zero(); n],
            u_vec: vec![Vector6::zeros(); n],
            d_inv: vec![0.0; n],
            u_scalar: vec![0.0; n],
            com: Vector3::zeros(),
            com_velocity: Vector3::zeros(),
            jacobian: DMatrix::zeros(6, n),
            dtau_dq: DMatrix::zeros(n, n),
            dtau_dv: DMatrix::zeros(n, n),
            ddq_dq: DMatrix::zeros(n, n),
            ddq_dv: DMatrix::zeros(n, n),
            minv: DMatrix::zeros(n, n),
            hv: vec![Force::zero(); n],
            jw: vec![Motion::zero(); n],
            ov: vec![Motion::zero(); n],
            oa: vec![Motion::zero(); n],
            oycrb: vec![Inertia::zero(); n],
            oh: vec![Force::zero(); n],
            doycrb: vec![Matrix6::zeros(); n],
            of: vec![Force::zero(); n],
            du: vec![Motion::zero(); n],
            dw: vec![Motion::zero(); n],
            dv: vec![Motion::zero(); n],
            da: vec![Motion::zero(); n],
            df: vec![Force::zero(); n],
            chol: DMatrix::zeros(n, n),
            fcrb: std::array::from_fn(|_| vec![0.0; n]),
            subtree_end: vec![0; n],
        }
    }
}
