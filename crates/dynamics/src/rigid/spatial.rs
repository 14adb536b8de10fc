//! Spatial algebra (Featherstone, *Rigid Body Dynamics Algorithms*, ch. 2), in Pinocchio's
//! layout: every 6D vector is a pair of [`Vector3`]s, linear part first.
//!
//! - [`Motion`] `(v, w)`: linear velocity of the frame origin and angular velocity, both in the
//!   frame's coordinates.
//! - [`Force`] `(f, n)`: force and moment about the frame origin.
//! - [`Se3`] `(R, p)`: the placement of a child frame in a parent frame, `x_parent = R x_child + p`.
//!   `act` maps child coordinates to parent coordinates, `act_inv` the other way.
//! - [`Inertia`] `(m, h = m c, Ī)`: a rigid body's spatial inertia with its rotational inertia `Ī`
//!   about the frame origin (not the centre of mass), which makes sums and transforms cheap.

use nalgebra::{Matrix3, Matrix6, Vector3};

/// Skew-symmetric matrix `[x]` with `[x] y = x × y`.
#[inline]
pub fn skew(x: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -x.z, x.y, x.z, 0.0, -x.x, -x.y, x.x, 0.0)
}

/// A spatial motion vector (twist or spatial acceleration).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Motion {
    /// Linear part (velocity of the frame origin).
    pub v: Vector3<f64>,
    /// Angular part.
    pub w: Vector3<f64>,
}

/// A spatial force vector (wrench).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Force {
    /// Linear force.
    pub f: Vector3<f64>,
    /// Moment about the frame origin.
    pub n: Vector3<f64>,
}

impl Motion {
    /// The zero motion.
    #[inline]
    pub fn zero() -> Self {
        Self::default()
    }

    /// Motion from linear and angular parts.
    #[inline]
    pub fn new(v: Vector3<f64>, w: Vector3<f64>) -> Self {
        Self { v, w }
    }

    /// Spatial cross product `self × m` (motion on motion, Featherstone's `crm`).
    #[inline]
    pub fn cross(&self, m: &Motion) -> Motion {
        Motion {
            v: self.w.cross(&m.v) + self.v.cross(&m.w),
            w: self.w.cross(&m.w),
        }
    }

    /// Spatial cross product `self ×* f` (motion on force, Featherstone's `crf`).
    #[inline]
    pub fn cross_force(&self, f: &Force) -> Force {
        Force {
            f: self.w.cross(&f.f),
            n: self.w.cross(&f.n) + self.v.cross(&f.f),
        }
    }

    /// Power pairing `self · f`.
    #[inline]
    pub fn dot(&self, f: &Force) -> f64 {
        self.v.dot(&f.f) + self.w.dot(&f.n)
    }

    /// `self * s` for a scalar.
    #[inline]
    pub fn scale(&self, s: f64) -> Motion {
        Motion {
            v: self.v * s,
            w: self.w * s,
        }
    }
}

impl std::ops::Add for Motion {
    type Output = Motion;
    #[inline]
    fn add(self, o: Motion) -> Motion {
        Motion {
            v: self.v + o.v,
            w: self.w + o.w,
        }
    }
}

impl std::ops::Sub for Motion {
    type Output = Motion;
    #[inline]
    fn sub(self, o: Motion) -> Motion {
        Motion {
            v: self.v - o.v,
            w: self.w - o.w,
        }
    }
}

impl std::ops::AddAssign for Motion {
    #[inline]
    fn add_assign(&mut self, o: Motion) {
        self.v += o.v;
        self.w += o.w;
    }
}

impl Force {
    /// The zero force.
    #[inline]
    pub fn zero() -> Self {
        Self::default()
    }

    /// `self * s` for a scalar.
    #[inline]
    pub fn scale(&self, s: f64) -> Force {
        Force {
            f: self.f * s,
            n: self.n * s,
        }
    }
}

impl std::ops::Add for Force {
    type Output = Force;
    #[inline]
    fn add(self, o: Force) -> Force {
        Force {
            f: self.f + o.f,
            n: self.n + o.n,
        }
    }
}

impl std::ops::Sub for Force {
    type Output = Force;
    #[inline]
    fn sub(self, o: Force) -> Force {
        Force {
            f: self.f - o.f,
            n: self.n - o.n,
        }
    }
}

