//! `eval record`: a short recording on one training scenario, checked file by file (index,
//! shard shapes and dtypes, label ranges, DLM values, noise injection), its determinism, and
//! the refusal of a scenario that is not a training one.

#![allow(clippy::unwrap_used)]
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use eval::record::{record, RecordError, RecordOptions};

fn scenario(name: &str) -> PathBuf {
    test_support::scenarios_dir().join(name)
}

fn options(noise: f64, jobs: usize) -> RecordOptions {
    RecordOptions {
        scenarios: vec![scenario("train_lab.yaml")],
        samples: 300,
        noise,
        seed: 3,
        jobs,
        image_px: 32,
        episode_s: 12.0,
        shard_samples: 128,
        ..RecordOptions::default()
    }
}

/// A parsed `.npy` file: descr, shape and the data bytes.
fn read_npy(path: &Path) -> (String, Vec<usize>, Vec<u8>) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00", "{}", path.display());
    let len = usize::from(u16::from_le_bytes([bytes[8], bytes[9]]));
    assert_eq!((10 + len) % 64, 0, "data of {} not aligned", path.display());
    let header = std::str::from_utf8(&bytes[10..10 + len]).unwrap();
    let descr = header
        .split("'descr': '")
        .nth(1)
        .unwrap()
        .split('\'')
        .next()
        .unwrap();
    let shape: Vec<usize> = header
        .split("'shape': (")
        .nth(1)
        .unwrap()
        .split(')')
        .next()
        .unwrap()
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().unwrap())
        .collect();
    (descr.to_string(), shape, bytes[10 + len..].to_vec())
}

fn f32s(data: &[u8]) -> Vec<f32> {
    data.chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

fn u32s(data: &[u8]) -> Vec<u32> {
    data.chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

/// Every field of a recording concatenated over its shards (descr checked against the index).
fn read_all(dir: &Path) -> (serde_json::Value, BTreeMap<String, Vec<u8>>) {
    let index: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("index.json")).unwrap()).unwrap();
    let mut fields: BTreeMap<String, Vec<u8>> = BTreeMap::new();
    for shard in index["shards"].as_array().unwrap() {
        let n = shard["samples"].as_u64().unwrap() as usize;
        for (name, spec) in index["fields"].as_object().unwrap() {
            let file = shard["files"][name].as_str().unwrap();
            let (descr, shape, data) = read_npy(&dir.join(file));
            let want_descr = match spec["dtype"].as_str().unwrap() {
                "uint8" => "|u1",
                "uint32" => "<u4",
                "float32" => "<f4",
                other => panic!("dtype {other}"),
            };
            assert_eq!(descr, want_descr, "{file}");
            let mut want_shape = vec![n];
            want_shape.extend(
                spec["shape"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|d| d.as_u64().unwrap() as usize),
            );
            assert_eq!(shape, want_shape, "{file}");
            let elem = if descr == "|u1" { 1 } else { 4 };
            assert_eq!(data.len(), shape.iter().product::<usize>() * elem, "{file}");
            fields.entry(name.clone()).or_default().extend(data);
        }
    }
    (index, fields)
}

