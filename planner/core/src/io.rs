//! Map files: heights as `.npy` plus a JSON sidecar, readable with `numpy.load` and `json.load`.
//!
//! Format (written by `pf-plan scenario export NAME --out DIR`, read by `pf-plan plan --map`):
//! - `DIR/NAME.heights.npy`: float64 (`<f8`), C order, shape `(height, width)`, `heights[iy, ix]`
//!   is the terrain height in metres at the centre of cell `(ix, iy)`;
//! - `DIR/NAME.obstacles.npy` (only when the map has obstacles): bool (`|b1`), same shape, `true` =
//!   hard obstacle. The reader also accepts `|u1`/integer masks (non-zero = obstacle);
//! - `DIR/NAME.json`:
//!   ```json
//!   {"name": "c_shape", "seed": 3, "origin": [0.0, 0.0], "resolution": 0.125,
//!    "width": 128, "height": 128, "heights": "c_shape.heights.npy", "obstacles": null,
//!    "start": [1.5, 8.0], "start_yaw": 0.0, "goal": {"center": [14.2, 8.0], "radius": 0.5},
//!    "traversability": {"height_weight": 1.0, "slope_weight": 0.0, ...}}
//!   ```
//!   `origin` is the lower-left corner of cell (0, 0); `heights`/`obstacles` are paths relative to
//!   the JSON file; `seed` and `traversability` may be omitted (defaults apply);
//! - a scenario with a *prior* (the map the robot is given before it moves; the true map above is
//!   what its sensors reveal) adds `DIR/NAME.prior.heights.npy`, optionally
//!   `DIR/NAME.prior.obstacles.npy`, and to the sidecar
//!   `"prior": {"heights": "NAME.prior.heights.npy", "obstacles": null}`. The prior has the true
//!   map's geometry (origin, resolution, width, height); its arrays obey the same rules (same
//!   shape, files inside the sidecar's directory). Sidecars without `prior` have none.
//!
//! The `.npy` reader accepts versions 1.0–3.0 with little-endian `f8`, `f4`, `i8`, `i4`, `u1`,
//! `b1` data in C or Fortran order; anything else is a typed [`PlanError::Format`].

use std::fs;
use std::io::Read;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::PlanError;
use crate::grid::GoalRegion;
use crate::map::{GridMap, Point, MAX_MAP_CELLS};
use crate::traversability::TraversabilityParams;

const NPY_MAGIC: &[u8] = b"\x93NUMPY";

/// A map together with a planning problem on it: what a sidecar file describes.
#[derive(Debug, Clone, PartialEq)]
pub struct MapScenario {
    /// Scenario name (file stem).
    pub name: String,
    /// Seed the terrain was generated from, if it was generated.
    pub seed: Option<u64>,
    /// The terrain.
    pub map: GridMap,
    /// Start position, metres.
    pub start: Point,
    /// Heading at the start, radians.
    pub start_yaw: f64,
    /// Goal region.
    pub goal: GoalRegion,
    /// Traversability model to plan with.
    pub traversability: TraversabilityParams,
    /// What the robot knows before it moves (same geometry as `map`), when that differs from the
    /// true map; `None`: nothing is known beforehand.
    pub prior: Option<GridMap>,
}

impl MapScenario {
    /// Checks the map and, if present, that the prior is a valid map of the same geometry.
    pub fn validate(&self) -> Result<(), PlanError> {
        self.map.validate()?;
        if let Some(prior) = &self.prior {
            prior.validate()?;
            let map = &self.map;
            let same = prior.origin == map.origin
                && prior.resolution == map.resolution
                && prior.width == map.width
                && prior.height == map.height;
            if !same {
                return Err(PlanError::InvalidOption {
                    name: "prior",
                    reason: format!(
                        "the prior map ({} x {} cells of {} m at {:?}) must have the true map's \
                         geometry ({} x {} cells of {} m at {:?})",
                        prior.width,
                        prior.height,
                        prior.resolution,
                        prior.origin,
                        map.width,
                        map.height,
                        map.resolution,
                        map.origin
                    ),
                });
            }
        }
        Ok(())
    }
}