impl std::ops::AddAssign for Force {
    #[inline]
    fn add_assign(&mut self, o: Force) {
        self.f += o.f;
        self.n += o.n;
    }
}

/// A rigid transform: the placement of a child frame in a parent frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Se3 {
    /// Rotation; its columns are the child axes in parent coordinates.
    pub rot: Matrix3<f64>,
    /// Child origin in parent coordinates.
    pub trans: Vector3<f64>,
}

impl Default for Se3 {
    fn default() -> Self {
        Self::identity()
    }
}

impl Se3 {
    /// The identity placement.
    #[inline]
    pub fn identity() -> Self {
        Self {
            rot: Matrix3::identity(),
            trans: Vector3::zeros(),
        }
    }

    /// Placement from rotation and translation.
    #[inline]
    pub fn new(rot: Matrix3<f64>, trans: Vector3<f64>) -> Self {
        Self { rot, trans }
    }

    /// URDF `<origin xyz rpy>`: `R = Rz(yaw) Ry(pitch) Rx(roll)`.
    pub fn from_xyz_rpy(xyz: [f64; 3], rpy: [f64; 3]) -> Self {
        Self {
            rot: rpy_matrix(rpy),
            trans: Vector3::from(xyz),
        }
    }

    /// Composition `self * other` (placement of `other`'s child in `self`'s parent).
    #[inline]
    pub fn mul(&self, other: &Se3) -> Se3 {
        Se3 {
            rot: self.rot * other.rot,
            trans: self.rot * other.trans + self.trans,
        }
    }

    /// The inverse placement.
    #[inline]
    pub fn inverse(&self) -> Se3 {
        let rt = self.rot.transpose();
        Se3 {
            rot: rt,
            trans: -(rt * self.trans),
        }
    }

    /// A point given in child coordinates, expressed in parent coordinates.
    #[inline]
    pub fn act_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rot * p + self.trans
    }

    /// A motion given in child coordinates, expressed in parent coordinates.
    #[inline]
    pub fn act_motion(&self, m: &Motion) -> Motion {
        let w = self.rot * m.w;
        Motion {
            v: self.rot * m.v + self.trans.cross(&w),
            w,
        }
    }

    /// A motion given in parent coordinates, expressed in child coordinates.
    #[inline]
    pub fn act_inv_motion(&self, m: &Motion) -> Motion {
        Motion {
            v: self.rot.tr_mul(&(m.v - self.trans.cross(&m.w))),
            w: self.rot.tr_mul(&m.w),
        }
    }

    /// A force given in child coordinates, expressed in parent coordinates.
    #[inline]
    pub fn act_force(&self, f: &Force) -> Force {
        let ff = self.rot * f.f;
        Force {
            f: ff,
            n: self.rot * f.n + self.trans.cross(&ff),
        }
    }

    /// A force given in parent coordinates, expressed in child coordinates.
    #[inline]
    pub fn act_inv_force(&self, f: &Force) -> Force {
        Force {
            f: self.rot.tr_mul(&f.f),
            n: self.rot.tr_mul(&(f.n - self.trans.cross(&f.f))),
        }
    }

    /// A spatial inertia given in child coordinates, expressed in parent coordinates.
    #[inline]
    pub fn act_inertia(&self, y: &Inertia) -> Inertia {
        // Ī' = R Ī Rᵀ − ([Rh][p] + [p][Rh]) − m [p]², with [a][b] = b aᵀ − (a·b) I.
        let hr = self.rot * y.h;
        let p = &self.trans;
        let ir = self.rot * y.ibar * self.rot.transpose();
        let m = y.mass;
        let diag = 2.0 * hr.dot(p) + m * p.norm_squared();
        let mut out = ir;
        for c in 0..3 {
            for r in 0..3 {
                out[(r, c)] -= p[r] * hr[c] + hr[r] * p[c] + m * p[r] * p[c];
            }
            out[(c, c)] += diag;
        }
        Inertia {
            mass: m,
            h: hr + p * m,
            ibar: out,
        }
    }

    /// A 6x6 spatial inertia (linear rows/columns first) given in child coordinates, expressed in
    /// parent coordinates: `X* Y X*ᵀ` computed block-wise.
    #[inline]
    pub fn act_matrix6(&self, y: &Matrix6<f64>) -> Matrix6<f64> {
        let r = &self.rot;
        let a: Matrix3<f64> = y.fixed_view::<3, 3>(0, 0).into_owned();
        let b: Matrix3<f64> = y.fixed_view::<3, 3>(0, 3).into_owned();
        let c: Matrix3<f64> = y.fixed_view::<3, 3>(3, 3).into_owned();
        let ar = r * a * r.transpose();
        let br = r * b * r.transpose();
        let cr = r * c * r.transpose();
        let p = skew(&self.trans);
        let ap = ar * p;
        let y12 = br - ap;
        let pb = p * br;
        let y22 = cr - p * ap + pb + pb.transpose();
        let mut out = Matrix6::zeros();
        out.fixed_view_mut::<3, 3>(0, 0).copy_from(&ar);
        out.fixed_view_mut::<3, 3>(0, 3).copy_from(&y12);
        out.fixed_view_mut::<3, 3>(3, 0).copy_from(&y12.transpose());
        out.fixed_view_mut::<3, 3>(3, 3).copy_from(&y22);
        out
    }
}

