//! The table's outputs: `runs.json` (every run), `table.json` and `table.md` (mean ± standard
//! deviation over seeds per scenario × method, in the layout of the paper's Table 1).

use std::path::Path;

use protocol::ControllerKind;
use serde::{Deserialize, Serialize};

use super::audit::IntentionAudit;
use super::places::{self, MoverContact, Place};
use super::run::{Prepared, RunResult, RunTrace};
use super::TableError;
use crate::figure::{self, GridRow, Trace};

/// Mean and sample standard deviation of some numbers.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Stat {
    pub mean: f64,
    pub std: f64,
    /// How many numbers (runs) it is over.
    pub n: usize,
}

impl Stat {
    /// `None` for no numbers.
    #[must_use]
    pub fn of(values: &[f64]) -> Option<Self> {
        if values.is_empty() {
            return None;
        }
        #[allow(clippy::cast_precision_loss)]
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let std = if values.len() > 1 {
            (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
        } else {
            0.0
        };
        Some(Self {
            mean,
            std,
            n: values.len(),
        })
    }

    /// Standard error of the mean (0 for a single number).
    #[must_use]
    pub fn standard_error(&self) -> f64 {
        #[allow(clippy::cast_precision_loss)]
        let n = self.n as f64;
        if self.n > 1 {
            self.std / n.sqrt()
        } else {
            0.0
        }
    }

    fn show(s: Option<Self>, decimals: usize) -> String {
        s.map_or_else(
            || "–".to_string(),
            |s| {
                if s.n > 1 {
                    format!("{:.*} ± {:.*}", decimals, s.mean, decimals, s.std)
                } else {
                    format!("{:.*}", decimals, s.mean)
                }
            },
        )
    }
}

/// One scenario × method of the table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Row {
    pub scenario: String,
    pub role: String,
    pub method: ControllerKind,
    pub runs: usize,
    pub successes: usize,
    pub interventions: Option<Stat>,
    /// All collisions, any kind.
    pub collisions: Option<Stat>,
    pub collisions_wall: u32,
    pub collisions_furniture: u32,
    pub collisions_glass: u32,
    pub collisions_person: u32,
    pub collisions_robot: u32,
    /// Completion time over the successful runs (as the paper reports it).
    pub time_s: Option<Stat>,
    /// Mean |jerk| in m/s³ over the runs that have one.
    pub smoothness: Option<Stat>,
    pub path_length_m: Option<Stat>,
    pub goals_reached: Option<Stat>,
    pub goals_total: usize,
    /// The smallest person gap over all runs (`None` without people).
    pub min_person_distance_m: Option<f64>,
    /// The smallest glass gap over all runs (`None` without glass).
    pub min_glass_distance_m: Option<f64>,
    pub mean_position_error_m: Option<Stat>,
    /// Share of cycles in which the collision monitor limited the command (`None`: off).
    #[serde(default)]
    pub collision_monitor_share: Option<Stat>,
    /// Share of cycles the dynamic window drove recovering (`None`: no recovery).
    #[serde(default)]
    pub recovery_share: Option<Stat>,
    /// Recoveries per run (`None`: no recovery).
    #[serde(default)]
    pub recoveries: Option<Stat>,
    /// The intention audit summed over the runs that have one.
    #[serde(default)]
    pub intention_audit: Option<IntentionAudit>,
    /// Where interventions gathered over the seeds ([`super::places`]); empty in tables made
    /// before 2026-11-30.
    #[serde(default)]
    pub intervention_places: Vec<Place>,
    /// The interventions for a contact with a person or robot, with their bearing
    /// ([`places::mover_contacts`]); empty in tables made before 2026-12-03.
    #[serde(default)]
    pub mover_contacts: Vec<MoverContact>,
}

