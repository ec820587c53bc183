//! Safe wrapper over liblcm (FFI; the patched build of `scripts/build_liblcm.sh`): open by URL, publish, subscribe, handle with timeout.
//!
//! This crate is the only place of the project with `unsafe` code for LCM. It speaks raw bytes;
//! encoding and decoding messages is the job of the `lcm-types` crate.
//!
//! ```no_run
//! use std::time::Duration;
//! use lcm_transport::Lcm;
//!
//! let lcm = Lcm::open("memq://")?;
//! let _sub = lcm.subscribe("PING", |channel, bytes| println!("{channel}: {} bytes", bytes.len()))?;
//! lcm.publish("PING", b"hello")?;
//! lcm.handle_timeout(Duration::from_millis(100))?;
//! # Ok::<(), lcm_transport::LcmError>(())
//! ```
//!
//! # Thread safety
//!
//! [`Lcm`] is `Send` and `Sync`: share it between threads with an `Arc`.
//! - [`Lcm::publish`] may be called from any thread, including from inside a handler. Calls are
//!   serialised by a mutex of this wrapper, because liblcm 1.3.1 documents thread safety for the
//!   udpm provider only (the `file://` writer has no lock of its own).
//! - [`Lcm::handle_timeout`] runs the handlers on the calling thread, one at a time. Concurrent
//!   calls from several threads are serialised by a second mutex; a call from inside a handler
//!   (recursion, forbidden by liblcm) returns [`LcmError::ReentrantHandle`] instead of deadlocking.
//! - [`Lcm::subscribe`] and dropping a [`Subscription`] may happen on any thread, also inside a
//!   handler: liblcm guards its handler lists with its own recursive mutex. Each handler closure
//!   lives in a slot with a small state machine, so a handler that is unsubscribed while it runs
//!   (from its own body or from another thread) finishes its current call, is then dropped and
//!   is never called again. Slots are freed only between two `handle` calls, when no handler can
//!   be running, so liblcm never calls into freed memory.
//! - Handler closures must be `Send + 'static`: they are called on whichever thread handles.
//!   A panic inside a handler is caught at the FFI boundary (a panic must never unwind into C),
//!   logged with `tracing`, and the handler stays subscribed.
//!
//! # Received sizes
//!
//! The size liblcm hands over with a message is checked before a slice is made over it: above
//! the instance's maximum ([`Lcm::set_max_message_size`], default [`MAX_MESSAGE_BYTES`]) or with
//! a null buffer the message is dropped, counted ([`Lcm::dropped_messages`]) and logged. An
//! unpatched liblcm computed that size from a malformed packet as 17 − 18, i.e. 2³² − 1
//! (docs/liblcm-fix.md).

mod ffi;

use std::ffi::{CStr, CString};
use std::os::raw::{c_char, c_int, c_uint, c_void};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::ptr::NonNull;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::ThreadId;
use std::time::Duration;

use thiserror::Error;

/// The environment variable that names the bus when the caller gives no URL ([`url_from_env_or`]).
pub const DEFAULT_URL_ENV: &str = "LCM_DEFAULT_URL";

/// Largest message size an instance can be configured to hand to a handler, and its default,
/// bytes (liblcm's own `LCM_MAX_MESSAGE_SIZE`, 256 MiB); anything larger is dropped, counted and
/// logged before a slice is made over it.
pub const MAX_MESSAGE_BYTES: usize = 1 << 28;

/// Longest channel name liblcm accepts for publishing (`LCM_MAX_CHANNEL_NAME_LENGTH`).
pub const MAX_CHANNEL_LEN: usize = 63;

