//! The `planner-service` command line: `plan` one path, `bench` the planner, `serve` the fleet
//! API.
//!
//! [`run`] does the work so tests can call it; `main` only parses arguments and reports
//! errors. `serve` settings come from the config file, then the environment (`FLEET_TOKEN`,
//! `FLEET_DATA_DIR`, `FLEET_LISTEN`), then the flags: CLI > env > file > defaults.

use std::io::Write;
use std::net::SocketAddr;
use std::path::{Path as FsPath, PathBuf};
use std::sync::Arc;

use anyhow::Context;
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use map_store::{load_ros_map, ImportLimits};
use protocol::shutdown::StopSignal;
use protocol::{Pose2D, SessionArgs, SiteId};

use crate::bench::{markdown_table, run_bench, BenchOptions};
use crate::config::ServiceConfig;
use crate::http::auth::TokenSource;
use crate::http::{ServeOptions, Server};
use planning::intention::{dlm_on_map, floor_plan_route, render_lpe};
use planning::picture::{render_picture_with_route, save_picture};
use planning::{Planner, PlanningMap};

/// Fleet planner: hybrid A* paths and intentions on floor plans.
#[derive(Debug, Parser)]
#[command(name = "planner-service", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Plan one path on a ROS map and print it.
    Plan(PlanArgs),
    /// Benchmark hybrid A* against 2-D A* on random start/goal pairs.
    Bench(BenchArgs),
    /// Run the fleet service: HTTP API + dashboard, map server and fleet over Zenoh.
    Serve(ServeArgs),
    /// The whole fleet on this machine: the service, the simulator and one agent per robot as
    /// separate processes over Zenoh, until Ctrl-C.
    Demo(DemoArgs),
    /// Benchmark the replanning loop: N simulated robots (a separate process) sending poses at
    /// a rate over Zenoh.
    BenchFleet(BenchFleetArgs),
    /// A Zenoh router: forwards between the sessions connected to it, so robots and the
    /// service on networks that cannot reach each other meet through it (docs/deploy.md).
    Router(RouterArgs),
    /// A replanning worker: joins the site over Zenoh and replans the robots that rendezvous
    /// hashing over the live workers gives it, while the service keeps the task book
    /// (docs/deploy.md).
    Worker(WorkerArgs),
    /// The robots' side of `bench-fleet` (started by it).
    #[command(hide = true)]
    BenchRobots(BenchRobotsArgs),
    /// Benchmark task listing and the live-stream snapshot at growing numbers of stored tasks.
    BenchStore(BenchStoreArgs),
    /// Make a site's Zenoh security folder: a CA, a certificate per process and per robot's
    /// agent, and the access-control rules (acl.json5); an existing CA and certificates are
    /// kept, so adding robots re-issues nothing else.
    Certs(CertsArgs),
}

#[derive(Debug, Args)]
pub struct CertsArgs {
    /// Folder to write (created; an existing site folder is completed).
    #[arg(long)]
    pub out: PathBuf,
    /// Site the rules are for: keys under fleet/<site>/.
    #[arg(long, default_value = map_store::config::DEFAULT_SITE)]
    pub site: SiteId,
    /// Robots that get an agent certificate (repeatable or comma-separated).
    #[arg(long = "robot", value_delimiter = ',')]
    pub robots: Vec<protocol::RobotId>,
    /// Host names or addresses the processes are reached on besides loopback (repeatable):
    /// a session checks a peer's certificate against the endpoint it connects to.
    #[arg(long = "host")]
    pub hosts: Vec<String>,
}

