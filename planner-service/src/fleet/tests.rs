//! The fleet's rules on plain data: a real task database in a temporary folder, goals and
//! poses on the `junctions` floor plan the integration tests drive on, times passed in (no
//! Zenoh, no sleeping).

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use planning::Goal;
use protocol::{
    AgentState, AgentStatus, ControllerKind, Header, MapName, MapRef, Pose2D, PoseEstimate,
    RobotId, TaskId, TaskState,
};

use super::book::{Decision, Effect};
use super::core::Core;
use super::{ErrorKind, FleetConfig, NewTask, Now, TaskStateKind, TaskStore};

fn config() -> FleetConfig {
    FleetConfig {
        robot_timeout_ms: 600,
        pause_timeout_ms: 1500,
        max_plan_failures: 3,
        ..FleetConfig::default()
    }
}

fn open(dir: &Path, now: Now) -> (Core, Arc<TaskStore>, Vec<RobotId>) {
    let store = Arc::new(TaskStore::open(dir).unwrap());
    let (core, resumed) = Core::open(Arc::clone(&store), config(), now).unwrap();
    (core, store, resumed)
}

fn robot(id: &str) -> RobotId {
    RobotId::new(id).unwrap()
}

fn pose_on(map: &str, x: f64, y: f64) -> PoseEstimate {
    PoseEstimate {
        header: Header::new(1, 1_000_000),
        pose: Pose2D::new(x, y, 0.0),
        covariance: [0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.005],
        sensor_stamp_ns: 1_000_000,
        map: MapRef {
            name: MapName::new(map).unwrap(),
            version: 1,
        },
        unmapped_obstacles_m: Vec::new(),
    }
}

fn pose(x: f64, y: f64) -> PoseEstimate {
    pose_on("junctions", x, y)
}

fn status(localized: bool) -> AgentStatus {
    AgentStatus {
        header: Header::new(1, 1_000_000),
        state: AgentState::Idle,
        stop_reason: None,
        controller: ControllerKind::DynamicWindow,
        map: None,
        localized,
        recovering: false,
        backing_up: false,
        rotating_in_place: false,
        giving_way: false,
    }
}

fn new_task(robot_id: Option<&str>, goals: &[(f64, f64)]) -> NewTask {
    NewTask {
        map: MapName::new("junctions").unwrap(),
        robot_id: robot_id.map(robot),
        goals: goals.iter().map(|&(x, y)| Goal::at(x, y)).collect(),
    }
}

fn ms(t: Now, ms: u64) -> Now {
    t.after(Duration::from_millis(ms))
}

/// The task changes among `effects`: (new state, previous state).
fn announced(effects: &[Effect]) -> Vec<(TaskStateKind, Option<TaskStateKind>)> {
    effects
        .iter()
        .filter_map(|e| match e {
            Effect::Announce { task, before } => Some((task.kind(), *before)),
            _ => None,
        })
        .collect()
}

fn decision(core: &mut Core, id: &RobotId, p: &PoseEstimate, now: Now) -> Decision {
    core.begin_cycle(id, p, now, false).0.decision
}

fn state_of(store: &TaskStore, id: &TaskId) -> TaskState {
    store.get(id).unwrap().unwrap().state
}

