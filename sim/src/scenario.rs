//! The scenario file: what the planner gets (a crude floor plan) and what the world really holds.
//!
//! A scenario is YAML (see `sim/scenarios/README.md` and `sim/scenarios/example.yaml`), checked
//! twice: structurally by serde (`deny_unknown_fields`, types) and by the JSON Schema committed as
//! `sim/scenario.schema.json` (generated from these structs with `schemars`), then semantically by
//! [`Scenario::validate`], whose errors name the field path and the offending value.

use std::path::{Path, PathBuf};

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Why a scenario could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    #[error("cannot read scenario {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot parse scenario {path}: {reason}")]
    Parse { path: PathBuf, reason: String },
    #[error("invalid scenario field {field} = {value}: {reason}")]
    Invalid {
        field: String,
        value: String,
        reason: String,
    },
    #[error("cannot load floor plan {path}: {source}")]
    Map {
        path: PathBuf,
        #[source]
        source: map_core::MapError,
    },
}

impl ScenarioError {
    pub fn invalid(
        field: impl Into<String>,
        value: impl std::fmt::Display,
        reason: impl Into<String>,
    ) -> Self {
        Self::Invalid {
            field: field.into(),
            value: value.to_string(),
            reason: reason.into(),
        }
    }
}

/// An RGB colour, 0..=255 per channel.
pub type Rgb = [u8; 3];

/// A map-frame pose (REP-103: x forward, y left, yaw counter-clockwise).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PoseSpec {
    pub x_m: f64,
    pub y_m: f64,
    #[serde(default)]
    pub yaw_rad: f64,
}

impl PoseSpec {
    pub fn to_pose(self) -> protocol::Pose2D {
        protocol::Pose2D::new(self.x_m, self.y_m, self.yaw_rad)
    }
}

/// A map-frame point.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PointSpec {
    pub x_m: f64,
    pub y_m: f64,
}

/// Procedural wall surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum WallTexture {
    #[default]
    Plain,
    Bricks,
    Panels,
    Wainscot,
    Tiles,
    Concrete,
}

/// Procedural floor surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum FloorTexture {
    #[default]
    Tiles,
    Plain,
    Planks,
    Carpet,
}

fn default_wall_color() -> Rgb {
    [200, 196, 186]
}
fn default_floor_color() -> Rgb {
    [150, 140, 125]
}
fn default_ceiling_color() -> Rgb {
    [225, 225, 220]
}
fn default_light() -> f64 {
    1.0
}

/// How the walls, floor and ceiling of an area look.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Look {
    #[serde(default = "default_wall_color")]
    pub wall_color: Rgb,
    #[serde(default)]
    pub wall_texture: WallTexture,
    #[serde(default = "default_floor_color")]
    pub floor_color: Rgb,
    #[serde(default)]
    pub floor_texture: FloorTexture,
    #[serde(default = "default_ceiling_color")]
    pub ceiling_color: Rgb,
    /// Brightness multiplier of the area's lighting, 0.2..=2.0.
    #[serde(default = "default_light")]
    #[schemars(range(min = 0.2, max = 2.0))]
    pub light: f64,
}

impl Default for Look {
    fn default() -> Self {
        Self {
            wall_color: default_wall_color(),
            wall_texture: WallTexture::default(),
            floor_color: default_floor_color(),
            floor_texture: FloorTexture::default(),
            ceiling_color: default_ceiling_color(),
            light: default_light(),
        }
    }
}

/// An axis-aligned map region with its own look; later areas win where areas overlap.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AreaSpec {
    pub name: String,
    pub min_x_m: f64,
    pub min_y_m: f64,
    pub max_x_m: f64,
    pub max_y_m: f64,
    pub look: Look,
}

/// Appearance of the building: a default look plus per-area overrides.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AppearanceSpec {
    #[serde(default)]
    pub default: Look,
    #[serde(default)]
    pub areas: Vec<AreaSpec>,
}

fn default_box_height() -> f64 {
    0.8
}
fn default_box_color() -> Rgb {
    [140, 95, 55]
}

