//! Run logs written and read back: every topic round-trips typed, in time order, with its
//! stamp as `log_time`; every message validates against its channel's JSON schema; the file
//! appears only when finished; a file that is not MCAP is refused naming it.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::collections::BTreeMap;
use std::path::Path;

use fleet_log::{
    CompressedImage, InitialPose, LogError, LogMessage, LogOptions, LogWriter, MapInfo, Recorder,
    RunLog, RunSummary, StampedPose, Topic,
};
use protocol::{
    AgentState, AgentStatus, CameraFrame, CmdVel, ControllerKind, Dlm, Header, Image,
    ImageEncoding, Intention, LaserScan, MapName, MapRef, Odometry, Pose2D, PoseEstimate,
};

fn map_ref() -> MapRef {
    MapRef {
        name: MapName::new("junctions").unwrap(),
        version: 2,
    }
}

fn scan(seq: u64, stamp_ns: u64) -> LaserScan {
    LaserScan {
        header: Header::new(seq, stamp_ns),
        angle_min_rad: -1.5,
        angle_increment_rad: 0.01,
        range_min_m: 0.05,
        range_max_m: 10.0,
        // Values with no short decimal form: the JSON must carry them exactly.
        ranges_m: (0..300).map(|i| 0.1 + i as f32 / 7.0).collect(),
    }
}

fn odom(seq: u64, stamp_ns: u64) -> Odometry {
    Odometry {
        header: Header::new(seq, stamp_ns),
        pose: Pose2D::new(1.0 / 3.0, -2.0 / 7.0, 0.1),
        v_mps: 0.3,
        omega_radps: -0.05,
    }
}

fn rgb_frame(stamp_ns: u64) -> CameraFrame {
    let (w, h) = (32u32, 24u32);
    let data = (0..w * h * 3).map(|i| (i % 251) as u8).collect();
    CameraFrame {
        header: Header::new(1, stamp_ns),
        image: Image::new(w, h, ImageEncoding::Rgb8, data).unwrap(),
    }
}

/// One of everything, in the order an agent would process them (stamps not sorted).
fn messages() -> Vec<LogMessage> {
    let pose = PoseEstimate {
        header: Header::new(1, 100_000_000),
        pose: Pose2D::new(3.0, 4.0, 0.25),
        covariance: [0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.004],
        sensor_stamp_ns: 100_000_000,
        map: map_ref(),
        unmapped_obstacles_m: Vec::new(),
    };
    vec![
        LogMessage::Map(MapInfo {
            stamp_ns: 0,
            name: "junctions".into(),
            version: 2,
            path: Some("/maps/junctions.yaml".into()),
            content_hash: Some("ab".repeat(32)),
            initial_pose: Some(Pose2D::new(3.0, 4.0, 0.0)),
            initial_covariance: Some([0.0225, 0.0, 0.0, 0.0, 0.0225, 0.0, 0.0, 0.0, 0.01]),
            source: "test".into(),
        }),
        LogMessage::AgentConfig {
            stamp_ns: 0,
            config: serde_json::json!({"amcl": {"seed": 7}, "controller": "dynamic-window"}),
        },
        LogMessage::Odom(odom(1, 100_000_000)),
        LogMessage::Scan(scan(1, 100_000_000)),
        LogMessage::GroundTruth(StampedPose {
            header: Header::new(1, 100_000_000),
            pose: Pose2D::new(3.01, 4.0, 0.24),
        }),
        LogMessage::AmclPose(pose),
        LogMessage::Intention(Intention {
            header: Header::new(1, 100_000_000),
            task_id: Some("task_a".parse().unwrap()),
            goal_index: 0,
            answers_pose_seq: 1,
            answers_pose_stamp_ns: 100_000_000,
            map: map_ref(),
            path: vec![Pose2D::new(3.0, 4.0, 0.0), Pose2D::new(3.5, 4.0, 0.0)],
            dlm: Dlm::GoForward,
            arriving: false,
            lpe: None,
        }),
        LogMessage::CmdVel(CmdVel {
            header: Header::new(1, 100_000_000),
            v_mps: 0.2,
            omega_radps: 0.1,
        }),
        // The dynamic window drives in the DLM-Net's place.
        LogMessage::AgentStatus(AgentStatus {
            header: Header::new(1, 100_000_000),
            state: AgentState::Driving,
            stop_reason: None,
            controller: ControllerKind::Dlm,
            map: Some(map_ref()),
            localized: true,
            recovering: true,
            backing_up: false,
            rotating_in_place: false,
            giving_way: false,
        }),
        // A late odometry reading with an older stamp: read back in time order before the scan.
        LogMessage::Odom(odom(0, 50_000_000)),
        LogMessage::InitialPose(InitialPose {
            header: Header::new(1, 200_000_000),
            pose: Pose2D::new(5.0, 4.0, 0.0),
            covariance: [0.0225, 0.0, 0.0, 0.0, 0.0225, 0.0, 0.0, 0.0, 0.01],
        }),
        LogMessage::Odom(odom(2, 200_000_000)),
        LogMessage::RunSummary(RunSummary {
            stamp_ns: 200_000_000,
            scenario: "task_a".into(),
            method: "dynamic-window".into(),
            seed: 1,
            success: false,
            goals_reached: 1,
            goals_total: 4,
            collisions: 0,
            interventions: 1,
            time_s: 0.2,
        }),
    ]
}