/// Errors of the LCM transport.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum LcmError {
    #[error("LCM URL {url:?} contains a NUL byte")]
    UrlContainsNul { url: String },
    #[error("liblcm could not open {url:?} (bad URL, unknown provider, or socket setup failed)")]
    OpenFailed { url: String },
    #[error("invalid channel {channel:?}: {reason}")]
    InvalidChannel {
        channel: String,
        reason: &'static str,
    },
    #[error("message of {len} bytes is larger than liblcm can send ({max} bytes)")]
    MessageTooLarge { len: usize, max: usize },
    #[error("liblcm failed to publish {len} bytes on {channel:?}")]
    PublishFailed { channel: String, len: usize },
    #[error(
        "liblcm rejected the subscription pattern {channel:?} (not a valid regular expression)"
    )]
    SubscribeFailed { channel: String },
    #[error("liblcm rejected queue capacity {capacity}")]
    QueueCapacity { capacity: usize },
    #[error("handle_timeout called from inside an LCM handler (recursion is not allowed)")]
    ReentrantHandle,
    #[error("liblcm reported an error while waiting for or dispatching messages")]
    HandleFailed,
    #[error("maximum message size {bytes} is outside 1..={max} bytes")]
    MaxMessageSize { bytes: usize, max: usize },
}

type Handler = Box<dyn FnMut(&str, &[u8]) + Send + 'static>;

/// Where the closure of one subscription is, seen from the dispatching thread.
enum SlotState {
    /// Subscribed and not running.
    Idle(Handler),
    /// Taken out by the trampoline while it runs.
    Running,
    /// Unsubscribed; the closure has been (or will be, when the running call ends) dropped.
    Removed,
}

struct HandlerSlot {
    state: Mutex<SlotState>,
    limits: Arc<ReceiveLimits>,
}

/// The received-size check of one instance, shared with its handler slots.
struct ReceiveLimits {
    max_message_bytes: AtomicUsize,
    dropped: AtomicU64,
}

fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    // No code of this crate panics while holding these locks; if a caller's panic ever poisoned
    // one, the protected data is still consistent (plain state swaps), so keep going.
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

/// One LCM instance (`lcm_t`): a connection to an LCM bus given by its URL.
pub struct Lcm {
    raw: NonNull<ffi::LcmT>,
    url: String,
    publish_lock: Mutex<()>,
    handle_lock: Mutex<()>,
    handling_thread: Mutex<Option<ThreadId>>,
    /// Every slot handed to liblcm as `userdata`; freed only while `handle_lock` is held.
    slots: Mutex<Vec<Arc<HandlerSlot>>>,
    limits: Arc<ReceiveLimits>,
}

// SAFETY: see the module documentation. liblcm 1.3.1 guards its subscription tables with an
// internal recursive mutex; publish and handle are serialised by this wrapper's own mutexes;
// `lcm_create`/`lcm_destroy` run only in `open`/`drop`, which have exclusive access.
unsafe impl Send for Lcm {}
// SAFETY: as above; every `&self` method is safe to call concurrently.
unsafe impl Sync for Lcm {}

impl std::fmt::Debug for Lcm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Lcm").field("url", &self.url).finish()
    }
}

impl Lcm {
    /// Opens the LCM bus at `url` (`udpm://group:port?ttl=0`, `memq://`, `file:///path?mode=w`).
    pub fn open(url: &str) -> Result<Self, LcmError> {
        let c_url = CString::new(url).map_err(|_| LcmError::UrlContainsNul {
            url: url.to_owned(),
        })?;
        // SAFETY: `c_url` is a valid NUL-terminated string that outlives the call.
        let raw = unsafe { ffi::lcm_create(c_url.as_ptr()) };
        let raw = NonNull::new(raw).ok_or_else(|| LcmError::OpenFailed {
            url: url.to_owned(),
        })?;
        tracing::debug!(url, "opened LCM");
        Ok(Self {
            raw,
            url: url.to_owned(),
            publish_lock: Mutex::new(()),
            handle_lock: Mutex::new(()),
            handling_thread: Mutex::new(None),
            slots: Mutex::new(Vec::new()),
            limits: Arc::new(ReceiveLimits {
                max_message_bytes: AtomicUsize::new(MAX_MESSAGE_BYTES),
                dropped: AtomicU64::new(0),
            }),
        })
    }

    /// The URL this instance was opened with.
    pub fn url(&self) -> &str {
        &self.url
    }

