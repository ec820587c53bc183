//! Hand-written declarations of the part of `<lcm/lcm.h>` (liblcm 1.3.1) this crate uses.
//! Checked against `build/lcm/include/lcm/lcm.h` (the patched 1.3.1 build of `scripts/build_liblcm.sh`);
//! the layout of `lcm_recv_buf_t` must match it exactly (`data_size` is a `uint32_t`).

use std::os::raw::{c_char, c_int, c_uint, c_void};

/// Opaque `lcm_t`.
#[repr(C)]
pub(crate) struct LcmT {
    _private: [u8; 0],
}

/// Opaque `lcm_subscription_t`.
#[repr(C)]
pub(crate) struct LcmSubscriptionT {
    _private: [u8; 0],
}

/// `lcm_recv_buf_t`: the payload of one received message.
#[repr(C)]
pub(crate) struct LcmRecvBufT {
    pub data: *mut c_void,
    pub data_size: u32,
    pub recv_utime: i64,
    pub lcm: *mut LcmT,
}

/// `lcm_msg_handler_t`.
pub(crate) type LcmMsgHandler =
    unsafe extern "C" fn(rbuf: *const LcmRecvBufT, channel: *const c_char, user_data: *mut c_void);

extern "C" {
    pub(crate) fn lcm_create(provider: *const c_char) -> *mut LcmT;
    pub(crate) fn lcm_destroy(lcm: *mut LcmT);
    pub(crate) fn lcm_subscribe(
        lcm: *mut LcmT,
        channel: *const c_char,
        handler: LcmMsgHandler,
        userdata: *mut c_void,
    ) -> *mut LcmSubscriptionT;
    pub(crate) fn lcm_unsubscribe(lcm: *mut LcmT, handler: *mut LcmSubscriptionT) -> c_int;
    pub(crate) fn lcm_publish(
        lcm: *mut LcmT,
        channel: *const c_char,
        data: *const c_void,
        datalen: c_uint,
    ) -> c_int;
    pub(crate) fn lcm_handle_timeout(lcm: *mut LcmT, timeout_millis: c_int) -> c_int;
    pub(crate) fn lcm_subscription_set_queue_capacity(
        handler: *mut LcmSubscriptionT,
        num_messages: c_int,
    ) -> c_int;
}
