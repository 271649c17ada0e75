//! The fleet demo (`planner-service demo`): the whole system on one machine.
//!
//! In this process: the planner service (HTTP API + dashboard, map server, fleet core) on an
//! embedded store with the scenario's floor plans (and the Nav2 reference maps when the shared
//! folder is found) preloaded. As separate processes talking to it over Zenoh on loopback, started
//! by [`crate::launch`]: the simulator with N robots and one `robot-agent` per robot. It prints the
//! dashboard URL and the token and runs until Ctrl-C or SIGTERM, then stops the agents, the
//! simulator and the service, in that order.
//!
//! It supervises the agents as a process manager would: an agent that exits (a crash, a kill)
//! is started again with back-off ([`crate::restart`], `[demo.agent_restart]`), localizing from
//! the pose the service last heard from it. Meanwhile the service sees the robot fall silent,
//! marks it offline and pauses its task, and resumes the task when the new agent reports, as it
//! does for agents that run on their own. The simulator is the world: when it exits the demo
//! stops.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use map_store::{import_into, ImportLimits, MapStore};
use protocol::security::{Identity, SiteFiles};
use protocol::{ControllerKind, MapName, Pose2D, RobotId};

use crate::http::{ServeOptions, Server};
use crate::launch::{Robots, RobotsSpec};
use crate::restart::{ChildPhase, RestartPolicy, Restarts};

/// How long each group of children (agents, then the simulator) gets to stop after SIGTERM.
const STOP_GRACE: Duration = Duration::from_secs(5);
/// How often the demo looks at its children.
const SUPERVISE_INTERVAL: Duration = Duration::from_millis(200);

/// What to start.
#[derive(Debug, Clone)]
pub struct DemoOptions {
    pub serve: ServeOptions,
    pub robots: usize,
    /// Scenario the simulator runs (its floor plan is the robots' map).
    pub scenario: PathBuf,
    /// Controller of each robot, cycled when fewer than robots are given.
    pub controllers: Vec<ControllerKind>,
    /// Folder holding `sim` and `robot-agent` (default: next to this executable).
    pub bin_dir: Option<PathBuf>,
    /// Folder of the network controllers' models (default: looked up, see
    /// [`protocol::data_dirs`]).
    pub models_dir: Option<PathBuf>,
    /// Zenoh mutual TLS and access control between the service, the simulator and the agents,
    /// with the site's certificates made (or reused) in `<data_dir>/zenoh-site`.
    pub secure: bool,
    /// Record the run: one log per agent and one of the simulator in this folder
    /// ([`RobotsSpec::record_dir`]).
    pub record_dir: Option<PathBuf>,
}

/// Imports `first` and then every ROS floor plan (`*.yaml`) in `dirs`, each named after its
/// file; a name already imported is skipped and a missing folder is skipped. Identical content
/// is not stored twice, so a restart imports nothing new.
///
/// # Errors
/// A plan that cannot be read or stored.
pub fn preload_maps(
    store: &MapStore,
    first: &Path,
    dirs: &[PathBuf],
) -> anyhow::Result<Vec<MapName>> {
    let mut files: Vec<PathBuf> = Vec::new();
    for dir in dirs {
        let Ok(entries) = std::fs::read_dir(dir) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if map_store::import::is_ros_yaml(&p) {
                files.push(p);
            }
        }
    }
    files.sort();
    files.insert(0, first.to_path_buf());
    let mut names = Vec::new();
    for f in files {
        let name = map_store::import::name_from_path(&f)?;
        if names.contains(&name) {
            continue;
        }
        import_into(store, &name, &f, None, &ImportLimits::default())
            .with_context(|| format!("cannot preload {}", f.display()))?;
        names.push(name);
    }
    Ok(names)
}

/// The floor plan of a scenario (resolved against the scenario's folder) and its map name, the
/// plan's file stem.
fn scenario_plan(scenario: &Path) -> anyhow::Result<(PathBuf, MapName)> {
    let parsed = sim::Scenario::load(scenario)?;
    let plan = parsed.floor_plan_path(scenario);
    let name = map_store::import::name_from_path(&plan)?;
    Ok((plan, name))
}

/// A started demo; [`Demo::stop`] ends it.
pub struct Demo {
    pub server: Server,
    pub map: MapName,
    robots: Option<Robots>,
    /// One per agent, in roster order.
    restarts: Vec<Restarts>,
    restart_policy: RestartPolicy,
}

