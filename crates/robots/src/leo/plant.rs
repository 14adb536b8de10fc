//! A planar Leo-like biped (paper p0): torso on a boom, hips, knees, ankles and a shoulder.
//!
//! The boom is modelled as the sagittal base: `boom_x` and `boom_z` (prismatic) and
//! `torso_pitch` (revolute about y), so the torso moves in the x-z plane. Seven actuated joints
//! (p0, Sec. IV-B): `left_hip`, `left_knee`, `left_ankle`, `right_hip`, `right_knee`,
//! `right_ankle` driven by DC motors (voltage actions, in this order), and the `shoulder` held by a
//! PD controller. Feet, knees, hip, torso top and arm tip carry ground-contact points.
//!
//! Dimensions and masses are Leo-like (torso 0.942 kg as p0's idealized model, thigh 0.116 m,
//! shin 0.1085 m), not the real robot's data. All joints rotate about +y: a positive angle
//! swings the part below it backwards (towards −x); the robot walks towards +x.

use nalgebra::{DVector, Vector3};
use tandem_dynamics::actuators::{Actuator, DcMotor, PdController};
use tandem_dynamics::contact::GroundContact;
use tandem_dynamics::rigid::{forward_kinematics, Data, Model};
use tandem_dynamics::rigid_plant::{Overrides, RigidBodyPlant, RigidPlantConfig, RigidPlantError};

/// Thigh length (m).
pub const THIGH: f64 = 0.116;
/// Shin length (m).
pub const SHIN: f64 = 0.1085;
/// Ankle height above the sole (m).
pub const ANKLE_HEIGHT: f64 = 0.03;
/// Hip height when standing straight with flat feet on the ground (m).
pub const HIP_HEIGHT: f64 = THIGH + SHIN + ANKLE_HEIGHT;

/// The learned (voltage-driven) joints, in action order.
pub const MOTOR_JOINTS: [&str; 6] = [
    "left_hip",
    "left_knee",
    "left_ankle",
    "right_hip",
    "right_knee",
    "right_ankle",
];

fn inertial(mass: f64, com: [f64; 3], i: [f64; 3]) -> String {
    format!(
        r#"<inertial><origin xyz="{} {} {}" rpy="0 0 0"/><mass value="{mass}"/><inertia ixx="{}" ixy="0" ixz="0" iyy="{}" iyz="0" izz="{}"/></inertial>"#,
        com[0], com[1], com[2], i[0], i[1], i[2]
    )
}

fn joint(name: &str, ty: &str, parent: &str, child: &str, xyz: [f64; 3], axis: &str) -> String {
    format!(
        r#"<joint name="{name}" type="{ty}"><parent link="{parent}"/><child link="{child}"/><origin xyz="{} {} {}" rpy="0 0 0"/><axis xyz="{axis}"/><limit lower="-3.14" upper="3.14" effort="10" velocity="50"/></joint>"#,
        xyz[0], xyz[1], xyz[2]
    )
}

/// The biped's URDF text.
pub fn leo_urdf() -> String {
    let mut s = String::from("<?xml version=\"1.0\"?>\n<robot name=\"leo_planar\">\n");
    s += "<link name=\"world\"/>\n<link name=\"boom_carriage\"/>\n<link name=\"boom_slider\"/>\n";
    s += &joint(
        "boom_x",
        "prismatic",
        "world",
        "boom_carriage",
        [0.0; 3],
        "1 0 0",
    );
    s += &joint(
        "boom_z",
        "prismatic",
        "boom_carriage",
        "boom_slider",
        [0.0; 3],
        "0 0 1",
    );
    s += &joint(
        "torso_pitch",
        "continuous",
        "boom_slider",
        "torso",
        [0.0; 3],
        "0 1 0",
    );
    s += &format!(
        "<link name=\"torso\">{}</link>\n",
        inertial(0.942, [0.0, 0.0, 0.1], [0.0055, 0.0053, 0.001])
    );
    s += &joint(
        "shoulder",
        "revolute",
        "torso",
        "arm",
        [0.0, 0.0, 0.24],
        "0 1 0",
    );
    s += &format!(
        "<link name=\"arm\">{}</link>\n",
        inertial(0.15, [0.0, 0.0, -0.075], [0.00029, 0.00029, 0.00002])
    );
    for (side, y) in [("left", 0.04), ("right", -0.04)] {
        let thigh = format!("{side}_thigh");
        let shin = format!("{side}_shin");
        let foot = format!("{side}_foot");
        s += &joint(
            &format!("{side}_hip"),
            "revolute",
            "torso",
            &thigh,
            [0.0, y, 0.0],
            "0 1 0",
        );
        s += &format!(
            "<link name=\"{thigh}\">{}</link>\n",
            inertial(0.177, [0.0, 0.0, -THIGH / 2.0], [0.0002, 0.0002, 0.00002])
        );
        s += &joint(
            &format!("{side}_knee"),
            "revolute",
            &thigh,
            &shin,
            [0.0, 0.0, -THIGH],
            "0 1 0",
        );
        s += &format!(
            "<link name=\"{shin}\">{}</link>\n",
            inertial(0.122, [0.0, 0.0, -SHIN / 2.0], [0.00012, 0.00012, 0.00001])
        );
        s += &joint(
            &format!("{side}_ankle"),
            "revolute",
            &shin,
            &foot,
            [0.0, 0.0, -SHIN],
            "0 1 0",
        );
        s += &format!(
            "<link name=\"{foot}\">{}</link>\n",
            inertial(0.06, [0.015, 0.0, -0.02], [0.00002, 0.00004, 0.00004])
        );
    }
    s += "</robot>\n";
    s
}

