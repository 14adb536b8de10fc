//! Analytical derivatives of inverse and forward dynamics.
//!
//! [`rnea_derivatives`] is a world-frame algorithm in the spirit of Carpentier & Mansard (RSS
//! 2018): one O(n) pass gathers world axes, velocities, accelerations, composite inertias and
//! their variations, then every entry of `∂τ/∂q`, `∂τ/∂q̇` is a few 6-vector dot products.
//! [`rnea_derivatives_tangent`] derives the same matrices independently, by propagating tangents
//! through RNEA (`∂(X_J⁻¹ m)/∂q = −S × (X_J⁻¹ m)`, `∂(X_J f)/∂q = X_J (S ×* f)`), one sweep per
//! coordinate. Forward dynamics follows from `∂q̈/∂x = −M⁻¹ ∂τ/∂x|_{a = q̈}` and `∂q̈/∂τ = M⁻¹`
//! ([`aba_derivatives`]); [`aba_derivatives_fd`] is the finite-difference twin used as the test
//! oracle.

use super::spatial::{skew, Force, Motion};
use super::{aba, crba, rnea, Data, Model};
use nalgebra::{DMatrix, Matrix6, Vector3, Vector6};

/// Last index (exclusive) of the subtree rooted at joint `k`: depth-first order makes every
/// subtree a contiguous range `k..end`.
#[inline]
fn subtree_end(model: &Model, k: usize) -> usize {
    let mut e = k + 1;
    while e < model.nv() && is_descendant(model, e, k) {
        e += 1;
    }
    e
}

#[inline]
fn is_descendant(model: &Model, mut j: usize, k: usize) -> bool {
    while let Some(p) = model.joints[j].parent {
        if p == k {
            return true;
        }
        if p < k {
            return false;
        }
        j = p;
    }
    false
}

#[inline]
fn m6(m: &Motion) -> Vector6<f64> {
    Vector6::new(m.v.x, m.v.y, m.v.z, m.w.x, m.w.y, m.w.z)
}

#[inline]
fn f6(f: &Force) -> Vector6<f64> {
    Vector6::new(f.f.x, f.f.y, f.f.z, f.n.x, f.n.y, f.n.z)
}

/// `v ×* Y − Y (v ×) = −(M + Mᵀ)` with `M = Y (v ×)`, computed block-wise: with
/// `Y = [[m I, −[h]], [[h], Ī]]` and `v × = [[[w], [v]], [0, [w]]]`,
/// `M = [[m [w], m [v] − [h][w]], [[h][w], [h][v] + Ī [w]]]`.
#[inline]
fn inertia_variation(y: &super::Inertia, m: &Motion) -> Matrix6<f64> {
    let w = skew(&m.w);
    let vx = skew(&m.v);
    let hx = skew(&y.h);
    let hw = hx * w;
    let m11 = w * y.mass;
    let m12 = vx * y.mass - hw;
    let m21 = hw;
    let m22 = hx * vx + y.ibar * w;
    let mut out = Matrix6::zeros();
    out.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(-(m11 + m11.transpose())));
    let off = -(m12 + m21.transpose());
    out.fixed_view_mut::<3, 3>(0, 3).copy_from(&off);
    out.fixed_view_mut::<3, 3>(3, 0).copy_from(&off.transpose());
    out.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(-(m22 + m22.transpose())));
    out
}

/// `∂τ/∂q` and `∂τ/∂v` of `rnea(q, v, a)` into `data.dtau_dq`, `data.dtau_dv` (and `data.tau`).
///
/// World-frame algorithm in the spirit of Carpentier & Mansard (RSS 2018). With `J_k` the world
/// motion axis of joint `k`, `p(k)` its parent, `Y^c_i`, `H_i`, `F_i` the composite inertia,
/// momentum and force of the subtree of `i`, and `Ẏ^c_i = Σ_j (v_j ×* Y_j − Y_j v_j ×)`:
/// `u_k = J_k × v_p(k)`, `w_k = u_k × v_p(k) − J_k × a_p(k)`, and for `k ⪯ i`
/// `∂τ_i/∂q_k = Jᵢ·(Y^c_i w_k − Ẏ^c_i u_k − u_k ×* H_i)`,
/// `∂τ_i/∂q̇_k = Jᵢ·(Ẏ^c_i J_k − 2 Y^c_i u_k + J_k ×* H_i)`; for an ancestor `i ≺ k` the same
/// brackets taken at `k` (plus `J_k ×* F_k` for `q`) are projected on `J_i`. Each entry is a few
/// 6-vector dot products after an O(n) pass.
pub fn rnea_derivatives(model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: &[f64]) {
    rnea_derivatives_impl(model, data, q, v, a, false);
}