impl Demo {
    /// Starts the service, the simulator and the agents.
    ///
    /// # Errors
    /// A missing binary, model or scenario, a service that cannot start, a child that cannot
    /// spawn or a simulator that does not report its robots.
    pub async fn start(opts: DemoOptions) -> anyhow::Result<Self> {
        if opts.robots == 0 {
            bail!("invalid --robots 0: need at least one robot");
        }
        let bin_dir = match &opts.bin_dir {
            Some(d) => d.clone(),
            None => std::env::current_exe()?
                .parent()
                .map(Path::to_path_buf)
                .context("executable has no folder")?,
        };
        // Binaries and models are checked before the service starts.
        crate::launch::binary(&bin_dir, "sim")?;
        crate::launch::binary(&bin_dir, "robot-agent")?;
        let (plan, map) = scenario_plan(&opts.scenario)?;
        {
            let maps_dir = opts.serve.data_dir.join("maps");
            // The scenario's plan and its siblings (the shipped floor plans), and the Nav2
            // reference maps when the shared folder is found.
            let mut dirs: Vec<PathBuf> = plan.parent().map(Path::to_path_buf).into_iter().collect();
            match protocol::data_dirs::find_nav2_maps_dir(None) {
                Ok(nav2) => dirs.push(nav2),
                Err(e) => tracing::info!("not preloading the Nav2 reference maps: {e}"),
            }
            let names = tokio::task::spawn_blocking(move || {
                let store = MapStore::open(&maps_dir)?;
                preload_maps(&store, &plan, &dirs)
            })
            .await??;
            tracing::info!(maps = names.len(), "floor plans preloaded");
        }
        let mut serve = opts.serve.clone();
        let site = serve.config.zenoh.site.clone();
        let security = if opts.secure {
            let files = SiteFiles::new(serve.data_dir.join("zenoh-site"));
            let robots = (1..=opts.robots)
                .map(|k| RobotId::new(format!("robot_{k}")))
                .collect::<Result<Vec<_>, _>>()?;
            let (issue_files, issue_site) = (files.clone(), site.clone());
            let report = tokio::task::spawn_blocking(move || {
                protocol::security::issue(&issue_files, &issue_site, &robots, &[])
            })
            .await??;
            tracing::info!(
                dir = %files.dir.display(),
                issued = report.issued.len(),
                kept = report.kept.len(),
                "zenoh mutual TLS and access control on"
            );
            let mut session = serve.config.zenoh.session_args();
            files.secure(&mut session, &Identity::Planner);
            serve.config.zenoh.override_with(&session);
            Some(files)
        } else {
            None
        };
        let scheme = if security.is_some() { "tls" } else { "tcp" };
        if serve.config.zenoh.listen.is_empty() {
            serve.config.zenoh.listen = vec![format!("{scheme}/127.0.0.1:0")];
        }
        let restart_policy = serve.config.demo.agent_restart;
        let server = Server::start(serve).await?;
        let mut demo = Self {
            server,
            map,
            robots: None,
            restarts: Vec::new(),
            restart_policy,
        };
        let endpoints = demo.zenoh_endpoints().await;
        if endpoints.is_empty() {
            demo.stop().await;
            bail!("the service listens on no tcp or tls endpoint for the robots");
        }
        let spec = RobotsSpec {
            bin_dir,
            scenario: opts.scenario.clone(),
            robots: opts.robots,
            site,
            connect: endpoints,
            map: demo.map.clone(),
            controllers: opts.controllers.clone(),
            models_dir: opts.models_dir.clone(),
            roster_timeout: Duration::from_secs(60),
            security,
            record_dir: opts.record_dir.clone(),
        };
        match tokio::task::spawn_blocking(move || Robots::start(&spec)).await {
            Ok(Ok(robots)) => {
                let now = Instant::now();
                demo.restarts = robots
                    .agents
                    .iter()
                    .map(|_| Restarts::new(demo.restart_policy, now))
                    .collect();
                demo.robots = Some(robots);
                Ok(demo)
            }
            Ok(Err(e)) => {
                demo.stop().await;
                Err(e.into())
            }
            Err(e) => {
                demo.stop().await;
                Err(anyhow::anyhow!("the launcher panicked: {e}"))
            }
        }
    }

    /// The Zenoh endpoints the robots connect to.
    pub async fn zenoh_endpoints(&self) -> Vec<String> {
        self.server
            .zenoh_locators()
            .await
            .into_iter()
            .filter(|l| l.starts_with("tcp/") || l.starts_with("tls/"))
            .collect()
    }

