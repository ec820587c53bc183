//! GeoTIFF elevation rasters through the pure-Rust `tiff` crate.
//!
//! - one band (SamplesPerPixel = 1) of u8/u16/u32, i8/i16/i32 or f32/f64 samples, in strips or
//!   tiles, uncompressed, deflate or LZW; only the strips or tiles that meet the crop are decoded;
//! - geometry from ModelPixelScaleTag (33550) and ModelTiepointTag (33922), or from an
//!   axis-aligned ModelTransformationTag (34264); GTRasterTypeGeoKey = PixelIsPoint shifts the
//!   tie point from a cell corner to a cell centre;
//! - nodata from GDAL_NODATA (42113, text such as "-9999" or "nan");
//! - no georeferencing, or geographic (degree) coordinates: the cell size must be given
//!   (`source_cell_size`), because a slope needs metres along both axes.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use tiff::decoder::{ChunkType, Decoder, DecodingResult, Limits};
use tiff::tags::Tag;
use tiff::TiffError;

use super::raster::WindowSink;
use super::raster::{elevation, CellWindow, Crop, Raster, RasterGeometry};
use crate::error::PlanError;
use crate::io::{format_error, io_error};

/// Largest strip or tile decoded at once, bytes.
const MAX_CHUNK_BYTES: usize = 256 << 20;
/// GeoKey ids (GeoTIFF 1.1, section 7.4).
const GT_MODEL_TYPE_GEO_KEY: u16 = 1024;
const GT_RASTER_TYPE_GEO_KEY: u16 = 1025;
const MODEL_TYPE_GEOGRAPHIC: u16 = 2;
const RASTER_PIXEL_IS_POINT: u16 = 2;

/// Reads the first image of a GeoTIFF: the whole raster's geometry and the elevations of
/// `crop` (all without one), at most `max_cells` cells. `source_cell_size` replaces the file's
/// cell size (required when it has none or it is in degrees). Warnings go to `warnings`.
pub fn read_geotiff(
    path: &Path,
    crop: Option<&Crop>,
    max_cells: usize,
    source_cell_size: Option<f64>,
    warnings: &mut Vec<String>,
) -> Result<(RasterGeometry, Raster), PlanError> {
    let file = File::open(path).map_err(|e| io_error(path, e))?;
    let tiff_error = |what: &str, e: TiffError| format_error(path, format!("{what}: {e}"));
    let mut limits = Limits::default();
    limits.decoding_buffer_size = MAX_CHUNK_BYTES;
    let mut decoder = Decoder::new(BufReader::new(file))
        .map_err(|e| tiff_error("not a readable TIFF", e))?
        .with_limits(limits);
    let (width, height) = decoder
        .dimensions()
        .map_err(|e| tiff_error("image size", e))?;
    let samples = tag_u64(&mut decoder, Tag::SamplesPerPixel, path)?.unwrap_or(1);
    if samples != 1 {
        return Err(format_error(
            path,
            format!(
                "SamplesPerPixel = {samples}: {samples} bands, a single-band elevation raster is \
                 expected (extract one, e.g. gdal_translate -b 1)"
            ),
        ));
    }
    let sample = SampleKind::of(&mut decoder, path)?;
    let geometry = georeference(
        &mut decoder,
        width as usize,
        height as usize,
        source_cell_size,
        path,
        warnings,
    )?;
    geometry.validate(path)?;
    let nodata = gdal_nodata(&mut decoder, sample, path)?;
    let window = CellWindow::resolve(&geometry, crop, max_cells, path)?;
    let mut sink = WindowSink::new(window);
    read_window(&mut decoder, &geometry, nodata, &mut sink, path)?;
    Ok((geometry, sink.finish(&geometry)))
}

/// A supported sample type.
#[derive(Debug, Clone, Copy, PartialEq)]
enum SampleKind {
    Unsigned(u16),
    Signed(u16),
    Float(u16),
}