/// The sidecar's `prior` object: the prior map's arrays (its geometry is the true map's).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PriorSidecar {
    pub heights: String,
    #[serde(default)]
    pub obstacles: Option<String>,
}

/// The JSON sidecar, field for field.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sidecar {
    pub name: String,
    #[serde(default)]
    pub seed: Option<u64>,
    pub origin: Point,
    pub resolution: f64,
    pub width: usize,
    pub height: usize,
    pub heights: String,
    #[serde(default)]
    pub obstacles: Option<String>,
    pub start: Point,
    #[serde(default)]
    pub start_yaw: f64,
    pub goal: GoalRegion,
    #[serde(default)]
    pub traversability: TraversabilityParams,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prior: Option<PriorSidecar>,
}

/// Writes `DIR/NAME.json`, `DIR/NAME.heights.npy`, (with obstacles) `DIR/NAME.obstacles.npy` and
/// (with a prior) `DIR/NAME.prior.heights.npy` [+ `DIR/NAME.prior.obstacles.npy`]; returns the
/// path of the JSON file.
pub fn save_scenario(scenario: &MapScenario, dir: &Path) -> Result<PathBuf, PlanError> {
    scenario.validate()?;
    check_name(&scenario.name)?;
    fs::create_dir_all(dir).map_err(|e| io_error(dir, e))?;
    let map = &scenario.map;
    let (heights_file, obstacles_file) = write_map_arrays(map, dir, &scenario.name)?;
    let prior = match &scenario.prior {
        Some(prior) => {
            let (heights, obstacles) =
                write_map_arrays(prior, dir, &format!("{}.prior", scenario.name))?;
            Some(PriorSidecar { heights, obstacles })
        }
        None => None,
    };
    let sidecar = Sidecar {
        name: scenario.name.clone(),
        seed: scenario.seed,
        origin: map.origin,
        resolution: map.resolution,
        width: map.width,
        height: map.height,
        heights: heights_file,
        obstacles: obstacles_file,
        start: scenario.start,
        start_yaw: scenario.start_yaw,
        goal: scenario.goal,
        traversability: scenario.traversability,
        prior,
    };
    let json_path = dir.join(format!("{}.json", scenario.name));
    let text = serde_json::to_string_pretty(&sidecar).map_err(|e| format_error(&json_path, e))?;
    fs::write(&json_path, text + "\n").map_err(|e| io_error(&json_path, e))?;
    Ok(json_path)
}

/// Writes `DIR/STEM.heights.npy` and (with obstacles) `DIR/STEM.obstacles.npy`; returns their
/// file names.
fn write_map_arrays(
    map: &GridMap,
    dir: &Path,
    stem: &str,
) -> Result<(String, Option<String>), PlanError> {
    let heights_file = format!("{stem}.heights.npy");
    write_npy_f64(
        &dir.join(&heights_file),
        (map.height, map.width),
        &map.heights,
    )?;
    let obstacles_file = match &map.obstacles {
        Some(mask) => {
            let file = format!("{stem}.obstacles.npy");
            write_npy_bool(&dir.join(&file), (map.height, map.width), mask)?;
            Some(file)
        }
        None => None,
    };
    Ok((heights_file, obstacles_file))
}

/// Largest sidecar accepted, bytes (a real one is a few hundred bytes).
pub const MAX_SIDECAR_BYTES: u64 = 1 << 20;

/// Reads a sidecar and its arrays, and checks every invariant (shapes, finite values, start/goal
/// finite), refusing maps of more than [`MAX_MAP_CELLS`] cells before their data is read.
pub fn load_scenario(json_path: &Path) -> Result<MapScenario, PlanError> {
    load_scenario_limited(json_path, MAX_MAP_CELLS)
}

