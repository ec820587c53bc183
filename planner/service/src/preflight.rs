//! Reads the few fixed-position fields of a packet (request id, map size claims) straight from
//! the bytes, before the full decoder runs. This is what lets the service refuse a map that
//! claims more cells than `--max-map-cells` before anything is allocated for it, and answer a
//! request that fails to decode with its own id.
//!
//! Layout (lcm-gen wire format, see `lcm_types/*.lcm`): a top-level message starts with its
//! 8-byte fingerprint; `header_t` is `utime i64, seq i64, frame_id string` where a string is an
//! i32 length (counting the NUL) followed by that many bytes.

use lcm_types::pfnav::{PlanRequest, TerrainMap};
use lcm_types::Message;

/// The size claims at the start of a `terrain_map_t` (before its arrays).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MapClaim {
    /// `header.seq`.
    pub seq: i64,
    pub width: i32,
    pub height: i32,
    /// Length of the `heights` array.
    pub num_cells: i32,
}

impl MapClaim {
    /// The largest cell count the claim implies (negative values count as 0; they fail later).
    pub fn claimed_cells(&self) -> u64 {
        let non_negative = |v: i32| u64::try_from(v).unwrap_or(0);
        (non_negative(self.width) * non_negative(self.height)).max(non_negative(self.num_cells))
    }
}

/// What could be read from the front of a `plan_request_t` packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RequestPeek {
    /// `request_id`, when the packet is long enough to hold it.
    pub request_id: Option<i64>,
    /// The size claims of the inline map, when there is one and they are readable.
    pub inline_map: Option<MapClaim>,
}

/// Bounds-checked big-endian reads; every failure is `None` (the packet is too short).
struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let end = self.pos.checked_add(n)?;
        let slice = self.bytes.get(self.pos..end)?;
        self.pos = end;
        Some(slice)
    }
    fn i8(&mut self) -> Option<i8> {
        self.take(1).map(|b| i8::from_be_bytes([b[0]]))
    }
    fn i32(&mut self) -> Option<i32> {
        self.take(4)?.try_into().ok().map(i32::from_be_bytes)
    }
    fn i64(&mut self) -> Option<i64> {
        self.take(8)?.try_into().ok().map(i64::from_be_bytes)
    }
    fn skip(&mut self, n: usize) -> Option<()> {
        self.take(n).map(|_| ())
    }
    /// Skips `header_t` and returns its `seq`.
    fn header(&mut self) -> Option<i64> {
        self.skip(8)?; // utime
        let seq = self.i64()?;
        let len = usize::try_from(self.i32()?).ok()?;
        self.skip(len)?;
        Some(seq)
    }
    /// Reads the claims of a `terrain_map_t` body (no fingerprint).
    fn map_claim(&mut self) -> Option<MapClaim> {
        let seq = self.header()?;
        self.skip(3 * 8)?; // origin_x, origin_y, resolution
        Some(MapClaim {
            seq,
            width: self.i32()?,
            height: self.i32()?,
            num_cells: self.i32()?,
        })
    }
}

fn has_fingerprint(bytes: &[u8], fingerprint: u64) -> bool {
    bytes.get(..8) == Some(&fingerprint.to_be_bytes()[..])
}

/// The size claims of a published `terrain_map_t`, or `None` if the packet is not one (wrong
/// fingerprint) or too short to hold them.
pub fn peek_map(bytes: &[u8]) -> Option<MapClaim> {
    if !has_fingerprint(bytes, TerrainMap::FINGERPRINT) {
        return None;
    }
    Cursor { bytes, pos: 8 }.map_claim()
}

/// What the front of a `plan_request_t` says, or `None` for another type (wrong fingerprint).
pub fn peek_request(bytes: &[u8]) -> Option<RequestPeek> {
    if !has_fingerprint(bytes, PlanRequest::FINGERPRINT) {
        return None;
    }
    let mut cursor = Cursor { bytes, pos: 8 };
    let mut peek = RequestPeek::default();
    if cursor.header().is_none() {
        return Some(peek);
    }
    peek.request_id = cursor.i64();
    if peek.request_id.is_some() && cursor.i8().is_some_and(|n| n >= 1) {
        peek.inline_map = cursor.map_claim();
    }
    Some(peek)
}

#[cfg(test)]
mod tests {
    use super::*;
    use lcm_types::pfnav::Header;

    fn map(width: i32, height: i32) -> TerrainMap {
        let cells = usize::try_from(width * height).unwrap();
        TerrainMap {
            header: Header {
                utime: 1,
                seq: 42,
                frame_id: "world".into(),
            },
            origin_x: 0.0,
            origin_y: 0.0,
            resolution: 0.5,
            width,
            height,
            num_cells: width * height,
            heights: vec![0.0; cells],
            num_obstacle_cells: 0,
            obstacle_mask: Vec::new(),
            ..TerrainMap::default()
        }
    }

    #[test]
    fn map_claims_match_the_encoded_fields() {
        let bytes = map(3, 5).encode().unwrap();
        let claim = peek_map(&bytes).unwrap();
        assert_eq!(
            claim,
            MapClaim {
                seq: 42,
                width: 3,
                height: 5,
                num_cells: 15
            }
        );
        assert_eq!(claim.claimed_cells(), 15);
        // Truncated right after num_cells: still readable; one byte earlier: not.
        // After num_cells: the heights, num_obstacle_cells, num_known_cells,
        // unknown_traversability and num_variance_cells (masks and variances empty).
        let header_end = bytes.len() - 15 * 8 - 4 - 4 - 8 - 4;
        assert!(peek_map(&bytes[..header_end]).is_some());
        assert!(peek_map(&bytes[..header_end - 1]).is_none());
    }

    #[test]
    fn request_peek_reads_id_and_inline_map_claims() {
        let mut request = PlanRequest {
            request_id: 77,
            num_inline_maps: 1,
            inline_map: vec![map(4, 2)],
            ..PlanRequest::default()
        };
        request.header.frame_id = "world".into();
        let bytes = request.encode().unwrap();
        let peek = peek_request(&bytes).unwrap();
        assert_eq!(peek.request_id, Some(77));
        assert_eq!(peek.inline_map.map(|c| c.claimed_cells()), Some(8));
        assert_eq!(peek_request(&bytes[..30]).unwrap().inline_map, None);
        assert_eq!(peek_map(&bytes), None, "a request is not a map");
        assert_eq!(peek_request(&map(1, 1).encode().unwrap()), None);
    }

    #[test]
    fn huge_claims_do_not_overflow() {
        let claim = MapClaim {
            seq: 0,
            width: i32::MAX,
            height: i32::MAX,
            num_cells: -5,
        };
        assert_eq!(claim.claimed_cells(), (i32::MAX as u64) * (i32::MAX as u64));
    }
}
