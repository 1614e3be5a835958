//! The scene file exactly as written: serde structs that reject unknown keys and wrong
//! types, nothing more. Every value the scene must check (ranges, finiteness, required
//! keys) is an `Option` here so that [`super::build`] can name the key when it is missing.

use std::collections::BTreeMap;

use serde::Deserialize;

/// The whole file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawScene {
    pub name: Option<String>,
    pub description: Option<String>,
    pub gravity: Option<Vec<f64>>,
    pub planar: Option<String>,
    #[serde(default)]
    pub material: BTreeMap<String, RawMaterial>,
    #[serde(default)]
    pub section: BTreeMap<String, RawSection>,
    #[serde(default)]
    pub rod: Vec<RawRod>,
    #[serde(default)]
    pub clamp: Vec<RawSupport>,
    #[serde(default)]
    pub pin: Vec<RawSupport>,
    #[serde(default)]
    pub point_mass: Vec<RawPointMass>,
    #[serde(default)]
    pub load: Vec<RawLoad>,
    #[serde(default)]
    pub line_load: Vec<RawLineLoad>,
    #[serde(default)]
    pub link: Vec<RawLink>,
    #[serde(default)]
    pub initial_velocity: Vec<RawInitialVelocity>,
    #[serde(default)]
    pub probe: Vec<RawProbe>,
    #[serde(default)]
    pub obstacle: Vec<RawObstacle>,
    #[serde(default)]
    pub contact: Vec<RawContact>,
    pub integrator: Option<RawIntegrator>,
}

/// `[[contact]]`: contact between two rods, or of one rod with itself.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawContact {
    pub rods: Option<Vec<String>>,
    pub stiffness: Option<f64>,
    pub contact_radius: Option<f64>,
    pub friction: Option<f64>,
    pub slip: Option<f64>,
    pub model: Option<String>,
    pub points_per_radius: Option<i64>,
}

/// `[[obstacle]]`: a rigid plane, sphere or cylinder the rods' nodes can touch.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawObstacle {
    pub kind: Option<String>,
    pub point: Option<Vec<f64>>,
    pub normal: Option<Vec<f64>>,
    pub center: Option<Vec<f64>>,
    pub axis: Option<Vec<f64>>,
    pub radius: Option<f64>,
    pub stiffness: Option<f64>,
    pub friction: Option<f64>,
    pub slip: Option<f64>,
    pub friction_law: Option<String>,
    pub tangential_stiffness: Option<f64>,
    pub rods: Option<Vec<String>>,
    pub contact_radius: Option<f64>,
    pub displacement: Option<Vec<f64>>,
    pub time: Option<Vec<f64>>,
    pub factor: Option<Vec<f64>>,
    pub ramp: Option<String>,
}

/// `[[probe]]`: a node whose state goes to `probes.csv` every step.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawProbe {
    pub name: Option<String>,
    pub at: Option<Vec<f64>>,
    pub rod: Option<String>,
    pub node: Option<i64>,
    pub s: Option<f64>,
}

/// `[material.NAME]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMaterial {
    #[serde(rename = "E")]
    pub e: Option<f64>,
    pub nu: Option<f64>,
    #[serde(rename = "G")]
    pub g: Option<f64>,
    pub density: Option<f64>,
    pub damping: Option<f64>,
}

/// `[section.NAME]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSection {
    #[serde(rename = "A")]
    pub a: Option<f64>,
    #[serde(rename = "I11")]
    pub i11: Option<f64>,
    #[serde(rename = "I22")]
    pub i22: Option<f64>,
    #[serde(rename = "I12")]
    pub i12: Option<f64>,
    #[serde(rename = "J")]
    pub j: Option<f64>,
    pub shear_factor: Option<f64>,
    #[serde(rename = "A1")]
    pub a1: Option<f64>,
    #[serde(rename = "A2")]
    pub a2: Option<f64>,
    pub rho_inertia: Option<Vec<Vec<f64>>>,
}

