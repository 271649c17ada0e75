//! Round trips of every message kind through the codec, and the receiver's rejections.

// Fixture helpers outside #[test] fns are test code too; a panic is the right failure there.
#![allow(clippy::unwrap_used)]

use std::f64::consts::PI;
use std::io::Cursor;

use protocol::codec::{peek_kind, FRAME_MAGIC, FRAME_PREFIX_LEN};
use protocol::{
    decode, encode, AgentState, AgentStatus, CameraFrame, CmdVel, ControllerKind, DecodeError, Dlm,
    EncodeError, Header, Image, ImageEncoding, Intention, LaserScan, MapGrid, MapId, MapMeta,
    MapName, MapRef, Odometry, Pose2D, PoseEstimate, RobotId, StopReason, TaskEvent, TaskId,
    TaskState, WireMessage, UNKNOWN_CELL, WIRE_VERSION,
};

fn header(seq: u64) -> Header {
    Header::new(seq, 1_723_456_789_123_456_789 + seq * 100_000_000)
}

fn map_ref() -> MapRef {
    MapRef {
        name: MapName::new("office_3f").unwrap(),
        version: 4,
    }
}

fn scan() -> LaserScan {
    // 181 beams over 180 degrees, 1 degree apart, some without return.
    let ranges_m = (0..181)
        .map(|i| {
            if i % 17 == 0 {
                30.0
            } else {
                0.5 + (i as f32 * 0.731).sin().abs() * 12.0
            }
        })
        .collect();
    LaserScan {
        header: header(1),
        angle_min_rad: -std::f32::consts::FRAC_PI_2,
        angle_increment_rad: std::f32::consts::PI / 180.0,
        range_min_m: 0.05,
        range_max_m: 30.0,
        ranges_m,
    }
}

fn odom() -> Odometry {
    Odometry {
        header: header(2),
        pose: Pose2D::new(12.345_678_901, -3.210_987_654_3, 1.234_567_890_123),
        v_mps: 0.4817,
        omega_radps: -0.1234,
    }
}

fn cmd_vel() -> CmdVel {
    CmdVel {
        header: header(3),
        v_mps: 0.5,
        omega_radps: -0.25,
    }
}

fn pose() -> PoseEstimate {
    PoseEstimate {
        header: header(4),
        pose: Pose2D::new(5.123_456_789, 7.987_654_321, -2.8),
        covariance: [0.0123, 0.001, 0.0, 0.001, 0.0234, 0.0, 0.0, 0.0, 0.0031],
        sensor_stamp_ns: 1_723_456_789_100_000_000,
        map: map_ref(),
        unmapped_obstacles_m: Vec::new(),
    }
}

fn rgb_bytes(w: u32, h: u32) -> Vec<u8> {
    (0..w * h * 3)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect()
}

fn camera() -> CameraFrame {
    CameraFrame {
        header: header(5),
        image: Image::new(224, 224, ImageEncoding::Rgb8, rgb_bytes(224, 224)).unwrap(),
    }
}