#[derive(Debug, Args)]
pub struct BenchStoreArgs {
    /// Stored tasks, one fresh database each.
    #[arg(long, value_delimiter = ',', default_value = "1000,100000")]
    pub sizes: Vec<usize>,
    /// Of them, tasks that have not ended.
    #[arg(long, default_value_t = 50)]
    pub live: usize,
    /// Timed runs of each indexed read.
    #[arg(long, default_value_t = 200)]
    pub reps: usize,
    /// Timed runs of each full-scan read (the baseline before the index; 0: none).
    #[arg(long, default_value_t = 5)]
    pub baseline_reps: usize,
    /// Write the results as JSON here.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Simulated robots.
    #[arg(long, default_value_t = 3)]
    pub robots: usize,
    /// HTTP address of the API and dashboard.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub listen: SocketAddr,
    /// Data directory (maps, tasks, token); kept between runs.
    #[arg(long, default_value = "out/demo-data")]
    pub data_dir: PathBuf,
    /// Bearer token of mutating routes (default: generated once, kept in the data directory).
    #[arg(long, env = "FLEET_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Configuration file (TOML; see planner.example.toml).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Scenario the simulator runs (default: task_a.yaml, task A's junctions world, in the
    /// scenarios folder: $FLEET_SCENARIOS_DIR, ./sim/scenarios, ./scenarios or the user data
    /// directory).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Controller per robot, cycled: lpe (LPE-Net, the default: it beats the dynamic window in
    /// `eval table`, docs/evaluation.md), dynamic-window, path-tracker, dlm, none.
    #[arg(long, value_delimiter = ',', default_value = "lpe")]
    pub controllers: Vec<protocol::ControllerKind>,
    /// Folder of the dlm/lpe/none models (<controller>.onnx). Default: $FLEET_MODELS_DIR,
    /// ./models or the user data directory.
    #[arg(long)]
    pub models_dir: Option<PathBuf>,
    /// Zenoh mutual TLS and access control between the service, the simulator and the agents
    /// (certificates made once in <data-dir>/zenoh-site; see docs/deploy.md).
    #[arg(long)]
    pub secure: bool,
    /// Record the run as MCAP logs in this folder (docs/logs.md): `<robot id>.mcap` per agent
    /// (`<robot id>-restart<N>.mcap` after a restart) and `sim.mcap` (the first robot's ground
    /// truth), each finished when the demo stops.
    #[arg(long)]
    pub record_dir: Option<PathBuf>,
}

#[derive(Debug, Args)]
pub struct BenchFleetArgs {
    /// Simulated robots.
    #[arg(long, default_value_t = 100)]
    pub robots: usize,
    /// Poses per second per robot.
    #[arg(long, default_value_t = 10.0)]
    pub rate_hz: f64,
    /// Length of the measured run.
    #[arg(long, default_value_t = 20.0)]
    pub duration_s: f64,
    /// Map (ROS YAML); default: Nav2's 100 m x 100 m map with 15 % obstacles, in
    /// <shared>/maps/nav2 ($FLEET_SHARED_DIR, ./shared, ../shared or the user data directory).
    #[arg(long)]
    pub map: Option<PathBuf>,
    /// Speed of the simulated robots along their paths.
    #[arg(long, default_value_t = 0.5)]
    pub speed_mps: f64,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Configuration file (TOML).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Write the results as JSON here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Measure with `[path_reuse]` on, and the same load with a new search every cycle as the
    /// reference in the same run.
    #[arg(long)]
    pub path_reuse: bool,
    /// Seconds of load before the measurement (the first tasks and their first plans, all at
    /// once: a start-up burst, not the fleet at work).
    #[arg(long, default_value_t = 3.0)]
    pub warmup_s: f64,
    /// Replan in this many worker processes (`planner-service worker`) instead of the service.
    #[arg(long, default_value_t = 0)]
    pub workers: usize,
    /// Pin worker k to CPU core k (`taskset`), so each worker has one core.
    #[arg(long)]
    pub pin_workers: bool,
}

#[derive(Debug, Args)]
pub struct RouterArgs {
    /// The endpoints to listen on (`--zenoh-listen`, repeatable; e.g. tcp/0.0.0.0:7447), other
    /// routers to connect to, and the site's TLS and access-control files.
    #[command(flatten)]
    pub zenoh: SessionArgs,
}

