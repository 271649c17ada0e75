//! The intention pipeline: a pose estimate in, the intention for a task's goals out. This is
//! the one place that goes "pose → goal advancement → hybrid A* → DLM, LPE, thinned path"; the
//! fleet service's replanning workers, the closed-loop evaluation and every test that needs
//! intentions call [`IntentionPlanner::answer`], so what is evaluated is what drives robots.
//!
//! One [`IntentionPlanner`] serves one robot: it keeps that robot's search state and the trail
//! of poses it answered (the travelled part of the LPE image).

use std::collections::VecDeque;
use std::sync::Arc;

use protocol::{Dlm, Header, Image, ImageEncoding, Intention, Pose2D, PoseEstimate, TaskId};
use serde::{Deserialize, Serialize};

use crate::config::PlannerConfig;
use crate::error::{Endpoint, PlanError};
use crate::goals::{Advance, GoalProgress};
use crate::hybrid_astar::Planner;
use crate::intention::avoid::{path_clear_of, AvoidParams, Neighbour};
use crate::intention::dlm::{dlm_on_map, is_arriving, DlmParams};
use crate::intention::lpe::{render_lpe, LpeImage, LpeParams};
use crate::intention::reuse::{KeptPlan, ReuseParams};
use crate::intention::seen::SeenObstacleParams;
use crate::map::{Disc, PlanningMap};
use crate::path::Path;

/// Everything the pipeline needs besides the map; the service fills it from its `[planner]`,
/// `[dlm]`, `[lpe]` and `[fleet]` tables.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IntentionConfig {
    pub planner: PlannerConfig,
    pub dlm: DlmParams,
    pub lpe: LpeParams,
    /// A goal counts as reached when the pose estimate is this close to it.
    pub goal_tolerance_m: f64,
    /// Spacing of the path sent in an intention (the planner's own is finer); turns in place
    /// are kept whatever the spacing; 0 keeps every pose.
    pub path_spacing_m: f64,
    /// Answered poses kept as the travelled part of the LPE image.
    pub trail_poses: usize,
    /// When the previous plan answers instead of a new search.
    #[serde(default)]
    pub reuse: ReuseParams,
    /// How plans keep clear of the fleet's other robots ([`IntentionPlanner::answer_among`]).
    #[serde(default)]
    pub avoid: AvoidParams,
    /// How plans keep clear of the obstacles the robot reports seeing where the floor plan is
    /// free ([`PoseEstimate::unmapped_obstacles_m`]).
    #[serde(default)]
    pub seen: SeenObstacleParams,
}

impl Default for IntentionConfig {
    fn default() -> Self {
        Self {
            planner: PlannerConfig::default(),
            dlm: DlmParams::default(),
            lpe: LpeParams::default(),
            goal_tolerance_m: 0.35,
            path_spacing_m: 0.2,
            trail_poses: 60,
            reuse: ReuseParams::default(),
            avoid: AvoidParams::default(),
            seen: SeenObstacleParams::default(),
        }
    }
}

/// The pipeline's answer to one pose.
#[derive(Debug, Clone, PartialEq)]
pub enum Answer {
    /// Every goal is reached.
    Done,
    /// Heading for goal `goal_index`: the plan to it, or why there is none from this pose.
    Heading {
        goal_index: usize,
        plan: Result<Planned, PlanError>,
    },
}

/// A plan to the current goal with its intention.
#[derive(Debug, Clone, PartialEq)]
pub struct Planned {
    /// The goal as planned (a free heading resolved).
    pub goal: Pose2D,
    /// The planned path thinned to the configured spacing (what the intention carries).
    pub path: Vec<Pose2D>,
    /// Length of the full planned path.
    pub length_m: f64,
    pub dlm: Dlm,
    /// `dlm` is an arriving `Stop` ([`Intention::arriving`]).
    pub arriving: bool,
    /// Rendered when asked for.
    pub lpe: Option<LpeImage>,
    /// The rest of the previous plan, no new search (see [`ReuseParams`]).
    pub reused: bool,
    /// How many other robots the path keeps clear of (see [`AvoidParams`]): 0 when none was
    /// near or no path round them was found.
    pub avoided_robots: usize,
}

