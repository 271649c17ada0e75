//! Multi-process end-to-end harness: starts the real binaries (planner service, simulator,
//! robot agents) as separate processes talking over Zenoh on loopback, and drives them over
//! HTTP the way an operator does with curl.
//!
//! The binaries come from the cargo target folder of the test executable
//! (`target/<profile>/`), or from `FLEET_BIN_DIR`; `scripts/test.sh` builds them before the
//! tests run. The simulator and the agents are started by the same launcher as
//! `planner-service demo` ([`planner_service::launch`], via [`start_robots`]); every process is
//! a [`Process`], killed when its handle drops, so a failing test leaves nothing behind.

use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

pub use planner_service::launch::{LaunchError, Process, Robots, RobotsSpec};
use protocol::{ControllerKind, MapName};
use serde_json::Value;
/// The repository root (for the scenarios and floor plans).
pub use test_support::repo_root;

/// The child processes' log filter unless `RUST_LOG` is set: a failing test prints its
/// children's output, and Zenoh's link openings and closings are what tell a lost connection
/// from a stalled process.
const CHILD_LOG: &str = "info,zenoh_transport=debug,zenoh::net::runtime::orchestrator=debug";

/// `RUST_LOG`, else [`CHILD_LOG`].
fn child_log() -> String {
    std::env::var("RUST_LOG").unwrap_or_else(|_| CHILD_LOG.into())
}

/// A harness failure, with what was being done.
#[derive(Debug, thiserror::Error)]
pub enum HarnessError {
    #[error("{0}")]
    Setup(String),
    #[error("{what}: {source}")]
    Io {
        what: String,
        #[source]
        source: std::io::Error,
    },
    #[error("HTTP {what}: {reason}")]
    Http { what: String, reason: String },
    #[error("timed out after {after:?} waiting for {what}")]
    Timeout { what: String, after: Duration },
    #[error(transparent)]
    Launch(#[from] LaunchError),
}

type Result<T> = std::result::Result<T, HarnessError>;

fn io(what: impl Into<String>) -> impl FnOnce(std::io::Error) -> HarnessError {
    let what = what.into();
    move |source| HarnessError::Io { what, source }
}

/// The folder with `planner-service`, `sim` and `robot-agent`.
///
/// # Errors
/// [`HarnessError::Setup`] naming the missing binary and how to build it.
pub fn bin_dir() -> Result<PathBuf> {
    let dir = match std::env::var_os("FLEET_BIN_DIR") {
        Some(d) => PathBuf::from(d),
        None => {
            let exe = std::env::current_exe().map_err(io("locate the test executable"))?;
            // target/<profile>/deps/<test> → target/<profile>
            exe.parent()
                .and_then(Path::parent)
                .map(Path::to_path_buf)
                .ok_or_else(|| HarnessError::Setup("test executable has no folder".into()))?
        }
    };
    for name in ["planner-service", "sim", "robot-agent"] {
        if !dir.join(name).is_file() {
            return Err(HarnessError::Setup(format!(
                "no {name} in {}: run `cargo build --workspace --bins` first (scripts/test.sh does)",
                dir.display()
            )));
        }
    }
    Ok(dir)
}

/// A TCP port that was free a moment ago (for endpoints that must stay the same across a
/// restart of the service).
///
/// # Errors
/// If no port can be bound.
pub fn free_port() -> Result<u16> {
    let l = TcpListener::bind("127.0.0.1:0").map_err(io("bind a free port"))?;
    Ok(l.local_addr().map_err(io("read the free port"))?.port())
}

/// A running planner service.
pub struct Service {
    pub proc: Process,
    pub url: String,
    pub token: String,
    /// The Zenoh endpoint robots connect to.
    pub zenoh: String,
}

impl Service {
    /// Starts `planner-service serve` on a free HTTP port with its Zenoh listener on
    /// `zenoh_port` (fixed, so robots find a restarted service again).
    ///
    /// # Errors
    /// If it does not print its address within 60 s.
    pub fn start(bins: &Path, data_dir: &Path, zenoh_port: u16, token: &str) -> Result<Self> {
        let zenoh = format!("tcp/127.0.0.1:{zenoh_port}");
        let args: Vec<String> = vec![
            "serve".into(),
            "--listen".into(),
            "127.0.0.1:0".into(),
            "--data-dir".into(),
            data_dir.display().to_string(),
            "--token".into(),
            token.into(),
            "--zenoh-listen".into(),
            zenoh.clone(),
        ];
        let mut cmd = Command::new(bins.join("planner-service"));
        cmd.args(&args)
            .env("RUST_LOG", child_log())
            .env_remove("RUST_BACKTRACE");
        let mut proc = Process::spawn("service", cmd)?;
        let url = proc.wait_line(Duration::from_secs(60), |l| {
            l.strip_prefix("listening on ")
                .map(|u| u.trim().to_string())
        })?;
        Ok(Self {
            proc,
            url,
            token: token.into(),
            zenoh,
        })
    }

