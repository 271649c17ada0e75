//! The HTTP API against a real server: `Server` on 127.0.0.1:0 with a real map store (redb in
//! a temp dir), a real Zenoh session on loopback and the shared Nav2 maps as upload data.

// Helpers outside `#[test]` functions panic on purpose: a failed step fails the test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::time::Duration;

use planner_service::config::ServiceConfig;
use planner_service::http::{ServeOptions, Server};
use reqwest::multipart::{Form, Part};
use reqwest::StatusCode;
use serde_json::{json, Value};

const TOKEN: &str = "test-token-0123456789";

fn nav2(file: &str) -> PathBuf {
    test_support::nav2_maps_dir().join(file)
}

fn read(file: &str) -> Vec<u8> {
    std::fs::read(nav2(file)).unwrap()
}

fn config() -> ServiceConfig {
    let mut c = ServiceConfig::default();
    c.http.listen = "127.0.0.1:0".parse().unwrap();
    c.http.token = Some(TOKEN.to_string());
    c.zenoh.listen = vec!["tcp/127.0.0.1:0".to_string()];
    c
}

async fn start(data_dir: &Path, config: ServiceConfig) -> Server {
    Server::start(ServeOptions {
        config,
        data_dir: data_dir.to_path_buf(),
    })
    .await
    .unwrap()
}

fn client() -> reqwest::Client {
    reqwest::Client::builder()
        .timeout(Duration::from_secs(60))
        .build()
        .unwrap()
}

fn ros_form(name: &str, yaml: &str) -> Form {
    let text = std::fs::read_to_string(nav2(yaml)).unwrap();
    let image = text
        .lines()
        .find_map(|l| l.strip_prefix("image:"))
        .unwrap()
        .trim()
        .trim_matches('"')
        .to_string();
    Form::new()
        .text("name", name.to_string())
        .part(
            "yaml",
            Part::bytes(text.into_bytes()).file_name(yaml.to_string()),
        )
        .part("image", Part::bytes(read(&image)).file_name(image))
}

fn picture_form(name: &str, file: &str, resolution_m: &str) -> Form {
    Form::new()
        .text("name", name.to_string())
        .part(
            "picture",
            Part::bytes(read(file)).file_name(file.to_string()),
        )
        .text("resolution_m", resolution_m.to_string())
}

async fn json(resp: reqwest::Response) -> Value {
    resp.json::<Value>().await.unwrap()
}

/// Asserts the error body of docs/api.md and returns its reason.
async fn expect_error(resp: reqwest::Response, status: StatusCode, code: &str) -> String {
    assert_eq!(resp.status(), status);
    let body = json(resp).await;
    assert_eq!(body["error"], code, "{body}");
    let reason = body["reason"].as_str().unwrap().to_string();
    assert!(!reason.is_empty());
    reason
}