/// [`load_scenario`] with a lower cell limit (at most [`MAX_MAP_CELLS`]).
///
/// The arrays must be files in the sidecar's own directory (a relative path without `..`): a
/// sidecar is data and must not be able to point the reader at other files.
pub fn load_scenario_limited(json_path: &Path, max_cells: usize) -> Result<MapScenario, PlanError> {
    let max_cells = max_cells.min(MAX_MAP_CELLS);
    let text = read_limited(json_path, MAX_SIDECAR_BYTES, "a map sidecar")?;
    let sidecar: Sidecar = serde_json::from_str(&text).map_err(|e| format_error(json_path, e))?;
    let too_large = sidecar
        .width
        .checked_mul(sidecar.height)
        .map_or(true, |n| n > max_cells);
    if too_large {
        return Err(format_error(
            json_path,
            format!(
                "map of {} x {} cells exceeds the limit of {max_cells} cells",
                sidecar.width, sidecar.height
            ),
        ));
    }
    let map = read_map_arrays(
        json_path,
        &sidecar,
        &sidecar.heights,
        sidecar.obstacles.as_deref(),
        max_cells,
        "",
    )?;
    let prior = match &sidecar.prior {
        Some(prior) => Some(read_map_arrays(
            json_path,
            &sidecar,
            &prior.heights,
            prior.obstacles.as_deref(),
            max_cells,
            "prior ",
        )?),
        None => None,
    };
    let finite = |p: Point| p[0].is_finite() && p[1].is_finite();
    if !finite(sidecar.start) || !sidecar.start_yaw.is_finite() {
        return Err(PlanError::Format {
            path: json_path.display().to_string(),
            reason: "start and start_yaw must be finite".into(),
        });
    }
    if !(finite(sidecar.goal.center)
        && sidecar.goal.radius.is_finite()
        && sidecar.goal.radius >= 0.0)
    {
        return Err(PlanError::Format {
            path: json_path.display().to_string(),
            reason: "goal centre must be finite and its radius finite and >= 0".into(),
        });
    }
    sidecar.traversability.validate()?;
    Ok(MapScenario {
        name: sidecar.name,
        seed: sidecar.seed,
        map,
        start: sidecar.start,
        start_yaw: sidecar.start_yaw,
        goal: sidecar.goal,
        traversability: sidecar.traversability,
        prior,
    })
}

/// The map of a sidecar's geometry with the arrays in `heights_file` [+ `obstacles_file`], each
/// confined to the sidecar's directory and of the sidecar's shape. `what` ("" or "prior ") names
/// the map in errors.
fn read_map_arrays(
    json_path: &Path,
    sidecar: &Sidecar,
    heights_file: &str,
    obstacles_file: Option<&str>,
    max_cells: usize,
    what: &str,
) -> Result<GridMap, PlanError> {
    let dir = json_path.parent().unwrap_or(Path::new("."));
    let expect_shape = |array: &NpyArray, path: &Path| {
        if array.shape != (sidecar.height, sidecar.width) {
            return Err(PlanError::Format {
                path: path.display().to_string(),
                reason: format!(
                    "{what}array shape {:?} does not match the sidecar's (height, width) = ({}, {})",
                    array.shape, sidecar.height, sidecar.width
                ),
            });
        }
        Ok(())
    };
    let heights_path = array_path(json_path, dir, heights_file, what)?;
    let heights = read_npy_limited(&heights_path, max_cells)?;
    expect_shape(&heights, &heights_path)?;
    let obstacles = match obstacles_file {
        Some(file) => {
            let path = array_path(json_path, dir, file, what)?;
            let mask = read_npy_limited(&path, max_cells)?;
            expect_shape(&mask, &path)?;
            Some(mask.values.iter().map(|&v| v != 0.0).collect())
        }
        None => None,
    };
    Ok(GridMap::new(
        sidecar.origin,
        sidecar.resolution,
        sidecar.width,
        sidecar.height,
        heights.values,
        obstacles,
    )?)
}