/// Unmapped furniture: an upright box, possibly rotated.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BoxSpec {
    /// Centre.
    pub x_m: f64,
    pub y_m: f64,
    #[schemars(range(min = 0.0))]
    pub size_x_m: f64,
    #[schemars(range(min = 0.0))]
    pub size_y_m: f64,
    #[serde(default)]
    pub yaw_rad: f64,
    #[serde(default = "default_box_height")]
    #[schemars(range(min = 0.0))]
    pub height_m: f64,
    #[serde(default = "default_box_color")]
    pub color: Rgb,
}

impl BoxSpec {
    /// The box as the world holds it.
    pub fn shape(&self) -> crate::geom::Obb {
        crate::geom::Obb::new(
            self.x_m,
            self.y_m,
            self.size_x_m,
            self.size_y_m,
            self.yaw_rad,
        )
    }
}

fn default_glass_thickness() -> f64 {
    0.04
}
fn default_frame_color() -> Rgb {
    [90, 90, 95]
}
fn default_glass_tint() -> Rgb {
    [170, 215, 225]
}

/// A glass wall or door: a thin pane from (x0, y0) to (x1, y1), floor to ceiling, with frames.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GlassSpec {
    pub x0_m: f64,
    pub y0_m: f64,
    pub x1_m: f64,
    pub y1_m: f64,
    #[serde(default = "default_glass_thickness")]
    #[schemars(range(min = 0.0))]
    pub thickness_m: f64,
    #[serde(default = "default_frame_color")]
    pub frame_color: Rgb,
    #[serde(default = "default_glass_tint")]
    pub tint: Rgb,
}

impl GlassSpec {
    /// The pane as the world holds it.
    pub fn shape(&self) -> crate::geom::Obb {
        crate::geom::Obb::from_segment(self.x0_m, self.y0_m, self.x1_m, self.y1_m, self.thickness_m)
    }
}

/// How a person walks their route.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum RouteMode {
    /// Back and forth along the route.
    #[default]
    PingPong,
    /// From the last point back to the first and round again.
    Loop,
}

fn default_person_radius() -> f64 {
    0.25
}
fn default_shirt() -> Rgb {
    [40, 80, 160]
}
fn default_pants() -> Rgb {
    [45, 45, 55]
}

/// A person walking a polyline route at a constant speed (waiting while a robot is in the way).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PersonSpec {
    #[schemars(length(min = 1))]
    pub route: Vec<PointSpec>,
    #[schemars(range(min = 0.0, max = 2.5))]
    pub speed_mps: f64,
    #[serde(default)]
    pub mode: RouteMode,
    #[serde(default = "default_person_radius")]
    #[schemars(range(min = 0.05, max = 0.6))]
    pub radius_m: f64,
    #[serde(default = "default_shirt")]
    pub shirt_color: Rgb,
    #[serde(default = "default_pants")]
    pub pants_color: Rgb,
}

/// A whole scenario file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Short identifier, e.g. `task_a`.
    #[schemars(length(min = 1))]
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// Whether the scenario is for training (demonstrations), evaluation (tasks A–E) or a
    /// behaviour check (§4.2: people, glass doors).
    pub role: Role,
    /// ROS map YAML of the crude floor plan, relative to the scenario file.
    pub floor_plan: String,
    /// Seeds every random source of the world (sensor noise, appearance variation).
    pub seed: u64,
    #[schemars(range(min = 0.0))]
    pub time_limit_s: f64,
    pub start: PoseSpec,
    #[schemars(length(min = 1))]
    pub goals: Vec<PointSpec>,
    #[serde(default)]
    pub appearance: AppearanceSpec,
    /// Unmapped furniture.
    #[serde(default)]
    pub furniture: Vec<BoxSpec>,
    #[serde(default)]
    pub glass: Vec<GlassSpec>,
    #[serde(default)]
    pub people: Vec<PersonSpec>,
    /// Other robots standing still (a robot that finished its task where it stopped): the
    /// simulator adds them after the robots it drives, and nobody commands them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub parked_robots: Vec<PoseSpec>,
    /// What a right run does with the goals, so a harness can judge it. `true` (the default):
    /// it reaches every goal in order. `false`: the way to the goals is closed in the ground truth
    /// (e.g. by an unmapped glass door) though open on the plan, and a right run reaches none of
    /// them: it stops short of the obstacle, touches nothing and ends at the time limit.
    #[serde(default = "default_true", skip_serializing_if = "is_true")]
    pub expect_goals_reached: bool,
}

