//! ESRI ASCII grid (`.asc`): a `key value` header, then `nrows` rows of `ncols` values, the
//! northernmost row first.
//!
//! Header items (case-insensitive, any order): `ncols`, `nrows`, `xllcorner` or `xllcenter`,
//! `yllcorner` or `yllcenter`, `cellsize` or both `dx` and `dy`, optional `NODATA_value`. The
//! file is read as a stream of whitespace-separated tokens, so only the crop window is stored
//! and a header that promises more or fewer values than the file holds is an error.

use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::Path;

use super::raster::{elevation, CellWindow, Crop, Raster, RasterGeometry, WindowSink};
use crate::error::PlanError;
use crate::io::{format_error, io_error};

/// Longest token accepted (a number with 17 significant digits and an exponent is ~25 bytes).
const MAX_TOKEN_BYTES: usize = 64;

/// Reads the header and the cells of `crop` (all without one), at most `max_cells` of them.
/// Returns the whole raster's geometry and the window's elevations.
pub fn read_esri_ascii(
    path: &Path,
    crop: Option<&Crop>,
    max_cells: usize,
) -> Result<(RasterGeometry, Raster), PlanError> {
    let file = File::open(path).map_err(|e| io_error(path, e))?;
    let mut tokens = Tokens::new(BufReader::new(file), path);
    let (header, first_value) = read_header(&mut tokens, path)?;
    let geometry = header.geometry;
    geometry.validate(path)?;
    let window = CellWindow::resolve(&geometry, crop, max_cells, path)?;
    let total = geometry.columns.checked_mul(geometry.rows).ok_or_else(|| {
        format_error(
            path,
            format!(
                "ncols × nrows = {} × {} overflows",
                geometry.columns, geometry.rows
            ),
        )
    })?;
    let mut sink = WindowSink::new(window);
    let mut next = Some(first_value);
    for index in 0..total {
        let token = match next.take() {
            Some(token) => token,
            None => tokens.next()?.ok_or_else(|| {
                format_error(
                    path,
                    format!(
                        "the file ends after {index} of ncols × nrows = {} × {} = {total} values \
                         (truncated, or the header claims more rows than the file holds)",
                        geometry.columns, geometry.rows
                    ),
                )
            })?,
        };
        let (row, column) = (index / geometry.columns, index % geometry.columns);
        let item = || format!("row {row}, column {column} (0-based, row 0 = first in the file)");
        let value: f64 = token
            .parse()
            .map_err(|_| format_error(path, format!("{}: {token:?} is not a number", item())))?;
        let height = elevation(value, header.nodata, path, item)?;
        sink.put(column, row, height);
    }
    if let Some(extra) = tokens.next()? {
        return Err(format_error(
            path,
            format!(
                "more data than ncols × nrows = {} × {} = {total} values (next token {extra:?}): \
                 the header does not describe the file",
                geometry.columns, geometry.rows
            ),
        ));
    }
    Ok((geometry, sink.finish(&geometry)))
}

struct Header {
    geometry: RasterGeometry,
    nodata: Option<f64>,
}

const KEYS: [&str; 10] = [
    "ncols",
    "nrows",
    "xllcorner",
    "xllcenter",
    "yllcorner",
    "yllcenter",
    "cellsize",
    "dx",
    "dy",
    "nodata_value",
];

