//! Rust encoders and decoders for the `lcm_types/*.lcm` wire contract (LCM package `pfnav`),
//! generated at build time by `lcm-codegen`, byte-identical to lcm-gen's.
//!
//! ```
//! use lcm_types::pfnav::PlanRequest;
//! use lcm_types::Message;
//!
//! let mut request = PlanRequest::default();
//! request.request_id = 7;
//! request.method = PlanRequest::METHOD_DIJKSTRA;
//! let bytes = request.encode().unwrap();
//! assert_eq!(&bytes[..8], &PlanRequest::FINGERPRINT.to_be_bytes());
//! assert_eq!(PlanRequest::decode(&bytes).unwrap(), request);
//! ```
//!
//! Every type implements [`Message`]; [`AnyMessage`] decodes any of them by fingerprint.
//! Decoders reject wrong fingerprints, truncation, trailing bytes, negative or oversize
//! lengths (see [`DecodeLimits`]) without panicking and without allocating more than the input
//! could hold. Encoders reject arrays whose length differs from their length member.

pub mod codec;

pub use codec::{DecodeError, DecodeLimits, EncodeError, Message};

include!(concat!(env!("OUT_DIR"), "/pfnav_types.rs"));

/// The bus contract of `lcm_types/channels.toml`: the default URL and every channel name.
pub mod channels {
    include!(concat!(env!("OUT_DIR"), "/channels.rs"));
}
