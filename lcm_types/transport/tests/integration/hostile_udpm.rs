//! Raw UDP packets that crashed liblcm's receive path, sent to a subscriber of this wrapper on
//! `udpm://`: the 139-byte LC03 fragment with fragment_offset 0xFFFFFFFF (unpatched: a memcpy
//! about 4 GiB past the fragment buffer, SIGSEGV of this test process) and the 17-byte LC02
//! packet whose channel name has no NUL (unpatched: data_size 17 − 18). The subscriber must stay
//! alive, never see a hostile payload, and still receive a valid message afterwards.
//!
//! Only inside the test network namespace (`bash scripts/netns.sh cargo test`, which sets
//! `PFNAV_IN_NETNS=1`); elsewhere the test prints why and returns without sending anything.

use std::net::{Ipv4Addr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use lcm_transport::Lcm;

const GROUP: Ipv4Addr = Ipv4Addr::new(239, 255, 76, 67);
const PORT: u16 = 17_311;
const CHANNEL: &str = "HOSTILE_RAW";

fn in_namespace() -> bool {
    let inside = std::env::var("PFNAV_IN_NETNS").as_deref() == Ok("1");
    if !inside {
        eprintln!("skipped: udpm tests run only inside scripts/netns.sh (PFNAV_IN_NETNS=1)");
    }
    inside
}

/// LC03 header: magic, sequence, message size, fragment offset, fragment number, fragment count.
fn long_packet(
    msg_size: u32,
    offset: u32,
    fragment_no: u16,
    fragments: u16,
    rest: &[u8],
) -> Vec<u8> {
    let mut p = Vec::with_capacity(20 + rest.len());
    p.extend_from_slice(&0x4c43_3033u32.to_be_bytes());
    p.extend_from_slice(&1u32.to_be_bytes());
    p.extend_from_slice(&msg_size.to_be_bytes());
    p.extend_from_slice(&offset.to_be_bytes());
    p.extend_from_slice(&fragment_no.to_be_bytes());
    p.extend_from_slice(&fragments.to_be_bytes());
    p.extend_from_slice(rest);
    p
}

/// LC02 header: magic, sequence; then the channel name (NUL-terminated when valid) and payload.
fn short_packet(rest: &[u8]) -> Vec<u8> {
    let mut p = Vec::with_capacity(8 + rest.len());
    p.extend_from_slice(&0x4c43_3032u32.to_be_bytes());
    p.extend_from_slice(&7u32.to_be_bytes());
    p.extend_from_slice(rest);
    p
}

#[test]
fn regression_liblcm_fragment_offset_wrap_and_short_packet_without_nul_leave_a_subscriber_alive() {
    if !in_namespace() {
        return;
    }
    let url = format!("udpm://{GROUP}:{PORT}?ttl=0");
    let receiver = Arc::new(Lcm::open(&url).unwrap());
    let received: Arc<Mutex<Vec<Vec<u8>>>> = Arc::default();
    let sink = Arc::clone(&received);
    let stop = Arc::new(AtomicBool::new(false));
    let (subscribed_tx, subscribed) = std::sync::mpsc::channel();
    let handler_thread = {
        let receiver = Arc::clone(&receiver);
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || {
            let _sub = receiver
                .subscribe(CHANNEL, move |_, bytes| {
                    sink.lock().unwrap().push(bytes.to_vec())
                })
                .unwrap();
            subscribed_tx.send(()).unwrap();
            while !stop.load(Ordering::SeqCst) {
                receiver.handle_timeout(Duration::from_millis(20)).unwrap();
            }
        })
    };
    // The hostile packets must reach a subscribed handler, not an empty channel table.
    subscribed
        .recv_timeout(Duration::from_secs(10))
        .expect("the handler thread subscribed");

    let socket = UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).unwrap();
    socket.set_multicast_loop_v4(true).unwrap();
    socket.set_multicast_ttl_v4(0).unwrap();
    let mut channel = CHANNEL.as_bytes().to_vec();
    channel.push(0);
    // The reported packet: 20-byte header, channel with NUL, filler up to 139 bytes.
    let mut rest = channel.clone();
    rest.resize(139 - 20, 0x41);
    let fragment = long_packet(1000, 0xFFFF_FFFF, 0, 2, &rest);
    assert_eq!(fragment.len(), 139);
    // 8-byte header and 9 channel bytes without NUL: 17 bytes.
    let short = short_packet(&CHANNEL.as_bytes()[..9]);
    assert_eq!(short.len(), 17);
    // Variants: a later fragment with a huge offset, a header-only fragment, the whole channel
    // name without NUL filling a short packet.
    let later = long_packet(1000, 0xFFFF_FF00, 1, 2, &[0x42; 100]);
    let header_only = long_packet(1000, 0, 0, 2, &[]);
    let name_only = short_packet(CHANNEL.as_bytes());
    for _ in 0..10 {
        for packet in [&fragment, &short, &later, &header_only, &name_only] {
            socket.send_to(packet, (GROUP, PORT)).unwrap();
        }
    }

    let sender = Lcm::open(&url).unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    while received.lock().unwrap().is_empty() && Instant::now() < deadline {
        sender.publish(CHANNEL, b"valid").unwrap();
        std::thread::sleep(Duration::from_millis(50));
    }
    stop.store(true, Ordering::SeqCst);
    handler_thread.join().expect("the handler thread survived");
    let got = received.lock().unwrap();
    assert!(!got.is_empty(), "the valid message was not received");
    assert!(
        got.iter().all(|m| m == b"valid"),
        "a hostile packet reached the handler: {:?}",
        got.iter().map(Vec::len).collect::<Vec<_>>()
    );
    assert_eq!(receiver.dropped_messages(), 0);
}
