//! Every quantity of `tests/fixtures/pinocchio/{leg2r,arm7}.json` (computed by Pinocchio 4.1 from
//! the URDFs beside them) agrees to 1e-9 relative, or 1e-10 absolute near zero.

use serde_json::Value;
use tandem_dynamics::rigid::*;

const DIR: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../tests/fixtures/pinocchio/"
);

fn vecf(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn rows(v: &Value) -> Vec<Vec<f64>> {
    v.as_array().unwrap().iter().map(vecf).collect()
}

struct Checker {
    worst: f64,
    count: usize,
}

impl Checker {
    fn close(&mut self, what: &str, got: f64, want: f64) {
        let err = (got - want).abs();
        let tol = 1e-10_f64.max(1e-9 * want.abs());
        assert!(
            err <= tol,
            "{what}: got {got:.17e}, want {want:.17e} (err {err:.3e})"
        );
        self.worst = self.worst.max(err / tol);
        self.count += 1;
    }
    fn slice(&mut self, what: &str, got: &[f64], want: &[f64]) {
        assert_eq!(got.len(), want.len(), "{what}: length");
        for (i, (g, w)) in got.iter().zip(want).enumerate() {
            self.close(&format!("{what}[{i}]"), *g, *w);
        }
    }
}

fn check_model(name: &str) {
    let model = Model::from_urdf_file(format!("{DIR}{name}.urdf")).unwrap();
    let fx: Value =
        serde_json::from_str(&std::fs::read_to_string(format!("{DIR}{name}.json")).unwrap())
            .unwrap();
    let names: Vec<String> = fx["joint_names"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap().to_string())
        .collect();
    assert_eq!(model.joint_names(), names);
    assert_eq!(fx["nv"].as_u64().unwrap() as usize, model.nv());
    let g = vecf(&fx["gravity"]);
    assert_eq!(model.gravity.as_slice(), g.as_slice());
    let mut ck = Checker {
        worst: 0.0,
        count: 0,
    };
    ck.close(
        "total_mass",
        model.total_mass(),
        fx["total_mass"].as_f64().unwrap(),
    );
    // Body inertias after fixed-joint merging.
    for (jn, b) in fx["body_inertias_pinocchio"].as_object().unwrap() {
        let j = &model.joints[model.joint_index(jn).unwrap()];
        ck.close("body mass", j.inertia.mass, b["mass"].as_f64().unwrap());
        ck.slice("body lever", j.inertia.com().as_slice(), &vecf(&b["lever"]));
        let ic = j.inertia.inertia_at_com();
        for (r, row) in rows(&b["inertia_at_com"]).iter().enumerate() {
            for (c, w) in row.iter().enumerate() {
                ck.close("body inertia", ic[(r, c)], *w);
            }
        }
    }
    for jf in fx["joints"].as_array().unwrap() {
        let j = &model.joints[model.joint_index(jf["name"].as_str().unwrap()).unwrap()];
        ck.close("lower", j.lower, jf["lower"].as_f64().unwrap());
        ck.close("upper", j.upper, jf["upper"].as_f64().unwrap());
        ck.close("effort", j.effort, jf["effort"].as_f64().unwrap());
        ck.close("velocity", j.velocity, jf["velocity"].as_f64().unwrap());
        let parent = jf["parent_joint"].as_str().unwrap();
        assert_eq!(
            j.parent
                .map(|p| model.joints[p].name.as_str())
                .unwrap_or("universe"),
            parent
        );
    }

    let mut data = Data::new(&model);
    let samples = fx["samples"].as_array().unwrap();
    assert!(samples.len() >= 10);
    for (si, s) in samples.iter().enumerate() {
        let (q, v, a, tau) = (vecf(&s["q"]), vecf(&s["v"]), vecf(&s["a"]), vecf(&s["tau"]));
        let tag = |w: &str| format!("{name} sample {si} {w}");
        let r = rnea(&model, &mut data, &q, &v, &a).clone();
        ck.slice(&tag("rnea"), r.as_slice(), &vecf(&s["rnea"]));
        let m = crba(&model, &mut data, &q).clone();
        for (i, row) in rows(&s["mass_matrix"]).iter().enumerate() {
            for (j, w) in row.iter().enumerate() {
                ck.close(&tag("mass_matrix"), m[(i, j)], *w);
            }
        }
        let dd = aba(&model, &mut data, &q, &v, &tau).clone();
        ck.slice(&tag("aba"), dd.as_slice(), &vecf(&s["aba"]));
        let nle = nonlinear_effects(&model, &mut data, &q, &v).clone();
        ck.slice(&tag("nle"), nle.as_slice(), &vecf(&s["nle"]));
        let gt = gravity_torque(&model, &mut data, &q).clone();
        ck.slice(
            &tag("gravity_torque"),
            gt.as_slice(),
            &vecf(&s["gravity_torque"]),
        );

        forward_kinematics(&model, &mut data, &q);
        update_frame_placements(&model, &mut data);
        let check_placement = |ck: &mut Checker, what: &str, got: &Se3, want: &Value| {
            ck.slice(what, got.trans.as_slice(), &vecf(&want["translation"]));
            for (r, row) in rows(&want["rotation"]).iter().enumerate() {
                for (c, w) in row.iter().enumerate() {
                    ck.close(what, got.rot[(r, c)], *w);
                }
            }
        };
        let lp = s["link_placements"].as_object().unwrap();
        assert_eq!(lp.len(), model.frames.len());
        for (ln, want) in lp {
            let k = model.frame_index(ln).unwrap();
            let got = data.o_m_f[k];
            check_placement(&mut ck, &tag(&format!("link {ln}")), &got, want);
        }
        for (jn, want) in s["joint_placements"].as_object().unwrap() {
            let got = data.o_m_i[model.joint_index(jn).unwrap()];
            check_placement(&mut ck, &tag(&format!("joint {jn}")), &got, want);
        }
        for (fname, want) in s["frame_jacobians"].as_object().unwrap() {
            let k = model.frame_index(fname).unwrap();
            frame_jacobian(&model, &mut data, k);
            for (r, row) in rows(want).iter().enumerate() {
                for (c, w) in row.iter().enumerate() {
                    ck.close(
                        &tag(&format!("jacobian {fname}")),
                        data.jacobian[(r, c)],
                        *w,
                    );
                }
            }
        }
        center_of_mass(&model, &mut data, &q, &v);
        ck.slice(&tag("com"), data.com.as_slice(), &vecf(&s["com"]));
        ck.slice(
            &tag("com_velocity"),
            data.com_velocity.as_slice(),
            &vecf(&s["com_velocity"]),
        );
        let ke = kinetic_energy(&model, &mut data, &q, &v);
        ck.close(
            &tag("kinetic_energy"),
            ke,
            s["kinetic_energy"].as_f64().unwrap(),
        );
        let pe = potential_energy(&model, &mut data, &q);
        ck.close(
            &tag("potential_energy"),
            pe,
            s["potential_energy"].as_f64().unwrap(),
        );
    }
    eprintln!(
        "{name}: {} values, worst error/tolerance {:.3}",
        ck.count, ck.worst
    );
}

#[test]
fn leg2r_matches_pinocchio() {
    check_model("leg2r");
}

#[test]
fn arm7_matches_pinocchio() {
    check_model("arm7");
}
