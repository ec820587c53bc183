//! Hostile and broken elevation models: each is a typed error naming the file and the item,
//! never a panic, and nothing is allocated for sizes a header merely claims.

use crate::import_fixtures as fixtures;

use std::fs;
use std::path::{Path, PathBuf};

use fixtures::{geotiff_bytes, Dem, TiffTags};
use pf_planner::error::PlanError;
use pf_planner::import::{import_map, scenario_from, Crop, ImportOptions, Placement, Resolution};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
use tiff::encoder::colortype;

fn write(dir: &Path, name: &str, bytes: impl AsRef<[u8]>) -> PathBuf {
    let path = dir.join(name);
    fs::write(&path, bytes).expect("write");
    path
}

/// Imports `bytes` as `name` and returns the error text, which must name the file.
fn error_of(dir: &Path, name: &str, bytes: impl AsRef<[u8]>) -> String {
    let path = write(dir, name, bytes);
    let err = import_map(&path, &ImportOptions::default())
        .map(|m| m.map.len())
        .expect_err(name);
    let text = err.to_string();
    if matches!(err, PlanError::Format { .. } | PlanError::Io { .. }) {
        assert!(
            text.contains(name),
            "{name}: the error names the file: {text}"
        );
    }
    text
}

const HEADER: &str = "ncols 3\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n";

#[test]
fn broken_ascii_grids_are_refused_with_the_reason() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let cases: &[(&str, String, &str)] = &[
        (
            "short.asc",
            format!("{HEADER}1 2 3\n4 5\n"),
            "ends after 5 of",
        ),
        (
            "long.asc",
            format!("{HEADER}1 2 3\n4 5 6\n7\n"),
            "more data than",
        ),
        (
            "inf.asc",
            format!("{HEADER}1 2 3\n4 inf 6\n"),
            "row 1, column 1",
        ),
        ("nan.asc", format!("{HEADER}1 2 3\nnan 5 6\n"), "not finite"),
        (
            "word.asc",
            format!("{HEADER}1 2 3\n4 five 6\n"),
            "\"five\" is not a number",
        ),
        (
            "huge_value.asc",
            format!("{HEADER}1 2 -3.4e38\n4 5 6\n"),
            "undeclared nodata",
        ),
        (
            "zero_cell.asc",
            HEADER.replace("cellsize 1", "cellsize 0") + "1 2 3\n4 5 6\n",
            "must be finite and > 0",
        ),
        (
            "negative_cell.asc",
            HEADER.replace("cellsize 1", "cellsize -2") + "1 2 3\n4 5 6\n",
            "-2",
        ),
        (
            "zero_rows.asc",
            HEADER.replace("nrows 2", "nrows 0") + "1 2 3\n",
            "nrows",
        ),
        (
            "fraction_rows.asc",
            HEADER.replace("nrows 2", "nrows 2.5") + "1 2 3\n4 5 6\n",
            "whole number",
        ),
        (
            "unknown_key.asc",
            format!("byteorder LSBFIRST\n{HEADER}1 2 3\n4 5 6\n"),
            "unknown header item \"byteorder\"",
        ),
        (
            "twice.asc",
            format!("{HEADER}cellsize 1\n1 2 3\n4 5 6\n"),
            "appears twice",
        ),
        (
            "no_nrows.asc",
            HEADER.replace("nrows 2\n", "") + "1 2 3\n4 5 6\n",
            "no nrows",
        ),
        (
            "both_corners.asc",
            format!("{HEADER}xllcenter 0.5\n1 2 3\n4 5 6\n"),
            "exactly one of xllcorner and xllcenter",
        ),
        ("header_only.asc", HEADER.to_string(), "no data values"),
        (
            "inf_corner.asc",
            HEADER.replace("xllcorner 0", "xllcorner inf") + "1 2 3\n4 5 6\n",
            "is not finite",
        ),
        (
            "long_token.asc",
            format!("{HEADER}1 2 {}\n4 5 6\n", "9".repeat(500)),
            "longer than",
        ),
        (
            "binary.asc",
            "ncols \u{0}\u{1}".to_string() + "\u{fffd}",
            "ends inside the header",
        ),
        ("empty.asc", String::new(), "ends inside the header"),
    ];
    for (name, text, expected) in cases {
        let message = error_of(d, name, text);
        assert!(message.contains(expected), "{name}: {message}");
    }
    let binary = error_of(d, "bytes.asc", [0xffu8, 0xfe, 0x00, 0x41, 0x20, 0x31]);
    assert!(binary.contains("not text"), "{binary}");
}