impl Planned {
    /// The intention message answering `pose` (the LPE image travels only when `send_lpe`).
    #[must_use]
    pub fn intention(
        &self,
        header: Header,
        pose: &PoseEstimate,
        task_id: Option<TaskId>,
        goal_index: usize,
        send_lpe: bool,
    ) -> Intention {
        Intention {
            path: self.path.clone(),
            dlm: self.dlm,
            arriving: self.arriving,
            lpe: self.lpe.as_ref().filter(|_| send_lpe).and_then(wire_image),
            ..stop_intention(header, pose, task_id, goal_index)
        }
    }
}

fn wire_image(lpe: &LpeImage) -> Option<Image> {
    // An RGB buffer always matches its own size; `None` would only hide an impossible case.
    Image::new(
        lpe.image.width(),
        lpe.image.height(),
        ImageEncoding::Rgb8,
        lpe.image.as_raw().clone(),
    )
    .ok()
}

/// A `Stop` intention answering `pose`: no task, the task ended, or no plan.
#[must_use]
pub fn stop_intention(
    header: Header,
    pose: &PoseEstimate,
    task_id: Option<TaskId>,
    goal_index: usize,
) -> Intention {
    Intention {
        header,
        task_id,
        goal_index: u32::try_from(goal_index).unwrap_or(u32::MAX),
        answers_pose_seq: pose.header.seq,
        answers_pose_stamp_ns: pose.header.stamp_ns,
        map: pose.map.clone(),
        path: Vec::new(),
        dlm: Dlm::Stop,
        arriving: false,
        lpe: None,
    }
}

/// One robot's intention pipeline (see the module docs).
pub struct IntentionPlanner {
    /// For goals with a heading.
    fixed: Planner,
    /// For goals with any heading (a heading tolerance of π).
    free: Planner,
    config: IntentionConfig,
    trail: VecDeque<Pose2D>,
    kept: Option<KeptPlan>,
    /// The new search that kept answers left due (see [`Self::take_refresh`]).
    refresh: Refresh,
    /// Counts kept plans, so a search's result is adopted only by the plan it refreshes.
    generation: u64,
    /// The DLM of the last answer, which the heading measure's hysteresis holds a turn on.
    last_dlm: Option<Dlm>,
    /// Cycles left before a search round other robots is tried again after one failed.
    avoid_paused: u32,
    /// How many other robots the kept plan was searched round.
    kept_avoided: usize,
}

/// Where the due new search of a kept plan stands.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Refresh {
    Idle,
    /// Due, from the pose of the answer that made it due.
    Due(Pose2D),
    /// Taken by the caller ([`IntentionPlanner::take_refresh`]); the kept plan answers on.
    Running,
}

impl IntentionPlanner {
    /// A pipeline on `map`.
    ///
    /// # Errors
    /// [`PlanError::InvalidConfig`] for a bad planner or pipeline value,
    /// [`PlanError::InvalidParams`] for bad DLM or LPE parameters;
    /// [`PlanError::RadiusMismatch`] when the map was inflated for another robot.
    pub fn new(map: Arc<PlanningMap>, config: IntentionConfig) -> Result<Self, PlanError> {
        config.planner.validate()?;
        config.dlm.validate()?;
        config.lpe.validate()?;
        config.reuse.validate()?;
        config.avoid.validate()?;
        config.seen.validate()?;
        if !(config.goal_tolerance_m.is_finite() && config.goal_tolerance_m > 0.0) {
            return Err(PlanError::invalid_config(
                "goal_tolerance_m",
                config.goal_tolerance_m,
                "must be positive",
            ));
        }
        if !(config.path_spacing_m.is_finite() && config.path_spacing_m >= 0.0) {
            return Err(PlanError::invalid_config(
                "path_spacing_m",
                config.path_spacing_m,
                "must be zero or positive",
            ));
        }
        let fixed = Planner::new(Arc::clone(&map), config.planner.clone())?;
        let free_config = PlannerConfig {
            goal_yaw_tolerance_rad: std::f64::consts::PI,
            ..config.planner.clone()
        };
        let free = Planner::new(map, free_config)?;
        Ok(Self {
            fixed,
            free,
            config,
            trail: VecDeque::new(),
            kept: None,
            refresh: Refresh::Idle,
            generation: 0,
            last_dlm: None,
            avoid_paused: 0,
            kept_avoided: 0,
        })
    }

