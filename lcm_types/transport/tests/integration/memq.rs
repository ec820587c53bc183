//! Behaviour of the wrapper on the in-process `memq://` provider (no network involved).

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use lcm_transport::{Lcm, LcmError, Subscription};

const WAIT: Duration = Duration::from_millis(200);

/// Handles until `done` says so or 200 idle waits pass; returns how many messages were handled.
fn handle_until(lcm: &Lcm, mut done: impl FnMut() -> bool) -> usize {
    let mut handled = 0;
    let mut idle = 0;
    while !done() && idle < 200 {
        if lcm
            .handle_timeout(Duration::from_millis(10))
            .expect("handle")
        {
            handled += 1;
        } else {
            idle += 1;
        }
    }
    handled
}

type Received = Arc<Mutex<Vec<(String, Vec<u8>)>>>;

fn recorder<'l>(lcm: &'l Lcm, pattern: &str) -> (Subscription<'l>, Received) {
    let received: Received = Arc::default();
    let sink = Arc::clone(&received);
    let sub = lcm
        .subscribe(pattern, move |channel, bytes| {
            sink.lock()
                .unwrap()
                .push((channel.to_owned(), bytes.to_vec()));
        })
        .expect("subscribe");
    (sub, received)
}

#[test]
fn published_bytes_arrive_unchanged_on_the_right_channel() {
    let lcm = Lcm::open("memq://").unwrap();
    let (_sub, received) = recorder(&lcm, "CHAN_A");
    let payload: Vec<u8> = (0..=255u8).cycle().take(100_000).collect();
    lcm.publish("CHAN_A", &payload).unwrap();
    lcm.publish("CHAN_A", b"").unwrap();
    lcm.publish("CHAN_B", b"not for us").unwrap();
    handle_until(&lcm, || received.lock().unwrap().len() >= 2);
    // Drain anything else (CHAN_B must not reach the CHAN_A handler).
    while lcm.handle_timeout(Duration::ZERO).unwrap() {}
    let got = received.lock().unwrap();
    assert_eq!(got.len(), 2);
    assert_eq!(got[0].0, "CHAN_A");
    assert_eq!(got[0].1, payload);
    assert_eq!(got[1].1, Vec::<u8>::new());
}

#[test]
fn handle_timeout_reports_timeout_when_nothing_arrives() {
    let lcm = Lcm::open("memq://").unwrap();
    let (_sub, received) = recorder(&lcm, "QUIET");
    assert!(!lcm.handle_timeout(Duration::from_millis(20)).unwrap());
    assert!(!lcm.handle_timeout(Duration::ZERO).unwrap());
    assert!(received.lock().unwrap().is_empty());
}

#[test]
fn patterns_are_anchored_regular_expressions() {
    let lcm = Lcm::open("memq://").unwrap();
    let (_sub, received) = recorder(&lcm, "PFNAV_.*");
    for channel in ["PFNAV_MAP", "XPFNAV_MAP", "PFNAV_REQUEST", "OTHER"] {
        lcm.publish(channel, channel.as_bytes()).unwrap();
    }
    while lcm.handle_timeout(WAIT).unwrap() {}
    let channels: Vec<String> = received
        .lock()
        .unwrap()
        .iter()
        .map(|(c, _)| c.clone())
        .collect();
    assert_eq!(channels, ["PFNAV_MAP", "PFNAV_REQUEST"]);
}

#[test]
fn dropping_a_subscription_stops_delivery() {
    let lcm = Lcm::open("memq://").unwrap();
    let (sub, received) = recorder(&lcm, "DROP_ME");
    lcm.publish("DROP_ME", b"1").unwrap();
    handle_until(&lcm, || !received.lock().unwrap().is_empty());
    drop(sub);
    lcm.publish("DROP_ME", b"2").unwrap();
    while lcm.handle_timeout(Duration::from_millis(20)).unwrap() {}
    assert_eq!(received.lock().unwrap().len(), 1);
}

#[test]
fn invalid_channels_and_urls_are_typed_errors() {
    let lcm = Lcm::open("memq://").unwrap();
    let long = "C".repeat(64);
    assert!(matches!(
        lcm.publish("", b"x"),
        Err(LcmError::InvalidChannel { .. })
    ));
    assert!(matches!(
        lcm.publish(&long, b"x"),
        Err(LcmError::InvalidChannel { .. })
    ));
    assert!(matches!(
        lcm.publish("A\0B", b"x"),
        Err(LcmError::InvalidChannel { .. })
    ));
    lcm.publish(&"C".repeat(63), b"x")
        .expect("63 bytes is the limit, inclusive");
    assert!(matches!(
        lcm.subscribe("", |_, _| {}),
        Err(LcmError::InvalidChannel { .. })
    ));
    assert!(matches!(
        lcm.subscribe("BAD[", |_, _| {}),
        Err(LcmError::SubscribeFailed { .. })
    ));
    assert!(matches!(
        Lcm::open("nosuchprovider://x"),
        Err(LcmError::OpenFailed { .. })
    ));
    assert!(matches!(
        Lcm::open("memq://\0"),
        Err(LcmError::UrlContainsNul { .. })
    ));
    let (sub, _) = recorder(&lcm, "CAP");
    assert!(matches!(
        sub.set_queue_capacity(0),
        Err(LcmError::QueueCapacity { .. })
    ));
    sub.set_queue_capacity(1000).unwrap();
}

