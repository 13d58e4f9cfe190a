//! A recording checked against itself and its metadata, after every sample
//! has been read and bounded ([`crate::read`]) and before any analysis sees
//! it. What is refused here would otherwise give a silently wrong answer:
//!
//! * a **dead accelerometer**: an acceleration column whose samples are all
//!   equal (a disconnected, saturated or switched-off sensor; a real frame
//!   always vibrates, and the format's piezoelectric sensors have no DC to
//!   hold);
//! * a **wrapped or glitched angle**: `angle_rad` is the unwrapped shaft
//!   angle, so between two samples it changes by at most what the fastest
//!   recorded speed turns the shaft in two sample periods (plus an encoder
//!   line's worth); a wrap to `[0, 2 pi)` or `(-pi, pi]` jumps by about
//!   `2 pi`;
//! * an **angle that contradicts the speed**: over the recording the angle
//!   must turn as far as the recorded speed integrates to, in the same
//!   sense (a constant angle, an angle that runs backwards);
//! * a **travel that moves the other way** than its metadata's `direction`:
//!   `speed_radps` is positive when the car moves up (the format), so a
//!   travel up integrates to a positive shaft angle;
//! * a **travel whose metadata describe another distance** than its shaft
//!   turned on the rig's sheave ([`check_travel_distance`], which needs the
//!   rig's sheave radius and so is called by the commands that have it);
//! * a **pole-pair count that is not the machine's**: the phase currents
//!   of a travel turn `p` electrical turns per shaft turn
//!   ([`check_pole_pairs`], with the rig's `p`);
//! * a **one-sample glitch** in a phase current or the speed: a sample
//!   that leaves both neighbours by more than the rig's physics can move
//!   the signal in a sample period, and comes back
//!   ([`check_slew`], with limits the commands compute from the rig).
//!
//! Each error names the file, the line of the first offending sample where
//! there is one, the column or field, what the data show and what is
//! expected.

use std::path::Path;

use crate::read::ReadError;
use crate::{CarDirection, Recording, RecordingKind, ACC_CAR, ACC_CW, ACC_MACHINE, ANGLE, I_A, I_B, SPEED};

/// Slack of the angle-step bound, rad: an encoder of 256 lines or more
/// resolves far finer; a wrap jumps by about `2 pi`.
pub const ANGLE_STEP_SLACK_RAD: f64 = 0.05;

/// The sample-to-sample angle change allowed is this many times what the
/// fastest recorded speed turns in one period: the speed column is a
/// filtered estimate that may lag or undershoot the true speed.
pub const ANGLE_STEP_SPEED_FACTOR: f64 = 2.0;

/// The recorded angle and the integrated speed must agree over the
/// recording within this fraction of the larger (speed estimates filter and
/// lag; both come from the one encoder) ...
pub const ANGLE_SPEED_AGREEMENT: f64 = 0.1;
/// ... plus this many rad (a few samples of estimator lag at rated speed).
pub const ANGLE_SPEED_SLACK_RAD: f64 = 0.5;

/// A travel is checked against its `direction` only when its shaft turned
/// mostly one way: the net angle at least this fraction of the total turned.
pub const ONE_WAY_FRACTION: f64 = 0.5;
/// ... and by at least this many rad (a recording at standstill has no
/// direction to contradict).
pub const MIN_TRAVEL_ANGLE_RAD: f64 = 1.0;

/// The line of sample row `row` (0-based) of a samples file: the header is
/// line 1 and rows follow without blank lines ([`crate::read`]).
fn line_of(row: usize) -> usize {
    row + 2
}

/// Checks `recording` (read from `toml_path` and `csv_path`) against itself
/// and its metadata; see the module documentation.
///
/// # Errors
/// [`ReadError::Inconsistent`] naming the file, line, column or field.
pub fn check(recording: &Recording, toml_path: &Path, csv_path: &Path) -> Result<(), ReadError> {
    for name in [ACC_CAR, ACC_CW, ACC_MACHINE] {
        if let Some(column) = recording.column(name) {
            check_live(&column.values, name, csv_path)?;
        }
    }
    let dt = 1.0 / recording.meta.sample_rate_hz;
    let speed = recording.column(SPEED).map(|c| c.values.as_slice());
    if let Some(angle) = recording.column(ANGLE) {
        check_angle_steps(&angle.values, speed, dt, csv_path)?;
        if let Some(speed) = speed {
            check_angle_against_speed(&angle.values, speed, dt, csv_path)?;
        }
    }
    if let (RecordingKind::Travel { direction, .. }, Some(speed)) = (&recording.meta.kind, speed) {
        check_direction(*direction, speed, dt, toml_path)?;
    }
    Ok(())
}