    #[must_use]
    pub fn config(&self) -> &IntentionConfig {
        &self.config
    }

    /// The map the pipeline plans on.
    #[must_use]
    pub fn map(&self) -> &Arc<PlanningMap> {
        self.fixed.map()
    }

    /// Plans on `map` from now on (a new map version); a no-op for the current map.
    ///
    /// # Errors
    /// [`PlanError::RadiusMismatch`] when `map` was inflated for another robot.
    pub fn set_map(&mut self, map: Arc<PlanningMap>) -> Result<(), PlanError> {
        if Arc::ptr_eq(self.fixed.map(), &map) {
            return Ok(());
        }
        self.fixed.set_map(Arc::clone(&map))?;
        self.free.set_map(map)?;
        self.trail.clear();
        self.drop_kept();
        self.last_dlm = None;
        Ok(())
    }

    /// Forgets the travelled trail and the kept plan (the robot was carried or relocalised
    /// elsewhere).
    pub fn clear_trail(&mut self) {
        self.trail.clear();
        self.drop_kept();
        self.last_dlm = None;
    }

    fn drop_kept(&mut self) {
        self.kept = None;
        self.refresh = Refresh::Idle;
    }

    /// The new search that the last answers left due ([`ReuseParams::max_cycles`] answers in a
    /// row from the kept plan), to run off the pose-to-intention path: on another thread, at
    /// a lower priority, while the kept plan goes on answering. Hand its result to
    /// [`Self::adopt`]. `None`: none is due. An answer that finds a due search not taken runs
    /// it first, from its own pose.
    pub fn take_refresh(&mut self) -> Option<RefreshJob> {
        let Refresh::Due(from) = self.refresh else {
            return None;
        };
        let (goal, free_heading) = self.kept.as_ref().map(KeptPlan::goal)?;
        self.refresh = Refresh::Running;
        let planner = if free_heading {
            &self.free
        } else {
            &self.fixed
        };
        Some(RefreshJob {
            map: Arc::clone(planner.map()),
            planner: planner.config().clone(),
            from,
            goal,
            free_heading,
            generation: self.generation,
        })
    }

    /// Takes the result of a [`RefreshJob`]: the new plan replaces the kept one it refreshes
    /// (one searched since, or a new map or goal, wins). A search that found no path leaves
    /// the kept plan, which still holds, answering, and another search due after
    /// `max_cycles` more of its answers.
    ///
    /// # Errors
    /// The search's own error, handed back for the caller to report.
    pub fn adopt(&mut self, refreshed: Result<Refreshed, PlanError>) -> Result<(), PlanError> {
        if self.refresh != Refresh::Running {
            return Ok(());
        }
        self.refresh = Refresh::Idle;
        match refreshed {
            Ok(r) => {
                if r.generation == self.generation {
                    self.generation += 1;
                    self.kept = Some(r.kept);
                    // Searched on the floor plan alone; a robot in its way sends the next
                    // answer to a search round it.
                    self.kept_avoided = 0;
                }
                Ok(())
            }
            Err(e) => {
                if let Some(k) = self.kept.as_mut() {
                    k.postpone_refresh();
                }
                Err(e)
            }
        }
    }

    /// Runs the due new search here, on the pipeline's own planner ([`Self::take_refresh`],
    /// the job, [`Self::adopt`] in one): what a caller without another thread does once its
    /// answer has gone out. `Ok(false)`: none was due.
    ///
    /// # Errors
    /// As [`Self::adopt`].
    pub fn refresh(&mut self) -> Result<bool, PlanError> {
        let Some(job) = self.take_refresh() else {
            return Ok(false);
        };
        let planner = if job.free_heading {
            &mut self.free
        } else {
            &mut self.fixed
        };
        let refreshed = job.run(planner);
        self.adopt(refreshed).map(|()| true)
    }

    /// Where `pose` leaves the robot on its goals (no planning).
    #[must_use]
    pub fn advance(&self, pose: Pose2D, progress: &GoalProgress<'_>) -> Advance {
        progress.advance(pose, self.config.goal_tolerance_m)
    }