    /// One supervision round at `now`: agents seen to have exited are scheduled for a restart,
    /// agents whose back-off has passed are started again at the robot's last reported pose
    /// (the roster's start pose if it never reported one). Returns what it did, for the log.
    ///
    /// # Errors
    /// The simulator exited (`sim exited (…)`): the world is gone, the demo must stop.
    pub fn supervise(&mut self, now: Instant) -> anyhow::Result<Vec<String>> {
        let Some(robots) = self.robots.as_mut() else {
            return Ok(Vec::new());
        };
        if let Some(what) = robots.sim_exited() {
            bail!("{what}");
        }
        let mut done = Vec::new();
        for (i, status) in robots.exited_agents() {
            let Some(r) = self.restarts.get_mut(i) else {
                continue;
            };
            if matches!(r.phase(), ChildPhase::Running { .. }) {
                let delay = r.exited(now);
                done.push(format!(
                    "agent {} exited ({status}); restarting it in {:.1} s",
                    robots.roster.robots[i].id,
                    delay.as_secs_f64()
                ));
            }
        }
        for i in 0..self.restarts.len() {
            if !self.restarts[i].due(now) {
                continue;
            }
            let id = robots.roster.robots[i].id.clone();
            let pose = last_pose(&self.server, &id).unwrap_or(robots.roster.robots[i].pose());
            let r = &mut self.restarts[i];
            r.started(now);
            match robots.restart_agent(i, pose) {
                Ok(()) => done.push(format!(
                    "agent {id} restarted (restart {}) at x {:.2} m, y {:.2} m, yaw {:.2} rad",
                    r.restarts(),
                    pose.x_m,
                    pose.y_m,
                    pose.yaw_rad
                )),
                Err(e) => {
                    let delay = r.exited(now);
                    done.push(format!(
                        "agent {id} could not be restarted ({e}); trying again in {:.1} s",
                        delay.as_secs_f64()
                    ));
                }
            }
        }
        Ok(done)
    }

    /// Stops the agents, then the simulator (SIGTERM, then SIGKILL after 5 s), then the service.
    pub async fn stop(mut self) {
        if let Some(robots) = self.robots.take() {
            if let Err(e) = tokio::task::spawn_blocking(move || robots.stop(STOP_GRACE)).await {
                tracing::warn!("stopping the robots failed: {e}");
            }
        }
        if let Err(e) = self.server.stop().await {
            tracing::warn!("service did not stop cleanly: {e}");
        }
    }
}

/// Where the service last saw `robot` (its agent's estimate), as a start pose for a new agent.
fn last_pose(server: &Server, robot: &RobotId) -> Option<Pose2D> {
    let p = server.fleet().robot(robot)?.pose?;
    Some(Pose2D::new(p.x_m, p.y_m, p.yaw_rad))
}

/// Runs the demo until Ctrl-C or SIGTERM, printing the dashboard URL and the token to `out`.
///
/// # Errors
/// Start-up failures.
pub async fn run(opts: DemoOptions, out: &mut dyn Write) -> anyhow::Result<()> {
    let robots = opts.robots;
    let mut demo = Demo::start(opts).await?;
    writeln!(out, "fleet demo: {robots} robots on map {}", demo.map)?;
    writeln!(out, "dashboard: {}/", demo.server.url())?;
    writeln!(out, "listening on {}", demo.server.url())?;
    writeln!(out, "token: {}", demo.server.token())?;
    writeln!(out, "zenoh: {}", demo.zenoh_endpoints().await.join(" "))?;
    writeln!(
        out,
        "try: curl -X POST {}/api/v1/tasks -H 'Authorization: Bearer {}' -H 'Content-Type: application/json' -d '{{\"map\":\"{}\",\"goals\":[{{\"x_m\":13.0,\"y_m\":10.0}}]}}'",
        demo.server.url(),
        demo.server.token(),
        demo.map
    )?;
    out.flush()?;
    let mut check = tokio::time::interval(SUPERVISE_INTERVAL);
    check.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let stop = crate::cli::wait_for_stop_signal();
    tokio::pin!(stop);
    loop {
        tokio::select! {
            r = &mut stop => {
                if let Err(e) = r {
                    tracing::error!("{e:#}");
                }
                break;
            }
            _ = check.tick() => {
                match demo.supervise(Instant::now()) {
                    Ok(done) => {
                        for line in done {
                            tracing::warn!("{line}");
                        }
                    }
                    Err(e) => {
                        tracing::error!("{e:#}; stopping the demo");
                        demo.stop().await;
                        return Err(e);
                    }
                }
            }
        }
    }
    writeln!(out, "stopping")?;
    demo.stop().await;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scenario_plans_are_named_after_their_file() {
        let s = test_support::scenario("task_a");
        let (plan, name) = scenario_plan(&s).unwrap();
        assert_eq!(name.as_str(), "junctions");
        assert_eq!(
            plan,
            test_support::scenarios_dir().join("maps/junctions.yaml")
        );
    }

    #[test]
    fn preloading_twice_stores_each_plan_once() {
        let dir = tempfile::tempdir().unwrap();
        let store = MapStore::open(dir.path()).unwrap();
        let maps = test_support::scenarios_dir().join("maps");
        let plan = maps.join("junctions.yaml");
        let dirs = [maps, dir.path().join("missing")];
        let first = preload_maps(&store, &plan, &dirs).unwrap();
        assert_eq!(first.first().map(MapName::as_str), Some("junctions"));
        assert!(first.len() > 1, "{first:?}");
        let listed = store.list().unwrap().len();
        assert_eq!(listed, first.len());
        preload_maps(&store, &plan, &dirs).unwrap();
        assert_eq!(store.list().unwrap().len(), listed);
        assert!(store.list().unwrap().iter().all(|m| m.version == 1));
    }
}
