//! The immutable [`Model`] of a robot: a kinematic tree of 1-DoF joints built from URDF.
//!
//! Joint order is Pinocchio's: depth-first over the URDF tree from the root link, the child joints
//! of a link visited in alphabetical order of their names. Fixed joints have no coordinate: the
//! child link is merged into the body of its nearest movable ancestor (its inertia is added there,
//! and its frame is kept as a [`Frame`] for kinematics).

use super::spatial::{axis_rotation, Inertia, Motion, Se3};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use std::collections::{BTreeMap, HashMap};

/// Largest URDF accepted, in bytes (64 MiB). Robot descriptions are kilobytes to a few
/// megabytes (meshes live in separate files); the limit keeps a hostile or mistaken input from
/// exhausting memory in the XML parser. [`UrdfError::TooLarge`] names it.
pub const MAX_URDF_BYTES: usize = 64 << 20;

/// Deepest XML element nesting accepted (the `<robot>` element is depth 1). URDF itself needs 6
/// (`robot/link/visual/geometry/mesh`, plus vendor extensions a few levels deeper); urdf-rs's
/// parser recurses once per level, so thousands of nested elements would overflow its stack.
/// The nesting is measured by an iterative scan before urdf-rs sees the text.
pub const MAX_XML_DEPTH: usize = 256;

/// Standard gravity of the fixtures and of the papers' robots: `(0, 0, -9.81)` m/s², z up.
pub const STANDARD_GRAVITY: [f64; 3] = [0.0, 0.0, -9.81];

/// Why a URDF could not be turned into a [`Model`]. Every variant names the offending element.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UrdfError {
    /// The file could not be read.
    #[error("cannot read URDF file {path}: {message}")]
    Io {
        /// The path.
        path: String,
        /// The OS error.
        message: String,
    },
    /// Not well-formed XML, or not the URDF structure.
    #[error("malformed URDF: {0}")]
    Malformed(String),
    /// A `<joint type=...>` that URDF does not define.
    #[error("joint '{joint}' has unknown type '{joint_type}'")]
    UnknownJointType {
        /// The joint's name.
        joint: String,
        /// The type attribute.
        joint_type: String,
    },
    /// A valid URDF feature this library does not model.
    #[error("joint '{joint}': {what} is not supported")]
    Unsupported {
        /// The joint's name.
        joint: String,
        /// What is unsupported (`"floating joint"`, `"mimic"`, ...).
        what: String,
    },
    /// Two elements with the same name.
    #[error("duplicate {element} name '{name}'")]
    Duplicate {
        /// `"link"` or `"joint"`.
        element: &'static str,
        /// The repeated name.
        name: String,
    },
    /// A joint refers to a link that does not exist.
    #[error("joint '{joint}' refers to unknown link '{link}'")]
    UnknownLink {
        /// The joint's name.
        joint: String,
        /// The missing link.
        link: String,
    },
    /// A link is the child of two joints.
    #[error("link '{link}' has two parents (joints '{first}' and '{second}')")]
    TwoParents {
        /// The link.
        link: String,
        /// First parent joint.
        first: String,
        /// Second parent joint.
        second: String,
    },
    /// The joints form a cycle (no root, or links unreachable from the root).
    #[error("the kinematic graph has a cycle through link '{link}'")]
    Cycle {
        /// A link on the cycle.
        link: String,
    },
    /// More than one link without a parent.
    #[error("the URDF has several root links: '{first}' and '{second}'")]
    SeveralRoots {
        /// One root.
        first: String,
        /// Another root.
        second: String,
    },
    /// An `<inertial>` without `<mass>` or `<inertia>`.
    #[error("link '{link}': <inertial> has no <{missing}>")]
    MissingInertia {
        /// The link.
        link: String,
        /// `"mass"` or `"inertia"`.
        missing: &'static str,
    },
    /// A negative/non-finite mass, or an inertia tensor that is not positive definite.
    #[error("link '{link}': {reason}")]
    BadInertia {
        /// The link.
        link: String,
        /// What is wrong.
        reason: String,
    },
    /// A joint whose subtree has no inertia about its axis: the mass matrix would be singular.
    #[error("joint '{joint}' moves no mass or inertia about its axis (singular mass matrix)")]
    MasslessJoint {
        /// The joint.
        joint: String,
    },
    /// A zero or non-finite joint axis.
    #[error("joint '{joint}' has an invalid axis {axis:?}")]
    BadAxis {
        /// The joint.
        joint: String,
        /// The axis as written.
        axis: [f64; 3],
    },
    /// A revolute or prismatic joint without `<limit>`. urdfdom (and so ROS and Pinocchio)
    /// rejects such a joint; urdf-rs would silently give it the range `[0, 0]` and zero effort.
    #[error("joint '{joint}' is {joint_type} but has no <limit> (use type=\"continuous\" for an unbounded revolute joint)")]
    MissingLimit {
        /// The joint.
        joint: String,
        /// `"revolute"` or `"prismatic"`.
        joint_type: String,
    },
    /// The input is larger or more deeply nested than [`MAX_URDF_BYTES`] or
    /// [`MAX_XML_DEPTH`] allow; checked before the XML is parsed into a robot.
    #[error("URDF {what} {found} exceeds the limit of {limit}")]
    TooLarge {
        /// `"size (bytes)"` or `"XML nesting depth"`.
        what: &'static str,
        /// The limit.
        limit: usize,
        /// What was found (the size, or the depth and where it was reached).
        found: String,
    },
    /// A non-finite number in an origin or limit.
    #[error("joint '{joint}': non-finite {what}")]
    NonFinite {
        /// The joint or link.
        joint: String,
        /// Which attribute.
        what: &'static str,
    },
}

