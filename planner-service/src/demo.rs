//! The fleet demo (`planner-service demo`): the whole system on one machine.
//!
//! In this process: the planner service (HTTP API + dashboard, map server, fleet core) on an
//! embedded store with the shipped floor plans preloaded. As separate processes talking to it
//! over Zenoh on loopback: the simulator with N robots and one `robot-agent` per robot. It
//! prints the dashboard URL and the token and runs until Ctrl-C or SIGTERM, then stops the
//! agents, the simulator and the service, in that order.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::Duration;

use anyhow::{bail, Context};
use map_store::{import_into, ImportLimits, MapStore};
use protocol::{MapName, Pose2D};
use tokio::io::{AsyncBufReadExt, BufReader};
use tokio::process::{Child, Command};

use crate::http::{ServeOptions, Server};

/// What to start.
#[derive(Debug, Clone)]
pub struct DemoOptions {
    pub serve: ServeOptions,
    pub robots: usize,
    /// Scenario the simulator runs (its floor plan is the robots' map).
    pub scenario: PathBuf,
    /// Controller of each robot, cycled when fewer than robots are given.
    pub controllers: Vec<String>,
    /// Folder holding `sim` and `robot-agent` (default: next to this executable).
    pub bin_dir: Option<PathBuf>,
}

/// The shipped scenarios (`sim/scenarios` in the source tree, or `FLEET_SCENARIOS_DIR`).
#[must_use]
pub fn scenarios_dir() -> PathBuf {
    std::env::var_os("FLEET_SCENARIOS_DIR").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("../sim/scenarios"),
        PathBuf::from,
    )
}

