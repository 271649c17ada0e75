//! Where a table's interventions happened: the places where the human stepped in more than
//! once over a scenario's seeds. A round's analysis starts from such a list (a maze's wall end
//! the robot clips, a goal it circles); before it, each round grouped `runs.json` by hand.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::run::{InterventionEvent, RunResult};

/// Interventions closer than this are at one place (m): two robot diameters, so that the
/// pick-ups of one stall or one wall end fall together and the next doorway's do not.
pub const PLACE_RADIUS_M: f64 = 1.0;
/// A place is listed from this many interventions on.
pub const MIN_INTERVENTIONS: u32 = 2;
/// At most this many places per scenario × method, the most interventions first.
pub const MAX_PLACES: usize = 5;

/// One place where interventions gathered.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Place {
    /// Mean of the true positions where the robot was picked up (m).
    pub x_m: f64,
    pub y_m: f64,
    /// The farthest of them from that mean (m).
    pub extent_m: f64,
    pub interventions: u32,
    /// Runs (seeds) with at least one intervention here.
    pub runs: u32,
    /// Interventions by cause (`no progress`, `collision: wall`, ...).
    pub causes: BTreeMap<String, u32>,
}

impl Place {
    /// `no progress 7, collision: wall 2`: the causes, most first.
    #[must_use]
    pub fn causes_text(&self) -> String {
        let mut causes: Vec<(&String, &u32)> = self.causes.iter().collect();
        causes.sort_by(|a, b| b.1.cmp(a.1).then_with(|| a.0.cmp(b.0)));
        causes
            .iter()
            .map(|(cause, n)| format!("{cause} {n}"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// A contact with a person or another robot, with where they were against the robot's heading:
/// a round's analysis asks first whether the camera could have seen them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MoverContact {
    pub seed: u64,
    pub t_s: f64,
    /// Where the robot was picked up (true position, m).
    pub x_m: f64,
    pub y_m: f64,
    /// `collision: person` or `collision: robot`.
    pub cause: String,
    /// Their centre's bearing from the robot's centre against its heading (rad, left positive).
    pub bearing_rad: f64,
    /// Whether any of them was inside the camera's horizontal field of view.
    pub in_camera_view: bool,
}

/// The contacts with people and robots among some runs' interventions, in seed and time order.
#[must_use]
pub fn mover_contacts(runs: &[&RunResult]) -> Vec<MoverContact> {
    events_in_order(runs)
        .into_iter()
        .filter_map(|(seed, e)| {
            Some(MoverContact {
                seed,
                t_s: e.t_s,
                x_m: e.x_m,
                y_m: e.y_m,
                cause: e.cause.clone(),
                bearing_rad: e.contact_bearing_rad?,
                in_camera_view: e.contact_in_camera_view?,
            })
        })
        .collect()
}

/// Groups points (m) into places: points less than [`PLACE_RADIUS_M`] apart are at one place,
/// and so are chains of them (single linkage: a robot circling a goal leaves a ring of pick-ups
/// wider than the radius, one place all the same). Each place lists its points' indices in
/// order; the places come in the order of their first point.
#[must_use]
pub fn gather(points_m: &[(f64, f64)]) -> Vec<Vec<usize>> {
    // Union-find; the root of a place is its smallest index.
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let mut parent: Vec<usize> = (0..points_m.len()).collect();
    for (i, a) in points_m.iter().enumerate() {
        for (j, b) in points_m.iter().enumerate().skip(i + 1) {
            if (a.0 - b.0).hypot(a.1 - b.1) < PLACE_RADIUS_M {
                let (ri, rj) = (root(&mut parent, i), root(&mut parent, j));
                parent[ri.max(rj)] = ri.min(rj);
            }
        }
    }
    let mut members: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
    for i in 0..points_m.len() {
        members.entry(root(&mut parent, i)).or_default().push(i);
    }
    members.into_values().collect()
}

/// The mean of some of `points_m` and the farthest of them from it.
#[must_use]
pub fn centre_and_extent(points_m: &[(f64, f64)], members: &[usize]) -> ((f64, f64), f64) {
    #[allow(clippy::cast_precision_loss)]
    let n = members.len().max(1) as f64;
    let x_m = members.iter().map(|&i| points_m[i].0).sum::<f64>() / n;
    let y_m = members.iter().map(|&i| points_m[i].1).sum::<f64>() / n;
    let extent_m = members
        .iter()
        .map(|&i| (points_m[i].0 - x_m).hypot(points_m[i].1 - y_m))
        .fold(0.0, f64::max);
    ((x_m, y_m), extent_m)
}

/// The interventions of some runs in seed and time order, so that what is made of them does
/// not depend on the order of the runs.
#[must_use]
pub fn events_in_order<'a>(runs: &[&'a RunResult]) -> Vec<(u64, &'a InterventionEvent)> {
    let mut events: Vec<(u64, &InterventionEvent)> = runs
        .iter()
        .flat_map(|r| r.intervention_log.iter().map(move |e| (r.seed, e)))
        .collect();
    events.sort_by(|a, b| a.0.cmp(&b.0).then_with(|| a.1.t_s.total_cmp(&b.1.t_s)));
    events
}

/// The places of one scenario × method's runs ([`gather`]) with at least
/// [`MIN_INTERVENTIONS`], at most [`MAX_PLACES`], the most first.
#[must_use]
pub fn places(runs: &[&RunResult]) -> Vec<Place> {
    let events = events_in_order(runs);
    let points_m: Vec<(f64, f64)> = events.iter().map(|(_, e)| (e.x_m, e.y_m)).collect();
    let mut places: Vec<Place> = gather(&points_m)
        .into_iter()
        .filter(|m| m.len() >= MIN_INTERVENTIONS as usize)
        .map(|m| {
            let ((x_m, y_m), extent_m) = centre_and_extent(&points_m, &m);
            let mut seeds: Vec<u64> = m.iter().map(|&i| events[i].0).collect();
            seeds.sort_unstable();
            seeds.dedup();
            let mut causes = BTreeMap::new();
            for &i in &m {
                *causes.entry(events[i].1.cause.clone()).or_default() += 1;
            }
            Place {
                x_m,
                y_m,
                extent_m,
                interventions: u32::try_from(m.len()).unwrap_or(u32::MAX),
                runs: u32::try_from(seeds.len()).unwrap_or(u32::MAX),
                causes,
            }
        })
        .collect();
    places.sort_by(|a, b| {
        b.interventions
            .cmp(&a.interventions)
            .then_with(|| b.runs.cmp(&a.runs))
            .then_with(|| a.x_m.total_cmp(&b.x_m))
            .then_with(|| a.y_m.total_cmp(&b.y_m))
    });
    places.truncate(MAX_PLACES);
    places
}

#[cfg(test)]
mod tests {
    use protocol::ControllerKind;

