//! Kidnap trials: does the agent notice that it was carried away, say so, and find itself again?
//!
//! Each trial is one closed-loop run of [`crate::table`] on the kidnap scenario (the Nav2 depot
//! map with unmapped furniture and a person, `eval/scenarios/kidnap_depot.yaml`): the robot
//! drives its loop of goals with the dynamic window; at `kidnap_at_s` the simulator carries it
//! `distance_m` away in a seeded random direction and turns it to a random heading, without
//! the odometry or the agent knowing (the simulator's [`sim::World::carry_robot`]). Then, from
//! the agent's own outputs only, the trial measures:
//! - when the agent first reported lost localization (its decision's stop reason), and
//! - when the published pose re-converged: the first cycle from which it stays within
//!   `converged_position_m` and `converged_yaw_deg` of the truth to the end of the trial.
//!
//! A trial recovers when both happened, the re-convergence within `within_s` of the kidnap,
//! and no human intervention (which tells the agent its pose) came between.

use std::path::Path;

use map_core::{CellClass, DistanceField, OccupancyGrid, Sources};
use protocol::{normalize_angle, ControllerKind, Pose2D, StopReason};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use sim::{Command, Scenario};

use crate::table::run::{Cycle, CycleObserver, CycleOutcome};
use crate::table::{self, Prepared, TableError, TableOptions};

/// The kidnap scenario (its floor plan is given separately).
pub const SCENARIO_YAML: &str = include_str!("../scenarios/kidnap_depot.yaml");

/// Settings of the trials.
#[derive(Debug, Clone)]
pub struct KidnapOptions {
    pub trials: u64,
    /// Trial `k` (from 0) runs with seed `first_seed + k`.
    pub first_seed: u64,
    /// Simulated time of the kidnap.
    pub kidnap_at_s: f64,
    /// How far the robot is carried.
    pub distance_m: f64,
    /// The trial ends this long after the kidnap.
    pub after_s: f64,
    /// Re-converged: within these of the truth from some cycle to the end of the trial...
    pub converged_position_m: f64,
    pub converged_yaw_deg: f64,
    /// ...and from a cycle no later than this after the kidnap.
    pub within_s: f64,
    /// The closed loop's settings (agent configuration, ...).
    pub run: TableOptions,
}

impl Default for KidnapOptions {
    fn default() -> Self {
        Self {
            trials: 10,
            first_seed: 1,
            kidnap_at_s: 15.0,
            distance_m: 5.0,
            after_s: 30.0,
            converged_position_m: 0.25,
            converged_yaw_deg: 5.0,
            within_s: 10.0,
            run: TableOptions {
                // The judge must not carry the robot because a relocalizing robot makes no
                // progress: that would tell the agent its pose.
                stuck_timeout_s: 60.0,
                audit_intentions: false,
                ..TableOptions::default()
            },
        }
    }
}

/// What one trial measured.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct KidnapTrial {
    pub seed: u64,
    /// Where the robot was and where it was put (true poses); `None` if no free spot was found.
    pub from: Option<Pose2D>,
    pub to: Option<Pose2D>,
    /// Seconds from the kidnap until the agent first reported lost localization.
    pub lost_reported_after_s: Option<f64>,
    /// Seconds from the kidnap until the published pose re-converged for good.
    pub reconverged_after_s: Option<f64>,
    /// Largest position error in the last 5 s of the trial.
    pub final_position_error_m: f64,
    /// Interventions after the kidnap (each re-initialises AMCL at the truth).
    pub interventions_after_kidnap: u32,
    pub goals_reached: usize,
    pub recovered: bool,
}

/// All trials.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct KidnapReport {
    pub trials: Vec<KidnapTrial>,
    pub recovered: usize,
    pub within_s: f64,
    pub distance_m: f64,
}

/// One cycle as the trial saw it.
#[derive(Debug, Clone, Copy)]
struct Sample {
    t_s: f64,
    position_error_m: f64,
    yaw_error_deg: f64,
    lost: bool,
}

struct Kidnapper<'a> {
    options: &'a KidnapOptions,
    clearance: &'a DistanceField,
    plan: &'a OccupancyGrid,
    rng: ChaCha8Rng,
    kidnap: Option<(f64, Pose2D, Option<Pose2D>)>,
    samples: Vec<Sample>,
}

