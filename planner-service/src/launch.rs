//! The launcher of the simulated fleet: the simulator and one `robot-agent` per robot as child
//! processes talking Zenoh to a running service. `planner-service demo` and the end-to-end tests
//! (`fleet-tests`) both start their robots with it.
//!
//! [`Robots::start`] runs `sim run`, reads the roster line it prints ([`sim::Roster`], parsed by
//! [`sim::Roster::parse_line`]) and starts one agent per robot at that robot's start pose, with
//! the controllers of the [`RobotsSpec`] cycled over the robots. Every child is a [`Process`]:
//! its stdout and stderr lines are echoed to this process's stderr prefixed with its name,
//! [`Process::wait_line`] waits for a line, and the child is killed (SIGKILL) when its handle
//! drops, so a failed start, an error or a panic leaves nothing running. [`Robots::stop`] ends
//! them politely instead: SIGTERM to every agent (an agent sends a last zero velocity), then to
//! the simulator, SIGKILL after a grace period. [`Robots::restart_agent`] starts an agent that
//! exited again (the demo's supervision, [`crate::restart`]).
//!
//! Network controllers (`dlm`, `lpe`, `none`) get `--model <models>/<controller>.onnx`, where
//! `<models>` is [`RobotsSpec::models_dir`] or else looked up with
//! [`protocol::data_dirs::find_models_dir`]; both are checked before anything starts.

use std::io::{BufRead, BufReader, Read, Write as _};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use protocol::data_dirs::DataDirError;
use protocol::security::{Identity, SiteFiles};
use protocol::{ControllerKind, MapName, Pose2D, RobotId, SiteId};
use sim::roster::Roster;

/// Why the robots could not be started, or a child gave up.
#[derive(Debug, thiserror::Error)]
pub enum LaunchError {
    #[error("cannot find {} (build it: cargo build --release -p {name})", path.display())]
    MissingBinary { name: String, path: PathBuf },
    #[error("cannot start {what}: {source}")]
    Spawn {
        what: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{name} exited ({status}) before {waiting_for}")]
    Exited {
        name: String,
        status: String,
        waiting_for: String,
    },
    #[error("{name} closed its output before {waiting_for}")]
    Closed { name: String, waiting_for: String },
    #[error("timed out after {after:?} waiting for {what}")]
    Timeout { what: String, after: Duration },
    #[error("the simulator printed a bad roster line: {0}")]
    BadRoster(String),
    #[error("the simulator reported {got} robots, {want} were asked for")]
    RobotCount { want: usize, got: usize },
    #[error("invalid robots = 0: need at least one robot")]
    NoRobots,
    #[error("invalid controllers = {0}: it reads the simulator's ground truth, so no agent runs it (only `eval` does)")]
    NotDeployable(ControllerKind),
    #[error("controller {controller} needs a model")]
    ModelsDir {
        controller: ControllerKind,
        #[source]
        source: DataDirError,
    },
    #[error("controller {controller} needs the model {}, which does not exist", path.display())]
    MissingModel {
        controller: ControllerKind,
        path: PathBuf,
    },
}

/// `<dir>/<name>` (plus the platform's executable suffix), if it is a file.
///
/// # Errors
/// [`LaunchError::MissingBinary`] naming the path and how to build it.
pub fn binary(dir: &Path, name: &str) -> Result<PathBuf, LaunchError> {
    let path = dir.join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
    if path.is_file() {
        Ok(path)
    } else {
        Err(LaunchError::MissingBinary {
            name: name.to_string(),
            path,
        })
    }
}

/// A child process, killed when dropped, whose output lines are echoed to stderr as
/// `[name] line` and collected for [`Process::wait_line`] until [`Process::stop_collecting`].
///
/// It also stops by itself when this process dies without killing it (SIGKILL, a crash): its
/// stdin is a pipe that only this process holds open, and it is told to stop at the end of it
/// ([`protocol::shutdown::STOP_ON_STDIN_EOF_ENV`]).
pub struct Process {
    /// The label of its output lines, e.g. `sim` or `agent robot_1`.
    pub name: String,
    child: Child,
    lines: Option<mpsc::Receiver<String>>,
    /// Held, never written: its closing is the child's signal that we are gone.
    _lifeline: Option<std::process::ChildStdin>,
}

impl Process {
    /// Starts `command` with its stdout and stderr piped and its stdin the lifeline (anything
    /// else, such as environment variables, is the caller's).
    ///
    /// # Errors
    /// [`LaunchError::Spawn`] when the process cannot start.
    pub fn spawn(name: &str, mut command: Command) -> Result<Self, LaunchError> {
        let mut child = command
            .env(protocol::shutdown::STOP_ON_STDIN_EOF_ENV, "1")
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|source| LaunchError::Spawn {
                what: format!("{name} ({})", command.get_program().to_string_lossy()),
                source,
            })?;
        let (tx, rx) = mpsc::channel();
        let streams: Vec<Box<dyn Read + Send>> = [
            child
                .stdout
                .take()
                .map(|s| Box::new(s) as Box<dyn Read + Send>),
            child
                .stderr
                .take()
                .map(|s| Box::new(s) as Box<dyn Read + Send>),
        ]
        .into_iter()
        .flatten()
        .collect();
        for stream in streams {
            let tx = tx.clone();
            let label = name.to_string();
            std::thread::spawn(move || {
                for line in BufReader::new(stream).lines().map_while(Result::ok) {
                    // Not `eprintln!`: a stderr that is gone must not end the draining.
                    let _ = writeln!(std::io::stderr(), "[{label}] {line}");
                    // Nobody collecting any more is fine: keep draining so the child never
                    // blocks on a full pipe.
                    let _ = tx.send(line);
                }
            });
        }
        let lifeline = child.stdin.take();
        Ok(Self {
            name: name.to_string(),
            child,
            lines: Some(rx),
            _lifeline: lifeline,
        })
    }

