//! Several hosts through a Zenoh router (issue 16, docs/deploy.md): the robots (simulator and
//! agent) in one Linux network namespace, the planner service and a replanning worker in
//! another, and `planner-service router` between them, each namespace joined to the router's by its own
//! veth pair, so the only way between robots and service is through the router. The worker,
//! not the service, plans the robot. Cutting the robots' link pauses their task with a reason;
//! restoring it resumes the task, which completes.
//!
//! Needs root (`ip netns`, `ip link`): CI runs as root. Elsewhere the test says so and passes.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use fleet_tests::{
    alive_workers, bin_dir, free_port, history_kinds, planned_by, repo_root,
    resumed_after_a_pause_and_completed, robot_xy, start_worker, state_kind, task_once_online,
    Process, Robots, RobotsSpec, Service,
};
use protocol::MapName;
use serde_json::Value;

const TOKEN: &str = "multihost-test-token-0123456789abcdef";

fn ip(args: &[&str]) {
    let status = Command::new("ip").args(args).status().unwrap();
    assert!(status.success(), "ip {}", args.join(" "));
}

/// A network namespace joined to the root namespace by a veth pair: `host_addr` on the root
/// side (`host_if`), `inner_addr` inside. Deleted, with its link, on drop.
struct Netns {
    name: String,
    host_if: String,
    host_addr: String,
    inner_addr: String,
}

impl Netns {
    fn create(name: &str, subnet: &str) -> Self {
        let host_if = format!("{name}h");
        let inner_if = format!("{name}n");
        let ns = Self {
            name: name.to_string(),
            host_if: host_if.clone(),
            host_addr: format!("{subnet}.1"),
            inner_addr: format!("{subnet}.2"),
        };
        ip(&["netns", "add", name]);
        ip(&[
            "link", "add", &host_if, "type", "veth", "peer", "name", &inner_if,
        ]);
        ip(&["link", "set", &inner_if, "netns", name]);
        ip(&[
            "addr",
            "add",
            &format!("{}/24", ns.host_addr),
            "dev",
            &host_if,
        ]);
        ip(&["link", "set", &host_if, "up"]);
        let inside = |args: &[&str]| {
            let mut all = vec!["netns", "exec", name, "ip"];
            all.extend_from_slice(args);
            ip(&all);
        };
        inside(&[
            "addr",
            "add",
            &format!("{}/24", ns.inner_addr),
            "dev",
            &inner_if,
        ]);
        inside(&["link", "set", &inner_if, "up"]);
        inside(&["link", "set", "lo", "up"]);
        ns
    }

    /// `program args` run inside the namespace.
    fn command(&self, program: &Path) -> Command {
        let mut cmd = Command::new("ip");
        cmd.args(["netns", "exec", &self.name]).arg(program);
        cmd
    }

    /// Cuts (or restores) the namespace's only link.
    fn set_link(&self, up: bool) {
        ip(&["link", "set", &self.host_if, if up { "up" } else { "down" }]);
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        // Best effort: deleting the namespace also deletes the veth pair.
        let _ = Command::new("ip")
            .args(["netns", "del", &self.name])
            .status();
        let _ = Command::new("ip")
            .args(["link", "del", &self.host_if])
            .status();
    }
}

/// A folder of `sim` and `robot-agent` that run the real binaries inside `ns` as Zenoh
/// clients of the router, so the demo's launcher starts the robots on the robots' network.
fn wrapped_bins(dir: &Path, bins: &Path, ns: &Netns) -> PathBuf {
    let wrapped = dir.join("robot-bins");
    std::fs::create_dir_all(&wrapped).unwrap();
    for name in ["sim", "robot-agent"] {
        let path = wrapped.join(name);
        std::fs::write(
            &path,
            format!(
                "#!/bin/sh\nexec ip netns exec {} {} \"$@\" --zenoh-mode client\n",
                ns.name,
                bins.join(name).display()
            ),
        )
        .unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    }
    wrapped
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
}