impl SampleKind {
    fn of(decoder: &mut Decoder<BufReader<File>>, path: &Path) -> Result<Self, PlanError> {
        let bits = tag_u64(decoder, Tag::BitsPerSample, path)?.unwrap_or(1);
        let format = tag_u64(decoder, Tag::SampleFormat, path)?.unwrap_or(1);
        let kind = match (format, bits) {
            (1, 8 | 16 | 32) => SampleKind::Unsigned(bits as u16),
            (2, 8 | 16 | 32) => SampleKind::Signed(bits as u16),
            (3, 32 | 64) => SampleKind::Float(bits as u16),
            _ => {
                let name = match format {
                    1 => "unsigned integer",
                    2 => "signed integer",
                    3 => "floating point",
                    4 => "untyped",
                    5 => "complex integer",
                    6 => "complex floating point",
                    _ => "unknown",
                };
                return Err(format_error(
                    path,
                    format!(
                        "unsupported samples: SampleFormat {format} ({name}) of {bits} bits \
                         (supported: 8/16/32-bit integers, 32/64-bit floats)"
                    ),
                ));
            }
        };
        Ok(kind)
    }

    /// `value` rounded to what a sample of this kind can hold (GDAL writes nodata as text).
    fn representable(self, value: f64) -> f64 {
        match self {
            SampleKind::Float(32) => value as f32 as f64,
            SampleKind::Float(_) => value,
            SampleKind::Unsigned(_) | SampleKind::Signed(_) => value.round(),
        }
    }
}

/// The first value of a numeric tag, if present.
fn tag_u64(
    decoder: &mut Decoder<BufReader<File>>,
    tag: Tag,
    path: &Path,
) -> Result<Option<u64>, PlanError> {
    let values = decoder
        .find_tag_unsigned_vec::<u64>(tag)
        .map_err(|e| format_error(path, format!("tag {tag:?}: {e}")))?;
    Ok(values.and_then(|v| v.first().copied()))
}

fn tag_f64s(
    decoder: &mut Decoder<BufReader<File>>,
    tag: Tag,
    path: &Path,
) -> Result<Option<Vec<f64>>, PlanError> {
    let value = decoder
        .find_tag(tag)
        .map_err(|e| format_error(path, format!("tag {tag:?}: {e}")))?;
    value
        .map(|v| v.into_f64_vec())
        .transpose()
        .map_err(|e| format_error(path, format!("tag {tag:?} is not a list of numbers: {e}")))
}

/// GeoKey `key` of the GeoKeyDirectoryTag, when stored inline (as every short-valued key is).
fn geo_key(directory: &[u16], key: u16) -> Option<u16> {
    let count = usize::from(*directory.get(3)?);
    directory
        .get(4..)?
        .chunks_exact(4)
        .take(count)
        .find(|entry| entry[0] == key && entry[1] == 0)
        .map(|entry| entry[3])
}

