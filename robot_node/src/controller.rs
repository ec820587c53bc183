//! The controller FMU as the node drives it: low_state_t and nav_cmd_t copied into the FMU's
//! inputs, the joint torques and the FSM state read back. Every name is resolved against the
//! FMU's modelDescription once, at start; the loop then uses value references and fixed-size
//! buffers only. The FMU runs its own estimator (`estimator = kalman`): low_state_t carries
//! what a robot measures (IMU, encoders), not the trunk's position and velocity.

use std::path::Path;

use anyhow::Context;
use lcm_types::pfnav::NavCmd;

use crate::fmu_host::{CoSimulation, Fmi2Library, UnpackedFmu};
use crate::inbox::{BodyState, NavReference};
use crate::model_description::{ModelDescription, ScalarKind};

const JOINTS: usize = 12;
/// base.quat (4), imu.gyro (3), imu.acc (3), joint.q (12), joint.dq (12), ref.* (8), terrain (2).
const REAL_INPUTS: usize = 4 + 3 + 3 + JOINTS + JOINTS + 8 + 2;
/// cmd.mode and contact[1..4].
const INTEGER_INPUTS: usize = 1 + 4;

/// The most periods one `fmi2DoStep` spans: the FMU refuses a step whose ticks could take too
/// long (its work budget), and allows at least 8 ticks for any configuration it accepts.
pub const PERIODS_PER_DO_STEP: u32 = 4;
/// est.pos (3), est.vel (3), est.rpy (3), est.posVar (3).
const ESTIMATE_OUTPUTS: usize = 12;

/// The controller's estimate of the trunk after a step (its `est.*` outputs).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Estimate {
    pub position: [f64; 3],
    pub velocity: [f64; 3],
    pub rpy: [f64; 3],
    pub position_variance: [f64; 3],
    /// `est.status`, the estimator's status bit mask.
    pub status: i32,
}

/// What one controller step produced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControllerOutput {
    pub torques: [f64; JOINTS],
    /// The FMU's `fsm.state`.
    pub fsm_state: i32,
    pub estimate: Estimate,
}

pub struct HostedController {
    fmu: CoSimulation,
    // Kept alive (the unpacked binary and resources) for as long as the instance.
    _unpacked: UnpackedFmu,
    real_inputs: [u32; REAL_INPUTS],
    integer_inputs: [u32; INTEGER_INPUTS],
    torques: [u32; JOINTS],
    estimate: [u32; ESTIMATE_OUTPUTS],
    /// fsm.state and est.status.
    integer_outputs: [u32; 2],
    /// FMU ModeRequest codes of nav_cmd_t's MODE_PASSIVE, MODE_STAND, MODE_LOCOMOTION.
    mode_codes: [i32; 3],
    /// Periods stepped: the communication point is steps × step, free of summed rounding.
    steps: u64,
    step: f64,
}

fn names() -> Vec<String> {
    let mut names: Vec<String> = ["w", "x", "y", "z"]
        .iter()
        .map(|c| format!("base.quat.{c}"))
        .collect();
    names.extend((1..=3).map(|i| format!("imu.gyro[{i}]")));
    names.extend((1..=3).map(|i| format!("imu.acc[{i}]")));
    names.extend((1..=JOINTS).map(|i| format!("joint.q[{i}]")));
    names.extend((1..=JOINTS).map(|i| format!("joint.dq[{i}]")));
    names.extend(
        ["x", "y", "z", "yaw", "vx", "vy", "yawRate", "bodyHeight"]
            .iter()
            .map(|r| format!("ref.{r}")),
    );
    names.extend(["terrain.dzdx".to_owned(), "terrain.dzdy".to_owned()]);
    names
}

fn references<const N: usize>(
    description: &ModelDescription,
    names: impl IntoIterator<Item = String>,
    kind: ScalarKind,
    causality: &str,
) -> anyhow::Result<[u32; N]> {
    let found: Vec<u32> = names
        .into_iter()
        .map(|name| {
            description
                .variable(&name, kind, causality)
                .map(|v| v.value_reference)
        })
        .collect::<Result<_, _>>()?;
    found
        .try_into()
        .map_err(|v: Vec<u32>| anyhow::anyhow!("expected {N} variables, found {}", v.len()))
}