/// `table.json`: the rows and how they were made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Table {
    pub seeds: Vec<u64>,
    pub methods: Vec<ControllerKind>,
    pub rows: Vec<Row>,
    /// Simulated seconds of all runs together and the wall-clock seconds the table took.
    pub simulated_s: f64,
    pub wall_s: f64,
    pub jobs: usize,
    /// Whether the intention pipeline kept paths while they held (`[path_reuse]`); absent in
    /// tables made before it was the default, all of which searched every cycle unless their
    /// command said `--path-reuse`.
    #[serde(default)]
    pub path_reuse: bool,
}

impl Table {
    /// Simulated seconds per wall-clock second, all cores together.
    #[must_use]
    pub fn real_time_factor(&self) -> f64 {
        if self.wall_s > 0.0 {
            self.simulated_s / self.wall_s
        } else {
            0.0
        }
    }
}

/// Groups runs by scenario × method in first-seen order.
#[must_use]
pub fn rows(runs: &[RunResult]) -> Vec<Row> {
    let mut keys: Vec<(String, ControllerKind)> = Vec::new();
    for r in runs {
        let key = (r.scenario.clone(), r.method);
        if !keys.contains(&key) {
            keys.push(key);
        }
    }
    keys.into_iter()
        .map(|(scenario, method)| {
            let group: Vec<&RunResult> = runs
                .iter()
                .filter(|r| r.scenario == scenario && r.method == method)
                .collect();
            let of = |f: &dyn Fn(&RunResult) -> Option<f64>| {
                Stat::of(&group.iter().filter_map(|r| f(r)).collect::<Vec<_>>())
            };
            let min_of = |f: &dyn Fn(&RunResult) -> Option<f64>| {
                group.iter().filter_map(|r| f(r)).min_by(f64::total_cmp)
            };
            let sum = |f: &dyn Fn(&RunResult) -> u32| group.iter().map(|r| f(r)).sum();
            Row {
                role: group.first().map(|r| r.role.clone()).unwrap_or_default(),
                method,
                runs: group.len(),
                successes: group.iter().filter(|r| r.success).count(),
                interventions: of(&|r| Some(f64::from(r.interventions))),
                collisions: of(&|r| Some(f64::from(r.collisions.total()))),
                collisions_wall: sum(&|r| r.collisions.wall),
                collisions_furniture: sum(&|r| r.collisions.furniture),
                collisions_glass: sum(&|r| r.collisions.glass),
                collisions_person: sum(&|r| r.collisions.person),
                collisions_robot: sum(&|r| r.collisions.robot),
                time_s: of(&|r| r.success.then_some(r.time_s)),
                smoothness: of(&|r| r.smoothness),
                path_length_m: of(&|r| Some(r.path_length_m)),
                #[allow(clippy::cast_precision_loss)]
                goals_reached: of(&|r| Some(r.goals_reached as f64)),
                goals_total: group.first().map_or(0, |r| r.goals_total),
                min_person_distance_m: min_of(&|r| r.min_person_distance_m),
                min_glass_distance_m: min_of(&|r| r.min_glass_distance_m),
                mean_position_error_m: of(&|r| Some(r.mean_position_error_m)),
                collision_monitor_share: of(&|r| r.collision_monitor_share.map(|s| 100.0 * s)),
                recovery_share: of(&|r| r.recovery_share.map(|s| 100.0 * s)),
                recoveries: of(&|r| r.recoveries.map(f64::from)),
                intention_audit: IntentionAudit::sum(
                    group.iter().filter_map(|r| r.intention_audit.as_ref()),
                ),
                intervention_places: places::places(&group),
                mover_contacts: places::mover_contacts(&group),
                scenario,
            }
        })
        .collect()
}

