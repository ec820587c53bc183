//! The received-size check of the wrapper: a message above the instance's maximum never reaches a
//! handler (no slice is made over it), it is counted, and smaller ones still arrive. memq only.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use lcm_transport::{Lcm, LcmError, MAX_MESSAGE_BYTES};

#[test]
fn messages_above_the_maximum_size_are_dropped_and_counted() {
    let lcm = Lcm::open("memq://").unwrap();
    assert_eq!(lcm.max_message_size(), MAX_MESSAGE_BYTES);
    lcm.set_max_message_size(16).unwrap();
    let received: Arc<Mutex<Vec<Vec<u8>>>> = Arc::default();
    let sink = Arc::clone(&received);
    let _sub = lcm
        .subscribe("SIZE", move |_, bytes| {
            sink.lock().unwrap().push(bytes.to_vec())
        })
        .unwrap();
    lcm.publish("SIZE", &[7u8; 17]).unwrap();
    lcm.publish("SIZE", &[1u8; 16]).unwrap();
    lcm.publish("SIZE", &[]).unwrap();
    while lcm.handle_timeout(Duration::ZERO).unwrap() {}
    assert_eq!(
        *received.lock().unwrap(),
        vec![vec![1u8; 16], Vec::new()],
        "only the messages within the limit reach the handler"
    );
    assert_eq!(lcm.dropped_messages(), 1);
}

#[test]
fn the_maximum_size_must_be_between_one_byte_and_the_liblcm_limit() {
    let lcm = Lcm::open("memq://").unwrap();
    for bytes in [0, MAX_MESSAGE_BYTES + 1] {
        assert_eq!(
            lcm.set_max_message_size(bytes),
            Err(LcmError::MaxMessageSize {
                bytes,
                max: MAX_MESSAGE_BYTES
            })
        );
    }
    lcm.set_max_message_size(MAX_MESSAGE_BYTES).unwrap();
    assert_eq!(lcm.dropped_messages(), 0);
}