/// URDF roll-pitch-yaw to a rotation matrix: `Rz(yaw) Ry(pitch) Rx(roll)`.
pub fn rpy_matrix(rpy: [f64; 3]) -> Matrix3<f64> {
    let (sr, cr) = rpy[0].sin_cos();
    let (sp, cp) = rpy[1].sin_cos();
    let (sy, cy) = rpy[2].sin_cos();
    Matrix3::new(
        cy * cp,
        cy * sp * sr - sy * cr,
        cy * sp * cr + sy * sr,
        sy * cp,
        sy * sp * sr + cy * cr,
        sy * sp * cr - cy * sr,
        -sp,
        cp * sr,
        cp * cr,
    )
}

/// Rotation by `angle` about the unit `axis` (Rodrigues' formula), given `sin` and `cos`.
#[inline]
pub fn axis_rotation(axis: &Vector3<f64>, s: f64, c: f64) -> Matrix3<f64> {
    let (x, y, z) = (axis.x, axis.y, axis.z);
    let t = 1.0 - c;
    Matrix3::new(
        t * x * x + c,
        t * x * y - s * z,
        t * x * z + s * y,
        t * x * y + s * z,
        t * y * y + c,
        t * y * z - s * x,
        t * x * z - s * y,
        t * y * z + s * x,
        t * z * z + c,
    )
}

/// A rigid body's spatial inertia about a frame origin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inertia {
    /// Mass (kg).
    pub mass: f64,
    /// First moment `m c` with `c` the centre of mass (kg m).
    pub h: Vector3<f64>,
    /// Rotational inertia about the frame origin (kg m²).
    pub ibar: Matrix3<f64>,
}

impl Default for Inertia {
    fn default() -> Self {
        Self::zero()
    }
}

impl Inertia {
    /// The inertia of nothing.
    #[inline]
    pub fn zero() -> Self {
        Self {
            mass: 0.0,
            h: Vector3::zeros(),
            ibar: Matrix3::zeros(),
        }
    }

    /// From mass, centre of mass and rotational inertia about the centre of mass.
    pub fn from_com(mass: f64, com: Vector3<f64>, inertia_at_com: Matrix3<f64>) -> Self {
        let cx = skew(&com);
        Self {
            mass,
            h: com * mass,
            ibar: inertia_at_com - cx * cx * mass,
        }
    }

    /// Centre of mass (the origin for a massless body).
    pub fn com(&self) -> Vector3<f64> {
        if self.mass > 0.0 {
            self.h / self.mass
        } else {
            Vector3::zeros()
        }
    }

    /// Rotational inertia about the centre of mass.
    pub fn inertia_at_com(&self) -> Matrix3<f64> {
        let c = self.com();
        let cx = skew(&c);
        self.ibar + cx * cx * self.mass
    }

    /// The momentum `Y m` of motion `m`.
    #[inline]
    pub fn mul_motion(&self, m: &Motion) -> Force {
        Force {
            f: m.v * self.mass - self.h.cross(&m.w),
            n: self.ibar * m.w + self.h.cross(&m.v),
        }
    }

    /// Kinetic energy `½ mᵀ Y m`.
    #[inline]
    pub fn kinetic_energy(&self, m: &Motion) -> f64 {
        0.5 * m.dot(&self.mul_motion(m))
    }

