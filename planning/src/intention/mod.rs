//! Intentions (paper §3.1, DESIGN.md §4): what the planner expects the controller to do next.
//!
//! - [`dlm`]: the discretized local move from the signed curvature of the path ahead.
//! - [`lpe`]: the local path and environment image (224 x 224 RGB, heading-up).
//! - [`pipeline`]: pose in, intention out: the one pipeline the service and the evaluation run.
//! - [`reuse`]: when the previous plan answers instead of a new search.
//! - [`avoid`]: plans that keep clear of the fleet's other robots.
//! - [`seen`]: plans that keep clear of what the robot's laser sees and the floor plan lacks.
//! - [`route`]: the floor plan's route to the goal, which the `route` DLM measures.

pub mod avoid;
pub mod dlm;
pub mod lpe;
pub mod pipeline;
pub mod reuse;
pub mod route;
pub mod seen;

pub use avoid::{AvoidParams, Neighbour};
pub use dlm::{
    dlm_from_path, dlm_on_map, is_arriving, next_dlm, next_dlm_along, path_left_m, DlmMeasure,
    DlmParams,
};
pub use lpe::{render_lpe, LpeImage, LpeParams};
pub use pipeline::{
    stop_intention, thin_path, Answer, IntentionConfig, IntentionPlanner, Planned, RefreshJob,
    Refreshed,
};
pub use reuse::{KeptPlan, KeptRest, ReuseParams};
pub use route::floor_plan_route;
pub use seen::SeenObstacleParams;
