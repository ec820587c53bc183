//! Terrain import on DEMs made here: orientation, both readers agree, crop, resampling, nodata,
//! scale, the file round trip and a plan on the imported map.

use crate::import_fixtures as fixtures;

use std::fs;
use std::path::{Path, PathBuf};

use fixtures::{geo_keys, geotiff_bytes, tiled_geotiff_i16, Dem, TiffTags};
use pf_planner::import::{
    import_map, scenario_from, Crop, ImportOptions, ImportedMap, Placement, Resolution,
};
use pf_planner::io::{load_scenario, save_scenario};
use pf_planner::map::GridMap;
use pf_planner::plan::{plan, Method, PlanRequest, PlannerOptions};
use pf_planner::traversability::slope_deg;
use tiff::encoder::compression::DeflateLevel;
use tiff::encoder::{colortype, Compression};

/// Rises 3 m per m to the east and 7 m per m to the north: a flip or a transpose shows.
fn slanted(x: f64, y: f64) -> f64 {
    50.0 + 3.0 * x + 7.0 * y
}

/// 6 x 4 cells of 2 m, south-west corner at (1000, 5000).
fn slanted_dem() -> Dem {
    Dem::from_fn(6, 4, 1000.0, 5000.0, 2.0, slanted)
}

fn import(path: &Path, options: &ImportOptions) -> ImportedMap {
    import_map(path, options).unwrap_or_else(|e| panic!("import {}: {e}", path.display()))
}

fn write(dir: &Path, name: &str, bytes: impl AsRef<[u8]>) -> PathBuf {
    let path = dir.join(name);
    fs::write(&path, bytes).expect("write");
    path
}

/// Checks the imported map is `f` at the source cell centres (shifted to min 0, then scaled):
/// map cell (ix, iy) is the source cell `ix` columns east of and `iy` rows north of the
/// crop's south-west cell.
fn assert_matches(map: &GridMap, west: f64, south: f64, cell: f64, f: impl Fn(f64, f64) -> f64) {
    let at = |ix: usize, iy: usize| {
        f(
            west + (ix as f64 + 0.5) * cell,
            south + (iy as f64 + 0.5) * cell,
        )
    };
    let scale = map.resolution / cell;
    let base = at(0, 0); // the slanted plane's lowest cell is the south-west one
    for iy in 0..map.height {
        for ix in 0..map.width {
            let expected = (at(ix, iy) - base) * scale;
            let got = map.heights[map.index(ix, iy)];
            assert!(
                (got - expected).abs() < 1e-9,
                "cell ({ix}, {iy}): {got} != {expected}"
            );
        }
    }
}

#[test]
fn an_ascii_grid_keeps_its_orientation_north_up_to_the_maps_y_up() {
    let dir = tempfile::tempdir().expect("tempdir");
    let dem = slanted_dem();
    let path = dir.path().join("slanted.asc");
    dem.write_asc(&path, None);
    let imported = import(&path, &ImportOptions::default());
    let map = &imported.map;
    assert_eq!((map.width, map.height, map.resolution), (6, 4, 2.0));
    assert_eq!(map.origin, [0.0, 0.0]);
    assert_eq!(map.obstacles, None);
    assert_matches(map, 1000.0, 5000.0, 2.0, slanted);
    // East is +x, north is +y: the gradient the DEM was built with.
    let (ix, iy) = (2, 1);
    let east = map.heights[map.index(ix + 1, iy)] - map.heights[map.index(ix, iy)];
    let north = map.heights[map.index(ix, iy + 1)] - map.heights[map.index(ix, iy)];
    assert!((east - 6.0).abs() < 1e-9 && (north - 14.0).abs() < 1e-9);
    let s = &imported.summary;
    assert_eq!(s.elevation_offset, slanted(1001.0, 5001.0));
    assert_eq!((s.height_min, s.height_max), (0.0, 3.0 * 10.0 + 7.0 * 6.0));
    let expected_slope = (3.0f64.hypot(7.0)).atan().to_degrees();
    assert!((s.slope.p50 - expected_slope).abs() < 1e-9, "{:?}", s.slope);
    assert_eq!(s.nodata_fraction, 0.0);

    // The same grid with cell-centre header items is the same map.
    let text = dem
        .to_asc(None)
        .replace("xllcorner 1000", "XLLCENTER 1001")
        .replace("yllcorner 5000", "yllcenter 5001");
    let centred = write(dir.path(), "centred.asc", text);
    assert_eq!(import(&centred, &ImportOptions::default()).map, *map);
}