    /// Answers one pose: records it in the trail, moves past reached goals, plans hybrid A*
    /// from the pose to the next goal and derives the DLM, the thinned path and (when
    /// `render_lpe`) the LPE image.
    pub fn answer(
        &mut self,
        pose: &PoseEstimate,
        progress: &GoalProgress<'_>,
        render_lpe: bool,
    ) -> Answer {
        self.answer_among(pose, progress, render_lpe, &[])
    }

    /// [`Self::answer`] for a robot of a fleet, with the other robots near it (map frame, same
    /// map): the plan keeps clear of them where it can ([`AvoidParams`]), as it does of the
    /// obstacles the pose reports seeing ([`SeenObstacleParams`]).
    pub fn answer_among(
        &mut self,
        pose: &PoseEstimate,
        progress: &GoalProgress<'_>,
        render_lpe: bool,
        others: &[Neighbour],
    ) -> Answer {
        let robot = pose.pose;
        self.trail.push_back(robot);
        while self.trail.len() > self.config.trail_poses {
            self.trail.pop_front();
        }
        match self.advance(robot, progress) {
            Advance::Done => {
                self.last_dlm = None;
                Answer::Done
            }
            Advance::Heading { index, target } => {
                let free_heading = progress
                    .goals
                    .get(index)
                    .is_some_and(|g| g.yaw_rad.is_none());
                Answer::Heading {
                    goal_index: index,
                    plan: self.plan(
                        robot,
                        target,
                        free_heading,
                        render_lpe,
                        others,
                        &pose.unmapped_obstacles_m,
                    ),
                }
            }
        }
    }

    fn plan(
        &mut self,
        robot: Pose2D,
        goal: Pose2D,
        free_heading: bool,
        render_lpe: bool,
        others: &[Neighbour],
        seen_m: &[[f64; 2]],
    ) -> Result<Planned, PlanError> {
        // The caller did not take the search the last answer left due: it answers now.
        if let Refresh::Due(_) = self.refresh {
            self.drop_kept();
        }
        let own_radius_m = self.config.planner.robot_radius_m;
        let (mut discs, near) = self.config.avoid.discs(others, robot, goal, own_radius_m);
        let robot_discs = discs.len();
        discs.extend(self.config.seen.discs(seen_m, robot, goal, own_radius_m));
        let seen = discs.len() > robot_discs;
        let kept_rest = self
            .kept
            .as_mut()
            .and_then(|k| {
                k.follow(
                    self.fixed.map(),
                    robot,
                    goal,
                    free_heading,
                    &self.config.reuse,
                )
            })
            // A kept path that another robot now stands on is searched again (round it), and so
            // is one that passes a seen obstacle's berth by less than `kept_margin_m`: near what
            // the laser sees, the path follows what it sees now (a person who stopped, a
            // cabinet seen whole), as a new search every cycle would.
            .filter(|rest| {
                let (robots, seen) = discs.split_at(robot_discs);
                path_clear_of(&rest.poses, robots, own_radius_m)
                    && path_clear_of(
                        &rest.poses,
                        seen,
                        own_radius_m + self.config.seen.kept_margin_m,
                    )
            });
        let reused = kept_rest.is_some();
        let (poses, length_m) = match kept_rest {
            Some(rest) => (rest.poses, rest.length_m),
            None => {
                let (path, avoided) =
                    self.search_among(robot, goal, free_heading, &discs, near, seen)?;
                self.kept_avoided = avoided;
                self.generation += 1;
                self.kept = self.config.reuse.enabled.then(|| {
                    KeptPlan::new(
                        self.fixed.map().key(),
                        goal,
                        free_heading,
                        path.poses.clone(),
                    )
                });
                (path.poses, path.length_m)
            }
        };
        if reused
            && self.refresh == Refresh::Idle
            && self
                .kept
                .as_ref()
                .is_some_and(|k| k.refresh_due(&self.config.reuse))
        {
            self.refresh = Refresh::Due(robot);
        }
        let dlm = dlm_on_map(
            self.fixed.map(),
            &poses,
            robot,
            goal,
            &self.config.dlm,
            self.last_dlm,
            &discs[robot_discs..],
        );
        self.last_dlm = Some(dlm);
        let arriving = is_arriving(dlm, &poses, robot, &self.config.dlm);
        let lpe = if render_lpe {
            let trail: Vec<Pose2D> = self.trail.iter().copied().collect();
            // The parameters were validated in `new`, the only way rendering can fail.
            render_lpe_image(self.fixed.map(), robot, &trail, &poses, &self.config.lpe)
        } else {
            None
        };
        Ok(Planned {
            goal,
            path: thin_path(&poses, self.config.path_spacing_m),
            length_m,
            dlm,
            arriving,
            lpe,
            reused,
            avoided_robots: self.kept_avoided,
        })
    }