    /// Sets the largest message (bytes, 1 to [`MAX_MESSAGE_BYTES`]) handed to this instance's
    /// handlers; larger ones are dropped and counted in [`Lcm::dropped_messages`].
    pub fn set_max_message_size(&self, bytes: usize) -> Result<(), LcmError> {
        if !(1..=MAX_MESSAGE_BYTES).contains(&bytes) {
            return Err(LcmError::MaxMessageSize {
                bytes,
                max: MAX_MESSAGE_BYTES,
            });
        }
        self.limits
            .max_message_bytes
            .store(bytes, Ordering::Relaxed);
        Ok(())
    }

    /// The largest message handed to handlers, bytes.
    pub fn max_message_size(&self) -> usize {
        self.limits.max_message_bytes.load(Ordering::Relaxed)
    }

    /// Messages liblcm delivered that were dropped before any handler saw them: size above
    /// [`Lcm::max_message_size`], or a null buffer with a non-zero size.
    pub fn dropped_messages(&self) -> u64 {
        self.limits.dropped.load(Ordering::Relaxed)
    }

    /// Publishes `data` on `channel` (1 to [`MAX_CHANNEL_LEN`] bytes, no NUL).
    pub fn publish(&self, channel: &str, data: &[u8]) -> Result<(), LcmError> {
        let c_channel = checked_channel(channel, true)?;
        let len = c_uint::try_from(data.len()).map_err(|_| LcmError::MessageTooLarge {
            len: data.len(),
            max: c_uint::MAX as usize,
        })?;
        let _guard = lock(&self.publish_lock);
        // SAFETY: `raw` is a live lcm_t; the channel string and the data slice stay valid for
        // the duration of the call, and liblcm copies what it keeps.
        let status = unsafe {
            ffi::lcm_publish(
                self.raw.as_ptr(),
                c_channel.as_ptr(),
                data.as_ptr().cast::<c_void>(),
                len,
            )
        };
        if status == 0 {
            Ok(())
        } else {
            Err(LcmError::PublishFailed {
                channel: channel.to_owned(),
                len: data.len(),
            })
        }
    }

    /// Subscribes `handler` to every channel matching `channel_pattern` (a POSIX extended regular
    /// expression anchored at both ends, so a plain name matches only itself). The handler is
    /// called with the channel name and the raw message bytes from [`Lcm::handle_timeout`].
    /// Dropping the returned [`Subscription`] unsubscribes.
    pub fn subscribe<F>(
        &self,
        channel_pattern: &str,
        handler: F,
    ) -> Result<Subscription<'_>, LcmError>
    where
        F: FnMut(&str, &[u8]) + Send + 'static,
    {
        let c_channel = checked_channel(channel_pattern, false)?;
        let slot = Arc::new(HandlerSlot {
            state: Mutex::new(SlotState::Idle(Box::new(handler))),
            limits: Arc::clone(&self.limits),
        });
        let userdata = Arc::as_ptr(&slot).cast_mut().cast::<c_void>();
        // The slot must be registered before liblcm can call the trampoline with it.
        lock(&self.slots).push(Arc::clone(&slot));
        // SAFETY: `raw` is live; the channel string is valid for the call (liblcm copies it);
        // `userdata` points into `slot`, which `self.slots` keeps alive at least until this
        // subscription is removed and no handle call is in progress.
        let raw_sub = unsafe {
            ffi::lcm_subscribe(self.raw.as_ptr(), c_channel.as_ptr(), trampoline, userdata)
        };
        match NonNull::new(raw_sub) {
            Some(raw) => Ok(Subscription {
                lcm: self,
                raw,
                slot,
            }),
            None => {
                *lock(&slot.state) = SlotState::Removed;
                Err(LcmError::SubscribeFailed {
                    channel: channel_pattern.to_owned(),
                })
            }
        }
    }