/// Largest path CSV accepted, bytes (a 10-minute walk logged at 1 kHz is about 40 MB).
pub const MAX_PATH_CSV_BYTES: u64 = 256 << 20;

/// The polyline of a CSV file with a header line naming columns `x` and `y` (others, such as
/// `pf-plan plan`'s `t,x,y,z,yaw,...`, are ignored). `source` names the file in errors. Every
/// value must be a finite number and the path must have at least one point.
pub fn parse_path_csv(text: &str, source: &str) -> Result<Vec<Point>, PlanError> {
    let bad = |reason: String| PlanError::Format {
        path: source.to_string(),
        reason,
    };
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let (_, header) = lines
        .next()
        .ok_or_else(|| bad("empty: expected a header line with columns x and y".into()))?;
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    let column = |name: &str| {
        names.iter().position(|&n| n == name).ok_or_else(|| {
            bad(format!(
                "the header {header:?} has no column {name:?} (expected e.g. \"x,y\")"
            ))
        })
    };
    let (cx, cy) = (column("x")?, column("y")?);
    let mut path = Vec::new();
    for (index, line) in lines {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != names.len() {
            return Err(bad(format!(
                "line {}: {} fields, the header has {}",
                index + 1,
                fields.len(),
                names.len()
            )));
        }
        let value = |c: usize| {
            let v: f64 = fields[c].parse().map_err(|_| {
                bad(format!(
                    "line {}: {} = {:?} is not a number",
                    index + 1,
                    names[c],
                    fields[c]
                ))
            })?;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(bad(format!(
                    "line {}: {} = {v} is not finite",
                    index + 1,
                    names[c]
                )))
            }
        };
        path.push([value(cx)?, value(cy)?]);
    }
    if path.is_empty() {
        return Err(bad("the path has no points".into()));
    }
    Ok(path)
}

/// [`parse_path_csv`] of a file (at most [`MAX_PATH_CSV_BYTES`]).
pub fn read_path_csv(path: &Path) -> Result<Vec<Point>, PlanError> {
    let text = read_limited(path, MAX_PATH_CSV_BYTES, "a path CSV")?;
    parse_path_csv(&text, &path.display().to_string())
}

/// A 2-D array read from `.npy`, converted to f64, in C (row-major) order.
#[derive(Debug, Clone, PartialEq)]
pub struct NpyArray {
    /// (rows, columns).
    pub shape: (usize, usize),
    /// Row-major values.
    pub values: Vec<f64>,
}

/// Writes a 2-D float64 array (`<f8`, C order).
pub fn write_npy_f64(path: &Path, shape: (usize, usize), data: &[f64]) -> Result<(), PlanError> {
    fs::write(path, npy_f64_bytes(&[shape.0, shape.1], data)).map_err(|e| io_error(path, e))
}

/// Writes a 2-D bool array (`|b1`, C order).
pub fn write_npy_bool(path: &Path, shape: (usize, usize), data: &[bool]) -> Result<(), PlanError> {
    let mut bytes = npy_header("|b1", &[shape.0, shape.1]);
    bytes.extend(data.iter().map(|&b| u8::from(b)));
    fs::write(path, bytes).map_err(|e| io_error(path, e))
}

/// One float64 member of an `.npz` archive: name (without `.npy`), shape, row-major values.
pub type NpzEntry<'a> = (&'a str, &'a [usize], &'a [f64]);