    /// A new search round `discs` (standing for `robots` other robots, and for seen obstacles
    /// when `seen`) when there are any and the last such search did not fail within
    /// `retry_cycles`; else, or when it finds no path, on the floor plan alone. Also how many
    /// robots the path keeps clear of.
    fn search_among(
        &mut self,
        robot: Pose2D,
        goal: Pose2D,
        free_heading: bool,
        discs: &[Disc],
        robots: usize,
        seen: bool,
    ) -> Result<(Path, usize), PlanError> {
        if !discs.is_empty() && self.avoid_paused == 0 {
            let planner = if free_heading {
                &mut self.free
            } else {
                &mut self.fixed
            };
            let (budget_ms, max_expansions) = if seen {
                (self.config.seen.budget_ms, self.config.seen.max_expansions)
            } else {
                (self.config.avoid.budget_ms, u64::MAX)
            };
            match planner.plan_avoiding(robot, goal, discs, budget_ms, max_expansions) {
                Ok(path) => return Ok((path, robots)),
                Err(_) => self.avoid_paused = self.config.avoid.retry_cycles,
            }
        } else {
            self.avoid_paused = self.avoid_paused.saturating_sub(1);
        }
        self.search(robot, goal, free_heading).map(|p| (p, 0))
    }

    /// A new hybrid-A* search from `robot` to `goal`.
    fn search(
        &mut self,
        robot: Pose2D,
        goal: Pose2D,
        free_heading: bool,
    ) -> Result<Path, PlanError> {
        let planner = if free_heading {
            &mut self.free
        } else {
            &mut self.fixed
        };
        search_from(planner, robot, goal)
    }
}

/// A kept plan's due new search, taken out of its pipeline to run elsewhere
/// ([`IntentionPlanner::take_refresh`]).
#[derive(Debug, Clone)]
pub struct RefreshJob {
    map: Arc<PlanningMap>,
    planner: PlannerConfig,
    from: Pose2D,
    goal: Pose2D,
    free_heading: bool,
    generation: u64,
}

/// A [`RefreshJob`]'s new plan, for [`IntentionPlanner::adopt`].
#[derive(Debug, Clone)]
pub struct Refreshed {
    kept: KeptPlan,
    generation: u64,
}

impl RefreshJob {
    /// The configuration of the planner the search runs on.
    #[must_use]
    pub fn planner_config(&self) -> &PlannerConfig {
        &self.planner
    }

    /// The map the search runs on.
    #[must_use]
    pub fn map(&self) -> &Arc<PlanningMap> {
        &self.map
    }

    /// Runs the search on `planner`, one made with [`Self::planner_config`] (its buffers are
    /// reused; it is moved to the job's map).
    ///
    /// # Errors
    /// No path from the job's pose, or `planner` was made for another robot radius.
    pub fn run(self, planner: &mut Planner) -> Result<Refreshed, PlanError> {
        planner.set_map(Arc::clone(&self.map))?;
        let path = search_from(planner, self.from, self.goal)?;
        Ok(Refreshed {
            kept: KeptPlan::new(self.map.key(), self.goal, self.free_heading, path.poses),
            generation: self.generation,
        })
    }
}