/// Heel and toe positions in the foot frame (m).
pub const HEEL: [f64; 3] = [-0.03, 0.0, -ANKLE_HEIGHT];
/// See [`HEEL`].
pub const TOE: [f64; 3] = [0.06, 0.0, -ANKLE_HEIGHT];
/// The top of the torso (its contact point) in the torso frame (m).
pub const HEAD: [f64; 3] = [0.0, 0.0, 0.26];
/// The arm's tip (its contact point) in the arm frame (m).
pub const HAND: [f64; 3] = [0.0, 0.0, -0.15];

/// The biped as a plant: six DC motors (actions are volts), a PD shoulder, foot/knee/hip/torso/arm
/// contact points on a ground plane at z = 0.
pub fn leo_plant(
    config: RigidPlantConfig,
    overrides: &Overrides,
) -> Result<RigidBodyPlant, RigidPlantError> {
    let model = Model::from_urdf_str(&leo_urdf())
        .map_err(|e| RigidPlantError::Config(format!("biped URDF: {e}")))?;
    let mut p = RigidBodyPlant::new(model, config)?;
    for j in MOTOR_JOINTS {
        p = p.with_actuator(j, Actuator::Motor(DcMotor::default()))?;
    }
    p = p.with_actuator(
        "shoulder",
        Actuator::Pd(PdController {
            kp: 2.0,
            kd: 0.1,
            target: 0.0,
            torque_max: 2.0,
        }),
    )?;
    for side in ["left", "right"] {
        p = p
            .with_contact(&format!("{side}_heel"), &format!("{side}_foot"), HEEL)?
            .with_contact(&format!("{side}_toe"), &format!("{side}_foot"), TOE)?
            .with_contact(&format!("{side}_knee"), &format!("{side}_shin"), [0.0; 3])?;
    }
    p = p
        .with_contact("hip", "torso", [0.0; 3])?
        .with_contact("head", "torso", HEAD)?
        .with_contact("hand", "arm", HAND)?;
    p = p.with_ground(GroundContact::default());
    p.with_overrides(overrides)
}

/// p0, Table I: the true Leo has a heavier torso (1.25 kg instead of 0.942) and viscous joint
/// friction 0.03 on every actuator.
pub fn leo_true_overrides() -> Overrides {
    Overrides {
        link_mass: [("torso".to_string(), 1.25)].into_iter().collect(),
        viscous_friction: Some(0.03),
        ..Overrides::default()
    }
}

/// Standing straight, feet flat on the ground (static sinkage of the contacts included).
pub fn standing_state(model: &Model) -> DVector<f64> {
    let n = model.nv();
    let mut x = DVector::zeros(2 * n);
    let z = model.joint_index("boom_z").expect("biped has boom_z");
    x[z] = HIP_HEIGHT - 0.0002;
    x
}

/// The biped drawn as sagittal-plane polylines `(x, z)` (m) at joint positions `q`: each leg
/// hip–knee–ankle and its foot heel–toe, the torso hip–head, the arm shoulder–hand. For pictures
/// of a gait.
pub fn skeleton(model: &Model, q: &[f64]) -> Result<Vec<Vec<[f64; 2]>>, RigidPlantError> {
    if q.len() != model.nv() {
        return Err(RigidPlantError::Config(format!(
            "skeleton: {} joint positions for a model of {}",
            q.len(),
            model.nv()
        )));
    }
    let mut data = Data::new(model);
    forward_kinematics(model, &mut data, q);
    let joint = |name: &str| {
        model
            .joint_index(name)
            .ok_or_else(|| RigidPlantError::Config(format!("skeleton: no joint {name}")))
    };
    let point = |j: usize, p: [f64; 3]| {
        let w = data.o_m_i[j].act_point(&Vector3::new(p[0], p[1], p[2]));
        [w.x, w.z]
    };
    let torso = joint("torso_pitch")?;
    let mut lines = vec![
        vec![point(torso, [0.0; 3]), point(torso, HEAD)],
        vec![
            point(joint("shoulder")?, [0.0; 3]),
            point(joint("shoulder")?, HAND),
        ],
    ];
    for side in ["left", "right"] {
        let ankle = joint(&format!("{side}_ankle"))?;
        lines.push(vec![
            point(joint(&format!("{side}_hip"))?, [0.0; 3]),
            point(joint(&format!("{side}_knee"))?, [0.0; 3]),
            point(ankle, [0.0; 3]),
        ]);
        lines.push(vec![point(ankle, HEEL), point(ankle, TOE)]);
    }
    Ok(lines)
}