/// The motion subspace of a 1-DoF joint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum JointKind {
    /// Rotation by `q` radians about the unit axis (URDF `revolute` or `continuous`).
    Revolute,
    /// Translation by `q` metres along the unit axis (URDF `prismatic`).
    Prismatic,
}

/// One movable joint and the rigid body it moves.
#[derive(Debug, Clone, PartialEq)]
pub struct JointModel {
    /// URDF joint name.
    pub name: String,
    /// The URDF link this joint moves (its frame is the joint frame).
    pub child_link: String,
    /// Revolute or prismatic.
    pub kind: JointKind,
    /// Unit axis in the joint frame.
    pub axis: Vector3<f64>,
    /// Index of the parent joint (`None`: attached to the world).
    pub parent: Option<usize>,
    /// Placement of the joint frame at `q = 0` in the parent joint's frame (fixed joints between
    /// them folded in).
    pub placement: Se3,
    /// Inertia of everything rigidly moved by this joint (fixed children merged), in its frame.
    pub inertia: Inertia,
    /// Lower position limit (`-inf` for continuous joints).
    pub lower: f64,
    /// Upper position limit (`+inf` for continuous joints).
    pub upper: f64,
    /// Effort limit (N m or N); `inf` when the URDF gives none.
    pub effort: f64,
    /// Velocity limit; `inf` when the URDF gives none.
    pub velocity: f64,
    /// Viscous damping coefficient from `<dynamics damping>`.
    pub damping: f64,
    /// Coulomb friction from `<dynamics friction>`.
    pub friction: f64,
    /// Reflected rotor inertia added to `M[i][i]` (0 from URDF; set for geared motors). RNEA,
    /// CRBA and ABA include it, as Pinocchio's `armature` does.
    pub armature: f64,
    /// `Some((k, ±1))` when `axis` is exactly `±e_k`: the joint rotation then touches two
    /// columns only (Pinocchio's `JointModelRX/RY/RZ`; `−e_k` turns by `−q` about `e_k`).
    pub(crate) aligned: Option<(usize, f64)>,
}

impl JointModel {
    /// The joint's motion subspace `S` (unit velocity) in its own frame.
    #[inline]
    pub fn subspace(&self) -> Motion {
        match self.kind {
            JointKind::Revolute => Motion::new(Vector3::zeros(), self.axis),
            JointKind::Prismatic => Motion::new(self.axis, Vector3::zeros()),
        }
    }