    /// Waits for an output line for which `pick` returns something.
    ///
    /// # Errors
    /// [`LaunchError::Timeout`]; [`LaunchError::Exited`] or [`LaunchError::Closed`] when the
    /// process ends first (or no longer collects its lines).
    pub fn wait_line<T>(
        &mut self,
        timeout: Duration,
        mut pick: impl FnMut(&str) -> Option<T>,
    ) -> Result<T, LaunchError> {
        let waiting_for = format!("the awaited output line of {}", self.name);
        let deadline = Instant::now() + timeout;
        let Some(lines) = &self.lines else {
            return Err(LaunchError::Closed {
                name: self.name.clone(),
                waiting_for,
            });
        };
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match lines.recv_timeout(left.min(Duration::from_millis(200))) {
                Ok(line) => {
                    if let Some(v) = pick(&line) {
                        return Ok(v);
                    }
                }
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    if let Ok(Some(status)) = self.child.try_wait() {
                        return Err(LaunchError::Exited {
                            name: self.name.clone(),
                            status: status.to_string(),
                            waiting_for,
                        });
                    }
                    if left.is_zero() {
                        return Err(LaunchError::Timeout {
                            what: format!("output of {}", self.name),
                            after: timeout,
                        });
                    }
                }
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    // Both pipes closed: the process is exiting; give it a moment to finish.
                    let grace = Instant::now() + Duration::from_secs(1);
                    while self.is_running() && Instant::now() < grace {
                        std::thread::sleep(Duration::from_millis(20));
                    }
                    return Err(match self.child.try_wait() {
                        Ok(Some(status)) => LaunchError::Exited {
                            name: self.name.clone(),
                            status: status.to_string(),
                            waiting_for,
                        },
                        _ => LaunchError::Closed {
                            name: self.name.clone(),
                            waiting_for,
                        },
                    });
                }
            }
        }
    }

    /// Stops collecting output lines (they are still echoed): for a long-running child nobody
    /// waits on, so its lines do not pile up in memory.
    pub fn stop_collecting(&mut self) {
        self.lines = None;
    }

    /// Kills the process at once (SIGKILL: a crash, as far as the others can tell).
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Asks the process to stop (SIGTERM) without waiting; `false` when it had already exited
    /// or the signal could not be sent.
    pub fn request_stop(&mut self) -> bool {
        if !self.is_running() {
            return false;
        }
        // std has no portable way to send SIGTERM (and this workspace has no unsafe code).
        Command::new("kill")
            .arg("-TERM")
            .arg(self.child.id().to_string())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success())
    }

    /// Waits until the process exits or `deadline` passes, then kills it if it still runs.
    pub fn wait_or_kill(&mut self, deadline: Instant) {
        while Instant::now() < deadline {
            if !self.is_running() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        if self.is_running() {
            tracing::warn!(
                "{} did not stop within its grace period; killing it",
                self.name
            );
        }
        self.kill();
    }

    /// Whether it still runs.
    pub fn is_running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    /// Its exit status once it has exited.
    pub fn exit_status(&mut self) -> Option<ExitStatus> {
        self.child.try_wait().ok().flatten()
    }

    #[must_use]
    pub fn pid(&self) -> u32 {
        self.child.id()
    }
}

