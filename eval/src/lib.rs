//! Evaluation: closed-loop runs of simulator, agent and planner (the paper's Table 1).
//!
//! - [`metrics`]: the metrics of Table 1.
//! - [`amcl_accuracy`]: AMCL against the simulator's ground truth on tasks A–E, in lock-step.
//! - [`kidnap`]: kidnap trials on the depot map: lost localization reported, re-convergence.
//! - [`expert`]: the privileged expert (method `expert`) that reads the ground truth and
//!   demonstrates for imitation.
//! - [`record`]: demonstrations of the expert on the training scenarios, recorded as an
//!   imitation-learning dataset (`eval record`, `training/DATASET.md`).
//! - [`figure`]: pictures of runs like the paper's Figure 5 (plan, planned path, traces).
//! - [`cli`]: the `eval` command line.

pub mod amcl_accuracy;
pub mod cli;
pub mod expert;
pub mod figure;
pub mod kidnap;
pub mod metrics;
pub mod record;
pub mod table;