/// Writes a numpy `.npz` archive of float64 arrays, stored uncompressed (numpy reads both): the
/// one `.npz` writer of the planner (the feedback field's and the occupation density's).
pub fn write_npz(path: &Path, entries: &[NpzEntry<'_>]) -> Result<(), PlanError> {
    use std::io::Write;
    let file = fs::File::create(path).map_err(|e| io_error(path, e))?;
    let mut zip = zip::ZipWriter::new(std::io::BufWriter::new(file));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Stored)
        .large_file(false);
    for &(name, dims, data) in entries {
        zip.start_file(format!("{name}.npy"), options)
            .map_err(|e| io_error(path, e))?;
        zip.write_all(&npy_f64_bytes(dims, data))
            .map_err(|e| io_error(path, e))?;
    }
    zip.finish().map_err(|e| io_error(path, e))?;
    Ok(())
}

/// A whole `.npy` file (version 1.0) of little-endian float64 in C order with shape `dims` (any
/// number of dimensions; `[]` is a scalar): the one `.npy` writer of the planner (map arrays here,
/// the `.npz` members of [`write_npz`]).
pub fn npy_f64_bytes(dims: &[usize], data: &[f64]) -> Vec<u8> {
    let mut bytes = npy_header("<f8", dims);
    bytes.reserve(data.len() * 8);
    for v in data {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    bytes
}

fn npy_header(descr: &str, dims: &[usize]) -> Vec<u8> {
    let shape = match dims {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            dims.iter()
                .map(usize::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let mut dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    // Version 1.0: magic (6) + version (2) + length (2) + dict padded so the data starts 64-aligned.
    let unpadded = 10 + dict.len() + 1;
    dict.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    dict.push('\n');
    let mut bytes = Vec::with_capacity(10 + dict.len());
    bytes.extend_from_slice(NPY_MAGIC);
    bytes.extend_from_slice(&[1, 0]);
    // A shape of a few dimensions is far below 64 KiB: the u16 length cannot overflow.
    bytes.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    bytes.extend_from_slice(dict.as_bytes());
    bytes
}

/// Reads a 2-D `.npy` array (see the module docs for the accepted dtypes).
pub fn read_npy(path: &Path) -> Result<NpyArray, PlanError> {
    read_npy_limited(path, MAX_MAP_CELLS)
}

/// Reads a 2-D `.npy` array of at most `max_cells` elements. The header is read and checked
/// first (shape against the limit, data size against the file's length), so an oversize or
/// inconsistent file is refused without reading its data.
pub fn read_npy_limited(path: &Path, max_cells: usize) -> Result<NpyArray, PlanError> {
    let format = |reason: String| PlanError::Format {
        path: path.display().to_string(),
        reason,
    };
    let mut file = fs::File::open(path).map_err(|e| io_error(path, e))?;
    let file_len = file.metadata().map_err(|e| io_error(path, e))?.len();
    let mut prefix = Vec::with_capacity(NPY_PREFIX_LEN);
    (&mut file)
        .take(NPY_PREFIX_LEN as u64)
        .read_to_end(&mut prefix)
        .map_err(|e| io_error(path, e))?;
    let (header_start, header_len) = npy_header_extent(&prefix).map_err(format)?;
    if header_len > MAX_NPY_HEADER_BYTES {
        return Err(format(format!(
            "header of {header_len} bytes exceeds {MAX_NPY_HEADER_BYTES}"
        )));
    }
    let mut head = prefix;
    (&mut file)
        .take((header_start + header_len).saturating_sub(head.len()) as u64)
        .read_to_end(&mut head)
        .map_err(|e| io_error(path, e))?;
    let header = parse_npy_header(&head, max_cells).map_err(format)?;
    let expected = header.data_start as u64 + header.data_bytes() as u64;
    if file_len != expected {
        return Err(format(format!(
            "file has {file_len} bytes, expected {expected} for shape {:?} of {}",
            header.shape, header.descr
        )));
    }
    let mut bytes = head;
    bytes.truncate(header.data_start);
    bytes.reserve_exact(header.data_bytes());
    file.read_to_end(&mut bytes)
        .map_err(|e| io_error(path, e))?;
    npy_values(&header, &bytes[header.data_start..]).map_err(format)
}

/// Bytes of an `.npy` file that hold the magic, the version and the header length.
const NPY_PREFIX_LEN: usize = 12;
/// Largest `.npy` header accepted (numpy writes 64–128 bytes).
const MAX_NPY_HEADER_BYTES: usize = 64 * 1024;

/// A parsed `.npy` header.
struct NpyHeader {
    descr: &'static str,
    item: usize,
    fortran: bool,
    shape: (usize, usize),
    data_start: usize,
}

impl NpyHeader {
    fn data_bytes(&self) -> usize {
        // Bounded by the cell limit times 8: no overflow.
        self.shape.0 * self.shape.1 * self.item
    }
}

/// `(header start, header length)` from the first bytes of an `.npy` file.
fn npy_header_extent(bytes: &[u8]) -> Result<(usize, usize), String> {
    if bytes.len() < 10 || &bytes[..6] != NPY_MAGIC {
        return Err("not an .npy file (bad magic)".into());
    }
    match bytes[6] {
        1 => Ok((10, u16::from_le_bytes([bytes[8], bytes[9]]) as usize)),
        2 | 3 if bytes.len() >= 12 => Ok((
            12,
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
        )),
        v => Err(format!("unsupported .npy version {v}")),
    }
}

/// Parses the header at the start of `bytes` (which must hold all of it).
fn parse_npy_header(bytes: &[u8], max_cells: usize) -> Result<NpyHeader, String> {
    let (header_start, header_len) = npy_header_extent(bytes)?;
    let data_start = header_start
        .checked_add(header_len)
        .filter(|&end| end <= bytes.len())
        .ok_or("truncated .npy header")?;
    let header =
        std::str::from_utf8(&bytes[header_start..data_start]).map_err(|_| "header is not text")?;
    let descr = dict_value(header, "descr").ok_or("header has no 'descr'")?;
    let descr = descr.trim_matches(|c| c == '\'' || c == '"');
    let fortran = dict_value(header, "fortran_order").ok_or("header has no 'fortran_order'")?;
    let fortran = match fortran.trim() {
        "True" => true,
        "False" => false,
        other => return Err(format!("bad fortran_order {other}")),
    };
    let shape_text = dict_value(header, "shape").ok_or("header has no 'shape'")?;
    let dims: Vec<usize> = shape_text
        .trim_matches(|c| c == '(' || c == ')')
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse::<usize>()
                .map_err(|_| format!("bad shape {shape_text}"))
        })
        .collect::<Result<_, _>>()?;
    let [rows, cols] = dims[..] else {
        return Err(format!("expected a 2-D array, got shape {shape_text}"));
    };
    let max_cells = max_cells.min(MAX_MAP_CELLS);
    rows.checked_mul(cols)
        .filter(|&n| n <= max_cells)
        .ok_or(format!(
            "array of shape ({rows}, {cols}) exceeds {max_cells} cells"
        ))?;
    let (descr, item) = match descr {
        "<f8" => ("<f8", 8),
        "<i8" => ("<i8", 8),
        "<f4" => ("<f4", 4),
        "<i4" => ("<i4", 4),
        "|u1" | "<u1" => ("|u1", 1),
        "|b1" | "<b1" => ("|b1", 1),
        other => {
            return Err(format!(
                "unsupported dtype {other} (expected <f8, <f4, <i8, <i4, |u1 or |b1)"
            ))
        }
    };
    Ok(NpyHeader {
        descr,
        item,
        fortran,
        shape: (rows, cols),
        data_start,
    })
}

/// The values of `data` (exactly the array's bytes) in C order, as f64.
fn npy_values(header: &NpyHeader, data: &[u8]) -> Result<NpyArray, String> {
    let (rows, cols) = header.shape;
    let count = rows * cols;
    if data.len() != header.data_bytes() {
        return Err(format!(
            "data has {} bytes, expected {} for shape ({rows}, {cols}) of {}",
            data.len(),
            header.data_bytes(),
            header.descr
        ));
    }
    let raw: Vec<f64> = data
        .chunks_exact(header.item)
        .map(|c| match header.descr {
            "<f8" => f64::from_le_bytes(c.try_into().unwrap_or([0; 8])),
            "<i8" => i64::from_le_bytes(c.try_into().unwrap_or([0; 8])) as f64,
            "<f4" => f32::from_le_bytes(c.try_into().unwrap_or([0; 4])) as f64,
            "<i4" => i32::from_le_bytes(c.try_into().unwrap_or([0; 4])) as f64,
            _ => c[0] as f64,
        })
        .collect();
    let values = if header.fortran {
        let mut v = vec![0.0; count];
        for c in 0..cols {
            for r in 0..rows {
                v[r * cols + c] = raw[c * rows + r];
            }
        }
        v
    } else {
        raw
    };
    Ok(NpyArray {
        shape: (rows, cols),
        values,
    })
}

/// Parses the bytes of a whole 2-D `.npy` file.
pub fn parse_npy(bytes: &[u8]) -> Result<NpyArray, String> {
    let header = parse_npy_header(bytes, MAX_MAP_CELLS)?;
    npy_values(&header, &bytes[header.data_start..])
}

/// A sidecar's array file: a relative path inside the sidecar's directory (no `..`, no root).
/// `what` ("" or "prior ") names the map the file belongs to in the error.
fn array_path(json_path: &Path, dir: &Path, file: &str, what: &str) -> Result<PathBuf, PlanError> {
    let relative = Path::new(file);
    let inside = !file.is_empty()
        && relative
            .components()
            .all(|c| matches!(c, std::path::Component::Normal(_)));
    if inside {
        Ok(dir.join(relative))
    } else {
        Err(format_error(
            json_path,
            format!(
                "{what}array file {file:?} must be a relative path inside the sidecar's directory"
            ),
        ))
    }
}

/// Reads a text file of at most `max_bytes`.
fn read_limited(path: &Path, max_bytes: u64, what: &str) -> Result<String, PlanError> {
    let file = fs::File::open(path).map_err(|e| io_error(path, e))?;
    let mut text = String::new();
    file.take(max_bytes + 1)
        .read_to_string(&mut text)
        .map_err(|e| io_error(path, e))?;
    if text.len() as u64 > max_bytes {
        return Err(format_error(
            path,
            format!("larger than {max_bytes} bytes: not {what}"),
        ));
    }
    Ok(text)
}

/// The raw text of `key`'s value in a Python dict literal (shape tuples kept whole).
fn dict_value<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let key_pos = header
        .find(&format!("'{key}'"))
        .or_else(|| header.find(&format!("\"{key}\"")))?;
    let rest = &header[key_pos + key.len() + 2..];
    let rest = rest.trim_start().strip_prefix(':')?.trim_start();
    let end = if rest.starts_with('(') {
        rest.find(')')? + 1
    } else {
        rest.find([',', '}'])?
    };
    Some(rest[..end].trim())
}

fn check_name(name: &str) -> Result<(), PlanError> {
    let ok = !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if ok {
        Ok(())
    } else {
        Err(PlanError::InvalidOption {
            name: "scenario name",
            reason: format!("{name:?}: use letters, digits, '_' or '-'"),
        })
    }
}

pub(crate) fn io_error(path: &Path, e: impl std::fmt::Display) -> PlanError {
    PlanError::Io {
        path: path.display().to_string(),
        reason: e.to_string(),
    }
}

pub(crate) fn format_error(path: &Path, e: impl std::fmt::Display) -> PlanError {
    PlanError::Format {
        path: path.display().to_string(),
        reason: e.to_string(),
    }
}

#[cfg(test)]
mod tests;