    /// The joint transform `X_J(q)` (child joint frame in the frame at `q = 0`).
    #[inline]
    pub fn joint_transform(&self, q: f64) -> Se3 {
        match self.kind {
            JointKind::Revolute => {
                let (s, c) = libm::sincos(q);
                Se3::new(axis_rotation(&self.axis, s, c), Vector3::zeros())
            }
            JointKind::Prismatic => Se3::new(Matrix3::identity(), self.axis * q),
        }
    }

    /// `placement * X_J(q)`: the joint frame in its parent joint's frame.
    #[inline(always)]
    pub fn local_placement(&self, q: f64) -> Se3 {
        match self.kind {
            JointKind::Revolute => {
                let (s, c) = libm::sincos(q);
                let r = &self.placement.rot;
                let rot = match self.aligned {
                    Some((k, sign)) => {
                        let s = sign * s;
                        // R · Rot(e_k, q) only mixes the two columns other than k.
                        let (i, j) = ((k + 1) % 3, (k + 2) % 3);
                        let (ci, cj) = (r.column(i), r.column(j));
                        let mut out = *r;
                        out.set_column(i, &(ci * c + cj * s));
                        out.set_column(j, &(cj * c - ci * s));
                        out
                    }
                    None => r * axis_rotation(&self.axis, s, c),
                };
                Se3::new(rot, self.placement.trans)
            }
            JointKind::Prismatic => Se3::new(
                self.placement.rot,
                self.placement.trans + self.placement.rot * (self.axis * q),
            ),
        }
    }
}

/// A URDF link frame, attached to a body.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// URDF link name.
    pub name: String,
    /// The joint whose body carries this link (`None`: the world).
    pub joint: Option<usize>,
    /// Placement of the link frame in that joint's frame (or in the world).
    pub placement: Se3,
}

/// An immutable robot model. Algorithms read it and write a [`super::Data`].
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    /// URDF robot name.
    pub name: String,
    /// Movable joints in Pinocchio's order; joint `i` owns `q[i]`, `v[i]`.
    pub joints: Vec<JointModel>,
    /// Every URDF link, in depth-first order (same traversal as the joints).
    pub frames: Vec<Frame>,
    /// World-frame gravity (m/s²).
    pub gravity: Vector3<f64>,
    /// Mass rigidly attached to the world: the root link and links fixed to it. Ignored by the
    /// dynamics, and left out of [`Model::total_mass`], the centre of mass and the potential
    /// energy, as Pinocchio leaves out its universe's inertia.
    pub world_mass: f64,
}