/// [`rnea_derivatives`]; with `mass` it also writes the mass matrix `M[k][i] = J_k·(Y^c_i J_i)`
/// (`k ⪯ i`, world frame as in Pinocchio's CRBA) into `data.mass_matrix` from the composite
/// inertias it already has, so that [`aba_derivatives`] needs no separate [`crba`].
#[allow(clippy::needless_range_loop)] // indices address several per-joint arrays and the tree
fn rnea_derivatives_impl(
    model: &Model,
    data: &mut Data,
    q: &[f64],
    v: &[f64],
    a: &[f64],
    mass: bool,
) {
    rnea(model, data, q, v, a);
    let n = model.nv();
    let a0 = Motion::new(-model.gravity, Vector3::zeros());
    // Forward: world axes, velocities, accelerations; per-body inertias and their variations.
    for i in 0..n {
        let om = data.o_m_i[i];
        let j = &model.joints[i];
        let jw = om.act_motion(&j.subspace());
        let ov = om.act_motion(&data.v[i]);
        let (ovp, oap) = match j.parent {
            Some(p) => (data.ov[p], data.oa[p]),
            None => (Motion::zero(), a0),
        };
        data.ov[i] = ov;
        data.oa[i] = om.act_motion(&data.a[i]);
        data.jw[i] = jw;
        let u = jw.cross(&ovp);
        data.du[i] = u;
        data.dw[i] = u.cross(&ovp) - jw.cross(&oap);
        let oy = om.act_inertia(&j.inertia);
        data.oycrb[i] = oy;
        data.oh[i] = oy.mul_motion(&ov);
        data.doycrb[i] = inertia_variation(&oy, &ov);
        data.of[i] = om.act_force(&data.f[i]); // composite (RNEA backward pass done)
    }
    // Backward: composites.
    for i in (0..n).rev() {
        if let Some(p) = model.joints[i].parent {
            let (y, h, d) = (data.oycrb[i], data.oh[i], data.doycrb[i]);
            data.oycrb[p] += y;
            data.oh[p] += h;
            data.doycrb[p] += d;
        }
    }
    data.dtau_dq.fill(0.0);
    data.dtau_dv.fill(0.0);
    if mass {
        data.mass_matrix.fill(0.0);
    }
    for i in 0..n {
        let ji = data.jw[i];
        let pi = f6(&data.oycrb[i].mul_motion(&ji));
        let qi = data.doycrb[i].tr_mul(&m6(&ji));
        let ri = f6(&ji.cross_force(&data.oh[i]));
        // Row i, columns k ⪯ i.
        let mut k = Some(i);
        while let Some(kk) = k {
            let (jk, uk, wk) = (m6(&data.jw[kk]), m6(&data.du[kk]), m6(&data.dw[kk]));
            data.dtau_dq[(i, kk)] = pi.dot(&wk) - qi.dot(&uk) + ri.dot(&uk);
            data.dtau_dv[(i, kk)] = qi.dot(&jk) - 2.0 * pi.dot(&uk) - ri.dot(&jk);
            if mass {
                let mki = pi.dot(&jk);
                data.mass_matrix[(kk, i)] = mki;
                data.mass_matrix[(i, kk)] = mki;
            }
            k = model.joints[kk].parent;
        }
        if mass {
            data.mass_matrix[(i, i)] += model.joints[i].armature;
        }
        // Column i, rows of the strict ancestors of i.
        if model.joints[i].parent.is_some() {
            let (u, w) = (data.du[i], data.dw[i]);
            let y = &data.oycrb[i];
            let h = &data.oh[i];
            let tq = f6(&(ji.cross_force(&data.of[i]) + y.mul_motion(&w) - u.cross_force(h)))
                - data.doycrb[i] * m6(&u);
            let tv =
                data.doycrb[i] * m6(&ji) + f6(&(ji.cross_force(h) - y.mul_motion(&u).scale(2.0)));
            let mut r = model.joints[i].parent;
            while let Some(rr) = r {
                let jr = m6(&data.jw[rr]);
                data.dtau_dq[(rr, i)] = jr.dot(&tq);
                data.dtau_dv[(rr, i)] = jr.dot(&tv);
                r = model.joints[rr].parent;
            }
        }
    }
}