#[test]
fn absurd_sizes_are_refused_before_anything_is_allocated() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = "ncols 1000000000\nnrows 1000000000\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3\n";
    let message = error_of(dir.path(), "absurd.asc", text);
    assert!(message.contains("exceed the limit"), "{message}");
    let overflow = format!(
        "ncols {}\nnrows {}\nxllcorner 0\nyllcorner 0\ncellsize 1\n1\n",
        usize::MAX,
        usize::MAX
    );
    let message = error_of(dir.path(), "overflow.asc", overflow);
    assert!(message.contains("exceed the limit"), "{message}");
    // The output limit: 4 x 4 cells resampled to 0.01 m would be 160 000 cells.
    let dem = Dem::from_fn(4, 4, 0.0, 0.0, 1.0, |x, y| x + y);
    let path = dir.path().join("small.asc");
    dem.write_asc(&path, None);
    let options = ImportOptions {
        resolution: Resolution::CellSize(0.01),
        max_cells: 10_000,
        ..ImportOptions::default()
    };
    let err = import_map(&path, &options).expect_err("too many output cells");
    assert!(err.to_string().contains("limit of 10000 cells"), "{err}");
}

fn f32_tiff(width: u32, height: u32, values: &[f32], tags: &TiffTags) -> Vec<u8> {
    geotiff_bytes::<colortype::Gray32Float>(width, height, values, tags)
}

#[test]
fn broken_geotiffs_are_refused_with_the_reason() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let dem = Dem::from_fn(8, 6, 0.0, 0.0, 1.0, |x, y| x + 2.0 * y);
    let values: Vec<f32> = dem.values.iter().map(|&v| v as f32).collect();
    let tags = TiffTags {
        georef: Some(dem.georef()),
        ..TiffTags::default()
    };
    let good = f32_tiff(8, 6, &values, &tags);
    assert!(import_map(&write(d, "good.tif", &good), &ImportOptions::default()).is_ok());

    let truncated = error_of(d, "truncated.tif", &good[..good.len() / 2]);
    assert!(truncated.contains("not a readable TIFF"), "{truncated}");
    let message = error_of(d, "not_tiff.tif", b"GIF89a this is not a tiff at all");
    assert!(message.contains("not a readable TIFF"), "{message}");
    let rgb = geotiff_bytes::<colortype::RGB8>(8, 6, &[7u8; 8 * 6 * 3], &tags);
    let message = error_of(d, "rgb.tif", rgb);
    assert!(message.contains("SamplesPerPixel = 3"), "{message}");
    let wide = geotiff_bytes::<colortype::Gray64>(8, 6, &[7u64; 48], &tags);
    let message = error_of(d, "u64.tif", wide);
    assert!(message.contains("unsupported samples"), "{message}");
    let mut with_nan = values.clone();
    with_nan[13] = f32::NAN;
    let message = error_of(d, "nan.tif", f32_tiff(8, 6, &with_nan, &tags));
    assert!(message.contains("row 1, column 5"), "{message}");
    let mut with_min = values.clone();
    with_min[0] = f32::MIN;
    let message = error_of(d, "min.tif", f32_tiff(8, 6, &with_min, &tags));
    assert!(message.contains("undeclared nodata"), "{message}");
    let zero_scale = TiffTags {
        georef: Some(([0.0, 1.0, 0.0], dem.georef().1)),
        ..TiffTags::default()
    };
    let message = error_of(d, "zero_scale.tif", f32_tiff(8, 6, &values, &zero_scale));
    assert!(message.contains("dx (cell width) = 0"), "{message}");
    let bad_nodata = TiffTags {
        nodata: Some("none"),
        ..tags.clone()
    };
    let message = error_of(d, "bad_nodata.tif", f32_tiff(8, 6, &values, &bad_nodata));
    assert!(message.contains("GDAL_NODATA"), "{message}");
    let all_nodata = TiffTags {
        nodata: Some("0"),
        ..tags.clone()
    };
    let message = error_of(d, "all_nodata.tif", f32_tiff(1, 1, &[0.0], &all_nodata));
    assert!(message.contains("every cell"), "{message}");
    // A header that claims 60 000 x 60 000 cells: refused from the header, nothing decoded.
    let mut huge = good.clone();
    patch_dimensions(&mut huge, 60_000, 60_000);
    let message = error_of(d, "huge.tif", huge);
    assert!(message.contains("exceed the limit"), "{message}");
    let missing = import_map(&d.join("missing.tif"), &ImportOptions::default()).expect_err("io");
    assert!(matches!(missing, PlanError::Io { .. }), "{missing}");
}

/// Rewrites ImageWidth, ImageLength and RowsPerStrip (one strip) of a little-endian TIFF.
fn patch_dimensions(bytes: &mut [u8], width: u32, height: u32) {
    let ifd = u32::from_le_bytes(bytes[4..8].try_into().expect("4 bytes")) as usize;
    let count = u16::from_le_bytes([bytes[ifd], bytes[ifd + 1]]) as usize;
    for e in 0..count {
        let at = ifd + 2 + 12 * e;
        let tag = u16::from_le_bytes([bytes[at], bytes[at + 1]]);
        let value = match tag {
            256 => width,
            257 | 278 => height,
            _ => continue,
        };
        bytes[at + 2..at + 4].copy_from_slice(&4u16.to_le_bytes());
        bytes[at + 8..at + 12].copy_from_slice(&value.to_le_bytes());
    }
}