#[test]
fn geotiffs_of_every_sample_type_compression_strips_or_tiles_give_the_ascii_grids_map() {
    let dir = tempfile::tempdir().expect("tempdir");
    // Integer heights of 60..132 so that every sample type holds them exactly.
    let dem = Dem::from_fn(6, 4, 1000.0, 5000.0, 2.0, |x, y| {
        (slanted(x, y) - 37_000.0).round()
    });
    let asc = dir.path().join("dem.asc");
    dem.write_asc(&asc, None);
    let reference = import(&asc, &ImportOptions::default()).map;
    let tags = TiffTags {
        georef: Some(dem.georef()),
        rows_per_strip: Some(3), // two strips, the second one short
        ..TiffTags::default()
    };
    let (w, h) = (dem.columns as u32, dem.rows as u32);
    let v = &dem.values;
    let files = [
        (
            "f32",
            geotiff_bytes::<colortype::Gray32Float>(
                w,
                h,
                &v.iter().map(|&x| x as f32).collect::<Vec<_>>(),
                &tags,
            ),
        ),
        (
            "f64",
            geotiff_bytes::<colortype::Gray64Float>(w, h, v, &tags),
        ),
        (
            "i16",
            geotiff_bytes::<colortype::GrayI16>(
                w,
                h,
                &v.iter().map(|&x| x as i16).collect::<Vec<_>>(),
                &tags,
            ),
        ),
        (
            "u16",
            geotiff_bytes::<colortype::Gray16>(
                w,
                h,
                &v.iter().map(|&x| x as u16).collect::<Vec<_>>(),
                &tags,
            ),
        ),
        (
            "i32",
            geotiff_bytes::<colortype::GrayI32>(
                w,
                h,
                &v.iter().map(|&x| x as i32).collect::<Vec<_>>(),
                &tags,
            ),
        ),
        (
            "f32_lzw",
            geotiff_bytes::<colortype::Gray32Float>(
                w,
                h,
                &v.iter().map(|&x| x as f32).collect::<Vec<_>>(),
                &TiffTags {
                    compression: Compression::Lzw,
                    ..tags.clone()
                },
            ),
        ),
        (
            "i16_deflate",
            geotiff_bytes::<colortype::GrayI16>(
                w,
                h,
                &v.iter().map(|&x| x as i16).collect::<Vec<_>>(),
                &TiffTags {
                    compression: Compression::Deflate(DeflateLevel::Best),
                    ..tags.clone()
                },
            ),
        ),
        (
            "tiled_i16",
            tiled_geotiff_i16(
                6,
                4,
                &v.iter().map(|&x| x as i16).collect::<Vec<_>>(),
                16,
                dem.georef(),
            ),
        ),
    ];
    for (kind, bytes) in files {
        let path = write(dir.path(), &format!("dem_{kind}.tif"), bytes);
        let imported = import(&path, &ImportOptions::default());
        assert_eq!(imported.map, reference, "{kind}");
        assert_eq!(imported.summary.source.west, 1000.0, "{kind}");
        assert_eq!(imported.summary.source.south, 5000.0, "{kind}");
    }
}

#[test]
fn tiles_are_read_only_where_the_crop_needs_them_and_agree_with_the_whole_raster() {
    let dir = tempfile::tempdir().expect("tempdir");
    // 40 x 35 cells in 16 x 16 tiles: 3 x 3 tiles, padded at the east and south edges.
    let dem = Dem::from_fn(40, 35, 0.0, 0.0, 1.0, |x, y| {
        (x * 3.0 + y * y * 0.1).round()
    });
    let data: Vec<i16> = dem.values.iter().map(|&x| x as i16).collect();
    let path = write(
        dir.path(),
        "tiled.tif",
        tiled_geotiff_i16(40, 35, &data, 16, dem.georef()),
    );
    let keep = ImportOptions {
        keep_elevation: true,
        ..ImportOptions::default()
    };
    let whole = import(&path, &keep).map;
    for iy in 0..35 {
        for ix in 0..40 {
            let file_value = dem.values[(34 - iy) * 40 + ix];
            assert_eq!(
                whole.heights[whole.index(ix, iy)],
                file_value,
                "({ix}, {iy})"
            );
        }
    }
    let crop = Crop::Cells {
        column0: 14,
        row0: 30,
        column1: 37,
        row1: 35,
    };
    let options = ImportOptions {
        crop: Some(crop),
        ..keep
    };
    let part = import(&path, &options).map;
    assert_eq!((part.width, part.height), (23, 5));
    for iy in 0..5 {
        for ix in 0..23 {
            // File rows 30..35 are the southernmost: map rows 0..5 of the whole raster.
            let expected = whole.heights[whole.index(ix + 14, iy)];
            assert_eq!(part.heights[part.index(ix, iy)], expected, "({ix}, {iy})");
        }
    }
}

