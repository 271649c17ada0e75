//! Scripted encounters (`eval record --encounters P`): each kind fits on a real training
//! scenario's routes, a glass door really closes the passage from wall to wall, and the
//! privileged expert, which labels these episodes, stops short of the door, keeps clear of the
//! people without contact, goes round a parked robot and furniture in its way and through the
//! middle of an open glass door the drawn path passes off-centre.

#![allow(clippy::unwrap_used)]
use std::collections::BTreeMap;

use eval::record::encounter::{self, Encounter};
use eval::table::run::{run_with, Prepared};
use eval::table::TableOptions;
use protocol::ControllerKind;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sim::geom::Obb;
use sim::scenario::{PointSpec, PoseSpec};
use sim::{SimConfig, World};

/// Scenarios with their encounters, found over random start/goal pairs of one training map.
fn encounters_on(name: &str) -> (Prepared, BTreeMap<Encounter, Prepared>) {
    let path = test_support::scenarios_dir().join(name);
    let options = TableOptions::default();
    let base = Prepared::load(&path, &options).unwrap();
    let world = World::new(
        base.scenario.clone(),
        base.plan.clone(),
        SimConfig::default(),
    )
    .unwrap();
    let pairs = planning::sample::sample_pairs(&base.planning, 60, 7, 8.0, name).unwrap();
    let mut found = BTreeMap::new();
    for (i, (start, goal)) in pairs.iter().enumerate() {
        if world
            .disc_overlap(start.x_m, start.y_m, 0.4, None, true)
            .is_some()
            || world
                .disc_overlap(goal.x_m, goal.y_m, 0.5, None, false)
                .is_some()
        {
            continue;
        }
        for kind in Encounter::ALL {
            if found.contains_key(&kind) {
                continue;
            }
            let mut scenario = base.scenario.clone();
            scenario.start = PoseSpec {
                x_m: start.x_m,
                y_m: start.y_m,
                yaw_rad: start.yaw_rad,
            };
            scenario.goals = vec![PointSpec {
                x_m: goal.x_m,
                y_m: goal.y_m,
            }];
            let added = encounter::add_first_fitting(
                &mut scenario,
                &base.planning,
                &options.intention.planner,
                &world,
                *start,
                (goal.x_m, goal.y_m),
                &[kind],
                &mut ChaCha8Rng::seed_from_u64(i as u64),
            );
            if added == Some(kind) {
                let prepared = Prepared::new(&path, scenario, base.plan.clone(), &options).unwrap();
                found.insert(kind, prepared);
            }
        }
        if found.len() == Encounter::ALL.len() {
            break;
        }
    }
    (base, found)
}

/// The floor plan's path from the scenario's start to its first goal.
fn first_leg(base: &Prepared, s: &sim::Scenario, options: &TableOptions) -> planning::Path {
    let mut planner = planning::Planner::new(
        std::sync::Arc::clone(&base.planning),
        options.intention.planner.clone(),
    )
    .unwrap();
    let start = protocol::Pose2D::new(s.start.x_m, s.start.y_m, s.start.yaw_rad);
    let goal = planning::Goal::at(s.goals[0].x_m, s.goals[0].y_m).pose_from(start);
    planner.plan(start, goal).unwrap()
}

/// The middle of the opening an open glass door's two panes leave (right pane, then left).
fn opening_middle(panes: &[sim::scenario::GlassSpec]) -> (f64, f64) {
    (
        0.5 * (panes[0].x1_m + panes[1].x0_m),
        0.5 * (panes[0].y1_m + panes[1].y0_m),
    )
}

