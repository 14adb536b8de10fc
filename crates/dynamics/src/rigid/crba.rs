//! Composite rigid-body algorithm (Featherstone, Table 6.2): the joint-space mass matrix `M(q)`.

use super::model::JointKind;
use super::spatial::{Inertia, Se3};
use super::{Data, Model};
use nalgebra::DMatrix;

/// `acc += X·Y` ([`Se3::act_inertia`]) written out for the CRBA's inner step. With `hr = R h`
/// and `g = hr + (m/2) p`, the rotational inertia about the parent origin is
/// `R Ī Rᵀ − (p gᵀ + g pᵀ) + 2 (g·p) 1`, and `R Ī Rᵀ` takes six entries of `(R Ī) Rᵀ` by
/// symmetry: 45 products instead of 54 and none of the zero-padding of generic 3×3 code.
#[inline(always)]
fn add_act_inertia(x: &Se3, y: &Inertia, acc: &mut Inertia) {
    let r = &x.rot;
    let (r00, r01, r02) = (r[(0, 0)], r[(0, 1)], r[(0, 2)]);
    let (r10, r11, r12) = (r[(1, 0)], r[(1, 1)], r[(1, 2)]);
    let (r20, r21, r22) = (r[(2, 0)], r[(2, 1)], r[(2, 2)]);
    let i = &y.ibar;
    let (i00, i01, i02) = (i[(0, 0)], i[(0, 1)], i[(0, 2)]);
    let (i11, i12, i22) = (i[(1, 1)], i[(1, 2)], i[(2, 2)]);
    // T = R Ī (Ī symmetric).
    let t00 = r00 * i00 + r01 * i01 + r02 * i02;
    let t01 = r00 * i01 + r01 * i11 + r02 * i12;
    let t02 = r00 * i02 + r01 * i12 + r02 * i22;
    let t10 = r10 * i00 + r11 * i01 + r12 * i02;
    let t11 = r10 * i01 + r11 * i11 + r12 * i12;
    let t12 = r10 * i02 + r11 * i12 + r12 * i22;
    let t20 = r20 * i00 + r21 * i01 + r22 * i02;
    let t21 = r20 * i01 + r21 * i11 + r22 * i12;
    let t22 = r20 * i02 + r21 * i12 + r22 * i22;
    let m = y.mass;
    let h = &y.h;
    let hx = r00 * h.x + r01 * h.y + r02 * h.z;
    let hy = r10 * h.x + r11 * h.y + r12 * h.z;
    let hz = r20 * h.x + r21 * h.y + r22 * h.z;
    let p = &x.trans;
    let half = 0.5 * m;
    let (gx, gy, gz) = (hx + half * p.x, hy + half * p.y, hz + half * p.z);
    let d = 2.0 * (gx * p.x + gy * p.y + gz * p.z);
    let o00 = t00 * r00 + t01 * r01 + t02 * r02 - 2.0 * p.x * gx + d;
    let o11 = t10 * r10 + t11 * r11 + t12 * r12 - 2.0 * p.y * gy + d;
    let o22 = t20 * r20 + t21 * r21 + t22 * r22 - 2.0 * p.z * gz + d;
    let o01 = t00 * r10 + t01 * r11 + t02 * r12 - (p.x * gy + gx * p.y);
    let o02 = t00 * r20 + t01 * r21 + t02 * r22 - (p.x * gz + gx * p.z);
    let o12 = t10 * r20 + t11 * r21 + t12 * r22 - (p.y * gz + gy * p.z);
    acc.mass += m;
    acc.h.x += hx + m * p.x;
    acc.h.y += hy + m * p.y;
    acc.h.z += hz + m * p.z;
    let a = &mut acc.ibar;
    a[(0, 0)] += o00;
    a[(1, 1)] += o11;
    a[(2, 2)] += o22;
    a[(0, 1)] += o01;
    a[(1, 0)] += o01;
    a[(0, 2)] += o02;
    a[(2, 0)] += o02;
    a[(1, 2)] += o12;
    a[(2, 1)] += o12;
}