#[test]
fn world_and_cell_crops_pick_the_same_window() {
    let dir = tempfile::tempdir().expect("tempdir");
    let dem = Dem::from_fn(20, 15, 300.0, 700.0, 1.0, slanted);
    let path = dir.path().join("crop.asc");
    dem.write_asc(&path, None);
    // Centres x 305.5..=311.5 (columns 5..=11), y 702.5..=709.5 (southern rows 2..=9, file
    // rows 5..=12).
    let world = ImportOptions {
        crop: Some(Crop::World {
            min: [305.2, 702.1],
            max: [311.9, 709.6],
        }),
        ..ImportOptions::default()
    };
    let cells = ImportOptions {
        crop: Some(Crop::Cells {
            column0: 5,
            row0: 5,
            column1: 12,
            row1: 13,
        }),
        ..ImportOptions::default()
    };
    let a = import(&path, &world);
    let b = import(&path, &cells);
    assert_eq!(a.map, b.map);
    assert_eq!((a.map.width, a.map.height), (7, 8));
    assert_eq!(
        (a.summary.window.west, a.summary.window.south),
        (305.0, 702.0)
    );
    assert_matches(&a.map, 305.0, 702.0, 1.0, slanted);
}

#[test]
fn resampling_a_plane_keeps_the_plane_and_its_slope() {
    let dir = tempfile::tempdir().expect("tempdir");
    let plane = |x: f64, y: f64| 10.0 + 0.2 * x - 0.1 * y;
    let dem = Dem::from_fn(12, 10, 0.0, 0.0, 1.0, plane);
    let path = dir.path().join("plane.asc");
    dem.write_asc(&path, None);
    for resolution in [
        Resolution::CellSize(0.5),
        Resolution::CellSize(2.0),
        Resolution::Size {
            columns: 30,
            rows: 30,
        },
    ] {
        let options = ImportOptions {
            resolution,
            keep_elevation: true,
            ..ImportOptions::default()
        };
        let map = import(&path, &options).map;
        let cell = map.resolution;
        let slope = (0.2f64.hypot(0.1)).atan().to_degrees();
        for iy in 0..map.height {
            for ix in 0..map.width {
                let [x, y] = map.cell_center(ix, iy);
                // Inside the hull of the source centres bilinear reproduces a plane exactly.
                let inside = (0.5..=11.5).contains(&x) && (0.5..=9.5).contains(&y);
                let interior = ix > 0 && iy > 0 && ix + 1 < map.width && iy + 1 < map.height;
                if inside {
                    let h = map.heights[map.index(ix, iy)];
                    assert!(
                        (h - plane(x, y)).abs() < 1e-9,
                        "{resolution:?} ({ix}, {iy})"
                    );
                }
                let neighbours_inside = [(-1.0, 0.0), (1.0, 0.0), (0.0, -1.0), (0.0, 1.0)]
                    .iter()
                    .all(|(dx, dy)| {
                        (0.5..=11.5).contains(&(x + dx * cell))
                            && (0.5..=9.5).contains(&(y + dy * cell))
                    });
                if interior && neighbours_inside {
                    let s = slope_deg(&map, ix, iy);
                    assert!((s - slope).abs() < 1e-6, "{resolution:?} ({ix}, {iy}): {s}");
                }
            }
        }
    }
    // --size 30,30 on a 12 x 10 m window: cells of 0.4 m, 30 x 25.
    let sized = import(
        &path,
        &ImportOptions {
            resolution: Resolution::Size {
                columns: 30,
                rows: 30,
            },
            ..ImportOptions::default()
        },
    );
    assert_eq!((sized.map.width, sized.map.height), (30, 25));
    assert!((sized.map.resolution - 0.4).abs() < 1e-12);
}

