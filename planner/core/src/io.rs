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
//!   the JSON file; `seed` and `traversability` may be omitted (defaults apply).
//!
//! The `.npy` reader accepts versions 1.0–3.0 with little-endian `f8`, `f4`, `i8`, `i4`, `u1`,
//! `b1` data in C or Fortran order; anything else is a typed [`PlanError::Format`].

use std::fs;
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
}

/// Writes `DIR/NAME.json`, `DIR/NAME.heights.npy` and (with obstacles) `DIR/NAME.obstacles.npy`;
/// returns the path of the JSON file.
pub fn save_scenario(scenario: &MapScenario, dir: &Path) -> Result<PathBuf, PlanError> {
    scenario.map.validate()?;
    check_name(&scenario.name)?;
    fs::create_dir_all(dir).map_err(|e| io_error(dir, e))?;
    let heights_file = format!("{}.heights.npy", scenario.name);
    let map = &scenario.map;
    write_npy_f64(
        &dir.join(&heights_file),
        (map.height, map.width),
        &map.heights,
    )?;
    let obstacles_file = match &map.obstacles {
        Some(mask) => {
            let file = format!("{}.obstacles.npy", scenario.name);
            write_npy_bool(&dir.join(&file), (map.height, map.width), mask)?;
            Some(file)
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
    };
    let json_path = dir.join(format!("{}.json", scenario.name));
    let text = serde_json::to_string_pretty(&sidecar).map_err(|e| format_error(&json_path, e))?;
    fs::write(&json_path, text + "\n").map_err(|e| io_error(&json_path, e))?;
    Ok(json_path)
}

/// Reads a sidecar and its arrays, and checks every invariant (shapes, finite values, start/goal finite).
pub fn load_scenario(json_path: &Path) -> Result<MapScenario, PlanError> {
    let text = fs::read_to_string(json_path).map_err(|e| io_error(json_path, e))?;
    let sidecar: Sidecar = serde_json::from_str(&text).map_err(|e| format_error(json_path, e))?;
    let dir = json_path.parent().unwrap_or(Path::new("."));
    let heights_path = dir.join(&sidecar.heights);
    let heights = read_npy(&heights_path)?;
    let expect_shape = |array: &NpyArray, path: &Path| {
        if array.shape != (sidecar.height, sidecar.width) {
            return Err(PlanError::Format {
                path: path.display().to_string(),
                reason: format!(
                    "array shape {:?} does not match the sidecar's (height, width) = ({}, {})",
                    array.shape, sidecar.height, sidecar.width
                ),
            });
        }
        Ok(())
    };
    expect_shape(&heights, &heights_path)?;
    let obstacles = match &sidecar.obstacles {
        Some(file) => {
            let path = dir.join(file);
            let mask = read_npy(&path)?;
            expect_shape(&mask, &path)?;
            Some(mask.values.iter().map(|&v| v != 0.0).collect())
        }
        None => None,
    };
    let map = GridMap::new(
        sidecar.origin,
        sidecar.resolution,
        sidecar.width,
        sidecar.height,
        heights.values,
        obstacles,
    )?;
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
    })
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
    let mut bytes = npy_header("<f8", shape);
    bytes.reserve(data.len() * 8);
    for v in data {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    fs::write(path, bytes).map_err(|e| io_error(path, e))
}

/// Writes a 2-D bool array (`|b1`, C order).
pub fn write_npy_bool(path: &Path, shape: (usize, usize), data: &[bool]) -> Result<(), PlanError> {
    let mut bytes = npy_header("|b1", shape);
    bytes.extend(data.iter().map(|&b| u8::from(b)));
    fs::write(path, bytes).map_err(|e| io_error(path, e))
}

fn npy_header(descr: &str, shape: (usize, usize)) -> Vec<u8> {
    let mut dict = format!(
        "{{'descr': '{descr}', 'fortran_order': False, 'shape': ({}, {}), }}",
        shape.0, shape.1
    );
    // Version 1.0: magic (6) + version (2) + length (2) + dict padded so the data starts 64-aligned.
    let unpadded = 10 + dict.len() + 1;
    dict.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    dict.push('\n');
    let mut bytes = Vec::with_capacity(10 + dict.len());
    bytes.extend_from_slice(NPY_MAGIC);
    bytes.extend_from_slice(&[1, 0]);
    bytes.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    bytes.extend_from_slice(dict.as_bytes());
    bytes
}

