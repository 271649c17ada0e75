//! The built `map-store` binary: import, list, export, and rejections with a non-zero exit,
//! a message naming field and value, and nothing stored.

// Helpers outside #[test] functions are test code too.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::Path;
use std::process::{Command, Output};

fn map_store(data_dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_map-store"))
        .arg("--data-dir")
        .arg(data_dir)
        .args(args)
        .env_remove("MAP_STORE_DATA_DIR")
        .output()
        .unwrap()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn nav2(file: &str) -> String {
    test_support::nav2_maps_dir()
        .join(file)
        .display()
        .to_string()
}

fn stored_versions(data_dir: &Path) -> serde_json::Value {
    let out = map_store(data_dir, &["list", "--json"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn import_list_export_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let out = map_store(&data, &["import", &nav2("depot.yaml")]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let s = text(&out.stdout);
    for part in [
        "id:         depot-",
        "name:       depot",
        "version:    1",
        "width:      604",
        "height:     307",
        "resolution: 0.05",
        "origin:     x 0 m, y 0 m, yaw 0 rad",
        "free:       179481",
        "occupied:   5947",
        "unknown:    0",
    ] {
        assert!(s.contains(part), "{part:?} missing in\n{s}");
    }
    let out = map_store(
        &data,
        &["import", &nav2("testmap.yaml"), "--name", "depot", "--json"],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let meta: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(meta["version"], 2);
    assert_eq!(meta["occupied_cells"], 29);

    let list = stored_versions(&data);
    assert_eq!(list.as_array().unwrap().len(), 2);
    let out = map_store(&data, &["list"]);
    assert!(text(&out.stdout).contains("depot"));

    let v1_id = list[1]["id"].as_str().unwrap().to_string();
    let yaml = dir.path().join("out.yaml");
    let out = map_store(&data, &["export", &v1_id, yaml.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    // Re-importing the export gives the same content, hence the same id and version.
    let out = map_store(
        &data,
        &[
            "import",
            yaml.to_str().unwrap(),
            "--name",
            "depot",
            "--json",
        ],
    );
    let again: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(again["id"].as_str(), Some(v1_id.as_str()));
    assert_eq!(again["version"], 1);
}

#[test]
fn picture_import_needs_a_scale() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let out = map_store(&data, &["import", &nav2("testmap.png")]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("resolution"),
        "{}",
        text(&out.stderr)
    );
    let out = map_store(
        &data,
        &["import", &nav2("testmap.png"), "--resolution", "0.1"],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stdout).contains("name:       testmap"));
    assert!(text(&out.stdout).contains("occupied:   29"));
}

#[test]
fn bad_inputs_exit_non_zero_name_the_problem_and_store_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let yaml = dir.path().join("bad.yaml");
    std::fs::write(
        &yaml,
        format!(
            "image: {}\nresolution: -0.05\norigin: [0, 0, 0]\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
            nav2("testmap.pgm")
        ),
    )
    .unwrap();
    let missing = dir.path().join("missing.yaml");
    let (png, depot) = (nav2("testmap.png"), nav2("depot.yaml"));
    let cases: [(Vec<&str>, &[&str]); 4] = [
        (
            vec!["import", yaml.to_str().unwrap()],
            &["resolution", "-0.05"],
        ),
        (vec!["import", missing.to_str().unwrap()], &["missing.yaml"]),
        (
            vec!["import", &png, "--resolution", "0"],
            &["resolution", "0"],
        ),
        (
            vec!["import", &depot, "--name", "a/b"],
            &["map_name", "a/b"],
        ),
    ];
    for (args, parts) in cases {
        let out = map_store(&data, &args);
        assert!(!out.status.success(), "{args:?} should fail");
        assert_eq!(out.status.code(), Some(1), "{args:?}");
        let err = text(&out.stderr);
        for p in parts {
            assert!(err.contains(p), "{args:?}: {p:?} missing in {err}");
        }
    }
    assert_eq!(stored_versions(&data), serde_json::json!([]));
    let out = map_store(
        &data,
        &[
            "export",
            "nothing",
            dir.path().join("x.yaml").to_str().unwrap(),
        ],
    );
    assert!(!out.status.success());
    assert!(text(&out.stderr).contains("nothing"));
    assert!(!dir.path().join("x.yaml").exists());
}