#[test]
fn robots_and_service_on_two_networks_meet_through_a_router_and_ride_out_a_cut_link() {
    if !is_root() {
        eprintln!("skipped: network namespaces need root (CI runs as root)");
        return;
    }
    let bins = bin_dir().unwrap();
    let dir = tempfile::tempdir().unwrap();
    // Names and subnets unique to this run (interface names stay under 16 characters).
    let tag = std::process::id() % 200 + 20;
    let robots_ns = Netns::create(&format!("fr{tag}"), &format!("10.231.{tag}"));
    let server_ns = Netns::create(&format!("fs{tag}"), &format!("10.232.{tag}"));

    // The router, in the root namespace: the only place both networks reach.
    let port = free_port().unwrap();
    let robots_side = format!("tcp/{}:{port}", robots_ns.host_addr);
    let server_side = format!("tcp/{}:{port}", server_ns.host_addr);
    let mut router_cmd = Command::new(bins.join("planner-service"));
    router_cmd
        .arg("router")
        .args([
            "--zenoh-listen",
            &robots_side,
            "--zenoh-listen",
            &server_side,
        ])
        .env("RUST_LOG", "info");
    let mut router = Process::spawn("router", router_cmd).unwrap();
    router
        .wait_line(Duration::from_secs(30), |l| {
            l.starts_with("zenoh router:").then_some(())
        })
        .unwrap();

    // The service on the server network: HTTP on its own address (the test reaches it over
    // the server's link), Zenoh only through the router.
    let mut serve = server_ns.command(&bins.join("planner-service"));
    serve
        .arg("serve")
        .args(["--listen", &format!("{}:0", server_ns.inner_addr)])
        .arg("--data-dir")
        .arg(dir.path().join("data"))
        .args(["--token", TOKEN, "--zenoh-connect", &server_side])
        .args(["--zenoh-mode", "client"])
        .env("RUST_LOG", "info");
    let mut proc = Process::spawn("service", serve).unwrap();
    let url = proc
        .wait_line(Duration::from_secs(60), |l| {
            l.strip_prefix("listening on ")
                .map(|u| u.trim().to_string())
        })
        .unwrap();
    let service = Service {
        proc,
        url,
        token: TOKEN.into(),
        zenoh: server_side.clone(),
    };
    service
        .upload_ros_map(
            "junctions",
            &repo_root().join("sim/scenarios/maps/junctions.yaml"),
        )
        .unwrap();
    // A replanning worker beside the service, also a client of the router.
    let worker = start_worker(
        server_ns.command(&bins.join("planner-service")),
        "w1",
        &server_side,
        &["--zenoh-mode", "client"],
    )
    .unwrap();
    service
        .wait_for("/api/v1/workers", Duration::from_secs(20), |_| {
            alive_workers(&service)
                .ok()?
                .contains(&"w1".to_string())
                .then_some(())
        })
        .unwrap();

    // The robots on theirs, connected to the router's robots side only.
    let spec = RobotsSpec::new(
        &wrapped_bins(dir.path(), &bins, &robots_ns),
        &repo_root().join("sim/scenarios/task_a.yaml"),
        1,
        MapName::new("junctions").unwrap(),
        vec![robots_side],
    );
    let robots = Robots::start(&spec).unwrap();

    let id = task_once_online(&service, "robot_1", "junctions", (9.0, 4.0)).unwrap();
    let task_path = format!("/api/v1/tasks/{id}");
    let wait_state = |kind: &str, secs: u64| -> Value {
        service
            .wait_for(&task_path, Duration::from_secs(secs), |t| {
                (state_kind(t) == kind).then(|| t.clone())
            })
            .unwrap()
    };
    wait_state("active", 30);
    service
        .wait_for("/api/v1/robots/robot_1", Duration::from_secs(30), |r| {
            (r["status"]["state"] == "driving").then_some(())
        })
        .unwrap();
    assert_eq!(
        planned_by(&service, "robot_1").unwrap().as_deref(),
        Some("w1"),
        "the worker does not plan the robot: {}",
        service.get("/api/v1/workers").unwrap()
    );

    // The robots' network goes away: the task pauses, saying why.
    robots_ns.set_link(false);
    let paused = wait_state("paused", 30);
    let reason = paused["state"]["reason"].as_str().unwrap();
    assert!(
        reason.contains("robot_1") || reason.contains("liveliness"),
        "{reason}"
    );
    std::thread::sleep(Duration::from_secs(2));
    assert_eq!(
        state_kind(&service.get(&task_path).unwrap()),
        "paused",
        "the task resumed while the link was down"
    );

    // Back: the sessions reconnect through the router, the task resumes and completes.
    robots_ns.set_link(true);
    wait_state("active", 60);
    let done = wait_state("completed", 180);
    assert!(
        resumed_after_a_pause_and_completed(&done),
        "{:?}",
        history_kinds(&done)
    );
    let (x, y) = robot_xy(&service, "robot_1").unwrap().unwrap();
    assert!(
        (x - 9.0).hypot(y - 4.0) < 0.6,
        "robot_1 ended at ({x}, {y})"
    );
    robots.stop(Duration::from_secs(5));
    drop(worker);
    drop(service);
    router.kill();
}
