//! AMCL update time on the Nav2 depot map: one full filter cycle (motion, likelihood field with
//! beam skipping, KLD resampling) at 2,000 and 10,000 particles × 60 beams, against references
//! in the same run: all 181 beams, no beam skipping, and the sensor model evaluated naively
//! (exact f32 distance field + one `exp` per beam) instead of the quantized table.
//!
//! Run: `cargo bench -p robot-agent --bench amcl`

// A benchmark whose setup fails has nothing to measure: aborting with the reason is right.
#![allow(clippy::expect_used)]

#[path = "../tests/amcl_world/mod.rs"]
mod amcl_world;

use std::hint::black_box;
use std::sync::Arc;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use map_core::{DistanceField, Sources};
use protocol::{Header, Odometry, Pose2D};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use robot_agent::amcl::{sensor::beam_likelihood, Amcl, AmclConfig, LikelihoodField, ScanModel};

fn odom(x: f64) -> Odometry {
    Odometry {
        header: Header::default(),
        pose: Pose2D::new(x, 0.0, 0.0),
        v_mps: 0.0,
        omega_radps: 0.0,
    }
}

fn bench_update(c: &mut Criterion) {
    let (map, truth) = amcl_world::depot_world();
    let field = Arc::new(LikelihoodField::new(&map, 2.0).expect("field"));
    let pose = Pose2D::new(5.0, 7.5, 0.2);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let scan = amcl_world::Laser::default().scan(&truth, &pose, 0, &mut rng);

    let mut group = c.benchmark_group("amcl_update");
    group.sample_size(20);
    let cases: [(&str, usize, usize, bool); 5] = [
        ("60_beams_skip", 2_000, 60, true),
        ("60_beams_skip", 10_000, 60, true),
        ("60_beams_noskip", 10_000, 60, false),
        ("181_beams_skip", 10_000, 181, true),
        ("181_beams_noskip", 10_000, 181, false),
    ];
    for (name, n, beams, skip) in cases {
        // min = max so that KLD keeps the count fixed and every iteration costs the same.
        let config = AmclConfig {
            min_particles: n,
            max_particles: n,
            max_beams: beams,
            do_beamskip: skip,
            ..AmclConfig::default()
        };
        let mut amcl = Amcl::new(config, Arc::clone(&field)).expect("amcl");
        amcl.set_initial_pose(pose, [0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.005])
            .expect("pose");
        amcl.update(&odom(0.0), Some(&scan)).expect("update");
        let mut k = 0u64;
        group.bench_with_input(BenchmarkId::new(name, n), &n, |b, _| {
            b.iter(|| {
                // Alternate 0.3 m back and forth so that every call passes the update gate.
                k += 1;
                let x = if k.is_multiple_of(2) { 0.0 } else { 0.3 };
                black_box(amcl.update(&odom(x), Some(&scan)).expect("update"))
            });
        });
    }
    group.finish();

    // Sensor model alone over the same 10,000 poses: table lookup vs the formula on the exact
    // distance field.
    let config = AmclConfig::default();
    let model = ScanModel::new(&field, &config, &scan);
    let exact = DistanceField::compute(&map, Sources::Occupied);
    let mut amcl = Amcl::new(
        AmclConfig {
            min_particles: 10_000,
            max_particles: 10_000,
            ..config.clone()
        },
        Arc::clone(&field),
    )
    .expect("amcl");
    amcl.set_initial_pose(pose, [0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.005])
        .expect("pose");
    let poses: Vec<Pose2D> = amcl.particles().iter().map(|p| p.pose).collect();
    let beams: Vec<(f64, f64)> = (0..scan.ranges_m.len())
        .filter(|&i| scan.is_return(i))
        .step_by(3)
        .map(|i| {
            (
                f64::from(scan.ranges_m[i]),
                f64::from(scan.beam_angle_rad(i)),
            )
        })
        .collect();
    let range_max = f64::from(scan.range_max_m);
    let mut group = c.benchmark_group("amcl_sensor_10000");
    group.sample_size(20);
    group.bench_function("table", |b| {
        b.iter(|| poses.iter().map(|p| model.likelihood(p).ln()).sum::<f64>());
    });
    group.bench_function("naive_exp", |b| {
        b.iter(|| {
            poses
                .iter()
                .map(|p| {
                    beams
                        .iter()
                        .map(|&(r, a)| {
                            let t = p.yaw_rad + a;
                            let (cx, cy) =
                                map.world_to_cell(p.x_m + r * t.cos(), p.y_m + r * t.sin());
                            let d = if map.contains(cx, cy) {
                                f64::from(exact.at(cx, cy)).min(2.0)
                            } else {
                                2.0
                            };
                            beam_likelihood(&config, d, range_max).ln()
                        })
                        .sum::<f64>()
                })
                .sum::<f64>()
        });
    });
    group.finish();
}

criterion_group!(benches, bench_update);
criterion_main!(benches);
