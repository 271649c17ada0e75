//! `eval compare`: two closed-loop tables of the same scenarios and seeds, run for run.
//!
//! A table is deterministic per scenario × method × seed, so two tables of the same seeds differ
//! only by what was changed between them (a model, a flag, the code). The runs pair up by
//! scenario and seed, and the paired difference of interventions, with its standard error over
//! the pairs, says whether a change is larger than the spread of one table's seeds (round 11 of
//! docs/evaluation.md: a 5-seed mean moves by about ±0.25 interventions per run from one block
//! of seeds to the next). Plain data in, numbers and markdown out; the command reads and prints.

use std::collections::BTreeMap;

use protocol::ControllerKind;
use serde::{Deserialize, Serialize};

use super::judge::Collisions;
use super::places;
use super::report::Stat;
use super::run::RunResult;

/// Why two tables cannot be compared.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum CompareError {
    /// A side holds several methods and none was chosen.
    #[error("the {side} table holds the methods {methods}: choose one with --{side}-method")]
    SeveralMethods { side: &'static str, methods: String },
    /// The chosen method has no run on a side.
    #[error("the {side} table has no run of method {method}")]
    NoSuchMethod {
        side: &'static str,
        method: ControllerKind,
    },
    /// A scenario and seed appears twice on one side.
    #[error("the {side} table has scenario {scenario} seed {seed} twice")]
    Duplicate {
        side: &'static str,
        scenario: String,
        seed: u64,
    },
    /// No scenario and seed is on both sides.
    #[error("no run pairs up: the tables share no scenario and seed")]
    NothingInCommon,
}

/// What one side's runs measured, over the runs that pair up.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Side {
    pub method: ControllerKind,
    pub runs: usize,
    pub successes: usize,
    /// Interventions per run: mean, sample standard deviation, runs.
    pub interventions: Stat,
    /// Contacts summed over the runs.
    pub contacts: Collisions,
    /// Mean smoothness (m/s³) over the runs that have one.
    pub smoothness: Option<f64>,
}

/// One scenario's pairs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioPair {
    pub scenario: String,
    pub pairs: usize,
    pub base_interventions: f64,
    pub other_interventions: f64,
    /// Mean time (s) over the runs that succeeded, each side's own.
    pub base_time_s: Option<f64>,
    pub other_time_s: Option<f64>,
}

/// A place where either side's interventions gathered ([`super::places::gather`] over both
/// sides' pick-ups), with each side's count.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlaceChange {
    pub scenario: String,
    pub x_m: f64,
    pub y_m: f64,
    pub extent_m: f64,
    pub base_interventions: u32,
    pub other_interventions: u32,
}

/// The comparison: `other` against `base`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Comparison {
    pub base: Side,
    pub other: Side,
    pub scenarios: Vec<ScenarioPair>,
    /// Other minus base, interventions per run, over the pairs.
    pub paired: Stat,
    /// Pairs where other needed fewer / more / as many interventions.
    pub better: usize,
    pub worse: usize,
    pub same: usize,
    /// Runs of either side left out because the other side has no run of that scenario and seed.
    pub unpaired: usize,
    /// Per scenario, the places with at least [`places::MIN_INTERVENTIONS`] of both sides
    /// together, at most [`places::MAX_PLACES`], the largest change first.
    #[serde(default)]
    pub places: Vec<PlaceChange>,
}

/// The places of one scenario's pairs, the largest change first.
fn place_changes(scenario: &str, runs: &[(&RunResult, &RunResult)]) -> Vec<PlaceChange> {
    let base: Vec<&RunResult> = runs.iter().map(|(x, _)| *x).collect();
    let other: Vec<&RunResult> = runs.iter().map(|(_, y)| *y).collect();
    let (base, other) = (
        places::events_in_order(&base),
        places::events_in_order(&other),
    );
    let points_m: Vec<(f64, f64)> = base
        .iter()
        .chain(&other)
        .map(|(_, e)| (e.x_m, e.y_m))
        .collect();
    let mut changes: Vec<PlaceChange> = places::gather(&points_m)
        .into_iter()
        .filter(|m| m.len() >= places::MIN_INTERVENTIONS as usize)
        .map(|m| {
            let ((x_m, y_m), extent_m) = places::centre_and_extent(&points_m, &m);
            let from_base = m.iter().filter(|&&i| i < base.len()).count();
            PlaceChange {
                scenario: scenario.to_string(),
                x_m,
                y_m,
                extent_m,
                base_interventions: u32::try_from(from_base).unwrap_or(u32::MAX),
                other_interventions: u32::try_from(m.len() - from_base).unwrap_or(u32::MAX),
            }
        })
        .collect();
    let change = |p: &PlaceChange| p.other_interventions.abs_diff(p.base_interventions);
    changes.sort_by(|a, b| {
        change(b)
            .cmp(&change(a))
            .then_with(|| {
                (b.base_interventions + b.other_interventions)
                    .cmp(&(a.base_interventions + a.other_interventions))
            })
            .then_with(|| a.x_m.total_cmp(&b.x_m))
            .then_with(|| a.y_m.total_cmp(&b.y_m))
    });
    changes.truncate(places::MAX_PLACES);
    changes
}