#[test]
fn a_task_goes_from_created_through_each_goal_to_completed() {
    let dir = tempfile::tempdir().unwrap();
    let t0 = Now::read();
    let (mut core, store, resumed) = open(dir.path(), t0);
    assert!(resumed.is_empty());
    let r = robot("robot_1");
    let (seen, effects) = core.pose_arrived(&r, pose(3.0, 4.0), t0, false);
    assert!(seen.new && seen.came_back && !seen.event_due);
    assert!(effects.is_empty());

    // Queued, then at once assigned to the only free robot on the map.
    let (task, effects) = core
        .create(new_task(None, &[(8.0, 4.0), (13.0, 10.0)]), 1, t0)
        .unwrap();
    assert_eq!(
        task.state,
        TaskState::Assigned {
            robot_id: r.clone()
        }
    );
    use TaskStateKind::{Active, Assigned, Completed, Queued};
    assert_eq!(
        announced(&effects),
        [(Queued, None), (Assigned, Some(Queued))]
    );

    let heading = |next| Decision::Plan {
        task: task.id.clone(),
        goals: task.goals.clone(),
        next,
    };
    let (cycle, effects) = core.begin_cycle(&r, &pose(3.0, 4.0), ms(t0, 100), false);
    assert_eq!(cycle.decision, heading(0));
    assert_eq!(announced(&effects), [(Active, Some(Assigned))]);
    // On the way to the same goal: nothing to store or announce.
    let (cycle, effects) = core.begin_cycle(&r, &pose(5.0, 4.0), ms(t0, 200), false);
    assert_eq!((cycle.decision, effects), (heading(0), Vec::new()));
    // Within the tolerance of the first goal: on to the second.
    let (cycle, effects) = core.begin_cycle(&r, &pose(8.2, 4.1), ms(t0, 300), false);
    assert_eq!(cycle.decision, heading(1));
    assert_eq!(announced(&effects), [(Active, Some(Active))]);
    assert_eq!(
        state_of(&store, &task.id),
        TaskState::Active {
            robot_id: r.clone(),
            goal_index: 1
        }
    );
    // At the last goal: completed, and the robot is free.
    let (cycle, effects) = core.begin_cycle(&r, &pose(13.0, 10.2), ms(t0, 400), false);
    assert_eq!(cycle.decision, Decision::Completed(task.id.clone()));
    assert_eq!(announced(&effects), [(Completed, Some(Active))]);
    assert_eq!(core.book.task_of(&r), None);
    assert_eq!(core.view(&r).unwrap().task_id, None);
    assert_eq!(
        decision(&mut core, &r, &pose(13.0, 10.2), ms(t0, 500)),
        Decision::Idle
    );

    let stored = store.get(&task.id).unwrap().unwrap();
    let kinds: Vec<TaskStateKind> = stored
        .history
        .iter()
        .map(|h| TaskStateKind::of(&h.state))
        .collect();
    assert_eq!(kinds, [Queued, Assigned, Active, Active, Completed]);
    assert_eq!(stored.robot_id, Some(r));
}

#[test]
fn cancelling_a_running_task_stops_its_robot_and_a_second_cancel_conflicts() {
    let dir = tempfile::tempdir().unwrap();
    let t0 = Now::read();
    let (mut core, store, _) = open(dir.path(), t0);
    let r = robot("robot_1");
    core.pose_arrived(&r, pose(3.0, 4.0), t0, false);
    let (task, effects) = core
        .create(new_task(Some("robot_1"), &[(13.0, 10.0)]), 1, t0)
        .unwrap();
    assert_eq!(announced(&effects), [(TaskStateKind::Assigned, None)]);
    assert!(matches!(
        decision(&mut core, &r, &pose(3.0, 4.0), ms(t0, 100)),
        Decision::Plan { next: 0, .. }
    ));

    let (cancelled, effects) = core.cancel(&task.id, ms(t0, 200)).unwrap();
    assert_eq!(cancelled.state, TaskState::Cancelled);
    assert_eq!(state_of(&store, &task.id), TaskState::Cancelled);
    assert_eq!(
        announced(&effects),
        [(TaskStateKind::Cancelled, Some(TaskStateKind::Active))]
    );
    assert!(effects.contains(&Effect::Stop(r.clone())), "{effects:?}");
    assert_eq!(core.book.task_of(&r), None);
    assert_eq!(
        decision(&mut core, &r, &pose(3.0, 4.0), ms(t0, 300)),
        Decision::Idle
    );

    let again = core.cancel(&task.id, ms(t0, 400)).unwrap_err();
    assert_eq!(again.kind(), ErrorKind::Conflict);
    assert!(
        again.to_string().contains("already ended (cancelled)"),
        "{again}"
    );
    let missing = core
        .cancel(&TaskId::new("t-999999").unwrap(), ms(t0, 400))
        .unwrap_err();
    assert_eq!(missing.kind(), ErrorKind::NotFound, "{missing}");
}

