//! Evaluation: closed-loop runs of simulator, agent and planner (the paper's Table 1).
//!
//! Today it holds the metrics of Table 1 ([`metrics`]); the lock-step harness, the
//! demonstration recorder and the trajectory plots come with the robot-agent work.

pub mod metrics;