impl Kidnapper<'_> {
    /// A pose `distance_m` from `from` in a random direction, at least 0.5 m from the plan's
    /// walls, that the world accepts (nothing unmapped there either).
    fn carry(&mut self, world: &mut sim::World, from: Pose2D) -> Option<Pose2D> {
        for _ in 0..500 {
            let bearing = self
                .rng
                .gen_range(-std::f64::consts::PI..std::f64::consts::PI);
            let x = from.x_m + self.options.distance_m * bearing.cos();
            let y = from.y_m + self.options.distance_m * bearing.sin();
            let (cx, cy) = self.plan.world_to_cell(x, y);
            if self.plan.class_at(cx, cy) != CellClass::Free
                || f64::from(self.clearance.at(cx, cy)) < 0.5
            {
                continue;
            }
            let yaw = self
                .rng
                .gen_range(-std::f64::consts::PI..std::f64::consts::PI);
            let to = Pose2D::new(x, y, yaw);
            if world.carry_robot(0, to).is_ok() {
                return Some(to);
            }
        }
        None
    }
}

impl CycleObserver for Kidnapper<'_> {
    fn on_cycle(&mut self, cycle: Cycle<'_>) -> Result<CycleOutcome, TableError> {
        let lost = matches!(
            cycle.decision.stop_reason,
            Some(StopReason::LocalizationLost { .. })
        );
        if let Some(estimate) = cycle.estimate_pose {
            self.samples.push(Sample {
                t_s: cycle.t_s,
                position_error_m: estimate.distance_m(&cycle.truth_pose),
                yaw_error_deg: normalize_angle(estimate.yaw_rad - cycle.truth_pose.yaw_rad)
                    .abs()
                    .to_degrees(),
                lost,
            });
        }
        tracing::debug!(
            t_s = cycle.t_s,
            estimate = ?cycle.estimate_pose,
            truth = ?cycle.truth_pose,
            state = ?cycle.decision.state,
            "kidnap trial cycle"
        );
        let mut cmd = Command {
            v_mps: cycle.decision.cmd_v_mps,
            omega_radps: cycle.decision.cmd_omega_radps,
        };
        if self.kidnap.is_none() && cycle.t_s >= self.options.kidnap_at_s {
            let to = self.carry(cycle.world, cycle.truth_pose);
            self.kidnap = Some((cycle.t_s, cycle.truth_pose, to));
            if to.is_some() {
                // Carried: the wheels stand still when it is put down.
                cmd = Command::default();
            }
        }
        let stop = self
            .kidnap
            .is_some_and(|(t, _, _)| cycle.t_s >= t + self.options.after_s);
        Ok(CycleOutcome { cmd, stop })
    }
}

/// The kidnap scenario on the floor plan at `plan_path`.
///
/// # Errors
/// [`TableError::Scenario`] naming the file when the plan cannot be loaded.
pub fn prepare(plan_path: &Path, options: &TableOptions) -> Result<Prepared, TableError> {
    let name = Path::new("eval/scenarios/kidnap_depot.yaml");
    let scenario = Scenario::from_yaml(SCENARIO_YAML, name).map_err(|e| TableError::Scenario {
        path: name.display().to_string(),
        reason: e.to_string(),
    })?;
    let plan = map_core::load_ros_map(plan_path, &map_core::ImportLimits::default())
        .map_err(|e| TableError::Scenario {
            path: plan_path.display().to_string(),
            reason: e.to_string(),
        })?
        .grid;
    Prepared::new(name, scenario, plan, options)
}