struct Scan {
    types: Vec<(String, String)>,
    inertial_missing: Vec<(String, &'static str)>,
    /// Revolute/prismatic joints (name, type) without a `<limit>` child.
    limit_missing: Vec<(String, String)>,
}

/// A light pass over the XML so that structural problems name their element (urdf-rs's serde
/// errors do not).
fn prescan(xml: &str) -> Result<Scan, UrdfError> {
    use quick_xml::events::Event;
    let mut reader = quick_xml::Reader::from_str(xml);
    let mut stack: Vec<String> = Vec::new();
    let mut link_name = String::new();
    let mut inertial_children: Option<(bool, bool)> = None;
    let mut scan = Scan {
        types: Vec::new(),
        inertial_missing: Vec::new(),
        limit_missing: Vec::new(),
    };
    // The open <joint>: (name, type, has <limit>).
    let mut open_joint: Option<(String, String, bool)> = None;
    let needs_limit = |ty: &str| ty == "revolute" || ty == "prismatic";
    let mut saw_robot = false;
    loop {
        let ev = reader.read_event().map_err(|e| {
            UrdfError::Malformed(format!(
                "XML error at byte {}: {e}",
                reader.error_position()
            ))
        })?;
        let (start, empty) = match &ev {
            Event::Start(s) => (Some(s.clone()), false),
            Event::Empty(s) => (Some(s.clone()), true),
            _ => (None, false),
        };
        if let Some(s) = start {
            let tag = String::from_utf8_lossy(s.name().as_ref()).into_owned();
            let attr = |key: &str| -> Option<String> {
                s.attributes().flatten().find_map(|a| {
                    (a.key.as_ref() == key.as_bytes())
                        .then(|| String::from_utf8_lossy(&a.value).into_owned())
                })
            };
            let parent = stack.last().map(String::as_str);
            match (parent, tag.as_str()) {
                (None, "robot") => saw_robot = true,
                (None, other) => {
                    return Err(UrdfError::Malformed(format!(
                        "root element is <{other}>, expected <robot>"
                    )))
                }
                (Some("robot"), "joint") => {
                    let name = attr("name").unwrap_or_default();
                    let ty = attr("type").unwrap_or_default();
                    if empty {
                        if needs_limit(&ty) {
                            scan.limit_missing.push((name.clone(), ty.clone()));
                        }
                    } else {
                        open_joint = Some((name.clone(), ty.clone(), false));
                    }
                    scan.types.push((name, ty));
                }
                (Some("joint"), "limit") => {
                    if let Some(j) = open_joint.as_mut() {
                        j.2 = true;
                    }
                }
                (Some("robot"), "link") => link_name = attr("name").unwrap_or_default(),
                (Some("link"), "inertial") => {
                    inertial_children = Some((false, false));
                    if empty {
                        scan.inertial_missing.push((link_name.clone(), "mass"));
                        inertial_children = None;
                    }
                }
                (Some("inertial"), "mass") => {
                    if let Some(c) = inertial_children.as_mut() {
                        c.0 = true
                    }
                }
                (Some("inertial"), "inertia") => {
                    if let Some(c) = inertial_children.as_mut() {
                        c.1 = true
                    }
                }
                _ => {}
            }
            if !empty {
                if stack.len() >= MAX_XML_DEPTH {
                    return Err(UrdfError::TooLarge {
                        what: "XML nesting depth",
                        limit: MAX_XML_DEPTH,
                        found: format!(
                            "> {MAX_XML_DEPTH} (element <{tag}> at byte {})",
                            reader.buffer_position()
                        ),
                    });
                }
                stack.push(tag);
            }
        }
        match ev {
            Event::End(_) => match stack.pop().as_deref() {
                Some("inertial") => {
                    if let Some((m, i)) = inertial_children.take() {
                        if !m {
                            scan.inertial_missing.push((link_name.clone(), "mass"));
                        } else if !i {
                            scan.inertial_missing.push((link_name.clone(), "inertia"));
                        }
                    }
                }
                Some("joint") if stack.last().map(String::as_str) == Some("robot") => {
                    if let Some((name, ty, false)) = open_joint.take() {
                        if needs_limit(&ty) {
                            scan.limit_missing.push((name, ty));
                        }
                    }
                }
                _ => {}
            },
            Event::Eof => break,
            _ => {}
        }
    }
    if !stack.is_empty() {
        return Err(UrdfError::Malformed(format!(
            "unexpected end of file inside <{}>",
            stack.last().map(String::as_str).unwrap_or("")
        )));
    }
    if !saw_robot {
        return Err(UrdfError::Malformed("no <robot> element".into()));
    }
    Ok(scan)
}

/// Rejects inputs above [`MAX_URDF_BYTES`].
fn check_size(len: usize) -> Result<(), UrdfError> {
    if len > MAX_URDF_BYTES {
        return Err(UrdfError::TooLarge {
            what: "size (bytes)",
            limit: MAX_URDF_BYTES,
            found: if len == MAX_URDF_BYTES + 1 {
                format!("> {MAX_URDF_BYTES}")
            } else {
                len.to_string()
            },
        });
    }
    Ok(())
}

fn check_inertia(link: &urdf_rs::Link) -> Result<Inertia, UrdfError> {
    let inl = &link.inertial;
    let m = inl.mass.value;
    let i = &inl.inertia;
    let bad = |reason: String| UrdfError::BadInertia {
        link: link.name.clone(),
        reason,
    };
    let vals = [m, i.ixx, i.ixy, i.ixz, i.iyy, i.iyz, i.izz];
    if vals.iter().any(|x| !x.is_finite())
        || inl
            .origin
            .xyz
            .iter()
            .chain(inl.origin.rpy.iter())
            .any(|x| !x.is_finite())
    {
        return Err(bad("non-finite inertial value".into()));
    }
    if m < 0.0 {
        return Err(bad(format!("negative mass {m}")));
    }
    let tensor = Matrix3::new(
        i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz,
    );
    if m == 0.0 && tensor.iter().all(|x| *x == 0.0) {
        return Ok(Inertia::zero());
    }
    if m == 0.0 {
        return Err(bad("zero mass with a non-zero inertia tensor".into()));
    }
    let eig = SymmetricEigen::new(tensor).eigenvalues;
    if eig.iter().any(|e| *e <= 0.0) {
        return Err(bad(format!(
            "inertia tensor is not positive definite (eigenvalues {:.3e}, {:.3e}, {:.3e})",
            eig[0], eig[1], eig[2]
        )));
    }
    let pose = Se3::from_xyz_rpy(*inl.origin.xyz, *inl.origin.rpy);
    let ic = pose.rot * tensor * pose.rot.transpose();
    Ok(Inertia::from_com(m, pose.trans, ic))
}

impl Model {
    /// Reads and parses a URDF file. A file larger than [`MAX_URDF_BYTES`] is rejected before
    /// it is read.
    pub fn from_urdf_file(path: impl AsRef<std::path::Path>) -> Result<Model, UrdfError> {
        use std::io::Read as _;
        let path = path.as_ref();
        let io = |e: std::io::Error| UrdfError::Io {
            path: path.display().to_string(),
            message: e.to_string(),
        };
        // Read at most one byte past the limit, so that a huge file (or an endless stream such
        // as /dev/zero) is refused without being read whole.
        let mut bytes = Vec::new();
        std::fs::File::open(path)
            .map_err(io)?
            .take(MAX_URDF_BYTES as u64 + 1)
            .read_to_end(&mut bytes)
            .map_err(io)?;
        check_size(bytes.len())?;
        let xml = String::from_utf8(bytes).map_err(|e| UrdfError::Io {
            path: path.display().to_string(),
            message: format!("not UTF-8 text: {e}"),
        })?;
        Self::from_urdf_str(&xml)
    }