#[test]
fn dispatch_picks_the_nearest_free_localized_online_robot_on_the_map_ties_by_id() {
    let dir = tempfile::tempdir().unwrap();
    let t0 = Now::read();
    let (mut core, _store, _) = open(dir.path(), t0);
    // Distances to the goal (8, 4): `gone` and `elsewhere` are nearest but cannot take it,
    // `unsure` is not localized, `busy` has a task; `robot_a` and `robot_b` tie.
    for (id, p) in [
        ("far", pose(3.0, 4.0)),
        ("unsure", pose(7.0, 4.0)),
        ("elsewhere", pose_on("depot", 8.0, 4.0)),
        ("gone", pose(8.2, 4.0)),
        ("busy", pose(8.0, 5.0)),
        ("robot_b", pose(6.0, 4.0)),
        ("robot_a", pose(10.0, 4.0)),
    ] {
        core.pose_arrived(&robot(id), p, t0, false);
    }
    core.status_arrived(&robot("unsure"), status(false), t0);
    core.robot_left(&robot("gone"), "robot left", t0);
    core.create(new_task(Some("busy"), &[(13.0, 10.0)]), 1, t0)
        .unwrap();

    let goal = [(8.0, 4.0)];
    let robot_of = |core: &mut Core| {
        let (task, _) = core.create(new_task(None, &goal), 1, t0).unwrap();
        (task.state.robot_id().cloned(), task.id)
    };
    assert_eq!(robot_of(&mut core).0, Some(robot("robot_a")));
    assert_eq!(robot_of(&mut core).0, Some(robot("robot_b")));
    assert_eq!(robot_of(&mut core).0, Some(robot("far")));
    // No one left: both wait, and the older goes first once a robot can take one.
    let (none, older) = robot_of(&mut core);
    let (_, newer) = robot_of(&mut core);
    assert_eq!(none, None);
    let (_, effects) = core.status_arrived(&robot("unsure"), status(true), ms(t0, 100));
    assert!(
        announced(&effects).is_empty(),
        "a status alone dispatches nothing"
    );
    let (_, effects) = core.watchdog(ms(t0, 200));
    assert_eq!(
        announced(&effects),
        [(TaskStateKind::Assigned, Some(TaskStateKind::Queued))]
    );
    assert_eq!(core.book.task_of(&robot("unsure")), Some(&older));
    assert_eq!(core.book.task(&newer).unwrap().state, TaskState::Queued);
}

#[test]
fn the_queue_per_map_goes_oldest_first_and_forgets_cancelled_and_assigned_tasks() {
    let dir = tempfile::tempdir().unwrap();
    let t0 = Now::read();
    let (mut core, _store, _) = open(dir.path(), t0);
    let on_depot = |goal: (f64, f64)| NewTask {
        map: MapName::new("depot").unwrap(),
        ..new_task(None, &[goal])
    };
    // A backlog on a map no robot is on, and three tasks waiting on `junctions`.
    for i in 0..50 {
        core.create(on_depot((1.0 + f64::from(i) * 0.1, 1.0)), 1, ms(t0, 0))
            .unwrap();
    }
    let mut waiting = Vec::new();
    for i in 0..3 {
        let (task, _) = core
            .create(new_task(None, &[(8.0, 4.0)]), 1, ms(t0, 1 + i))
            .unwrap();
        assert_eq!(task.state, TaskState::Queued);
        waiting.push(task.id);
    }
    core.cancel(&waiting[0], ms(t0, 10)).unwrap();

    // The first free robot on `junctions` takes the oldest task still queued there, the
    // second the next; the depot backlog stays as it is.
    let (_, effects) = core.pose_arrived(&robot("robot_a"), pose(3.0, 4.0), ms(t0, 20), false);
    assert_eq!(
        announced(&effects),
        [(TaskStateKind::Assigned, Some(TaskStateKind::Queued))]
    );
    assert_eq!(core.book.task_of(&robot("robot_a")), Some(&waiting[1]));
    core.pose_arrived(&robot("robot_b"), pose(3.0, 6.0), ms(t0, 30), false);
    assert_eq!(core.book.task_of(&robot("robot_b")), Some(&waiting[2]));
    let (_, effects) = core.pose_arrived(&robot("robot_c"), pose(3.0, 6.0), ms(t0, 40), false);
    assert!(announced(&effects).is_empty(), "{effects:?}");
    // A robot on the depot takes the depot's oldest.
    core.pose_arrived(
        &robot("robot_d"),
        pose_on("depot", 0.0, 0.0),
        ms(t0, 50),
        false,
    );
    let first_depot = core.book.task_of(&robot("robot_d")).cloned().unwrap();
    assert_eq!(first_depot.as_str(), "t-000001");
}

