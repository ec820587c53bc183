//! FMU states (`fmi2GetFMUstate` & co.) and their serialized form.
//!
//! An [`InstanceState`] is everything an instance carries between FMI calls: its phase in the
//! call sequence, parameters, inputs, outputs, clock and the controller's own state. Setting it
//! back makes the instance continue exactly as it did from that point (bit for bit: the controller
//! is deterministic and its MPC solver cache leaves no trace in results).
//!
//! Serialized form (all integers little-endian):
//!
//! | bytes | content |
//! |---|---|
//! | 8 | magic `PFNAVFMU` |
//! | 4 | layout id of the state types ([`STATE_LAYOUT`]) |
//! | 38 | the FMU's GUID (ASCII, `{…}`) |
//! | 4 | CRC-32 of the robot description (URDF) the state was taken with |
//! | 8 | payload length n |
//! | 4 | CRC-32 of the payload |
//! | n | payload: the [`InstanceState`] in CBOR (RFC 8949) |
//!
//! A blob is checked in that order before anything is decoded: a blob of another program, of a
//! build of this FMU with other state types, of another interface (GUID) or robot, truncated or
//! corrupted is refused with the reason, and nothing in the instance changes.

use quad_controller::{Command, ControllerConfig, ControllerState};
use serde::{Deserialize, Serialize};

use crate::instance::Phase;
use crate::variables::Inputs;
use crate::FmuError;

/// First bytes of every serialized state.
pub const MAGIC: &[u8; 8] = b"PFNAVFMU";
include!(concat!(env!("OUT_DIR"), "/state_layout.rs"));
/// Length of a GUID in the header: `{` + 36 characters of the UUID + `}`.
pub const GUID_LEN: usize = 38;
/// Length of the header before the payload.
pub const HEADER_LEN: usize = MAGIC.len() + 4 + GUID_LEN + 4 + 8 + 4;
/// Largest payload accepted (a state is about 20 kB; anything near this is not ours).
pub const MAX_PAYLOAD: u64 = 16 << 20;

/// Everything an instance carries between FMI calls.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct InstanceState {
    /// Where in the FMI call sequence the instance is.
    pub phase: Phase,
    /// Parameters (as set, also before initialization).
    pub config: ControllerConfig,
    /// Inputs as last set.
    pub inputs: Inputs,
    /// Outputs of the last step.
    pub command: Command,
    /// The controller's state (present once initialization is done).
    pub controller: Option<ControllerState>,
    /// `fmi2SetupExperiment` start time, s.
    pub start_time: f64,
    /// `fmi2SetupExperiment` stop time, s.
    pub stop_time: Option<f64>,
    /// End of the last completed doStep, s.
    pub time: f64,
    /// Control ticks run since initialization.
    pub ticks_done: u64,
    /// `fmi2LastSuccessfulTime`, s.
    pub last_successful_time: f64,
}

impl InstanceState {
    /// The serialized form for the FMU with GUID `guid` whose robot description has CRC-32
    /// `robot_crc`.
    pub fn encode(&self, guid: &str, robot_crc: u32) -> Result<Vec<u8>, FmuError> {
        if guid.len() != GUID_LEN {
            return Err(FmuError::SavedState(format!(
                "GUID {guid:?} is not {GUID_LEN} bytes long"
            )));
        }
        let mut payload = Vec::new();
        ciborium::into_writer(self, &mut payload)
            .map_err(|e| FmuError::SavedState(format!("cannot encode the state: {e}")))?;
        let mut blob = Vec::with_capacity(HEADER_LEN + payload.len());
        blob.extend_from_slice(MAGIC);
        blob.extend_from_slice(&STATE_LAYOUT.to_le_bytes());
        blob.extend_from_slice(guid.as_bytes());
        blob.extend_from_slice(&robot_crc.to_le_bytes());
        blob.extend_from_slice(&(payload.len() as u64).to_le_bytes());
        blob.extend_from_slice(&crc32fast::hash(&payload).to_le_bytes());
        blob.extend_from_slice(&payload);
        Ok(blob)
    }

    /// Reads a serialized state, checking it was made by a build with these state types, for the
    /// FMU with GUID `guid` and the robot whose description has CRC-32 `robot_crc`.
    pub fn decode(blob: &[u8], guid: &str, robot_crc: u32) -> Result<InstanceState, FmuError> {
        let refuse = |reason: String| Err(FmuError::SavedState(reason));
        if blob.len() < HEADER_LEN {
            return refuse(format!(
                "{} bytes, shorter than the {HEADER_LEN}-byte header of a serialized state",
                blob.len()
            ));
        }
        let (magic, rest) = split::<8>(blob)?;
        if magic != MAGIC {
            return refuse("not a serialized state of this FMU (wrong magic bytes)".to_owned());
        }
        let (layout, rest) = split::<4>(rest)?;
        let layout = u32::from_le_bytes(*layout);
        if layout != STATE_LAYOUT {
            return refuse(format!(
                "serialized by a build with other state types (layout {layout:#010x}, this FMU's is {STATE_LAYOUT:#010x})"
            ));
        }
        let (theirs, rest) = rest.split_at_checked(GUID_LEN).ok_or_else(|| {
            FmuError::SavedState("serialized state ends inside its header".to_owned())
        })?;
        if theirs != guid.as_bytes() {
            return refuse(format!(
                "serialized by an FMU with GUID {}, this one is {guid}",
                String::from_utf8_lossy(theirs)
            ));
        }
        let (robot, rest) = split::<4>(rest)?;
        let robot = u32::from_le_bytes(*robot);
        if robot != robot_crc {
            return refuse(format!(
                "taken with another robot description (URDF CRC-32 {robot:08x}, this FMU's is {robot_crc:08x})"
            ));
        }
        let (length, rest) = split::<8>(rest)?;
        let length = u64::from_le_bytes(*length);
        let (crc, payload) = split::<4>(rest)?;
        let crc = u32::from_le_bytes(*crc);
        if length > MAX_PAYLOAD || length != payload.len() as u64 {
            return refuse(format!(
                "header announces {length} payload bytes, {} follow (truncated or padded)",
                payload.len()
            ));
        }
        if crc32fast::hash(payload) != crc {
            return refuse("payload checksum mismatch (corrupted)".to_owned());
        }
        ciborium::from_reader(payload)
            .map_err(|e| FmuError::SavedState(format!("cannot decode the payload: {e}")))
    }
}

/// The first `N` bytes of `bytes` and the rest.
fn split<const N: usize>(bytes: &[u8]) -> Result<(&[u8; N], &[u8]), FmuError> {
    bytes
        .split_first_chunk::<N>()
        .ok_or_else(|| FmuError::SavedState("serialized state ends inside its header".to_owned()))
}