impl Drop for Process {
    fn drop(&mut self) {
        self.kill();
    }
}

/// What [`Robots::start`] starts.
#[derive(Debug, Clone)]
pub struct RobotsSpec {
    /// Folder holding the `sim` and `robot-agent` binaries.
    pub bin_dir: PathBuf,
    /// Scenario the simulator runs.
    pub scenario: PathBuf,
    /// Number of simulated robots (`robot_1` … `robot_n`).
    pub robots: usize,
    /// Zenoh keys are under `fleet/<site>/`.
    pub site: SiteId,
    /// Zenoh endpoints the simulator and the agents connect to (the service's listener, e.g.
    /// `tcp/127.0.0.1:7447`); no multicast discovery when there is one.
    pub connect: Vec<String>,
    /// The map the agents fetch and localize on: the scenario's floor plan in the map store.
    pub map: MapName,
    /// Controller of each robot, cycled over the robots; empty means dynamic window.
    pub controllers: Vec<ControllerKind>,
    /// Folder of `<controller>.onnx` for the network controllers; `None`: looked up with
    /// [`protocol::data_dirs::find_models_dir`] when a network controller is asked for.
    pub models_dir: Option<PathBuf>,
    /// How long the simulator may take to print its roster.
    pub roster_timeout: Duration,
    /// The site's certificates and access-control rules (`planner-service certs`): each child
    /// gets its own identity's certificate; `None`: plain TCP.
    pub security: Option<SiteFiles>,
    /// Folder of run logs (MCAP, docs/logs.md): each agent records `<robot id>.mcap`
    /// (`<robot id>-restart<N>.mcap` after its N-th restart, so a restart keeps the log of the
    /// run before it) and the simulator `sim.mcap` (the first robot's ground truth). `None`:
    /// nothing is recorded.
    pub record_dir: Option<PathBuf>,
}

impl RobotsSpec {
    /// `robots` dynamic-window robots of `scenario` on `map`, connected to `connect`, on the
    /// default site.
    #[must_use]
    pub fn new(
        bin_dir: &Path,
        scenario: &Path,
        robots: usize,
        map: MapName,
        connect: Vec<String>,
    ) -> Self {
        Self {
            bin_dir: bin_dir.to_path_buf(),
            scenario: scenario.to_path_buf(),
            robots,
            site: SiteId::default(),
            connect,
            map,
            controllers: vec![ControllerKind::DynamicWindow],
            models_dir: None,
            roster_timeout: Duration::from_secs(60),
            security: None,
            record_dir: None,
        }
    }

    /// Gives a child the Zenoh TLS and access-control flags of `identity` when the site is
    /// secured.
    fn secure(&self, cmd: &mut Command, identity: &Identity) {
        let Some(files) = &self.security else {
            return;
        };
        let mut session = protocol::SessionArgs::default();
        files.secure(&mut session, identity);
        for (flag, path) in [
            ("--zenoh-tls-ca", &session.tls_ca),
            ("--zenoh-tls-cert", &session.tls_cert),
            ("--zenoh-tls-key", &session.tls_key),
            ("--zenoh-acl", &session.acl),
        ] {
            if let Some(path) = path {
                cmd.arg(flag).arg(path);
            }
        }
    }

    /// The controller of the `i`-th robot.
    #[must_use]
    pub fn controller(&self, i: usize) -> ControllerKind {
        if self.controllers.is_empty() {
            ControllerKind::DynamicWindow
        } else {
            self.controllers[i % self.controllers.len()]
        }
    }

