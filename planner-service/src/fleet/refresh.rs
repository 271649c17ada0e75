//! Kept plans' due new searches, run off the answer path on threads of the lowest priority.
//!
//! With path reuse a robot's kept plan answers a pose in tens of microseconds, and every
//! `max_cycles` answers a new search is due, which takes milliseconds of CPU. Run at the same
//! priority as the answers, on a busy machine, the scheduler shares the cores evenly between
//! them and answers wait behind searches: 250 robots at 10 Hz on two cores had a p99 of
//! 3 ms with no due searches and 40–130 ms with them (docs/benchmarks.md). The pool's threads
//! run at nice 19, so every robot's answer goes first and the searches take the time that is
//! left, while the kept plan goes on answering (planning's `IntentionPlanner::take_refresh`).

use std::sync::mpsc;
use std::sync::{Arc, Mutex};

use planning::{PlanError, Planner, RefreshJob, Refreshed};
use tokio::sync::oneshot;

use super::lock;

/// A search's result, on its way back to the robot's worker.
pub(crate) type RefreshReply = oneshot::Receiver<Result<Refreshed, PlanError>>;

struct Job {
    job: RefreshJob,
    reply: oneshot::Sender<Result<Refreshed, PlanError>>,
}

/// The low-priority search threads of one process (see the module docs); they end when the
/// pool is dropped.
#[derive(Debug)]
pub(crate) struct RefreshPool {
    jobs: mpsc::Sender<Job>,
}

impl RefreshPool {
    /// Starts `threads` search threads (at least one).
    pub fn start(threads: usize) -> Self {
        let (jobs, rx) = mpsc::channel::<Job>();
        let rx = Arc::new(Mutex::new(rx));
        for i in 0..threads.max(1) {
            let rx = Arc::clone(&rx);
            let started = std::thread::Builder::new()
                .name(format!("refresh-{i}"))
                .spawn(move || serve(&rx));
            if let Err(e) = started {
                // The others serve; with none, due searches wait and the kept plans answer on.
                tracing::warn!("cannot start a search thread: {e}");
            }
        }
        Self { jobs }
    }

    /// Queues `job`; its result comes back on the receiver (dropped unanswered when the pool
    /// is gone). The queue needs no bound: a robot has at most one search due at a time.
    pub fn submit(&self, job: RefreshJob) -> RefreshReply {
        let (reply, rx) = oneshot::channel();
        // A send fails only once every thread has ended: the reply is dropped with the job.
        let _ = self.jobs.send(Job { job, reply });
        rx
    }
}

/// One search thread: planners kept per configuration, so their buffers are reused.
fn serve(jobs: &Mutex<mpsc::Receiver<Job>>) {
    lower_priority();
    let mut planners: Vec<Planner> = Vec::new();
    loop {
        let next = lock(jobs).recv();
        let Ok(Job { job, reply }) = next else {
            return;
        };
        let found = planners
            .iter()
            .position(|p| p.config() == job.planner_config());
        let planner = match found {
            Some(i) => &mut planners[i],
            None => match Planner::new(Arc::clone(job.map()), job.planner_config().clone()) {
                Ok(p) => {
                    planners.push(p);
                    let last = planners.len() - 1;
                    &mut planners[last]
                }
                Err(e) => {
                    let _ = reply.send(Err(e));
                    continue;
                }
            },
        };
        // The worker may have gone meanwhile: nobody waits for the result then.
        let _ = reply.send(job.run(planner));
    }
}

/// Nice 19 for the calling thread (Linux's `setpriority` on a thread id sets that thread's).
fn lower_priority() {
    let tid = rustix::thread::gettid();
    if let Err(e) = rustix::process::setpriority_process(Some(tid), 19) {
        tracing::warn!("search thread keeps its priority: {e}");
    }
}

#[cfg(test)]
mod tests {
    use planning::{Answer, Goal, GoalProgress, IntentionConfig, IntentionPlanner, PlanningMap};
    use protocol::{Header, MapName, MapRef, Pose2D, PoseEstimate};

    use super::*;

    fn estimate(pose: Pose2D) -> PoseEstimate {
        PoseEstimate {
            header: Header::new(1, 1),
            pose,
            covariance: [0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.003],
            sensor_stamp_ns: 1,
            map: MapRef {
                name: MapName::new("depot").unwrap(),
                version: 1,
            },
            unmapped_obstacles_m: Vec::new(),
        }
    }

    /// A due search goes to the pool, runs on a thread of nice 19 and comes back as a plan
    /// that the pipeline adopts.
    #[tokio::test]
    async fn a_due_search_runs_on_a_low_priority_thread_and_comes_back() {
        let mut config = IntentionConfig::default();
        config.reuse.enabled = true;
        config.reuse.max_cycles = 1;
        let map =
            Arc::new(PlanningMap::new(test_support::nav2_map("depot"), &config.planner).unwrap());
        let (start, end) = planning::sample::sample_pairs(&map, 1, 5, 6.0, "depot").unwrap()[0];
        let goals = [Goal::at(end.x_m, end.y_m)];
        let mut p = IntentionPlanner::new(map, config).unwrap();
        let answer = |p: &mut IntentionPlanner, pose| match p.answer(
            &estimate(pose),
            &GoalProgress::new(&goals, 0),
            false,
        ) {
            Answer::Heading { plan, .. } => plan.unwrap(),
            Answer::Done => panic!("done at the start"),
        };
        let first = answer(&mut p, start);
        assert!(!first.reused);
        assert!(answer(&mut p, first.path[1]).reused);
        let job = p
            .take_refresh()
            .expect("one answer from the plan: a search is due");
        let pool = RefreshPool::start(1);
        let refreshed = pool.submit(job).await.expect("answered");
        p.adopt(refreshed).unwrap();
        assert!(answer(&mut p, first.path[1]).reused);

        let nice = std::fs::read_dir("/proc/self/task")
            .unwrap()
            .filter_map(|t| {
                let dir = t.unwrap().path();
                let comm = std::fs::read_to_string(dir.join("comm")).unwrap();
                (comm.trim() == "refresh-0").then(|| {
                    let stat = std::fs::read_to_string(dir.join("stat")).unwrap();
                    // The fields after the command's closing parenthesis; nice is the 19th.
                    let rest = &stat[stat.rfind(')').unwrap() + 2..];
                    rest.split(' ').nth(16).unwrap().parse::<i32>().unwrap()
                })
            })
            .collect::<Vec<_>>();
        assert_eq!(nice, [19]);
    }
}
