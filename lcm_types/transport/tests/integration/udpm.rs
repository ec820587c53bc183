//! The wrapper over real UDP multicast. Each test runs in a private network namespace: if the
//! test process is not already isolated (only a loopback interface), it re-runs itself under
//! `unshare --net` with a multicast route on `lo`, so no packet ever reaches the host network.

use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use lcm_transport::Lcm;

/// Set in the environment of the re-executed test so that it can never re-execute itself again.
const CHILD_MARKER: &str = "LCM_TRANSPORT_TEST_IN_NETNS";

/// True when the only network interface of this process's network namespace is loopback.
/// `/proc/self/net/dev` follows the process's namespace (unlike `/sys/class/net`).
fn isolated() -> bool {
    let Ok(dev) = std::fs::read_to_string("/proc/self/net/dev") else {
        return false;
    };
    // Two header lines, then one "name: counters" line per interface.
    dev.lines()
        .skip(2)
        .filter_map(|line| line.split(':').next())
        .all(|name| name.trim() == "lo")
}

/// Runs the test `name` of this binary inside a fresh network namespace unless already isolated.
/// Returns true when the caller should run the test body itself.
fn run_here_or_in_namespace(name: &str) -> bool {
    if isolated() {
        return true;
    }
    assert!(
        std::env::var_os(CHILD_MARKER).is_none(),
        "re-executed inside unshare --net but still not isolated; refusing to use udpm"
    );
    let exe = std::env::current_exe().expect("test binary path");
    let status = Command::new("unshare")
        .args(["--net", "bash", "-c"])
        .arg(
            "ip link set lo up && ip link set lo multicast on && \
             ip route add 224.0.0.0/4 dev lo && exec \"$0\" \"$@\"",
        )
        .arg(exe)
        .args(["--exact", name, "--test-threads=1", "--nocapture"])
        .env(CHILD_MARKER, "1")
        .status()
        .expect("unshare must exist (util-linux) and the tests need root for a private netns");
    assert!(
        status.success(),
        "{name} failed inside its private network namespace"
    );
    false
}

#[test]
fn udpm_roundtrip_of_small_and_fragmented_messages() {
    if !run_here_or_in_namespace("udpm_roundtrip_of_small_and_fragmented_messages") {
        return;
    }
    // The stack's multicast group (loopback only: ttl=0) on a port of this test's own.
    let group = lcm_types::channels::DEFAULT_URL
        .trim_start_matches("udpm://")
        .split(':')
        .next()
        .unwrap();
    let url = &format!("udpm://{group}:17301?ttl=0");
    let receiver = Lcm::open(url).unwrap();
    let sender = Lcm::open(url).unwrap();
    let received: Arc<Mutex<Vec<Vec<u8>>>> = Arc::default();
    let sink = Arc::clone(&received);
    let _sub = receiver
        .subscribe("UDPM_TEST", move |_, bytes| {
            sink.lock().unwrap().push(bytes.to_vec())
        })
        .unwrap();
    // 200 kB needs fragmentation (LCM fragments above ~64 kB).
    let big: Vec<u8> = (0..200_000u32).map(|i| (i * 7 % 251) as u8).collect();
    sender.publish("UDPM_TEST", b"small").unwrap();
    sender.publish("UDPM_TEST", &big).unwrap();
    let deadline = Instant::now() + Duration::from_secs(5);
    while received.lock().unwrap().len() < 2 && Instant::now() < deadline {
        receiver.handle_timeout(Duration::from_millis(50)).unwrap();
    }
    let got = received.lock().unwrap();
    assert_eq!(got.len(), 2);
    assert_eq!(got[0], b"small");
    assert_eq!(got[1], big);
    assert_eq!(receiver.url(), url);
}