    /// The model file of each network controller among the robots'.
    fn models(&self) -> Result<Vec<(ControllerKind, PathBuf)>, LaunchError> {
        let mut models: Vec<(ControllerKind, PathBuf)> = Vec::new();
        let mut dir: Option<PathBuf> = None;
        for i in 0..self.robots {
            let controller = self.controller(i);
            if !controller.needs_model() || models.iter().any(|(c, _)| *c == controller) {
                continue;
            }
            let folder = match &dir {
                Some(d) => d.clone(),
                None => {
                    let d = protocol::data_dirs::find_models_dir(self.models_dir.as_deref())
                        .map_err(|source| LaunchError::ModelsDir { controller, source })?;
                    dir = Some(d.clone());
                    d
                }
            };
            let path = folder.join(format!("{}.onnx", controller.as_str()));
            if !path.is_file() {
                return Err(LaunchError::MissingModel { controller, path });
            }
            models.push((controller, path));
        }
        Ok(models)
    }
}

/// The running simulator and agents.
pub struct Robots {
    pub sim: Process,
    /// What the simulator reported: the robots and their start poses.
    pub roster: Roster,
    /// One per robot, in roster order, named `agent <robot id>`.
    pub agents: Vec<Process>,
    /// What starting an agent again needs.
    spec: RobotsSpec,
    agent_bin: PathBuf,
    models: Vec<(ControllerKind, PathBuf)>,
    /// Starts of each agent so far (its log's name counts them).
    starts: Vec<u32>,
}

impl Robots {
    /// Starts the simulator, waits for its roster and starts one agent per robot. Blocks (up
    /// to [`RobotsSpec::roster_timeout`]); async callers run it on a blocking thread.
    ///
    /// # Errors
    /// [`LaunchError`]: a missing binary or model, a child that cannot start, a simulator that
    /// exits or reports no (or a bad, or a short) roster in time. Whatever had started is
    /// killed.
    pub fn start(spec: &RobotsSpec) -> Result<Self, LaunchError> {
        if spec.robots == 0 {
            return Err(LaunchError::NoRobots);
        }
        if let Some(kind) = spec.controllers.iter().find(|k| !k.deployable()) {
            return Err(LaunchError::NotDeployable(*kind));
        }
        let sim_bin = binary(&spec.bin_dir, "sim")?;
        let agent_bin = binary(&spec.bin_dir, "robot-agent")?;
        let models = spec.models()?;

        let mut cmd = Command::new(&sim_bin);
        cmd.arg("run")
            .arg("--scenario")
            .arg(&spec.scenario)
            .arg("--robots")
            .arg(spec.robots.to_string())
            .arg("--site")
            .arg(spec.site.as_str());
        for e in &spec.connect {
            cmd.arg("--connect").arg(e);
        }
        if let Some(dir) = &spec.record_dir {
            cmd.arg("--record").arg(dir.join("sim.mcap"));
        }
        spec.secure(&mut cmd, &Identity::Sim);
        let mut sim = Process::spawn("sim", cmd)?;
        let roster = read_roster(&mut sim, spec.roster_timeout)?;
        sim.stop_collecting();
        if roster.robots.len() != spec.robots {
            return Err(LaunchError::RobotCount {
                want: spec.robots,
                got: roster.robots.len(),
            });
        }

        let mut robots = Self {
            sim,
            roster,
            agents: Vec::with_capacity(spec.robots),
            spec: spec.clone(),
            agent_bin,
            models,
            starts: vec![0; spec.robots],
        };
        for i in 0..robots.roster.robots.len() {
            let pose = robots.roster.robots[i].pose();
            let agent = robots.spawn_agent(i, pose)?;
            robots.agents.push(agent);
        }
        Ok(robots)
    }