    /// The 6x6 matrix (linear rows/columns first).
    pub fn to_matrix6(&self) -> Matrix6<f64> {
        let hx = skew(&self.h);
        let mut out = Matrix6::zeros();
        out.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(Matrix3::identity() * self.mass));
        out.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-hx));
        out.fixed_view_mut::<3, 3>(3, 0).copy_from(&hx);
        out.fixed_view_mut::<3, 3>(3, 3).copy_from(&self.ibar);
        out
    }
}

impl std::ops::Add for Inertia {
    type Output = Inertia;
    #[inline]
    fn add(self, o: Inertia) -> Inertia {
        Inertia {
            mass: self.mass + o.mass,
            h: self.h + o.h,
            ibar: self.ibar + o.ibar,
        }
    }
}

impl std::ops::AddAssign for Inertia {
    #[inline]
    fn add_assign(&mut self, o: Inertia) {
        self.mass += o.mass;
        self.h += o.h;
        self.ibar += o.ibar;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_se3() -> Se3 {
        Se3::from_xyz_rpy([0.3, -0.2, 0.5], [0.4, -1.1, 2.0])
    }

    fn sample_inertia() -> Inertia {
        Inertia::from_com(
            2.5,
            Vector3::new(0.1, -0.05, 0.2),
            Matrix3::new(0.3, 0.01, -0.02, 0.01, 0.25, 0.03, -0.02, 0.03, 0.1),
        )
    }

    #[test]
    fn transforms_preserve_power_and_invert() {
        let x = sample_se3();
        let m = Motion::new(Vector3::new(1.0, 2.0, 3.0), Vector3::new(-0.5, 0.7, 0.2));
        let f = Force {
            f: Vector3::new(0.3, -4.0, 1.0),
            n: Vector3::new(2.0, 0.1, -0.6),
        };
        // Power is frame independent.
        let p1 = m.dot(&f);
        let p2 = x.act_motion(&m).dot(&x.act_force(&f));
        assert!((p1 - p2).abs() < 1e-12);
        let back = x.act_inv_motion(&x.act_motion(&m));
        assert!((back.v - m.v).norm() + (back.w - m.w).norm() < 1e-12);
        let fb = x.act_inv_force(&x.act_force(&f));
        assert!((fb.f - f.f).norm() + (fb.n - f.n).norm() < 1e-12);
        let xi = x.mul(&x.inverse());
        assert!((xi.rot - Matrix3::identity()).norm() < 1e-12 && xi.trans.norm() < 1e-12);
    }

    #[test]
    fn inertia_transform_is_consistent_with_6x6_and_momentum() {
        let x = sample_se3();
        let y = sample_inertia();
        let m = Motion::new(Vector3::new(1.0, -2.0, 0.5), Vector3::new(0.3, 0.2, -0.9));
        // h_parent = X* (Y (X^-1 m_parent)).
        let yp = x.act_inertia(&y);
        let lhs = yp.mul_motion(&m);
        let rhs = x.act_force(&y.mul_motion(&x.act_inv_motion(&m)));
        assert!((lhs.f - rhs.f).norm() + (lhs.n - rhs.n).norm() < 1e-12);
        let m6 = x.act_matrix6(&y.to_matrix6());
        assert!((m6 - yp.to_matrix6()).norm() < 1e-12);
        // Mass, COM and inertia at COM round-trip.
        assert!((yp.com() - x.act_point(&y.com())).norm() < 1e-12);
        let ic = x.rot * y.inertia_at_com() * x.rot.transpose();
        assert!((yp.inertia_at_com() - ic).norm() < 1e-12);
    }

    #[test]
    fn rpy_and_axis_rotation_agree_with_elementary_rotations() {
        let r = rpy_matrix([0.0, 0.0, 0.3]);
        let z = axis_rotation(&Vector3::z(), 0.3f64.sin(), 0.3f64.cos());
        assert!((r - z).norm() < 1e-15);
        let composed = axis_rotation(&Vector3::z(), 0.3f64.sin(), 0.3f64.cos())
            * axis_rotation(&Vector3::y(), 0.2f64.sin(), 0.2f64.cos())
            * axis_rotation(&Vector3::x(), 0.1f64.sin(), 0.1f64.cos());
        assert!((rpy_matrix([0.1, 0.2, 0.3]) - composed).norm() < 1e-15);
    }
}