type Key = (String, u64);

/// The runs of one side keyed by scenario and seed, of `method` or of the one method it holds.
fn side_runs<'a>(
    side: &'static str,
    runs: &'a [RunResult],
    method: Option<ControllerKind>,
) -> Result<(ControllerKind, BTreeMap<Key, &'a RunResult>), CompareError> {
    let method = match method {
        Some(m) => m,
        None => {
            let mut methods: Vec<ControllerKind> = runs.iter().map(|r| r.method).collect();
            methods.sort_by_key(|m| m.to_string());
            methods.dedup();
            match methods.as_slice() {
                [] => return Err(CompareError::NothingInCommon),
                [one] => *one,
                many => {
                    return Err(CompareError::SeveralMethods {
                        side,
                        methods: many
                            .iter()
                            .map(ToString::to_string)
                            .collect::<Vec<_>>()
                            .join(", "),
                    })
                }
            }
        }
    };
    let mut keyed = BTreeMap::new();
    for r in runs.iter().filter(|r| r.method == method) {
        if keyed.insert((r.scenario.clone(), r.seed), r).is_some() {
            return Err(CompareError::Duplicate {
                side,
                scenario: r.scenario.clone(),
                seed: r.seed,
            });
        }
    }
    if keyed.is_empty() {
        return Err(CompareError::NoSuchMethod { side, method });
    }
    Ok((method, keyed))
}

/// Stat of the numbers; the pairs are never empty, and an empty set reads as nothing.
fn stat(values: impl Iterator<Item = f64>) -> Stat {
    Stat::of(&values.collect::<Vec<_>>()).unwrap_or(Stat {
        mean: 0.0,
        std: 0.0,
        n: 0,
    })
}

fn mean(values: impl Iterator<Item = f64>) -> Option<f64> {
    Stat::of(&values.collect::<Vec<_>>()).map(|s| s.mean)
}

/// Mean time over the runs that succeeded.
fn mean_time<'a>(runs: impl Iterator<Item = &'a RunResult>) -> Option<f64> {
    mean(runs.filter(|r| r.success).map(|r| r.time_s))
}

fn side_of(method: ControllerKind, runs: &[&RunResult]) -> Side {
    let mut contacts = Collisions::default();
    for r in runs {
        contacts.add(&r.collisions);
    }
    Side {
        method,
        runs: runs.len(),
        successes: runs.iter().filter(|r| r.success).count(),
        interventions: stat(runs.iter().map(|r| f64::from(r.interventions))),
        contacts,
        smoothness: mean(runs.iter().filter_map(|r| r.smoothness)),
    }
}

/// Pairs `other`'s runs with `base`'s by scenario and seed and measures the difference.
///
/// # Errors
/// [`CompareError`] when a side's method is ambiguous or absent, a run is duplicated, or no
/// run pairs up.
pub fn compare(
    base: &[RunResult],
    base_method: Option<ControllerKind>,
    other: &[RunResult],
    other_method: Option<ControllerKind>,
) -> Result<Comparison, CompareError> {
    let (bm, b) = side_runs("base", base, base_method)?;
    let (om, o) = side_runs("other", other, other_method)?;
    let keys: Vec<&Key> = b.keys().filter(|k| o.contains_key(*k)).collect();
    if keys.is_empty() {
        return Err(CompareError::NothingInCommon);
    }
    let unpaired = b.len() + o.len() - 2 * keys.len();
    let pb: Vec<&RunResult> = keys.iter().map(|k| b[*k]).collect();
    let po: Vec<&RunResult> = keys.iter().map(|k| o[*k]).collect();
    let diffs: Vec<f64> = pb
        .iter()
        .zip(&po)
        .map(|(x, y)| f64::from(y.interventions) - f64::from(x.interventions))
        .collect();
    let mut scenarios: BTreeMap<&str, Vec<(&RunResult, &RunResult)>> = BTreeMap::new();
    for (x, y) in pb.iter().zip(&po) {
        scenarios.entry(&x.scenario).or_default().push((x, y));
    }
    let places = scenarios
        .iter()
        .flat_map(|(name, runs)| place_changes(name, runs))
        .collect();
    Ok(Comparison {
        base: side_of(bm, &pb),
        other: side_of(om, &po),
        scenarios: scenarios
            .into_iter()
            .map(|(name, runs)| ScenarioPair {
                scenario: name.to_string(),
                pairs: runs.len(),
                base_interventions: mean(runs.iter().map(|(x, _)| f64::from(x.interventions)))
                    .unwrap_or(0.0),
                other_interventions: mean(runs.iter().map(|(_, y)| f64::from(y.interventions)))
                    .unwrap_or(0.0),
                base_time_s: mean_time(runs.iter().map(|(x, _)| *x)),
                other_time_s: mean_time(runs.iter().map(|(_, y)| *y)),
            })
            .collect(),
        paired: stat(diffs.iter().copied()),
        better: diffs.iter().filter(|v| **v < 0.0).count(),
        worse: diffs.iter().filter(|v| **v > 0.0).count(),
        same: diffs.iter().filter(|v| **v == 0.0).count(),
        unpaired,
        places,
    })
}