fn inconsistent(path: &Path, line: Option<usize>, column: &str, found: String, expected: &str) -> ReadError {
    ReadError::Inconsistent {
        path: path.to_path_buf(),
        line,
        column: column.to_string(),
        found,
        expected: expected.to_string(),
    }
}

/// Refuses an acceleration `values` (column `name` of `path`) whose samples
/// are all equal: a dead, saturated or disconnected sensor.
///
/// # Errors
/// [`ReadError::Inconsistent`] naming the file and the column.
pub fn check_live(values: &[f64], name: &str, path: &Path) -> Result<(), ReadError> {
    match values.first() {
        Some(&first) if values.len() > 1 && values.iter().all(|&a| a == first) => Err(inconsistent(
            path,
            None,
            name,
            format!("every one of its {} samples is {first}: a dead, saturated or disconnected sensor", values.len()),
            "a live accelerometer (a frame always vibrates)",
        )),
        _ => Ok(()),
    }
}

/// No step of the angle larger than the fastest recorded speed allows.
fn check_angle_steps(angle: &[f64], speed: Option<&[f64]>, dt: f64, path: &Path) -> Result<(), ReadError> {
    let fastest = match speed {
        Some(s) => s.iter().fold(0.0_f64, |m, w| m.max(w.abs())),
        None => crate::column_bound(SPEED).map_or(f64::INFINITY, |(bound, _)| bound),
    };
    let limit = ANGLE_STEP_SPEED_FACTOR * fastest * dt + ANGLE_STEP_SLACK_RAD;
    let Some(k) = angle.windows(2).position(|w| (w[1] - w[0]).abs() > limit) else {
        return Ok(());
    };
    let step = angle[k + 1] - angle[k];
    let wrap =
        if (step.abs() - std::f64::consts::TAU).abs() < 1.0 { " (a wrap by one revolution)" } else { " (a glitch)" };
    Err(inconsistent(
        path,
        Some(line_of(k + 1)),
        ANGLE,
        format!("the angle jumps by {step:.4} rad from the line before{wrap}"),
        &format!(
            "the unwrapped shaft angle (the format), which moves by at most {limit:.4} rad per sample at the \
             recording's fastest speed ({fastest:.4} rad/s)"
        ),
    ))
}

/// The angle turned over the recording agrees with the integrated speed.
fn check_angle_against_speed(angle: &[f64], speed: &[f64], dt: f64, path: &Path) -> Result<(), ReadError> {
    let (Some(first), Some(last)) = (angle.first(), angle.last()) else { return Ok(()) };
    let turned = last - first;
    let integrated = integral(speed, dt);
    let tolerance = ANGLE_SPEED_AGREEMENT * turned.abs().max(integrated.abs()) + ANGLE_SPEED_SLACK_RAD;
    if (turned - integrated).abs() <= tolerance {
        return Ok(());
    }
    Err(inconsistent(
        path,
        None,
        ANGLE,
        format!(
            "the angle turns by {turned:.3} rad over the recording, but `{SPEED}` integrates to {integrated:.3} rad"
        ),
        "an angle and a speed from the same shaft (both positive when the car moves up), or leave the angle out",
    ))
}

/// A travel that turned the shaft mostly one way turned it the way its
/// metadata's `direction` says.
fn check_direction(direction: CarDirection, speed: &[f64], dt: f64, toml_path: &Path) -> Result<(), ReadError> {
    let net = integral(speed, dt);
    let total: f64 = speed.iter().map(|w| w.abs() * dt).sum();
    if total < MIN_TRAVEL_ANGLE_RAD || net.abs() < ONE_WAY_FRACTION * total {
        return Ok(());
    }
    let (said, moved) = match direction {
        CarDirection::Up => ("up", if net > 0.0 { None } else { Some("down") }),
        CarDirection::Down => ("down", if net < 0.0 { None } else { Some("up") }),
    };
    let Some(moved) = moved else { return Ok(()) };
    Err(inconsistent(
        toml_path,
        None,
        "direction",
        format!(
            "the metadata says direction = \"{said}\", but `{SPEED}` (positive when the car moves up) integrates to \
             {net:+.2} rad over the samples: the car moved {moved}"
        ),
        "the direction the samples show (or the speed with the format's sign)",
    ))
}