    /// Waits up to `timeout` for a message and dispatches it to the matching handlers on this
    /// thread. Returns `Ok(true)` when a message was handled, `Ok(false)` on timeout.
    /// A zero timeout dispatches what is already queued and returns at once.
    pub fn handle_timeout(&self, timeout: Duration) -> Result<bool, LcmError> {
        let me = std::thread::current().id();
        if *lock(&self.handling_thread) == Some(me) {
            return Err(LcmError::ReentrantHandle);
        }
        let millis = c_int::try_from(timeout.as_millis()).unwrap_or(c_int::MAX);
        let _guard = lock(&self.handle_lock);
        *lock(&self.handling_thread) = Some(me);
        // SAFETY: `raw` is live; handlers run on this thread through `trampoline`, whose
        // `userdata` slots are kept alive by `self.slots` (not pruned while we hold handle_lock).
        let status = unsafe { ffi::lcm_handle_timeout(self.raw.as_ptr(), millis) };
        *lock(&self.handling_thread) = None;
        // No handler can run now (we hold handle_lock): free the slots of removed subscriptions.
        lock(&self.slots).retain(|slot| !matches!(*lock(&slot.state), SlotState::Removed));
        match status {
            s if s > 0 => Ok(true),
            0 => Ok(false),
            _ => Err(LcmError::HandleFailed),
        }
    }
}

impl Drop for Lcm {
    fn drop(&mut self) {
        // Every Subscription borrows self, so all are gone; handlers cannot run any more.
        // SAFETY: `raw` came from lcm_create and is destroyed exactly once.
        unsafe { ffi::lcm_destroy(self.raw.as_ptr()) };
        tracing::debug!(url = %self.url, "closed LCM");
    }
}

/// `LCM_DEFAULT_URL` if set and non-empty, else `default` (the stack's is
/// `lcm_types::channels::DEFAULT_URL`).
pub fn url_from_env_or(default: &str) -> String {
    match std::env::var(DEFAULT_URL_ENV) {
        Ok(url) if !url.is_empty() => url,
        _ => default.to_owned(),
    }
}

fn checked_channel(channel: &str, for_publish: bool) -> Result<CString, LcmError> {
    let invalid = |reason| LcmError::InvalidChannel {
        channel: channel.to_owned(),
        reason,
    };
    if channel.is_empty() {
        return Err(invalid("empty"));
    }
    if for_publish && channel.len() > MAX_CHANNEL_LEN {
        return Err(invalid("longer than 63 bytes"));
    }
    CString::new(channel).map_err(|_| invalid("contains a NUL byte"))
}

/// A live subscription; dropping it unsubscribes (see the crate documentation for the rules
/// when that happens while the handler runs).
pub struct Subscription<'lcm> {
    lcm: &'lcm Lcm,
    raw: NonNull<ffi::LcmSubscriptionT>,
    slot: Arc<HandlerSlot>,
}

// SAFETY: the subscription handle is only passed back to liblcm functions that take the
// instance's internal mutex (unsubscribe, set_queue_capacity before any dispatch races are
// possible), so using or dropping it from another thread is sound.
unsafe impl Send for Subscription<'_> {}
// SAFETY: the only `&self` method, `set_queue_capacity`, writes one int field that liblcm
// reads under its own lock; concurrent calls set the same kind of value.
unsafe impl Sync for Subscription<'_> {}

impl std::fmt::Debug for Subscription<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Subscription")
            .field("url", &self.lcm.url)
            .finish()
    }
}

impl Subscription<'_> {
    /// Sets how many received messages liblcm may queue for this subscription before it drops
    /// new ones (liblcm's default is 30; 0 means unbounded, which this wrapper refuses).
    pub fn set_queue_capacity(&self, capacity: usize) -> Result<(), LcmError> {
        let num = c_int::try_from(capacity)
            .ok()
            .filter(|&n| n > 0)
            .ok_or(LcmError::QueueCapacity { capacity })?;
        // SAFETY: `raw` is a live subscription of a live lcm_t (we borrow the Lcm).
        let status = unsafe { ffi::lcm_subscription_set_queue_capacity(self.raw.as_ptr(), num) };
        if status == 0 {
            Ok(())
        } else {
            Err(LcmError::QueueCapacity { capacity })
        }
    }
}