/// Reads a 2-D `.npy` array (see the module docs for the accepted dtypes).
pub fn read_npy(path: &Path) -> Result<NpyArray, PlanError> {
    let bytes = fs::read(path).map_err(|e| io_error(path, e))?;
    parse_npy(&bytes).map_err(|reason| PlanError::Format {
        path: path.display().to_string(),
        reason,
    })
}

/// Parses the bytes of a 2-D `.npy` file.
pub fn parse_npy(bytes: &[u8]) -> Result<NpyArray, String> {
    if bytes.len() < 10 || &bytes[..6] != NPY_MAGIC {
        return Err("not an .npy file (bad magic)".into());
    }
    let (header_len, header_start): (usize, usize) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(format!("unsupported .npy version {v}")),
    };
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
    let count = rows
        .checked_mul(cols)
        .filter(|&n| n <= MAX_MAP_CELLS)
        .ok_or(format!(
            "array of shape ({rows}, {cols}) exceeds {MAX_MAP_CELLS} cells"
        ))?;
    let item = match descr {
        "<f8" | "<i8" => 8,
        "<f4" | "<i4" => 4,
        "|u1" | "|b1" | "<u1" | "<b1" => 1,
        other => {
            return Err(format!(
                "unsupported dtype {other} (expected <f8, <f4, <i8, <i4, |u1 or |b1)"
            ))
        }
    };
    let data = &bytes[data_start..];
    if data.len() != count * item {
        return Err(format!(
            "data has {} bytes, expected {} for shape ({rows}, {cols}) of {descr}",
            data.len(),
            count * item
        ));
    }
    let raw: Vec<f64> = data
        .chunks_exact(item)
        .map(|c| match descr {
            "<f8" => f64::from_le_bytes(c.try_into().unwrap_or([0; 8])),
            "<i8" => i64::from_le_bytes(c.try_into().unwrap_or([0; 8])) as f64,
            "<f4" => f32::from_le_bytes(c.try_into().unwrap_or([0; 4])) as f64,
            "<i4" => i32::from_le_bytes(c.try_into().unwrap_or([0; 4])) as f64,
            _ => c[0] as f64,
        })
        .collect();
    let values = if fortran {
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

fn io_error(path: &Path, e: impl std::fmt::Display) -> PlanError {
    PlanError::Io {
        path: path.display().to_string(),
        reason: e.to_string(),
    }
}

fn format_error(path: &Path, e: impl std::fmt::Display) -> PlanError {
    PlanError::Format {
        path: path.display().to_string(),
        reason: e.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_is_64_byte_aligned_and_parses_back() {
        let data: Vec<f64> = (0..6).map(|i| i as f64 * 0.5 - 1.0).collect();
        let mut bytes = npy_header("<f8", (2, 3));
        assert_eq!(bytes.len() % 64, 0);
        for v in &data {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        let a = parse_npy(&bytes).expect("parse");
        assert_eq!(a.shape, (2, 3));
        assert_eq!(a.values, data);
    }

    #[test]
    fn fortran_order_and_small_dtypes_are_converted() {
        // numpy: np.asfortranarray(np.array([[1, 2, 3], [4, 5, 6]], dtype='<i4')).
        let header = "{'descr': '<i4', 'fortran_order': True, 'shape': (2, 3), }";
        let mut bytes = NPY_MAGIC.to_vec();
        bytes.extend_from_slice(&[1, 0]);
        bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
        bytes.extend_from_slice(header.as_bytes());
        for v in [1i32, 4, 2, 5, 3, 6] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        let a = parse_npy(&bytes).expect("parse");
        assert_eq!(a.values, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    }

    #[test]
    fn malformed_files_are_errors() {
        assert!(parse_npy(b"hello").is_err());
        let mut bytes = npy_header("<f8", (2, 3));
        bytes.extend_from_slice(&[0u8; 8]);
        assert!(parse_npy(&bytes).unwrap_err().contains("expected 48"));
        let bytes = npy_header("<c16", (1, 1));
        assert!(parse_npy(&bytes).unwrap_err().contains("unsupported dtype"));
        let bytes = npy_header("<f8", (1 << 40, 1 << 40));
        assert!(parse_npy(&bytes).unwrap_err().contains("exceeds"));
    }
}