    /// Parses URDF text.
    ///
    /// Joint limits follow urdfdom (the parser behind ROS and Pinocchio): a `revolute` or
    /// `prismatic` joint must have a `<limit>` ([`UrdfError::MissingLimit`] names it otherwise);
    /// `continuous` joints are unbounded; a `<limit>` without `effort`/`velocity` (or with 0)
    /// leaves that limit infinite.
    ///
    /// Input is bounded before it is parsed: at most [`MAX_URDF_BYTES`] bytes and
    /// [`MAX_XML_DEPTH`] levels of element nesting ([`UrdfError::TooLarge`] otherwise). The
    /// number of links is not limited: building the model walks the tree without recursion.
    pub fn from_urdf_str(xml: &str) -> Result<Model, UrdfError> {
        check_size(xml.len())?;
        const KNOWN: [&str; 7] = [
            "revolute",
            "continuous",
            "prismatic",
            "fixed",
            "floating",
            "planar",
            "spherical",
        ];
        let scan = prescan(xml)?;
        for (name, ty) in &scan.types {
            if !KNOWN.contains(&ty.as_str()) {
                return Err(UrdfError::UnknownJointType {
                    joint: name.clone(),
                    joint_type: ty.clone(),
                });
            }
        }
        if let Some((joint, ty)) = scan.limit_missing.first() {
            return Err(UrdfError::MissingLimit {
                joint: joint.clone(),
                joint_type: ty.clone(),
            });
        }
        if let Some((link, missing)) = scan.inertial_missing.first() {
            return Err(UrdfError::MissingInertia {
                link: link.clone(),
                missing,
            });
        }
        let robot =
            urdf_rs::read_from_string(xml).map_err(|e| UrdfError::Malformed(e.to_string()))?;
        Self::from_robot(&robot)
    }