#[test]
fn a_handler_can_publish_a_reply() {
    let lcm = Arc::new(Lcm::open("memq://").unwrap());
    let (_replies, received) = recorder(&lcm, "PONG");
    let publisher = Arc::clone(&lcm);
    let _ping = lcm
        .subscribe("PING", move |_, bytes| {
            let mut reply = bytes.to_vec();
            reply.reverse();
            publisher.publish("PONG", &reply).unwrap();
        })
        .unwrap();
    lcm.publish("PING", b"abc").unwrap();
    handle_until(&lcm, || !received.lock().unwrap().is_empty());
    assert_eq!(received.lock().unwrap()[0].1, b"cba");
}

#[test]
fn a_panicking_handler_is_contained_and_stays_subscribed() {
    let lcm = Lcm::open("memq://").unwrap();
    let calls = Arc::new(AtomicUsize::new(0));
    let counter = Arc::clone(&calls);
    let _sub = lcm
        .subscribe("BOOM", move |_, bytes| {
            counter.fetch_add(1, Ordering::SeqCst);
            assert!(bytes != b"panic", "handler panics on purpose");
        })
        .unwrap();
    let (_other, received) = recorder(&lcm, "BOOM");
    for payload in [&b"panic"[..], b"fine"] {
        lcm.publish("BOOM", payload).unwrap();
    }
    handle_until(&lcm, || received.lock().unwrap().len() >= 2);
    assert_eq!(calls.load(Ordering::SeqCst), 2);
    assert_eq!(
        received.lock().unwrap().len(),
        2,
        "the other handler saw both"
    );
}

#[test]
fn a_handler_may_unsubscribe_itself_and_recursion_is_refused() {
    // A 'static instance lets the handler hold its own Subscription and call back into LCM.
    let lcm: &'static Lcm = Box::leak(Box::new(Lcm::open("memq://").unwrap()));
    let own: Arc<Mutex<Option<Subscription<'static>>>> = Arc::default();
    let recursion = Arc::new(Mutex::new(None));
    let calls = Arc::new(AtomicUsize::new(0));
    let (own2, recursion2, calls2) = (Arc::clone(&own), Arc::clone(&recursion), Arc::clone(&calls));
    let sub = lcm
        .subscribe("ONCE", move |_, _| {
            calls2.fetch_add(1, Ordering::SeqCst);
            *recursion2.lock().unwrap() = Some(lcm.handle_timeout(Duration::ZERO));
            // Unsubscribe from inside the running handler: this drops the closure's own slot.
            own2.lock().unwrap().take();
        })
        .unwrap();
    *own.lock().unwrap() = Some(sub);
    for _ in 0..3 {
        lcm.publish("ONCE", b"x").unwrap();
    }
    while lcm.handle_timeout(Duration::from_millis(20)).unwrap() {}
    assert_eq!(calls.load(Ordering::SeqCst), 1);
    assert_eq!(
        *recursion.lock().unwrap(),
        Some(Err(LcmError::ReentrantHandle))
    );
}

#[test]
fn publishing_from_many_threads_while_one_thread_handles() {
    const THREADS: usize = 4;
    const PER_THREAD: usize = 500;
    let lcm = Arc::new(Lcm::open("memq://").unwrap());
    let counts = Arc::new(Mutex::new([0usize; THREADS]));
    let sink = Arc::clone(&counts);
    let sub = lcm
        .subscribe("MANY", move |_, bytes| {
            sink.lock().unwrap()[usize::from(bytes[0])] += 1;
        })
        .unwrap();
    sub.set_queue_capacity(THREADS * PER_THREAD).unwrap();
    let publishers: Vec<_> = (0..THREADS)
        .map(|t| {
            let lcm = Arc::clone(&lcm);
            std::thread::spawn(move || {
                for _ in 0..PER_THREAD {
                    lcm.publish("MANY", &[u8::try_from(t).unwrap(); 64])
                        .unwrap();
                }
            })
        })
        .collect();
    for p in publishers {
        p.join().unwrap();
    }
    handle_until(&lcm, || {
        counts.lock().unwrap().iter().sum::<usize>() >= THREADS * PER_THREAD
    });
    assert_eq!(*counts.lock().unwrap(), [PER_THREAD; THREADS]);
}

#[test]
fn a_subscription_can_be_dropped_on_another_thread() {
    let lcm = Arc::new(Lcm::open("memq://").unwrap());
    let (sub, received) = recorder(&lcm, "ELSEWHERE");
    std::thread::scope(|scope| {
        scope.spawn(move || drop(sub));
    });
    lcm.publish("ELSEWHERE", b"x").unwrap();
    while lcm.handle_timeout(Duration::from_millis(20)).unwrap() {}
    assert!(received.lock().unwrap().is_empty());
}
