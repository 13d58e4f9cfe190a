//! Foreign rigs: the commercial drive completes the rig's travels over its
//! parameter ranges, and the foreign acquisition's recordings show its
//! high-pass corner, its clock, its current quantisation and its
//! pre-trigger, each measured independently of the code that made them.

use std::sync::OnceLock;

use closed_loop::foreign::{simulate_commercial_travel, Acquisition, ForeignDrive, ForeignRig};
use closed_loop::synthetic::{make_foreign_dataset, DatasetSpec};
use closed_loop::{SimOptions, TravelRun, TravelSpec};
use drive_core::config::Direction;
use rand::SeedableRng;
use recording::{Recording, RecordingKind, ACC_CAR, ANGLE, I_A, I_B, I_C, REF_SPEED, SPEED, TIME_S};
use rig_config::RigConfig;

fn rig() -> RigConfig {
    RigConfig::embedded_default().expect("embedded rig")
}

/// Checks one full travel of the commercial drive with `drive`: it ends
/// idle with the car at rest near its landing, follows its profile, and
/// keeps the current below the trip level.
fn check_travel(rig: &RigConfig, drive: &ForeignDrive, m_car_kg: f64, direction: Direction) {
    let spec = TravelSpec::full_travel(rig, m_car_kg, direction);
    let options = SimOptions { sample_rate_hz: 500.0, ..SimOptions::for_rig(rig) };
    let what = format!("{m_car_kg} kg {direction:?} with {}", drive.summary());
    let run: TravelRun =
        simulate_commercial_travel(rig, &spec, drive, &options, None).unwrap_or_else(|e| panic!("{what}: {e}"));
    assert_eq!(run.drive_state.last(), Some(&0.0), "{what}: not idle at the end");
    let landing_error_m = run.lw_m.last().unwrap() - spec.lw_end_m;
    assert!(landing_error_m.abs() < 0.1, "{what}: landed {landing_error_m} m off");
    assert!(run.shaft_speed_radps.last().unwrap().abs() < 1e-9, "{what}: still moving");
    let r = rig.mechanics.sheave_radius_m;
    let rated = drive.rated_speed_mps;
    let (mut worst, mut cruise) = (0.0f64, Vec::new());
    for k in 0..run.time_s.len() {
        if run.drive_state[k] == 3.0 {
            let error = (run.shaft_speed_radps[k] * r - run.ref_speed_mps[k]).abs();
            worst = worst.max(error);
            if (run.ref_speed_mps[k].abs() - rated).abs() < 1e-6 {
                cruise.push(error);
            }
        }
    }
    assert!(worst < 0.35 * rated, "{what}: speed error up to {worst} m/s");
    assert!(cruise.len() > 1000, "{what}: no constant-speed stage");
    let late = &cruise[cruise.len() / 2..];
    let mean = late.iter().sum::<f64>() / late.len() as f64;
    assert!(mean < 0.03 * rated, "{what}: mean speed error {mean} m/s in the second half of the constant speed");
    let peak = run.phase_currents_a.iter().flatten().fold(0.0f64, |m, i| m.max(i.abs()));
    assert!(peak < rig.motor.overcurrent_trip_a, "{what}: {peak} A");
}

#[test]
fn commercial_drive_completes_full_travels_for_random_draws() {
    let rig = rig();
    for seed in [11, 12, 13] {
        let drive = ForeignDrive::random(&mut rand::rngs::StdRng::seed_from_u64(seed));
        for m in [33.0, 70.5] {
            for direction in [Direction::Up, Direction::Down] {
                check_travel(&rig, &drive, m, direction);
            }
        }
    }
}

#[test]
fn commercial_drive_completes_full_travels_at_the_corners_of_its_ranges() {
    let rig = rig();
    // The sloppiest: slowest loops, longest integral, slowest filter, no
    // pre-torque, light weighing, no inertia feed-forward, the hardest profile.
    let sloppy = ForeignDrive {
        current_bandwidth_hz: 250.0,
        speed_bandwidth_hz: 2.0,
        speed_integral_time_s: 0.4,
        speed_filter_time_constant_s: 0.01,
        pre_torque: false,
        weighing_error_pct: -10.0,
        inertia_feedforward: false,
        start_torque_ramp_s: 0.05,
        brake_lift_delay_s: 0.1,
        brake_drop_delay_s: 0.05,
        stop_torque_ramp_s: 0.05,
        rated_speed_mps: 0.5,
        accel_mps2: 0.8,
        jerk_mps3: 2.0,
        rotor_start_angle_deg: 200.0,
    };
    // The stiffest: fastest loops, shortest integral, slowest filter, heavy weighing.
    let stiff = ForeignDrive {
        current_bandwidth_hz: 1000.0,
        speed_bandwidth_hz: 8.0,
        speed_integral_time_s: 0.08,
        pre_torque: true,
        weighing_error_pct: 10.0,
        ..sloppy
    };
    for drive in [sloppy, stiff] {
        drive.validate().unwrap();
        check_travel(&rig, &drive, 70.5, Direction::Up);
        check_travel(&rig, &drive, 70.5, Direction::Down);
    }
}