/// Mass matrix (full, symmetric) in `data.mass_matrix`; also fills placements and `ycrb`.
///
/// Featherstone's CRBA in local coordinates, organized as Pinocchio's: going from the leaves to
/// the root, joint `i` owns the column `F_i = Ycrb_i S_i`, and the columns of its whole subtree
/// (contiguous, since joints are in depth-first order) are in frame `i` when `i` is reached. Row
/// `i` of `M` is then `S_iᵀ F_c` over that subtree, and the block moves one frame up as a whole:
/// the columns are independent, so the transform runs over short contiguous rows the compiler
/// vectorizes, instead of carrying each column up the chain one ancestor at a time.
pub fn crba<'d>(model: &Model, data: &'d mut Data, q: &[f64]) -> &'d DMatrix<f64> {
    let nv = model.nv();
    assert_eq!(q.len(), nv);
    for (i, j) in model.joints.iter().enumerate() {
        data.li_m_i[i] = j.local_placement(q[i]);
        data.ycrb[i] = j.inertia;
        data.subtree_end[i] = i + 1;
    }
    let m = data.mass_matrix.as_mut_slice(); // column-major nv × nv
    let [fx, fy, fz, nx, ny, nz] = &mut data.fcrb;
    for i in (0..nv).rev() {
        let j = &model.joints[i];
        // Every descendant has a larger index, so the subtree's extent is final here.
        let end = data.subtree_end[i];
        // Parents come first, so ycrb[i] is read while its parent's entry is written.
        let (before, from_i) = data.ycrb.split_at_mut(i);
        let yi = &from_i[0];
        let f = yi.mul_motion(&j.subspace());
        (fx[i], fy[i], fz[i]) = (f.f.x, f.f.y, f.f.z);
        (nx[i], ny[i], nz[i]) = (f.n.x, f.n.y, f.n.z);

        // Row i over the subtree: S_i · F_c (S is angular for a revolute joint, linear for a
        // prismatic one).
        let (rx, ry, rz) = match j.kind {
            JointKind::Revolute => (&nx[i..end], &ny[i..end], &nz[i..end]),
            JointKind::Prismatic => (&fx[i..end], &fy[i..end], &fz[i..end]),
        };
        for (k, ((x, y), z)) in rx.iter().zip(ry).zip(rz).enumerate() {
            let mic = j.axis.x * x + j.axis.y * y + j.axis.z * z;
            let c = i + k;
            m[c * nv + i] = mic;
            m[i * nv + c] = mic;
        }
        m[i * nv + i] += j.armature;

        if let Some(p) = j.parent {
            let x = &data.li_m_i[i];
            transform_forces(
                x,
                &mut fx[i..end],
                &mut fy[i..end],
                &mut fz[i..end],
                &mut nx[i..end],
                &mut ny[i..end],
                &mut nz[i..end],
            );
            add_act_inertia(x, yi, &mut before[p]);
            data.subtree_end[p] = data.subtree_end[p].max(end);
        }
    }
    &data.mass_matrix
}

/// [`Se3::act_force`] on a block of forces stored as six rows: `f ← R f`, `n ← R n + p × (R f)`.
#[inline(always)]
fn transform_forces(
    x: &Se3,
    fx: &mut [f64],
    fy: &mut [f64],
    fz: &mut [f64],
    nx: &mut [f64],
    ny: &mut [f64],
    nz: &mut [f64],
) {
    let r = &x.rot;
    let p = &x.trans;
    let n = fx.len();
    let (fy, fz, nx, ny, nz) = (
        &mut fy[..n],
        &mut fz[..n],
        &mut nx[..n],
        &mut ny[..n],
        &mut nz[..n],
    );
    for c in 0..n {
        let (a, b, d) = (fx[c], fy[c], fz[c]);
        let gx = r[(0, 0)] * a + r[(0, 1)] * b + r[(0, 2)] * d;
        let gy = r[(1, 0)] * a + r[(1, 1)] * b + r[(1, 2)] * d;
        let gz = r[(2, 0)] * a + r[(2, 1)] * b + r[(2, 2)] * d;
        let (a, b, d) = (nx[c], ny[c], nz[c]);
        nx[c] = r[(0, 0)] * a + r[(0, 1)] * b + r[(0, 2)] * d + (p.y * gz - p.z * gy);
        ny[c] = r[(1, 0)] * a + r[(1, 1)] * b + r[(1, 2)] * d + (p.z * gx - p.x * gz);
        nz[c] = r[(2, 0)] * a + r[(2, 1)] * b + r[(2, 2)] * d + (p.x * gy - p.y * gx);
        (fx[c], fy[c], fz[c]) = (gx, gy, gz);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix3, Vector3};

    #[test]
    fn written_out_inertia_transform_matches_the_generic_one() {
        let x = Se3::from_xyz_rpy([0.3, -0.7, 1.1], [0.4, -1.2, 2.5]);
        let ic = Matrix3::new(0.9, 0.05, -0.02, 0.05, 0.7, 0.03, -0.02, 0.03, 0.4);
        let y = Inertia::from_com(2.5, Vector3::new(0.1, -0.2, 0.35), ic);
        let mut acc = Inertia::from_com(1.3, Vector3::new(-0.4, 0.2, 0.1), ic * 0.5);
        let want = acc + x.act_inertia(&y);
        add_act_inertia(&x, &y, &mut acc);
        assert!((acc.mass - want.mass).abs() < 1e-14);
        assert!((acc.h - want.h).abs().max() < 1e-14);
        assert!((acc.ibar - want.ibar).abs().max() < 1e-13);
    }
}