#[test]
fn a_short_recording_has_the_documented_files_and_values() {
    let out = tempfile::tempdir().unwrap();
    let summary = record(&options(1.0, 2), out.path(), &|_| {}).unwrap();
    assert_eq!(summary.samples, 300);
    let (index, fields) = read_all(out.path());
    assert_eq!(index["format"], "intention-fleet-demonstrations");
    assert_eq!(index["samples"], 300);
    assert_eq!(index["image_px"], 32);
    // The LPE images' rendering, for the card of a model trained on them.
    let rendering: protocol::LpeParams =
        serde_json::from_value(index["lpe_rendering"].clone()).unwrap();
    assert_eq!(rendering, protocol::LpeParams::default());
    // And how the DLM labels were derived, for the card of a DLM-Net trained on them.
    let dlm: planning::DlmParams = serde_json::from_value(index["dlm_params"].clone()).unwrap();
    assert_eq!(dlm, planning::DlmParams::default());
    assert!(index["policy"].is_null());
    assert_eq!(index["dataset_id"], summary.dataset_id.as_str());
    assert_eq!(index["scenarios"][0]["name"], "train_lab");
    // 300 samples in shards of 128.
    let counts: Vec<u64> = index["shards"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["samples"].as_u64().unwrap())
        .collect();
    assert_eq!(counts, vec![128, 128, 44]);
    assert_eq!(fields["camera"].len(), 300 * 32 * 32 * 3);
    assert_eq!(fields["lpe"].len(), 300 * 32 * 32 * 3);
    // Images are not blank: the camera sees a world, the LPE draws a map.
    for name in ["camera", "lpe"] {
        let px = &fields[name];
        assert!(px.iter().any(|&v| v != px[0]), "{name} is uniform");
    }

    let label = f32s(&fields["label"]);
    let executed = f32s(&fields["executed"]);
    let target = f32s(&fields["target"]);
    assert_eq!(target.len(), label.len());
    assert!(label
        .iter()
        .chain(&executed)
        .chain(&target)
        .all(|v| (-1.0..=1.0).contains(v)));
    assert!(
        label.chunks(2).any(|c| c[0] > 0.1),
        "the expert never drove"
    );
    assert!(fields["dlm"].iter().all(|&d| d < 4));
    assert!(fields["scenario"].chunks(4).all(|c| c == [0, 0, 0, 0]));
    assert!(fields["noisy"].iter().all(|&n| n == 1));
    // Episodes end at the first cycle past 12 s.
    let t = f32s(&fields["t_s"]);
    assert!(t
        .iter()
        .all(|v| v.is_finite() && *v > 0.0 && *v <= 12.0 + 0.1 + 1e-3));
    let pose = f32s(&fields["pose_true"]);
    assert!(pose.iter().all(|v| v.is_finite()));

    // Noise goes into what the robot executes, the speed is never touched.
    let perturbed = label
        .chunks(2)
        .zip(executed.chunks(2))
        .filter(|(l, e)| (l[1] - e[1]).abs() > 1e-4)
        .count();
    assert!(perturbed > 30, "only {perturbed} perturbed samples");
    assert!(label
        .chunks(2)
        .zip(executed.chunks(2))
        .all(|(l, e)| l[0] == e[0]));
    // The labels correct the push: pushed left (executed ω above the label), the expert turns
    // right on average, and the other way round.
    let mean_label_w = |left: bool| {
        let ws: Vec<f32> = label
            .chunks(2)
            .zip(executed.chunks(2))
            .filter(|(l, e)| {
                if left {
                    e[1] - l[1] > 0.05
                } else {
                    e[1] - l[1] < -0.05
                }
            })
            .map(|(l, _)| l[1])
            .collect();
        assert!(ws.len() > 10);
        ws.iter().sum::<f32>() / ws.len() as f32
    };
    let (left, right) = (mean_label_w(true), mean_label_w(false));
    assert!(
        left < 0.0 && right > 0.0,
        "label ω {left} when pushed left, {right} when pushed right"
    );

    // The labels are the expert's for the state: the same episodes without noise give the
    // same labels until the first perturbation (≥ 1 s in), then the states part.
    let clean_dir = tempfile::tempdir().unwrap();
    record(&options(0.0, 2), clean_dir.path(), &|_| {}).unwrap();
    let (_, clean) = read_all(clean_dir.path());
    let clean_label = f32s(&clean["label"]);
    let clean_exec = f32s(&clean["executed"]);
    assert_eq!(clean_label, clean_exec, "no noise: executed is the label");
    assert!(clean["noisy"].iter().all(|&n| n == 0));
    assert_eq!(clean["episode"], fields["episode"]);
    let first = label
        .chunks(2)
        .zip(executed.chunks(2))
        .position(|(l, e)| (l[1] - e[1]).abs() > 1e-4)
        .unwrap();
    assert!(first >= 5);
    assert_eq!(label[..2 * first], clean_label[..2 * first]);
    assert_ne!(label, clean_label);

    // The curvature DLM labels the same states (the expert never reads the DLM), and is
    // another dataset.
    let mut curvature = options(1.0, 2);
    curvature.run.intention.dlm = planning::DlmParams::curvature();
    assert_ne!(curvature.dataset_id().unwrap(), summary.dataset_id);
    let curvature_dir = tempfile::tempdir().unwrap();
    record(&curvature, curvature_dir.path(), &|_| {}).unwrap();
    let (curvature_index, curvature_fields) = read_all(curvature_dir.path());
    assert_eq!(curvature_index["dlm_params"]["measure"], "curvature");
    assert_eq!(curvature_fields["label"], fields["label"]);
    assert_eq!(curvature_fields["camera"], fields["camera"]);

    // Labels come from a new search every cycle, whatever the service's default; kept paths
    // would be another dataset.
    assert!(!options(1.0, 2).run.intention.reuse.enabled);
    let mut kept = options(1.0, 2);
    kept.run.intention.reuse.enabled = true;
    assert_ne!(kept.dataset_id().unwrap(), summary.dataset_id);
}