fn write_all(path: &Path, messages: &[LogMessage], options: LogOptions) {
    let mut writer = LogWriter::create(path, options).unwrap();
    for m in messages {
        writer.write(m).unwrap();
    }
    writer.finish().unwrap();
}

#[test]
fn every_topic_round_trips_in_time_order_with_its_stamp() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sub/run.mcap");
    let written = messages();
    write_all(&path, &written, LogOptions::default());

    let log = RunLog::open(&path).unwrap();
    // File order is the order written, message for message.
    let recorded: Vec<LogMessage> = log
        .as_recorded()
        .iter()
        .map(|e| e.message.clone())
        .collect();
    assert_eq!(recorded, written);
    for e in log.as_recorded() {
        assert_eq!(e.log_time_ns, e.message.stamp_ns(), "{e:?}");
    }
    // Time order: sorted, ties in recorded order.
    let sorted: Vec<&LogMessage> = log.messages().iter().map(|e| &e.message).collect();
    let stamps: Vec<u64> = sorted.iter().map(|m| m.stamp_ns()).collect();
    assert!(stamps.windows(2).all(|w| w[0] <= w[1]), "{stamps:?}");
    assert!(matches!(sorted[0], LogMessage::Map(_)));
    assert!(matches!(sorted[2], LogMessage::Odom(o) if o.header.seq == 0));
    assert!(matches!(sorted[3], LogMessage::Odom(o) if o.header.seq == 1));

    let counts = log.counts();
    assert_eq!(counts[&Topic::Odom], 3);
    assert_eq!(counts[&Topic::Scan], 1);
    assert!(!counts.contains_key(&Topic::Camera));
    assert_eq!(log.map().unwrap().name, "junctions");
    assert_eq!(log.agent_config().unwrap()["amcl"]["seed"], 7);
    assert_eq!(log.run_summary().unwrap().interventions, 1);
    assert_eq!(log.ground_truth().len(), 1);
    assert_eq!(counts[&Topic::AgentStatus], 1);
    assert!(log.agent_statuses()[0].recovering);
    assert!(log.unknown_topics().is_empty());

    // The channels as any MCAP reader sees them: json messages with a jsonschema each.
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let mut topics: BTreeMap<String, (String, String, String)> = BTreeMap::new();
    for channel in summary.channels.values() {
        let schema = channel.schema.as_ref().unwrap();
        topics.insert(
            channel.topic.clone(),
            (
                channel.message_encoding.clone(),
                schema.encoding.clone(),
                schema.name.clone(),
            ),
        );
    }
    assert_eq!(topics.len(), 11, "{topics:?}");
    assert_eq!(
        topics["/scan"],
        ("json".into(), "jsonschema".into(), "fleet.LaserScan".into())
    );
    let stats = summary.stats.unwrap();
    assert_eq!(stats.message_count, written.len() as u64);
    assert_eq!(stats.message_start_time, 0);
    assert_eq!(stats.message_end_time, 200_000_000);
}

#[test]
fn every_message_matches_its_channel_schema() {
    let mut all = messages();
    all.push(LogMessage::Camera(
        CompressedImage::from_frame(&rgb_frame(5), 80).unwrap(),
    ));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    write_all(&path, &all, LogOptions::default());
    let bytes = std::fs::read(&path).unwrap();
    let mut checked = BTreeMap::new();
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        let schema = message.channel.schema.as_ref().unwrap();
        let schema: serde_json::Value = serde_json::from_slice(&schema.data).unwrap();
        let validator = jsonschema::validator_for(&schema).unwrap();
        let instance: serde_json::Value = serde_json::from_slice(&message.data).unwrap();
        let errors: Vec<String> = validator
            .iter_errors(&instance)
            .map(|e| e.to_string())
            .collect();
        assert!(errors.is_empty(), "{}: {errors:?}", message.channel.topic);
        *checked
            .entry(message.channel.topic.clone())
            .or_insert(0usize) += 1;
    }
    assert_eq!(checked.len(), Topic::ALL.len(), "{checked:?}");
    // And a message that breaks the schema is caught by it.
    let schema = Topic::Odom.schema();
    let validator = jsonschema::validator_for(&schema).unwrap();
    assert!(!validator.is_valid(&serde_json::json!({"header": {"seq": 1}})));
}