/// `[[rod]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRod {
    pub name: Option<String>,
    pub material: Option<String>,
    pub section: Option<String>,
    pub points: Option<Vec<Vec<f64>>>,
    /// An integer or an array of integers; checked by hand for a clearer message.
    pub elements: Option<toml::Value>,
    pub d1: Option<Vec<f64>>,
    pub curvature: Option<Vec<f64>>,
    pub curvature_measure: Option<String>,
    pub drag: Option<f64>,
    pub initial: Option<RawInitialShape>,
}

/// `[rod.initial]`: the rod's initial configuration apart from its reference shape.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawInitialShape {
    pub positions: Option<Vec<Vec<f64>>>,
    pub rotations: Option<Vec<Vec<f64>>>,
    pub stretch: Option<f64>,
    pub origin: Option<Vec<f64>>,
    pub displacement: Option<Vec<Vec<f64>>>,
    pub rotation: Option<Vec<f64>>,
    pub center: Option<Vec<f64>>,
    pub translation: Option<Vec<f64>>,
}

/// `[[clamp]]` and `[[pin]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSupport {
    pub at: Option<Vec<f64>>,
    pub displacement: Option<Vec<f64>>,
    pub rotation: Option<Vec<f64>>,
    pub time: Option<Vec<f64>>,
    pub factor: Option<Vec<f64>>,
    pub ramp: Option<String>,
    pub slide: Option<Vec<f64>>,
    pub spin: Option<bool>,
}

/// `[[point_mass]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawPointMass {
    pub at: Option<Vec<f64>>,
    pub mass: Option<f64>,
}

/// `[[load]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawLoad {
    pub at: Option<Vec<f64>>,
    pub force: Option<Vec<f64>>,
    pub moment: Option<Vec<f64>>,
    pub time: Option<Vec<f64>>,
    pub factor: Option<Vec<f64>>,
}

/// `[[line_load]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawLineLoad {
    pub rod: Option<String>,
    pub segment: Option<i64>,
    pub force: Option<Vec<f64>>,
    pub moment: Option<Vec<f64>>,
    pub follower: Option<bool>,
    pub time: Option<Vec<f64>>,
    pub factor: Option<Vec<f64>>,
}

/// `[[link]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawLink {
    pub pivot: Option<Vec<f64>>,
    pub at: Option<Vec<f64>>,
    pub penalty: Option<f64>,
    pub tol: Option<f64>,
}

/// `[[initial_velocity]]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawInitialVelocity {
    pub at: Option<Vec<f64>>,
    pub all: Option<bool>,
    pub rod: Option<String>,
    pub segment: Option<i64>,
    pub v_nodes: Option<Vec<Vec<f64>>>,
    pub omega_nodes: Option<Vec<Vec<f64>>>,
    pub center: Option<Vec<f64>>,
    pub v: Option<Vec<f64>>,
    pub omega: Option<Vec<f64>>,
}

/// `[integrator]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawIntegrator {
    pub scheme: Option<String>,
    pub dt: Option<f64>,
    pub t_end: Option<f64>,
    pub alpha: Option<f64>,
    pub alpha_gv: Option<f64>,
    pub alpha_gn: Option<f64>,
    pub alpha_ov: Option<f64>,
    pub alpha_on: Option<f64>,
    pub chi_gamma: Option<f64>,
    pub chi_omega: Option<f64>,
    pub chi_v: Option<f64>,
    pub chi_nu: Option<f64>,
    pub rho_inf: Option<f64>,
    pub strategy: Option<String>,
    pub fallback: Option<bool>,
    pub cutback: Option<i64>,
    pub newton: Option<String>,
    pub newton_tol: Option<f64>,
    pub max_iter: Option<i64>,
    pub outer_tol: Option<f64>,
    pub max_outer: Option<i64>,
    pub energy_tol: Option<f64>,
    pub max_link_rounds: Option<i64>,
    pub output_every: Option<i64>,
}