#[test]
fn recordings_are_deterministic_for_any_number_of_jobs() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let mut o = options(0.5, 1);
    o.samples = 250;
    record(&o, a.path(), &|_| {}).unwrap();
    o.jobs = 3;
    record(&o, b.path(), &|_| {}).unwrap();
    let files = |dir: &Path| -> BTreeMap<PathBuf, Vec<u8>> {
        let mut out = BTreeMap::new();
        let mut stack = vec![dir.to_path_buf()];
        while let Some(d) = stack.pop() {
            for e in std::fs::read_dir(&d).unwrap() {
                let p = e.unwrap().path();
                if p.is_dir() {
                    stack.push(p);
                } else {
                    out.insert(
                        p.strip_prefix(dir).unwrap().to_path_buf(),
                        std::fs::read(&p).unwrap(),
                    );
                }
            }
        }
        out
    };
    let (fa, fb) = (files(a.path()), files(b.path()));
    assert!(fa.len() > 10);
    assert_eq!(fa.keys().collect::<Vec<_>>(), fb.keys().collect::<Vec<_>>());
    for (k, v) in &fa {
        assert!(v == &fb[k], "{} differs", k.display());
    }
}

#[test]
fn evaluation_and_behaviour_scenarios_are_refused() {
    for (file, role) in [
        ("task_a.yaml", "evaluation"),
        ("behaviour_glass_door.yaml", "behaviour"),
    ] {
        let mut o = options(0.0, 1);
        o.scenarios.push(scenario(file));
        let out = tempfile::tempdir().unwrap();
        let err = record(&o, out.path(), &|_| {}).unwrap_err();
        assert!(matches!(err, RecordError::NotTraining { .. }), "{err}");
        let text = err.to_string();
        assert!(text.contains(file) && text.contains(role), "{text}");
        // Nothing was written.
        assert!(std::fs::read_dir(out.path()).unwrap().next().is_none());
    }
}

#[test]
fn the_command_line_refuses_an_evaluation_scenario() {
    let out = tempfile::tempdir().unwrap();
    let result = Command::new(env!("CARGO_BIN_EXE_eval"))
        .args(["record", "--samples", "10", "--scenario"])
        .arg(scenario("task_a.yaml"))
        .arg("--out")
        .arg(out.path())
        .output()
        .unwrap();
    assert!(!result.status.success());
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(
        stderr.contains("task_a.yaml") && stderr.contains("evaluation"),
        "{stderr}"
    );
}