fn png_bytes() -> Vec<u8> {
    let img = image::RgbImage::from_fn(224, 224, |x, y| {
        if (x as i32 - 112).abs() < 3 && y > 112 {
            image::Rgb([255, 0, 0])
        } else if (x as i32 - 112).abs() < 3 {
            image::Rgb([0, 0, 255])
        } else {
            image::Rgb([200, 200, 200])
        }
    });
    let mut out = Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

fn intention(lpe: Option<Image>) -> Intention {
    Intention {
        header: header(6),
        task_id: Some(TaskId::new("task-0001").unwrap()),
        goal_index: 2,
        answers_pose_seq: 4,
        answers_pose_stamp_ns: 1_723_456_789_523_456_789,
        map: map_ref(),
        path: (0..50)
            .map(|i| {
                Pose2D::new(
                    5.0 + 0.1 * i as f64,
                    7.0 + 0.01 * (i * i) as f64,
                    0.02 * i as f64,
                )
            })
            .collect(),
        dlm: Dlm::TurnLeft,
        arriving: false,
        lpe,
    }
}

fn status() -> AgentStatus {
    AgentStatus {
        header: header(7),
        state: AgentState::Stopping,
        stop_reason: Some(StopReason::StaleIntention { age_ms: 640 }),
        controller: ControllerKind::Dlm,
        map: Some(map_ref()),
        localized: true,
        recovering: false,
        backing_up: false,
        rotating_in_place: false,
        giving_way: false,
    }
}

fn task_event() -> TaskEvent {
    TaskEvent {
        header: header(8),
        task_id: TaskId::new("task-0001").unwrap(),
        map: MapName::new("office_3f").unwrap(),
        state: TaskState::Active {
            robot_id: RobotId::new("robot_1").unwrap(),
            goal_index: 1,
        },
        goal_count: 3,
    }
}

fn map_meta() -> MapMeta {
    let name = MapName::new("office_3f").unwrap();
    let hash = "9f86d081884c7d659a2feaa0c55ad015a3bf4f1b2b0b822cd15d6c15b0f00a08";
    MapMeta {
        id: MapId::from_name_and_hash(&name, hash).unwrap(),
        name,
        version: 4,
        content_hash: hash.into(),
        width_cells: 10,
        height_cells: 10,
        resolution_m: 0.05,
        origin: Pose2D::new(-10.0, -5.5, 0.0),
        free_cells: 64,
        occupied_cells: 36,
        unknown_cells: 0,
        created_ns: 1_723_000_000_000_000_000,
    }
}

fn map_grid() -> MapGrid {
    let cells = (0..100u32)
        .map(|i| {
            let (x, y) = (i % 10, i / 10);
            if x == 0 || y == 0 || x == 9 || y == 9 {
                100
            } else if x == 5 && y == 5 {
                UNKNOWN_CELL
            } else {
                (i % 3) as u8
            }
        })
        .collect();
    MapGrid {
        meta: map_meta(),
        cells,
    }
}

fn round_trip<M: WireMessage + PartialEq + std::fmt::Debug>(msg: &M) -> Vec<u8> {
    let bytes = encode(msg).unwrap();
    let back: M = decode(&bytes).unwrap();
    assert_eq!(&back, msg, "{} did not round-trip", M::KIND);
    assert_eq!(
        peek_kind(&bytes).unwrap(),
        (WIRE_VERSION, M::KIND.to_string())
    );
    bytes
}

#[test]
fn json_kinds_round_trip_as_json_envelopes() {
    let all = [
        round_trip(&scan()),
        round_trip(&odom()),
        round_trip(&cmd_vel()),
        round_trip(&pose()),
        round_trip(&status()),
        round_trip(&task_event()),
        round_trip(&map_meta()),
    ];
    let kinds = [
        "scan",
        "odom",
        "cmd_vel",
        "pose",
        "status",
        "task_event",
        "map_meta",
    ];
    for (bytes, kind) in all.iter().zip(kinds) {
        let v: serde_json::Value = serde_json::from_slice(bytes).unwrap();
        assert_eq!(v["wire_version"], 1);
        assert_eq!(v["kind"], kind);
        assert!(v["msg"].is_object());
        assert_eq!(v.as_object().unwrap().len(), 3);
    }
}

#[test]
fn every_status_and_task_state_round_trips() {
    for reason in [
        None,
        Some(StopReason::NoIntention),
        Some(StopReason::StaleIntention { age_ms: 0 }),
        Some(StopReason::LocalizationLost {
            position_std_m: 1.75,
        }),
        Some(StopReason::ControllerError {
            message: "onnx: shape mismatch".into(),
        }),
        Some(StopReason::GoalReached),
        Some(StopReason::Collision),
        Some(StopReason::Commanded),
    ] {
        for state in [
            AgentState::Starting,
            AgentState::Idle,
            AgentState::Driving,
            AgentState::Stopping,
            AgentState::Stopped,
            AgentState::Relocalizing,
        ] {
            round_trip(&AgentStatus {
                state,
                stop_reason: reason.clone(),
                map: None,
                recovering: state == AgentState::Driving,
                backing_up: false,
                rotating_in_place: state == AgentState::Driving,
                giving_way: state == AgentState::Driving,
                ..status()
            });
        }
    }
    let robot_id = RobotId::new("r-2.b").unwrap();
    for state in [
        TaskState::Queued,
        TaskState::Assigned {
            robot_id: robot_id.clone(),
        },
        TaskState::Active {
            robot_id: robot_id.clone(),
            goal_index: 0,
        },
        TaskState::Paused {
            robot_id,
            goal_index: 1,
            reason: "robot went offline".into(),
        },
        TaskState::Completed,
        TaskState::Failed {
            reason: "goal 2 is inside a wall".into(),
        },
        TaskState::Cancelled,
    ] {
        round_trip(&TaskEvent {
            state,
            ..task_event()
        });
    }
    for dlm in Dlm::ALL {
        round_trip(&Intention {
            dlm,
            arriving: false,
            task_id: None,
            ..intention(None)
        });
    }
}

#[test]
fn json_uses_unit_suffixed_field_names() {
    let text = String::from_utf8(encode(&cmd_vel()).unwrap()).unwrap();
    assert!(text.contains("\"v_mps\":0.5"), "{text}");
    assert!(text.contains("\"omega_radps\":-0.25"), "{text}");
    assert!(text.contains("\"stamp_ns\""), "{text}");
    let text = String::from_utf8(encode(&pose()).unwrap()).unwrap();
    for field in ["\"x_m\"", "\"y_m\"", "\"yaw_rad\"", "\"sensor_stamp_ns\""] {
        assert!(text.contains(field), "{field} missing in {text}");
    }
    let text = String::from_utf8(encode(&scan()).unwrap()).unwrap();
    for field in [
        "\"angle_min_rad\"",
        "\"angle_increment_rad\"",
        "\"range_max_m\"",
        "\"ranges_m\"",
    ] {
        assert!(text.contains(field), "{field} missing in {text}");
    }
}

/// Splits a frame into (JSON header, blob) for inspection.
fn frame_parts(bytes: &[u8]) -> (serde_json::Value, &[u8]) {
    assert_eq!(&bytes[..4], &FRAME_MAGIC);
    assert_eq!(u16::from_le_bytes([bytes[4], bytes[5]]), WIRE_VERSION);
    let h = u32::from_le_bytes([bytes[6], bytes[7], bytes[8], bytes[9]]) as usize;
    let header = serde_json::from_slice(&bytes[FRAME_PREFIX_LEN..FRAME_PREFIX_LEN + h]).unwrap();
    (header, &bytes[FRAME_PREFIX_LEN + h..])
}

#[test]
fn camera_frame_round_trips_with_raw_blob() {
    let frame = camera();
    let bytes = round_trip(&frame);
    let (header, blob) = frame_parts(&bytes);
    assert_eq!(header["kind"], "camera");
    assert_eq!(header["blob_len"], 224 * 224 * 3);
    assert_eq!(blob, frame.image.data.as_slice());
    // The pixels are not in the JSON: the header stays small.
    assert!(
        bytes.len() - blob.len() < 200,
        "header is {} bytes",
        bytes.len() - blob.len()
    );
    assert!(header["msg"]["image"].get("data").is_none());
}

#[test]
fn intention_round_trips_with_and_without_lpe() {
    let without = intention(None);
    let bytes = round_trip(&without);
    let (header, blob) = frame_parts(&bytes);
    assert_eq!(header["kind"], "intention");
    assert_eq!(header["blob_len"], 0);
    assert!(blob.is_empty());
    assert!(header["msg"]["lpe"].is_null());

    let png = png_bytes();
    let with = intention(Some(
        Image::new(224, 224, ImageEncoding::Png, png.clone()).unwrap(),
    ));
    let bytes = round_trip(&with);
    let (header, blob) = frame_parts(&bytes);
    assert_eq!(blob, png.as_slice());
    assert_eq!(header["msg"]["lpe"]["encoding"], "png");
    assert_eq!(header["msg"]["lpe"]["width_px"], 224);
    assert_eq!(header["msg"]["dlm"], "turn_left");
    let back: Intention = decode(&bytes).unwrap();
    let decoded = image::load_from_memory(&back.lpe.unwrap().data)
        .unwrap()
        .to_rgb8();
    assert_eq!(decoded.dimensions(), (224, 224));
    assert_eq!(decoded.get_pixel(112, 200), &image::Rgb([255, 0, 0]));
}

#[test]
fn an_arriving_stop_drives_and_a_plain_stop_rests() {
    let arriving = Intention {
        dlm: Dlm::Stop,
        arriving: true,
        ..intention(None)
    };
    assert!(!arriving.rests() && !arriving.stops());
    let back: Intention = decode(&round_trip(&arriving)).unwrap();
    assert!(back.arriving);
    let stop = Intention {
        arriving: false,
        ..arriving.clone()
    };
    assert!(stop.rests() && stop.stops());
    let no_task = Intention {
        task_id: None,
        dlm: Dlm::GoForward,
        ..stop.clone()
    };
    assert!(no_task.rests() && !no_task.stops());
    // A planner from before the field: no `arriving` on the wire reads as false.
    let mut json = serde_json::to_value(&stop).unwrap();
    json.as_object_mut().unwrap().remove("arriving");
    let old: Intention = serde_json::from_value(json).unwrap();
    assert!(!old.arriving && old.rests());
}

#[test]
fn map_grid_round_trips_with_cells_as_blob() {
    let grid = map_grid();
    let bytes = round_trip(&grid);
    let (header, blob) = frame_parts(&bytes);
    assert_eq!(header["kind"], "map_grid");
    assert_eq!(blob, grid.cells.as_slice());
    assert_eq!(header["msg"]["meta"]["id"], "office_3f-9f86d081884c");
    assert!(header["msg"].get("cells").is_none());
}

#[test]
fn floats_round_trip_exactly() {
    let mut p = pose();
    for i in 0..500 {
        let t = f64::from(i) * 0.123_456_789_012_345_67 + 1e-7;
        p.pose = Pose2D::new(t * 37.1, -t / 3.0, protocol::normalize_angle(t * PI));
        p.covariance[0] = t * 1e-5;
        round_trip(&p);
    }
}

/// Rewrites the wire version in the frame prefix only.
fn with_frame_version(bytes: &[u8], version: u16) -> Vec<u8> {
    let mut out = bytes.to_vec();
    out[4..6].copy_from_slice(&version.to_le_bytes());
    out
}

/// Replaces the first occurrence of `from` by the same-length `to`.
fn replace_bytes(bytes: &[u8], from: &[u8], to: &[u8]) -> Vec<u8> {
    assert_eq!(from.len(), to.len());
    let at = bytes.windows(from.len()).position(|w| w == from).unwrap();
    let mut out = bytes.to_vec();
    out[at..at + to.len()].copy_from_slice(to);
    out
}

#[test]
fn unknown_wire_version_is_rejected_with_reason() {
    let framed = with_frame_version(&encode(&camera()).unwrap(), 2);
    let err = decode::<CameraFrame>(&framed).unwrap_err();
    assert!(
        matches!(
            err,
            DecodeError::UnsupportedVersion {
                got: 2,
                supported: 1
            }
        ),
        "{err:?}"
    );
    assert_eq!(
        err.to_string(),
        "unsupported wire version 2 (this build speaks 1)"
    );

    let json = String::from_utf8(encode(&cmd_vel()).unwrap())
        .unwrap()
        .replace("\"wire_version\":1", "\"wire_version\":2");
    let err = decode::<CmdVel>(json.as_bytes()).unwrap_err();
    assert!(
        matches!(
            err,
            DecodeError::UnsupportedVersion {
                got: 2,
                supported: 1
            }
        ),
        "{err:?}"
    );

    let seven = String::from_utf8(encode(&status()).unwrap())
        .unwrap()
        .replace("\"wire_version\":1", "\"wire_version\":7");
    let err = decode::<AgentStatus>(seven.as_bytes()).unwrap_err();
    assert_eq!(
        err.to_string(),
        "unsupported wire version 7 (this build speaks 1)"
    );

    // A future version may change the whole envelope; the version is still what gets reported.
    let future = br#"{"wire_version":2,"type":"cmd_vel","payload":[1,2]}"#;
    assert!(matches!(
        decode::<CmdVel>(future),
        Err(DecodeError::UnsupportedVersion { got: 2, .. })
    ));
    let mut future_frame = with_frame_version(&encode(&map_grid()).unwrap(), 2);
    future_frame.truncate(FRAME_PREFIX_LEN);
    assert!(matches!(
        decode::<MapGrid>(&future_frame),
        Err(DecodeError::UnsupportedVersion { got: 2, .. })
    ));
    assert!(peek_kind(&framed).is_err());

    // Frame prefix says 1 but the header inside disagrees.
    let bytes = encode(&intention(None)).unwrap();
    let text = replace_bytes(&bytes, b"\"wire_version\":1", b"\"wire_version\":3");
    assert!(matches!(
        decode::<Intention>(&text),
        Err(DecodeError::UnsupportedVersion { got: 3, .. })
    ));
}

#[test]
fn wrong_kind_is_rejected() {
    let err = decode::<CmdVel>(&encode(&odom()).unwrap()).unwrap_err();
    assert!(
        matches!(&err, DecodeError::WrongKind { expected: "cmd_vel", got } if got == "odom"),
        "{err:?}"
    );
    assert_eq!(
        err.to_string(),
        "wrong message kind: expected cmd_vel, got \"odom\""
    );
    let err = decode::<Intention>(&encode(&camera()).unwrap()).unwrap_err();
    assert!(
        matches!(
            err,
            DecodeError::WrongKind {
                expected: "intention",
                ..
            }
        ),
        "{err:?}"
    );
    let err = decode::<CameraFrame>(&encode(&pose()).unwrap()).unwrap_err();
    assert!(
        matches!(
            err,
            DecodeError::WrongKind {
                expected: "camera",
                ..
            }
        ),
        "{err:?}"
    );
}

#[test]
fn truncated_frames_are_rejected() {
    let bytes = encode(&camera()).unwrap();
    let full = bytes.len();
    for cut in [1, 3, 4, 9] {
        let err = decode::<CameraFrame>(&bytes[..cut]).unwrap_err();
        assert!(
            matches!(err, DecodeError::Truncated { needed: FRAME_PREFIX_LEN, got } if got == cut),
            "cut {cut}: {err:?}"
        );
    }
    // Inside the JSON header.
    let err = decode::<CameraFrame>(&bytes[..20]).unwrap_err();
    assert!(
        matches!(err, DecodeError::Truncated { got: 20, .. }),
        "{err:?}"
    );
    // Inside the blob: the needed size is the whole frame.
    let err = decode::<CameraFrame>(&bytes[..full - 1]).unwrap_err();
    assert!(
        matches!(err, DecodeError::Truncated { needed, got } if needed == full && got == full - 1),
        "{err:?}"
    );
    assert!(err.to_string().contains(&full.to_string()));
    let err = decode::<CameraFrame>(&[]).unwrap_err();
    assert!(
        matches!(err, DecodeError::Truncated { got: 0, .. }),
        "{err:?}"
    );
    // Trailing garbage after the blob is not silently ignored.
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(matches!(
        decode::<CameraFrame>(&longer),
        Err(DecodeError::Invalid {
            field: "blob_len",
            ..
        })
    ));
    // A JSON envelope cut short is malformed JSON.
    let json = encode(&scan()).unwrap();
    assert!(matches!(
        decode::<LaserScan>(&json[..json.len() / 2]),
        Err(DecodeError::Json(_))
    ));
}

#[test]
fn bad_magic_is_rejected() {
    let mut bytes = encode(&camera()).unwrap();
    bytes[0] = b'X';
    assert!(matches!(
        decode::<CameraFrame>(&bytes),
        Err(DecodeError::BadMagic)
    ));
    assert!(matches!(
        decode::<CmdVel>(b"\x00\x01\x02\x03garbage"),
        Err(DecodeError::BadMagic)
    ));
    assert!(matches!(
        decode::<CmdVel>(b"[1,2,3]"),
        Err(DecodeError::BadMagic)
    ));
}

#[test]
fn framing_must_match_the_kind() {
    // A camera frame sent as plain JSON (as if someone base64-ed the pixels) is refused.
    let json = br#"{"wire_version":1,"kind":"camera","msg":{"header":{"seq":1,"stamp_ns":2},"image":{"width_px":1,"height_px":1,"encoding":"rgb8"}}}"#;
    let err = decode::<CameraFrame>(json).unwrap_err();
    assert!(
        matches!(
            err,
            DecodeError::Invalid {
                field: "framing",
                ..
            }
        ),
        "{err:?}"
    );
    // And a JSON kind inside a frame too.
    let header = br#"{"wire_version":1,"kind":"cmd_vel","blob_len":0,"msg":{"header":{"seq":1,"stamp_ns":2},"v_mps":0.0,"omega_radps":0.0}}"#;
    let mut frame = FRAME_MAGIC.to_vec();
    frame.extend_from_slice(&WIRE_VERSION.to_le_bytes());
    frame.extend_from_slice(&(header.len() as u32).to_le_bytes());
    frame.extend_from_slice(header);
    let err = decode::<CmdVel>(&frame).unwrap_err();
    assert!(
        matches!(
            err,
            DecodeError::Invalid {
                field: "framing",
                ..
            }
        ),
        "{err:?}"
    );
}

/// Builds a frame by hand from a JSON header and a blob.
fn frame(header: &serde_json::Value, blob: &[u8]) -> Vec<u8> {
    let header = serde_json::to_vec(header).unwrap();
    let mut out = FRAME_MAGIC.to_vec();
    out.extend_from_slice(&WIRE_VERSION.to_le_bytes());
    out.extend_from_slice(&(header.len() as u32).to_le_bytes());
    out.extend_from_slice(&header);
    out.extend_from_slice(blob);
    out
}

#[test]
fn image_length_mismatch_is_rejected() {
    let bytes = encode(&camera()).unwrap();
    let (mut header, blob) = frame_parts(&bytes);
    let short = &blob[..blob.len() - 3];
    header["blob_len"] = serde_json::json!(short.len());
    let err = decode::<CameraFrame>(&frame(&header, short)).unwrap_err();
    assert!(
        matches!(
            &err,
            DecodeError::Invalid {
                field: "image.data",
                ..
            }
        ),
        "{err:?}"
    );
    assert!(err.to_string().contains("150528"), "{err}");

    // The sender is stopped too.
    let mut bad = camera();
    bad.image.data.pop();
    let err = encode(&bad).unwrap_err();
    assert!(
        matches!(err, EncodeError::Invalid { kind: "camera", .. }),
        "{err:?}"
    );

    // An LPE said to be PNG that is not.
    let mut lpe = intention(Some(
        Image::new(224, 224, ImageEncoding::Png, png_bytes()).unwrap(),
    ));
    let bytes = encode(&lpe).unwrap();
    let (header, _) = frame_parts(&bytes);
    let err = decode::<Intention>(&frame(
        &header,
        &vec![0u8; header["blob_len"].as_u64().unwrap() as usize],
    ))
    .unwrap_err();
    assert!(
        matches!(
            err,
            DecodeError::Invalid {
                field: "image.data",
                ..
            }
        ),
        "{err:?}"
    );
    // Blob bytes without an LPE description.
    lpe.lpe = None;
    let (mut header, _) = frame_parts(&encode(&lpe).unwrap());
    header["blob_len"] = serde_json::json!(4);
    let err = decode::<Intention>(&frame(&header, &[1, 2, 3, 4])).unwrap_err();
    assert!(
        matches!(err, DecodeError::Invalid { field: "lpe", .. }),
        "{err:?}"
    );
}

#[test]
fn grid_length_mismatch_is_rejected() {
    let bytes = encode(&map_grid()).unwrap();
    let (mut header, blob) = frame_parts(&bytes);
    header["blob_len"] = serde_json::json!(99);
    let err = decode::<MapGrid>(&frame(&header, &blob[..99])).unwrap_err();
    assert!(
        matches!(&err, DecodeError::Invalid { field: "cells", .. }),
        "{err:?}"
    );
    assert!(err.to_string().contains("10x10"), "{err}");
    let mut bad = map_grid();
    bad.cells.push(0);
    assert!(matches!(
        encode(&bad),
        Err(EncodeError::Invalid {
            kind: "map_grid",
            ..
        })
    ));
}

#[test]
fn unencodable_values_are_refused_at_the_sender() {
    let mut s = scan();
    s.ranges_m[10] = f32::INFINITY;
    let err = encode(&s).unwrap_err();
    assert!(err.to_string().contains("ranges_m"), "{err}");
    let mut c = cmd_vel();
    c.v_mps = f64::NAN;
    assert!(matches!(
        encode(&c),
        Err(EncodeError::Invalid {
            kind: "cmd_vel",
            ..
        })
    ));
}

#[test]
fn invalid_ids_inside_messages_are_rejected() {
    let text = String::from_utf8(encode(&task_event()).unwrap())
        .unwrap()
        .replace("\"robot_1\"", "\"robot/1\"");
    let err = decode::<TaskEvent>(text.as_bytes()).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, DecodeError::Json(_)), "{err:?}");
    assert!(msg.contains("robot_id") && msg.contains("robot/1"), "{msg}");
}