/// The travel's rope-length change in its metadata agrees with the
/// distance its shaft turned (1:1 roping: the car moves `r` times the shaft
/// angle, `r` the rig's sheave radius; the angle column where there is one,
/// else the integrated speed) within this fraction ...
pub const DISTANCE_AGREEMENT: f64 = 0.1;
/// ... plus this many m (rope creep and stretch, a levelling correction).
pub const DISTANCE_SLACK_M: f64 = 0.05;

/// Checks a travel's `lw_start_m`..`lw_end_m` against the distance its
/// shaft turned on a sheave of radius `sheave_radius_m` (m, the rig's):
/// metadata that describe another travel than the samples (a travel cut
/// short, a speed in other units, another rig) are refused with both sides
/// named. A free decay passes.
///
/// # Errors
/// [`ReadError::Inconsistent`] naming the metadata file and its fields.
pub fn check_travel_distance(recording: &Recording, toml_path: &Path, sheave_radius_m: f64) -> Result<(), ReadError> {
    let RecordingKind::Travel { lw_start_m, lw_end_m, .. } = recording.meta.kind else { return Ok(()) };
    let dt = 1.0 / recording.meta.sample_rate_hz;
    let (turned, from) = match (recording.column(ANGLE), recording.column(SPEED)) {
        (Some(a), _) if a.values.len() > 1 => (a.values[a.values.len() - 1] - a.values[0], ANGLE),
        (_, Some(w)) => (integral(&w.values, dt), SPEED),
        _ => return Ok(()),
    };
    let moved_m = (turned * sheave_radius_m).abs();
    let said_m = (lw_end_m - lw_start_m).abs();
    if (moved_m - said_m).abs() <= DISTANCE_AGREEMENT * said_m.max(moved_m) + DISTANCE_SLACK_M {
        return Ok(());
    }
    Err(inconsistent(
        toml_path,
        None,
        "lw_start_m, lw_end_m",
        format!(
            "the metadata say the rope length changes by {said_m:.3} m ({lw_start_m} -> {lw_end_m}), but `{from}` \
             turns the shaft by {turned:.2} rad, {moved_m:.3} m of rope on the rig's {sheave_radius_m} m sheave"
        ),
        "metadata of the travel the samples record, the samples of a whole travel, and the rig it ran on (--config)",
    ))
}

/// The current vector's turns are counted on samples whose current
/// magnitude is at least this fraction of the recording's largest (below,
/// its angle is noise) ...
pub const POLE_PAIR_CURRENT_FRACTION: f64 = 0.2;
/// ... over at least this much shaft rotation, rad (two turns).
pub const POLE_PAIR_MIN_SHAFT_RAD: f64 = 4.0 * std::f64::consts::PI;
/// Electrical turns per shaft turn further than this from the rig's pole
/// pairs: another machine's count.
pub const POLE_PAIR_TOLERANCE: f64 = 0.5;

/// Electrical turns of the phase currents per shaft turn over a travel:
/// the angle of the current vector (`alpha = i_a`, `beta = (i_a + 2 i_b) /
/// sqrt 3`) turned, over the shaft angle turned (the integrated speed),
/// both summed over consecutive samples whose current magnitude reaches
/// [`POLE_PAIR_CURRENT_FRACTION`] of the largest. `None` for a free decay,
/// a recording without the columns, or less than
/// [`POLE_PAIR_MIN_SHAFT_RAD`] of shaft rotation counted.
pub fn electrical_turns_per_shaft_turn(recording: &Recording) -> Option<f64> {
    let RecordingKind::Travel { .. } = recording.meta.kind else { return None };
    let (a, b, w) = (&recording.column(I_A)?.values, &recording.column(I_B)?.values, &recording.column(SPEED)?.values);
    let dt = 1.0 / recording.meta.sample_rate_hz;
    let vector = |k: usize| (a[k], (a[k] + 2.0 * b[k]) / 3f64.sqrt());
    let magnitude = |k: usize| {
        let (x, y) = vector(k);
        x.hypot(y)
    };
    let n = a.len().min(b.len()).min(w.len());
    let largest = (0..n).map(magnitude).fold(0.0, f64::max);
    let (mut electrical, mut shaft) = (0.0, 0.0);
    for (k, speed) in w.iter().enumerate().take(n).skip(1) {
        if magnitude(k - 1) < POLE_PAIR_CURRENT_FRACTION * largest
            || magnitude(k) < POLE_PAIR_CURRENT_FRACTION * largest
        {
            continue;
        }
        let ((x0, y0), (x1, y1)) = (vector(k - 1), vector(k));
        // The turn between the two vectors, in (-pi, pi].
        electrical += (x0 * y1 - y0 * x1).atan2(x0 * x1 + y0 * y1);
        shaft += speed * dt;
    }
    (shaft.abs() >= POLE_PAIR_MIN_SHAFT_RAD).then(|| (electrical / shaft).abs())
}

