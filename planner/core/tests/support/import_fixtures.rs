//! Elevation models written by the terrain-import tests: ESRI ASCII text, GeoTIFFs through the
//! `tiff` encoder (with the GeoTIFF tags as custom tags) and a tiled GeoTIFF built byte by byte
//! (the encoder writes strips only). Shared by the `import_*` tests here and pf-plan's `import_cli` test.
#![allow(dead_code)]

use std::fs;
use std::io::Cursor;
use std::path::Path;

use tiff::encoder::{colortype, Compression, TiffEncoder};
use tiff::tags::Tag;

/// A north-up test DEM: heights at cell centres, the file's (northern) first row first.
#[derive(Debug, Clone)]
pub struct Dem {
    pub columns: usize,
    pub rows: usize,
    pub west: f64,
    pub south: f64,
    pub cell: f64,
    /// Row-major, row 0 = north.
    pub values: Vec<f64>,
}

impl Dem {
    /// Heights `f(x, y)` at the cell centres, world coordinates.
    pub fn from_fn(
        columns: usize,
        rows: usize,
        west: f64,
        south: f64,
        cell: f64,
        f: impl Fn(f64, f64) -> f64,
    ) -> Self {
        let mut values = Vec::with_capacity(columns * rows);
        for row in 0..rows {
            let y = south + (rows - row) as f64 * cell - cell / 2.0;
            for column in 0..columns {
                let x = west + (column as f64 + 0.5) * cell;
                values.push(f(x, y));
            }
        }
        Self {
            columns,
            rows,
            west,
            south,
            cell,
            values,
        }
    }

    pub fn north(&self) -> f64 {
        self.south + self.rows as f64 * self.cell
    }

    /// ESRI ASCII text with `xllcorner`/`yllcorner` and, if given, `NODATA_value`.
    pub fn to_asc(&self, nodata: Option<f64>) -> String {
        let mut text = format!(
            "ncols {}\nnrows {}\nxllcorner {}\nyllcorner {}\ncellsize {}\n",
            self.columns, self.rows, self.west, self.south, self.cell
        );
        if let Some(nd) = nodata {
            text += &format!("NODATA_value {nd}\n");
        }
        for row in self.values.chunks(self.columns) {
            let line: Vec<String> = row.iter().map(|v| v.to_string()).collect();
            text += &line.join(" ");
            text.push('\n');
        }
        text
    }

    pub fn write_asc(&self, path: &Path, nodata: Option<f64>) {
        fs::write(path, self.to_asc(nodata)).expect("write .asc");
    }

    /// ModelPixelScaleTag and ModelTiepointTag (raster (0, 0) = the north-west corner).
    pub fn georef(&self) -> ([f64; 3], [f64; 6]) {
        (
            [self.cell, self.cell, 0.0],
            [0.0, 0.0, 0.0, self.west, self.north(), 0.0],
        )
    }
}

/// Options of [`geotiff_bytes`].
#[derive(Clone, Default)]
pub struct TiffTags<'a> {
    pub georef: Option<([f64; 3], [f64; 6])>,
    pub nodata: Option<&'a str>,
    /// GeoKeyDirectoryTag, written as given.
    pub geo_keys: Option<Vec<u16>>,
    pub rows_per_strip: Option<u32>,
    pub compression: Compression,
}

/// A one-image TIFF of `data` (row 0 = north) in strips, with the GeoTIFF tags of `tags`.
pub fn geotiff_bytes<C: colortype::ColorType>(
    width: u32,
    height: u32,
    data: &[C::Inner],
    tags: &TiffTags,
) -> Vec<u8>
where
    [C::Inner]: tiff::encoder::TiffValue,
{
    let mut cursor = Cursor::new(Vec::new());
    {
        let mut encoder = TiffEncoder::new(&mut cursor)
            .expect("encoder")
            .with_compression(tags.compression);
        let mut image = encoder.new_image::<C>(width, height).expect("image");
        if let Some((scale, tie)) = tags.georef {
            image
                .encoder()
                .write_tag(Tag::ModelPixelScaleTag, &scale[..])
                .expect("scale tag");
            image
                .encoder()
                .write_tag(Tag::ModelTiepointTag, &tie[..])
                .expect("tiepoint tag");
        }
        if let Some(keys) = &tags.geo_keys {
            image
                .encoder()
                .write_tag(Tag::GeoKeyDirectoryTag, &keys[..])
                .expect("geokeys");
        }
        if let Some(nodata) = tags.nodata {
            image
                .encoder()
                .write_tag(Tag::GdalNodata, nodata)
                .expect("nodata tag");
        }
        if let Some(rows) = tags.rows_per_strip {
            image.rows_per_strip(rows).expect("rows per strip");
        }
        image.write_data(data).expect("data");
    }
    cursor.into_inner()
}