/// The raster's lower-left corner and cell sizes from the GeoTIFF tags.
fn georeference(
    decoder: &mut Decoder<BufReader<File>>,
    columns: usize,
    rows: usize,
    source_cell_size: Option<f64>,
    path: &Path,
    warnings: &mut Vec<String>,
) -> Result<RasterGeometry, PlanError> {
    let keys = match decoder
        .find_tag(Tag::GeoKeyDirectoryTag)
        .map_err(|e| format_error(path, format!("GeoKeyDirectoryTag: {e}")))?
    {
        Some(value) => value.into_u16_vec().map_err(|e| {
            format_error(
                path,
                format!("GeoKeyDirectoryTag is not a list of shorts: {e}"),
            )
        })?,
        None => Vec::new(),
    };
    let geographic = geo_key(&keys, GT_MODEL_TYPE_GEO_KEY) == Some(MODEL_TYPE_GEOGRAPHIC);
    let pixel_is_point = geo_key(&keys, GT_RASTER_TYPE_GEO_KEY) == Some(RASTER_PIXEL_IS_POINT);
    let scale = tag_f64s(decoder, Tag::ModelPixelScaleTag, path)?;
    let tiepoint = tag_f64s(decoder, Tag::ModelTiepointTag, path)?;
    let transform = tag_f64s(decoder, Tag::ModelTransformationTag, path)?;
    // (x of raster point (0, 0), y of raster point (0, 0), dx, dy); y decreases down the rows.
    let placed = match (scale, tiepoint, transform) {
        (Some(scale), tie, _) => {
            let [sx, sy, ..] = scale[..] else {
                return Err(format_error(
                    path,
                    format!("ModelPixelScaleTag has {} values, expected 3", scale.len()),
                ));
            };
            let (x0, y0) = match tie.as_deref() {
                Some([i, j, _, x, y, ..]) => (x - i * sx, y + j * sy),
                Some(short) => {
                    return Err(format_error(
                        path,
                        format!("ModelTiepointTag has {} values, expected 6", short.len()),
                    ))
                }
                None => (0.0, 0.0),
            };
            Some((x0, y0, sx, sy))
        }
        (None, _, Some(m)) => {
            let [a, b, _, d, e, f, _, h, ..] = m[..] else {
                return Err(format_error(
                    path,
                    format!("ModelTransformationTag has {} values, expected 16", m.len()),
                ));
            };
            if b != 0.0 || e != 0.0 || a <= 0.0 || f >= 0.0 {
                return Err(format_error(
                    path,
                    "ModelTransformationTag describes a rotated, sheared or flipped raster: only \
                     north-up rasters are supported (warp it, e.g. gdalwarp)",
                ));
            }
            Some((d, h, a, -f))
        }
        (None, _, None) => None,
    };
    let (mut west, mut north, mut dx, mut dy) = placed.unwrap_or((0.0, 0.0, 1.0, 1.0));
    if pixel_is_point {
        // The tie point is the centre of the first cell, not its corner.
        west -= dx / 2.0;
        north += dy / 2.0;
    }
    match source_cell_size {
        Some(size) => {
            if placed.is_some() {
                warnings.push(format!(
                    "--source-cell-size {size} replaces the file's cell size {dx} x {dy}"
                ));
            }
            dx = size;
            dy = size;
            if geographic || placed.is_none() {
                // Degrees or no georeference: the raster starts at (0, 0).
                west = 0.0;
                north = rows as f64 * size;
            }
        }
        None if placed.is_none() => {
            return Err(format_error(
                path,
                "no ModelPixelScaleTag or ModelTransformationTag: the cell size is unknown; give \
                 it with --source-cell-size METRES",
            ))
        }
        None if geographic => {
            return Err(format_error(
                path,
                format!(
                    "geographic coordinates (cells of {dx} x {dy} degrees): reproject to a metric \
                     CRS (e.g. gdalwarp -t_srs EPSG:32632) or give the cell size in metres with \
                     --source-cell-size"
                ),
            ))
        }
        None => {}
    }
    Ok(RasterGeometry {
        columns,
        rows,
        west,
        south: north - rows as f64 * dy,
        dx,
        dy,
    })
}

/// GDAL_NODATA (text) as a value of the raster's sample type.
fn gdal_nodata(
    decoder: &mut Decoder<BufReader<File>>,
    sample: SampleKind,
    path: &Path,
) -> Result<Option<f64>, PlanError> {
    let Some(value) = decoder
        .find_tag(Tag::GdalNodata)
        .map_err(|e| format_error(path, format!("GDAL_NODATA: {e}")))?
    else {
        return Ok(None);
    };
    let text = value
        .into_string()
        .map_err(|e| format_error(path, format!("GDAL_NODATA is not text: {e}")))?;
    let text = text.trim_matches(|c: char| c == '\0' || c.is_whitespace());
    let nodata: f64 = text
        .parse()
        .map_err(|_| format_error(path, format!("GDAL_NODATA {text:?} is not a number")))?;
    Ok(Some(sample.representable(nodata)))
}