/// Refuses a travel whose phase currents turn another number of electrical
/// turns per shaft turn than `pole_pairs` (the rig's `[motor].pole_pairs`):
/// a rig file of another machine would turn the currents into a torque
/// that neither follows nor opposes the motion. Names the samples file and
/// the rig's field. A travel with too little current or rotation to count
/// passes.
///
/// # Errors
/// [`ReadError::Inconsistent`] naming the samples file and `[motor].pole_pairs`.
pub fn check_pole_pairs(recording: &Recording, csv_path: &Path, pole_pairs: u32) -> Result<(), ReadError> {
    let Some(turns) = electrical_turns_per_shaft_turn(recording) else { return Ok(()) };
    if turns < POLE_PAIR_TOLERANCE || (turns - f64::from(pole_pairs)).abs() <= POLE_PAIR_TOLERANCE {
        return Ok(());
    }
    Err(inconsistent(
        csv_path,
        None,
        &format!("{I_A}, {I_B}"),
        format!(
            "the phase currents turn {turns:.2} electrical turns per shaft turn (`{SPEED}` integrated), but the \
             rig's [motor].pole_pairs = {pole_pairs}"
        ),
        "the pole pairs of the machine that made the recording (--config, [motor].pole_pairs)",
    ))
}

/// How fast the recorded signals of a rig can change, from the rig's
/// physics (the commands compute it from `--config`): a step between two
/// samples beyond it is a glitch of the acquisition, not the machine.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlewLimits {
    /// Largest rate of change of a phase current, A/s (the whole bus and
    /// the back-EMF across the smallest winding inductance).
    pub current_a_per_s: f64,
    /// Smallest change of a current the acquisition shows, A (quantum and
    /// noise): added to every step allowed.
    pub current_slack_a: f64,
    /// Largest shaft acceleration, rad/s^2 (the largest measurable torque
    /// and the ropes' pull on the machine's inertia).
    pub shaft_rad_per_s2: f64,
    /// Smallest change of the speed estimate, rad/s (an encoder line per
    /// sample period): added to every step allowed.
    pub speed_slack_radps: f64,
}

/// A step between two samples is a glitch when larger than this many times
/// the rig's fastest physical change over one sample period, plus the slack.
pub const SLEW_FACTOR: f64 = 2.0;

/// Refuses a one-sample glitch in a phase current or the speed of a travel
/// (a sample that leaves both neighbours by more than [`SlewLimits`] allows
/// and comes back), naming the samples file, the line and the column.
///
/// # Errors
/// [`ReadError::Inconsistent`].
pub fn check_slew(recording: &Recording, csv_path: &Path, limits: &SlewLimits) -> Result<(), ReadError> {
    let dt = 1.0 / recording.meta.sample_rate_hz;
    let current = SLEW_FACTOR * limits.current_a_per_s * dt + limits.current_slack_a;
    let speed = SLEW_FACTOR * limits.shaft_rad_per_s2 * dt + limits.speed_slack_radps;
    for (name, limit, unit, why) in [
        (crate::I_A, current, "A", "the bus across the winding"),
        (crate::I_B, current, "A", "the bus across the winding"),
        (crate::I_C, current, "A", "the bus across the winding"),
        (SPEED, speed, "rad/s", "the largest torque on the machine's inertia"),
    ] {
        let Some(column) = recording.column(name) else { continue };
        let Some(k) = column.values.windows(3).position(|w| is_spike(w, limit)) else { continue };
        let step = column.values[k + 1] - column.values[k];
        return Err(inconsistent(
            csv_path,
            Some(line_of(k + 1)),
            name,
            format!("the signal steps by {step:.4} {unit} from the line before and back on the next: a glitch"),
            &format!(
                "a step of at most {limit:.4} {unit} per sample on this rig ({why}, twice over, plus the \
                 acquisition's resolution)"
            ),
        ));
    }
    Ok(())
}