/// The tangent-propagation twin of [`rnea_derivatives`]: one forward-mode sweep per coordinate
/// (O(n · depth) spatial operations). Exact like the world-frame algorithm, slower; kept as a
/// second, independent derivation for the tests.
#[allow(clippy::needless_range_loop)] // indices address several per-joint arrays and the tree
pub fn rnea_derivatives_tangent(model: &Model, data: &mut Data, q: &[f64], v: &[f64], a: &[f64]) {
    rnea(model, data, q, v, a);
    let n = model.nv();
    let a0 = Motion::new(-model.gravity, Vector3::zeros());
    for k in 0..n {
        let end = subtree_end(model, k);
        for wrt_q in [true, false] {
            // Forward sweep over the subtree of k.
            for jj in k..end {
                let j = &model.joints[jj];
                let s = j.subspace();
                let sqd = s.scale(v[jj]);
                let li = &data.li_m_i[jj];
                let (dv, da) = if jj == k {
                    if wrt_q {
                        let (vp, ap) = match j.parent {
                            Some(p) => {
                                (li.act_inv_motion(&data.v[p]), li.act_inv_motion(&data.a[p]))
                            }
                            None => (Motion::zero(), li.act_inv_motion(&a0)),
                        };
                        let dv = s.cross(&vp).scale(-1.0);
                        let da = s.cross(&ap).scale(-1.0) + dv.cross(&sqd);
                        (dv, da)
                    } else {
                        (s, data.v[jj].cross(&s))
                    }
                } else {
                    let p = j.parent.expect("subtree member below k has a parent");
                    let dv = li.act_inv_motion(&data.dv[p]);
                    let da = li.act_inv_motion(&data.da[p]) + dv.cross(&sqd);
                    (dv, da)
                };
                let y = &j.inertia;
                let vi = &data.v[jj];
                data.df[jj] = y.mul_motion(&da)
                    + dv.cross_force(&data.hv[jj])
                    + vi.cross_force(&y.mul_motion(&dv));
                data.dv[jj] = dv;
                data.da[jj] = da;
            }
            // Backward sweep: the subtree, then the chain of ancestors.
            let out = if wrt_q {
                &mut data.dtau_dq
            } else {
                &mut data.dtau_dv
            };
            for jj in (k..end).rev() {
                let j = &model.joints[jj];
                out[(jj, k)] = j.subspace().dot(&data.df[jj]);
                // (Armature adds `armature * a` to τ: no q or v dependence.)
                if jj == k {
                    break;
                }
                let p = j.parent.expect("subtree member below k has a parent");
                let fp = data.li_m_i[jj].act_force(&data.df[jj]);
                if p >= k {
                    data.df[p] += fp;
                }
            }
            let mut carry = data.df[k];
            if wrt_q {
                carry += model.joints[k].subspace().cross_force(&data.f[k]);
            }
            let mut jj = k;
            while let Some(p) = model.joints[jj].parent {
                carry = data.li_m_i[jj].act_force(&carry);
                out[(p, k)] = model.joints[p].subspace().dot(&carry);
                jj = p;
            }
            for r in 0..k {
                if !is_ancestor(model, r, k) {
                    out[(r, k)] = 0.0;
                }
            }
            for r in end..n {
                out[(r, k)] = 0.0;
            }
        }
    }
}

#[inline]
fn is_ancestor(model: &Model, r: usize, k: usize) -> bool {
    let mut j = k;
    while let Some(p) = model.joints[j].parent {
        if p == r {
            return true;
        }
        j = p;
    }
    false
}

/// In-place Cholesky `A = L Lᵀ` of the column-major `n x n` matrix `a` (lower triangle
/// overwritten with `L`, its diagonal with `1 / L_jj`). Returns `false` if `a` is not positive
/// definite. Column-oriented (left-looking) so that the inner loops run over contiguous memory.
fn cholesky_in_place(a: &mut [f64], n: usize) -> bool {
    debug_assert_eq!(a.len(), n * n);
    for j in 0..n {
        // Column j of L: a[j.., j] -= Σ_{k<j} L[j, k] L[j.., k].
        for k in 0..j {
            let ljk = a[j + k * n];
            let (left, right) = a.split_at_mut(j * n);
            let colk = &left[k * n + j..k * n + n];
            let colj = &mut right[j..n];
            for (x, y) in colj.iter_mut().zip(colk) {
                *x -= ljk * y;
            }
        }
        let d = a[j + j * n];
        if d <= 0.0 || !d.is_finite() {
            return false;
        }
        let inv = 1.0 / d.sqrt();
        a[j + j * n] = inv;
        for x in &mut a[j * n + j + 1..j * n + n] {
            *x *= inv;
        }
    }
    true
}