/// Decodes the strips or tiles that meet the window and stores its cells.
fn read_window(
    decoder: &mut Decoder<BufReader<File>>,
    geometry: &RasterGeometry,
    nodata: Option<f64>,
    sink: &mut WindowSink,
    path: &Path,
) -> Result<(), PlanError> {
    let (columns, rows) = (geometry.columns, geometry.rows);
    let (chunk_width, chunk_height) = match decoder.get_chunk_type() {
        ChunkType::Strip => {
            let per_strip = tag_u64(decoder, Tag::RowsPerStrip, path)?.unwrap_or(rows as u64);
            (columns, (per_strip as usize).clamp(1, rows))
        }
        ChunkType::Tile => {
            let tile_width = tag_u64(decoder, Tag::TileWidth, path)?.unwrap_or(0) as usize;
            let tile_length = tag_u64(decoder, Tag::TileLength, path)?.unwrap_or(0) as usize;
            if tile_width == 0 || tile_length == 0 {
                return Err(format_error(
                    path,
                    format!("tiles of {tile_width} x {tile_length} cells"),
                ));
            }
            (tile_width, tile_length)
        }
    };
    let across = columns.div_ceil(chunk_width);
    let (want_rows, want_columns) = (sink.rows(), sink.columns());
    for chunk_row in want_rows.start / chunk_height..want_rows.end.div_ceil(chunk_height) {
        for chunk_column in want_columns.start / chunk_width..want_columns.end.div_ceil(chunk_width)
        {
            let index = chunk_row * across + chunk_column;
            let (x0, y0) = (chunk_column * chunk_width, chunk_row * chunk_height);
            let data_width = chunk_width.min(columns - x0);
            let data_height = chunk_height.min(rows - y0);
            let chunk = u32::try_from(index)
                .map_err(|_| format_error(path, format!("chunk index {index} overflows")))
                .and_then(|i| {
                    decoder.read_chunk(i).map_err(|e| {
                        format_error(path, format!("strip/tile {index} (rows from {y0}): {e}"))
                    })
                })?;
            let values = SampleValues(&chunk);
            if values.len() != data_width * data_height {
                return Err(format_error(
                    path,
                    format!(
                        "strip/tile {index} holds {} samples, expected {data_width} x {data_height}",
                        values.len()
                    ),
                ));
            }
            for r in 0..data_height {
                for c in 0..data_width {
                    let (row, column) = (y0 + r, x0 + c);
                    let item = || format!("row {row}, column {column} (0-based, row 0 = north)");
                    let height = elevation(values.get(r * data_width + c), nodata, path, item)?;
                    sink.put(column, row, height);
                }
            }
        }
    }
    Ok(())
}

/// The samples of a decoded chunk as f64.
struct SampleValues<'a>(&'a DecodingResult);

impl SampleValues<'_> {
    fn len(&self) -> usize {
        match self.0 {
            DecodingResult::U8(v) => v.len(),
            DecodingResult::U16(v) => v.len(),
            DecodingResult::U32(v) => v.len(),
            DecodingResult::I8(v) => v.len(),
            DecodingResult::I16(v) => v.len(),
            DecodingResult::I32(v) => v.len(),
            DecodingResult::F32(v) => v.len(),
            DecodingResult::F64(v) => v.len(),
            // Excluded by SampleKind::of; a length that never matches turns into an error.
            _ => usize::MAX,
        }
    }

    fn get(&self, i: usize) -> f64 {
        match self.0 {
            DecodingResult::U8(v) => f64::from(v[i]),
            DecodingResult::U16(v) => f64::from(v[i]),
            DecodingResult::U32(v) => f64::from(v[i]),
            DecodingResult::I8(v) => f64::from(v[i]),
            DecodingResult::I16(v) => f64::from(v[i]),
            DecodingResult::I32(v) => f64::from(v[i]),
            DecodingResult::F32(v) => f64::from(v[i]),
            DecodingResult::F64(v) => v[i],
            _ => f64::NAN,
        }
    }
}