fn default_true() -> bool {
    true
}

// serde's `skip_serializing_if` passes a reference.
#[allow(clippy::trivially_copy_pass_by_ref)]
fn is_true(v: &bool) -> bool {
    *v
}

/// What a scenario is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    Training,
    Evaluation,
    /// One situation of the paper's §4.2 (a person ahead or oncoming, a glass door) whose right
    /// response `expect_goals_reached` and the absence of contact define.
    Behaviour,
}

fn check_finite(field: &str, v: f64) -> Result<(), ScenarioError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(ScenarioError::invalid(field, v, "must be a finite number"))
    }
}

fn check_range(field: &str, v: f64, lo: f64, hi: f64, reason: &str) -> Result<(), ScenarioError> {
    if v.is_finite() && v >= lo && v <= hi {
        Ok(())
    } else {
        Err(ScenarioError::invalid(field, v, reason))
    }
}

fn check_positive(field: &str, v: f64) -> Result<(), ScenarioError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(ScenarioError::invalid(
            field,
            v,
            "must be a positive finite number",
        ))
    }
}

impl Scenario {
    /// Parses YAML text; `path` is only used in messages.
    ///
    /// # Errors
    /// [`ScenarioError::Parse`] with serde's message (which names unknown or missing fields), or
    /// [`ScenarioError::Invalid`] from [`Scenario::validate`].
    pub fn from_yaml(text: &str, path: &Path) -> Result<Self, ScenarioError> {
        let scenario: Scenario = serde_yaml::from_str(text).map_err(|e| ScenarioError::Parse {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        scenario.validate()?;
        Ok(scenario)
    }

    /// Reads and validates a scenario file (the floor plan is loaded by [`crate::World`]).
    ///
    /// # Errors
    /// As [`Scenario::from_yaml`], plus [`ScenarioError::Io`].
    pub fn load(path: &Path) -> Result<Self, ScenarioError> {
        let text = std::fs::read_to_string(path).map_err(|source| ScenarioError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_yaml(&text, path)
    }

    /// The floor-plan YAML path resolved against the scenario file's folder.
    pub fn floor_plan_path(&self, scenario_path: &Path) -> PathBuf {
        scenario_path
            .parent()
            .unwrap_or_else(|| Path::new("."))
            .join(&self.floor_plan)
    }

    /// Checks every value the types cannot: finiteness, positive sizes, ranges, non-empty lists.
    ///
    /// # Errors
    /// [`ScenarioError::Invalid`] naming the field path (e.g. `furniture[2].size_x_m`) and value.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        if self.name.trim().is_empty() {
            return Err(ScenarioError::invalid("name", "\"\"", "must not be empty"));
        }
        if self.floor_plan.trim().is_empty() {
            return Err(ScenarioError::invalid(
                "floor_plan",
                "\"\"",
                "must name a ROS map YAML",
            ));
        }
        check_positive("time_limit_s", self.time_limit_s)?;
        check_finite("start.x_m", self.start.x_m)?;
        check_finite("start.y_m", self.start.y_m)?;
        check_finite("start.yaw_rad", self.start.yaw_rad)?;
        if self.goals.is_empty() {
            return Err(ScenarioError::invalid(
                "goals",
                "[]",
                "need at least one goal",
            ));
        }
        for (i, g) in self.goals.iter().enumerate() {
            check_finite(&format!("goals[{i}].x_m"), g.x_m)?;
            check_finite(&format!("goals[{i}].y_m"), g.y_m)?;
        }
        check_look("appearance.default", &self.appearance.default)?;
        for (i, a) in self.appearance.areas.iter().enumerate() {
            let f = format!("appearance.areas[{i}]");
            for (name, v) in [
                ("min_x_m", a.min_x_m),
                ("min_y_m", a.min_y_m),
                ("max_x_m", a.max_x_m),
                ("max_y_m", a.max_y_m),
            ] {
                check_finite(&format!("{f}.{name}"), v)?;
            }
            if a.max_x_m <= a.min_x_m {
                return Err(ScenarioError::invalid(
                    format!("{f}.max_x_m"),
                    a.max_x_m,
                    format!("must exceed min_x_m = {}", a.min_x_m),
                ));
            }
            if a.max_y_m <= a.min_y_m {
                return Err(ScenarioError::invalid(
                    format!("{f}.max_y_m"),
                    a.max_y_m,
                    format!("must exceed min_y_m = {}", a.min_y_m),
                ));
            }
            check_look(&format!("{f}.look"), &a.look)?;
        }
        for (i, b) in self.furniture.iter().enumerate() {
            let f = format!("furniture[{i}]");
            check_finite(&format!("{f}.x_m"), b.x_m)?;
            check_finite(&format!("{f}.y_m"), b.y_m)?;
            check_finite(&format!("{f}.yaw_rad"), b.yaw_rad)?;
            check_positive(&format!("{f}.size_x_m"), b.size_x_m)?;
            check_positive(&format!("{f}.size_y_m"), b.size_y_m)?;
            check_positive(&format!("{f}.height_m"), b.height_m)?;
        }
        for (i, g) in self.glass.iter().enumerate() {
            let f = format!("glass[{i}]");
            for (name, v) in [
                ("x0_m", g.x0_m),
                ("y0_m", g.y0_m),
                ("x1_m", g.x1_m),
                ("y1_m", g.y1_m),
            ] {
                check_finite(&format!("{f}.{name}"), v)?;
            }
            check_positive(&format!("{f}.thickness_m"), g.thickness_m)?;
            let len = (g.x1_m - g.x0_m).hypot(g.y1_m - g.y0_m);
            if len < 0.1 {
                return Err(ScenarioError::invalid(
                    format!("{f}.x1_m"),
                    g.x1_m,
                    format!("pane is {len:.3} m long; need at least 0.1 m"),
                ));
            }
        }
        for (i, r) in self.parked_robots.iter().enumerate() {
            check_finite(&format!("parked_robots[{i}].x_m"), r.x_m)?;
            check_finite(&format!("parked_robots[{i}].y_m"), r.y_m)?;
            check_finite(&format!("parked_robots[{i}].yaw_rad"), r.yaw_rad)?;
        }
        for (i, p) in self.people.iter().enumerate() {
            let f = format!("people[{i}]");
            if p.route.is_empty() {
                return Err(ScenarioError::invalid(
                    format!("{f}.route"),
                    "[]",
                    "need at least one point",
                ));
            }
            for (j, q) in p.route.iter().enumerate() {
                check_finite(&format!("{f}.route[{j}].x_m"), q.x_m)?;
                check_finite(&format!("{f}.route[{j}].y_m"), q.y_m)?;
            }
            check_range(
                &format!("{f}.speed_mps"),
                p.speed_mps,
                0.0,
                2.5,
                "must lie in [0, 2.5]",
            )?;
            check_range(
                &format!("{f}.radius_m"),
                p.radius_m,
                0.05,
                0.6,
                "must lie in [0.05, 0.6]",
            )?;
        }
        Ok(())
    }
}

fn check_look(field: &str, look: &Look) -> Result<(), ScenarioError> {
    check_range(
        &format!("{field}.light"),
        look.light,
        0.2,
        2.0,
        "must lie in [0.2, 2.0]",
    )
}

/// The JSON Schema of [`Scenario`], as committed in `sim/scenario.schema.json`.
pub fn json_schema() -> String {
    let schema = schemars::schema_for!(Scenario);
    // A Schema is a serde_json::Value inside; serializing it cannot fail.
    let mut text = serde_json::to_string_pretty(&schema).unwrap_or_default();
    text.push('\n');
    text
}