#[test]
fn camera_frames_are_jpeg_only_when_asked_and_decode_back() {
    let dir = tempfile::tempdir().unwrap();
    let off = dir.path().join("off.mcap");
    let mut writer = LogWriter::create(&off, LogOptions::default()).unwrap();
    writer.camera(&rgb_frame(7)).unwrap();
    writer.finish().unwrap();
    assert!(RunLog::open(&off).unwrap().as_recorded().is_empty());

    let on = dir.path().join("on.mcap");
    let options = LogOptions {
        camera: true,
        ..LogOptions::default()
    };
    let mut writer = LogWriter::create(&on, options).unwrap();
    writer.camera(&rgb_frame(1_500_000_007)).unwrap();
    writer.finish().unwrap();
    let log = RunLog::open(&on).unwrap();
    let [entry] = log.as_recorded() else {
        panic!("one frame expected: {:?}", log.counts())
    };
    assert_eq!(entry.log_time_ns, 1_500_000_007);
    let LogMessage::Camera(image) = &entry.message else {
        panic!("{entry:?}")
    };
    assert_eq!(image.format, "jpeg");
    assert_eq!(
        (image.timestamp.sec, image.timestamp.nsec),
        (1, 500_000_007)
    );
    let decoded = image::load_from_memory(&image.bytes().unwrap()).unwrap();
    assert_eq!((decoded.width(), decoded.height()), (32, 24));
}

#[test]
fn the_file_appears_only_when_finished() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let partial = fleet_log::partial_path(&path);
    assert_eq!(partial, dir.path().join("run.mcap.partial"));
    let mut writer = LogWriter::create(&path, LogOptions::default()).unwrap();
    writer.odom(&odom(1, 1)).unwrap();
    assert!(partial.is_file() && !path.exists());
    // A reader of the unfinished file says what is wrong with it, naming it.
    let err = RunLog::open(&partial).unwrap_err();
    assert!(
        matches!(err, LogError::Mcap { .. }),
        "{err}: an unfinished log is a broken MCAP"
    );
    assert!(err.to_string().contains("run.mcap.partial"), "{err}");
    writer.finish().unwrap();
    assert!(path.is_file() && !partial.exists());
    assert_eq!(RunLog::open(&path).unwrap().as_recorded().len(), 1);

    // Truncated: the end is missing.
    let bytes = std::fs::read(&path).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let err = RunLog::open(&cut).unwrap_err();
    assert!(err.to_string().contains("cut.mcap"), "{err}");
}

#[test]
fn a_file_that_is_not_mcap_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("poses.csv");
    std::fs::write(&csv, "stamp_ns,x_m,y_m\n1,2,3\n").unwrap();
    let err = RunLog::open(&csv).unwrap_err();
    assert!(matches!(err, LogError::NotMcap { .. }), "{err:?}");
    let text = err.to_string();
    assert!(
        text.contains("poses.csv") && text.contains("not an MCAP file"),
        "{text}"
    );
    let empty = dir.path().join("empty.mcap");
    std::fs::write(&empty, "").unwrap();
    let text = RunLog::open(&empty).unwrap_err().to_string();
    assert!(
        text.contains("empty.mcap") && text.contains("empty"),
        "{text}"
    );
    let missing = dir.path().join("missing.mcap");
    let text = RunLog::open(&missing).unwrap_err().to_string();
    assert!(
        text.contains("missing.mcap") && text.contains("cannot read"),
        "{text}"
    );
}

#[test]
fn the_recorder_thread_keeps_the_order_and_finishes_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("live.mcap");
    let mut recorder = Recorder::start(
        &path,
        LogOptions {
            camera: true,
            ..LogOptions::default()
        },
    )
    .unwrap();
    for i in 0..200u64 {
        recorder.record(LogMessage::Odom(odom(i, 1_000 * (200 - i))));
        if i % 20 == 0 {
            recorder.record_camera(&rgb_frame(i));
        }
    }
    assert_eq!(recorder.finish().unwrap(), path);
    let log = RunLog::open(&path).unwrap();
    let seqs: Vec<u64> = log
        .as_recorded()
        .iter()
        .filter_map(|e| match &e.message {
            LogMessage::Odom(o) => Some(o.header.seq),
            _ => None,
        })
        .collect();
    assert_eq!(seqs, (0..200).collect::<Vec<_>>());
    assert_eq!(log.counts()[&Topic::Camera], 10);
    // A recorder dropped without finish still leaves a complete file.
    let dropped = dir.path().join("dropped.mcap");
    {
        let mut r = Recorder::start(&dropped, LogOptions::default()).unwrap();
        r.record(LogMessage::Odom(odom(1, 1)));
    }
    assert_eq!(RunLog::open(&dropped).unwrap().as_recorded().len(), 1);
    // A folder that cannot be created is an error at start, naming it.
    let blocker = dir.path().join("file");
    std::fs::write(&blocker, "x").unwrap();
    let err = Recorder::start(&blocker.join("x.mcap"), LogOptions::default()).unwrap_err();
    assert!(err.to_string().contains("file"), "{err}");
}