#[test]
fn every_kind_fits_and_the_expert_handles_it_without_contact() {
    let (base, found) = encounters_on("train_office.yaml");
    assert_eq!(
        found.keys().copied().collect::<Vec<_>>(),
        Encounter::ALL.to_vec(),
        "not every kind fitted on train_office"
    );
    let options = TableOptions {
        time_limit_s: Some(75.0),
        // No intervention: the expert must hold before the door by itself.
        stuck_timeout_s: 1000.0,
        ..TableOptions::default()
    };
    for (kind, prepared) in &found {
        let s = &prepared.scenario;
        match kind {
            Encounter::GlassDoor => {
                assert_eq!(s.glass.len(), base.scenario.glass.len() + 1);
                let pane = s.glass.last().unwrap();
                let width = (pane.x1_m - pane.x0_m).hypot(pane.y1_m - pane.y0_m);
                assert!((0.5..=3.2).contains(&width), "door {width} m wide");
                // Both ends sit in the floor plan's walls: no gap to slip through.
                for (x, y) in [(pane.x0_m, pane.y0_m), (pane.x1_m, pane.y1_m)] {
                    let g = base.planning.to_grid(protocol::Pose2D::new(x, y, 0.0));
                    let clearance_m = base.planning.clearance_m(g.x_m, g.y_m);
                    assert!(
                        clearance_m < 0.06,
                        "door end ({x}, {y}) is {clearance_m} m from a wall"
                    );
                }
            }
            Encounter::RobotParked => {
                assert_eq!(s.parked_robots.len(), base.scenario.parked_robots.len() + 1);
                let parked = s.parked_robots.last().unwrap();
                let from_start = (parked.x_m - s.start.x_m).hypot(parked.y_m - s.start.y_m);
                assert!(from_start >= 2.0, "parked {from_start} m from the start");
            }
            Encounter::Furniture => {
                assert_eq!(s.furniture.len(), base.scenario.furniture.len() + 1);
                let shape = s.furniture.last().unwrap().shape();
                assert!(shape.distance(s.start.x_m, s.start.y_m) >= 0.5);
                // It stands in the way of a robot keeping to the floor plan's path ...
                let path = first_leg(&base, s, &options);
                let closest_m = path
                    .poses
                    .iter()
                    .map(|p| shape.distance(p.x_m, p.y_m))
                    .fold(f64::INFINITY, f64::min);
                assert!(closest_m < 0.25, "the path passes {closest_m} m from it");
                eprintln!(
                    "furniture {:?} path {} m from {:?}",
                    s.furniture.last(),
                    path.length_m,
                    s.start
                );
                // ... and leaves a passage beside it.
                let world = World::new(s.clone(), base.plan.clone(), SimConfig::default()).unwrap();
                let free = path.poses.iter().any(|p| {
                    (1..=12).any(|k| {
                        let (nx, ny) = (-p.yaw_rad.sin(), p.yaw_rad.cos());
                        [1.0, -1.0].iter().any(|side| {
                            let d = side * 0.1 * f64::from(k);
                            let (x, y) = (p.x_m + d * nx, p.y_m + d * ny);
                            shape.distance(x, y) < 0.8
                                && world.disc_overlap(x, y, 0.45, None, false).is_none()
                        })
                    })
                });
                assert!(free, "no 0.9 m passage beside the furniture");
            }
            Encounter::OpenGlassDoor => {
                assert_eq!(s.glass.len(), base.scenario.glass.len() + 2);
                let panes = &s.glass[s.glass.len() - 2..];
                // Each pane starts in a wall; the other ends leave the opening between them.
                let wall_m = |x: f64, y: f64| {
                    let g = base.planning.to_grid(protocol::Pose2D::new(x, y, 0.0));
                    base.planning.clearance_m(g.x_m, g.y_m)
                };
                assert!(wall_m(panes[0].x0_m, panes[0].y0_m) < 0.06, "{panes:?}");
                assert!(wall_m(panes[1].x1_m, panes[1].y1_m) < 0.06, "{panes:?}");
                let opening_m =
                    (panes[1].x0_m - panes[0].x1_m).hypot(panes[1].y0_m - panes[0].y1_m);
                assert!((0.98..=1.42).contains(&opening_m), "opening {opening_m} m");
                // The drawn path goes through the opening, off its middle by at most 0.35 m.
                let path = first_leg(&base, s, &options);
                let middle = opening_middle(panes);
                let off_m = path
                    .poses
                    .iter()
                    .map(|p| (p.x_m - middle.0).hypot(p.y_m - middle.1))
                    .fold(f64::INFINITY, f64::min);
                assert!(
                    off_m <= 0.4,
                    "the path passes {off_m} m from the opening's middle"
                );
            }
            Encounter::PersonThroughDoor => {
                assert_eq!(s.glass.len(), base.scenario.glass.len() + 2);
                assert_eq!(s.people.len(), base.scenario.people.len() + 1);
                let panes = &s.glass[s.glass.len() - 2..];
                let middle = opening_middle(panes);
                let door_m = (middle.0 - s.start.x_m).hypot(middle.1 - s.start.y_m);
                let (lo, hi) = encounter::THROUGH_DOOR_M;
                assert!(
                    (lo - 0.5..=hi + 0.5).contains(&door_m),
                    "the door is {door_m} m from the start"
                );
                // The person sets off beyond the door and walks through its opening's middle.
                let person = s.people.last().unwrap();
                let first = &person.route[0];
                let set_off_m = (first.x_m - s.start.x_m).hypot(first.y_m - s.start.y_m);
                assert!(set_off_m > door_m + 0.5, "sets off {set_off_m} m out");
                let through_m = person
                    .route
                    .windows(2)
                    .map(|w| {
                        Obb::from_segment(w[0].x_m, w[0].y_m, w[1].x_m, w[1].y_m, 0.0)
                            .distance(middle.0, middle.1)
                    })
                    .fold(f64::INFINITY, f64::min);
                assert!(
                    through_m < 0.05,
                    "the route passes {through_m} m from the opening's middle"
                );
            }
            Encounter::PersonAhead
            | Encounter::PersonOncoming
            | Encounter::PersonHeadOn
            | Encounter::PersonHeadOnNear => {
                assert_eq!(s.people.len(), base.scenario.people.len() + 1);
                let person = s.people.last().unwrap();
                let first = &person.route[0];
                let from_start = (first.x_m - s.start.x_m).hypot(first.y_m - s.start.y_m);
                assert!(
                    from_start >= 2.0,
                    "{kind:?} starts {from_start} m from the robot"
                );
                if *kind == Encounter::PersonHeadOnNear {
                    // Near enough to meet within seconds of the start, not 7-18 m off.
                    let (_, hi) = encounter::HEAD_ON_NEAR_M;
                    assert!(
                        from_start <= hi + 0.2,
                        "a near head-on person sets off {from_start} m from the robot"
                    );
                }
                if matches!(kind, Encounter::PersonHeadOn | Encounter::PersonHeadOnNear) {
                    // Along the robot's own line, up to its start: they must meet.
                    let path = first_leg(&base, s, &options);
                    for q in &person.route {
                        let off_m = path
                            .poses
                            .iter()
                            .map(|p| (p.x_m - q.x_m).hypot(p.y_m - q.y_m))
                            .fold(f64::INFINITY, f64::min);
                        let behind_m = (q.x_m - s.start.x_m).hypot(q.y_m - s.start.y_m);
                        assert!(
                            off_m < 0.2 || behind_m < 2.6,
                            "route point {q:?} {off_m} m off the path"
                        );
                    }
                    let last = person.route.last().unwrap();
                    let (p0, p1) = (&path.poses[0], &path.poses[1]);
                    let heading = (p1.y_m - p0.y_m).atan2(p1.x_m - p0.x_m);
                    let (dx, dy) = (last.x_m - p0.x_m, last.y_m - p0.y_m);
                    let ahead_m = dx * heading.cos() + dy * heading.sin();
                    // (A wall behind the start cuts the route short there.)
                    assert!(
                        ahead_m < 0.5,
                        "the route ends {ahead_m} m ahead of the start"
                    );
                }
            }
        }
        let (result, _) =
            run_with(prepared, ControllerKind::Expert, 1, &options, |_| {}, None).unwrap();
        assert_eq!(result.collisions.glass, 0, "{kind:?}: {result:?}");
        assert_eq!(result.collisions.person, 0, "{kind:?}: {result:?}");
        assert_eq!(result.collisions.robot, 0, "{kind:?}: {result:?}");
        if *kind == Encounter::Furniture {
            assert_eq!(result.collisions.furniture, 0, "{result:?}");
        }
        if matches!(
            kind,
            Encounter::RobotParked
                | Encounter::Furniture
                | Encounter::OpenGlassDoor
                | Encounter::PersonThroughDoor
        ) {
            // Gone round (or through), not followed or waited at for ever.
            assert_eq!(result.goals_reached, 1, "{result:?}");
        }
        if *kind == Encounter::GlassDoor {
            assert_eq!(result.goals_reached, 0, "the door closes the only way");
            assert!(result.min_glass_distance_m.unwrap() > 0.02, "{result:?}");
            // It drove up to the door rather than refusing to start.
            assert!(result.path_length_m > 2.0, "{result:?}");
        }
    }
}