    /// Builds the model from a parsed urdf-rs robot.
    ///
    /// urdf-rs fills a missing `<limit>` with zeros, which cannot be told from a written one
    /// here: a revolute/prismatic joint without `<limit>` gets the range `[0, 0]`. Parse with
    /// [`Model::from_urdf_str`] to have it rejected.
    pub fn from_robot(robot: &urdf_rs::Robot) -> Result<Model, UrdfError> {
        if robot.links.is_empty() {
            return Err(UrdfError::Malformed(format!(
                "robot '{}' has no <link>",
                robot.name
            )));
        }
        let mut links: HashMap<&str, &urdf_rs::Link> = HashMap::new();
        for l in &robot.links {
            if links.insert(l.name.as_str(), l).is_some() {
                return Err(UrdfError::Duplicate {
                    element: "link",
                    name: l.name.clone(),
                });
            }
        }
        let mut seen_joints = HashMap::new();
        let mut parent_of: HashMap<&str, &urdf_rs::Joint> = HashMap::new();
        let mut children: HashMap<&str, BTreeMap<&str, &urdf_rs::Joint>> = HashMap::new();
        for j in &robot.joints {
            if seen_joints.insert(j.name.as_str(), ()).is_some() {
                return Err(UrdfError::Duplicate {
                    element: "joint",
                    name: j.name.clone(),
                });
            }
            use urdf_rs::JointType as T;
            let what = match j.joint_type {
                T::Floating => Some("floating joint"),
                T::Planar => Some("planar joint"),
                T::Spherical => Some("spherical joint"),
                _ => None,
            };
            if let Some(what) = what {
                return Err(UrdfError::Unsupported {
                    joint: j.name.clone(),
                    what: what.into(),
                });
            }
            if let Some(m) = &j.mimic {
                return Err(UrdfError::Unsupported {
                    joint: j.name.clone(),
                    what: format!("mimic (of joint '{}')", m.joint),
                });
            }
            for l in [&j.parent.link, &j.child.link] {
                if !links.contains_key(l.as_str()) {
                    return Err(UrdfError::UnknownLink {
                        joint: j.name.clone(),
                        link: l.clone(),
                    });
                }
            }
            if let Some(prev) = parent_of.insert(j.child.link.as_str(), j) {
                return Err(UrdfError::TwoParents {
                    link: j.child.link.clone(),
                    first: prev.name.clone(),
                    second: j.name.clone(),
                });
            }
            children
                .entry(j.parent.link.as_str())
                .or_default()
                .insert(j.name.as_str(), j);
        }
        let roots: Vec<&str> = robot
            .links
            .iter()
            .map(|l| l.name.as_str())
            .filter(|l| !parent_of.contains_key(l))
            .collect();
        let root = match roots.as_slice() {
            [] => {
                return Err(UrdfError::Cycle {
                    link: robot
                        .links
                        .first()
                        .map(|l| l.name.clone())
                        .unwrap_or_default(),
                })
            }
            [r] => *r,
            [a, b, ..] => {
                return Err(UrdfError::SeveralRoots {
                    first: a.to_string(),
                    second: b.to_string(),
                })
            }
        };

        let mut model = Model {
            name: robot.name.clone(),
            joints: Vec::new(),
            frames: Vec::new(),
            gravity: Vector3::from(STANDARD_GRAVITY),
            world_mass: 0.0,
        };
        let root_inertia = check_inertia(links[root])?;
        model.world_mass += root_inertia.mass;
        model.frames.push(Frame {
            name: root.to_string(),
            joint: None,
            placement: Se3::identity(),
        });
        let tree = Tree {
            links: &links,
            children: &children,
        };
        tree.visit(&mut model, root)?;
        if model.frames.len() != robot.links.len() {
            let reached: std::collections::HashSet<&str> =
                model.frames.iter().map(|f| f.name.as_str()).collect();
            let lost = robot
                .links
                .iter()
                .find(|l| !reached.contains(l.name.as_str()))
                .map(|l| l.name.clone())
                .unwrap_or_default();
            return Err(UrdfError::Cycle { link: lost });
        }
        model.check_massless()?;
        Ok(model)
    }