/// The foreign rig of the recording tests, and its dataset: the 70.5 kg car
/// up and down, a 33 kg free decay on 2.5 m of rope.
fn dataset() -> &'static (ForeignRig, Vec<(String, Recording)>) {
    static DATA: OnceLock<(ForeignRig, Vec<(String, Recording)>)> = OnceLock::new();
    DATA.get_or_init(|| {
        let rig = rig();
        let mut foreign = ForeignRig::random(&mut rand::rngs::StdRng::seed_from_u64(7));
        let acq = foreign.acquisition.as_mut().unwrap();
        // A clock far off, and a pre-trigger long enough to see the quiet part.
        acq.set("clock_offset_ppm", -180.0).unwrap();
        acq.set("pre_trigger_s", 0.8).unwrap();
        let spec = DatasetSpec {
            m_car_kg: vec![70.5],
            decay_masses_kg: vec![33.0],
            decay_rope_length_m: 2.5,
            decay_duration_s: 2.0,
            ..DatasetSpec::rig(&rig)
        };
        let data = make_foreign_dataset(&rig, &spec, &foreign).expect("foreign dataset");
        (foreign, data)
    })
}

fn acquisition() -> Acquisition {
    dataset().0.acquisition.unwrap()
}

fn recording(stem: &str) -> &'static Recording {
    &dataset().1.iter().find(|(s, _)| s == stem).unwrap_or_else(|| panic!("no {stem}")).1
}

fn column<'a>(r: &'a Recording, name: &str) -> &'a [f64] {
    &r.column(name).unwrap_or_else(|| panic!("no {name}")).values
}

#[test]
fn recordings_load_and_their_time_column_is_uniform_at_the_acquisitions_rate() {
    let acq = acquisition();
    let dir = tempfile::tempdir().unwrap();
    for (stem, r) in &dataset().1 {
        assert_eq!(r.meta.sample_rate_hz, acq.sample_rate_hz, "{stem}");
        let t = column(r, TIME_S);
        let period = 1.0 / acq.sample_rate_hz;
        assert_eq!(t[0], 0.0);
        for k in 1..t.len() {
            assert!(((t[k] - t[k - 1]) - period).abs() < 1e-9 * period, "{stem}: step {k}");
        }
        recording::write_recording(dir.path(), stem, r).unwrap();
    }
    let read = recording::read_dataset(dir.path(), rig().mechanics.rope_total_length_m).unwrap();
    assert_eq!(read.len(), dataset().1.len());
    // The travel is as long on the acquisition's clock as its clock error
    // makes it: its motion starts at the pre-trigger time.
    let up = recording("travel_up_m70.5");
    let reference = column(up, REF_SPEED);
    let first = reference.iter().position(|v| *v > 1e-9).unwrap();
    let expected = acq.pre_trigger_s * (1.0 + acq.clock_offset_ppm * 1e-6) * acq.sample_rate_hz;
    // The drive's first reference comes one speed-loop period after it
    // enters its travel state; then the anti-alias filter's delay.
    let late = closed_loop::foreign::commercial_drive::SPEED_LOOP_PERIOD_S * acq.sample_rate_hz + 10.0;
    let after = first as f64 - expected;
    assert!(after > -2.0 && after < late, "motion at sample {first}, pre-trigger at {expected}");
}

#[test]
fn current_columns_are_quantised_to_the_acquisitions_step() {
    let acq = acquisition();
    let step = 2.0 * acq.current_full_scale_a / 2f64.powi(acq.current_bits as i32);
    for stem in ["travel_up_m70.5", "travel_down_m70.5"] {
        let r = recording(stem);
        for name in [I_A, I_B, I_C] {
            let values = column(r, name);
            for v in values {
                let codes = v / step;
                assert!((codes - codes.round()).abs() < 1e-9, "{stem} {name}: {v} is not a multiple of {step}");
            }
            let mut distinct: Vec<i64> = values.iter().map(|v| (v / step).round() as i64).collect();
            distinct.sort_unstable();
            distinct.dedup();
            assert!(distinct.len() > 50, "{stem} {name}: {} codes", distinct.len());
        }
    }
}