#[derive(Debug, Args)]
pub struct WorkerArgs {
    /// This worker's id, unique on the site (its liveliness token and metrics label).
    /// Default: `<host name>-<process id>`.
    #[arg(long)]
    pub worker_id: Option<protocol::WorkerId>,
    /// Configuration file (TOML; see planner.example.toml): the `[planner]`, `[dlm]`, `[lpe]`,
    /// `[path_reuse]` and `[fleet]` tables the service uses, and `[zenoh]`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Site: Zenoh keys are under fleet/<site>/. Default: `[zenoh] site`.
    #[arg(long)]
    pub site: Option<SiteId>,
    /// How long a cycle waits for the service's answer (and a map fetch for the map store's).
    #[arg(long, default_value_t = 2000)]
    pub query_timeout_ms: u64,
    /// The Zenoh session: `--zenoh-connect` the service's endpoint or a router.
    #[command(flatten)]
    pub zenoh: SessionArgs,
}

#[derive(Debug, Args)]
pub struct BenchRobotsArgs {
    /// The service's Zenoh endpoint (repeatable).
    #[arg(long, required = true)]
    pub connect: Vec<String>,
    /// The robots, their starts and goals, the site and the map (JSON, written by bench-fleet).
    #[arg(long)]
    pub plan: PathBuf,
    #[arg(long)]
    pub rate_hz: f64,
    #[arg(long)]
    pub duration_s: f64,
    #[arg(long, default_value_t = 0.0)]
    pub warmup_s: f64,
    #[arg(long)]
    pub speed_mps: f64,
}

#[derive(Debug, Args)]
pub struct ServeArgs {
    /// HTTP address, e.g. 127.0.0.1:8080 (port 0: any free port). Default: `[http] listen`.
    #[arg(long, env = "FLEET_LISTEN")]
    pub listen: Option<SocketAddr>,
    /// Data directory: maps, tasks, the generated token.
    #[arg(long, env = "FLEET_DATA_DIR")]
    pub data_dir: PathBuf,
    /// Bearer token of mutating routes. Default: `[http] token`, else generated once and kept
    /// in <data-dir>/token.
    #[arg(long, env = "FLEET_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Configuration file (TOML; see planner.example.toml).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Site: Zenoh keys are under fleet/<site>/. Default: `[zenoh] site`.
    #[arg(long)]
    pub site: Option<SiteId>,
    /// The Zenoh session: `--zenoh-listen` / `--zenoh-connect` replace `[zenoh] listen` /
    /// `connect`, `--zenoh-multicast-scouting` turns `[zenoh] multicast` on.
    #[command(flatten)]
    pub zenoh: SessionArgs,
}

impl ServeArgs {
    /// The configuration file (or defaults) with the environment and flags applied on top.
    ///
    /// # Errors
    /// The file cannot be read or parsed, or a flag's value is invalid (named).
    pub fn resolve(&self) -> anyhow::Result<ServeOptions> {
        let mut config = load_config(self.config.as_deref())?;
        // clap already chose flag over environment for these.
        if let Some(listen) = self.listen {
            config.http.listen = listen;
        }
        if let Some(token) = &self.token {
            config.http.token = Some(token.clone());
        }
        if let Some(site) = &self.site {
            config.zenoh.site = site.clone();
        }
        config.zenoh.override_with(&self.zenoh);
        config
            .validate()
            .map_err(|reason| anyhow::anyhow!("invalid settings: {reason}"))?;
        Ok(ServeOptions {
            config,
            data_dir: self.data_dir.clone(),
        })
    }
}

#[derive(Debug, Args)]
pub struct PlanArgs {
    /// ROS map_server YAML.
    #[arg(long)]
    pub map: PathBuf,
    /// Start pose `x,y,yaw` (metres, metres, radians) in the map frame.
    #[arg(long, allow_hyphen_values = true)]
    pub start: Pose2D,
    /// Goal pose `x,y,yaw`.
    #[arg(long, allow_hyphen_values = true)]
    pub goal: Pose2D,
    /// Configuration file (TOML with `[planner]`, `[dlm]`, `[lpe]`); defaults otherwise.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Write the LPE intention image at the start as PNG.
    #[arg(long)]
    pub lpe: Option<PathBuf>,
    /// Write a picture of the map and path as PNG.
    #[arg(long)]
    pub picture: Option<PathBuf>,
}

