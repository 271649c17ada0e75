//! Bytes off the Zenoh wire: every message kind's decoder and the kind peek. A decoded message
//! is valid, and encodes and decodes back to itself.
#![no_main]

use libfuzzer_sys::fuzz_target;
use protocol::codec::peek_kind;
use protocol::{
    decode, encode, AgentStatus, CameraFrame, CmdVel, Intention, LaserScan, MapGrid, MapMeta,
    Odometry, PoseEstimate, TaskEvent, WireMessage,
};

fn check<M: WireMessage + PartialEq + std::fmt::Debug>(data: &[u8]) {
    let Ok(msg) = decode::<M>(data) else {
        return;
    };
    msg.validate().expect("a decoded message is valid");
    let again = encode(&msg).expect("a decoded message encodes");
    let back = decode::<M>(&again).expect("an encoded message decodes");
    assert_eq!(back, msg, "{} did not survive a round trip", M::KIND);
}

fuzz_target!(|data: &[u8]| {
    let _ = peek_kind(data);
    check::<LaserScan>(data);
    check::<Odometry>(data);
    check::<CmdVel>(data);
    check::<PoseEstimate>(data);
    check::<AgentStatus>(data);
    check::<MapMeta>(data);
    check::<TaskEvent>(data);
    check::<CameraFrame>(data);
    check::<Intention>(data);
    check::<MapGrid>(data);
});