#[test]
fn unknown_fields_are_rejected() {
    let text = String::from_utf8(encode(&cmd_vel()).unwrap())
        .unwrap()
        .replace("\"v_mps\"", "\"speed\":1,\"v_mps\"");
    assert!(matches!(
        decode::<CmdVel>(text.as_bytes()),
        Err(DecodeError::Json(_))
    ));
    let text = String::from_utf8(encode(&cmd_vel()).unwrap())
        .unwrap()
        .replace("\"kind\"", "\"extra\":0,\"kind\"");
    assert!(matches!(
        decode::<CmdVel>(text.as_bytes()),
        Err(DecodeError::Invalid {
            field: "envelope",
            ..
        })
    ));
}

/// The agent says which of its rules drives in place of the controller (the dashboard shows
/// it); an agent built before a flag existed leaves it out, and its status still parses.
#[test]
fn agent_status_takeover_flags_round_trip_and_default_to_false() {
    for (recovering, backing_up, rotating_in_place, giving_way) in [
        (false, false, true, false),
        (false, false, false, true),
        (true, false, false, false),
        (true, true, false, false),
        (false, false, true, true),
    ] {
        let sent = AgentStatus {
            state: AgentState::Driving,
            stop_reason: None,
            recovering,
            backing_up,
            rotating_in_place,
            giving_way,
            ..status()
        };
        let bytes = round_trip(&sent);
        let text = String::from_utf8(bytes).unwrap();
        assert!(
            text.contains(&format!("\"rotating_in_place\":{rotating_in_place}")),
            "{text}"
        );
        assert!(
            text.contains(&format!("\"giving_way\":{giving_way}")),
            "{text}"
        );
        assert!(
            text.contains(&format!("\"backing_up\":{backing_up}")),
            "{text}"
        );
    }

    // A status as an agent from before the two flags encoded it.
    let old = br#"{"wire_version":1,"kind":"status","msg":{"header":{"seq":7,"stamp_ns":1723456789823456789},"state":"driving","stop_reason":null,"controller":"lpe","map":{"name":"office_3f","version":4},"localized":true,"recovering":true}}"#;
    let parsed: AgentStatus = decode(old).unwrap();
    assert!(parsed.recovering);
    assert!(!parsed.backing_up);
    assert!(!parsed.rotating_in_place);
    assert!(!parsed.giving_way);
    assert_eq!(parsed.state, AgentState::Driving);
    assert_eq!(parsed.controller, ControllerKind::Lpe);

    // And from before `recovering` too.
    let older = br#"{"wire_version":1,"kind":"status","msg":{"header":{"seq":7,"stamp_ns":1723456789823456789},"state":"idle","stop_reason":null,"controller":"dlm","map":null,"localized":false}}"#;
    let parsed: AgentStatus = decode(older).unwrap();
    assert!(
        !parsed.recovering && !parsed.backing_up && !parsed.rotating_in_place && !parsed.giving_way
    );
}