    /// Starts the agent of the `index`-th robot of the roster, localizing from `pose`.
    fn spawn_agent(&mut self, index: usize, pose: Pose2D) -> Result<Process, LaunchError> {
        let restarts = self.starts[index];
        self.starts[index] += 1;
        let robot = &self.roster.robots[index];
        let controller = self.spec.controller(index);
        let model = self
            .models
            .iter()
            .find(|(c, _)| *c == controller)
            .map(|(_, p)| p.as_path());
        let cmd = agent_command(
            &self.agent_bin,
            &self.spec,
            &self.roster.zenoh,
            &AgentStart {
                id: &robot.id,
                pose,
                controller,
                model,
                restarts,
            },
        );
        let mut agent = Process::spawn(&format!("agent {}", robot.id), cmd)?;
        agent.stop_collecting();
        Ok(agent)
    }

    /// Starts the `index`-th agent again (its old process is reaped, killed if it still ran),
    /// localizing from `pose`: where the robot was last seen, not where it started.
    ///
    /// # Errors
    /// [`LaunchError::Spawn`]; `index` past the roster is [`LaunchError::RobotCount`].
    pub fn restart_agent(&mut self, index: usize, pose: Pose2D) -> Result<(), LaunchError> {
        if index >= self.agents.len() {
            return Err(LaunchError::RobotCount {
                want: index + 1,
                got: self.agents.len(),
            });
        }
        let agent = self.spawn_agent(index, pose)?;
        // Dropping the old handle reaps it.
        self.agents[index] = agent;
        Ok(())
    }

    /// The simulator's exit, with its status (`sim exited (signal: 9)`), once it has exited.
    pub fn sim_exited(&mut self) -> Option<String> {
        self.sim
            .exit_status()
            .map(|status| format!("{} exited ({status})", self.sim.name))
    }

    /// The agents that have exited: (roster index, exit status).
    pub fn exited_agents(&mut self) -> Vec<(usize, ExitStatus)> {
        self.agents
            .iter_mut()
            .enumerate()
            .filter_map(|(i, p)| p.exit_status().map(|s| (i, s)))
            .collect()
    }

    /// Stops the agents (SIGTERM, all at once), then the simulator, each group within `grace`
    /// before SIGKILL. Blocks up to twice `grace`.
    pub fn stop(mut self, grace: Duration) {
        for agent in &mut self.agents {
            agent.request_stop();
        }
        let deadline = Instant::now() + grace;
        for agent in &mut self.agents {
            agent.wait_or_kill(deadline);
        }
        self.sim.request_stop();
        self.sim.wait_or_kill(Instant::now() + grace);
    }
}

fn read_roster(sim: &mut Process, timeout: Duration) -> Result<Roster, LaunchError> {
    // Lines that look like JSON but are no roster are remembered for the error.
    let mut bad: Option<String> = None;
    let found = sim.wait_line(timeout, |line| match Roster::parse_line(line) {
        Ok(roster) => Some(roster),
        Err(e) => {
            if line.trim_start().starts_with('{') {
                bad = Some(format!("{e} in {line:?}"));
            }
            None
        }
    });
    match (found, bad) {
        (Ok(roster), _) => Ok(roster),
        (Err(_), Some(bad)) => Err(LaunchError::BadRoster(bad)),
        (Err(e), None) => Err(e),
    }
}

/// One start of one robot's agent: the first when `restarts` is 0.
#[derive(Debug, Clone, Copy)]
struct AgentStart<'a> {
    id: &'a RobotId,
    pose: Pose2D,
    controller: ControllerKind,
    model: Option<&'a Path>,
    restarts: u32,
}