#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Random start/goal pairs per map.
    #[arg(long, default_value_t = 1000)]
    pub pairs: usize,
    /// Map YAML files (default: the three Nav2 100by100 maps in <shared>/maps/nav2).
    #[arg(long, num_args = 1..)]
    pub maps: Vec<PathBuf>,
    /// Write the results as JSON here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Seed of the pair sampler.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Configuration file (its `[planner]` table is used).
    #[arg(long)]
    pub config: Option<PathBuf>,
}

fn load_config(path: Option<&FsPath>) -> anyhow::Result<ServiceConfig> {
    Ok(match path {
        Some(p) => ServiceConfig::load(p)?,
        None => ServiceConfig::default(),
    })
}

/// Runs a parsed command line, writing results to `out`.
///
/// # Errors
/// Any failure, with context; nothing is written to files named in the arguments unless the
/// plan succeeded.
pub fn run(cli: Cli, out: &mut dyn Write) -> anyhow::Result<()> {
    match cli.command {
        Command::Plan(args) => plan(&args, out),
        Command::Bench(args) => bench(&args, out),
        Command::Serve(args) => serve(&args, out),
        Command::Demo(args) => demo(args, out),
        Command::BenchFleet(args) => bench_fleet(&args, out),
        Command::BenchRobots(args) => bench_robots(&args, out),
        Command::Router(args) => router(&args, out),
        Command::Worker(args) => worker(&args, out),
        Command::BenchStore(args) => bench_store(&args, out),
        Command::Certs(args) => certs(&args, out),
    }
}

fn certs(args: &CertsArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    use protocol::security::{issue, Identity, SiteFiles};
    let files = SiteFiles::new(&args.out);
    let report = issue(&files, &args.site, &args.robots, &args.hosts)?;
    if report.new_ca {
        writeln!(out, "new site CA: {}", files.ca_cert().display())?;
    }
    for identity in &report.issued {
        writeln!(out, "issued {identity}: {}", files.cert(identity).display())?;
    }
    for identity in &report.kept {
        writeln!(out, "kept   {identity}")?;
    }
    writeln!(
        out,
        "rules: {} ({} robots)\nkeep {} off the robots; each process gets ca.pem, its own \
         .pem and .key, and acl.json5:",
        files.acl().display(),
        report.robots.len(),
        files.ca_key().display()
    )?;
    let example = Identity::Planner;
    writeln!(
        out,
        "  --zenoh-tls-ca {} --zenoh-tls-cert {} --zenoh-tls-key {} --zenoh-acl {}",
        files.ca_cert().display(),
        files.cert(&example).display(),
        files.key(&example).display(),
        files.acl().display()
    )?;
    Ok(())
}

fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("cannot start the tokio runtime")
}

fn demo(args: DemoArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    let serve = ServeArgs {
        listen: Some(args.listen),
        data_dir: args.data_dir,
        token: args.token,
        config: args.config,
        site: None,
        zenoh: SessionArgs::default(),
    }
    .resolve()?;
    let opts = crate::demo::DemoOptions {
        serve,
        robots: args.robots,
        scenario: match args.scenario {
            Some(s) => s,
            None => protocol::data_dirs::find_scenarios_dir(None)?.join("task_a.yaml"),
        },
        controllers: args.controllers,
        bin_dir: None,
        models_dir: args.models_dir,
        secure: args.secure,
        record_dir: args.record_dir,
    };
    runtime()?.block_on(crate::demo::run(opts, out))
}