    use super::*;
    use crate::table::run::test_run_with_log;

    fn run(seed: u64, log: &[(f64, f64, &str)]) -> RunResult {
        test_run_with_log("task_d", seed, ControllerKind::Dlm, log)
    }

    #[test]
    fn interventions_gather_by_place_across_seeds_and_lone_ones_are_left_out() {
        // Task D of DLM-Net r5 alone in miniature: circling the first goal (4, 20) in three
        // seeds, a wall end clipped twice in one, and one stall elsewhere.
        let runs = [
            run(
                0,
                &[
                    (4.3, 19.6, "no progress"),
                    (4.8, 20.4, "no progress"),
                    (20.6, 12.8, "collision: wall"),
                ],
            ),
            run(1, &[(3.7, 20.2, "no progress"), (12.0, 6.0, "no progress")]),
            run(
                2,
                &[
                    (20.9, 13.1, "collision: wall"),
                    (4.1, 19.9, "collision: furniture"),
                ],
            ),
        ];
        let refs: Vec<&RunResult> = runs.iter().collect();
        let found = places(&refs);
        assert_eq!(found.len(), 2, "{found:?}");
        let goal = &found[0];
        assert_eq!((goal.interventions, goal.runs), (4, 3));
        assert!((goal.x_m - 4.225).abs() < 1e-9 && (goal.y_m - 20.025).abs() < 1e-9);
        assert_eq!(goal.causes_text(), "no progress 3, collision: furniture 1");
        let wall = &found[1];
        assert_eq!((wall.interventions, wall.runs), (2, 2));
        assert_eq!(wall.causes_text(), "collision: wall 2");
        // (12, 6) happened once: not a place.
        assert!(found.iter().all(|p| (p.x_m - 12.0).abs() > 1.0));

        // The order of the runs does not matter.
        let reversed: Vec<&RunResult> = runs.iter().rev().collect();
        assert_eq!(places(&reversed), found);
    }