/// Solves `L Lᵀ x = b` in place (`b` → `x`), `l` from [`cholesky_in_place`]; `first` is the index
/// of the first nonzero of `b` (the forward substitution starts there).
#[inline]
fn cholesky_solve_in_place(l: &[f64], n: usize, x: &mut [f64], first: usize) {
    // Forward: L y = b, column-oriented.
    for k in first..n {
        let col = &l[k * n..k * n + n];
        let yk = x[k] * col[k];
        x[k] = yk;
        for (xi, lik) in x[k + 1..n].iter_mut().zip(&col[k + 1..n]) {
            *xi -= lik * yk;
        }
    }
    // Backward: Lᵀ x = y, row i of Lᵀ is column i of L.
    for i in (0..n).rev() {
        let col = &l[i * n..i * n + n];
        let mut s = x[i];
        for (xk, lki) in x[i + 1..n].iter().zip(&col[i + 1..n]) {
            s -= lki * xk;
        }
        x[i] = s * col[i];
    }
}

/// Factorizes `data.mass_matrix` into `data.chol` and writes `M⁻¹` into `data.minv`.
fn minverse_from_mass_matrix(data: &mut Data, n: usize) -> bool {
    data.chol.copy_from(&data.mass_matrix);
    let l = data.chol.as_mut_slice();
    if !cholesky_in_place(l, n) {
        return false;
    }
    let minv = data.minv.as_mut_slice();
    minv.fill(0.0);
    for c in 0..n {
        let col = &mut minv[c * n..c * n + n];
        col[c] = 1.0;
        cholesky_solve_in_place(l, n, col, c);
    }
    true
}

/// `M(q)⁻¹` into `data.minv` (computes the mass matrix). Returns `false` if `M` is not positive
/// definite (a model error that [`Model`] construction rules out).
pub fn compute_minverse(model: &Model, data: &mut Data, q: &[f64]) -> bool {
    crba(model, data, q);
    minverse_from_mass_matrix(data, model.nv())
}

/// Derivatives of forward dynamics `q̈ = aba(q, v, τ)`: `data.ddq_dq`, `data.ddq_dv`,
/// `data.minv` (= ∂q̈/∂τ), and `data.ddq`; also leaves `M(q)` in `data.mass_matrix` (built from
/// the world-frame composite inertias of the inverse-dynamics derivatives, no separate CRBA).
/// `∂q̈/∂x = −M⁻¹ ∂τ/∂x` is solved in place with the Cholesky factor, column by column.
pub fn aba_derivatives(model: &Model, data: &mut Data, q: &[f64], v: &[f64], tau: &[f64]) {
    aba(model, data, q, v, tau);
    let n = model.nv();
    // Copy ddq to a stack buffer when small.
    let mut buf = [0.0; 64];
    let ddq_heap;
    let ddq: &[f64] = if n <= 64 {
        buf[..n].copy_from_slice(data.ddq.as_slice());
        &buf[..n]
    } else {
        ddq_heap = data.ddq.as_slice().to_vec();
        &ddq_heap
    };
    rnea_derivatives_impl(model, data, q, v, ddq, true);
    if minverse_from_mass_matrix(data, n) {
        data.ddq_dq.gemm(-1.0, &data.minv, &data.dtau_dq, 0.0);
        data.ddq_dv.gemm(-1.0, &data.minv, &data.dtau_dv, 0.0);
    } else {
        // Not positive definite (ruled out by `Model` construction): NaN, never silent garbage.
        data.minv.fill(f64::NAN);
        data.ddq_dq.fill(f64::NAN);
        data.ddq_dv.fill(f64::NAN);
    }
    data.ddq.as_mut_slice().copy_from_slice(ddq);
}

/// Finite-difference twin of [`aba_derivatives`] (central differences, step `h`): returns
/// `(∂q̈/∂q, ∂q̈/∂v, ∂q̈/∂τ)`. Allocates; meant for tests and checks.
pub fn aba_derivatives_fd(
    model: &Model,
    data: &mut Data,
    q: &[f64],
    v: &[f64],
    tau: &[f64],
    h: f64,
) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
    let n = model.nv();
    let mut out = [
        DMatrix::zeros(n, n),
        DMatrix::zeros(n, n),
        DMatrix::zeros(n, n),
    ];
    for (which, m) in out.iter_mut().enumerate() {
        for k in 0..n {
            let mut x = [q.to_vec(), v.to_vec(), tau.to_vec()];
            x[which][k] += h;
            let fp = aba(model, data, &x[0], &x[1], &x[2]).clone();
            x[which][k] -= 2.0 * h;
            let fm = aba(model, data, &x[0], &x[1], &x[2]).clone();
            m.set_column(k, &((fp - fm) / (2.0 * h)));
        }
    }
    let [a, b, c] = out;
    (a, b, c)
}