async fn map_count(c: &reqwest::Client, url: &str) -> usize {
    let list = json(c.get(format!("{url}/api/v1/maps")).send().await.unwrap()).await;
    list.as_array().unwrap().len()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn maps_upload_list_meta_versions_image() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path(), config()).await;
    let url = server.url();
    let c = client();
    let post = |form: Form| {
        c.post(format!("{url}/api/v1/maps"))
            .bearer_auth(TOKEN)
            .multipart(form)
            .send()
    };

    let resp = post(ros_form("depot", "depot.yaml")).await.unwrap();
    assert_eq!(resp.status(), StatusCode::CREATED);
    let depot = json(resp).await;
    assert_eq!(depot["name"], "depot");
    assert_eq!(depot["version"], 1);
    assert_eq!(depot["resolution_m"], 0.05);
    let (w, h) = (
        depot["width_cells"].as_u64().unwrap(),
        depot["height_cells"].as_u64().unwrap(),
    );
    assert_eq!((w, h), (604, 307));

    // Identical content: the existing version, 200.
    let resp = post(ros_form("depot", "depot.yaml")).await.unwrap();
    assert_eq!(resp.status(), StatusCode::OK);
    assert_eq!(json(resp).await["id"], depot["id"]);

    // The same name with other content is version 2 (origin and image differ).
    let resp = post(ros_form("depot", "testmap.yaml")).await.unwrap();
    assert_eq!(resp.status(), StatusCode::CREATED);
    let depot2 = json(resp).await;
    assert_eq!(depot2["version"], 2);
    assert_eq!(depot2["origin"]["x_m"], 2.0);

    // A picture with its scale and an origin.
    let form = picture_form("plan", "testmap.png", "0.25").text("origin_x_m", "-1.5");
    let resp = post(form).await.unwrap();
    assert_eq!(resp.status(), StatusCode::CREATED);
    let plan = json(resp).await;
    assert_eq!(plan["resolution_m"], 0.25);
    assert_eq!(plan["origin"]["x_m"], -1.5);
    assert_eq!(plan["origin"]["y_m"], 0.0);
    assert_eq!(
        (plan["width_cells"].as_u64(), plan["height_cells"].as_u64()),
        (Some(10), Some(10))
    );

    let list = json(c.get(format!("{url}/api/v1/maps")).send().await.unwrap()).await;
    let names: Vec<(&str, u64)> = list
        .as_array()
        .unwrap()
        .iter()
        .map(|m| (m["name"].as_str().unwrap(), m["version"].as_u64().unwrap()))
        .collect();
    assert_eq!(names, [("depot", 2), ("plan", 1)]);

    let meta = json(
        c.get(format!("{url}/api/v1/maps/depot"))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(meta, depot2);
    let versions = json(
        c.get(format!("{url}/api/v1/maps/depot/versions"))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(versions, serde_json::json!([depot, depot2]));

    // The image of version 1: PNG with the grid's size, top row = largest y.
    let resp = c
        .get(format!("{url}/api/v1/maps/depot/image?version=1"))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::OK);
    assert_eq!(resp.headers()["content-type"], "image/png");
    assert_eq!(resp.headers()["x-map-width"], "604");
    assert_eq!(resp.headers()["x-map-height"], "307");
    assert_eq!(resp.headers()["x-map-resolution-m"], "0.05");
    let png = image::load_from_memory(&resp.bytes().await.unwrap())
        .unwrap()
        .to_luma8();
    assert_eq!(png.dimensions(), (604, 307));
    // The uploaded PGM is drawn top row first as well; trinary cells keep its three shades apart.
    let source = image::load_from_memory(&read("depot.pgm"))
        .unwrap()
        .to_luma8();
    let mut agree = 0_u32;
    for (p, q) in png.pixels().zip(source.pixels()) {
        let class = |v: u8| match v {
            0..=89 => 0,
            192..=255 => 2,
            _ => 1,
        };
        agree += u32::from(class(p.0[0]) == class(q.0[0]));
    }
    assert_eq!(agree, 604 * 307);

    // Unknown maps and versions: 404; an invalid name: 400.
    for path in [
        "nowhere",
        "nowhere/versions",
        "nowhere/image",
        "depot/image?version=9",
    ] {
        let resp = c
            .get(format!("{url}/api/v1/maps/{path}"))
            .send()
            .await
            .unwrap();
        expect_error(resp, StatusCode::NOT_FOUND, "not_found").await;
    }
    let resp = c
        .get(format!("{url}/api/v1/maps/.hidden"))
        .send()
        .await
        .unwrap();
    expect_error(resp, StatusCode::BAD_REQUEST, "bad_request").await;
    let resp = c
        .get(format!("{url}/api/v1/maps/depot/image?version=x"))
        .send()
        .await
        .unwrap();
    expect_error(resp, StatusCode::BAD_REQUEST, "bad_request").await;
    server.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn preview_renders_and_stores_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path(), config()).await;
    let url = server.url();
    let c = client();
    let resp = c
        .post(format!("{url}/api/v1/maps/preview"))
        .bearer_auth(TOKEN)
        .multipart(ros_form("depot", "depot.yaml"))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::OK);
    assert_eq!(resp.headers()["content-type"], "image/png");
    assert_eq!(resp.headers()["x-map-width"], "604");
    let png = image::load_from_memory(&resp.bytes().await.unwrap()).unwrap();
    assert_eq!((png.width(), png.height()), (604, 307));
    // `name` is optional for a preview.
    let form = Form::new()
        .part(
            "picture",
            Part::bytes(read("testmap.png")).file_name("p.png"),
        )
        .text("resolution_m", "0.1");
    let resp = c
        .post(format!("{url}/api/v1/maps/preview"))
        .bearer_auth(TOKEN)
        .multipart(form)
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::OK);
    assert_eq!(resp.headers()["x-map-height"], "10");
    assert_eq!(map_count(&c, &url).await, 0);
    // Nothing staged is left behind.
    let staged = std::fs::read_dir(dir.path().join("uploads"))
        .map(|d| d.count())
        .unwrap_or(0);
    assert_eq!(staged, 0);
    server.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_uploads_are_refused_and_store_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config();
    cfg.http.max_upload_bytes = 300_000;
    cfg.http.import_limits.max_pixels = 150_000;
    let server = start(dir.path(), cfg).await;
    let url = server.url();
    let c = client();
    let send = |path: &'static str, form: Form| {
        c.post(format!("{url}{path}"))
            .bearer_auth(TOKEN)
            .multipart(form)
            .send()
    };

    // Body over max_upload_bytes (the warehouse PGM is 1.7 MB): 413.
    let resp = send("/api/v1/maps", ros_form("big", "warehouse.yaml"))
        .await
        .unwrap();
    expect_error(resp, StatusCode::PAYLOAD_TOO_LARGE, "too_large").await;
    // Within the body limit but over the import limits' pixel count (604 × 307): 413.
    let resp = send("/api/v1/maps", ros_form("depot", "depot.yaml"))
        .await
        .unwrap();
    let reason = expect_error(resp, StatusCode::PAYLOAD_TOO_LARGE, "too_large").await;
    assert!(reason.contains("pixels"), "{reason}");

    let yaml = std::fs::read_to_string(nav2("testmap.yaml")).unwrap();
    let png = read("testmap.png");
    let ros = |yaml: String| {
        Form::new()
            .text("name", "t")
            .part("yaml", Part::bytes(yaml.into_bytes()).file_name("t.yaml"))
            .part("image", Part::bytes(png.clone()).file_name("testmap.png"))
    };
    let cases: Vec<(&str, Form, &str)> = vec![
        (
            "missing name",
            Form::new()
                .part("picture", Part::bytes(png.clone()).file_name("p.png"))
                .text("resolution_m", "0.1"),
            "name",
        ),
        ("bad name", picture_form("a b", "testmap.png", "0.1"), "a b"),
        (
            "no resolution",
            Form::new()
                .text("name", "p")
                .part("picture", Part::bytes(png.clone()).file_name("p.png")),
            "resolution_m",
        ),
        (
            "bad resolution",
            picture_form("p", "testmap.png", "-2"),
            "resolution_m",
        ),
        (
            "nan resolution",
            picture_form("p", "testmap.png", "NaN"),
            "resolution_m",
        ),
        (
            "bad origin",
            picture_form("p", "testmap.png", "0.1").text("origin_y_m", "north"),
            "origin_y_m",
        ),
        (
            "ROS map with a picture's origin",
            ros(yaml.clone()).text("origin_x_m", "1.0"),
            "origin_x_m",
        ),
        (
            "unknown part",
            picture_form("p", "testmap.png", "0.1").text("colour", "red"),
            "colour",
        ),
        (
            "twice",
            picture_form("p", "testmap.png", "0.1").text("name", "q"),
            "twice",
        ),
        (
            "yaml alone",
            Form::new().text("name", "t").part(
                "yaml",
                Part::bytes(yaml.clone().into_bytes()).file_name("t.yaml"),
            ),
            "image",
        ),
        ("nothing", Form::new().text("name", "t"), "picture"),
        (
            "not an image",
            Form::new()
                .text("name", "p")
                .part("picture", Part::bytes(b"hello".to_vec()).file_name("p.png"))
                .text("resolution_m", "0.1"),
            "image",
        ),
        ("bad yaml", ros("image: [unclosed".to_string()), "yaml"),
        (
            "bad threshold",
            ros(yaml.replace("occupied_thresh: 0.65", "occupied_thresh: 1.65")),
            "occupied_thresh",
        ),
        (
            "no resolution in yaml",
            ros(yaml.replace("resolution: 0.1", "")),
            "resolution",
        ),
        (
            "bad origin in yaml",
            ros(yaml.replace("origin: [2.0, 3.0, 1.0]", "origin: [2.0, 3.0]")),
            "origin",
        ),
        (
            "resolution beside a yaml",
            ros(yaml.clone()).text("resolution_m", "1"),
            "resolution_m",
        ),
    ];
    for (what, form, needle) in cases {
        let resp = send("/api/v1/maps", form).await.unwrap();
        let reason = expect_error(resp, StatusCode::BAD_REQUEST, "bad_request").await;
        assert!(reason.contains(needle), "{what}: {reason}");
    }
    // A body that is not multipart at all.
    let resp = c
        .post(format!("{url}/api/v1/maps"))
        .bearer_auth(TOKEN)
        .json(&serde_json::json!({"name": "x"}))
        .send()
        .await
        .unwrap();
    expect_error(resp, StatusCode::BAD_REQUEST, "bad_request").await;
    assert_eq!(map_count(&c, &url).await, 0);

    // The YAML's image entry is replaced by the uploaded image, whatever it names: an upload
    // cannot make the service read a file of the host.
    let resp = send(
        "/api/v1/maps",
        ros(yaml.replace("\"testmap.png\"", "/etc/passwd")),
    )
    .await
    .unwrap();
    assert_eq!(resp.status(), StatusCode::CREATED);
    assert_eq!(json(resp).await["width_cells"], 10);
    server.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mutating_routes_need_the_token_and_reads_are_open() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path(), config()).await;
    let url = server.url();
    let c = client();
    for auth in [None, Some("wrong-token-0123456789"), Some("")] {
        for path in ["/api/v1/maps", "/api/v1/maps/preview"] {
            let mut req =
                c.post(format!("{url}{path}"))
                    .multipart(picture_form("p", "testmap.png", "0.1"));
            if let Some(t) = auth {
                req = req.bearer_auth(t);
            }
            let resp = req.send().await.unwrap();
            expect_error(resp, StatusCode::UNAUTHORIZED, "unauthorized").await;
        }
    }
    let resp = c
        .post(format!("{url}/api/v1/maps"))
        .header("authorization", format!("Basic {TOKEN}"))
        .multipart(picture_form("p", "testmap.png", "0.1"))
        .send()
        .await
        .unwrap();
    expect_error(resp, StatusCode::UNAUTHORIZED, "unauthorized").await;
    // A token in the query string never authorizes a change.
    let resp = c
        .post(format!("{url}/api/v1/maps?access_token={TOKEN}"))
        .multipart(picture_form("p", "testmap.png", "0.1"))
        .send()
        .await
        .unwrap();
    expect_error(resp, StatusCode::UNAUTHORIZED, "unauthorized").await;
    assert_eq!(map_count(&c, &url).await, 0);

    for path in [
        "/",
        "/assets/app.js",
        "/assets/style.css",
        "/api/v1/maps",
        "/metrics",
    ] {
        let resp = c.get(format!("{url}{path}")).send().await.unwrap();
        assert_eq!(resp.status(), StatusCode::OK, "{path}");
    }
    let resp = c.get(format!("{url}/")).send().await.unwrap();
    assert!(resp.headers()["content-type"]
        .to_str()
        .unwrap()
        .starts_with("text/html"));
    assert!(resp.text().await.unwrap().contains("<html"));

    // Unknown routes and methods answer in the error format too.
    let resp = c.get(format!("{url}/api/v1/nothing")).send().await.unwrap();
    expect_error(resp, StatusCode::NOT_FOUND, "not_found").await;
    let resp = c
        .delete(format!("{url}/api/v1/maps"))
        .bearer_auth(TOKEN)
        .send()
        .await
        .unwrap();
    expect_error(resp, StatusCode::METHOD_NOT_ALLOWED, "method_not_allowed").await;

    // The counters saw all of it, by route template and status.
    let text = c
        .get(format!("{url}/metrics"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert!(
        text.contains("fleet_http_requests_total{route=\"/api/v1/maps\",status=\"401\"} 5"),
        "{text}"
    );
    assert!(
        text.contains("fleet_http_requests_total{route=\"/api/v1/maps/preview\",status=\"401\"} 3"),
        "{text}"
    );
    server.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn protect_reads_needs_the_token_on_reads() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config();
    cfg.http.protect_reads = true;
    let server = start(dir.path(), cfg).await;
    let url = server.url();
    let c = client();
    for path in ["/api/v1/maps", "/api/v1/maps/x/versions", "/metrics"] {
        let resp = c.get(format!("{url}{path}")).send().await.unwrap();
        expect_error(resp, StatusCode::UNAUTHORIZED, "unauthorized").await;
        let resp = c
            .get(format!("{url}{path}?access_token=wrong-token-0123456789"))
            .send()
            .await
            .unwrap();
        expect_error(resp, StatusCode::UNAUTHORIZED, "unauthorized").await;
    }
    let resp = c
        .get(format!("{url}/api/v1/maps"))
        .bearer_auth(TOKEN)
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::OK);
    let resp = c
        .get(format!("{url}/api/v1/maps?access_token={TOKEN}"))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::OK);
    // The dashboard itself loads without a token (it asks the user for one).
    for path in ["/", "/assets/app.js"] {
        let resp = c.get(format!("{url}{path}")).send().await.unwrap();
        assert_eq!(resp.status(), StatusCode::OK, "{path}");
    }
    server.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn generated_token_is_reused_across_restarts_and_maps_persist() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config();
    cfg.http.token = None;
    let server = start(dir.path(), cfg.clone()).await;
    let token = server.token().to_string();
    assert_eq!(token.len(), 32);
    let stored = std::fs::read_to_string(dir.path().join("token")).unwrap();
    assert_eq!(stored.trim(), token);
    let c = client();
    let resp = c
        .post(format!("{}/api/v1/maps", server.url()))
        .bearer_auth(&token)
        .multipart(ros_form("depot", "depot.yaml"))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::CREATED);
    server.stop().await.unwrap();

    let server = start(dir.path(), cfg).await;
    assert_eq!(server.token(), token);
    let list = json(
        c.get(format!("{}/api/v1/maps", server.url()))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(list[0]["name"], "depot");
    server.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn robots_fetch_uploaded_maps_over_zenoh() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path(), config()).await;
    let c = client();
    let resp = c
        .post(format!("{}/api/v1/maps", server.url()))
        .bearer_auth(TOKEN)
        .multipart(ros_form("depot", "depot.yaml"))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::CREATED);
    let endpoints = server.zenoh_locators().await;
    assert!(!endpoints.is_empty());
    let robot = zenoh::open(protocol::peer_config(&[], &endpoints).unwrap())
        .await
        .unwrap();
    let site = protocol::SiteId::new("default").unwrap();
    let name = protocol::MapName::new("depot").unwrap();
    let grid = map_store::fetch_map(&robot, &site, &name, None, Duration::from_secs(10))
        .await
        .unwrap();
    assert_eq!((grid.meta.width_cells, grid.meta.height_cells), (604, 307));
    assert_eq!(grid.cells.len(), 604 * 307);
    robot.close().await.unwrap();
    server.stop().await.unwrap();
}