/// The comparison as markdown: a row per side, a row per scenario, and the paired difference.
#[must_use]
pub fn markdown(c: &Comparison, base_name: &str, other_name: &str) -> String {
    let opt = |v: Option<f64>, d: usize| v.map_or_else(|| "–".to_string(), |v| format!("{v:.d$}"));
    let mut s = String::from(
        "| table | method | success | interventions per run (mean ± s.e.) | contacts w/f/g/p/r | smoothness (m/s³) |\n\
         |---|---|---|---|---|---|\n",
    );
    for (name, side) in [(base_name, &c.base), (other_name, &c.other)] {
        let k = side.contacts;
        s.push_str(&format!(
            "| {name} | {} | {}/{} | {:.2} ± {:.2} | {}/{}/{}/{}/{} | {} |\n",
            side.method,
            side.successes,
            side.runs,
            side.interventions.mean,
            side.interventions.standard_error(),
            k.wall,
            k.furniture,
            k.glass,
            k.person,
            k.robot,
            opt(side.smoothness, 2),
        ));
    }
    s.push_str(&format!(
        "\n| scenario | pairs | interventions: {base_name} | {other_name} | time (s): {base_name} | {other_name} |\n\
         |---|---|---|---|---|---|\n"
    ));
    for p in &c.scenarios {
        s.push_str(&format!(
            "| {} | {} | {:.2} | {:.2} | {} | {} |\n",
            p.scenario,
            p.pairs,
            p.base_interventions,
            p.other_interventions,
            opt(p.base_time_s, 0),
            opt(p.other_time_s, 0),
        ));
    }
    s.push_str(&format!(
        "\n{other_name} − {base_name}: {:+.2} ± {:.2} interventions per run (paired, standard error over \
         {} pairs); better in {}, worse in {}, the same in {}",
        c.paired.mean,
        c.paired.standard_error(),
        c.better + c.worse + c.same,
        c.better,
        c.worse,
        c.same,
    ));
    if c.unpaired > 0 {
        s.push_str(&format!("; {} runs without a partner left out", c.unpaired));
    }
    s.push('\n');
    if !c.places.is_empty() {
        s.push_str(&format!(
            "\nWhere the interventions were (both tables' pick-ups gathered as in `eval table`'s \
             places; at least {} together, at most {} per scenario, the largest change first):\n\n\
             | scenario | centre (x, y) (m) | extent (m) | {base_name} | {other_name} |\n\
             |---|---|---|---|---|\n",
            places::MIN_INTERVENTIONS,
            places::MAX_PLACES,
        ));
        for p in &c.places {
            s.push_str(&format!(
                "| {} | ({:.1}, {:.1}) | {:.1} | {} | {} |\n",
                p.scenario, p.x_m, p.y_m, p.extent_m, p.base_interventions, p.other_interventions,
            ));
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::table::run::test_run_with_log;

    fn run(scenario: &str, seed: u64, method: ControllerKind, interventions: u32) -> RunResult {
        crate::table::run::test_run(scenario, seed, method, interventions)
    }

    #[test]
    fn pairs_by_scenario_and_seed_and_measures_the_difference() {
        let lpe = ControllerKind::Lpe;
        let base: Vec<RunResult> = (0..4)
            .flat_map(|s| {
                [
                    run("task_a", s, lpe, 2),
                    run("task_b", s, lpe, u32::try_from(s).unwrap_or(0)),
                ]
            })
            .collect();
        // The other table lists its runs in another order, lacks one and has one more.
        let mut other: Vec<RunResult> = (0..3)
            .flat_map(|s| [run("task_b", s, lpe, 1), run("task_a", s, lpe, 1)])
            .rev()
            .collect();
        other.push(run("task_c", 0, lpe, 0));
        let c = compare(&base, None, &other, None).expect("comparable");
        assert_eq!(c.base.runs, 6);
        assert_eq!(c.unpaired, 2 + 1);
        // task_a: 2 -> 1 on seeds 0..2; task_b: 0,1,2 -> 1,1,1.
        assert_eq!((c.better, c.worse, c.same), (4, 1, 1));
        assert!((c.paired.mean - (-3.0 + 1.0 - 1.0) / 6.0).abs() < 1e-12);
        assert!(c.paired.standard_error() > 0.0);
        assert_eq!(c.scenarios.len(), 2);
        assert!((c.scenarios[0].base_interventions - 2.0).abs() < 1e-12);
        assert!((c.scenarios[1].base_interventions - 1.0).abs() < 1e-12);
        assert_eq!(c.base.contacts.glass, 0);
        let md = markdown(&c, "r6", "e05");
        assert!(md.contains("e05 − r6: -0.50 ± 0.34"), "{md}");
        assert!(md.contains("3 runs without a partner"), "{md}");
    }

    #[test]
    fn places_count_each_side_and_the_largest_change_comes_first() {
        let dlm = ControllerKind::Dlm;
        let with_log = |seed: u64, picks: &[(f64, f64)]| {
            let picks: Vec<(f64, f64, &str)> =
                picks.iter().map(|&(x, y)| (x, y, "no progress")).collect();
            test_run_with_log("task_d", seed, dlm, &picks)
        };
        // Base circles the goal (12, 6) four times and stalls once at (4, 20); other circles
        // it once and stalls at (4, 20) three times and once alone at (30, 4).
        let base = vec![
            with_log(0, &[(11.2, 6.1), (12.6, 6.8), (4.1, 20.0)]),
            with_log(1, &[(12.4, 5.3), (11.9, 6.5)]),
        ];
        let other = vec![
            with_log(0, &[(4.0, 20.2), (3.8, 19.9)]),
            with_log(1, &[(12.1, 6.2), (4.3, 20.1), (30.0, 4.0)]),
        ];
        let c = compare(&base, None, &other, None).expect("comparable");
        let got: Vec<(u32, u32)> = c
            .places
            .iter()
            .map(|p| (p.base_interventions, p.other_interventions))
            .collect();
        assert_eq!(got, vec![(4, 1), (1, 3)], "{:?}", c.places);
        assert!((c.places[0].x_m - 12.04).abs() < 1e-9, "{:?}", c.places[0]);
        let md = markdown(&c, "r5", "dm");
        assert!(md.contains("| task_d | (12.0, 6.2) |"), "{md}");
        assert!(md.contains("| 4 | 1 |") && md.contains("| 1 | 3 |"), "{md}");
    }

    #[test]
    fn a_table_of_several_methods_needs_a_choice() {
        let runs = vec![
            run("task_a", 0, ControllerKind::Lpe, 1),
            run("task_a", 0, ControllerKind::DynamicWindow, 3),
        ];
        let err = compare(&runs, None, &runs, Some(ControllerKind::Lpe)).expect_err("ambiguous");
        assert!(
            matches!(err, CompareError::SeveralMethods { side: "base", .. }),
            "{err}"
        );
        let c = compare(
            &runs,
            Some(ControllerKind::DynamicWindow),
            &runs,
            Some(ControllerKind::Lpe),
        )
        .expect("chosen");
        assert_eq!((c.better, c.paired.mean), (1, -2.0));
        assert_eq!(c.base.contacts.glass, 1);
        let err = compare(&runs, Some(ControllerKind::Dlm), &runs, None).expect_err("absent");
        assert_eq!(err.to_string(), "the base table has no run of method dlm");
    }

    #[test]
    fn tables_without_common_runs_are_refused() {
        let a = vec![run("task_a", 0, ControllerKind::Lpe, 1)];
        let b = vec![run("task_a", 1, ControllerKind::Lpe, 1)];
        assert_eq!(
            compare(&a, None, &b, None),
            Err(CompareError::NothingInCommon)
        );
        let dup = vec![a[0].clone(), a[0].clone()];
        assert!(matches!(
            compare(&dup, None, &a, None),
            Err(CompareError::Duplicate { side: "base", .. })
        ));
    }
}
