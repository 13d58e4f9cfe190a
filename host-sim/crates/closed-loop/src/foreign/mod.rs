//! Foreign rigs: recordings that differ from the project's own in ways that
//! are not effects of the plant. A real rig runs another drive (its own
//! gains, speed estimate, pre-torque, start and stop sequence, profile, and
//! a rotor standing at any electrical angle) and another data acquisition
//! (its own filters, noise, quantisation, sample clock and pre-trigger).
//! The project's diagnosis must hold on such recordings.
//!
//! - [`commercial_drive`]: a generic commercial elevator drive as a
//!   [`DriveController`] of the closed loop ([`ForeignDrive`] its parameters);
//! - [`acquisition`]: a foreign data acquisition ([`Acquisition`] its
//!   parameters);
//! - [`ForeignRig`]: which of the two replace the project's own;
//!   `crate::synthetic::make_foreign_dataset` records datasets with it.

pub mod acquisition;
pub mod commercial_drive;
pub mod params;

pub use acquisition::{Acquisition, AnalogSignal, Channel};
pub use commercial_drive::{CommercialDrive, ForeignDrive};
pub use params::{ParamError, ParamInfo, ParamKind};

use drive_core::{ControlOutput, SensorFrame, TravelCommand};

use crate::{simulate_travel_faulted, DriveController, FaultHook, SimError, SimOptions, TravelRun, TravelSpec};
use plant::free_decay::FreeDecayError;
use plant::sensors::Sensors;
use rig_config::RigConfig;

/// Why a foreign recording cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum ForeignError {
    /// A parameter of the drive or of the acquisition out of its range.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// The closed-loop simulation failed.
    #[error("travel simulation: {0}")]
    Sim(#[from] SimError),
    /// The free-decay simulation failed.
    #[error("{0}")]
    Decay(#[from] FreeDecayError),
    /// A combination the simulation cannot represent.
    #[error("{0}")]
    Unsupported(String),
    /// The drive never reached its travel state (no trigger).
    #[error("the drive never started the motion: no trigger for the recording")]
    NoMotion,
}

/// What replaces the project's own drive and data acquisition on a rig.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ForeignRig {
    /// The commercial drive with these parameters, or `None`: the project's
    /// drive core.
    pub drive: Option<ForeignDrive>,
    /// A foreign data acquisition with these parameters, or `None`: the
    /// project's own (exact samples at the dataset's rate, white noise).
    pub acquisition: Option<Acquisition>,
}

impl ForeignRig {
    /// The commercial drive and the foreign acquisition, both with their defaults.
    pub fn commercial() -> Self {
        Self { drive: Some(ForeignDrive::default()), acquisition: Some(Acquisition::default()) }
    }

    /// Both parts drawn at random within their ranges: the drive's
    /// parameters, then the acquisition's, those drawn last
    /// ([`ParamKind::DrawnLast`]: its high-pass order and current source)
    /// at the very end, so that a seed's earlier values do not depend on them.
    pub fn random<R: rand::Rng + ?Sized>(rng: &mut R) -> Self {
        let drive = ForeignDrive::random(rng);
        Self { drive: Some(drive), acquisition: Some(Acquisition::random(rng)) }
    }

    /// Checks every parameter against its range.
    ///
    /// # Errors
    /// [`ParamError::OutOfRange`] naming the first parameter out of its range.
    pub fn validate(&self) -> Result<(), ParamError> {
        if let Some(d) = &self.drive {
            d.validate()?;
        }
        if let Some(a) = &self.acquisition {
            a.validate()?;
        }
        Ok(())
    }