/// The command of a robot's agent. It connects to the service's endpoints and to the
/// simulator's (`sim_endpoints`, from the roster): Zenoh reconnects configured endpoints when a
/// link drops, and a link to a peer met by gossip stays lost. Zenoh 1.10.2's TLS links dropped
/// now and then under traffic both ways (eclipse-zenoh/zenoh#2557, patched in
/// `third_party/zenoh-link-tls`), and the lost link between a base and its agent used to leave
/// that robot without sensors for good; a link can still drop for other reasons.
fn agent_command(
    bin: &Path,
    spec: &RobotsSpec,
    sim_endpoints: &[String],
    start: &AgentStart<'_>,
) -> Command {
    let AgentStart {
        id,
        pose,
        controller,
        model,
        restarts,
    } = *start;
    let mut cmd = Command::new(bin);
    cmd.arg("--robot-id")
        .arg(id.as_str())
        .arg("--site")
        .arg(spec.site.as_str())
        .arg("--controller")
        .arg(controller.as_str())
        .arg("--map")
        .arg(spec.map.as_str())
        .arg("--initial-pose")
        // `{}` writes the shortest text that reads back as the same f64.
        .arg(format!("{},{},{}", pose.x_m, pose.y_m, pose.yaw_rad))
        .arg("--no-multicast");
    if let Some(model) = model {
        cmd.arg("--model").arg(model);
    }
    for e in spec.connect.iter().chain(sim_endpoints) {
        cmd.arg("--connect").arg(e);
    }
    if let Some(dir) = &spec.record_dir {
        let name = if restarts == 0 {
            format!("{}.mcap", id.as_str())
        } else {
            format!("{}-restart{restarts}.mcap", id.as_str())
        };
        cmd.arg("--record").arg(dir.join(name));
    }
    spec.secure(&mut cmd, &Identity::Agent(id.clone()));
    cmd
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn spec(dir: &Path, controllers: Vec<ControllerKind>) -> RobotsSpec {
        let mut s = RobotsSpec::new(
            dir,
            &dir.join("task_a.yaml"),
            3,
            MapName::new("junctions").unwrap(),
            vec!["tcp/127.0.0.1:7447".into()],
        );
        s.controllers = controllers;
        s
    }

    fn args_of(cmd: &Command) -> Vec<String> {
        cmd.get_args()
            .map(|a| a.to_string_lossy().into_owned())
            .collect()
    }

    /// The value after `flag` in `args`.
    fn flag_value(args: &[String], flag: &str) -> String {
        let i = args.iter().position(|a| a == flag).unwrap();
        args[i + 1].clone()
    }

    #[test]
    fn controllers_cycle_over_the_robots() {
        let dir = tempfile::tempdir().unwrap();
        let s = spec(
            dir.path(),
            vec![ControllerKind::PathTracker, ControllerKind::DynamicWindow],
        );
        let got: Vec<ControllerKind> = (0..3).map(|i| s.controller(i)).collect();
        assert_eq!(
            got,
            [
                ControllerKind::PathTracker,
                ControllerKind::DynamicWindow,
                ControllerKind::PathTracker
            ]
        );
        assert_eq!(
            spec(dir.path(), Vec::new()).controller(2),
            ControllerKind::DynamicWindow
        );
    }

    #[test]
    fn network_controllers_need_their_model_file() {
        let dir = tempfile::tempdir().unwrap();
        let mut s = spec(dir.path(), vec![ControllerKind::Dlm]);
        s.models_dir = Some(dir.path().to_path_buf());
        let err = s.models().unwrap_err();
        assert!(
            matches!(&err, LaunchError::MissingModel { path, .. } if *path == dir.path().join("dlm.onnx")),
            "{err}"
        );
        std::fs::write(dir.path().join("dlm.onnx"), b"").unwrap();
        assert_eq!(
            s.models().unwrap(),
            [(ControllerKind::Dlm, dir.path().join("dlm.onnx"))]
        );
        s.models_dir = Some(dir.path().join("missing"));
        assert!(matches!(
            s.models().unwrap_err(),
            LaunchError::ModelsDir { .. }
        ));
        // No network controller: no models folder needed.
        s.controllers = vec![ControllerKind::DynamicWindow];
        assert!(s.models().unwrap().is_empty());
    }

    #[test]
    fn missing_binaries_are_named_before_anything_starts() {
        let dir = tempfile::tempdir().unwrap();
        let err = match Robots::start(&spec(dir.path(), Vec::new())) {
            Err(e) => e,
            Ok(_) => panic!("started without binaries"),
        };
        assert!(
            err.to_string()
                .contains(&dir.path().join("sim").display().to_string()),
            "{err}"
        );
        let mut zero = spec(dir.path(), Vec::new());
        zero.robots = 0;
        assert!(matches!(Robots::start(&zero), Err(LaunchError::NoRobots)));
    }

    #[test]
    fn agents_get_the_roster_pose_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let s = spec(dir.path(), Vec::new());
        let pose = Pose2D::new(0.1 + 0.2, -1.0 / 3.0, -3.0);
        let cmd = agent_command(
            Path::new("robot-agent"),
            &s,
            &["tcp/127.0.0.1:40001".to_string()],
            &AgentStart {
                id: &RobotId::new("robot_2").unwrap(),
                pose,
                controller: ControllerKind::Lpe,
                model: Some(Path::new("/m/lpe.onnx")),
                restarts: 0,
            },
        );
        let args = args_of(&cmd);
        let at = |flag: &str| flag_value(&args, flag);
        let parsed: Vec<f64> = at("--initial-pose")
            .split(',')
            .map(|v| v.parse().unwrap())
            .collect();
        assert_eq!(parsed, [pose.x_m, pose.y_m, pose.yaw_rad]);
        assert_eq!(at("--robot-id"), "robot_2");
        assert_eq!(at("--controller"), "lpe");
        assert_eq!(at("--model"), "/m/lpe.onnx");
        assert_eq!(at("--map"), "junctions");
        // The service first, then the simulator: both configured, so both are reconnected.
        let connects: Vec<&String> = args
            .iter()
            .zip(args.iter().skip(1))
            .filter(|(flag, _)| *flag == "--connect")
            .map(|(_, value)| value)
            .collect();
        assert_eq!(connects, ["tcp/127.0.0.1:7447", "tcp/127.0.0.1:40001"]);
        assert!(args.iter().any(|a| a == "--no-multicast"));
        assert!(!args.iter().any(|a| a.starts_with("--zenoh-tls")));

        // A secured site: the agent presents its own robot's certificate.
        let mut secured = s.clone();
        secured.security = Some(SiteFiles::new("/site"));
        let cmd = agent_command(
            Path::new("robot-agent"),
            &secured,
            &[],
            &AgentStart {
                id: &RobotId::new("robot_2").unwrap(),
                pose,
                controller: ControllerKind::Lpe,
                model: None,
                restarts: 0,
            },
        );
        let args = args_of(&cmd);
        let at = |flag: &str| flag_value(&args, flag);
        assert_eq!(at("--zenoh-tls-cert"), "/site/agent.robot_2.pem");
        assert_eq!(at("--zenoh-tls-key"), "/site/agent.robot_2.key");
        assert_eq!(at("--zenoh-tls-ca"), "/site/ca.pem");
        assert_eq!(at("--zenoh-acl"), "/site/acl.json5");
        assert!(!args.iter().any(|a| a == "--record"));

        // Recording: one log per start of the agent, a restart does not overwrite the last.
        let mut recording = s.clone();
        recording.record_dir = Some(PathBuf::from("/logs"));
        let log = |restarts| {
            let cmd = agent_command(
                Path::new("robot-agent"),
                &recording,
                &[],
                &AgentStart {
                    id: &RobotId::new("robot_2").unwrap(),
                    pose,
                    controller: ControllerKind::DynamicWindow,
                    model: None,
                    restarts,
                },
            );
            flag_value(&args_of(&cmd), "--record")
        };
        assert_eq!(log(0), "/logs/robot_2.mcap");
        assert_eq!(log(2), "/logs/robot_2-restart2.mcap");
    }

    #[test]
    fn a_process_line_is_awaited_and_the_child_dies_with_its_handle() {
        let mut cmd = Command::new("sh");
        cmd.arg("-c")
            .arg("echo hello; echo '{\"robots\":[]}'; exec sleep 30");
        let mut p = Process::spawn("sh", cmd).unwrap();
        let roster = read_roster(&mut p, Duration::from_secs(10)).unwrap();
        assert!(roster.robots.is_empty());
        assert!(p.is_running());
        let pid = p.pid();
        drop(p);
        // The process is gone (reaped): no /proc entry on Linux.
        if Path::new("/proc").is_dir() {
            assert!(!Path::new(&format!("/proc/{pid}")).exists());
        }
    }

    #[test]
    fn a_bad_roster_line_is_reported() {
        let mut cmd = Command::new("sh");
        cmd.arg("-c")
            .arg("echo '{\"robots\":[{\"id\":\"robot_1\"}]}'");
        let mut p = Process::spawn("sh", cmd).unwrap();
        let err = read_roster(&mut p, Duration::from_secs(10)).unwrap_err();
        assert!(matches!(err, LaunchError::BadRoster(_)), "{err}");
    }
}