#[test]
fn nodata_cells_become_obstacles_filled_from_their_neighbours() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut dem = Dem::from_fn(5, 4, 0.0, 0.0, 1.0, |x, _| x.floor());
    // File row 1 = map row 2; columns 2 and 3.
    dem.values[5 + 2] = -9999.0;
    dem.values[5 + 3] = -9999.0;
    let asc = dir.path().join("holes.asc");
    dem.write_asc(&asc, Some(-9999.0));
    let tif = write(
        dir.path(),
        "holes.tif",
        geotiff_bytes::<colortype::Gray32Float>(
            5,
            4,
            &dem.values.iter().map(|&v| v as f32).collect::<Vec<_>>(),
            &TiffTags {
                georef: Some(dem.georef()),
                nodata: Some("-9999"),
                ..TiffTags::default()
            },
        ),
    );
    for path in [&asc, &tif] {
        let imported = import(path, &ImportOptions::default());
        let map = &imported.map;
        let mask = map.obstacles.as_ref().expect("obstacles");
        let blocked: Vec<(usize, usize)> = (0..map.len())
            .filter(|&i| mask[i])
            .map(|i| (i % 5, i / 5))
            .collect();
        assert_eq!(blocked, vec![(2, 2), (3, 2)], "{}", path.display());
        // Heights: the nearest valid cell's (here the one below, reached first).
        assert_eq!(map.heights[map.index(2, 2)], 2.0);
        assert_eq!(map.heights[map.index(3, 2)], 3.0);
        assert!((imported.summary.nodata_fraction - 0.1).abs() < 1e-12);
    }
    // A NaN nodata in a float GeoTIFF.
    let mut nan_values: Vec<f32> = dem.values.iter().map(|&v| v as f32).collect();
    nan_values[7] = f32::NAN;
    nan_values[8] = f32::NAN;
    let nan = write(
        dir.path(),
        "nan.tif",
        geotiff_bytes::<colortype::Gray32Float>(
            5,
            4,
            &nan_values,
            &TiffTags {
                georef: Some(dem.georef()),
                nodata: Some("nan"),
                ..TiffTags::default()
            },
        ),
    );
    let nan_map = import(&nan, &ImportOptions::default()).map;
    assert_eq!(nan_map, import(&asc, &ImportOptions::default()).map);
}

#[test]
fn a_uniform_scale_keeps_slopes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let hills = |x: f64, y: f64| 400.0 + 30.0 * (x / 40.0).sin() * (y / 25.0).cos() + 0.3 * x;
    let dem = Dem::from_fn(60, 50, 0.0, 0.0, 5.0, hills);
    let path = dir.path().join("hills.asc");
    dem.write_asc(&path, None);
    let full = import(&path, &ImportOptions::default());
    let small = import(
        &path,
        &ImportOptions {
            scale: 0.02,
            ..ImportOptions::default()
        },
    );
    assert!((small.map.resolution - 0.1).abs() < 1e-15);
    for i in 0..full.map.len() {
        let (ix, iy) = (i % 60, i / 60);
        assert!((small.map.heights[i] - 0.02 * full.map.heights[i]).abs() < 1e-9);
        let (a, b) = (slope_deg(&full.map, ix, iy), slope_deg(&small.map, ix, iy));
        assert!((a - b).abs() < 1e-9, "({ix}, {iy}): {a} vs {b}");
    }
    let (a, b) = (full.summary.slope, small.summary.slope);
    assert!((a.p95 - b.p95).abs() < 1e-9 && (a.max - b.max).abs() < 1e-9);
    assert!(a.max > 10.0, "the hills have real slopes: {a:?}");
    // --cell-size is the written map's: 0.2 m after the 1/50 scale = 10 m of source.
    let coarse = import(
        &path,
        &ImportOptions {
            scale: 0.02,
            resolution: Resolution::CellSize(0.2),
            ..ImportOptions::default()
        },
    );
    assert_eq!((coarse.map.width, coarse.map.height), (30, 25));
    assert!((coarse.map.resolution - 0.2).abs() < 1e-12);
}