#[test]
fn start_and_goal_must_be_given_inside_and_off_obstacles() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut dem = Dem::from_fn(10, 10, 0.0, 0.0, 1.0, |x, _| x);
    dem.values[0] = -1.0; // file row 0 = north: map cell (0, 9)
    let path = dir.path().join("field.asc");
    dem.write_asc(&path, Some(-1.0));
    let map = import_map(&path, &ImportOptions::default())
        .expect("import")
        .map;
    let placement = |start: Option<[f64; 2]>, goal: Option<[f64; 2]>| Placement {
        name: "field".into(),
        start,
        start_yaw: 0.0,
        goal,
        goal_radius: 0.5,
    };
    let cases = [
        (placement(None, Some([5.0, 5.0])), "--start X,Y --goal X,Y"),
        (placement(Some([1.0, 1.0]), None), "x 0..10, y 0..10"),
        (
            placement(Some([11.0, 1.0]), Some([5.0, 5.0])),
            "off the map",
        ),
        (placement(Some([1.0, 1.0]), Some([0.5, 9.5])), "obstacle"),
        (
            placement(Some([f64::NAN, 1.0]), Some([5.0, 5.0])),
            "off the map",
        ),
    ];
    for (p, expected) in cases {
        let err = scenario_from(map.clone(), &p).expect_err(expected);
        assert!(err.to_string().contains(expected), "{p:?}: {err}");
    }
    let bad_radius = Placement {
        goal_radius: -1.0,
        ..placement(Some([1.0, 1.0]), Some([5.0, 5.0]))
    };
    assert!(scenario_from(map.clone(), &bad_radius).is_err());
    let bad_scale = ImportOptions {
        scale: 0.0,
        ..ImportOptions::default()
    };
    assert!(import_map(&path, &bad_scale).is_err());
}

/// Random small grids, with headers that may lie about their size and values that may be
/// anything: an import returns a map or an error, never panics (fixed seed: reproducible).
#[test]
fn random_small_ascii_grids_never_panic() {
    let config = Config {
        cases: 256,
        failure_persistence: None,
        ..Config::default()
    };
    let mut runner =
        TestRunner::new_with_rng(config, TestRng::from_seed(RngAlgorithm::ChaCha, &[19; 32]));
    let token = prop_oneof![
        (-100.0f64..100.0).prop_map(|v| format!("{v}")),
        Just("-9999".to_string()),
        Just("nan".to_string()),
        Just("inf".to_string()),
        Just("x".to_string()),
        Just("1e39".to_string()),
    ];
    let grid = (
        0usize..6,
        0usize..6,
        -3i32..3,
        prop_oneof![Just(-1.0), Just(0.0), 0.01f64..10.0, Just(f64::NAN)],
        proptest::option::of(prop_oneof![Just(-9999.0), Just(0.0)]),
        proptest::collection::vec(token, 0..40),
        proptest::option::of((0usize..4, 0usize..4, 0usize..6, 0usize..6)),
        proptest::option::of(prop_oneof![0.05f64..5.0, Just(0.0)]),
        prop_oneof![Just(1.0), 0.01f64..2.0],
    );
    let dir = tempfile::tempdir().expect("tempdir");
    runner
        .run(
            &grid,
            |(ncols, nrows, extra, cell, nodata, tokens, crop, cell_size, scale)| {
                let mut text = format!(
                    "ncols {ncols}\nnrows {nrows}\nxllcorner 0\nyllcorner 0\ncellsize {cell}\n"
                );
                if let Some(nd) = nodata {
                    text += &format!("NODATA_value {nd}\n");
                }
                let count = ((ncols * nrows) as i32 + extra).max(0) as usize;
                for i in 0..count {
                    text += tokens.get(i).map_or("1", String::as_str);
                    text.push(' ');
                }
                let path = write(dir.path(), "random.asc", text);
                let options = ImportOptions {
                    crop: crop.map(|(column0, row0, column1, row1)| Crop::Cells {
                        column0,
                        row0,
                        column1,
                        row1,
                    }),
                    resolution: cell_size.map_or(Resolution::Source, Resolution::CellSize),
                    scale,
                    max_cells: 10_000,
                    ..ImportOptions::default()
                };
                if let Ok(imported) = import_map(&path, &options) {
                    prop_assert!(imported.map.validate().is_ok());
                    prop_assert!(imported.map.heights.iter().all(|h| *h >= 0.0));
                }
                Ok(())
            },
        )
        .expect("no panics, valid maps");
}

#[test]
fn elevations_below_zero_are_refused_only_when_kept() {
    let dir = tempfile::tempdir().expect("tempdir");
    // A shore: 4 m below sea level to 6 m above.
    let dem = Dem::from_fn(6, 5, 0.0, 0.0, 1.0, |x, _| 2.0 * x - 4.0);
    let path = dir.path().join("shore.asc");
    dem.write_asc(&path, None);
    let keep = ImportOptions {
        keep_elevation: true,
        ..ImportOptions::default()
    };
    let err = import_map(&path, &keep)
        .map(|m| m.map.len())
        .expect_err("kept below 0");
    assert!(err.to_string().contains("below 0 m"), "{err}");
    let shifted = import_map(&path, &ImportOptions::default()).expect("shifted to 0 m");
    let lowest = shifted
        .map
        .heights
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min);
    assert_eq!(lowest, 0.0);
}