#[test]
fn a_silent_robot_pauses_its_task_resumes_when_it_reports_and_fails_after_the_pause_timeout() {
    let dir = tempfile::tempdir().unwrap();
    let t0 = Now::read();
    let (mut core, store, _) = open(dir.path(), t0);
    let r = robot("robot_1");
    core.pose_arrived(&r, pose(3.0, 4.0), t0, false);
    let (task, _) = core
        .create(new_task(Some("robot_1"), &[(13.0, 10.0)]), 1, t0)
        .unwrap();
    decision(&mut core, &r, &pose(3.0, 4.0), t0);
    let mut driving = status(true);
    driving.state = AgentState::Driving;
    core.status_arrived(&r, driving, t0);
    use TaskStateKind::{Active, Failed, Paused};

    let (counts, effects) = core.watchdog(ms(t0, 500));
    assert_eq!((counts.online, counts.offline), (1, 0));
    assert!(effects.is_empty(), "{effects:?}");
    // Silent past robot_timeout_ms: offline, and the task paused with the reason.
    let (_, effects) = core.watchdog(ms(t0, 700));
    assert_eq!(announced(&effects), [(Paused, Some(Active))]);
    // Offline, and no longer saying `driving`.
    assert!(effects
        .iter()
        .any(|e| matches!(e, Effect::Robot(v) if v.id == r && !v.online && v.status.is_none())));
    match state_of(&store, &task.id) {
        TaskState::Paused { reason, .. } => {
            assert_eq!(reason, "robot robot_1 sent no pose for over 600 ms");
        }
        other => panic!("{other:?}"),
    }
    let (counts, effects) = core.watchdog(ms(t0, 800));
    assert_eq!((counts.online, counts.offline), (0, 1));
    assert!(effects.is_empty(), "paused once: {effects:?}");

    // It reports again: its next cycle resumes the task where it was.
    let (seen, _) = core.pose_arrived(&r, pose(3.5, 4.0), ms(t0, 1000), false);
    assert!(seen.came_back && !seen.new);
    let (cycle, effects) = core.begin_cycle(&r, &pose(3.5, 4.0), ms(t0, 1000), false);
    assert!(matches!(cycle.decision, Decision::Plan { next: 0, .. }));
    assert_eq!(announced(&effects), [(Active, Some(Paused))]);

    // Silent again, and this time for longer than pause_timeout_ms: failed, robot free.
    let (_, effects) = core.watchdog(ms(t0, 1700));
    assert_eq!(announced(&effects), [(Paused, Some(Active))]);
    let (_, effects) = core.watchdog(ms(t0, 3200));
    assert!(announced(&effects).is_empty(), "not over the timeout yet");
    let (_, effects) = core.watchdog(ms(t0, 3300));
    assert_eq!(announced(&effects), [(Failed, Some(Paused))]);
    assert_eq!(
        state_of(&store, &task.id),
        TaskState::Failed {
            reason: "robot robot_1 did not come back within 1 s".into()
        }
    );
    assert_eq!(core.book.task_of(&r), None);
}