/// The Python reader of `training/dataset.py` (what training uses) reads a recording and agrees
/// with the index. It runs the repository's `.venv` (made by `scripts/setup.sh`, whose
/// onnxruntime brings NumPy); `FLEET_PYTHON` names another interpreter.
#[test]
fn the_python_reader_reads_a_recording() {
    let root = test_support::repo_root();
    let python = std::env::var_os("FLEET_PYTHON")
        .map_or_else(|| root.join(".venv/bin/python"), PathBuf::from);
    assert!(
        python.exists(),
        "no Python at {} (run scripts/setup.sh, or set FLEET_PYTHON)",
        python.display()
    );
    let out = tempfile::tempdir().unwrap();
    let summary = record(&options(1.0, 1), out.path(), &|_| {}).unwrap();
    let output = Command::new(&python)
        .arg(root.join("training/dataset.py"))
        .arg(out.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(
        stdout.contains(&format!(
            "dataset {} in {}: {} samples",
            summary.dataset_id,
            out.path().display(),
            summary.samples
        )),
        "{stdout}"
    );
    assert!(stdout.contains("per DLM:"), "{stdout}");
}

/// A DAgger round: a network (the agent's untrained fixture, through the real ONNX Runtime)
/// drives with β = 0.25 and the expert labels. The learner's commands are executed in about
/// three cycles of four, the labels are the expert's (they differ from what was executed), and
/// the model is part of the dataset id.
#[test]
fn a_dagger_round_lets_the_learner_drive_and_the_expert_label() {
    let model = test_support::repo_root().join("models/fixtures/dlm.onnx");
    let mut o = options(0.0, 2);
    o.samples = 120;
    o.policy = Some(eval::record::Policy::load(&model, 0.25).unwrap());
    assert_eq!(
        o.policy.as_ref().unwrap().kind,
        protocol::ControllerKind::Dlm
    );
    let out = tempfile::tempdir().unwrap();
    let summary = record(&o, out.path(), &|_| {}).unwrap();
    assert_eq!(summary.samples, 120);
    let (index, fields) = read_all(out.path());
    assert_eq!(index["policy"]["kind"], "dlm");
    assert_eq!(index["policy"]["beta"], 0.25);
    let learner = &fields["learner"];
    #[allow(clippy::cast_precision_loss)]
    let share = learner.iter().filter(|&&l| l == 1).count() as f64 / learner.len() as f64;
    assert!((0.55..0.95).contains(&share), "learner drove {share}");
    let (label, executed) = (f32s(&fields["label"]), f32s(&fields["executed"]));
    assert!(
        label
            .chunks(2)
            .zip(executed.chunks(2))
            .zip(learner)
            .filter(|((l, e), &who)| who == 1 && (l[0] - e[0]).abs() + (l[1] - e[1]).abs() > 0.05)
            .count()
            > 10,
        "the labels are the executed commands"
    );
    // Another β is another dataset; β outside [0, 1] is refused.
    o.policy = Some(eval::record::Policy::load(&model, 0.5).unwrap());
    assert_ne!(o.dataset_id().unwrap(), summary.dataset_id);
    let err = eval::record::Policy::load(&model, 1.5).unwrap_err();
    assert!(err.to_string().contains("1.5"), "{err}");
    // The expert-only recording has no learner samples.
    o.policy = None;
    let plain = tempfile::tempdir().unwrap();
    record(&o, plain.path(), &|_| {}).unwrap();
    assert!(read_all(plain.path()).1["learner"].iter().all(|&l| l == 0));
}

/// Generated training buildings record like scenario files (named `generated/gen_…` in the
/// index); a seed of the evaluation range is refused before anything is written.
#[test]
fn generated_buildings_record_and_evaluation_seeds_are_refused() {
    let mut o = options(0.0, 2);
    o.scenarios.clear();
    o.generated = vec![5, 6];
    o.samples = 150;
    let out = tempfile::tempdir().unwrap();
    let summary = record(&o, out.path(), &|_| {}).unwrap();
    assert_eq!(summary.samples, 150);
    let (index, fields) = read_all(out.path());
    let names: Vec<&str> = index["scenarios"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["gen_000005", "gen_000006"]);
    // Both buildings were driven (episodes alternate between them).
    let scenario_ids: std::collections::BTreeSet<u8> =
        fields["scenario"].chunks(4).map(|c| c[0]).collect();
    assert_eq!(scenario_ids.len(), 2);
    // Another generated building is another dataset.
    o.generated = vec![5, 7];
    assert_ne!(o.dataset_id().unwrap(), summary.dataset_id);

    o.generated = vec![5, sim::procgen::EVALUATION_SEED_BASE + 3];
    let refused = tempfile::tempdir().unwrap();
    let err = record(&o, refused.path(), &|_| {}).unwrap_err();
    assert!(matches!(err, RecordError::NotTraining { .. }), "{err}");
    assert!(err.to_string().contains("1000003"), "{err}");
    assert!(std::fs::read_dir(refused.path()).unwrap().next().is_none());
}

/// `--encounter-kinds`: the episodes with an encounter get only the kinds asked for, the index
/// lists them, and the kinds are part of the dataset id; no kind, or one twice, is refused.
#[test]
fn encounters_come_only_of_the_kinds_asked_for() {
    use eval::record::encounter::Encounter;
    let mut o = options(0.0, 2);
    o.scenarios = vec![scenario("train_office.yaml")];
    // Furniture fits on fewer first legs than the other kinds (a straight stretch by a wall).
    o.samples = 500;
    o.every = 5;
    o.episode_s = 20.0;
    o.encounters = 1.0;
    o.encounter_kinds = vec![Encounter::Furniture];
    let out = tempfile::tempdir().unwrap();
    let summary = record(&o, out.path(), &|_| {}).unwrap();
    let (index, _) = read_all(out.path());
    assert_eq!(
        index["encounters"]["kinds"],
        serde_json::json!(["furniture"])
    );
    let episodes = index["encounters"]["episodes"].as_object().unwrap();
    assert_eq!(
        episodes.keys().collect::<Vec<_>>(),
        ["furniture"],
        "{episodes:?}"
    );
    assert!(!episodes["furniture"].as_array().unwrap().is_empty());
    let all = RecordOptions {
        encounter_kinds: Encounter::DEFAULT.to_vec(),
        ..o.clone()
    };
    assert_ne!(all.dataset_id().unwrap(), summary.dataset_id);
    for bad in [vec![], vec![Encounter::Furniture, Encounter::Furniture]] {
        let refused = RecordOptions {
            encounter_kinds: bad,
            ..o.clone()
        };
        let err = refused.validate().unwrap_err().to_string();
        assert!(err.contains("encounter_kinds"), "{err}");
    }
}

/// `--encounters-only`: every stored episode got its encounter (the rest were skipped), the
/// index says so, the option is part of the dataset id, and it is refused without encounters.
#[test]
fn encounters_only_stores_only_the_episodes_with_an_encounter() {
    use eval::record::encounter::Encounter;
    let mut o = options(0.0, 2);
    o.scenarios = vec![scenario("train_office.yaml")];
    o.samples = 400;
    o.every = 5;
    o.episode_s = 20.0;
    o.encounters = 1.0;
    o.encounter_kinds = vec![Encounter::Furniture];
    o.encounters_only = true;
    let out = tempfile::tempdir().unwrap();
    let summary = record(&o, out.path(), &|_| {}).unwrap();
    let (index, fields) = read_all(out.path());
    assert_eq!(index["encounters"]["only"], serde_json::json!(true));
    let listed = episode_ids(&index["encounters"]["episodes"]["furniture"]);
    let (_, stored) = stored_episodes(&fields);
    assert!(stored.len() >= 2, "{stored:?}");
    assert_eq!(stored, listed);
    // Furniture does not fit on every first leg: some episode numbers were skipped.
    assert!(
        stored.last().unwrap() + 1 > stored.len() as u32,
        "{stored:?}"
    );
    let every = RecordOptions {
        encounters_only: false,
        ..o.clone()
    };
    assert_ne!(every.dataset_id().unwrap(), summary.dataset_id);
    let refused = RecordOptions {
        encounters: 0.0,
        ..o.clone()
    };
    let err = refused.validate().unwrap_err().to_string();
    assert!(err.contains("encounters_only"), "{err}");
}

/// The episode ids `index.json` lists under `key` (`{probability, episodes}`).
fn listed_episodes(index: &serde_json::Value, key: &str) -> Vec<u32> {
    episode_ids(&index[key]["episodes"])
}

/// A JSON array of episode ids.
fn episode_ids(ids: &serde_json::Value) -> Vec<u32> {
    ids.as_array()
        .unwrap()
        .iter()
        .map(|e| e.as_u64().unwrap() as u32)
        .collect()
}

/// Each sample's episode id, and the stored episodes in order.
fn stored_episodes(fields: &BTreeMap<String, Vec<u8>>) -> (Vec<u32>, Vec<u32>) {
    let episodes = u32s(&fields["episode"]);
    let mut distinct = episodes.clone();
    distinct.dedup();
    (episodes, distinct)
}

/// How many of `distinct` have a sample `i` (of `episodes`) for which `sample(i)` holds.
fn episodes_with(episodes: &[u32], distinct: &[u32], sample: impl Fn(usize) -> bool) -> usize {
    distinct
        .iter()
        .filter(|e| (0..episodes.len()).any(|i| episodes[i] == **e && sample(i)))
        .count()
}

/// `wall_starts`: every episode starts facing its nearest wall 0.5–1.1 m away, and the
/// expert's first labels turn on the spot; the index lists the episodes, the option is part of
/// the dataset id, and a probability outside [0, 1] is refused.
#[test]
fn wall_starts_face_a_wall_and_the_expert_turns_on_the_spot() {
    let mut o = options(0.0, 2);
    o.scenarios = vec![scenario("train_office.yaml")];
    o.samples = 200;
    o.episode_s = 6.0;
    o.wall_starts = 1.0;
    let out = tempfile::tempdir().unwrap();
    let summary = record(&o, out.path(), &|_| {}).unwrap();
    let (index, fields) = read_all(out.path());
    assert_eq!(index["wall_starts"]["probability"], 1.0);
    let listed = listed_episodes(&index, "wall_starts");
    assert_eq!(listed, summary.wall_starts);
    let (episodes, distinct) = stored_episodes(&fields);
    assert!(distinct.len() >= 3, "{distinct:?}");
    assert_eq!(listed, distinct);

    let prepared =
        eval::table::run::Prepared::load(&scenario("train_office.yaml"), &o.run).unwrap();
    let walls = sim::raycast::WallGrid::from_grid(&prepared.plan);
    let pose = f32s(&fields["pose_true"]);
    let label = f32s(&fields["label"]);
    for e in &distinct {
        let first = episodes.iter().position(|x| x == e).unwrap();
        let (x, y, yaw) = (
            f64::from(pose[3 * first]),
            f64::from(pose[3 * first + 1]),
            f64::from(pose[3 * first + 2]),
        );
        // The nearest wall over these headings.
        let nearest = |headings: &mut dyn Iterator<Item = f64>| {
            headings
                .filter_map(|a| walls.cast(x, y, a.cos(), a.sin(), 3.0).map(|h| h.dist_m))
                .fold(f64::INFINITY, f64::min)
        };
        // Straight ahead (within the start's 0.3 rad and the first cycle's turn) a wall is
        // close, and no wall is closer than 0.5 m in any direction.
        let ahead = nearest(&mut (-5..=5).map(|k| yaw + f64::from(k) * 0.1));
        assert!(ahead <= 1.1 + 0.05, "episode {e}: wall {ahead} m ahead");
        let around = nearest(&mut (0..72).map(|k| f64::from(k) * std::f64::consts::TAU / 72.0));
        assert!(around >= 0.5 - 0.05, "episode {e}: wall {around} m away");
    }
    // The expert turns on the spot before it drives off: in the first second of most
    // episodes a label turns hard at walking pace or less.
    let t = f32s(&fields["t_s"]);
    let turning = episodes_with(&episodes, &distinct, |i| {
        t[i] <= 1.0 && label[2 * i].abs() < 0.3 && label[2 * i + 1].abs() > 0.3
    });
    assert!(
        2 * turning > distinct.len(),
        "{turning} of {}",
        distinct.len()
    );
    // The expert's target sets off at once where its command creeps up from rest: in the
    // first sample of each episode whose label moves, the target speed is well above it (a
    // network that cannot see the current speed learns the target, the agent ramps it).
    let target = f32s(&fields["target"]);
    let setting_off = distinct
        .iter()
        .filter_map(|e| (0..episodes.len()).find(|&i| episodes[i] == *e && label[2 * i] > 0.02))
        .collect::<Vec<_>>();
    let leading = setting_off
        .iter()
        .filter(|&&i| target[2 * i] >= label[2 * i] + 0.3)
        .count();
    assert!(
        3 * leading >= 2 * setting_off.len() && leading > 0,
        "the target led the label at {leading} of {} set-offs",
        setting_off.len()
    );

    let off = RecordOptions {
        wall_starts: 0.0,
        ..o.clone()
    };
    assert_ne!(off.dataset_id().unwrap(), summary.dataset_id);
    let err = RecordOptions {
        wall_starts: 1.5,
        ..o
    }
    .validate()
    .unwrap_err()
    .to_string();
    assert!(err.contains("wall_starts") && err.contains("1.5"), "{err}");
}

/// `eval record --goal-starts 1`: every episode starts next to its first goal with the goal
/// to the side or behind, so its DLM starts as a turn and the expert turns hard towards it
/// at walking pace; the index lists the episodes; the option is part of the dataset id and
/// checked, naming the field.
#[test]
fn goal_starts_begin_beside_the_first_goal_and_the_expert_turns_to_it() {
    let mut o = options(0.0, 2);
    o.scenarios = vec![scenario("train_office.yaml")];
    o.samples = 200;
    o.episode_s = 6.0;
    o.goal_starts = 1.0;
    let out = tempfile::tempdir().unwrap();
    let summary = record(&o, out.path(), &|_| {}).unwrap();
    let (index, fields) = read_all(out.path());
    assert_eq!(index["goal_starts"]["probability"], 1.0);
    assert!(index.get("wall_starts").is_none());
    let listed = listed_episodes(&index, "goal_starts");
    assert_eq!(listed, summary.goal_starts);
    let (episodes, distinct) = stored_episodes(&fields);
    assert!(distinct.len() >= 3, "{distinct:?}");
    assert_eq!(listed, distinct);
    let (label, dlm, t) = (f32s(&fields["label"]), &fields["dlm"], f32s(&fields["t_s"]));
    // The goal is 0.9 rad or more off the heading and at most 1.5 m away: the DLM of an
    // episode's first second is a turn (0 left, 1 right), and in its first 2 s the expert
    // turns hard (|ω| > 0.3 of the limit) at under half speed.
    let first_turns = episodes_with(&episodes, &distinct, |i| t[i] <= 1.0 && dlm[i] <= 1);
    assert!(
        2 * first_turns > distinct.len(),
        "{first_turns} of {}",
        distinct.len()
    );
    let turning = episodes_with(&episodes, &distinct, |i| {
        t[i] <= 2.0 && label[2 * i].abs() < 0.5 && label[2 * i + 1].abs() > 0.3
    });
    assert!(
        2 * turning > distinct.len(),
        "{turning} of {}",
        distinct.len()
    );

    let off = RecordOptions {
        goal_starts: 0.0,
        ..o.clone()
    };
    assert_ne!(off.dataset_id().unwrap(), summary.dataset_id);
    let err = RecordOptions {
        goal_starts: -0.1,
        ..o
    }
    .validate()
    .unwrap_err()
    .to_string();
    assert!(err.contains("goal_starts") && err.contains("-0.1"), "{err}");
}

/// `eval record --hairpin-starts 1` in a training maze: every stored episode starts behind a
/// thin wall from its first goal facing along the way round the wall's end, so the expert
/// drives off at once instead of turning on the spot; the index lists the episodes; the option is part of the dataset id and checked, naming the field.
#[test]
fn hairpin_starts_drive_round_a_wall_end_to_a_goal_behind_it() {
    let mut o = options(0.0, 2);
    o.scenarios = vec![scenario("train_maze_a.yaml")];
    o.samples = 240;
    o.episode_s = 6.0;
    o.hairpin_starts = 1.0;
    let out = tempfile::tempdir().unwrap();
    let summary = record(&o, out.path(), &|_| {}).unwrap();
    let (index, fields) = read_all(out.path());
    assert_eq!(index["hairpin_starts"]["probability"], 1.0);
    assert!(index.get("goal_starts").is_none());
    let listed = listed_episodes(&index, "hairpin_starts");
    assert_eq!(listed, summary.hairpin_starts);
    let (episodes, distinct) = stored_episodes(&fields);
    assert!(distinct.len() >= 3, "{distinct:?}");
    assert_eq!(listed, distinct);
    // In a hairpin the way starts along the wall, and the expert drives it at speed: in most
    // episodes its first 2 s hold a label above a third of the speed limit.
    let (label, t) = (f32s(&fields["label"]), f32s(&fields["t_s"]));
    let driving = episodes_with(&episodes, &distinct, |i| t[i] <= 2.0 && label[2 * i] > 0.33);
    assert!(
        2 * driving > distinct.len(),
        "{driving} of {}",
        distinct.len()
    );

    let off = RecordOptions {
        hairpin_starts: 0.0,
        ..o.clone()
    };
    assert_ne!(off.dataset_id().unwrap(), summary.dataset_id);
    let err = RecordOptions {
        hairpin_starts: 1.5,
        ..o
    }
    .validate()
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("hairpin_starts") && err.contains("1.5"),
        "{err}"
    );
}

