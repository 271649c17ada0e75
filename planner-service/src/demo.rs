//! The fleet demo (`planner-service demo`): the whole system on one machine.
//!
//! In this process: the planner service (HTTP API + dashboard, map server, fleet core) on an
//! embedded store with the scenario's floor plans (and the Nav2 reference maps when the shared
//! folder is found) preloaded. As separate processes talking to it over Zenoh on loopback, started
//! by [`crate::launch`]: the simulator with N robots and one `robot-agent` per robot. It prints the
//! dashboard URL and the token and runs until Ctrl-C or SIGTERM, then stops the agents, the
//! simulator and the service, in that order.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{bail, Context};
use map_store::{import_into, ImportLimits, MapStore};
use protocol::{ControllerKind, MapName};

use crate::http::{ServeOptions, Server};
use crate::launch::{Robots, RobotsSpec};

/// How long each group of children (agents, then the simulator) gets to stop after SIGTERM.
const STOP_GRACE: Duration = Duration::from_secs(5);

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
        if serve.config.zenoh.listen.is_empty() {
            serve.config.zenoh.listen = vec!["tcp/127.0.0.1:0".to_string()];
        }
        let site = serve.config.zenoh.site.clone();
        let server = Server::start(serve).await?;
        let endpoints: Vec<String> = server
            .zenoh_locators()
            .await
            .into_iter()
            .filter(|l| l.starts_with("tcp/"))
            .collect();
        let mut demo = Self {
            server,
            map,
            robots: None,
        };
        if endpoints.is_empty() {
            demo.stop().await;
            bail!("the service listens on no tcp endpoint for the robots");
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
        };
        match tokio::task::spawn_blocking(move || Robots::start(&spec)).await {
            Ok(Ok(robots)) => {
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

    /// The first child that exited, if any (name and status).
    pub fn exited_child(&mut self) -> Option<String> {
        self.robots.as_mut().and_then(Robots::exited)
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
    writeln!(
        out,
        "try: curl -X POST {}/api/v1/tasks -H 'Authorization: Bearer {}' -H 'Content-Type: application/json' -d '{{\"map\":\"{}\",\"goals\":[{{\"x_m\":13.0,\"y_m\":10.0}}]}}'",
        demo.server.url(),
        demo.server.token(),
        demo.map
    )?;
    out.flush()?;
    let mut check = tokio::time::interval(Duration::from_secs(1));
    loop {
        tokio::select! {
            r = crate::cli::wait_for_stop_signal() => {
                if let Err(e) = r {
                    tracing::error!("{e:#}");
                }
                break;
            }
            _ = check.tick() => {
                if let Some(what) = demo.exited_child() {
                    tracing::error!("{what}; stopping the demo");
                    demo.stop().await;
                    bail!("{what}");
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
