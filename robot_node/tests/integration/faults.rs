//! Each fault reaches damping with its reason in the status and the node recovers when the
//! peer is healthy again; garbage never crashes it.

use std::time::Duration;

use lcm_types::pfnav::RobotStatus;

use crate::support::{Body, Rig};

const WAIT: Duration = Duration::from_secs(5);

fn damped_with(rig: &Rig, what: &str, after: i64, reason: &str) -> RobotStatus {
    let status = rig.wait_status(what, after, WAIT, |s| {
        s.safety == RobotStatus::SAFETY_DAMPING && s.reason.contains(reason)
    });
    assert!(status.damping_entries >= 1);
    status
}

fn recovered(rig: &Rig, what: &str, after: i64) -> RobotStatus {
    rig.wait_status(what, after, WAIT, |s| s.safety == RobotStatus::SAFETY_OK)
}

#[test]
fn every_fault_damps_with_its_reason_and_the_node_recovers() {
    let rig = Rig::start("FAULTS_", |config| {
        config.safety.nav_timeout_ns = 200_000_000;
        // Damping outlasts a status period (100 ms), so every fault shows in a status message.
        config.safety.recover_cycles = 250;
    });
    let ok = recovered(&rig, "torque control at start", -1);

    // The body stops answering: damping once the 20 ms timeout has passed, never before; how
    // soon after is the benchmark's to measure (the target is 25 ms): the suite runs
    // beside other tests at a low priority.
    rig.set_body(Body::Silent);
    let silent = rig.wait_status("silence", ok.header.seq, WAIT, |_| true);
    let last_state = *rig.last_state_ns.lock().unwrap();
    let status = damped_with(&rig, "state timeout", ok.header.seq, "no low_state_t for");
    let first_damping = rig
        .commands
        .lock()
        .unwrap()
        .iter()
        .find(|c| c.at_ns > last_state && c.damping)
        .map(|c| c.at_ns)
        .expect("a damping command after the last state");
    let delay_ms = (first_damping - last_state) as f64 * 1e-6;
    assert!(
        (20.0..=20.0 + 200.0).contains(&delay_ms),
        "damping {delay_ms} ms after the last state"
    );
    assert!(silent.header.seq <= status.header.seq);
    rig.set_body(Body::Answer);
    let ok = recovered(&rig, "recovery after the body returns", status.header.seq);

    // One state with a NaN.
    rig.set_body(Body::NanOnce);
    let status = damped_with(
        &rig,
        "NaN",
        ok.header.seq,
        "non-finite value in low_state_t",
    );
    assert!(status.states_non_finite >= 1);
    let ok = recovered(&rig, "recovery after the NaN", status.header.seq);

    // One state whose seq goes back.
    rig.set_body(Body::OutOfOrderOnce);
    let status = damped_with(
        &rig,
        "out-of-order seq",
        ok.header.seq,
        "out-of-order low_state_t seq",
    );
    assert!(status.states_out_of_order >= 1);
    let ok = recovered(
        &rig,
        "recovery after the out-of-order seq",
        status.header.seq,
    );

    // Garbage instead of states for 300 ms, and garbage on the navigator channel.
    rig.set_body(Body::Garbage);
    for i in 0..2_000u32 {
        let junk: Vec<u8> = (0..(i % 97)).map(|k| (k * 31 + i) as u8).collect();
        let _ = rig.lcm.publish(&rig.channels.nav_cmd, &junk);
    }
    let status = damped_with(&rig, "garbage", ok.header.seq, "no low_state_t for");
    std::thread::sleep(Duration::from_millis(300));
    rig.set_body(Body::Answer);
    let ok = recovered(&rig, "recovery after the garbage", status.header.seq);
    assert!(
        ok.malformed_messages >= 2_000,
        "{} malformed",
        ok.malformed_messages
    );

    // The navigator goes quiet.
    rig.navigator_on
        .store(false, std::sync::atomic::Ordering::Relaxed);
    let status = damped_with(&rig, "navigator lost", ok.header.seq, "no nav_cmd_t for");
    rig.navigator_on
        .store(true, std::sync::atomic::Ordering::Relaxed);
    let ok = recovered(
        &rig,
        "recovery after the navigator returns",
        status.header.seq,
    );

    let commands = rig.commands.clone();
    let report = rig.stop();
    // One entry per fault; a starved scheduler may add a state timeout of its own.
    assert!(report.damping_entries >= 5, "one entry per fault at least");
    assert!(ok.damping_entries >= 5);
    assert!(commands.lock().unwrap().iter().all(|c| c.finite));
}
