//! Composite rigid-body algorithm (Featherstone, Table 6.2): the joint-space mass matrix `M(q)`.

use super::spatial::{Inertia, Se3};
use super::{Data, Model};
use nalgebra::{DMatrix, Matrix3};

/// [`Se3::act_inertia`] using the symmetry of `Ī`: `R Ī Rᵀ` from `T = R Ī` and the six
/// entries `T_r · R_c` with `r ≤ c` (45 instead of 54 products).
#[inline(always)]
fn act_inertia_sym(x: &Se3, y: &Inertia) -> Inertia {
    let r = &x.rot;
    let t = r * y.ibar;
    let p = &x.trans;
    let hr = r * y.h;
    let m = y.mass;
    let diag = 2.0 * hr.dot(p) + m * p.norm_squared();
    let mut out = Matrix3::zeros();
    for c in 0..3 {
        for rr in 0..=c {
            let e = t[(rr, 0)] * r[(c, 0)] + t[(rr, 1)] * r[(c, 1)] + t[(rr, 2)] * r[(c, 2)]
                - (p[rr] * hr[c] + hr[rr] * p[c] + m * p[rr] * p[c]);
            out[(rr, c)] = e;
            out[(c, rr)] = e;
        }
        out[(c, c)] += diag;
    }
    Inertia {
        mass: m,
        h: hr + p * m,
        ibar: out,
    }
}

/// Mass matrix (full, symmetric) in `data.mass_matrix`; also fills placements and `ycrb`.
pub fn crba<'d>(model: &Model, data: &'d mut Data, q: &[f64]) -> &'d DMatrix<f64> {
    assert_eq!(q.len(), model.nv());
    for (i, j) in model.joints.iter().enumerate() {
        data.li_m_i[i] = j.local_placement(q[i]);
        data.ycrb[i] = j.inertia;
    }
    for i in (0..model.nv()).rev() {
        let j = &model.joints[i];
        let s = j.subspace();
        // F = Ycrb_i S_i, carried up the tree one frame at a time.
        let yi = data.ycrb[i];
        let mut f = yi.mul_motion(&s);
        data.mass_matrix[(i, i)] = s.dot(&f) + j.armature;
        let mut k = i;
        while let Some(p) = model.joints[k].parent {
            f = data.li_m_i[k].act_force(&f);
            let mij = model.joints[p].subspace().dot(&f);
            data.mass_matrix[(i, p)] = mij;
            data.mass_matrix[(p, i)] = mij;
            k = p;
        }
        if let Some(p) = j.parent {
            let y = act_inertia_sym(&data.li_m_i[i], &yi);
            data.ycrb[p] += y;
        }
    }
    &data.mass_matrix
}
