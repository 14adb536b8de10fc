//! `tandem urdf inspect FILE` and `tandem urdf eval FILE --states JSON_FILE`: the rigid-body
//! dynamics of a URDF robot, in the conventions of `tests/fixtures/pinocchio/*.json` (gravity
//! `(0, 0, -9.81)`, Pinocchio's joint order, placements as translation + row-major rotation).

use std::path::PathBuf;

use clap::Subcommand;
use serde_json::{json, Map, Value};
use tandem_dynamics::rigid::{
    aba, center_of_mass, crba, forward_kinematics, gravity_torque, kinetic_energy,
    nonlinear_effects, potential_energy, rnea, update_frame_placements, Data, JointKind, Model,
    Se3,
};

use super::json::{check_output, kind, numbers, parse};
use super::{CliError, IoOp, Result};

/// `tandem urdf ...`
#[derive(Debug, Subcommand)]
pub enum UrdfCommand {
    /// Print the joints (order, type, axis, parent, limits, damping/friction), DoF and masses.
    Inspect {
        /// The URDF file.
        file: PathBuf,
    },
    /// Evaluate RNEA, CRBA, ABA, NLE, gravity torques, link placements, COM and energies for a
    /// list of states `[{"q": [...], "v": [...], "tau": [...], "a": [...]}, ...]` (`v`, `tau`, `a`
    /// default to zeros) and print one JSON object `{joint_names, results}`. Inputs must be
    /// finite, and so must every result: a state or model whose dynamics overflow `f64` (huge
    /// velocities, a 1e308 kg link) is an error naming the state and the quantity.
    Eval {
        /// The URDF file.
        file: PathBuf,
        /// JSON file with the list of states (at most 64 MiB).
        #[arg(long)]
        states: PathBuf,
    },
}

/// Runs a `urdf` subcommand.
pub fn run(cmd: UrdfCommand) -> Result<()> {
    match cmd {
        UrdfCommand::Inspect { file } => {
            let model = load(&file)?;
            write_stdout(&inspect(&model))
        }
        UrdfCommand::Eval { file, states } => {
            let model = load(&file)?;
            let text = tandem_core::read_file_capped(&states, tandem_core::MAX_INPUT_BYTES)
                .map_err(|source| CliError::io(IoOp::Read, &states, source))?;
            let what = format!("states file {}", states.display());
            let out = eval(&model, &parse(&text, &what)?, &what)?;
            let text = serde_json::to_string_pretty(&out).map_err(CliError::other)?;
            write_stdout(&(text + "\n"))
        }
    }
}

/// Writes to stdout; a closed pipe (`tandem urdf eval ... | head`) ends quietly with status 0.
fn write_stdout(text: &str) -> Result<()> {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => std::process::exit(0),
        Err(e) => Err(CliError::Other(format!("cannot write to stdout: {e}"))),
    }
}

fn load(file: &PathBuf) -> Result<Model> {
    Model::from_urdf_file(file).map_err(|e| CliError::Other(format!("{}: {e}", file.display())))
}

/// The human-readable summary printed by `inspect`.
pub fn inspect(model: &Model) -> String {
    let mut s = format!(
        "robot '{}': {} DoF (nq = nv = {}), moving mass {} kg, {} links\n",
        model.name,
        model.nv(),
        model.nv(),
        model.total_mass(),
        model.frames.len()
    );
    s += "joints (Pinocchio order):\n";
    s += "  #  name                 type       axis                  parent           mass [kg]  lower      upper      effort     velocity   damping  friction\n";
    for (i, j) in model.joints.iter().enumerate() {
        let parent = j
            .parent
            .map(|p| model.joints[p].name.clone())
            .unwrap_or_else(|| "universe".into());
        let ty = match (j.kind, j.lower.is_infinite() && j.upper.is_infinite()) {
            (JointKind::Revolute, true) => "continuous",
            (JointKind::Revolute, false) => "revolute",
            (JointKind::Prismatic, _) => "prismatic",
        };
        s += &format!(
            "  {i:<2} {:<20} {:<10} [{:>6.3}, {:>6.3}, {:>6.3}] {:<16} {:<10.4} {:<10.4} {:<10.4} {:<10.4} {:<10.4} {:<8.4} {:<8.4}\n",
            j.name, ty, j.axis.x, j.axis.y, j.axis.z, parent, j.inertia.mass, j.lower, j.upper,
            j.effort, j.velocity, j.damping, j.friction
        );
    }
    s += "links (body = the joint that moves it):\n";
    for f in &model.frames {
        let body = f
            .joint
            .map(|i| model.joints[i].name.clone())
            .unwrap_or_else(|| "universe".into());
        s += &format!("  {:<20} body {body}\n", f.name);
    }
    s
}

fn placement(m: &Se3) -> Value {
    let r = &m.rot;
    json!({
        "translation": [m.trans.x, m.trans.y, m.trans.z],
        "rotation": [[r[(0, 0)], r[(0, 1)], r[(0, 2)]], [r[(1, 0)], r[(1, 1)], r[(1, 2)]], [r[(2, 0)], r[(2, 1)], r[(2, 2)]]],
    })
}