/// `eval record --record-dir`: every stored episode also leaves its run log, named after the
/// samples' episode number, which replays through the agent's AMCL exactly as it ran; the
/// dataset is the same as without logs.
#[test]
fn the_command_line_records_a_run_log_per_episode() {
    let (out, logs) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let train_lab = scenario("train_lab.yaml");
    let status = Command::new(env!("CARGO_BIN_EXE_eval"))
        .args(["record", "--samples", "200", "--noise", "0", "--seed", "3"])
        .args(["--jobs", "2", "--image-px", "32", "--episode-s", "12"])
        .args(["--shard-samples", "128", "--scenario"])
        .arg(&train_lab)
        .arg("--record-dir")
        .arg(logs.path())
        .arg("--out")
        .arg(out.path())
        .status()
        .unwrap();
    assert!(status.success());

    let (_, fields) = read_all(out.path());
    let mut episodes = u32s(&fields["episode"]);
    episodes.dedup();
    assert!(episodes.len() >= 2, "episodes {episodes:?}");
    let names: Vec<String> = std::fs::read_dir(logs.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    for episode in &episodes {
        let prefix = format!("episode{episode:05}-train_lab-expert-seed");
        let name = names
            .iter()
            .find(|n| n.starts_with(&prefix) && n.ends_with(".mcap"))
            .unwrap_or_else(|| panic!("no log {prefix}*.mcap in {names:?}"));
        let log = fleet_log::RunLog::open(&logs.path().join(name)).unwrap();
        let summary = log.run_summary().unwrap();
        assert_eq!(summary.method, "expert");
        assert!(!log.ground_truth().is_empty());
        let config = robot_agent::replay::recorded_config(&log).unwrap();
        let plan = PathBuf::from(log.map().unwrap().path.clone().unwrap());
        assert_eq!(plan.file_name().unwrap(), "lab.yaml");
        let grid = map_core::ros::load_ros_map(&plan, &map_core::ImportLimits::default())
            .unwrap()
            .grid;
        let replayed = robot_agent::replay::replay(&log, &grid, &config).unwrap();
        assert_eq!(replayed.summary.max_live_difference_m, Some(0.0), "{name}");
    }

    // The logs change nothing in the dataset.
    let plain = tempfile::tempdir().unwrap();
    let mut o = options(0.0, 2);
    o.samples = 200;
    record(&o, plain.path(), &|_| {}).unwrap();
    assert_eq!(read_all(plain.path()).1, fields);
}

#[test]
fn a_recording_cut_by_its_wall_budget_is_the_recording_of_its_sample_count() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let mut o = options(0.5, 2);
    o.samples = 100_000;
    // Past the budget at once: the first batch of episodes runs, then the recording stops.
    o.max_wall_s = Some(1e-9);
    let cut = record(&o, a.path(), &|_| {}).unwrap();
    assert!(cut.samples > 0 && cut.samples < 100_000, "{}", cut.samples);
    o.max_wall_s = None;
    o.samples = cut.samples;
    let full = record(&o, b.path(), &|_| {}).unwrap();
    assert_eq!(full.samples, cut.samples);
    assert_eq!(full.dataset_id, cut.dataset_id);
    let (ia, fa) = read_all(a.path());
    let (ib, fb) = read_all(b.path());
    assert_eq!(ia["dataset_id"], ib["dataset_id"]);
    assert_eq!(ia["samples"], ib["samples"]);
    assert_eq!(ia["stopped_by_max_wall_s"], serde_json::json!(1e-9));
    assert!(ib.get("stopped_by_max_wall_s").is_none());
    assert_eq!(fa, fb);
    o.max_wall_s = Some(-1.0);
    let err = record(&o, b.path(), &|_| {}).unwrap_err().to_string();
    assert!(err.contains("max_wall_s") && err.contains("-1"), "{err}");
}
