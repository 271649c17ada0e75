//! Evaluation: closed-loop runs of simulator, agent and planner (the paper's Table 1).
//!
//! - [`metrics`]: the metrics of Table 1.
//! - [`amcl_accuracy`]: AMCL against the simulator's ground truth on tasks A–E, in lock-step.
//! - [`cli`]: the `eval` command line.

pub mod amcl_accuracy;
pub mod cli;
pub mod metrics;