    /// A foreign rig from TOML text: a `[drive]` table selects the
    /// commercial drive, an `[acquisition]` table the foreign acquisition,
    /// each with `name = value` lines for the parameters that differ from
    /// their defaults (numbers; switches also `true`/`false`); a part
    /// without its table is the project's. `origin` names the text in errors.
    ///
    /// # Errors
    /// [`ParamError::File`] for text that is not such TOML,
    /// [`ParamError::Unknown`] or [`ParamError::OutOfRange`] for a parameter.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, ParamError> {
        let file_error = |message: String| ParamError::File { origin: origin.to_string(), message };
        let table: toml::Table = text.parse().map_err(|e: toml::de::Error| file_error(e.message().to_string()))?;
        let mut rig = ForeignRig::default();
        for (key, value) in &table {
            let toml::Value::Table(entries) = value else {
                return Err(file_error(format!("`{key}` must be a table, [drive] or [acquisition]")));
            };
            let mut values = Vec::new();
            for (name, v) in entries {
                let number = match v {
                    toml::Value::Float(f) => *f,
                    toml::Value::Integer(i) => *i as f64,
                    toml::Value::Boolean(b) => f64::from(u8::from(*b)),
                    _ => return Err(file_error(format!("`{key}.{name}` must be a number"))),
                };
                values.push((name.as_str(), number));
            }
            match key.as_str() {
                "drive" => {
                    let mut drive = ForeignDrive::default();
                    for (name, v) in values {
                        drive.set(name, v)?;
                    }
                    rig.drive = Some(drive);
                }
                "acquisition" => {
                    let mut acquisition = Acquisition::default();
                    for (name, v) in values {
                        acquisition.set(name, v)?;
                    }
                    rig.acquisition = Some(acquisition);
                }
                _ => return Err(file_error(format!("unknown table [{key}]: expected [drive] or [acquisition]"))),
            }
        }
        Ok(rig)
    }

    /// The parts and their parameters as TOML text (`[drive]`,
    /// `[acquisition]`, one `name = value` a line), the project's own parts
    /// as comments: what [`Self::from_toml_str`] reads back.
    pub fn to_toml(&self) -> String {
        let table = |title: &str, params: &[ParamInfo], get: &dyn Fn(&str) -> Option<f64>| {
            let lines: Vec<String> =
                params.iter().map(|p| format!("{} = {:?}", p.name, get(p.name).unwrap_or(f64::NAN))).collect();
            format!("[{title}]\n{}\n", lines.join("\n"))
        };
        let drive = match &self.drive {
            Some(d) => table("drive", ForeignDrive::PARAMS, &|n| d.get(n)),
            None => "# drive: the project's drive core\n".to_string(),
        };
        let acquisition = match &self.acquisition {
            Some(a) => table("acquisition", Acquisition::PARAMS, &|n| a.get(n)),
            None => "# acquisition: the project's own\n".to_string(),
        };
        format!("{drive}{acquisition}")
    }
}

/// Rotates a three-phase set by `angle_rad` (rad) in the stationary frame,
/// keeping its zero-sequence part: the currents (A) or voltages (V) of the
/// same machine state with the rotor `angle_rad` further on.
pub fn rotate_abc(abc: [f64; 3], angle_rad: f64) -> [f64; 3] {
    let h = 0.5 * 3f64.sqrt();
    let zero = (abc[0] + abc[1] + abc[2]) / 3.0;
    let alpha = (2.0 * abc[0] - abc[1] - abc[2]) / 3.0;
    let beta = (abc[1] - abc[2]) / 3f64.sqrt();
    let (s, c) = angle_rad.sin_cos();
    let (a, b) = (alpha * c - beta * s, alpha * s + beta * c);
    [a + zero, -0.5 * a + h * b + zero, -0.5 * a - h * b + zero]
}

/// The plant's stator seen by a drive whose rotor started at electrical
/// angle `angle_rad`: the plant's rotor starts at 0, so the drive's phase
/// currents are the plant's rotated by `+angle_rad` and the plant's phase
/// voltages the drive's rotated by `-angle_rad`. Exact for a plant whose
/// three phases are alike (the machine is; the `dead_time` and
/// `current_sensor_error` effects are not); the current codes are
/// re-quantised (at most one code of extra error).
struct RotatedStator<'a> {
    drive: &'a mut dyn DriveController,
    angle_rad: f64,
    sensors: Sensors,
    period_counts: u16,
}

impl DriveController for RotatedStator<'_> {
    fn command_travel(&mut self, command: TravelCommand) -> Result<(), SimError> {
        self.drive.command_travel(command)
    }

    fn step(&mut self, sensors: &SensorFrame) -> Result<ControlOutput, SimError> {
        let s = &self.sensors;
        let plant = sensors.phase_current_codes.map(|c| (c as f64 - s.current_zero_code) * s.current_lsb_a);
        let mut frame = *sensors;
        frame.phase_current_codes = rotate_abc(plant, self.angle_rad).map(|i| s.current_code(i));
        let mut out = self.drive.step(&frame)?;
        if out.pwm_enabled {
            let period = self.period_counts as f64;
            let duty = out.pwm_compare.map(|c| c as f64 / period);
            let mean = (duty[0] + duty[1] + duty[2]) / 3.0;
            let v = rotate_abc(duty.map(|d| d - mean), -self.angle_rad);
            let (alpha, beta) = ((2.0 * v[0] - v[1] - v[2]) / 3.0, (v[1] - v[2]) / 3f64.sqrt());
            out.pwm_compare = commercial_drive::modulate(alpha, beta, 1.0, self.period_counts);
        }
        Ok(out)
    }
}