/// Whether the middle of three samples `w` is a one-sample spike: it leaves
/// both neighbours by more than `limit` in the same sense while they agree
/// within `limit`. A step that stays (an ideal current loop, a drive that
/// drops its current at a trip) is no glitch.
fn is_spike(w: &[f64], limit: f64) -> bool {
    let (out, back) = (w[1] - w[0], w[1] - w[2]);
    out.signum() == back.signum() && out.abs().min(back.abs()) > limit && (w[2] - w[0]).abs() <= limit
}

/// The integral of `signal` sampled every `dt` (rectangle rule), in its unit times s.
fn integral(signal: &[f64], dt: f64) -> f64 {
    signal.iter().sum::<f64>() * dt
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Column, RecordingMeta, TIME_S};
    use std::f64::consts::TAU;

    /// A 4 s travel at 1 kHz: the shaft speeds up to 6 rad/s and back,
    /// `angle` its exact integral.
    fn travel(direction: CarDirection) -> Recording {
        let fs = 1000.0;
        let n = 4000;
        let sign = if direction == CarDirection::Up { 1.0 } else { -1.0 };
        let speed: Vec<f64> = (0..n).map(|k| sign * 6.0 * (std::f64::consts::PI * k as f64 / n as f64).sin()).collect();
        let angle: Vec<f64> = speed.iter().scan(0.3, |a, w| Some(std::mem::replace(a, *a + w / fs))).collect();
        let acc: Vec<f64> = (0..n).map(|k| 0.01 * (k as f64 * 0.7).sin()).collect();
        Recording {
            meta: RecordingMeta {
                kind: RecordingKind::Travel {
                    m_car_kg: 70.5,
                    m_cw_kg: 33.0,
                    direction,
                    lw_start_m: 1.0,
                    lw_end_m: 2.0,
                },
                sample_rate_hz: fs,
                description: None,
            },
            columns: vec![
                Column::new(TIME_S, (0..n).map(|k| k as f64 / fs).collect()),
                Column::new(ACC_CAR, acc),
                Column::new(SPEED, speed),
                Column::new(ANGLE, angle),
            ],
        }
    }

    fn values<'a>(r: &'a mut Recording, name: &str) -> &'a mut Vec<f64> {
        &mut r.columns.iter_mut().find(|c| c.name == name).unwrap().values
    }

    fn error(r: &Recording) -> String {
        check(r, Path::new("t.toml"), Path::new("t.csv")).unwrap_err().to_string()
    }

    #[test]
    fn currents_that_turn_another_pole_pair_count_than_the_rigs_are_refused_naming_the_field() {
        // The travel's currents: 10 A turning 6 electrical turns per shaft turn.
        let mut r = travel(CarDirection::Up);
        let angle = r.column(ANGLE).unwrap().values.clone();
        let phase = |shift: f64| -> Vec<f64> { angle.iter().map(|a| 10.0 * (6.0 * a - shift).cos()).collect() };
        r.columns.push(Column::new(I_A, phase(0.0)));
        r.columns.push(Column::new(I_B, phase(TAU / 3.0)));
        let turns = electrical_turns_per_shaft_turn(&r).unwrap();
        assert!((turns - 6.0).abs() < 1e-3, "{turns}");
        let csv = Path::new("d/up.csv");
        check_pole_pairs(&r, csv, 6).unwrap();
        let err = check_pole_pairs(&r, csv, 5).unwrap_err().to_string();
        assert!(
            err.contains("d/up.csv") && err.contains("6.00 electrical turns") && err.contains("[motor].pole_pairs = 5"),
            "{err}"
        );
        // Down, the same count; a free decay has none to count.
        let mut down = travel(CarDirection::Down);
        let angle = down.column(ANGLE).unwrap().values.clone();
        let phase = |shift: f64| -> Vec<f64> { angle.iter().map(|a| 10.0 * (6.0 * a - shift).cos()).collect() };
        down.columns.push(Column::new(I_A, phase(0.0)));
        down.columns.push(Column::new(I_B, phase(TAU / 3.0)));
        assert!(check_pole_pairs(&down, csv, 12).is_err() && check_pole_pairs(&down, csv, 6).is_ok());
        r.meta.kind = RecordingKind::FreeDecay { mass_kg: 33.0, rope_length_m: 2.5 };
        assert_eq!(electrical_turns_per_shaft_turn(&r), None);
    }

    #[test]
    fn a_consistent_travel_passes_either_way() {
        for d in [CarDirection::Up, CarDirection::Down] {
            check(&travel(d), Path::new("t.toml"), Path::new("t.csv")).unwrap();
        }
    }

    #[test]
    fn a_wrapped_angle_is_refused_at_its_first_wrap() {
        let mut r = travel(CarDirection::Up);
        let angle = values(&mut r, ANGLE);
        let first_wrap = angle.iter().position(|&a| a >= TAU).unwrap();
        for a in angle.iter_mut() {
            *a = a.rem_euclid(TAU);
        }
        let err = error(&r);
        assert!(err.contains(&format!("line {}", first_wrap + 2)) && err.contains("wrap"), "{err}");
        assert!(err.contains("t.csv") && err.contains("angle_rad"), "{err}");
    }

    #[test]
    fn a_one_sample_angle_glitch_is_refused_with_its_line() {
        let mut r = travel(CarDirection::Up);
        values(&mut r, ANGLE)[1234] += 0.5;
        let err = error(&r);
        // Row 1234 is on line 1236 (the header is line 1).
        assert!(err.contains("line 1236") && err.contains("glitch"), "{err}");
    }

    #[test]
    fn a_constant_or_backward_angle_contradicts_the_speed() {
        let mut r = travel(CarDirection::Up);
        values(&mut r, ANGLE).iter_mut().for_each(|a| *a = 1.0);
        assert!(error(&r).contains("integrates to"), "{}", error(&r));
        let mut r = travel(CarDirection::Up);
        values(&mut r, ANGLE).iter_mut().for_each(|a| *a = -*a);
        assert!(error(&r).contains("integrates to"), "{}", error(&r));
    }

    #[test]
    fn a_travel_against_its_metadata_direction_is_refused_naming_the_field() {
        let mut r = travel(CarDirection::Up);
        if let RecordingKind::Travel { direction, .. } = &mut r.meta.kind {
            *direction = CarDirection::Down;
        }
        let err = error(&r);
        assert!(err.contains("t.toml") && err.contains("direction = \"down\"") && err.contains("moved up"), "{err}");
    }

    #[test]
    fn a_travel_whose_metadata_describe_another_distance_is_refused() {
        // The test travel turns the shaft by 6 * 4 s * 2 / pi = 15.28 rad.
        let r = travel(CarDirection::Up);
        let turned = values(&mut r.clone(), ANGLE).last().unwrap() - 0.3;
        let path = Path::new("t.toml");
        // A sheave on which that is the metadata's 1 m: accepted.
        check_travel_distance(&r, path, 1.0 / turned).unwrap();
        // Twice the radius: twice the distance.
        let err = check_travel_distance(&r, path, 2.0 / turned).unwrap_err().to_string();
        assert!(err.contains("t.toml") && err.contains("lw_start_m") && err.contains("2.000 m of rope"), "{err}");
        // Without the angle, the integrated speed tells the same.
        let mut no_angle = r.clone();
        no_angle.columns.retain(|c| c.name != ANGLE);
        assert!(check_travel_distance(&no_angle, path, 2.0 / turned).unwrap_err().to_string().contains(SPEED));
    }

    #[test]
    fn a_one_sample_glitch_in_a_current_or_the_speed_is_refused_with_its_line() {
        let limits = SlewLimits {
            current_a_per_s: 2.0e4,
            current_slack_a: 0.5,
            shaft_rad_per_s2: 500.0,
            speed_slack_radps: 0.5,
        };
        let mut r = travel(CarDirection::Up);
        r.columns.push(Column::new(crate::I_A, (0..4000).map(|k| 10.0 * (0.01 * k as f64).sin()).collect()));
        let path = Path::new("t.csv");
        check_slew(&r, path, &limits).unwrap();
        // At 1 kHz the rig allows 2 x 20 A + 0.5 A a sample.
        values(&mut r, crate::I_A)[700] += 100.0;
        let err = check_slew(&r, path, &limits).unwrap_err().to_string();
        assert!(err.contains("line 702") && err.contains("i_a_A") && err.contains("glitch"), "{err}");
        let mut r = travel(CarDirection::Up);
        values(&mut r, SPEED)[99] = 60.0;
        let err = check_slew(&r, path, &limits).unwrap_err().to_string();
        assert!(err.contains("line 101") && err.contains("speed_radps"), "{err}");
    }

    #[test]
    fn a_dead_accelerometer_is_refused() {
        let mut r = travel(CarDirection::Down);
        values(&mut r, ACC_CAR).iter_mut().for_each(|a| *a = 0.0);
        let err = error(&r);
        assert!(err.contains("acc_car_mps2") && err.contains("dead"), "{err}");
    }
}