    /// Starts `planner-service demo` (the service, the simulator and `robots` agents, on
    /// `scenario`) on a free HTTP port, with `config` as its configuration file if given. Its
    /// [`Service::zenoh`] is the endpoint it prints.
    ///
    /// # Errors
    /// If it does not print its address, token and Zenoh endpoint within 120 s.
    pub fn start_demo(
        bins: &Path,
        data_dir: &Path,
        scenario: &Path,
        robots: usize,
        token: &str,
        config: Option<&Path>,
        extra_args: &[&str],
    ) -> Result<Self> {
        let mut cmd = Command::new(bins.join("planner-service"));
        cmd.arg("demo")
            .args(extra_args)
            .arg("--listen")
            .arg("127.0.0.1:0")
            .arg("--data-dir")
            .arg(data_dir)
            .arg("--token")
            .arg(token)
            .arg("--scenario")
            .arg(scenario)
            .arg("--robots")
            .arg(robots.to_string())
            .env("RUST_LOG", child_log())
            .env_remove("RUST_BACKTRACE");
        if std::env::var_os("FLEET_MODELS_DIR").is_none() {
            // The demo's robots drive with LPE-Net; the tests run outside the repository root.
            cmd.env("FLEET_MODELS_DIR", repo_root().join("models"));
        }
        if let Some(config) = config {
            cmd.arg("--config").arg(config);
        }
        let mut proc = Process::spawn("demo", cmd)?;
        let wait = Duration::from_secs(120);
        let url = proc.wait_line(wait, |l| {
            l.strip_prefix("listening on ")
                .map(|u| u.trim().to_string())
        })?;
        let zenoh = proc.wait_line(wait, |l| {
            l.strip_prefix("zenoh: ").map(|u| u.trim().to_string())
        })?;
        Ok(Self {
            proc,
            url,
            token: token.into(),
            zenoh,
        })
    }

    fn client() -> Result<reqwest::blocking::Client> {
        reqwest::blocking::Client::builder()
            .timeout(Duration::from_secs(30))
            .build()
            .map_err(|e| HarnessError::Http {
                what: "client".into(),
                reason: e.to_string(),
            })
    }

    /// GET a JSON document.
    ///
    /// # Errors
    /// Transport failures or a non-2xx status (with the body).
    pub fn get(&self, path: &str) -> Result<Value> {
        let resp = Self::client()?
            .get(format!("{}{path}", self.url))
            .send()
            .map_err(|e| http_err(path, &e))?;
        json_of(path, resp)
    }

    /// POST JSON with the token; returns (status, body).
    ///
    /// # Errors
    /// Transport failures.
    pub fn post(&self, path: &str, body: &Value) -> Result<(u16, Value)> {
        let resp = Self::client()?
            .post(format!("{}{path}", self.url))
            .bearer_auth(&self.token)
            .json(body)
            .send()
            .map_err(|e| http_err(path, &e))?;
        let status = resp.status().as_u16();
        let text = resp.text().map_err(|e| http_err(path, &e))?;
        let value = serde_json::from_str(&text).unwrap_or(Value::String(text));
        Ok((status, value))
    }

    /// Uploads a ROS floor plan (YAML + image) as multipart.
    ///
    /// # Errors
    /// Transport failures or a non-2xx status.
    pub fn upload_ros_map(&self, name: &str, yaml: &Path) -> Result<Value> {
        let text = std::fs::read_to_string(yaml).map_err(io(format!("read {}", yaml.display())))?;
        let image_name = text
            .lines()
            .find_map(|l| l.trim().strip_prefix("image:"))
            .map(|v| v.trim().trim_matches(['\'', '"']).to_string())
            .ok_or_else(|| HarnessError::Setup(format!("{} names no image", yaml.display())))?;
        let image_path = yaml.parent().unwrap_or(Path::new(".")).join(&image_name);
        let image =
            std::fs::read(&image_path).map_err(io(format!("read {}", image_path.display())))?;
        let form = reqwest::blocking::multipart::Form::new()
            .text("name", name.to_string())
            .part(
                "yaml",
                reqwest::blocking::multipart::Part::text(text).file_name("map.yaml"),
            )
            .part(
                "image",
                reqwest::blocking::multipart::Part::bytes(image).file_name(image_name),
            );
        let resp = Self::client()?
            .post(format!("{}/api/v1/maps", self.url))
            .bearer_auth(&self.token)
            .multipart(form)
            .send()
            .map_err(|e| http_err("/api/v1/maps", &e))?;
        json_of("/api/v1/maps", resp)
    }