/// The header and the first data token (the first token that is a number where a key belongs).
fn read_header(
    tokens: &mut Tokens<impl BufRead>,
    path: &Path,
) -> Result<(Header, String), PlanError> {
    let mut values: [Option<String>; KEYS.len()] = Default::default();
    let first_value = loop {
        let token = tokens
            .next()?
            .ok_or_else(|| format_error(path, "the file ends inside the header: no data values"))?;
        if token.parse::<f64>().is_ok() {
            break token;
        }
        let key = token.to_ascii_lowercase();
        let slot = KEYS.iter().position(|&k| k == key).ok_or_else(|| {
            format_error(
                path,
                format!(
                    "unknown header item {token:?} (an ESRI ASCII grid has ncols, nrows, \
                     xllcorner/xllcenter, yllcorner/yllcenter, cellsize or dx and dy, NODATA_value)"
                ),
            )
        })?;
        if values[slot].is_some() {
            return Err(format_error(
                path,
                format!("header item {token} appears twice"),
            ));
        }
        let value = tokens
            .next()?
            .ok_or_else(|| format_error(path, format!("header item {token} has no value")))?;
        values[slot] = Some(value);
    };
    let get = |key: &str| values[KEYS.iter().position(|&k| k == key).unwrap_or(0)].as_deref();
    let number = |key: &str| -> Result<Option<f64>, PlanError> {
        get(key)
            .map(|text| {
                text.parse::<f64>().map_err(|_| {
                    format_error(
                        path,
                        format!("header item {key} = {text:?} is not a number"),
                    )
                })
            })
            .transpose()
    };
    let count = |key: &str| -> Result<usize, PlanError> {
        let text =
            get(key).ok_or_else(|| format_error(path, format!("the header has no {key}")))?;
        match text.parse::<usize>() {
            Ok(n) if n > 0 => Ok(n),
            _ => Err(format_error(
                path,
                format!("header item {key} = {text:?} must be a whole number > 0"),
            )),
        }
    };
    let columns = count("ncols")?;
    let rows = count("nrows")?;
    let (dx, dy) = match (number("cellsize")?, number("dx")?, number("dy")?) {
        (Some(size), None, None) => (size, size),
        (None, Some(dx), Some(dy)) => (dx, dy),
        _ => {
            return Err(format_error(
                path,
                "the header needs cellsize, or dx and dy (not both forms)",
            ))
        }
    };
    let corner = |corner_key: &str, center_key: &str, size: f64| -> Result<f64, PlanError> {
        match (number(corner_key)?, number(center_key)?) {
            (Some(corner), None) => Ok(corner),
            (None, Some(center)) => Ok(center - size / 2.0),
            _ => Err(format_error(
                path,
                format!("the header needs exactly one of {corner_key} and {center_key}"),
            )),
        }
    };
    let west = corner("xllcorner", "xllcenter", dx)?;
    let south = corner("yllcorner", "yllcenter", dy)?;
    let nodata = number("nodata_value")?;
    let geometry = RasterGeometry {
        columns,
        rows,
        west,
        south,
        dx,
        dy,
    };
    Ok((Header { geometry, nodata }, first_value))
}

/// Whitespace-separated tokens of a byte stream, each at most [`MAX_TOKEN_BYTES`] of UTF-8.
struct Tokens<'p, R: BufRead> {
    bytes: std::io::Bytes<R>,
    path: &'p Path,
    offset: u64,
}

impl<'p, R: BufRead> Tokens<'p, R> {
    fn new(reader: R, path: &'p Path) -> Self {
        Self {
            bytes: reader.bytes(),
            path,
            offset: 0,
        }
    }

    fn next(&mut self) -> Result<Option<String>, PlanError> {
        let mut token = Vec::new();
        for byte in self.bytes.by_ref() {
            let byte = byte.map_err(|e| io_error(self.path, e))?;
            self.offset += 1;
            if byte.is_ascii_whitespace() {
                if token.is_empty() {
                    continue;
                }
                break;
            }
            if token.len() == MAX_TOKEN_BYTES {
                return Err(format_error(
                    self.path,
                    format!(
                        "a token longer than {MAX_TOKEN_BYTES} bytes at byte {}: not an ESRI \
                         ASCII grid",
                        self.offset
                    ),
                ));
            }
            token.push(byte);
        }
        if token.is_empty() {
            return Ok(None);
        }
        String::from_utf8(token).map(Some).map_err(|_| {
            format_error(
                self.path,
                format!(
                    "bytes before offset {} are not text: not an ESRI ASCII grid",
                    self.offset
                ),
            )
        })
    }
}