/// The markdown table: one block of rows per scenario, like the paper's Table 1.
#[must_use]
pub fn markdown(table: &Table) -> String {
    let seeds = table
        .seeds
        .iter()
        .map(u64::to_string)
        .collect::<Vec<_>>()
        .join(", ");
    let mut out = format!(
        "Seeds {seeds}: mean ± standard deviation over seeds. Success: runs that reached every goal in time \
         (behaviour: did what the scenario expects, without contact). Time over the successful runs. \
         Smoothness: mean |jerk| of the true trajectory, m/s³. Collisions: wall/furniture/glass/person/robot, \
         summed over seeds. Gaps: smallest over all seeds, robot disc to person disc or glass pane. \
         Monitor: share of cycles in which the collision monitor slowed the command (– when off). \
         Recovery: times per run the dynamic window took over from a controller the monitor held, and \
         the share of cycles it drove (– when off or for the dynamic window itself).\n\n\
         | scenario | method | success | interventions | collisions (w/f/g/p/r) | time (s) | smoothness (m/s³) | goals | path (m) | min person gap (m) | min glass gap (m) | AMCL error (m) | monitor (%) | recoveries | recovery (%) |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n"
    );
    for r in &table.rows {
        let gap = |g: Option<f64>| g.map_or_else(|| "–".to_string(), |g| format!("{g:.2}"));
        out.push_str(&format!(
            "| {} | {} | {}/{} | {} | {}/{}/{}/{}/{} | {} | {} | {} / {} | {} | {} | {} | {} | {} | {} | {} |\n",
            r.scenario,
            r.method,
            r.successes,
            r.runs,
            Stat::show(r.interventions, 1),
            r.collisions_wall,
            r.collisions_furniture,
            r.collisions_glass,
            r.collisions_person,
            r.collisions_robot,
            Stat::show(r.time_s, 0),
            Stat::show(r.smoothness, 2),
            Stat::show(r.goals_reached, 1),
            r.goals_total,
            Stat::show(r.path_length_m, 0),
            gap(r.min_person_distance_m),
            gap(r.min_glass_distance_m),
            Stat::show(r.mean_position_error_m, 3),
            Stat::show(r.collision_monitor_share, 1),
            Stat::show(r.recoveries, 1),
            Stat::show(r.recovery_share, 1),
        ));
    }
    if table.rows.iter().any(|r| r.intention_audit.is_some()) {
        out.push_str(&audit_markdown(&table.rows));
    }
    if table.rows.iter().any(|r| !r.intervention_places.is_empty()) {
        out.push_str(&places_markdown(&table.rows));
    }
    if table.rows.iter().any(|r| !r.mover_contacts.is_empty()) {
        out.push_str(&contacts_markdown(&table.rows));
    }
    out.push_str(&format!(
        "\n{} runs, {:.0} simulated s in {:.0} s wall clock on {} jobs: real-time factor {:.1}.\n",
        table.rows.iter().map(|r| r.runs).sum::<usize>(),
        table.simulated_s,
        table.wall_s,
        table.jobs,
        table.real_time_factor()
    ));
    out
}

/// The intention audit: how often the DLM told from the agent's pose differed from the one the
/// true pose gives (`eval::table::audit`), summed over seeds.
fn audit_markdown(rows: &[Row]) -> String {
    let mut out = format!(
        "\nWrong intentions from the pose (summed over seeds): every cycle the pipeline also planned \
         from the true pose. Missed: a turn needed, `go_forward` told; wrong: the opposite turn, or a \
         turn where the truth went on. Event: at least {} such cycles in a row; blamed: an \
         intervention within {:.0} s of its start.\n\n\
         | scenario | method | cycles | DLM differs | turn missed | turn wrong | events | events → intervention | AMCL error when differs / agrees (m) |\n\
         |---|---|---|---|---|---|---|---|---|\n",
        super::audit::EVENT_CYCLES,
        super::audit::BLAME_S,
    );
    for r in rows {
        let Some(a) = &r.intention_audit else {
            continue;
        };
        #[allow(clippy::cast_precision_loss)]
        let pct = |n: u64| 100.0 * n as f64 / a.cycles.max(1) as f64;
        out.push_str(&format!(
            "| {} | {} | {} | {:.2} % | {} ({:.2} %) | {} ({:.2} %) | {} | {} | {:.3} / {:.3} |\n",
            r.scenario,
            r.method,
            a.cycles,
            pct(a.dlm_differs),
            a.turn_missed,
            pct(a.turn_missed),
            a.turn_wrong,
            pct(a.turn_wrong),
            a.events,
            a.events_with_intervention,
            a.mean_error_when_differs_m,
            a.mean_error_when_agrees_m,
        ));
    }
    out
}

