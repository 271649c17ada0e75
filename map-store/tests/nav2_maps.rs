//! Every shared Nav2 map imports with the expected size and plausible cell counts.

// Helpers outside #[test] functions are test code too.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use map_store::{load_ros_map, DistanceField, ImportLimits, Sources};

#[test]
fn all_nav2_maps_import() {
    let dir = test_support::nav2_maps_dir();
    // (map, width, height, resolution)
    let expected = [
        ("100by100_10", 2000, 2000, 0.05),
        ("100by100_15", 2000, 2000, 0.05),
        ("100by100_20", 2000, 2000, 0.05),
        ("depot", 604, 307, 0.05),
        ("warehouse", 1006, 1674, 0.03),
        ("tb3_sandbox", 384, 384, 0.05),
        ("testmap", 10, 10, 0.1),
    ];
    for (map, w, h, res) in expected {
        let m = load_ros_map(&dir.join(format!("{map}.yaml")), &ImportLimits::default()).unwrap();
        let g = &m.grid;
        assert_eq!((g.width_cells(), g.height_cells()), (w, h), "{map}");
        assert!((g.resolution_m() - res).abs() < 1e-12, "{map}");
        let c = g.counts();
        let total = u64::from(g.width_cells()) * u64::from(g.height_cells());
        assert_eq!(c.free + c.occupied + c.unknown, total, "{map}");
        assert!(c.free > 0 && c.occupied > 0, "{map}: {c:?}");
        println!("{map}: {}x{} {c:?}", g.width_cells(), g.height_cells());
        if let Some(density) = map.strip_prefix("100by100_") {
            // The benchmark maps are random obstacles at the stated density (percent).
            let want: f64 = density.parse().unwrap();
            let got = c.occupied as f64 / total as f64 * 100.0;
            assert!((got - want).abs() < 3.0, "{map}: {got:.1} % occupied");
            assert_eq!(c.unknown, 0, "{map}");
        }
        if map == "tb3_sandbox" || map == "warehouse" {
            assert!(c.unknown > 0, "{map} has unexplored space: {c:?}");
        }
    }
}

#[test]
fn tb3_sandbox_distance_field_is_zero_on_walls_and_positive_in_free_space() {
    let dir = test_support::nav2_maps_dir();
    let g = load_ros_map(&dir.join("tb3_sandbox.yaml"), &ImportLimits::default())
        .unwrap()
        .grid;
    let df = DistanceField::compute(&g, Sources::Occupied);
    let mut checked = 0;
    for cy in 0..i64::from(g.height_cells()) {
        for cx in 0..i64::from(g.width_cells()) {
            match g.class_at(cx, cy) {
                map_store::CellClass::Occupied => assert_eq!(df.at(cx, cy), 0.0),
                map_store::CellClass::Free => {
                    assert!(df.at(cx, cy) >= g.resolution_m() as f32 * 0.999);
                    checked += 1;
                }
                map_store::CellClass::Unknown => {}
            }
        }
    }
    assert!(checked > 1000);
    // Origin honoured: cell (0, 0)'s centre is half a cell from the origin (-10, -10).
    assert_eq!(g.cell_to_world(0, 0), (-9.975, -9.975));
    assert_eq!(g.world_to_cell(-10.0 + 1e-9, -10.0 + 1e-9), (0, 0));
}
