//! The estimator's status word: one bit per way the estimate is degraded. Declared once here;
//! the FMU's description of `est.status` is generated from [`StatusFlag::ALL`].

/// A condition the estimator reports. The discriminant is the bit in the status word.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum StatusFlag {
    /// A gyro reading was NaN/inf: the last valid rate is held.
    GyroInvalid = 1,
    /// A gyro axis was at or beyond the full-scale range (`est_gyro_limit`): clamped to it.
    GyroSaturated = 2,
    /// An accelerometer reading was NaN/inf: no tilt correction, no acceleration in the
    /// prediction.
    AccInvalid = 4,
    /// A foot has not been in contact for longer than the contact timeout (a foot that never
    /// touches down, a contact sensor stuck open).
    FootWithoutContact = 8,
    /// A position fix was refused (innovation beyond the gate, or non-finite).
    FixRejected = 16,
    /// The filter was re-initialised (non-finite or runaway covariance, or repeated fixes far
    /// from the estimate).
    CovarianceReset = 32,
    /// No foot in stance: the velocity is integrated from the accelerometer alone.
    NoStance = 64,
    /// A stance foot's velocity disagreed with the prediction while another stance foot
    /// agreed (a slipping foot): that foot was treated as swinging for the tick.
    FootSlip = 128,
    /// The slip gate has been dropping stance feet on more than
    /// [`super::DOUBTFUL_SLIP_SHARE`] of the ticks of the last second or so: feet slip or
    /// contacts are misjudged, and the position estimate (its height first) may drift.
    OdometryDoubtful = 256,
}

impl StatusFlag {
    /// Every flag with its name and description, in bit order.
    pub const ALL: [(StatusFlag, &'static str, &'static str); 9] = [
        (
            StatusFlag::GyroInvalid,
            "gyroInvalid",
            "gyro reading NaN/inf (last valid rate held)",
        ),
        (
            StatusFlag::GyroSaturated,
            "gyroSaturated",
            "gyro at or beyond est.gyroLimit (clamped)",
        ),
        (
            StatusFlag::AccInvalid,
            "accInvalid",
            "accelerometer reading NaN/inf (no tilt correction, no acceleration)",
        ),
        (
            StatusFlag::FootWithoutContact,
            "footWithoutContact",
            "a foot not in contact for longer than the contact timeout",
        ),
        (
            StatusFlag::FixRejected,
            "fixRejected",
            "a position fix refused by the innovation gate",
        ),
        (
            StatusFlag::CovarianceReset,
            "covarianceReset",
            "filter re-initialised (bad covariance or repeated far fixes)",
        ),
        (
            StatusFlag::NoStance,
            "noStance",
            "no foot in stance (velocity from the accelerometer alone)",
        ),
        (
            StatusFlag::FootSlip,
            "footSlip",
            "a stance foot's velocity beyond the slip gate (treated as swinging)",
        ),
        (
            StatusFlag::OdometryDoubtful,
            "odometryDoubtful",
            "stance feet dropped at the slip gate on a large share of recent ticks (slipping feet or misjudged contacts): the position estimate may drift",
        ),
    ];

    /// The flag's bit.
    pub fn bit(self) -> u32 {
        self as u32
    }
}

/// A set of [`StatusFlag`]s.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EstimatorStatus(u32);

impl EstimatorStatus {
    /// No flag set.
    pub const HEALTHY: EstimatorStatus = EstimatorStatus(0);

    /// Sets `flag`.
    pub fn set(&mut self, flag: StatusFlag) {
        self.0 |= flag.bit();
    }

    /// The bit mask.
    pub fn bits(self) -> u32 {
        self.0
    }
}
