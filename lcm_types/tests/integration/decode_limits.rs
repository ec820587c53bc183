//! Oversize claims are rejected before anything is allocated, limits apply, encoders check
//! lengths. A counting global allocator measures the largest single allocation.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use lcm_types::pfnav::{Header, PlanReply, PlanRequest, TerrainMap};
use lcm_types::{DecodeError, DecodeLimits, EncodeError, Message};

struct CountingAllocator;

static LARGEST_ALLOCATION: AtomicUsize = AtomicUsize::new(0);
/// Tests share the allocation counter: run the measured sections one at a time.
static MEASURE: Mutex<()> = Mutex::new(());

thread_local! {
    /// Only the measuring thread counts: other tests allocate on their own threads meanwhile.
    static MEASURING: Cell<bool> = const { Cell::new(false) };
}

unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if MEASURING.try_with(Cell::get).unwrap_or(false) {
            LARGEST_ALLOCATION.fetch_max(layout.size(), Ordering::SeqCst);
        }
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

fn largest_allocation_during<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let _guard = MEASURE.lock().unwrap_or_else(|e| e.into_inner());
    LARGEST_ALLOCATION.store(0, Ordering::SeqCst);
    MEASURING.with(|m| m.set(true));
    let result = f();
    MEASURING.with(|m| m.set(false));
    (result, LARGEST_ALLOCATION.load(Ordering::SeqCst))
}

fn map(width: i32, height: i32) -> TerrainMap {
    let cells = (width * height) as usize;
    TerrainMap {
        header: Header {
            utime: 1,
            seq: 2,
            frame_id: "world".into(),
        },
        origin_x: 0.0,
        origin_y: 0.0,
        resolution: 0.5,
        width,
        height,
        num_cells: width * height,
        heights: (0..cells).map(|i| i as f64 * 0.01).collect(),
        num_obstacle_cells: 0,
        obstacle_mask: Vec::new(),
        ..TerrainMap::default()
    }
}

/// Offset of `num_cells` in an encoded map: fingerprint, header (8 + 8 + string "world"),
/// origin_x, origin_y, resolution, width, height.
const NUM_CELLS_OFFSET: usize = 8 + 8 + 8 + (4 + 6) + 8 + 8 + 8 + 4 + 4;

#[test]
fn a_map_claiming_two_billion_cells_is_rejected_without_allocating() {
    let mut bytes = map(4, 4).encode().expect("consistent map");
    assert_eq!(
        &bytes[NUM_CELLS_OFFSET..NUM_CELLS_OFFSET + 4],
        &16i32.to_be_bytes(),
        "offset points at num_cells"
    );
    bytes[NUM_CELLS_OFFSET..NUM_CELLS_OFFSET + 4].copy_from_slice(&i32::MAX.to_be_bytes());
    let (result, largest) = largest_allocation_during(|| TerrainMap::decode(&bytes));
    match result {
        Err(DecodeError::ArrayExceedsBuffer {
            field,
            elements,
            available,
            ..
        }) => {
            assert_eq!(field, "heights");
            assert_eq!(elements, i32::MAX as u128);
            // The heights, then num_obstacle_cells, num_known_cells, unknown_traversability,
            // num_variance_cells.
            assert_eq!(available, 16 * 8 + 4 + 4 + 8 + 4);
        }
        other => panic!("expected ArrayExceedsBuffer, got {other:?}"),
    }
    // Only the header string was allocated before the claim was checked.
    assert!(largest < 64, "largest allocation {largest} bytes");
}

#[test]
fn negative_lengths_are_rejected() {
    let mut bytes = map(2, 2).encode().expect("consistent map");
    bytes[NUM_CELLS_OFFSET..NUM_CELLS_OFFSET + 4].copy_from_slice(&(-4i32).to_be_bytes());
    let err = TerrainMap::decode(&bytes).expect_err("negative length");
    assert_eq!(
        err,
        DecodeError::NegativeLength {
            type_name: "pfnav.terrain_map_t",
            field: "num_cells",
            value: -4
        }
    );
}

