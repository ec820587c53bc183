//! A map that claims more cells than `--max-map-cells` is refused before anything is allocated
//! for it: a counting allocator records the largest allocation made on the service's LCM
//! handler thread while it processes an oversize map (whose body is complete and valid, so a
//! decoder would have allocated its arrays).

use crate::common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::Duration;

use common::{config, flat_map, inline_request, map_message, TestService, HANDLER_ID};
use lcm_types::pfnav::{PlanReply, PlanRequest};

struct MaxAllocation;

static LARGEST_ON_HANDLER_THREAD: AtomicUsize = AtomicUsize::new(0);
/// The `handler_id` of the service under test (0: none yet).
static WATCHED_HANDLER: AtomicU64 = AtomicU64::new(0);

unsafe impl GlobalAlloc for MaxAllocation {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // try_with: the thread-local may already be gone while a thread shuts down.
        let watched = WATCHED_HANDLER.load(Ordering::SeqCst);
        if watched != 0 && HANDLER_ID.try_with(|t| t.get()).unwrap_or(0) == watched {
            LARGEST_ON_HANDLER_THREAD.fetch_max(layout.size(), Ordering::SeqCst);
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
static ALLOCATOR: MaxAllocation = MaxAllocation;

#[test]
fn oversize_maps_are_refused_before_allocation() {
    let mut cfg = config("OVR_");
    cfg.max_map_cells = 32 * 32;
    let service = TestService::start(cfg);
    WATCHED_HANDLER.store(service.handler_id, Ordering::SeqCst);
    // Warm up: one small valid request, so that one-time allocations are done.
    let small = flat_map(8, &[]);
    service.publish_request(&inline_request(
        1,
        PlanRequest::METHOD_DIJKSTRA,
        &small,
        [0.2, 0.2],
        [1.7, 1.7],
    ));
    assert_eq!(
        service.reply_to(1, Duration::from_secs(30)).status,
        PlanReply::STATUS_OK
    );
    LARGEST_ON_HANDLER_THREAD.store(0, Ordering::SeqCst);

    // 128 x 128 = 16 384 cells > 1 024: its heights alone would be a 131 072-byte Vec.
    let big = flat_map(128, &[]);
    let heights_bytes = big.heights.len() * 8;
    service.publish_request(&inline_request(
        2,
        PlanRequest::METHOD_DIJKSTRA,
        &big,
        [0.2, 0.2],
        [1.7, 1.7],
    ));
    let reply = service.reply_to(2, Duration::from_secs(30));
    assert_eq!(
        reply.status,
        PlanReply::STATUS_MAP_TOO_LARGE,
        "{}",
        reply.error
    );
    assert!(reply.error.contains("16384"), "{}", reply.error);
    service.publish_map(&map_message(&big, 9));
    // The map is not stored: a request naming it is refused.
    let mut by_seq = inline_request(
        3,
        PlanRequest::METHOD_DIJKSTRA,
        &small,
        [0.2, 0.2],
        [1.7, 1.7],
    );
    by_seq.num_inline_maps = 0;
    by_seq.inline_map.clear();
    by_seq.map_seq = 9;
    service.publish_request(&by_seq);
    assert_eq!(
        service.reply_to(3, Duration::from_secs(30)).status,
        PlanReply::STATUS_INVALID_MAP
    );
    let largest = LARGEST_ON_HANDLER_THREAD.load(Ordering::SeqCst);
    assert!(
        largest < heights_bytes / 4,
        "the handler thread allocated {largest} bytes at once while refusing a {heights_bytes}-byte map"
    );
    let report = service.stop();
    assert!(report.malformed_messages >= 1);
}