    /// Rejects joints whose subtree has no inertia about the joint axis.
    fn check_massless(&self) -> Result<(), UrdfError> {
        let n = self.joints.len();
        let mut ycrb: Vec<Inertia> = self.joints.iter().map(|j| j.inertia).collect();
        for i in (0..n).rev() {
            let s = self.joints[i].subspace();
            let d = s.dot(&ycrb[i].mul_motion(&s));
            if d.partial_cmp(&1e-14) != Some(std::cmp::Ordering::Greater) {
                return Err(UrdfError::MasslessJoint {
                    joint: self.joints[i].name.clone(),
                });
            }
            if let Some(p) = self.joints[i].parent {
                let y = self.joints[i].placement.act_inertia(&ycrb[i]);
                ycrb[p] += y;
            }
        }
        Ok(())
    }

    /// Number of degrees of freedom (`nq == nv`).
    #[inline]
    pub fn nv(&self) -> usize {
        self.joints.len()
    }

    /// Joint names in coordinate order.
    pub fn joint_names(&self) -> Vec<String> {
        self.joints.iter().map(|j| j.name.clone()).collect()
    }

    /// Total mass of the moving bodies (Pinocchio's `computeTotalMass`: without
    /// [`Model::world_mass`]).
    pub fn total_mass(&self) -> f64 {
        self.joints.iter().map(|j| j.inertia.mass).sum()
    }

    /// Index of a joint by name.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// Index of a link frame by name.
    pub fn frame_index(&self, name: &str) -> Option<usize> {
        self.frames.iter().position(|f| f.name == name)
    }

    /// Checks that `q` and `v` have `nv` finite entries: the boundary check before calling the
    /// unchecked algorithms.
    pub fn check_state(&self, q: &[f64], v: &[f64]) -> Result<(), crate::PlantError> {
        for (what, x) in [("q", q), ("v", v)] {
            if x.len() != self.nv() {
                return Err(crate::PlantError::WrongDim {
                    what: if what == "q" { "state" } else { "velocity" },
                    expected: self.nv(),
                    got: x.len(),
                });
            }
            if let Some((index, &value)) = x.iter().enumerate().find(|(_, z)| !z.is_finite()) {
                return Err(crate::PlantError::NonFinite {
                    what: "state",
                    index,
                    value,
                });
            }
        }
        Ok(())
    }

    /// Sets one body's mass (scaling its first moment and rotational inertia with it): the
    /// override behind idealized/true model pairs. Returns `false` if `joint` is unknown or the
    /// mass is not positive and finite.
    pub fn scale_body_mass(&mut self, joint: &str, mass: f64) -> bool {
        let Some(i) = self.joint_index(joint) else {
            return false;
        };
        if !(mass.is_finite() && mass > 0.0) {
            return false;
        }
        let y = &mut self.joints[i].inertia;
        if y.mass <= 0.0 {
            return false;
        }
        let s = mass / y.mass;
        y.mass = mass;
        y.h *= s;
        y.ibar *= s;
        true
    }
}

/// The URDF graph during the depth-first traversal.
struct Tree<'a> {
    links: &'a HashMap<&'a str, &'a urdf_rs::Link>,
    children: &'a HashMap<&'a str, BTreeMap<&'a str, &'a urdf_rs::Joint>>,
}

/// A joint waiting on the traversal stack: it hangs from a link carried by `body`, whose frame
/// is `in_body` in that body's frame, `depth` joints below the root.
struct Pending<'a> {
    joint: &'a urdf_rs::Joint,
    body: Option<usize>,
    in_body: Se3,
    depth: usize,
}

