//! Composite rigid-body algorithm (Featherstone, Table 6.2): the joint-space mass matrix `M(q)`.

use super::{Data, Model};
use nalgebra::DMatrix;

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
        let mut f = data.ycrb[i].mul_motion(&s);
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
            let y = data.li_m_i[i].act_inertia(&data.ycrb[i]);
            data.ycrb[p] += y;
        }
    }
    &data.mass_matrix
}