/// Where the interventions gathered (`eval::table::places`).
fn places_markdown(rows: &[Row]) -> String {
    let mut out = format!(
        "\nWhere the interventions were: places where at least {} gathered over the seeds (the \
         true positions where the robot was picked up, less than {:.1} m apart or chained so; \
         centre: their mean, extent: the farthest from it), at most {} per scenario × method, \
         the most first.\n\n\
         | scenario | method | centre (x, y) (m) | extent (m) | interventions | runs | causes |\n\
         |---|---|---|---|---|---|---|\n",
        places::MIN_INTERVENTIONS,
        places::PLACE_RADIUS_M,
        places::MAX_PLACES,
    );
    for r in rows {
        for p in &r.intervention_places {
            out.push_str(&format!(
                "| {} | {} | ({:.1}, {:.1}) | {:.1} | {} | {} | {} |\n",
                r.scenario,
                r.method,
                p.x_m,
                p.y_m,
                p.extent_m,
                p.interventions,
                p.runs,
                p.causes_text(),
            ));
        }
    }
    out
}

/// Each contact with a person or robot and whether the camera could see them.
fn contacts_markdown(rows: &[Row]) -> String {
    let mut out = format!(
        "\nContacts with people and robots: their centre's bearing from the robot's heading when \
         the human stepped in (left positive), and whether any of them was inside the camera's \
         {:.0}° view, seen from the camera {:.2} m ahead of the robot's centre.\n\n\
         | scenario | method | seed | t (s) | at (x, y) (m) | with | bearing (°) | in the camera's view |\n\
         |---|---|---|---|---|---|---|---|\n",
        sim::SimConfig::default().camera.hfov_rad.to_degrees(),
        sim::camera::CAMERA_FORWARD_M,
    );
    for r in rows {
        for c in &r.mover_contacts {
            out.push_str(&format!(
                "| {} | {} | {} | {:.1} | ({:.1}, {:.1}) | {} | {:+.0} | {} |\n",
                r.scenario,
                r.method,
                c.seed,
                c.t_s,
                c.x_m,
                c.y_m,
                c.cause.trim_start_matches("collision: "),
                c.bearing_rad.to_degrees(),
                if c.in_camera_view { "yes" } else { "no" },
            ));
        }
    }
    out
}

fn write(path: &Path, bytes: &[u8]) -> Result<(), TableError> {
    map_core::export::write_atomic(path, bytes).map_err(|e| TableError::Write {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })
}

/// Writes `runs.json`, `table.json` and `table.md` into `dir` (created if needed).
///
/// # Errors
/// [`TableError::Write`] naming the file.
pub fn write_tables(dir: &Path, runs: &[RunResult], table: &Table) -> Result<(), TableError> {
    std::fs::create_dir_all(dir).map_err(|e| TableError::Write {
        path: dir.to_path_buf(),
        reason: e.to_string(),
    })?;
    write_json(&dir.join("runs.json"), runs)?;
    write_json(&dir.join("table.json"), table)?;
    write(&dir.join("table.md"), markdown(table).as_bytes())
}