/// Imports every floor plan of the shipped scenarios (`<scenarios>/maps/*.yaml`, named after
/// the file) and the Nav2 reference maps when the shared folder is there. Identical content is
/// not stored twice, so a restart imports nothing new.
///
/// # Errors
/// A plan that cannot be read or stored.
pub fn preload_maps(store: &MapStore) -> anyhow::Result<Vec<MapName>> {
    let mut files: Vec<PathBuf> = Vec::new();
    // The Nav2 reference maps when `shared/` is there (a missing folder is skipped).
    let dirs = [
        scenarios_dir().join("maps"),
        map_store::paths::nav2_maps_dir(),
    ];
    for dir in dirs {
        let Ok(entries) = std::fs::read_dir(&dir) else {
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

/// The floor-plan name of a scenario: the stem of its `floor_plan` file.
fn scenario_plan(scenario: &Path) -> anyhow::Result<MapName> {
    let text = std::fs::read_to_string(scenario)
        .with_context(|| format!("cannot read scenario {}", scenario.display()))?;
    let plan = text
        .lines()
        .find_map(|l| l.strip_prefix("floor_plan:"))
        .map(|v| v.trim().trim_matches(['\'', '"']).to_string())
        .with_context(|| format!("scenario {} names no floor_plan", scenario.display()))?;
    Ok(map_store::import::name_from_path(Path::new(&plan))?)
}

fn bin(dir: &Path, name: &str) -> anyhow::Result<PathBuf> {
    let p = dir.join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
    if !p.is_file() {
        bail!(
            "cannot find {} (build it: cargo build --release -p {})",
            p.display(),
            name
        );
    }
    Ok(p)
}

fn model_for(controller: &str) -> Option<PathBuf> {
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    let file = match controller {
        "dlm" => "dlm.onnx",
        "lpe" => "lpe.onnx",
        "none" => "none.onnx",
        _ => return None,
    };
    Some(models.join(file))
}

/// A started demo; [`Demo::stop`] ends it.
pub struct Demo {
    pub server: Server,
    pub map: MapName,
    children: Vec<(String, Child)>,
}

impl Demo {
    /// Starts the service, the simulator and the agents.
    ///
    /// # Errors
    /// A missing binary or scenario, a service that cannot start, a child that cannot spawn or
    /// a simulator that does not report its robots.
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
        let sim_bin = bin(&bin_dir, "sim")?;
        let agent_bin = bin(&bin_dir, "robot-agent")?;
        let map = scenario_plan(&opts.scenario)?;
        {
            let maps_dir = opts.serve.data_dir.join("maps");
            let names = tokio::task::spawn_blocking(move || {
                let store = MapStore::open(&maps_dir)?;
                preload_maps(&store)
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
        if endpoints.is_empty() {
            bail!("the service listens on no tcp endpoint for the robots");
        }
        let mut demo = Self {
            server,
            map,
            children: Vec::new(),
        };
        match demo
            .spawn_children(&opts, &sim_bin, &agent_bin, &endpoints, site.as_str())
            .await
        {
            Ok(()) => Ok(demo),
            Err(e) => {
                demo.stop().await;
                Err(e)
            }
        }
    }

    async fn spawn_children(
        &mut self,
        opts: &DemoOptions,
        sim_bin: &Path,
        agent_bin: &Path,
        endpoints: &[String],
        site: &str,
    ) -> anyhow::Result<()> {
        let mut sim = Command::new(sim_bin);
        sim.arg("run")
            .arg("--scenario")
            .arg(&opts.scenario)
            .arg("--robots")
            .arg(opts.robots.to_string())
            .arg("--site")
            .arg(site)
            .stdout(Stdio::piped())
            .kill_on_drop(true);
        for e in endpoints {
            sim.arg("--connect").arg(e);
        }
        let mut sim = sim
            .spawn()
            .with_context(|| format!("cannot start {}", sim_bin.display()))?;
        let stdout = sim.stdout.take().context("simulator stdout")?;
        self.children.push(("sim".to_string(), sim));
        let mut lines = BufReader::new(stdout).lines();
        let mut robots: Vec<(String, Pose2D)> = Vec::new();
        while robots.len() < opts.robots {
            let line = tokio::time::timeout(Duration::from_secs(60), lines.next_line())
                .await
                .context("the simulator did not report its robots within 60 s")??
                .context("the simulator exited before reporting its robots")?;
            if let Some((id, pose)) = parse_robot_line(&line) {
                robots.push((id, pose));
            }
        }
        // Keep draining the simulator's stdout so it never blocks on a full pipe.
        tokio::spawn(async move {
            while let Ok(Some(line)) = lines.next_line().await {
                tracing::debug!(target: "sim", "{line}");
            }
        });
        let controllers = if opts.controllers.is_empty() {
            vec!["dynamic-window".to_string()]
        } else {
            opts.controllers.clone()
        };
        for (i, (id, pose)) in robots.iter().enumerate() {
            let controller = &controllers[i % controllers.len()];
            let mut agent = Command::new(agent_bin);
            agent
                .arg("--robot-id")
                .arg(id)
                .arg("--site")
                .arg(site)
                .arg("--controller")
                .arg(controller)
                .arg("--map")
                .arg(self.map.as_str())
                .arg("--initial-pose")
                .arg(format!("{},{},{}", pose.x_m, pose.y_m, pose.yaw_rad))
                .arg("--no-multicast")
                .kill_on_drop(true);
            if let Some(model) = model_for(controller) {
                agent.arg("--model").arg(model);
            }
            for e in endpoints {
                agent.arg("--connect").arg(e);
            }
            let child = agent
                .spawn()
                .with_context(|| format!("cannot start {} for {id}", agent_bin.display()))?;
            self.children.push((format!("agent {id}"), child));
        }
        Ok(())
    }

    /// The first child that exited, if any (name and status).
    pub fn exited_child(&mut self) -> Option<String> {
        for (name, child) in &mut self.children {
            if let Ok(Some(status)) = child.try_wait() {
                return Some(format!("{name} exited ({status})"));
            }
        }
        None
    }

    /// Stops the agents, then the simulator (SIGTERM, then SIGKILL after 5 s), then the service.
    pub async fn stop(mut self) {
        let children = std::mem::take(&mut self.children);
        for (name, mut child) in children.into_iter().rev() {
            terminate(&name, &mut child).await;
        }
        if let Err(e) = self.server.stop().await {
            tracing::warn!("service did not stop cleanly: {e}");
        }
    }
}

fn parse_robot_line(line: &str) -> Option<(String, Pose2D)> {
    let rest = line.strip_prefix("robot ")?;
    let (id, pose) = rest.split_once(" at ")?;
    let v: Vec<f64> = pose
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .ok()?;
    match v.as_slice() {
        [x, y, yaw] => Some((id.to_string(), Pose2D::new(*x, *y, *yaw))),
        _ => None,
    }
}

async fn terminate(name: &str, child: &mut Child) {
    if let Some(pid) = child.id() {
        // SIGTERM lets an agent send a last zero velocity; std has no portable way to send it.
        let sent = Command::new("kill")
            .arg("-TERM")
            .arg(pid.to_string())
            .status()
            .await
            .is_ok_and(|s| s.success());
        if sent
            && tokio::time::timeout(Duration::from_secs(5), child.wait())
                .await
                .is_ok()
        {
            return;
        }
    }
    if let Err(e) = child.kill().await {
        tracing::warn!("cannot stop {name}: {e}");
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
    fn robot_lines_parse_and_others_do_not() {
        let (id, p) = parse_robot_line("robot robot_2 at 1.500,-2.250,1.2500").unwrap();
        assert_eq!(id, "robot_2");
        assert_eq!((p.x_m, p.y_m, p.yaw_rad), (1.5, -2.25, 1.25));
        assert!(parse_robot_line("sim driver running").is_none());
        assert!(parse_robot_line("robot r at 1,2").is_none());
    }

    #[test]
    fn scenario_plans_are_named_after_their_file() {
        let s = scenarios_dir().join("task_a.yaml");
        assert_eq!(scenario_plan(&s).unwrap().as_str(), "junctions");
    }

    #[test]
    fn preloading_twice_stores_each_plan_once() {
        let dir = tempfile::tempdir().unwrap();
        let store = MapStore::open(dir.path()).unwrap();
        let first = preload_maps(&store).unwrap();
        assert!(first.iter().any(|n| n.as_str() == "junctions"));
        let listed = store.list().unwrap().len();
        preload_maps(&store).unwrap();
        assert_eq!(store.list().unwrap().len(), listed);
        assert!(store.list().unwrap().iter().all(|m| m.version == 1));
    }
}