/// The placements of named frames as a JSON map, each checked finite (`kind`: "link"/"joint").
fn placements<'a>(
    what: &str,
    kind: &str,
    names: impl Iterator<Item = &'a String>,
    poses: &[Se3],
) -> Result<Map<String, Value>> {
    names
        .zip(poses)
        .map(|(name, m)| {
            let quantity = format!("placement of {kind} '{name}'");
            check_output(what, &quantity, m.trans.as_slice())?;
            check_output(what, &quantity, m.rot.as_slice())?;
            Ok((name.clone(), placement(m)))
        })
        .collect()
}

/// One vector field of a state: `nv` finite numbers, zeros when absent and `optional`.
fn field(state: &Map<String, Value>, name: &str, nv: usize, what: &str) -> Result<Vec<f64>> {
    let Some(v) = state.get(name) else {
        if name == "q" {
            return Err(CliError::input(what, "missing \"q\""));
        }
        return Ok(vec![0.0; nv]);
    };
    let what = format!("{what} \"{name}\"");
    let x = numbers(v, &what)?;
    if x.len() != nv {
        return Err(CliError::input(
            what,
            format!("has {} entries, the model has {nv} DoF", x.len()),
        ));
    }
    if let Some((i, z)) = x.iter().enumerate().find(|(_, z)| !z.is_finite()) {
        return Err(CliError::input(
            what,
            format!("element {i} is not finite ({z})"),
        ));
    }
    Ok(x)
}

/// Evaluates every state of `states` (a JSON array) on `model`.
pub fn eval(model: &Model, states: &Value, what: &str) -> Result<Value> {
    let list = states.as_array().ok_or_else(|| {
        CliError::input(
            what,
            format!("expected a list of states, got {}", kind(states)),
        )
    })?;
    let nv = model.nv();
    let mut data = Data::new(model);
    let mut results = Vec::with_capacity(list.len());
    for (k, s) in list.iter().enumerate() {
        let sw = format!("{what}: state {k}");
        let obj = s
            .as_object()
            .ok_or_else(|| CliError::input(&sw, format!("expected an object, got {}", kind(s))))?;
        if let Some(extra) = obj
            .keys()
            .find(|key| !["q", "v", "tau", "a"].contains(&key.as_str()))
        {
            return Err(CliError::input(
                &sw,
                format!("unknown field \"{extra}\" (expected q, v, tau, a)"),
            ));
        }
        let q = field(obj, "q", nv, &sw)?;
        let v = field(obj, "v", nv, &sw)?;
        let tau = field(obj, "tau", nv, &sw)?;
        let a = field(obj, "a", nv, &sw)?;
        let r = rnea(model, &mut data, &q, &v, &a).as_slice().to_vec();
        check_output(&sw, "rnea", &r)?;
        let m = crba(model, &mut data, &q).clone();
        check_output(&sw, "mass_matrix", m.as_slice())?;
        let mm: Vec<Vec<f64>> = (0..nv)
            .map(|i| (0..nv).map(|j| m[(i, j)]).collect())
            .collect();
        let ddq = aba(model, &mut data, &q, &v, &tau).as_slice().to_vec();
        check_output(&sw, "aba", &ddq)?;
        let nle = nonlinear_effects(model, &mut data, &q, &v)
            .as_slice()
            .to_vec();
        check_output(&sw, "nle", &nle)?;
        let g = gravity_torque(model, &mut data, &q).as_slice().to_vec();
        check_output(&sw, "gravity_torque", &g)?;
        forward_kinematics(model, &mut data, &q);
        update_frame_placements(model, &mut data);
        let links = placements(
            &sw,
            "link",
            model.frames.iter().map(|f| &f.name),
            &data.o_m_f,
        )?;
        let joints = placements(
            &sw,
            "joint",
            model.joints.iter().map(|j| &j.name),
            &data.o_m_i,
        )?;
        center_of_mass(model, &mut data, &q, &v);
        let (com, vcom) = (data.com, data.com_velocity);
        check_output(&sw, "com", com.as_slice())?;
        check_output(&sw, "com_velocity", vcom.as_slice())?;
        let ke = kinetic_energy(model, &mut data, &q, &v);
        check_output(&sw, "kinetic_energy", &[ke])?;
        let pe = potential_energy(model, &mut data, &q);
        check_output(&sw, "potential_energy", &[pe])?;
        results.push(json!({
            "q": q, "v": v, "a": a, "tau": tau,
            "rnea": r,
            "mass_matrix": mm,
            "aba": ddq,
            "nle": nle,
            "gravity_torque": g,
            "link_placements": links,
            "joint_placements": joints,
            "com": [com.x, com.y, com.z],
            "com_velocity": [vcom.x, vcom.y, vcom.z],
            "kinetic_energy": ke,
            "potential_energy": pe,
        }));
    }
    Ok(json!({
        "model": model.name,
        "gravity": [model.gravity.x, model.gravity.y, model.gravity.z],
        "joint_names": model.joint_names(),
        "results": results,
    }))
}