#[test]
fn georeferencing_pixel_is_point_and_missing_or_degree_cell_sizes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let dem = slanted_dem();
    let data: Vec<f32> = dem.values.iter().map(|&v| v as f32).collect();
    let (scale, _) = dem.georef();
    // PixelIsPoint: the tie point is the centre of the north-west cell.
    let point_tie = [0.0, 0.0, 0.0, 1001.0, dem.north() - 1.0, 0.0];
    let point = write(
        dir.path(),
        "point.tif",
        geotiff_bytes::<colortype::Gray32Float>(
            6,
            4,
            &data,
            &TiffTags {
                georef: Some((scale, point_tie)),
                geo_keys: Some(geo_keys(1, 2)),
                ..TiffTags::default()
            },
        ),
    );
    let s = import(&point, &ImportOptions::default()).summary;
    assert_eq!((s.source.west, s.source.south), (1000.0, 5000.0));

    let bare = write(
        dir.path(),
        "bare.tif",
        geotiff_bytes::<colortype::Gray32Float>(6, 4, &data, &TiffTags::default()),
    );
    let err = import_map(&bare, &ImportOptions::default()).expect_err("no cell size");
    assert!(err.to_string().contains("--source-cell-size"), "{err}");
    let given = ImportOptions {
        source_cell_size: Some(2.0),
        ..ImportOptions::default()
    };
    let reference = {
        let asc = dir.path().join("ref.asc");
        dem.write_asc(&asc, None);
        import(&asc, &ImportOptions::default()).map
    };
    assert_eq!(import(&bare, &given).map, reference);

    let degrees = write(
        dir.path(),
        "degrees.tif",
        geotiff_bytes::<colortype::Gray32Float>(
            6,
            4,
            &data,
            &TiffTags {
                georef: Some(([0.001, 0.001, 0.0], [0.0, 0.0, 0.0, 8.5, 47.2, 0.0])),
                geo_keys: Some(geo_keys(2, 1)),
                ..TiffTags::default()
            },
        ),
    );
    let err = import_map(&degrees, &ImportOptions::default()).expect_err("degrees");
    assert!(err.to_string().contains("geographic"), "{err}");
    assert_eq!(import(&degrees, &given).map, reference);
}

#[test]
fn non_square_cells_need_resampling() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = "ncols 4\nnrows 3\nxllcorner 0\nyllcorner 0\ndx 2\ndy 1\n\
                1 2 3 4\n1 2 3 4\n1 2 3 4\n";
    let path = write(dir.path(), "rect.asc", text);
    let err = import_map(&path, &ImportOptions::default()).expect_err("not square");
    assert!(err.to_string().contains("--cell-size"), "{err}");
    let map = import(
        &path,
        &ImportOptions {
            resolution: Resolution::CellSize(1.0),
            ..ImportOptions::default()
        },
    )
    .map;
    assert_eq!((map.width, map.height), (8, 3));
    // Source centres x = 1, 3, 5, 7 hold 0..3 (after the shift); x = 0.5 clamps to the first,
    // 1.5 lies a quarter of the way to the second, 7.5 clamps to the last.
    let row: Vec<f64> = (0..8).map(|ix| map.heights[ix]).collect();
    assert_eq!(row, vec![0.0, 0.25, 0.75, 1.25, 1.75, 2.25, 2.75, 3.0]);
}

#[test]
fn an_imported_scenario_round_trips_and_plans() {
    let dir = tempfile::tempdir().expect("tempdir");
    // A valley between two ridges, 1 m DEM; at 1/10 scale the map is 4 x 3 m.
    let valley = |x: f64, y: f64| 200.0 + 0.02 * (y - 15.0).powi(2) + 0.1 * x;
    let mut dem = Dem::from_fn(40, 30, 0.0, 0.0, 1.0, valley);
    dem.values[15 * 40 + 20] = -9999.0; // one hole on the valley floor
    let path = dir.path().join("valley.asc");
    dem.write_asc(&path, Some(-9999.0));
    let imported = import(
        &path,
        &ImportOptions {
            scale: 0.1,
            ..ImportOptions::default()
        },
    );
    let placement = Placement {
        name: "valley".into(),
        start: Some([0.3, 1.5]),
        start_yaw: 0.0,
        goal: Some([3.7, 1.5]),
        goal_radius: 0.2,
    };
    let scenario = scenario_from(imported.map, &placement).expect("scenario");
    let json = save_scenario(&scenario, dir.path()).expect("save");
    let loaded = load_scenario(&json).expect("load");
    assert_eq!(loaded, scenario);
    let request = PlanRequest {
        map: loaded.map.clone(),
        start: loaded.start,
        start_yaw: loaded.start_yaw,
        goal: loaded.goal,
        method: Method::Pf,
        options: PlannerOptions {
            grid_size: 40,
            traversability: loaded.traversability,
            ..PlannerOptions::default()
        },
    };
    let result = plan(&request).expect("P-F plans on the imported map");
    let end = *result.path.last().expect("path");
    assert!(loaded.goal.contains(end), "ends at {end:?}");
    assert_eq!(result.metrics.length_in_obstacles, 0.0);
}