#[test]
fn a_task_on_another_map_than_the_robots_pose_is_not_advanced() {
    let dir = tempfile::tempdir().unwrap();
    let t0 = Now::read();
    let (mut core, store, _) = open(dir.path(), t0);
    // Known from its status only: it can be given a task on any map.
    let r = robot("robot_1");
    core.status_arrived(&r, status(true), t0);
    let (task, _) = core
        .create(new_task(Some("robot_1"), &[(8.0, 4.0)]), 1, t0)
        .unwrap();
    core.pose_arrived(&r, pose_on("depot", 8.0, 4.0), t0, false);
    let (cycle, effects) = core.begin_cycle(&r, &pose_on("depot", 8.0, 4.0), t0, false);
    assert_eq!(cycle.decision, Decision::OtherMap);
    assert!(effects.is_empty());
    assert_eq!(
        state_of(&store, &task.id),
        TaskState::Assigned {
            robot_id: r.clone()
        }
    );
    // A robot localized on another map is refused a task, and nothing is stored.
    let other = robot("robot_2");
    core.pose_arrived(&other, pose_on("depot", 3.0, 4.0), t0, false);
    let err = core
        .create(new_task(Some("robot_2"), &[(8.0, 4.0)]), 1, t0)
        .unwrap_err();
    assert_eq!(err.kind(), ErrorKind::Conflict);
    assert!(err.to_string().contains("localizes on map depot"), "{err}");
    let busy = core
        .create(new_task(Some("robot_1"), &[(8.0, 4.0)]), 1, t0)
        .unwrap_err();
    assert!(busy.to_string().contains("busy with task"), "{busy}");
    let ghost = core
        .create(new_task(Some("ghost"), &[(8.0, 4.0)]), 1, t0)
        .unwrap_err();
    assert_eq!(ghost.kind(), ErrorKind::NotFound);
    assert_eq!(store.all().unwrap().len(), 1);
}

#[test]
fn max_plan_failures_in_a_row_fail_the_task() {
    let dir = tempfile::tempdir().unwrap();
    let t0 = Now::read();
    let (mut core, store, _) = open(dir.path(), t0);
    let r = robot("robot_1");
    core.pose_arrived(&r, pose(3.0, 4.0), t0, false);
    let (task, _) = core
        .create(new_task(Some("robot_1"), &[(13.0, 10.0)]), 1, t0)
        .unwrap();
    decision(&mut core, &r, &pose(3.0, 4.0), t0);
    let fail = |core: &mut Core| core.plan_failed(&r, None, &task.id, 0, "no path", t0);
    assert!(fail(&mut core).is_empty());
    assert!(fail(&mut core).is_empty());
    // A path found in between starts the count over.
    core.planned(&r, None, None, t0);
    assert!(fail(&mut core).is_empty());
    assert!(fail(&mut core).is_empty());
    let effects = fail(&mut core);
    assert_eq!(
        announced(&effects),
        [(TaskStateKind::Failed, Some(TaskStateKind::Active))]
    );
    assert_eq!(
        state_of(&store, &task.id),
        TaskState::Failed {
            reason: "no path to goal 0 after 3 tries: no path".into()
        }
    );
    assert_eq!(core.book.task_of(&r), None);
}