impl<'a> Tree<'a> {
    /// Pushes the child joints of `link` so that they pop in alphabetical order.
    fn push_children(
        &self,
        stack: &mut Vec<Pending<'a>>,
        link: &str,
        body: Option<usize>,
        in_body: Se3,
        depth: usize,
    ) {
        if let Some(kids) = self.children.get(link) {
            stack.extend(kids.values().rev().map(|&joint| Pending {
                joint,
                body,
                in_body,
                depth,
            }));
        }
    }

    /// Visits the joints below `root` depth-first, the child joints of a link in alphabetical
    /// order, each subtree before the next sibling (Pinocchio's order), appending joints and
    /// frames to `model`. An explicit stack instead of recursion: a chain of any length cannot
    /// overflow the thread's stack.
    fn visit(&self, model: &mut Model, root: &str) -> Result<(), UrdfError> {
        let mut stack = Vec::new();
        self.push_children(&mut stack, root, None, Se3::identity(), 0);
        while let Some(Pending {
            joint: j,
            body,
            in_body,
            depth,
        }) = stack.pop()
        {
            if depth > self.links.len() {
                return Err(UrdfError::Cycle {
                    link: j.parent.link.clone(),
                });
            }
            let child = self.links[j.child.link.as_str()];
            let xyz = *j.origin.xyz;
            let rpy = *j.origin.rpy;
            if xyz.iter().chain(rpy.iter()).any(|x| !x.is_finite()) {
                return Err(UrdfError::NonFinite {
                    joint: j.name.clone(),
                    what: "origin",
                });
            }
            let origin = in_body.mul(&Se3::from_xyz_rpy(xyz, rpy));
            let inertia = check_inertia(child)?;
            use urdf_rs::JointType as T;
            let kind = match j.joint_type {
                T::Revolute | T::Continuous => Some(JointKind::Revolute),
                T::Prismatic => Some(JointKind::Prismatic),
                _ => None,
            };
            let Some(kind) = kind else {
                // Fixed: merge into the current body.
                match body {
                    Some(b) => model.joints[b].inertia += origin.act_inertia(&inertia),
                    None => model.world_mass += inertia.mass,
                }
                model.frames.push(Frame {
                    name: child.name.clone(),
                    joint: body,
                    placement: origin,
                });
                self.push_children(&mut stack, &child.name, body, origin, depth + 1);
                continue;
            };
            let a = Vector3::from(*j.axis.xyz);
            let n = a.norm();
            if !n.is_finite() || n < 1e-12 {
                return Err(UrdfError::BadAxis {
                    joint: j.name.clone(),
                    axis: *j.axis.xyz,
                });
            }
            let continuous = j.joint_type == T::Continuous;
            let lim = &j.limit;
            if !continuous && (lim.lower.is_nan() || lim.upper.is_nan()) {
                return Err(UrdfError::NonFinite {
                    joint: j.name.clone(),
                    what: "limit",
                });
            }
            let nz = |x: f64| if x > 0.0 { x } else { f64::INFINITY };
            let (damping, friction) = j
                .dynamics
                .as_ref()
                .map(|d| (d.damping, d.friction))
                .unwrap_or((0.0, 0.0));
            let idx = model.joints.len();
            model.joints.push(JointModel {
                name: j.name.clone(),
                child_link: child.name.clone(),
                kind,
                axis: a / n,
                parent: body,
                placement: origin,
                inertia,
                lower: if continuous {
                    f64::NEG_INFINITY
                } else {
                    lim.lower
                },
                upper: if continuous { f64::INFINITY } else { lim.upper },
                effort: nz(lim.effort),
                velocity: nz(lim.velocity),
                damping,
                friction,
                armature: 0.0,
                aligned: [1.0, -1.0].into_iter().find_map(|sign| {
                    (0..3)
                        .find(|&k| a / n == Vector3::ith(k, sign))
                        .map(|k| (k, sign))
                }),
            });
            model.frames.push(Frame {
                name: child.name.clone(),
                joint: Some(idx),
                placement: Se3::identity(),
            });
            self.push_children(
                &mut stack,
                &child.name,
                Some(idx),
                Se3::identity(),
                depth + 1,
            );
        }
        Ok(())
    }
}