/// The wire fuzzer's seed corpus (`fuzz/seeds/wire_decode`) is these fixtures as the codec
/// encodes them now, so the fuzzer starts from messages that decode. After a codec change,
/// `FLEET_WRITE_FUZZ_SEEDS=1 cargo test -p protocol --test wire fuzz_seeds` rewrites them.
#[test]
fn fuzz_seeds_are_the_current_encodings() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/seeds/wire_decode");
    let seeds: Vec<(&str, Vec<u8>)> = vec![
        ("scan", encode(&scan()).unwrap()),
        ("odom", encode(&odom()).unwrap()),
        ("cmd_vel", encode(&cmd_vel()).unwrap()),
        ("pose", encode(&pose()).unwrap()),
        ("status", encode(&status()).unwrap()),
        ("task_event", encode(&task_event()).unwrap()),
        ("map_meta", encode(&map_meta()).unwrap()),
        ("map_grid", encode(&map_grid()).unwrap()),
        (
            "camera",
            // Small pictures: a fuzzer mutates short inputs far faster.
            encode(&CameraFrame {
                header: header(5),
                image: Image::new(8, 6, ImageEncoding::Rgb8, rgb_bytes(8, 6)).unwrap(),
            })
            .unwrap(),
        ),
        ("intention", encode(&intention(None)).unwrap()),
        (
            "intention_lpe",
            encode(&intention(Some(
                Image::new(224, 224, ImageEncoding::Png, png_bytes()).unwrap(),
            )))
            .unwrap(),
        ),
    ];
    if std::env::var_os("FLEET_WRITE_FUZZ_SEEDS").is_some() {
        std::fs::create_dir_all(&dir).unwrap();
        for (name, bytes) in &seeds {
            std::fs::write(dir.join(format!("{name}.bin")), bytes).unwrap();
        }
    }
    for (name, bytes) in &seeds {
        let path = dir.join(format!("{name}.bin"));
        let stored = std::fs::read(&path).unwrap_or_default();
        assert!(
            stored == *bytes,
            "{} is not what the codec writes now; rewrite the seeds: FLEET_WRITE_FUZZ_SEEDS=1 cargo test -p protocol --test wire fuzz_seeds",
            path.display()
        );
    }
}