/// A point well clear of walls and a point inside a wall of the depot map, from the map itself.
fn depot_points() -> ((f64, f64), (f64, f64)) {
    use map_store::{CellClass, DistanceField, Sources};
    let ros =
        map_store::load_ros_map(&nav2("depot.yaml"), &map_store::ImportLimits::default()).unwrap();
    let grid = ros.grid;
    let field = DistanceField::compute(&grid, Sources::OccupiedOrUnknown);
    let (w, h) = (
        i64::from(grid.width_cells()),
        i64::from(grid.height_cells()),
    );
    let mut best = (0, 0, 0.0_f32);
    let mut wall = None;
    for cy in 0..h {
        for cx in 0..w {
            let d = field.at(cx, cy);
            if d > best.2 {
                best = (cx, cy, d);
            }
            // A wall cell with walls around it, so no rounding puts the goal beside it.
            if wall.is_none()
                && (-1..=1).all(|dy| {
                    (-1..=1).all(|dx| grid.class_at(cx + dx, cy + dy) == CellClass::Occupied)
                })
            {
                wall = Some((cx, cy));
            }
        }
    }
    assert!(best.2 > 1.0, "depot has a free spot 1 m from any wall");
    let (wx, wy) = wall.unwrap();
    (
        grid.cell_to_world(best.0, best.1),
        grid.cell_to_world(wx, wy),
    )
}

async fn upload_depot(c: &reqwest::Client, url: &str) {
    let resp = c
        .post(format!("{url}/api/v1/maps"))
        .bearer_auth(TOKEN)
        .multipart(ros_form("depot", "depot.yaml"))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::CREATED);
}