    /// Polls `path` until `pick` returns something.
    ///
    /// # Errors
    /// [`HarnessError::Timeout`] with the last document seen.
    pub fn wait_for<T>(
        &self,
        path: &str,
        timeout: Duration,
        mut pick: impl FnMut(&Value) -> Option<T>,
    ) -> Result<T> {
        let deadline = Instant::now() + timeout;
        let mut last = Value::Null;
        loop {
            if let Ok(v) = self.get(path) {
                if let Some(t) = pick(&v) {
                    return Ok(t);
                }
                last = v;
            }
            if Instant::now() > deadline {
                return Err(HarnessError::Timeout {
                    what: format!("{path} (last: {})", truncate(&last.to_string(), 600)),
                    after: timeout,
                });
            }
            std::thread::sleep(Duration::from_millis(250));
        }
    }
}

fn truncate(s: &str, n: usize) -> &str {
    match s.char_indices().nth(n) {
        Some((i, _)) => &s[..i],
        None => s,
    }
}

fn http_err(what: &str, e: &reqwest::Error) -> HarnessError {
    HarnessError::Http {
        what: what.into(),
        reason: e.to_string(),
    }
}

fn json_of(what: &str, resp: reqwest::blocking::Response) -> Result<Value> {
    let status = resp.status();
    let text = resp.text().map_err(|e| http_err(what, &e))?;
    if !status.is_success() {
        return Err(HarnessError::Http {
            what: what.into(),
            reason: format!("{status}: {text}"),
        });
    }
    serde_json::from_str(&text).map_err(|e| HarnessError::Http {
        what: what.into(),
        reason: format!("not JSON ({e}): {text}"),
    })
}

/// Starts the simulator on `scenario` with `robots` robots and one `controller` agent per
/// robot on `map`, all connected to the service's Zenoh endpoint `zenoh`.
///
/// # Errors
/// A bad map name, or [`LaunchError`] (the simulator does not report its robots within 60 s, a
/// child cannot start).
pub fn start_robots(
    bins: &Path,
    scenario: &Path,
    robots: usize,
    map: &str,
    controller: ControllerKind,
    zenoh: &str,
) -> Result<Robots> {
    let map = MapName::new(map).map_err(|e| HarnessError::Setup(format!("map {map:?}: {e}")))?;
    let mut spec = RobotsSpec::new(bins, scenario, robots, map, vec![zenoh.to_string()]);
    spec.controllers = vec![controller];
    Ok(Robots::start(&spec)?)
}

/// The children of process `parent` whose command line contains every one of `args` (Linux:
/// read from `/proc`; empty elsewhere).
#[must_use]
pub fn child_pids(parent: u32, args: &[&str]) -> Vec<u32> {
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return Vec::new();
    };
    let mut pids: Vec<u32> = entries
        .flatten()
        .filter_map(|e| e.file_name().to_str()?.parse::<u32>().ok())
        .filter(|pid| {
            // `stat` is "pid (comm) state ppid …"; comm may hold spaces, so split after ')'.
            let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else {
                return false;
            };
            let ppid = stat
                .rsplit_once(')')
                .and_then(|(_, rest)| rest.split_whitespace().nth(1))
                .and_then(|v| v.parse::<u32>().ok());
            if ppid != Some(parent) {
                return false;
            }
            let Ok(cmdline) = std::fs::read(format!("/proc/{pid}/cmdline")) else {
                return false;
            };
            let words: Vec<&[u8]> = cmdline.split(|b| *b == 0).collect();
            args.iter().all(|a| words.contains(&a.as_bytes()))
        })
        .collect();
    pids.sort_unstable();
    pids
}

/// The robot `id` in a robot list.
#[must_use]
pub fn robot<'a>(robots: &'a Value, id: &str) -> Option<&'a Value> {
    robots.as_array()?.iter().find(|r| r["id"] == id)
}