#[test]
fn a_restart_resumes_the_stored_unfinished_tasks() {
    let dir = tempfile::tempdir().unwrap();
    let t0 = Now::read();
    let (r1, r2, r3) = (robot("robot_1"), robot("robot_2"), robot("robot_3"));
    let (active, paused, queued) = {
        let (mut core, _store, _) = open(dir.path(), t0);
        core.pose_arrived(&r1, pose(3.0, 4.0), t0, false);
        core.pose_arrived(&r2, pose(3.0, 6.0), t0, false);
        let goals = [(8.0, 4.0), (13.0, 10.0)];
        let (active, _) = core
            .create(new_task(Some("robot_1"), &goals), 1, t0)
            .unwrap();
        decision(&mut core, &r1, &pose(8.0, 4.0), t0);
        let (paused, _) = core
            .create(new_task(Some("robot_2"), &goals), 1, t0)
            .unwrap();
        core.robot_left(&r2, "robot left", t0);
        let (queued, _) = core.create(new_task(None, &goals), 1, t0).unwrap();
        assert_eq!(queued.state, TaskState::Queued);
        (active.id, paused.id, queued.id)
    };

    let t1 = ms(t0, 10_000);
    let (mut core, store, mut resumed) = open(dir.path(), t1);
    resumed.sort();
    assert_eq!(resumed, [r1.clone(), r2.clone()]);
    let view = core.view(&r1).unwrap();
    assert_eq!((view.online, view.task_id.as_ref()), (false, Some(&active)));
    assert_eq!(core.book.task_of(&r2), Some(&paused));
    // robot_1 reports and goes on from the goal it had reached.
    core.pose_arrived(&r1, pose(8.0, 4.0), t1, false);
    let (cycle, effects) = core.begin_cycle(&r1, &pose(8.0, 4.0), t1, false);
    assert!(matches!(cycle.decision, Decision::Plan { next: 1, ref task, .. } if task == &active));
    assert!(effects.is_empty(), "still active on goal 1: {effects:?}");
    // A new robot takes the queued task.
    let (_, effects) = core.pose_arrived(&r3, pose(3.0, 6.0), t1, false);
    assert_eq!(
        announced(&effects),
        [(TaskStateKind::Assigned, Some(TaskStateKind::Queued))]
    );
    assert_eq!(core.book.task_of(&r3), Some(&queued));
    // robot_2 never comes back: its task's pause timer started at the restart.
    core.pose_arrived(&r1, pose(8.5, 4.5), ms(t1, 1400), false);
    core.pose_arrived(&r3, pose(3.0, 6.0), ms(t1, 1400), false);
    core.watchdog(ms(t1, 1400));
    assert!(matches!(
        state_of(&store, &paused),
        TaskState::Paused { .. }
    ));
    core.watchdog(ms(t1, 1600));
    assert!(matches!(
        state_of(&store, &paused),
        TaskState::Failed { .. }
    ));
    assert_eq!(core.book.task_of(&r2), None);
}

#[test]
fn robot_events_are_made_only_for_watchers_and_at_most_every_interval() {
    let dir = tempfile::tempdir().unwrap();
    let t0 = Now::read();
    let (mut core, _store, _) = open(dir.path(), t0);
    let r = robot("robot_1");
    let events = |effects: &[Effect]| {
        effects
            .iter()
            .filter(|e| matches!(e, Effect::Robot(_)))
            .count()
    };
    let (_, effects) = core.pose_arrived(&r, pose(3.0, 4.0), t0, false);
    assert_eq!(events(&effects), 0, "nobody watches");
    let (_, effects) = core.pose_arrived(&r, pose(3.1, 4.0), ms(t0, 10), true);
    assert_eq!(events(&effects), 1);
    let (_, effects) = core.pose_arrived(&r, pose(3.2, 4.0), ms(t0, 60), true);
    assert_eq!(events(&effects), 0, "within robot_event_interval_ms");
    let (_, effects) = core.pose_arrived(&r, pose(3.3, 4.0), ms(t0, 110), true);
    assert_eq!(events(&effects), 1);
    // A status event only when what the dashboard shows changed.
    let (new, effects) = core.status_arrived(&r, status(true), ms(t0, 120));
    assert_eq!((new, events(&effects)), (false, 1));
    let (_, effects) = core.status_arrived(&r, status(true), ms(t0, 130));
    assert_eq!(events(&effects), 0);
}