/// First-order high-pass `s / (s + wc)` of `x` (sampled every `dt` s) for
/// an input linear between samples: the exact solution of
/// `y' = -wc y + x'`.
fn exact_highpass(x: &[f64], corner_hz: f64, dt: f64) -> Vec<f64> {
    let wc = std::f64::consts::TAU * corner_hz;
    let decay = (-wc * dt).exp();
    let gain = (1.0 - decay) / (wc * dt);
    let mut y = vec![0.0; x.len()];
    for k in 1..x.len() {
        y[k] = decay * y[k - 1] + gain * (x[k] - x[k - 1]);
    }
    y
}

/// Two passes of a centred moving average over `n` samples.
fn smooth(x: &[f64], n: usize) -> Vec<f64> {
    let pass = |x: &[f64]| -> Vec<f64> {
        let mut prefix = vec![0.0; x.len() + 1];
        for (k, v) in x.iter().enumerate() {
            prefix[k + 1] = prefix[k] + v;
        }
        (0..x.len())
            .map(|k| {
                let (lo, hi) = (k.saturating_sub(n / 2), (k + n / 2 + 1).min(x.len()));
                (prefix[hi] - prefix[lo]) / (hi - lo) as f64
            })
            .collect()
    };
    pass(&pass(x))
}

#[test]
fn highpass_corner_measured_from_a_travel_equals_the_parameter() {
    // The car's low-frequency acceleration is the sheave's, `r d(speed)/dt`;
    // the recorded accelerometer is that through the acquisition's
    // high-pass. Fit its corner by least squares over the whole travel.
    let acq = acquisition();
    let r_sheave = rig().mechanics.sheave_radius_m;
    let up = recording("travel_up_m70.5");
    let fs = acq.sample_rate_hz;
    let speed = column(up, SPEED);
    let n = speed.len();
    let accel: Vec<f64> = (0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(n - 1));
            r_sheave * (speed[b] - speed[a]) * fs / (b - a) as f64
        })
        .collect();
    let window = (0.25 * fs) as usize;
    let recorded = smooth(column(up, ACC_CAR), window);
    let accel = smooth(&accel, window);
    let residual = |corner_hz: f64| -> f64 {
        let model = exact_highpass(&accel, corner_hz, 1.0 / fs);
        model.iter().zip(&recorded).map(|(m, r)| (m - r).powi(2)).sum()
    };
    let mut best = (f64::INFINITY, 0.0);
    for i in 0..=400 {
        let corner = 0.05 * (60.0f64).powf(i as f64 / 400.0); // 0.05 .. 3 Hz
        let e = residual(corner);
        if e < best.0 {
            best = (e, corner);
        }
    }
    let measured = best.1;
    println!("high-pass corner: measured {measured} Hz, parameter {} Hz", acq.highpass_hz);
    assert!((measured / acq.highpass_hz - 1.0).abs() < 0.1, "measured {measured} Hz, parameter {} Hz", acq.highpass_hz);
}

/// Eqn 9 for the fundamental, solved here by Newton's method: `x tan x =
/// mu l / m`, `f = x / l sqrt(EA / mu) / (2 pi)`.
fn eqn9_frequency_hz(ea_n: f64, mu: f64, length_m: f64, mass_kg: f64) -> f64 {
    let ratio = mu * length_m / mass_kg;
    let mut x = ratio.sqrt();
    for _ in 0..50 {
        let f = x * x.tan() - ratio;
        let df = x.tan() + x / x.cos().powi(2);
        x -= f / df;
    }
    x / length_m * (ea_n / mu).sqrt() / std::f64::consts::TAU
}