/// A GeoKeyDirectoryTag with GTModelTypeGeoKey and GTRasterTypeGeoKey.
pub fn geo_keys(model_type: u16, raster_type: u16) -> Vec<u16> {
    vec![1, 1, 0, 2, 1024, 0, 1, model_type, 1025, 0, 1, raster_type]
}

/// A little-endian, uncompressed, tiled GeoTIFF of i16 samples (row 0 = north), tiles of
/// `tile` x `tile` cells, padded at the east and south edges, with scale and tie point.
pub fn tiled_geotiff_i16(
    width: usize,
    height: usize,
    data: &[i16],
    tile: usize,
    georef: ([f64; 3], [f64; 6]),
) -> Vec<u8> {
    let (across, down) = (width.div_ceil(tile), height.div_ceil(tile));
    let tiles = across * down;
    let mut body = Vec::new(); // everything after the 8-byte header, before the IFD
    let mut offsets = Vec::new();
    for t in 0..tiles {
        let (x0, y0) = ((t % across) * tile, (t / across) * tile);
        offsets.push(8 + body.len() as u32);
        for r in 0..tile {
            for c in 0..tile {
                let (row, column) = (y0 + r, x0 + c);
                let v = if row < height && column < width {
                    data[row * width + column]
                } else {
                    0
                };
                body.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    let tile_bytes = (tile * tile * 2) as u32;
    let mut extra = Vec::new(); // out-of-line tag values, after the body
    let extra_base = 8 + body.len() as u32;
    let mut put_extra = |bytes: &[u8]| {
        let at = extra_base + extra.len() as u32;
        extra.extend_from_slice(bytes);
        at
    };
    let longs = |v: &[u32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    let doubles = |v: &[f64]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    // A value of at most 4 bytes sits in the entry itself, a longer one is pointed to.
    let (offsets_at, counts_at) = if tiles == 1 {
        (offsets[0], tile_bytes)
    } else {
        (
            put_extra(&longs(&offsets)),
            put_extra(&longs(&vec![tile_bytes; tiles])),
        )
    };
    let scale_at = put_extra(&doubles(&georef.0));
    let tie_at = put_extra(&doubles(&georef.1));
    // (tag, type, count, value or offset); types: 3 SHORT, 4 LONG, 12 DOUBLE.
    let entries: [(u16, u16, u32, u32); 13] = [
        (256, 4, 1, width as u32),
        (257, 4, 1, height as u32),
        (258, 3, 1, 16),
        (259, 3, 1, 1),
        (262, 3, 1, 1),
        (277, 3, 1, 1),
        (322, 4, 1, tile as u32),
        (323, 4, 1, tile as u32),
        (324, 4, tiles as u32, offsets_at),
        (325, 4, tiles as u32, counts_at),
        (339, 3, 1, 2),
        (33550, 12, 3, scale_at),
        (33922, 12, 6, tie_at),
    ];
    let ifd_at = extra_base + extra.len() as u32;
    let mut bytes = b"II*\0".to_vec();
    bytes.extend_from_slice(&ifd_at.to_le_bytes());
    bytes.extend_from_slice(&body);
    bytes.extend_from_slice(&extra);
    bytes.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    for (tag, kind, count, value) in entries {
        bytes.extend_from_slice(&tag.to_le_bytes());
        bytes.extend_from_slice(&kind.to_le_bytes());
        bytes.extend_from_slice(&count.to_le_bytes());
        bytes.extend_from_slice(&value.to_le_bytes()); // SHORTs sit in the low bytes (LE)
    }
    bytes.extend_from_slice(&0u32.to_le_bytes());
    bytes
}