impl Drop for Subscription<'_> {
    fn drop(&mut self) {
        // SAFETY: `raw` is a live subscription of the live lcm_t we borrow; after this call
        // liblcm never starts a new call of the handler (a call already past its
        // marked_for_deletion check may still start; the Removed state below makes it a no-op).
        let status = unsafe { ffi::lcm_unsubscribe(self.lcm.raw.as_ptr(), self.raw.as_ptr()) };
        if status != 0 {
            tracing::warn!(url = %self.lcm.url, "liblcm did not know the subscription being dropped");
        }
        let previous = std::mem::replace(&mut *lock(&self.slot.state), SlotState::Removed);
        // Dropped outside the lock: a closure's Drop may itself touch LCM.
        drop(previous);
    }
}

/// The C callback for every subscription: finds the slot, runs its closure, never unwinds.
unsafe extern "C" fn trampoline(
    rbuf: *const ffi::LcmRecvBufT,
    channel: *const c_char,
    user_data: *mut c_void,
) {
    // A panic must never unwind into C; if even the logging below panics, the message is lost.
    let _ = catch_unwind(AssertUnwindSafe(|| {
        if rbuf.is_null() || channel.is_null() || user_data.is_null() {
            tracing::error!("liblcm called a handler with a null argument; message dropped");
            return;
        }
        // SAFETY: `user_data` is the pointer of an `Arc<HandlerSlot>` registered in
        // `Lcm::slots`, which is not freed while a handle call (the only caller) is running.
        let slot = unsafe { &*user_data.cast_const().cast::<HandlerSlot>() };
        // SAFETY: liblcm passes a valid recv buffer and a NUL-terminated channel name, both
        // valid for the duration of this call.
        let (rbuf, channel) = unsafe { (&*rbuf, CStr::from_ptr(channel)) };
        // The size is checked before any slice is made from it: a receive path that computed it
        // from a malformed packet (an unpatched liblcm gave 17 − 18 = 2^32 − 1; `data_size` is a
        // uint32_t, so an underflow shows up as a huge value) must not become a slice over
        // memory that is not the message.
        let max = slot.limits.max_message_bytes.load(Ordering::Relaxed);
        let size = match usize::try_from(rbuf.data_size) {
            Ok(size) if size <= max => size,
            _ => {
                let dropped = slot.limits.dropped.fetch_add(1, Ordering::Relaxed) + 1;
                tracing::warn!(
                    channel = %channel.to_string_lossy(),
                    size = rbuf.data_size,
                    max,
                    dropped,
                    "liblcm delivered a message above the maximum message size; dropped"
                );
                return;
            }
        };
        if rbuf.data.is_null() && size > 0 {
            let dropped = slot.limits.dropped.fetch_add(1, Ordering::Relaxed) + 1;
            tracing::warn!(
                channel = %channel.to_string_lossy(),
                size,
                dropped,
                "liblcm delivered a null buffer with a non-zero size; dropped"
            );
            return;
        }
        let data: &[u8] = if size == 0 {
            &[]
        } else {
            // SAFETY: `data` is non-null and liblcm guarantees it points to `data_size` readable
            // bytes; the patched receive paths (docs/liblcm-fix.md) only deliver sizes bounded
            // by the received packet or the allocated fragment buffer, and `size` is at most the
            // configured maximum (≤ MAX_MESSAGE_BYTES).
            unsafe { std::slice::from_raw_parts(rbuf.data.cast::<u8>(), size) }
        };
        let channel = channel.to_string_lossy();

        let mut handler = match std::mem::replace(&mut *lock(&slot.state), SlotState::Running) {
            SlotState::Idle(handler) => handler,
            other => {
                // Removed (unsubscribed concurrently) or, impossibly, Running: restore and skip.
                *lock(&slot.state) = other;
                return;
            }
        };
        let result = catch_unwind(AssertUnwindSafe(|| handler(&channel, data)));
        {
            let mut state = lock(&slot.state);
            if matches!(*state, SlotState::Running) {
                *state = SlotState::Idle(handler);
            } else {
                // Unsubscribed while running: drop the closure after releasing the lock.
                drop(state);
                drop(handler);
            }
        }
        if result.is_err() {
            tracing::error!(channel = %channel, "LCM handler panicked; message dropped, handler kept");
        }
    }));
}