/// A new hybrid-A* search from `robot` to `goal` on `planner`.
fn search_from(planner: &mut Planner, robot: Pose2D, goal: Pose2D) -> Result<Path, PlanError> {
    match planner.plan(robot, goal) {
        // A pose estimate that grazes a wall (a cut corner, a few cm of AMCL error) is no
        // reason to stop for good: plan from the nearest free pose and lead there first.
        Err(
            e @ PlanError::InCollision {
                which: Endpoint::Start,
                ..
            },
        ) => {
            let free = nearest_free_start(planner.map(), robot).ok_or(e)?;
            let mut path = planner.plan(free, goal)?;
            path.poses.insert(0, robot);
            path.length_m += robot.distance_m(&free);
            Ok(path)
        }
        other => other,
    }
}

/// How far from an estimate inside the inflated obstacles the pipeline looks for a free start.
pub const START_RESCUE_M: f64 = 0.3;

/// The free pose nearest to `robot` within [`START_RESCUE_M`] (same heading), searched on
/// rings one map cell apart.
fn nearest_free_start(map: &PlanningMap, robot: Pose2D) -> Option<Pose2D> {
    let step_m = map.grid().resolution_m();
    let rings = (START_RESCUE_M / step_m).ceil() as usize;
    (1..=rings).find_map(|k| {
        let r = k as f64 * step_m;
        let n = (std::f64::consts::TAU * r / step_m).ceil().max(8.0) as usize;
        (0..n).find_map(|i| {
            let a = std::f64::consts::TAU * i as f64 / n as f64;
            let p = Pose2D::new(
                robot.x_m + r * a.cos(),
                robot.y_m + r * a.sin(),
                robot.yaw_rad,
            );
            map.check_endpoint(Endpoint::Start, p).ok().map(|_| p)
        })
    })
}

fn render_lpe_image(
    map: &PlanningMap,
    robot: Pose2D,
    trail: &[Pose2D],
    path: &[Pose2D],
    params: &LpeParams,
) -> Option<LpeImage> {
    render_lpe(map.grid(), robot, trail, path, params).ok()
}

/// Keeps the first and last pose and every pose at least `spacing_m` from the last kept one or
/// turned by more than 0.2 rad from it (turns in place); `spacing_m` 0 keeps everything.
#[must_use]
pub fn thin_path(path: &[Pose2D], spacing_m: f64) -> Vec<Pose2D> {
    const TURN_RAD: f64 = 0.2;
    let (Some(first), Some(last)) = (path.first(), path.last()) else {
        return Vec::new();
    };
    if spacing_m <= 0.0 || path.len() <= 2 {
        return path.to_vec();
    }
    // The tolerance keeps a pose exactly one spacing away despite rounding.
    let min_m = (spacing_m - 1e-9).max(0.0);
    let min_sq_m2 = min_m * min_m;
    let mut out = vec![*first];
    let mut kept = *first;
    for p in &path[1..path.len() - 1] {
        let turned = protocol::normalize_angle(p.yaw_rad - kept.yaw_rad).abs();
        if p.distance_sq_m2(&kept) >= min_sq_m2 || turned >= TURN_RAD {
            out.push(*p);
            kept = *p;
        }
    }
    out.push(*last);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thinning_keeps_ends_spacing_and_turns_in_place() {
        let mut path: Vec<Pose2D> = (0..=40)
            .map(|i| Pose2D::new(f64::from(i) * 0.05, 0.0, 0.0))
            .collect();
        // A quarter turn in place at the end of the straight part.
        for k in 1..=5 {
            path.push(Pose2D::new(
                2.0,
                0.0,
                f64::from(k) * std::f64::consts::FRAC_PI_2 / 5.0,
            ));
        }
        path.push(Pose2D::new(2.0, 0.05, std::f64::consts::FRAC_PI_2));
        let thin = thin_path(&path, 0.2);
        assert_eq!(thin.first(), path.first());
        assert_eq!(thin.last(), path.last());
        let straight = thin.iter().filter(|p| p.yaw_rad == 0.0).count();
        assert_eq!(straight, 11, "0 to 2 m every 0.2 m: {thin:?}");
        let turning = thin.iter().filter(|p| p.yaw_rad > 0.0).count();
        assert!(turning >= 5, "the turn in place survives: {thin:?}");
        assert_eq!(thin_path(&path, 0.0), path);
        assert!(thin_path(&[], 0.2).is_empty());
    }
}