fn write_png(path: &Path, img: &image::RgbImage) -> Result<(), TableError> {
    let mut bytes = std::io::Cursor::new(Vec::new());
    img.write_to(&mut bytes, image::ImageFormat::Png)
        .map_err(|e| TableError::Write {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
    write(path, bytes.get_ref())
}

/// Writes the Figure 5 pictures into `dir/figures/`: per scenario `<scenario>.png` (the plan
/// with furniture and glass, the planned path and every method's trace of the first seed) and
/// `grid.png` (scenario × method).
///
/// # Errors
/// [`TableError::Write`] naming the file, [`TableError::Setup`] when a world cannot be rebuilt.
pub fn write_figures(
    dir: &Path,
    prepared: &[Prepared],
    methods: &[ControllerKind],
    outcome: &[(RunResult, RunTrace)],
) -> Result<(), TableError> {
    let figures = dir.join("figures");
    std::fs::create_dir_all(&figures).map_err(|e| TableError::Write {
        path: figures.clone(),
        reason: e.to_string(),
    })?;
    let first_seed = outcome.iter().map(|(r, _)| r.seed).min().unwrap_or(0);
    let names: Vec<String> = methods.iter().map(ToString::to_string).collect();
    let mut worlds = Vec::with_capacity(prepared.len());
    for p in prepared {
        let world = sim::World::new(
            p.scenario.clone(),
            p.plan.clone(),
            sim::SimConfig::default(),
        )
        .map_err(|e| TableError::Setup {
            what: "figure world",
            reason: e.to_string(),
        })?;
        worlds.push(world);
    }
    struct Scene<'a> {
        goals: Vec<(f64, f64)>,
        planned: &'a [(f64, f64)],
        runs: Vec<(&'a str, &'a RunTrace)>,
    }
    let scenes: Vec<Scene<'_>> = prepared
        .iter()
        .map(|p| {
            let runs: Vec<(&str, &RunTrace)> = names
                .iter()
                .filter_map(|name| {
                    outcome
                        .iter()
                        .find(|(r, _)| {
                            r.scenario == p.scenario.name
                                && r.seed == first_seed
                                && r.method.as_str() == name
                        })
                        .map(|(_, t)| (name.as_str(), t))
                })
                .collect();
            // The planned path of the method that planned the most legs (all plan alike).
            let planned = runs
                .iter()
                .map(|(_, t)| t.planned_m.as_slice())
                .max_by_key(|p| p.len())
                .unwrap_or(&[]);
            Scene {
                goals: p.scenario.goals.iter().map(|g| (g.x_m, g.y_m)).collect(),
                planned,
                runs,
            }
        })
        .collect();
    let traces: Vec<Vec<Trace<'_>>> = scenes
        .iter()
        .map(|s| {
            s.runs
                .iter()
                .map(|(label, t)| Trace {
                    label,
                    points_m: &t.points_m,
                    interventions_m: &t.interventions_m,
                    collisions_m: &t.collisions_m,
                })
                .collect()
        })
        .collect();
    for ((p, scene), (world, tr)) in prepared.iter().zip(&scenes).zip(worlds.iter().zip(&traces)) {
        let img = figure::scenario_picture(world, scene.planned, &scene.goals, tr);
        write_png(&figures.join(format!("{}.png", p.scenario.name)), &img)?;
    }
    let rows: Vec<GridRow<'_>> = prepared
        .iter()
        .zip(&scenes)
        .zip(worlds.iter().zip(&traces))
        .map(|((p, scene), (world, tr))| GridRow {
            label: &p.scenario.name,
            world,
            planned_m: scene.planned,
            goals_m: &scene.goals,
            traces: tr,
        })
        .collect();
    let labels: Vec<&str> = names.iter().map(String::as_str).collect();
    write_png(
        &figures.join("grid.png"),
        &figure::grid_picture(&rows, &labels, 256),
    )
}

fn write_json<T: Serialize + ?Sized>(path: &Path, value: &T) -> Result<(), TableError> {
    let text = serde_json::to_string_pretty(value).map_err(|e| TableError::Write {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    write(path, format!("{text}\n").as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stat_is_mean_and_sample_std() {
        let s = Stat::of(&[1.0, 2.0, 3.0]).unwrap();
        assert!((s.mean - 2.0).abs() < 1e-12 && (s.std - 1.0).abs() < 1e-12 && s.n == 3);
        assert_eq!(Stat::of(&[]), None);
        assert_eq!(Stat::of(&[4.0]).unwrap().std, 0.0);
    }
}