#[test]
fn a_cycle_names_the_other_robots_near_it_on_its_map() {
    let dir = tempfile::tempdir().unwrap();
    let t0 = Now::read();
    let (mut core, _store, _) = open(dir.path(), t0);
    let r1 = robot("robot_1");
    // The robot, then others: near on the same map, far on the same map, near on another
    // map, and near but silent (last, so the loop below leaves it out).
    let robots = [
        ("robot_1", pose(3.0, 4.0)),
        ("near", pose(5.0, 4.5)),
        ("far", pose(13.0, 10.0)),
        ("elsewhere", pose_on("depot", 3.5, 4.0)),
        ("silent", pose(3.0, 5.0)),
    ];
    for (id, p) in &robots {
        core.pose_arrived(&robot(id), p.clone(), t0, false);
    }
    core.create(new_task(Some("robot_1"), &[(13.0, 10.0)]), 1, t0)
        .unwrap();
    // "silent" sends nothing more and is marked offline by the watchdog.
    let later = ms(t0, 700);
    for (id, p) in &robots[..4] {
        core.pose_arrived(&robot(id), p.clone(), later, false);
    }
    core.watchdog(later);
    let (cycle, _) = core.begin_cycle(&r1, &pose(3.0, 4.0), later, false);
    assert!(matches!(cycle.decision, Decision::Plan { .. }));
    assert_eq!(cycle.neighbours.len(), 1);
    assert_eq!(cycle.neighbours[0].pose, Pose2D::new(5.0, 4.5, 0.0));

    // None to a robot with nothing to plan, and none when the radius is 0.
    let (idle, _) = core.begin_cycle(&robot("near"), &pose(5.0, 4.5), later, false);
    assert!(idle.neighbours.is_empty());
    let dir = tempfile::tempdir().unwrap();
    let store = Arc::new(TaskStore::open(dir.path()).unwrap());
    let off = FleetConfig {
        neighbour_radius_m: 0.0,
        ..config()
    };
    let (mut core, _) = Core::open(store, off, t0).unwrap();
    core.pose_arrived(&r1, pose(3.0, 4.0), t0, false);
    core.pose_arrived(&robot("near"), pose(5.0, 4.5), t0, false);
    core.create(new_task(Some("robot_1"), &[(13.0, 10.0)]), 1, t0)
        .unwrap();
    let (cycle, _) = core.begin_cycle(&r1, &pose(3.0, 4.0), t0, false);
    assert!(matches!(cycle.decision, Decision::Plan { .. }));
    assert!(cycle.neighbours.is_empty());
}

#[test]
fn a_robot_s_velocity_comes_from_its_last_poses() {
    let dir = tempfile::tempdir().unwrap();
    let t0 = Now::read();
    let (mut core, _store, _) = open(dir.path(), t0);
    let r = robot("robot_1");
    let at = |x: f64, stamp_ms: u64| PoseEstimate {
        header: Header::new(stamp_ms, stamp_ms * 1_000_000),
        ..pose(x, 4.0)
    };
    let velocity = |core: &Core| core.registry.get(&r).unwrap().velocity_mps;
    core.pose_arrived(&r, at(3.0, 1000), t0, false);
    assert_eq!(velocity(&core), (0.0, 0.0));
    // 5 cm in 0.1 s, twice: 0.25 then 0.375 m/s (half the step's, half the old).
    core.pose_arrived(&r, at(3.05, 1100), t0, false);
    assert!(
        (velocity(&core).0 - 0.25).abs() < 1e-9,
        "{:?}",
        velocity(&core)
    );
    core.pose_arrived(&r, at(3.1, 1200), t0, false);
    assert!(
        (velocity(&core).0 - 0.375).abs() < 1e-9,
        "{:?}",
        velocity(&core)
    );
    // After a gap of more than a second the robot is taken as standing.
    core.pose_arrived(&r, at(3.2, 3000), t0, false);
    assert_eq!(velocity(&core), (0.0, 0.0));
}