async fn task_count(c: &reqwest::Client, url: &str) -> usize {
    let list = json(c.get(format!("{url}/api/v1/tasks")).send().await.unwrap()).await;
    list.as_array().unwrap().len()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tasks_are_created_validated_listed_and_cancelled() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path(), config()).await;
    let url = server.url();
    let c = client();
    upload_depot(&c, &url).await;
    let ((fx, fy), (wx, wy)) = depot_points();
    let post = |body: Value| {
        c.post(format!("{url}/api/v1/tasks"))
            .bearer_auth(TOKEN)
            .json(&body)
            .send()
    };

    // Bad requests: each refused with its status, none stored.
    let bad: Vec<(Value, StatusCode, &str)> = vec![
        (
            serde_json::json!({"map": "depot", "goals": []}),
            StatusCode::BAD_REQUEST,
            "goals",
        ),
        (
            serde_json::json!({"map": "depot", "goals": [{"x_m": -50.0, "y_m": fy}]}),
            StatusCode::BAD_REQUEST,
            "goals[0]",
        ),
        (
            serde_json::json!({"map": "depot", "goals": [{"x_m": fx, "y_m": fy}, {"x_m": wx, "y_m": wy}]}),
            StatusCode::BAD_REQUEST,
            "goals[1]",
        ),
        (
            serde_json::json!({"map": "depot", "goals": [{"x_m": fx}]}),
            StatusCode::BAD_REQUEST,
            "y_m",
        ),
        (
            serde_json::json!({"map": "depot", "goals": [{"x_m": fx, "y_m": fy}], "priority": 1}),
            StatusCode::BAD_REQUEST,
            "priority",
        ),
        (
            serde_json::json!({"map": "a/b", "goals": [{"x_m": fx, "y_m": fy}]}),
            StatusCode::BAD_REQUEST,
            "a/b",
        ),
        (
            serde_json::json!({"map": "nowhere", "goals": [{"x_m": fx, "y_m": fy}]}),
            StatusCode::NOT_FOUND,
            "nowhere",
        ),
        (
            serde_json::json!({"map": "depot", "robot_id": "ghost", "goals": [{"x_m": fx, "y_m": fy}]}),
            StatusCode::NOT_FOUND,
            "ghost",
        ),
    ];
    for (body, status, needle) in bad {
        let resp = post(body.clone()).await.unwrap();
        assert_eq!(resp.status(), status, "{body}");
        let err = json(resp).await;
        let reason = err["reason"].as_str().unwrap();
        assert!(reason.contains(needle), "{body}: {reason}");
    }
    for raw in ["{\"map\": \"depot\", \"goals\": [", "not json", ""] {
        let resp = c
            .post(format!("{url}/api/v1/tasks"))
            .bearer_auth(TOKEN)
            .header("content-type", "application/json")
            .body(raw)
            .send()
            .await
            .unwrap();
        expect_error(resp, StatusCode::BAD_REQUEST, "bad_request").await;
    }
    let resp = c
        .post(format!("{url}/api/v1/tasks"))
        .bearer_auth(TOKEN)
        .body(r#"{"map":"depot","goals":[]}"#)
        .send()
        .await
        .unwrap();
    let reason = expect_error(resp, StatusCode::BAD_REQUEST, "bad_request").await;
    assert!(reason.to_lowercase().contains("content-type"), "{reason}");
    // A body over max_json_bytes.
    let huge = format!(
        r#"{{"map":"depot","goals":[{}]}}"#,
        vec![r#"{"x_m":1,"y_m":1}"#; 70_000].join(",")
    );
    let resp = c
        .post(format!("{url}/api/v1/tasks"))
        .bearer_auth(TOKEN)
        .header("content-type", "application/json")
        .body(huge)
        .send()
        .await
        .unwrap();
    expect_error(resp, StatusCode::PAYLOAD_TOO_LARGE, "too_large").await;
    // Without a token.
    let resp = c
        .post(format!("{url}/api/v1/tasks"))
        .json(&serde_json::json!({"map": "depot", "goals": [{"x_m": fx, "y_m": fy}]}))
        .send()
        .await
        .unwrap();
    expect_error(resp, StatusCode::UNAUTHORIZED, "unauthorized").await;
    assert_eq!(task_count(&c, &url).await, 0);

    // A good task: queued (no robot is online), goals echoed, yaw null when not given.
    let resp = post(serde_json::json!({"map": "depot", "goals": [{"x_m": fx, "y_m": fy, "yaw_rad": 1.5}, {"x_m": fx, "y_m": fy}]}))
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::CREATED);
    let task = json(resp).await;
    assert_eq!(task["state"]["kind"], "queued");
    assert_eq!(task["map"], "depot");
    assert_eq!(task["map_version"], 1);
    assert_eq!(task["goals"][0]["yaw_rad"], 1.5);
    assert_eq!(task["goals"][1]["yaw_rad"], Value::Null);
    let id = task["id"].as_str().unwrap().to_string();

    let got = json(
        c.get(format!("{url}/api/v1/tasks/{id}"))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(got, task);
    let list = json(
        c.get(format!("{url}/api/v1/tasks?state=queued&map=depot&limit=5"))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(list.as_array().unwrap().len(), 1);
    // One task: a page of one is the last page (no Next-Cursor).
    let resp = c
        .get(format!("{url}/api/v1/tasks?limit=1"))
        .send()
        .await
        .unwrap();
    assert!(resp.headers().get("next-cursor").is_none());
    let list = json(
        c.get(format!("{url}/api/v1/tasks?state=active"))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(list.as_array().unwrap().len(), 0);
    let long_cursor = format!("cursor={}", "ab".repeat(500));
    for (q, needle) in [
        ("state=running", "running"),
        ("limit=0", "limit"),
        ("limit=5000", "limit"),
        ("robot_id=a%2Fb", "a/b"),
        ("colour=red", "colour"),
        ("cursor=zz", "cursor"),
        ("cursor=00ff", "cursor"),
        ("cursor=0000000000000001742f", "cursor"),
        (long_cursor.as_str(), "cursor"),
    ] {
        let resp = c
            .get(format!("{url}/api/v1/tasks?{q}"))
            .send()
            .await
            .unwrap();
        let reason = expect_error(resp, StatusCode::BAD_REQUEST, "bad_request").await;
        assert!(reason.contains(needle), "{q}: {reason}");
    }
    let resp = c
        .get(format!("{url}/api/v1/tasks/t-nothing"))
        .send()
        .await
        .unwrap();
    expect_error(resp, StatusCode::NOT_FOUND, "not_found").await;

    // Cancel: without a token 401, then 200, then 409 and the task stays cancelled.
    let cancel = |auth: bool| {
        let mut req = c.post(format!("{url}/api/v1/tasks/{id}/cancel"));
        if auth {
            req = req.bearer_auth(TOKEN);
        }
        req.send()
    };
    expect_error(
        cancel(false).await.unwrap(),
        StatusCode::UNAUTHORIZED,
        "unauthorized",
    )
    .await;
    let resp = cancel(true).await.unwrap();
    assert_eq!(resp.status(), StatusCode::OK);
    let cancelled = json(resp).await;
    assert_eq!(cancelled["state"]["kind"], "cancelled");
    let reason = expect_error(
        cancel(true).await.unwrap(),
        StatusCode::CONFLICT,
        "conflict",
    )
    .await;
    assert!(reason.contains(&id), "{reason}");
    let got = json(
        c.get(format!("{url}/api/v1/tasks/{id}"))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(got, cancelled);
    let resp = c
        .post(format!("{url}/api/v1/tasks/t-nothing/cancel"))
        .bearer_auth(TOKEN)
        .send()
        .await
        .unwrap();
    expect_error(resp, StatusCode::NOT_FOUND, "not_found").await;
    assert_eq!(task_count(&c, &url).await, 1);

    // Robots: none known yet.
    let robots = json(c.get(format!("{url}/api/v1/robots")).send().await.unwrap()).await;
    assert_eq!(robots, serde_json::json!([]));
    for path in ["robot_1", "robot_1/lpe.png", "robot_1/camera.jpg"] {
        let resp = c
            .get(format!("{url}/api/v1/robots/{path}"))
            .send()
            .await
            .unwrap();
        expect_error(resp, StatusCode::NOT_FOUND, "not_found").await;
    }

    let health = json(c.get(format!("{url}/healthz")).send().await.unwrap()).await;
    assert_eq!(health["status"], "ok");
    assert_eq!(health["robots_online"], 0);
    assert_eq!(health["tasks_active"], 0);
    let metrics = c
        .get(format!("{url}/metrics"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    for needle in [
        "fleet_replan_latency_seconds_bucket",
        "fleet_tasks{state=\"cancelled\"} 1",
        "fleet_robots{state=\"online\"} 0",
        "fleet_http_requests_total{route=\"/api/v1/tasks/{id}/cancel\",status=\"409\"} 1",
        "fleet_http_requests_total{route=\"/api/v1/tasks\",status=\"201\"} 1",
    ] {
        assert!(metrics.contains(needle), "{needle} missing in\n{metrics}");
    }
    server.stop().await.unwrap();
}

/// Reads server-sent events until one named `name` whose data satisfies `pred`.
async fn next_event(
    stream: &mut (impl futures::Stream<Item = reqwest::Result<axum::body::Bytes>> + Unpin),
    buf: &mut String,
    name: &str,
    pred: impl Fn(&Value) -> bool,
) -> Value {
    use futures::StreamExt;
    let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
    loop {
        while let Some(end) = buf.find("\n\n") {
            let block: String = buf.drain(..end + 2).collect();
            let mut event = None;
            let mut data = String::new();
            for line in block.lines() {
                if let Some(e) = line.strip_prefix("event: ") {
                    event = Some(e.to_string());
                } else if let Some(d) = line.strip_prefix("data: ") {
                    data.push_str(d);
                }
            }
            if event.as_deref() == Some(name) {
                let v: Value = serde_json::from_str(&data).unwrap();
                if pred(&v) {
                    return v;
                }
            }
        }
        let chunk = tokio::time::timeout_at(deadline, stream.next())
            .await
            .unwrap_or_else(|_| panic!("no `{name}` event within 20 s"))
            .unwrap()
            .unwrap();
        buf.push_str(std::str::from_utf8(&chunk).unwrap());
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn event_stream_sends_a_snapshot_then_task_events() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path(), config()).await;
    let url = server.url();
    let c = client();
    upload_depot(&c, &url).await;
    let ((fx, fy), _) = depot_points();
    let resp = c.get(format!("{url}/api/v1/events")).send().await.unwrap();
    assert_eq!(resp.status(), StatusCode::OK);
    assert_eq!(resp.headers()["content-type"], "text/event-stream");
    let mut stream = resp.bytes_stream();
    let mut buf = String::new();
    let snap = next_event(&mut stream, &mut buf, "snapshot", |_| true).await;
    assert_eq!(snap, serde_json::json!({"robots": [], "tasks": []}));

    let task = json(
        c.post(format!("{url}/api/v1/tasks"))
            .bearer_auth(TOKEN)
            .json(&serde_json::json!({"map": "depot", "goals": [{"x_m": fx, "y_m": fy}]}))
            .send()
            .await
            .unwrap(),
    )
    .await;
    let id = task["id"].clone();
    let ev = next_event(&mut stream, &mut buf, "task", |t| t["id"] == id).await;
    assert_eq!(ev["state"]["kind"], "queued");
    c.post(format!(
        "{url}/api/v1/tasks/{}/cancel",
        id.as_str().unwrap()
    ))
    .bearer_auth(TOKEN)
    .send()
    .await
    .unwrap();
    next_event(&mut stream, &mut buf, "task", |t| {
        t["id"] == id && t["state"]["kind"] == "cancelled"
    })
    .await;

    // A new subscriber's snapshot holds the live tasks only (not the cancelled one, however
    // recent); stopping the server ends open streams.
    let live = json(
        c.post(format!("{url}/api/v1/tasks"))
            .bearer_auth(TOKEN)
            .json(&serde_json::json!({"map": "depot", "goals": [{"x_m": fx, "y_m": fy}]}))
            .send()
            .await
            .unwrap(),
    )
    .await;
    let resp = c.get(format!("{url}/api/v1/events")).send().await.unwrap();
    let mut stream2 = resp.bytes_stream();
    let mut buf2 = String::new();
    let snap = next_event(&mut stream2, &mut buf2, "snapshot", |_| true).await;
    let ids: Vec<_> = snap["tasks"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["id"].clone())
        .collect();
    assert_eq!(ids, vec![live["id"].clone()]);
    tokio::time::timeout(Duration::from_secs(10), server.stop())
        .await
        .unwrap()
        .unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn task_pages_follow_the_next_cursor_to_the_end() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path(), config()).await;
    let url = server.url();
    let c = client();
    upload_depot(&c, &url).await;
    let ((fx, fy), _) = depot_points();
    let mut created = Vec::new();
    for _ in 0..5 {
        let task = json(
            c.post(format!("{url}/api/v1/tasks"))
                .bearer_auth(TOKEN)
                .json(&serde_json::json!({"map": "depot", "goals": [{"x_m": fx, "y_m": fy}]}))
                .send()
                .await
                .unwrap(),
        )
        .await;
        created.push(task["id"].clone());
    }
    created.reverse();
    let mut paged = Vec::new();
    let mut query = "limit=2&map=depot".to_string();
    let mut pages = 0;
    loop {
        let resp = c
            .get(format!("{url}/api/v1/tasks?{query}"))
            .send()
            .await
            .unwrap();
        let next = resp
            .headers()
            .get("next-cursor")
            .map(|v| v.to_str().unwrap().to_string());
        let page = json(resp).await;
        pages += 1;
        paged.extend(page.as_array().unwrap().iter().map(|t| t["id"].clone()));
        match next {
            Some(cursor) => query = format!("limit=2&map=depot&cursor={cursor}"),
            None => break,
        }
    }
    assert_eq!(pages, 3);
    assert_eq!(paged, created);
    tokio::time::timeout(Duration::from_secs(10), server.stop())
        .await
        .unwrap()
        .unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tasks_persist_across_a_restart() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path(), config()).await;
    let c = client();
    upload_depot(&c, &server.url()).await;
    let ((fx, fy), _) = depot_points();
    let mut ids = Vec::new();
    for _ in 0..2 {
        let task = json(
            c.post(format!("{}/api/v1/tasks", server.url()))
                .bearer_auth(TOKEN)
                .json(&serde_json::json!({"map": "depot", "goals": [{"x_m": fx, "y_m": fy}]}))
                .send()
                .await
                .unwrap(),
        )
        .await;
        ids.push(task["id"].as_str().unwrap().to_string());
    }
    let resp = c
        .post(format!("{}/api/v1/tasks/{}/cancel", server.url(), ids[0]))
        .bearer_auth(TOKEN)
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::OK);
    let before = json(
        c.get(format!("{}/api/v1/tasks", server.url()))
            .send()
            .await
            .unwrap(),
    )
    .await;
    server.stop().await.unwrap();

    let server = start(dir.path(), config()).await;
    let after = json(
        c.get(format!("{}/api/v1/tasks", server.url()))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(after, before);
    let t0 = json(
        c.get(format!("{}/api/v1/tasks/{}", server.url(), ids[0]))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(t0["state"]["kind"], "cancelled");
    let t1 = json(
        c.get(format!("{}/api/v1/tasks/{}", server.url(), ids[1]))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(t1["state"]["kind"], "queued");
    server.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn openapi_document_covers_exactly_the_router() {
    use std::collections::BTreeSet;
    let doc = planner_service::http::openapi::document();
    assert_eq!(doc["openapi"], "3.1.0");
    let served: BTreeSet<(String, String)> = planner_service::http::routes()
        .into_iter()
        .map(|r| (r.path.to_string(), r.method.to_string()))
        .collect();
    let mut documented = BTreeSet::new();
    for (path, item) in doc["paths"].as_object().unwrap() {
        for (method, op) in item.as_object().unwrap() {
            assert!(op["responses"].is_object(), "{method} {path} has responses");
            documented.insert((path.clone(), method.clone()));
        }
    }
    let missing: Vec<_> = served.difference(&documented).collect();
    let extra: Vec<_> = documented.difference(&served).collect();
    assert!(
        missing.is_empty(),
        "routes not in the OpenAPI document: {missing:?}"
    );
    assert!(
        extra.is_empty(),
        "documented routes the router lacks: {extra:?}"
    );
    assert!(served.len() >= 20, "{served:?}");

    // Every $ref points at something the document defines.
    fn refs(v: &Value, out: &mut Vec<String>) {
        match v {
            Value::Object(m) => {
                if let Some(Value::String(r)) = m.get("$ref") {
                    out.push(r.clone());
                }
                m.values().for_each(|x| refs(x, out));
            }
            Value::Array(a) => a.iter().for_each(|x| refs(x, out)),
            _ => {}
        }
    }
    let mut all = Vec::new();
    refs(&doc, &mut all);
    assert!(!all.is_empty());
    for r in all {
        let pointer = r.strip_prefix('#').unwrap();
        assert!(doc.pointer(pointer).is_some(), "dangling {r}");
    }

    // The served document is this one.
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path(), config()).await;
    let served_doc = json(
        client()
            .get(format!("{}/api/v1/openapi.json", server.url()))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(served_doc, doc);
    server.stop().await.unwrap();
}

#[test]
fn serve_command_prints_its_url_and_stops_on_sigterm() {
    use std::io::{BufRead, BufReader};
    use std::process::{Command, Stdio};
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_planner-service"))
        .args([
            "serve",
            "--listen",
            "127.0.0.1:0",
            "--zenoh-listen",
            "tcp/127.0.0.1:0",
        ])
        .env("FLEET_DATA_DIR", dir.path())
        .env_remove("FLEET_TOKEN")
        .env_remove("FLEET_LISTEN")
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let first = lines.next().unwrap().unwrap();
    let url = first.strip_prefix("listening on ").unwrap().to_string();
    assert!(url.starts_with("http://127.0.0.1:"), "{first}");
    let token_line = lines.next().unwrap().unwrap();
    let stored = std::fs::read_to_string(dir.path().join("token")).unwrap();
    assert!(token_line.contains(stored.trim()), "{token_line}");

    let rt = tokio::runtime::Runtime::new().unwrap();
    let health = rt.block_on(async {
        json(client().get(format!("{url}/healthz")).send().await.unwrap()).await
    });
    assert_eq!(health["status"], "ok");

    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let deadline = std::time::Instant::now() + Duration::from_secs(20);
    let exit = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "serve did not stop on SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(exit.success(), "{exit:?}");
    // A bad flag is refused with the field named and a non-zero exit.
    let out = Command::new(env!("CARGO_BIN_EXE_planner-service"))
        .args(["serve", "--listen", "127.0.0.1:0", "--token", "short"])
        .env("FLEET_DATA_DIR", dir.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("http.token"));
}

// ----- hardening (issue 17): input edges -------------------------------------------------

/// Sends raw bytes on a fresh connection, closes the sending side and returns the status line
/// and body of the answer.
async fn raw_exchange(url: &str, request: &[u8]) -> (String, String) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let addr = url.strip_prefix("http://").unwrap();
    let mut s = tokio::net::TcpStream::connect(addr).await.unwrap();
    s.write_all(request).await.unwrap();
    s.shutdown().await.unwrap();
    let mut answer = Vec::new();
    tokio::time::timeout(Duration::from_secs(20), s.read_to_end(&mut answer))
        .await
        .expect("an answer in time")
        .unwrap();
    let text = String::from_utf8_lossy(&answer).to_string();
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    (
        head.lines().next().unwrap_or("").to_string(),
        body.to_string(),
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn truncated_multipart_uploads_get_a_400() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path(), config()).await;
    let url = server.url();
    let png = read("testmap.png");
    let mut body = b"--XB\r\nContent-Disposition: form-data; name=\"name\"\r\n\r\nm\r\n--XB\r\nContent-Disposition: form-data; name=\"picture\"; filename=\"p.png\"\r\nContent-Type: image/png\r\n\r\n".to_vec();
    body.extend_from_slice(&png[..png.len() / 2]);
    let head = |len: usize| {
        format!(
            "POST /api/v1/maps HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {TOKEN}\r\nContent-Type: multipart/form-data; boundary=XB\r\nContent-Length: {len}\r\nConnection: close\r\n\r\n"
        )
        .into_bytes()
    };
    // The client promised 5000 bytes and hung up after fewer (was: 500 "failed to read stream").
    let request = [head(5000), body.clone()].concat();
    let (status, answer) = raw_exchange(&url, &request).await;
    assert!(status.starts_with("HTTP/1.1 400"), "{status} {answer}");
    let answer: Value = serde_json::from_str(&answer).unwrap();
    assert_eq!(answer["error"], "bad_request");
    assert!(
        answer["reason"].as_str().unwrap().contains("multipart"),
        "{answer}"
    );
    // A body that is whole as HTTP but ends inside a part (no closing boundary).
    let request = [head(body.len()), body].concat();
    let (status, answer) = raw_exchange(&url, &request).await;
    assert!(status.starts_with("HTTP/1.1 400"), "{status} {answer}");
    assert_eq!(map_count(&client(), &url).await, 0);
    server.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn numbers_out_of_their_physical_range_are_refused_and_store_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path(), config()).await;
    let url = server.url();
    let c = client();
    let upload = |form: Form| {
        c.post(format!("{url}/api/v1/maps"))
            .bearer_auth(TOKEN)
            .multipart(form)
            .send()
    };
    let yaml = std::fs::read_to_string(nav2("testmap.yaml")).unwrap();
    let png = read("testmap.png");
    let ros = |yaml: String| {
        Form::new()
            .text("name", "t")
            .part("yaml", Part::bytes(yaml.into_bytes()).file_name("t.yaml"))
            .part("image", Part::bytes(png.clone()).file_name("testmap.png"))
    };
    let maps: Vec<(&str, Form, &str)> = vec![
        (
            "tiny resolution in yaml",
            ros(yaml.replace("resolution: 0.1", "resolution: 1e-300")),
            "resolution = 1e-300",
        ),
        (
            "huge resolution in yaml",
            ros(yaml.replace("resolution: 0.1", "resolution: 11")),
            "resolution = 11",
        ),
        (
            "far origin in yaml",
            ros(yaml.replace("origin: [2.0, 3.0, 1.0]", "origin: [1e308, 3.0, 1.0]")),
            "origin.x_m = 1e308",
        ),
        (
            "origin yaw in yaml",
            ros(yaml.replace("origin: [2.0, 3.0, 1.0]", "origin: [2.0, 3.0, 1e300]")),
            "origin.yaw_rad = 1e300",
        ),
        (
            "map reaching past 100 km",
            ros(yaml.replace("origin: [2.0, 3.0, 1.0]", "origin: [99999.5, 3.0, 0.0]")),
            "extent",
        ),
        (
            "tiny picture resolution",
            picture_form("p", "testmap.png", "1e-300"),
            "resolution_m = 1e-300",
        ),
        (
            "far picture origin",
            picture_form("p", "testmap.png", "0.1").text("origin_y_m", "-2.5e301"),
            "origin_y_m = -2.5e301",
        ),
    ];
    for (what, form, needle) in maps {
        let reason = expect_error(
            upload(form).await.unwrap(),
            StatusCode::BAD_REQUEST,
            "bad_request",
        )
        .await;
        assert!(reason.contains(needle), "{what}: {reason}");
    }
    assert_eq!(map_count(&c, &url).await, 0);
    // The edges themselves are accepted.
    let resp = upload(picture_form("edge", "testmap.png", "10").text("origin_x_m", "-99000"))
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::CREATED);
    let resp = upload(picture_form("fine", "testmap.png", "0.001"))
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::CREATED);

    upload_depot(&c, &url).await;
    let ((fx, fy), _) = depot_points();
    let tasks: Vec<(Value, &str)> = vec![
        (
            serde_json::json!({"map": "depot", "goals": [{"x_m": 2.5e301, "y_m": fy}]}),
            "goals[0].x_m = 2.5e301",
        ),
        (
            serde_json::json!({"map": "depot", "goals": [{"x_m": fx, "y_m": fy}, {"x_m": fx, "y_m": -1e308}]}),
            "goals[1].y_m = -1e308",
        ),
        (
            serde_json::json!({"map": "depot", "goals": [{"x_m": fx, "y_m": fy, "yaw_rad": 1e300}]}),
            "goals[0].yaw_rad = 1e300",
        ),
        (
            serde_json::json!({"map": "depot", "goals": [{"x_m": fx, "y_m": fy, "yaw_rad": 6.3}]}),
            "goals[0].yaw_rad = 6.3",
        ),
    ];
    for (body, needle) in tasks {
        let resp = c
            .post(format!("{url}/api/v1/tasks"))
            .bearer_auth(TOKEN)
            .json(&body)
            .send()
            .await
            .unwrap();
        let reason = expect_error(resp, StatusCode::BAD_REQUEST, "bad_request").await;
        assert!(reason.contains(needle), "{body}: {reason}");
        assert!(reason.len() < 200, "{reason}");
    }
    assert_eq!(task_count(&c, &url).await, 0);
    // -2π and a free heading are fine.
    let resp = c
        .post(format!("{url}/api/v1/tasks"))
        .bearer_auth(TOKEN)
        .json(&serde_json::json!({"map": "depot", "goals": [{"x_m": fx, "y_m": fy, "yaw_rad": -std::f64::consts::TAU}, {"x_m": fx, "y_m": fy, "yaw_rad": null}]}))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::CREATED);

    // The version of an image: 1 to 2^32 - 1, as documented.
    for v in ["0", "4294967296", "-1"] {
        let resp = c
            .get(format!("{url}/api/v1/maps/depot/image?version={v}"))
            .send()
            .await
            .unwrap();
        expect_error(resp, StatusCode::BAD_REQUEST, "bad_request").await;
    }
    let resp = c
        .get(format!("{url}/api/v1/maps/depot/image?version=4294967295"))
        .send()
        .await
        .unwrap();
    expect_error(resp, StatusCode::NOT_FOUND, "not_found").await;
    server.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn error_reasons_hide_server_paths_and_cut_long_values() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path(), config()).await;
    let url = server.url();
    let c = client();
    let yaml = std::fs::read_to_string(nav2("testmap.yaml")).unwrap();
    let hidden = |reason: &str| {
        let data_dir = dir.path().display().to_string();
        assert!(!reason.contains(&data_dir), "{reason}");
        assert!(!reason.contains("uploads"), "{reason}");
        assert!(!reason.contains("/tmp"), "{reason}");
        assert!(
            !reason.contains(&format!("{}-", std::process::id())),
            "{reason}"
        );
    };
    // An image that does not decode (was: "cannot decode image /tmp/…/uploads/<pid>-<n>/map.pgm").
    let form = Form::new()
        .text("name", "t")
        .part("yaml", Part::bytes(yaml.into_bytes()).file_name("t.yaml"))
        .part(
            "image",
            Part::bytes(b"P5 junk".to_vec()).file_name("broken.pgm"),
        );
    let resp = c
        .post(format!("{url}/api/v1/maps"))
        .bearer_auth(TOKEN)
        .multipart(form)
        .send()
        .await
        .unwrap();
    let reason = expect_error(resp, StatusCode::BAD_REQUEST, "bad_request").await;
    hidden(&reason);
    assert!(reason.contains("part `image` (broken.pgm)"), "{reason}");
    let resp = c
        .post(format!("{url}/api/v1/maps/preview"))
        .bearer_auth(TOKEN)
        .multipart(
            Form::new()
                .part(
                    "picture",
                    Part::bytes(b"GIF89a".to_vec()).file_name("p.gif"),
                )
                .text("resolution_m", "0.1"),
        )
        .send()
        .await
        .unwrap();
    let reason = expect_error(resp, StatusCode::BAD_REQUEST, "bad_request").await;
    hidden(&reason);
    assert!(reason.contains("part `picture` (p.gif)"), "{reason}");

    // A 20 000-character id is echoed as 64 characters and an ellipsis.
    let long = "a".repeat(20_000);
    let resp = c
        .get(format!("{url}/api/v1/tasks/{long}"))
        .send()
        .await
        .unwrap();
    let reason = expect_error(resp, StatusCode::BAD_REQUEST, "bad_request").await;
    assert!(reason.contains('…') && reason.len() < 300, "{reason}");
    let resp = c
        .post(format!("{url}/api/v1/tasks"))
        .bearer_auth(TOKEN)
        .json(&serde_json::json!({"map": "depot", "robot_id": long, "goals": [{"x_m": 1.0, "y_m": 1.0}]}))
        .send()
        .await
        .unwrap();
    let reason = expect_error(resp, StatusCode::BAD_REQUEST, "bad_request").await;
    assert!(
        reason.contains("robot_id") && reason.contains('…') && reason.len() < 600,
        "{reason}"
    );
    let resp = c.get(format!("{url}/no/such/{long}")).send().await.unwrap();
    let reason = expect_error(resp, StatusCode::NOT_FOUND, "not_found").await;
    assert!(reason.len() < 200, "{reason}");
    server.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_bearer_scheme_is_case_insensitive() {
    let dir = tempfile::tempdir().unwrap();
    let server = start(dir.path(), config()).await;
    let url = server.url();
    let c = client();
    for (i, scheme) in ["bearer", "BEARER", "bEaReR", "Bearer"].iter().enumerate() {
        let resp = c
            .post(format!("{url}/api/v1/maps"))
            .header("Authorization", format!("{scheme}  {TOKEN}"))
            .multipart(picture_form(&format!("m{i}"), "testmap.png", "0.1"))
            .send()
            .await
            .unwrap();
        assert_eq!(resp.status(), StatusCode::CREATED, "{scheme}");
    }
    for value in [
        format!("Basic {TOKEN}"),
        format!("bearer{TOKEN}"),
        "bearer wrong-token-0123456789".to_string(),
    ] {
        let resp = c
            .post(format!("{url}/api/v1/maps"))
            .header("Authorization", value.clone())
            .multipart(picture_form("x", "testmap.png", "0.1"))
            .send()
            .await
            .unwrap();
        expect_error(resp, StatusCode::UNAUTHORIZED, "unauthorized").await;
    }
    assert_eq!(map_count(&c, &url).await, 4);
    server.stop().await.unwrap();
}

/// The cursor's pattern in the OpenAPI document admits exactly the cursors the server decodes,
/// and the upload body's `oneOf` admits exactly the part combinations the server takes.
#[test]
fn openapi_patterns_and_upload_shapes_match_the_server() {
    use planner_service::fleet::Cursor;
    use protocol::TaskId;
    let doc = planner_service::http::openapi::document();
    let cursor = &doc["paths"]["/api/v1/tasks"]["get"]["parameters"][4];
    assert_eq!(cursor["name"], "cursor");
    let valid = jsonschema::validator_for(&cursor["schema"]).unwrap();
    let long_id = "Z9_.-".repeat(12) + "abcd";
    for (created_ns, id) in [
        (0_u64, "t-1"),
        (u64::MAX, "a"),
        (1_763_000_000_000_000_000, long_id.as_str()),
        (42, "-_"),
    ] {
        let text = Cursor {
            created_ns,
            id: TaskId::new(id.to_string()).unwrap(),
        }
        .encode();
        assert!(valid.is_valid(&json!(text)), "{text}");
        assert!(Cursor::decode(&text).is_some(), "{text}");
    }
    let upper = Cursor {
        created_ns: 10,
        id: TaskId::new("Task-1".to_string()).unwrap(),
    }
    .encode()
    .to_uppercase();
    for bad in [
        "000000000000000000".to_string(),               // id byte 0x00
        "0000000000000000".to_string(),                 // no id
        "00000000000000002e61".to_string(),             // id starts with '.'
        "0000000000000000616".to_string(),              // odd length
        format!("0000000000000000{}", "61".repeat(65)), // id too long
        "0000000000000000612f".to_string(),             // '/' in the id
        upper,
    ] {
        assert!(!valid.is_valid(&json!(bad)), "{bad}");
        assert!(Cursor::decode(&bad).is_none(), "{bad}");
    }

    let upload = &doc["paths"]["/api/v1/maps"]["post"]["requestBody"]["content"]
        ["multipart/form-data"]["schema"];
    let valid = jsonschema::validator_for(upload).unwrap();
    let shape = |parts: &[&str]| {
        let mut body = serde_json::Map::new();
        for p in parts {
            let v = if p.ends_with("_m") {
                json!(0.05)
            } else {
                json!("x")
            };
            body.insert((*p).to_string(), v);
        }
        serde_json::Value::Object(body)
    };
    for ok in [
        &["name", "yaml", "image"][..],
        &["name", "picture", "resolution_m"],
        &[
            "name",
            "picture",
            "resolution_m",
            "origin_x_m",
            "origin_y_m",
        ],
    ] {
        assert!(valid.is_valid(&shape(ok)), "{ok:?}");
    }
    for bad in [
        &["name", "yaml", "image", "picture"][..],
        &["name", "yaml", "image", "origin_x_m"],
        &["name", "yaml", "image", "resolution_m"],
        &["name", "picture"],
        &["name", "yaml"],
        &["name", "image"],
        &["name"],
        &["yaml", "image"],
    ] {
        assert!(!valid.is_valid(&shape(bad)), "{bad:?}");
    }
}

#[test]
fn openapi_document_states_the_bounds_the_server_checks() {
    use planner_service::http::ranges;
    let doc = planner_service::http::openapi::document();
    let schema = |p: &str| doc.pointer(p).unwrap_or_else(|| panic!("{p}")).clone();
    // Ids and names: never empty, never longer than the protocol allows.
    for (p, max) in [
        ("/components/schemas/NewTask/properties/map", 51),
        ("/components/schemas/NewTask/properties/robot_id", 64),
        (
            "/paths/~1api~1v1~1maps/post/requestBody/content/multipart~1form-data/schema/properties/name",
            51,
        ),
    ] {
        let s = schema(p);
        assert_eq!(s["minLength"], 1, "{p}");
        assert_eq!(s["maxLength"], max, "{p}");
        assert!(s["pattern"].as_str().unwrap().starts_with('^'), "{p}");
    }
    let cursor = &doc["paths"]["/api/v1/tasks"]["get"]["parameters"][4];
    assert_eq!(cursor["name"], "cursor");
    assert_eq!(cursor["schema"]["maxLength"], 144);
    let version = &doc["paths"]["/api/v1/maps/{name}/image"]["get"]["parameters"][1];
    assert_eq!(version["name"], "version");
    assert_eq!(version["schema"]["minimum"], 1);
    assert_eq!(version["schema"]["maximum"], u64::from(u32::MAX));
    for (p, min, max) in [
        (
            "/components/schemas/Goal/properties/x_m",
            -ranges::MAX_COORDINATE_M,
            ranges::MAX_COORDINATE_M,
        ),
        (
            "/components/schemas/Goal/properties/y_m",
            -ranges::MAX_COORDINATE_M,
            ranges::MAX_COORDINATE_M,
        ),
        (
            "/components/schemas/Goal/properties/yaw_rad",
            -ranges::MAX_ABS_YAW_RAD,
            ranges::MAX_ABS_YAW_RAD,
        ),
        (
            "/paths/~1api~1v1~1maps/post/requestBody/content/multipart~1form-data/schema/properties/resolution_m",
            ranges::MIN_RESOLUTION_M,
            ranges::MAX_RESOLUTION_M,
        ),
        (
            "/paths/~1api~1v1~1maps~1preview/post/requestBody/content/multipart~1form-data/schema/properties/origin_x_m",
            -ranges::MAX_COORDINATE_M,
            ranges::MAX_COORDINATE_M,
        ),
    ] {
        let s = schema(p);
        assert_eq!(s["minimum"].as_f64(), Some(min), "{p}");
        assert_eq!(s["maximum"].as_f64(), Some(max), "{p}");
    }
    let codes = schema("/components/schemas/Error/properties/error/enum");
    assert!(codes
        .as_array()
        .unwrap()
        .contains(&Value::from("unavailable")));
}

// ----- hardening (issue 17): connections -------------------------------------------------

/// Reads until the server closes the connection; how long that took, or `None` when it was
/// still open after `limit`.
async fn closed_within(s: &mut tokio::net::TcpStream, limit: Duration) -> Option<Duration> {
    use tokio::io::AsyncReadExt;
    let t0 = std::time::Instant::now();
    let mut buf = [0_u8; 1024];
    let read_all = async {
        loop {
            match s.read(&mut buf).await {
                Ok(0) | Err(_) => break,
                Ok(_) => {}
            }
        }
    };
    tokio::time::timeout(limit, read_all).await.ok()?;
    Some(t0.elapsed())
}

async fn connect_and_send(url: &str, bytes: &[u8]) -> tokio::net::TcpStream {
    use tokio::io::AsyncWriteExt;
    let mut s = tokio::net::TcpStream::connect(url.strip_prefix("http://").unwrap())
        .await
        .unwrap();
    s.write_all(bytes).await.unwrap();
    s
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn slow_and_idle_connections_are_closed_and_extra_ones_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config();
    cfg.http.header_read_timeout_ms = 1500;
    cfg.http.idle_timeout_ms = 3000;
    cfg.http.max_connections = 3;
    let server = start(dir.path(), cfg).await;
    let url = server.url();
    let half_head = b"GET /healthz HTTP/1.1\r\nHost: x\r\n";
    // A fresh connection per request, so that no pooled connection holds a slot.
    let fresh = || {
        reqwest::Client::builder()
            .timeout(Duration::from_secs(20))
            .pool_max_idle_per_host(0)
            .build()
            .unwrap()
    };

    // Half a request head, nothing at all, and a request whose body stalls: the first two are
    // closed by the header-read timeout, the third by the idle timeout.
    let mut slow = connect_and_send(&url, half_head).await;
    let mut silent = connect_and_send(&url, b"").await;
    let stalled_head = format!(
        "POST /api/v1/tasks HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {TOKEN}\r\nContent-Type: application/json\r\nContent-Length: 100\r\n\r\n{{\"map\":"
    );
    let mut stalled = connect_and_send(&url, stalled_head.as_bytes()).await;
    let limit = Duration::from_secs(15);
    let (a, b, c) = tokio::join!(
        closed_within(&mut slow, limit),
        closed_within(&mut silent, limit),
        closed_within(&mut stalled, limit)
    );
    let (a, b, c) = (a.unwrap(), b.unwrap(), c.unwrap());
    let header = Duration::from_millis(1500);
    let idle = Duration::from_millis(3000);
    assert!(
        a >= header - Duration::from_millis(100) && a < header * 4,
        "{a:?}"
    );
    assert!(
        b >= header - Duration::from_millis(100) && b < header * 4,
        "{b:?}"
    );
    assert!(
        c >= idle - Duration::from_millis(100) && c < idle * 3,
        "{c:?}"
    );

    // Two slow clients hold two of the three slots: requests still work.
    let mut holders = vec![
        connect_and_send(&url, half_head).await,
        connect_and_send(&url, half_head).await,
    ];
    // (Retried for a moment: on a busy test machine a stray connection from another process,
    // e.g. a Zenoh peer retrying a port that this listener now has, can take a slot briefly.)
    let healthy = || async {
        let t0 = std::time::Instant::now();
        loop {
            let status = fresh()
                .get(format!("{url}/healthz"))
                .send()
                .await
                .unwrap()
                .status();
            if status == StatusCode::OK || t0.elapsed() > Duration::from_secs(3) {
                return status;
            }
            tokio::time::sleep(Duration::from_millis(250)).await;
        }
    };
    assert_eq!(healthy().await, StatusCode::OK);
    // (The server notices the client's close a moment later.)
    tokio::time::sleep(Duration::from_millis(200)).await;
    // A third takes the last slot: one more is refused at once, with a reason and a retry time.
    holders.push(connect_and_send(&url, half_head).await);
    tokio::time::sleep(Duration::from_millis(100)).await;
    let t0 = std::time::Instant::now();
    let (status, body) = raw_exchange(&url, b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n").await;
    assert!(t0.elapsed() < Duration::from_secs(1), "{:?}", t0.elapsed());
    assert!(status.starts_with("HTTP/1.1 503"), "{status}");
    let body: Value = serde_json::from_str(&body).unwrap();
    assert_eq!(body["error"], "unavailable");
    assert!(
        body["reason"].as_str().unwrap().contains("max_connections"),
        "{body}"
    );
    let resp = fresh().get(format!("{url}/healthz")).send().await.unwrap();
    assert_eq!(resp.status(), StatusCode::SERVICE_UNAVAILABLE);
    assert_eq!(resp.headers()["retry-after"], "1");
    // Once the slow clients are timed out, the slots are free again.
    for h in &mut holders {
        assert!(closed_within(h, limit).await.is_some());
    }
    assert_eq!(healthy().await, StatusCode::OK);

    // A quiet event stream is not idle: keep-alive comments come every half idle timeout.
    let mut events = fresh()
        .get(format!("{url}/api/v1/events"))
        .send()
        .await
        .unwrap();
    let t0 = std::time::Instant::now();
    let mut keep_alives = 0;
    while t0.elapsed() < idle + Duration::from_millis(1500) {
        let chunk = tokio::time::timeout(Duration::from_secs(5), events.chunk())
            .await
            .expect("the stream stays open")
            .unwrap()
            .expect("the stream is not closed");
        keep_alives += String::from_utf8_lossy(&chunk)
            .matches(": keep-alive")
            .count();
    }
    assert!(keep_alives >= 2, "{keep_alives}");
    drop(events);

    // Stopping closes connections that wait for a head at once.
    let mut waiting = connect_and_send(&url, half_head).await;
    tokio::time::sleep(Duration::from_millis(100)).await;
    let t0 = std::time::Instant::now();
    server.stop().await.unwrap();
    assert!(closed_within(&mut waiting, Duration::from_secs(5))
        .await
        .is_some());
    assert!(t0.elapsed() < Duration::from_secs(5), "{:?}", t0.elapsed());
}

/// A grey PNG of `w` × `h` pixels, all free, compressed to a few KB whatever its size.
fn blank_png(w: u32, h: u32) -> Vec<u8> {
    let img = image::GrayImage::from_pixel(w, h, image::Luma([254u8]));
    let mut png = Vec::new();
    image::DynamicImage::ImageLuma8(img)
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    png
}

/// Issue 17, item 3: a picture's decode is budgeted from its header before it is decoded, and
/// a map version's image is rendered once.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn decodes_are_budgeted_and_map_images_rendered_once() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config();
    // 16 MiB for all decodes: a 3000 × 3000 grey picture needs 3000 · 3000 · 2 B = 17.2 MB.
    cfg.http.decode_budget_bytes = 16 << 20;
    let server = start(dir.path(), cfg).await;
    let (url, c) = (server.url(), client());
    let big = blank_png(3000, 3000);
    assert!(big.len() < 200_000, "{} bytes", big.len());
    let form = Form::new()
        .text("name", "huge")
        .part("picture", Part::bytes(big).file_name("huge.png"))
        .text("resolution_m", "0.05");
    let resp = c
        .post(format!("{url}/api/v1/maps"))
        .bearer_auth(TOKEN)
        .multipart(form)
        .send()
        .await
        .unwrap();
    let reason = expect_error(resp, StatusCode::PAYLOAD_TOO_LARGE, "too_large").await;
    assert!(
        reason.contains("18 MB") && reason.contains("decode_budget_bytes"),
        "{reason}"
    );
    assert_eq!(
        map_count(&c, &url).await,
        0,
        "a refused upload stored something"
    );

    // Within the budget: stored, and its image rendered on the first request only.
    let form = Form::new()
        .text("name", "plan")
        .part(
            "picture",
            Part::bytes(blank_png(400, 300)).file_name("plan.png"),
        )
        .text("resolution_m", "0.05");
    let resp = c
        .post(format!("{url}/api/v1/maps"))
        .bearer_auth(TOKEN)
        .multipart(form)
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::CREATED);
    let image_url = format!("{url}/api/v1/maps/plan/image");
    let first = c.get(&image_url).send().await.unwrap();
    assert_eq!(first.status(), StatusCode::OK);
    let etag = first.headers()["etag"].clone();
    let first = first.bytes().await.unwrap();
    let second = c.get(&image_url).send().await.unwrap();
    assert_eq!(second.headers()["etag"], etag);
    assert_eq!(second.bytes().await.unwrap(), first);
    // The client's copy is current: 304, no body.
    let again = c
        .get(&image_url)
        .header("if-none-match", etag.clone())
        .send()
        .await
        .unwrap();
    assert_eq!(again.status(), StatusCode::NOT_MODIFIED);
    assert!(again.bytes().await.unwrap().is_empty());
    let metrics = c
        .get(format!("{url}/metrics"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert!(
        metrics.contains("fleet_http_map_image_lookups_total{result=\"hit\"} 1")
            && metrics.contains("fleet_http_map_image_lookups_total{result=\"miss\"} 1"),
        "{metrics}"
    );
    assert!(
        metrics.contains(&format!(
            "fleet_http_decode_budget_available_bytes {}",
            16 << 20
        )),
        "{metrics}"
    );
    server.stop().await.unwrap();
}