#[test]
fn decay_is_quiet_before_the_release_and_rings_at_the_eqn9_frequency_after_it() {
    let acq = acquisition();
    let rig = rig();
    let m = &rig.mechanics;
    let decay = recording("decay_m33.0");
    let RecordingKind::FreeDecay { mass_kg, rope_length_m } = decay.meta.kind else { panic!("not a decay") };
    let acc = column(decay, ACC_CAR);
    let fs = acq.sample_rate_hz;
    let release = (acq.pre_trigger_s * (1.0 + acq.clock_offset_ppm * 1e-6) * fs) as usize;
    let before = &acc[..release - 2];
    let rms = (before.iter().map(|v| v * v).sum::<f64>() / before.len() as f64).sqrt();
    assert!(rms < 1.2 * acq.acc_noise_mps2 + 1e-4, "before the release: rms {rms} m/s^2");
    let after = &acc[release + 2..release + 2 + fs as usize];
    let peak = after.iter().fold(0.0f64, |p, v| p.max(v.abs()));
    assert!(peak > 0.5 * acq.release_acceleration_mps2, "after the release: peak {peak} m/s^2");
    // The strongest line of the first second after the release.
    let magnitude = |f: f64| -> f64 {
        let (mut re, mut im) = (0.0, 0.0);
        for (k, v) in after.iter().enumerate() {
            let (s, c) = (std::f64::consts::TAU * f * k as f64 / fs).sin_cos();
            re += v * c;
            im -= v * s;
        }
        re.hypot(im)
    };
    let expected = eqn9_frequency_hz(m.rope_ea_n, m.rope_mass_per_length_kg_per_m, rope_length_m, mass_kg);
    let (mut best, mut at) = (0.0, 0.0);
    for i in 0..=3000 {
        let f = expected * (0.5 + i as f64 / 2000.0); // 0.5 .. 2 times Eqn 9
        let v = magnitude(f);
        if v > best {
            (best, at) = (v, f);
        }
    }
    // The acquisition's clock scales recorded frequencies by 1 / (1 + ppm).
    let recorded = at * (1.0 + acq.clock_offset_ppm * 1e-6);
    println!("decay: rms {rms} m/s^2 before the release, rings at {recorded} Hz, Eqn 9 {expected} Hz");
    assert!((recorded / expected - 1.0).abs() < 0.005, "rings at {recorded} Hz, Eqn 9 gives {expected} Hz");
}

#[test]
fn machine_torque_of_the_heavy_car_going_up_lifts_it_under_the_dq0_convention() {
    // Eqn 4 and Eqn 13: at constant speed the machine carries the
    // out-of-balance weight and the viscous losses.
    let (foreign, _) = dataset();
    let drive = foreign.drive.unwrap();
    let rig = rig();
    let m = &rig.mechanics;
    let up = recording("travel_up_m70.5");
    let reference = column(up, REF_SPEED);
    let cruise: Vec<usize> =
        (0..reference.len()).filter(|&k| (reference[k] - drive.rated_speed_mps).abs() < 1e-4).collect();
    let stage = cruise[cruise.len() / 4]..cruise[3 * cruise.len() / 4];
    let torque = dsp::machine_torque_nm(
        column(up, I_A),
        column(up, I_B),
        column(up, I_C),
        column(up, ANGLE),
        rig.motor.pole_pairs,
        rig.motor.flux_linkage_wb,
        rig.motor.ld_h,
        rig.motor.lq_h,
        drive.rotor_start_angle_deg.to_radians(),
    )
    .unwrap();
    let n = stage.len() as f64;
    let mean = torque[stage.clone()].iter().sum::<f64>() / n;
    let RecordingKind::Travel { lw_start_m, .. } = up.meta.kind else { panic!("not a travel") };
    let r = m.sheave_radius_m;
    let angle = column(up, ANGLE);
    let out_of_balance = stage
        .clone()
        .map(|k| {
            let lw = lw_start_m + r * angle[k];
            (70.5 - m.m_cw_kg + m.rope_mass_per_length_kg_per_m * (m.rope_total_length_m - 2.0 * lw))
                * m.gravity_mps2
                * r
        })
        .sum::<f64>()
        / n;
    let omega = drive.rated_speed_mps / r;
    let losses = m.c_sheave_nms_per_rad * omega + (m.c_cw_kg_per_s + m.c_car_kg_per_s) * r * r * omega;
    let expected = out_of_balance + losses;
    println!("mean machine torque {mean} N m, expected {expected} N m");
    assert!(mean > 0.0 && (mean / expected - 1.0).abs() < 0.1, "mean torque {mean} N m, expected {expected} N m");
}

#[test]
fn bad_parameters_and_help_name_the_parameter_and_its_range() {
    let host_sim = env!("CARGO_BIN_EXE_host-sim");
    let out = std::process::Command::new(host_sim)
        .args(["dataset", "--drive-param", "speed_bandwidth_hz=20", "--out", "/nonexistent/never"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("speed_bandwidth_hz") && err.contains("[2, 8]"), "{err}");
    let out = std::process::Command::new(host_sim)
        .args(["dataset", "--acquisition", "project", "--daq-param", "highpass_hz=0.5"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("--daq-param"), "{err}");
    let out = std::process::Command::new(host_sim).args(["dataset", "--help"]).output().unwrap();
    let help = String::from_utf8_lossy(&out.stdout);
    for p in ForeignDrive::PARAMS.iter().chain(Acquisition::PARAMS) {
        let line = help.lines().find(|l| l.trim_start().starts_with(&format!("{} = ", p.name)));
        let line = line.unwrap_or_else(|| panic!("--help does not list {}", p.name));
        assert!(line.contains(p.unit) || p.unit == "-", "{line}");
    }
}