#[test]
fn max_array_len_limits_real_maps_before_allocation() {
    let bytes = map(64, 64).encode().expect("consistent map");
    let limits = DecodeLimits {
        max_array_len: 4095,
        ..DecodeLimits::default()
    };
    let (result, largest) =
        largest_allocation_during(|| TerrainMap::decode_with_limits(&bytes, &limits));
    assert_eq!(
        result.expect_err("over the limit"),
        DecodeError::ArrayTooLong {
            type_name: "pfnav.terrain_map_t",
            field: "num_cells",
            value: 4096,
            limit: 4095
        }
    );
    assert!(largest < 64, "largest allocation {largest} bytes");
    let ok = TerrainMap::decode_with_limits(
        &bytes,
        &DecodeLimits {
            max_array_len: 4096,
            ..limits
        },
    );
    assert_eq!(ok.expect("at the limit").heights.len(), 4096);
}

#[test]
fn nested_inline_maps_are_bounded_by_the_same_rules() {
    let request = PlanRequest {
        num_inline_maps: 1,
        inline_map: vec![map(3, 3)],
        ..PlanRequest::default()
    };
    let bytes = request.encode().expect("consistent");
    assert_eq!(PlanRequest::decode(&bytes).expect("valid"), request);
    let limits = DecodeLimits {
        max_array_len: 8,
        ..DecodeLimits::default()
    };
    let err = PlanRequest::decode_with_limits(&bytes, &limits).expect_err("9 cells > 8");
    assert!(
        matches!(err, DecodeError::ArrayTooLong { value: 9, .. }),
        "{err}"
    );
}

#[test]
fn encoders_refuse_arrays_that_disagree_with_their_length_member() {
    let mut bad = map(2, 2);
    bad.num_cells = 5;
    assert_eq!(
        bad.encode().expect_err("mismatch"),
        EncodeError::LengthMismatch {
            type_name: "pfnav.terrain_map_t",
            field: "heights",
            declared: 5,
            actual: 4
        }
    );
    let negative = PlanReply {
        num_samples: -1,
        ..PlanReply::default()
    };
    assert!(matches!(
        negative.encode().expect_err("negative"),
        EncodeError::NegativeLength {
            field: "num_samples",
            value: -1,
            ..
        }
    ));
}

#[test]
fn encoding_layout_is_the_documented_one() {
    // header_t { utime = 0x0102030405060708, seq = -2, frame_id = "ab" }, by hand from the
    // LCM wire format rules: big-endian, string = i32 length incl. NUL + bytes + NUL.
    let header = Header {
        utime: 0x0102_0304_0506_0708,
        seq: -2,
        frame_id: "ab".into(),
    };
    let mut expected = Header::FINGERPRINT.to_be_bytes().to_vec();
    expected.extend_from_slice(&[1, 2, 3, 4, 5, 6, 7, 8]);
    expected.extend_from_slice(&[0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xfe]);
    expected.extend_from_slice(&[0, 0, 0, 3, b'a', b'b', 0]);
    assert_eq!(header.encode().expect("encodes"), expected);
    assert_eq!(header.encoded_len_one(), expected.len() - 8);
}

#[test]
fn encode_into_matches_encode_and_keeps_its_buffer() {
    use lcm_types::codec::Message;
    use lcm_types::pfnav::Header;
    let mut buffer = Vec::with_capacity(4096);
    let first = buffer.as_ptr();
    for seq in [1, 2] {
        let header = Header {
            seq,
            utime: 77,
            frame_id: "world".into(),
        };
        header.encode_into(&mut buffer).expect("encodes");
        assert_eq!(buffer, header.encode().expect("encodes"));
    }
    assert_eq!(buffer.as_ptr(), first, "the buffer was reallocated");
}