/// A hand-written test policy for the biped: joint-space PD through the motor model (volts from
/// desired torques), keeping the torso upright with the hips; with `stride > 0` a periodic gait
/// (hips swing in anti-phase, the swing knee flexes, the ankles keep the feet level).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BipedTestPolicy {
    /// Hip swing amplitude (rad); 0 = stand.
    pub stride: f64,
    /// Swing-knee flexion amplitude (rad).
    pub knee_lift: f64,
    /// Gait period (s).
    pub period: f64,
    /// Joint PD gains (N m/rad, N m s/rad).
    pub kp: f64,
    /// See `kp`.
    pub kd: f64,
    /// Torso-pitch gains applied through the hips.
    pub kp_torso: f64,
    /// See `kp_torso`.
    pub kd_torso: f64,
    /// Target torso pitch (rad, positive = leaning forward).
    pub lean: f64,
    /// Swing-foot placement gain on the forward speed (rad per m/s).
    pub cv: f64,
}

impl BipedTestPolicy {
    /// Stand still.
    pub fn stand() -> Self {
        Self {
            stride: 0.0,
            knee_lift: 0.0,
            period: 1.0,
            kp: 6.0,
            kd: 0.15,
            kp_torso: 4.0,
            kd_torso: 0.2,
            lean: 0.0,
            cv: 0.0,
        }
    }

    /// A slow walking gait.
    pub fn walk() -> Self {
        Self {
            stride: 0.1,
            knee_lift: 0.6,
            period: 0.6,
            kp_torso: 15.0,
            kd_torso: 0.2,
            lean: 0.0,
            cv: 0.0,
            ..Self::stand()
        }
    }

    /// Voltages for the six motors at time `t` in state `x` of the plant from [`leo_plant`]:
    /// desired joint torques converted at the motor's stall gain, `U = τ R / (G K)`, clipped.
    pub fn act(&self, plant: &RigidBodyPlant, t: f64, x: &DVector<f64>) -> DVector<f64> {
        let m = plant.model();
        let n = m.nv();
        let idx = |name: &str| m.joint_index(name).expect("biped joint");
        let (pitch, dpitch) = (x[idx("torso_pitch")], x[n + idx("torso_pitch")]);
        let motor = DcMotor::default();
        let mut u = DVector::zeros(6);
        let walking = self.stride > 0.0;
        // SIMBICON-like state machine (Yin et al. 2007): the legs alternate every half period;
        // the swing thigh is placed at `stride + cv · ẋ` ahead (balance feedback on the forward
        // speed), the swing knee flexes during the first 60 % of the swing.
        let half = 0.5 * self.period;
        let step = (t / half).floor();
        let frac = t / half - step;
        let swing_leg = (step as usize) % 2;
        let vx = x[n + idx("boom_x")];
        let mut tau = [[0.0; 3]; 2];
        let mut swinging = [false; 2];
        for (s, side) in ["left", "right"].iter().enumerate() {
            let (h, k, a) = (
                idx(&format!("{side}_hip")),
                idx(&format!("{side}_knee")),
                idx(&format!("{side}_ankle")),
            );
            swinging[s] = walking && s == swing_leg;
            // World thigh angle target (negative = foot ahead of the hip).
            let (thigh_des, knee_des) = if !walking {
                (0.0, 0.0)
            } else if swinging[s] {
                let lift = if frac < 0.6 { self.knee_lift } else { 0.0 };
                (-(self.stride + self.cv * vx), lift)
            } else {
                // Stance thigh: not tracked (its hip balances the torso); foot kept flat.
                (pitch + x[h], 0.0)
            };
            let hip_des = thigh_des - pitch;
            let ankle_des = -(pitch + hip_des + knee_des);
            tau[s] = [
                self.kp * (hip_des - x[h]) - self.kd * x[n + h],
                self.kp * (knee_des - x[k]) - self.kd * x[n + k],
                self.kp * (ankle_des - x[a]) - self.kd * x[n + a],
            ];
        }
        // The torso is balanced through the hips: the net hip torque is the torso PD torque
        // (its reaction pitches the torso back). Standing, both hips share it; walking, the
        // stance hip supplies it and cancels the swing hip's reaction.
        let torso = 2.0 * (self.kp_torso * (pitch - self.lean) + self.kd_torso * dpitch);
        match swinging {
            [true, false] => tau[1][0] = torso - tau[0][0],
            [false, true] => tau[0][0] = torso - tau[1][0],
            _ => {
                tau[0][0] += 0.5 * torso;
                tau[1][0] += 0.5 * torso;
            }
        }
        for s in 0..2 {
            for c in 0..3 {
                // Stall-torque voltage: the motor's back-EMF then adds its own damping
                // (G² K² / R ≈ 0.37 N m s/rad), which a 30 ms control period needs.
                u[3 * s + c] = motor
                    .voltage_for(tau[s][c], 0.0)
                    .clamp(-motor.voltage_max, motor.voltage_max);
            }
        }
        u
    }
}