impl HostedController {
    /// Unpacks the FMU at `archive`, instantiates it with the estimator on and initialises it
    /// for steps of `step` seconds. `initial_position`: the trunk's position when the node
    /// starts (`base.pos`, read by the estimator at its first tick only); None keeps the FMU's
    /// start values, a frame that starts where the robot stands.
    pub fn load(
        archive: &Path,
        step: f64,
        initial_position: Option<[f64; 3]>,
    ) -> anyhow::Result<Self> {
        let unpacked = UnpackedFmu::open(archive)?;
        let library = Fmi2Library::load(&unpacked.binary_path())?;
        let description = &unpacked.description;
        let real_inputs = references(description, names(), ScalarKind::Real, "input")?;
        let integer_inputs = references(
            description,
            std::iter::once("cmd.mode".to_owned()).chain((1..=4).map(|k| format!("contact[{k}]"))),
            ScalarKind::Integer,
            "input",
        )?;
        let torques = references(
            description,
            (1..=JOINTS).map(|i| format!("joint.tau[{i}]")),
            ScalarKind::Real,
            "output",
        )?;
        let estimate = references(
            description,
            ["pos", "vel", "rpy", "posVar"]
                .iter()
                .flat_map(|block| (1..=3).map(move |i| format!("est.{block}[{i}]"))),
            ScalarKind::Real,
            "output",
        )?;
        let integer_outputs = references(
            description,
            ["fsm.state".to_owned(), "est.status".to_owned()],
            ScalarKind::Integer,
            "output",
        )?;
        let estimator = description
            .variable("estimator", ScalarKind::Integer, "parameter")?
            .value_reference;
        let kalman = description.enumeration_code("estimator", "kalman")?;
        let mut mode_codes = [0; 3];
        for (code, item) in mode_codes
            .iter_mut()
            .zip(["Passive", "Stand", "Locomotion"])
        {
            *code = description.enumeration_code("cmd.mode", item)?;
        }

        let mut fmu = CoSimulation::instantiate(library, &unpacked, "pfnav-robot")?;
        fmu.enter_initialization(0.0)?;
        fmu.set_integer(&[estimator], &[kalman])
            .context("setting estimator = kalman")?;
        if let Some(position) = initial_position {
            let base: [u32; 3] = references(
                description,
                ["x", "y", "z"].iter().map(|c| format!("base.pos.{c}")),
                ScalarKind::Real,
                "input",
            )?;
            fmu.set_real(&base, &position)
                .context("setting the initial trunk position base.pos")?;
        }
        fmu.exit_initialization()?;
        Ok(Self {
            fmu,
            _unpacked: unpacked,
            real_inputs,
            integer_inputs,
            torques,
            estimate,
            integer_outputs,
            mode_codes,
            steps: 0,
            step,
        })
    }

    /// Copies `state` and `nav` into the inputs, steps the FMU `periods` (≥ 1) step lengths
    /// (it runs that many control ticks on these inputs; `fmi2DoStep`s of at most
    /// [`PERIODS_PER_DO_STEP`]) and reads the outputs. Allocation-free.
    pub fn step(
        &mut self,
        state: &BodyState,
        nav: &NavReference,
        periods: u32,
    ) -> anyhow::Result<ControllerOutput> {
        anyhow::ensure!(periods >= 1, "a controller step spans at least one period");
        let mut values = [0.0f64; REAL_INPUTS];
        let sensors = state
            .imu_quaternion
            .iter()
            .chain(&state.imu_gyroscope)
            .chain(&state.imu_accelerometer)
            .chain(&state.q)
            .chain(&state.dq)
            .map(|&v| f64::from(v));
        let reference = [
            nav.x,
            nav.y,
            nav.z,
            nav.yaw,
            nav.vx,
            nav.vy,
            nav.yaw_rate,
            nav.body_height,
            nav.terrain_dzdx,
            nav.terrain_dzdy,
        ];
        for (slot, value) in values.iter_mut().zip(sensors.chain(reference)) {
            *slot = value;
        }
        let mode = match nav.mode {
            NavCmd::MODE_PASSIVE => self.mode_codes[0],
            NavCmd::MODE_STAND => self.mode_codes[1],
            // The inbox only lets the three known modes through.
            _ => self.mode_codes[2],
        };
        let contact = state.foot_contact.map(i32::from);
        let integers = [mode, contact[0], contact[1], contact[2], contact[3]];
        self.fmu.set_real(&self.real_inputs, &values)?;
        self.fmu.set_integer(&self.integer_inputs, &integers)?;
        let mut left = periods;
        while left > 0 {
            let chunk = left.min(PERIODS_PER_DO_STEP);
            self.fmu
                .do_step(self.steps as f64 * self.step, f64::from(chunk) * self.step)?;
            self.steps += u64::from(chunk);
            left -= chunk;
        }
        let mut output = ControllerOutput {
            torques: [0.0; JOINTS],
            fsm_state: 0,
            estimate: Estimate::default(),
        };
        self.fmu.get_real(&self.torques, &mut output.torques)?;
        let mut estimate = [0.0f64; ESTIMATE_OUTPUTS];
        self.fmu.get_real(&self.estimate, &mut estimate)?;
        let e = &mut output.estimate;
        e.position.copy_from_slice(&estimate[0..3]);
        e.velocity.copy_from_slice(&estimate[3..6]);
        e.rpy.copy_from_slice(&estimate[6..9]);
        e.position_variance.copy_from_slice(&estimate[9..12]);
        let mut integers = [0i32; 2];
        self.fmu.get_integer(&self.integer_outputs, &mut integers)?;
        output.fsm_state = integers[0];
        e.status = integers[1];
        Ok(output)
    }
}
