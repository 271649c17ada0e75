//! Which worker replans which robot: rendezvous (highest random weight) hashing over the
//! workers that are alive.
//!
//! Every process computes the same answer from the same set of liveliness tokens, with no
//! coordination: the service (to know whether it must plan a robot itself and to show who
//! plans what) and each worker (to know which robots are its own). When a worker leaves only
//! its robots move, spread over the others; when one joins it takes about `1/n` of the robots
//! from the others. The hash is FNV-1a with a 64-bit finalizer, written out here rather than
//! `std`'s hasher, whose output may change between Rust releases: workers on hosts built by
//! different toolchains must still agree.

use protocol::{RobotId, WorkerId};

const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
const FNV_PRIME: u64 = 0x0000_0100_0000_01b3;

fn fnv1a(mut h: u64, bytes: &[u8]) -> u64 {
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(FNV_PRIME);
    }
    h
}

/// splitmix64's finalizer: FNV alone leaves similar ids with similar high bits.
fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The weight of `worker` for `robot`.
#[must_use]
pub fn weight(worker: &WorkerId, robot: &RobotId) -> u64 {
    // The separator keeps ("ab", "c") and ("a", "bc") apart.
    let h = fnv1a(FNV_OFFSET, worker.as_str().as_bytes());
    mix(fnv1a(fnv1a(h, b"/"), robot.as_str().as_bytes()))
}

/// The worker that replans `robot`: the highest weight, ties to the smaller id. `None` when
/// there is no worker.
pub fn owner<'a>(
    robot: &RobotId,
    workers: impl IntoIterator<Item = &'a WorkerId>,
) -> Option<&'a WorkerId> {
    workers.into_iter().max_by(|a, b| {
        weight(a, robot)
            .cmp(&weight(b, robot))
            .then_with(|| b.as_str().cmp(a.as_str()))
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use std::collections::BTreeMap;

    use super::*;

    fn workers(n: usize) -> Vec<WorkerId> {
        (1..=n)
            .map(|i| WorkerId::new(format!("w{i}")).unwrap())
            .collect()
    }

    fn robots(n: usize) -> Vec<RobotId> {
        (0..n)
            .map(|i| RobotId::new(format!("robot_{i:03}")).unwrap())
            .collect()
    }

    #[test]
    fn no_worker_owns_nothing_and_one_worker_owns_everything() {
        let r = RobotId::new("robot_1").unwrap();
        assert_eq!(owner(&r, &[]), None);
        let w = workers(1);
        assert_eq!(owner(&r, &w), Some(&w[0]));
    }

    #[test]
    fn the_answer_depends_on_the_set_not_its_order() {
        let mut w = workers(5);
        let before: Vec<_> = robots(200).iter().map(|r| owner(r, &w).cloned()).collect();
        w.reverse();
        let after: Vec<_> = robots(200).iter().map(|r| owner(r, &w).cloned()).collect();
        assert_eq!(before, after);
    }

    #[test]
    fn robots_spread_evenly_over_workers() {
        let w = workers(4);
        let mut counts: BTreeMap<&WorkerId, usize> = BTreeMap::new();
        for r in robots(1000) {
            *counts.entry(owner(&r, &w).unwrap()).or_default() += 1;
        }
        assert_eq!(counts.len(), 4);
        for (worker, n) in counts {
            assert!((200..=300).contains(&n), "{worker} got {n} of 1000 robots");
        }
    }

    #[test]
    fn a_leaving_worker_moves_only_its_own_robots() {
        let all = workers(3);
        let rest = &all[..2];
        let mut moved = 0;
        for r in robots(600) {
            let before = owner(&r, &all).unwrap();
            let after = owner(&r, rest).unwrap();
            if before == &all[2] {
                moved += 1;
            } else {
                assert_eq!(before, after, "{r} moved though its worker stayed");
            }
        }
        // And the leaver had its share.
        assert!((150..=250).contains(&moved), "{moved}");
    }

    #[test]
    fn the_hash_is_pinned_across_builds() {
        // Workers built by other toolchains must agree: the weights are fixed numbers.
        let w = WorkerId::new("w1").unwrap();
        let r = RobotId::new("robot_1").unwrap();
        assert_eq!(weight(&w, &r), weight(&w, &r));
        assert_eq!(format!("{:016x}", weight(&w, &r)), PINNED_W1_ROBOT_1);
    }

    // FNV-1a of "w1/robot_1", then splitmix64's finalizer (checked by hand in Python).
    const PINNED_W1_ROBOT_1: &str = "5a38164c268f4a18";
}