/// Runs one trial with `seed`.
///
/// # Errors
/// [`TableError`] when a run cannot be set up.
pub fn trial(
    prepared: &Prepared,
    clearance: &DistanceField,
    seed: u64,
    options: &KidnapOptions,
) -> Result<KidnapTrial, TableError> {
    let mut kidnapper = Kidnapper {
        options,
        clearance,
        plan: &prepared.plan,
        rng: ChaCha8Rng::seed_from_u64(seed ^ 0x6b69_646e_6170),
        kidnap: None,
        samples: Vec::new(),
    };
    let (result, _) = table::run::run_with(
        prepared,
        ControllerKind::DynamicWindow,
        seed,
        &options.run,
        |_| {},
        Some(&mut kidnapper),
    )?;
    let Some((kidnap_s, from, to)) = kidnapper.kidnap else {
        return Ok(KidnapTrial {
            seed,
            from: None,
            to: None,
            lost_reported_after_s: None,
            reconverged_after_s: None,
            final_position_error_m: f64::NAN,
            interventions_after_kidnap: 0,
            goals_reached: result.goals_reached,
            recovered: false,
        });
    };
    let after: Vec<Sample> = kidnapper
        .samples
        .iter()
        .copied()
        .filter(|s| s.t_s > kidnap_s)
        .collect();
    let lost_reported_after_s = after.iter().find(|s| s.lost).map(|s| s.t_s - kidnap_s);
    let good = |s: &Sample| {
        s.position_error_m <= options.converged_position_m
            && s.yaw_error_deg <= options.converged_yaw_deg
    };
    let reconverged_after_s = match after.iter().rposition(|s| !good(s)) {
        None => after.first().map(|s| s.t_s - kidnap_s),
        Some(i) => after.get(i + 1).map(|s| s.t_s - kidnap_s),
    };
    let end_s = after.last().map_or(kidnap_s, |s| s.t_s);
    let final_position_error_m = after
        .iter()
        .filter(|s| s.t_s >= end_s - 5.0)
        .map(|s| s.position_error_m)
        .fold(0.0, f64::max);
    let interventions_after_kidnap = u32::try_from(
        result
            .intervention_log
            .iter()
            .filter(|e| e.t_s > kidnap_s)
            .count(),
    )
    .unwrap_or(u32::MAX);
    let recovered = to.is_some()
        && lost_reported_after_s.is_some()
        && reconverged_after_s.is_some_and(|t| t <= options.within_s)
        && interventions_after_kidnap == 0;
    Ok(KidnapTrial {
        seed,
        from: Some(from),
        to,
        lost_reported_after_s,
        reconverged_after_s,
        final_position_error_m,
        interventions_after_kidnap,
        goals_reached: result.goals_reached,
        recovered,
    })
}

/// Runs every trial; `progress` gets each finished trial.
///
/// # Errors
/// [`TableError`] when the scenario or a run cannot be set up.
pub fn run(
    plan_path: &Path,
    options: &KidnapOptions,
    mut progress: impl FnMut(&KidnapTrial),
) -> Result<KidnapReport, TableError> {
    options.run.validate(&[ControllerKind::DynamicWindow])?;
    for (field, v) in [
        ("kidnap_at_s", options.kidnap_at_s),
        ("distance_m", options.distance_m),
        ("after_s", options.after_s),
        ("within_s", options.within_s),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(TableError::Invalid {
                field,
                value: v.to_string(),
                reason: "must be a positive, finite number".into(),
            });
        }
    }
    let prepared = prepare(plan_path, &options.run)?;
    let clearance = DistanceField::compute(&prepared.plan, Sources::Occupied);
    let mut trials = Vec::new();
    for k in 0..options.trials {
        let t = trial(&prepared, &clearance, options.first_seed + k, options)?;
        progress(&t);
        trials.push(t);
    }
    Ok(KidnapReport {
        recovered: trials.iter().filter(|t| t.recovered).count(),
        trials,
        within_s: options.within_s,
        distance_m: options.distance_m,
    })
}

/// A markdown table of the trials.
#[must_use]
pub fn markdown(report: &KidnapReport) -> String {
    let opt = |v: Option<f64>| v.map_or_else(|| "never".to_string(), |s| format!("{s:.1}"));
    let mut out = String::from(
        "| seed | carried from | to | lost reported after (s) | re-converged after (s) | final error (m) | interventions | recovered |\n|---|---|---|---|---|---|---|---|\n",
    );
    for t in &report.trials {
        let pose = |p: Option<Pose2D>| {
            p.map_or_else(
                || "-".to_string(),
                |p| format!("({:.1}, {:.1})", p.x_m, p.y_m),
            )
        };
        out.push_str(&format!(
            "| {} | {} | {} | {} | {} | {:.2} | {} | {} |\n",
            t.seed,
            pose(t.from),
            pose(t.to),
            opt(t.lost_reported_after_s),
            opt(t.reconverged_after_s),
            t.final_position_error_m,
            t.interventions_after_kidnap,
            if t.recovered { "yes" } else { "NO" },
        ));
    }
    out.push_str(&format!(
        "\n{}/{} trials re-converged within {:.0} s of a {:.0} m kidnap, reporting lost localization meanwhile.\n",
        report.recovered,
        report.trials.len(),
        report.within_s,
        report.distance_m
    ));
    out
}