/// The `state.kind` of a task document.
#[must_use]
pub fn state_kind(task: &Value) -> &str {
    task["state"]["kind"].as_str().unwrap_or("")
}

/// Waits (up to 90 s) until `robot_id` is online with a pose, then gives it a one-goal task to
/// `goal` (x, y in metres) on `map`; the task's id.
///
/// # Errors
/// [`HarnessError::Timeout`] when the robot never shows up, HTTP failures, or a task the
/// service refuses.
pub fn task_once_online(
    service: &Service,
    robot_id: &str,
    map: &str,
    goal: (f64, f64),
) -> Result<String> {
    service.wait_for("/api/v1/robots", Duration::from_secs(90), |v| {
        robot(v, robot_id)
            .and_then(|r| (r["online"] == true && r["pose"].is_object()).then_some(()))
    })?;
    let body = serde_json::json!({
        "map": map,
        "robot_id": robot_id,
        "goals": [{"x_m": goal.0, "y_m": goal.1}],
    });
    let (status, task) = service.post("/api/v1/tasks", &body)?;
    match task["id"].as_str() {
        Some(id) if status == 201 => Ok(id.to_string()),
        _ => Err(HarnessError::Http {
            what: "/api/v1/tasks".into(),
            reason: format!("{status}: {task}"),
        }),
    }
}

/// The state kinds a task document went through (its `history`), oldest first.
#[must_use]
pub fn history_kinds(task: &Value) -> Vec<&str> {
    task["history"]
        .as_array()
        .map(|h| h.iter().map(state_kind).collect())
        .unwrap_or_default()
}

/// Whether a task was paused, then active again, and ended completed.
#[must_use]
pub fn resumed_after_a_pause_and_completed(task: &Value) -> bool {
    let kinds = history_kinds(task);
    kinds
        .iter()
        .position(|k| *k == "paused")
        .is_some_and(|at| kinds[at..].contains(&"active"))
        && kinds.last() == Some(&"completed")
}

/// Where the service last saw robot `id` (x, y in metres), if it has a pose.
///
/// # Errors
/// Transport failures or a non-2xx status.
pub fn robot_xy(service: &Service, id: &str) -> Result<Option<(f64, f64)>> {
    let r = service.get(&format!("/api/v1/robots/{id}"))?;
    Ok(r["pose"]["x_m"].as_f64().zip(r["pose"]["y_m"].as_f64()))
}

/// Starts `planner-service worker --worker-id id` connected to `zenoh` (with `extra` flags
/// before it, e.g. `--zenoh-mode client`) and waits until it has joined the site.
///
/// # Errors
/// [`LaunchError`] when it cannot start or does not say it is ready within 60 s.
pub fn start_worker(command: Command, id: &str, zenoh: &str, extra: &[&str]) -> Result<Process> {
    let mut cmd = command;
    cmd.arg("worker")
        .args(["--worker-id", id, "--zenoh-connect", zenoh])
        .args(extra)
        .env("RUST_LOG", child_log());
    let mut proc = Process::spawn(&format!("worker {id}"), cmd)?;
    proc.wait_line(Duration::from_secs(60), |l| {
        l.starts_with(planner_service::cli::WORKER_READY_PREFIX)
            .then_some(())
    })?;
    Ok(proc)
}

/// The worker (`id` of `GET /api/v1/workers`) whose last cycle for robot `robot_id` it ran,
/// if any.
///
/// # Errors
/// Transport failures or a non-2xx status.
pub fn planned_by(service: &Service, robot_id: &str) -> Result<Option<String>> {
    let workers = service.get("/api/v1/workers")?;
    Ok(workers.as_array().and_then(|all| {
        all.iter()
            .find(|w| {
                w["robots"]
                    .as_array()
                    .is_some_and(|r| r.iter().any(|id| id == robot_id))
            })
            .and_then(|w| w["id"].as_str().map(str::to_string))
    }))
}

/// The ids of the workers `GET /api/v1/workers` lists alive (the service included).
///
/// # Errors
/// Transport failures or a non-2xx status.
pub fn alive_workers(service: &Service) -> Result<Vec<String>> {
    let workers = service.get("/api/v1/workers")?;
    Ok(workers
        .as_array()
        .map(|all| {
            all.iter()
                .filter(|w| w["alive"] == true)
                .filter_map(|w| w["id"].as_str().map(str::to_string))
                .collect()
        })
        .unwrap_or_default())
}
