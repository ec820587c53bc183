use std::path::Path;

use super::*;

fn geometry(columns: usize, rows: usize) -> RasterGeometry {
    RasterGeometry {
        columns,
        rows,
        west: 100.0,
        south: 200.0,
        dx: 2.0,
        dy: 2.0,
    }
}

#[test]
fn world_crop_keeps_the_cells_whose_centres_are_inside() {
    let g = geometry(10, 8);
    // Centres of columns: 101, 103, ...; of rows counted from the south: 201, 203, ...
    let crop = Crop::World {
        min: [102.5, 200.0],
        max: [107.0, 204.0],
    };
    let window = CellWindow::resolve(&g, Some(&crop), 1000, Path::new("t")).expect("window");
    // Columns 1..=3 (centres 103, 105, 107); southern rows 0..=1 = file rows 6..=7.
    assert_eq!(
        window,
        CellWindow {
            column0: 1,
            row0: 6,
            columns: 3,
            rows: 2
        }
    );
    let cropped = g.of_window(&window);
    assert_eq!((cropped.west, cropped.south), (102.0, 200.0));
}

#[test]
fn crops_outside_empty_or_too_large_are_refused() {
    let g = geometry(10, 8);
    let path = Path::new("dem.asc");
    let outside = Crop::World {
        min: [0.0, 0.0],
        max: [50.0, 50.0],
    };
    let err = CellWindow::resolve(&g, Some(&outside), 1000, path).expect_err("outside");
    assert!(err.to_string().contains("holds no cell centre"), "{err}");
    let reversed = Crop::Cells {
        column0: 5,
        row0: 0,
        column1: 5,
        row1: 3,
    };
    assert!(CellWindow::resolve(&g, Some(&reversed), 1000, path).is_err());
    let beyond = Crop::Cells {
        column0: 0,
        row0: 0,
        column1: 11,
        row1: 3,
    };
    assert!(CellWindow::resolve(&g, Some(&beyond), 1000, path).is_err());
    let err = CellWindow::resolve(&g, None, 79, path).expect_err("limit");
    assert!(err.to_string().contains("limit of 79 cells"), "{err}");
}

#[test]
fn resampling_a_plane_gives_the_same_plane_and_nodata_spreads_to_touching_cells() {
    let g = RasterGeometry {
        columns: 9,
        rows: 7,
        west: 0.0,
        south: 0.0,
        dx: 1.0,
        dy: 1.0,
    };
    let plane = |x: f64, y: f64| 3.0 + 0.5 * x - 0.25 * y;
    let values = (0..g.rows)
        .flat_map(|iy| (0..g.columns).map(move |ix| plane(ix as f64 + 0.5, iy as f64 + 0.5)))
        .collect();
    let raster = Raster {
        geometry: g,
        values,
    };
    let fine = resample(&raster, 0.25, 10_000).expect("resample");
    assert_eq!((fine.geometry.columns, fine.geometry.rows), (36, 28));
    for iy in 0..28 {
        for ix in 0..36 {
            let (x, y) = ((ix as f64 + 0.5) * 0.25, (iy as f64 + 0.5) * 0.25);
            // Inside the hull of the source centres the plane is reproduced; outside it is clamped.
            if (0.5..=8.5).contains(&x) && (0.5..=6.5).contains(&y) {
                let v = fine.values[iy * 36 + ix];
                assert!((v - plane(x, y)).abs() < 1e-12, "({ix}, {iy}): {v}");
            }
        }
    }
    let mut holed = raster.clone();
    holed.values[3 * 9 + 4] = f64::NAN; // source cell (4, 3), centre (4.5, 3.5)
    let same = resample(&holed, 1.0, 10_000).expect("resample");
    let nan: Vec<usize> = (0..same.values.len())
        .filter(|&i| same.values[i].is_nan())
        .collect();
    assert_eq!(
        nan,
        vec![3 * 9 + 4],
        "equal cells: only the nodata cell itself"
    );
    let half = resample(&holed, 0.5, 10_000).expect("resample");
    for iy in 0..14 {
        for ix in 0..18 {
            let (x, y) = ((ix as f64 + 0.5) * 0.5, (iy as f64 + 0.5) * 0.5);
            let touches = (x - 4.5).abs() < 1.0 && (y - 3.5).abs() < 1.0;
            assert_eq!(
                half.values[iy * 18 + ix].is_nan(),
                touches,
                "({ix}, {iy}) at ({x}, {y})"
            );
        }
    }
}

#[test]
fn nodata_is_filled_from_the_nearest_valid_cell() {
    let nan = f64::NAN;
    #[rustfmt::skip]
    let mut values = vec![
        1.0, nan, nan, nan,
        nan, nan, nan, 9.0,
    ];
    let mask = fill_nodata(&mut values, 4).expect("some valid");
    assert_eq!(values, vec![1.0, 1.0, 1.0, 9.0, 1.0, 1.0, 9.0, 9.0]);
    assert_eq!(mask, vec![false, true, true, true, true, true, true, false]);
    assert_eq!(fill_nodata(&mut [nan, nan], 2), None);
}

#[test]
fn slope_percentiles_use_the_traversability_slope() {
    // A 45° ramp along x: every cell (also at the edges, one-sided) is 45°.
    let heights = (0..20).map(|i| (i % 5) as f64).collect();
    let map = GridMap::new([0.0, 0.0], 1.0, 5, 4, heights, None).expect("map");
    let stats = slope_stats(&map);
    for v in [stats.p50, stats.p95, stats.max] {
        assert!((v - 45.0).abs() < 1e-9, "{stats:?}");
    }
}

#[test]
fn the_format_comes_from_the_extension() {
    assert_eq!(
        DemFormat::from_path(Path::new("a/b.ASC")).expect("asc"),
        DemFormat::EsriAscii
    );
    assert_eq!(
        DemFormat::from_path(Path::new("x.tiff")).expect("tiff"),
        DemFormat::GeoTiff
    );
    let err = DemFormat::from_path(Path::new("x.dem")).expect_err("unknown");
    assert!(err.to_string().contains("--format"), "{err}");
}

#[test]
fn flag_values_parse_or_say_why_not() {
    assert_eq!(numbers::<2>(" 1.5, -2").expect("two"), [1.5, -2.0]);
    assert!(numbers::<2>("1,2,3")
        .expect_err("three")
        .contains("expected 2"));
    assert!(numbers::<2>("1,inf").expect_err("inf").contains("finite"));
    assert_eq!(counts::<4>("0,10,64,80").expect("four"), [0, 10, 64, 80]);
    assert!(counts::<2>("3,-1")
        .expect_err("negative")
        .contains("whole number"));
    assert!(counts::<2>("3").expect_err("one").contains("expected 2"));
    assert_eq!(factor("1/50").expect("fraction"), 0.02);
    assert_eq!(factor("0.5").expect("number"), 0.5);
    for bad in ["0", "-1", "1/0", "x", "nan", "1/-2"] {
        assert!(factor(bad).is_err(), "{bad}");
    }
    assert_eq!(stem_name(Path::new("dir/hill dem.v2.asc")), "hill_dem_v2");
    assert_eq!(stem_name(Path::new("/")), "terrain");
}