fn bench_fleet(args: &BenchFleetArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    let opts = crate::fleet_bench::FleetBenchOptions {
        map_yaml: match &args.map {
            Some(m) => m.clone(),
            None => protocol::data_dirs::find_nav2_maps_dir(None)?.join("100by100_15.yaml"),
        },
        robots: args.robots,
        rate_hz: args.rate_hz,
        duration_s: args.duration_s,
        warmup_s: args.warmup_s,
        speed_mps: args.speed_mps,
        seed: args.seed,
        config: load_config(args.config.as_deref())?,
        path_reuse: args.path_reuse,
        workers: args.workers,
        pin_workers: args.pin_workers,
        robots_exe: std::env::current_exe().context("cannot find this executable")?,
    };
    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message(format!("{} robots at {} Hz", opts.robots, opts.rate_hz));
    let report = runtime()?.block_on(crate::fleet_bench::run_fleet_bench(&opts, &bar))?;
    bar.finish_and_clear();
    write!(out, "{}", crate::fleet_bench::markdown(&report))?;
    if let Some(path) = &args.out {
        std::fs::write(path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

fn router(args: &RouterArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    runtime()?.block_on(async {
        let stop = StopSignal::install().context("cannot listen for SIGTERM")?;
        let session = args
            .zenoh
            .open_router()
            .await
            .context("cannot start the Zenoh router")?;
        writeln!(
            out,
            "zenoh router: {}",
            protocol::zenoh_io::locators(&session).await.join(" ")
        )?;
        out.flush()?;
        stop.wait().await.context("cannot listen for Ctrl-C")?;
        writeln!(out, "stopping")?;
        session
            .close()
            .await
            .map_err(|e| anyhow::anyhow!("closing the router: {e}"))?;
        Ok(())
    })
}

/// The line a worker prints once it has joined the site (tests and launchers wait for it).
pub const WORKER_READY_PREFIX: &str = "worker ready: ";

fn worker(args: &WorkerArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    use crate::fleet::remote::{WorkerNode, WorkerOptions};
    let mut config = load_config(args.config.as_deref())?;
    if let Some(site) = &args.site {
        config.zenoh.site = site.clone();
    }
    config.zenoh.override_with(&args.zenoh);
    config
        .validate()
        .map_err(|reason| anyhow::anyhow!("invalid settings: {reason}"))?;
    if args.query_timeout_ms == 0 {
        anyhow::bail!("invalid --query-timeout-ms = 0: must be positive");
    }
    let id = match &args.worker_id {
        Some(id) => id.clone(),
        None => default_worker_id()?,
    };
    runtime()?.block_on(async {
        let stop = StopSignal::install().context("cannot listen for SIGTERM")?;
        let session = config
            .zenoh
            .session_args()
            .open()
            .await
            .context("cannot open the Zenoh session")?;
        let options = WorkerOptions {
            id: id.clone(),
            site: config.zenoh.site.clone(),
            query_timeout: std::time::Duration::from_millis(args.query_timeout_ms),
            config,
        };
        let node = WorkerNode::start(session.clone(), options)
            .await
            .context("cannot join the site")?;
        writeln!(
            out,
            "{WORKER_READY_PREFIX}{id} (zenoh: {})",
            protocol::zenoh_io::locators(&session).await.join(" ")
        )?;
        out.flush()?;
        stop.wait().await.context("cannot listen for Ctrl-C")?;
        writeln!(out, "stopping after {} cycles", node.cycles())?;
        out.flush()?;
        node.shutdown().await;
        session
            .close()
            .await
            .map_err(|e| anyhow::anyhow!("closing the Zenoh session: {e}"))?;
        Ok(())
    })
}

fn default_worker_id() -> anyhow::Result<protocol::WorkerId> {
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::env::var("HOSTNAME"))
        .unwrap_or_else(|_| "worker".into());
    // Host names may hold characters ids do not: keep the allowed ones.
    let host: String = host
        .trim()
        .chars()
        .filter(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-'))
        .take(40)
        .collect();
    let host = if host.is_empty() {
        "worker".into()
    } else {
        host
    };
    protocol::WorkerId::new(format!("{host}-{}", std::process::id()))
        .context("cannot make a worker id from the host name; pass --worker-id")
}

fn bench_robots(args: &BenchRobotsArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    let plan: crate::fleet_bench::RobotsPlan = serde_json::from_slice(
        &std::fs::read(&args.plan)
            .with_context(|| format!("cannot read {}", args.plan.display()))?,
    )
    .with_context(|| format!("{}: not a bench-fleet robots plan", args.plan.display()))?;
    let opts = crate::fleet_bench::RobotsOptions {
        connect: args.connect.clone(),
        plan,
        rate_hz: args.rate_hz,
        duration_s: args.duration_s,
        warmup_s: args.warmup_s,
        speed_mps: args.speed_mps,
    };
    let mut announced = Ok(());
    let result = runtime()?.block_on(crate::fleet_bench::run_robots(&opts, &mut |line| {
        if announced.is_ok() {
            announced = writeln!(out, "{line}").and_then(|()| out.flush());
        }
    }))?;
    announced?;
    writeln!(
        out,
        "{}{}",
        crate::fleet_bench::RESULT_PREFIX,
        serde_json::to_string(&result)?
    )?;
    Ok(())
}

fn bench_store(args: &BenchStoreArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    let opts = crate::store_bench::StoreBenchOptions {
        sizes: args.sizes.clone(),
        live: args.live,
        reps: args.reps.max(1),
        baseline_reps: args.baseline_reps,
    };
    let report = crate::store_bench::run_store_bench(&opts, &mut |msg| eprintln!("{msg}"))?;
    write!(out, "{}", crate::store_bench::markdown(&report))?;
    if let Some(path) = &args.out {
        std::fs::write(path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

fn serve(args: &ServeArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    let opts = args.resolve()?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("cannot start the tokio runtime")?;
    runtime.block_on(async {
        // Listen for SIGTERM before saying we listen: a supervisor may stop us at once.
        let stop = StopSignal::install().context("cannot listen for SIGTERM")?;
        let server = Server::start(opts).await?;
        writeln!(out, "listening on {}", server.url())?;
        match server.token_source() {
            TokenSource::Configured => writeln!(out, "token: {}", server.token())?,
            TokenSource::Stored(p) => {
                writeln!(out, "token: {} (from {})", server.token(), p.display())?
            }
            TokenSource::Generated(p) => {
                writeln!(
                    out,
                    "token: {} (generated, stored in {})",
                    server.token(),
                    p.display()
                )?;
            }
        }
        writeln!(out, "zenoh: {}", server.zenoh_locators().await.join(" "))?;
        out.flush()?;
        stop.wait().await.context("cannot listen for Ctrl-C")?;
        writeln!(out, "stopping")?;
        out.flush()?;
        server.stop().await?;
        Ok(())
    })
}

/// Ctrl-C, or SIGTERM on Unix (what `kill` and process supervisors send).
pub(crate) async fn wait_for_stop_signal() -> anyhow::Result<()> {
    StopSignal::install()
        .context("cannot listen for SIGTERM")?
        .wait()
        .await
        .context("cannot listen for Ctrl-C")
}

fn plan(args: &PlanArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    let cfg = load_config(args.config.as_deref())?;
    let ros = load_ros_map(&args.map, &ImportLimits::default())?;
    let map = Arc::new(PlanningMap::new(ros.grid, &cfg.planner)?);
    let mut planner = Planner::new(Arc::clone(&map), cfg.planner.clone())?;
    let path = planner
        .plan(args.start, args.goal)
        .context("planning failed")?;
    let dlm = dlm_on_map(
        &map,
        &path.poses,
        args.start,
        args.goal,
        &cfg.dlm,
        None,
        &[],
    );

    if let Some(lpe_path) = &args.lpe {
        let img = render_lpe(map.grid(), args.start, &[], &path.poses, &cfg.lpe)?;
        img.save_png(lpe_path)?;
    }
    if let Some(pic) = &args.picture {
        // The route measure's route, as far as the path goes, beside the path it measures
        // instead.
        let route = cfg
            .dlm
            .measure
            .uses_route()
            .then(|| floor_plan_route(&map, args.start, args.goal, path.length_m))
            .flatten()
            .unwrap_or_default();
        save_picture(
            &render_picture_with_route(map.grid(), &path.poses, &route),
            pic,
        )?;
    }
    if args.json {
        let doc = serde_json::json!({
            "map": args.map.display().to_string(),
            "start": args.start,
            "goal": args.goal,
            "dlm": dlm.as_str(),
            "path": path,
        });
        writeln!(out, "{}", serde_json::to_string_pretty(&doc)?)?;
    } else {
        #[allow(clippy::cast_precision_loss)]
        let plan_ms = path.plan_time_us as f64 / 1e3;
        writeln!(out, "map: {}", args.map.display())?;
        writeln!(
            out,
            "length: {:.3} m, {} poses",
            path.length_m,
            path.poses.len()
        )?;
        writeln!(out, "planning time: {plan_ms:.3} ms")?;
        writeln!(out, "states expanded: {}", path.states_expanded)?;
        writeln!(
            out,
            "heuristic cache hit: {}",
            path.stats.heuristic_cache_hit
        )?;
        writeln!(out, "DLM at start: {dlm}")?;
        writeln!(out, "poses (x_m y_m yaw_rad):")?;
        for p in &path.poses {
            writeln!(out, "{:.3} {:.3} {:.4}", p.x_m, p.y_m, p.yaw_rad)?;
        }
    }
    Ok(())
}

fn bench(args: &BenchArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    let cfg = load_config(args.config.as_deref())?;
    let mut opts = if args.maps.is_empty() {
        BenchOptions::nav2_default(&protocol::data_dirs::find_nav2_maps_dir(None)?)
    } else {
        BenchOptions::with_maps(args.maps.clone())
    };
    opts.pairs = args.pairs;
    opts.seed = args.seed;
    opts.config = cfg.planner;
    let total = (opts.pairs * opts.maps.len()) as u64;
    let bar = ProgressBar::new(total);
    if let Ok(style) =
        ProgressStyle::with_template("{bar:40} {pos}/{len} pairs {elapsed} eta {eta}")
    {
        bar.set_style(style);
    }
    let command: Vec<String> = std::env::args().collect();
    let report = run_bench(&opts, command.join(" "), &bar)?;
    bar.finish_and_clear();
    if let Some(path) = &args.out {
        std::fs::write(path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    write!(out, "{}", markdown_table(&report))?;
    for m in &report.maps {
        for f in &m.failures {
            writeln!(out, "failure on {}: {f}", m.map)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn poses_parse_and_errors_name_the_part() {
        let plan = |start: &str| {
            Cli::try_parse_from([
                "planner-service",
                "plan",
                "--map",
                "m.yaml",
                "--start",
                start,
                "--goal",
                "1,1,0",
            ])
            .map(|cli| match cli.command {
                Command::Plan(args) => args.start,
                _ => unreachable!("parsed a plan command"),
            })
            .map_err(|e| e.to_string())
        };
        assert_eq!(plan("1.5,-2,0.3").unwrap(), Pose2D::new(1.5, -2.0, 0.3));
        assert_eq!(plan("-1.5,-2,0.3").unwrap(), Pose2D::new(-1.5, -2.0, 0.3));
        let e = plan("1,2").unwrap_err();
        assert!(e.contains("--start") && e.contains("x,y,yaw"), "{e}");
        assert!(plan("1,nan,0").unwrap_err().contains("y = \"nan\""));
        assert!(plan("1,2,abc").unwrap_err().contains("yaw = \"abc\""));
    }

    #[test]
    fn serve_takes_the_shared_zenoh_flags() {
        Cli::command().debug_assert();
        let cli = Cli::try_parse_from([
            "planner-service",
            "serve",
            "--data-dir",
            "/tmp/d",
            "--listen",
            "127.0.0.1:0",
            "--zenoh-listen",
            "tcp/127.0.0.1:0",
            "--zenoh-connect",
            "tcp/10.0.0.2:7447",
            "--zenoh-multicast-scouting",
        ])
        .unwrap();
        let Command::Serve(args) = cli.command else {
            unreachable!("parsed a serve command")
        };
        assert_eq!(args.listen, Some(SocketAddr::from(([127, 0, 0, 1], 0))));
        let opts = args.resolve().unwrap();
        assert_eq!(opts.config.zenoh.listen, ["tcp/127.0.0.1:0"]);
        assert_eq!(opts.config.zenoh.connect, ["tcp/10.0.0.2:7447"]);
        assert!(opts.config.zenoh.multicast);
        let bad = Cli::try_parse_from([
            "planner-service",
            "serve",
            "--data-dir",
            "/tmp/d",
            "--zenoh-connect",
            "nonsense",
        ])
        .unwrap();
        let Command::Serve(args) = bad.command else {
            unreachable!("parsed a serve command")
        };
        let e = format!("{:#}", args.resolve().unwrap_err());
        assert!(e.contains("connect") && e.contains("nonsense"), "{e}");
    }
}