    #[test]
    fn a_ring_round_a_goal_is_one_place() {
        // Circling a goal it drove past, the robot is picked up all round it, 2 m across.
        let ring: Vec<(f64, f64, &str)> = (0..8u32)
            .map(|k| {
                let a = f64::from(k) * std::f64::consts::FRAC_PI_4;
                (12.0 + a.cos(), 6.0 + a.sin(), "no progress")
            })
            .collect();
        let found = places(&[&run(0, &ring[..4]), &run(1, &ring[4..])]);
        assert_eq!(found.len(), 1, "{found:?}");
        let p = &found[0];
        assert_eq!((p.interventions, p.runs), (8, 2));
        assert!(
            (p.x_m - 12.0).abs() < 1e-9 && (p.y_m - 6.0).abs() < 1e-9,
            "{p:?}"
        );
        assert!((p.extent_m - 1.0).abs() < 1e-9, "{p:?}");
    }

    #[test]
    fn at_most_five_places_the_most_first() {
        let log: Vec<(f64, f64, &str)> = (0..7u32)
            .flat_map(|k| {
                let x_m = 5.0 * f64::from(k);
                // Place k gets k + 2 interventions.
                std::iter::repeat_n((x_m, 1.0, "no progress"), usize::try_from(k).unwrap() + 2)
            })
            .collect();
        let found = places(&[&run(3, &log)]);
        let counts: Vec<u32> = found.iter().map(|p| p.interventions).collect();
        assert_eq!(counts, vec![8, 7, 6, 5, 4]);
        assert!(found.iter().all(|p| p.runs == 1));
        assert!(places(&[&run(0, &[])]).is_empty());
    }

    #[test]
    fn mover_contacts_are_listed_in_seed_order_with_their_sight() {
        let mut late = run(
            4,
            &[
                (20.0, 13.0, "collision: person"),
                (8.0, 2.0, "collision: wall"),
            ],
        );
        let mut early = run(
            1,
            &[(26.6, 13.3, "collision: person"), (3.0, 3.0, "no progress")],
        );
        late.intervention_log[0].contact_bearing_rad = Some(-53f64.to_radians());
        late.intervention_log[0].contact_in_camera_view = Some(false);
        early.intervention_log[0].contact_bearing_rad = Some(-10f64.to_radians());
        early.intervention_log[0].contact_in_camera_view = Some(true);
        let found = mover_contacts(&[&late, &early]);
        let told: Vec<(u64, bool)> = found.iter().map(|c| (c.seed, c.in_camera_view)).collect();
        assert_eq!(told, vec![(1, true), (4, false)]);
        assert_eq!(found[1].cause, "collision: person");
        assert!((found[1].x_m - 20.0).abs() < 1e-12);
        assert!((found[1].bearing_rad + 53f64.to_radians()).abs() < 1e-12);
        // Walls and stalls have no sight and are not listed.
        assert!(mover_contacts(&[&run(0, &[(1.0, 1.0, "collision: wall")])]).is_empty());
    }
}