/// Simulates the travel `spec` on `rig` driven by the commercial drive with
/// `drive`, the rotor starting at `drive.rotor_start_angle_deg`, with
/// `hook` acting on the closed loop (none: the rig as it is). The run's
/// phase currents are those of the machine's phases (the rotor at that
/// angle), its speed, angle and reference the drive's.
///
/// # Errors
/// [`ForeignError::Param`] for a parameter out of range,
/// [`ForeignError::Unsupported`] for a rotor angle other than 0 with the
/// `dead_time` or `current_sensor_error` effect (they are tied to the
/// plant's own phases), [`ForeignError::Sim`] when the simulation fails.
pub fn simulate_commercial_travel(
    rig: &RigConfig,
    spec: &TravelSpec,
    drive: &ForeignDrive,
    options: &SimOptions,
    hook: Option<&mut dyn FaultHook>,
) -> Result<TravelRun, ForeignError> {
    let mut commercial = CommercialDrive::new(rig, drive)?;
    let angle = drive.rotor_start_angle_deg.to_radians();
    if angle == 0.0 {
        return Ok(simulate_travel_faulted(rig, spec, options, &mut commercial, hook, None, None)?);
    }
    if options.effects.dead_time.is_some() || options.effects.current_sensor_error.is_some() {
        return Err(ForeignError::Unsupported(format!(
            "drive: rotor_start_angle_deg = {} with the dead_time or current_sensor_error effect: those effects act on \
             the simulated machine's own phases, which only coincide with the drive's at rotor_start_angle_deg = 0",
            drive.rotor_start_angle_deg
        )));
    }
    let mut stator = RotatedStator {
        drive: &mut commercial,
        angle_rad: angle,
        sensors: Sensors::from_rig(rig),
        period_counts: rig.pwm_period_counts(),
    };
    let mut run = simulate_travel_faulted(rig, spec, options, &mut stator, hook, None, None)?;
    let [a, b, c] = &mut run.phase_currents_a;
    for k in 0..a.len() {
        let r = rotate_abc([a[k], b[k], c[k]], angle);
        (a[k], b[k], c[k]) = (r[0], r[1], r[2]);
    }
    Ok(run)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_moves_the_current_vector_and_keeps_the_zero_sequence() {
        use plant::pmsm::phase_currents_a;
        let (id, iq, theta) = (1.5, 12.0, 0.7);
        let plant = phase_currents_a(id, iq, theta);
        let rotated = rotate_abc(plant, 2.1);
        let expected = phase_currents_a(id, iq, theta + 2.1);
        for k in 0..3 {
            assert!((rotated[k] - expected[k]).abs() < 1e-12);
        }
        let with_zero = rotate_abc([1.0, 1.0, 1.0], 0.3);
        assert!(with_zero.iter().all(|v| (v - 1.0).abs() < 1e-12));
    }

    #[test]
    fn toml_lists_every_parameter() {
        let text = ForeignRig::commercial().to_toml();
        for p in ForeignDrive::PARAMS.iter().chain(Acquisition::PARAMS) {
            assert!(text.contains(&format!("{} = ", p.name)), "{}", p.name);
        }
        assert!(ForeignRig::default().to_toml().contains("project's drive core"));
    }

    #[test]
    fn toml_reads_back_what_it_writes_and_names_what_is_wrong() {
        use rand::SeedableRng;
        let drawn = ForeignRig::random(&mut rand::rngs::StdRng::seed_from_u64(3));
        assert_eq!(ForeignRig::from_toml_str(&drawn.to_toml(), "drawn").unwrap(), drawn);
        let only_daq = ForeignRig::from_toml_str("[acquisition]\nhighpass_hz = 0.3\n", "f").unwrap();
        assert!(only_daq.drive.is_none() && only_daq.acquisition.unwrap().highpass_hz == 0.3);
        let drive = ForeignRig::from_toml_str("[drive]\npre_torque = false\n", "f").unwrap().drive.unwrap();
        assert!(!drive.pre_torque);
        let err = ForeignRig::from_toml_str("[drive]\njerk_mps3 = 9\n", "rig.toml").unwrap_err().to_string();
        assert!(err.contains("jerk_mps3") && err.contains("[0.5, 2]"), "{err}");
        let err = ForeignRig::from_toml_str("[brake]\nx = 1\n", "rig.toml").unwrap_err().to_string();
        assert!(err.starts_with("rig.toml") && err.contains("[brake]"), "{err}");
    }
}
