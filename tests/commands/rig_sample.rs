//! Recordings this project did not make: `../shared/rig-sample/` beside the
//! repository holds recordings of the reference rig (`../shared/spec/rig.toml`,
//! no unmodelled effect) by an independent rig emulator, with its own drive
//! (gains, speed estimate, pre-torque, start and stop sequence) and its own
//! data acquisition (filtering, noise, sample rate, pre-trigger). Read in
//! place, never written.
//!
//! What the paper's procedures must find there (the sample's README): EA
//! 1.0e6 N from every free decay (within 2 %), guide damping 148 kg/s
//! (within 15 %), sheave damping 3 N m s/rad from every travel (within
//! 10 %), a machine torque that lifts the car going up, the verdict
//! `nominal`. And whatever a
//! recording holds, the diagnosis and the identification give a result for
//! the rest.

use std::path::PathBuf;

use diagnosis::calibrate::DECAY_MAX_FREQUENCY_HZ;
use diagnosis::identify_dataset::identify_dataset;
use diagnosis::{diagnose, DriveModel, GapOptions, Verdict};
use recording::read::read_dataset;
use recording::{Recording, RecordingKind, I_A, I_B, I_C};
use rig_config::RigConfig;

fn rig() -> RigConfig {
    RigConfig::embedded_default().expect("the embedded rig loads")
}

fn sample() -> Vec<(String, Recording)> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/rig-sample");
    assert!(
        dir.is_dir(),
        "{}: the foreign rig sample is expected beside the repository (shared/rig-sample)",
        dir.display()
    );
    read_dataset(&dir, rig().mechanics.rope_total_length_m).expect("the rig sample follows the measurement format")
}

#[test]
fn identification_finds_the_reference_rig_in_every_foreign_recording() {
    let rig = rig();
    let data = sample();
    let id = identify_dataset(&rig, &data, DECAY_MAX_FREQUENCY_HZ);
    assert!(id.left_out.is_empty(), "left out: {:?}", id.left_out);
    let decays = data.iter().filter(|(_, r)| matches!(r.meta.kind, RecordingKind::FreeDecay { .. })).count();
    let travels = data.len() - decays;
    assert_eq!((id.decays.len(), id.travels.len()), (decays, travels));
    for (stem, d) in &id.decays {
        println!(
            "{stem}: f1 {:.3} Hz, EA {:.4e} N, c {:.1} kg/s",
            d.first_frequency_hz, d.rope_ea_n, d.damping_kg_per_s
        );
        assert!((d.rope_ea_n / 1.0e6 - 1.0).abs() < 0.02, "{stem}: EA {}", d.rope_ea_n);
        assert!((d.damping_kg_per_s / 148.0 - 1.0).abs() < 0.15, "{stem}: guide damping {}", d.damping_kg_per_s);
    }
    for (stem, b) in &id.travels {
        println!(
            "{stem}: c_sheave {:.3} N m s/rad, mean torque {:+.2} N m at {:+.3} rad/s",
            b.sheave_damping_nms_per_rad, b.mean_torque_nm, b.mean_speed_radps
        );
        assert!(
            (b.sheave_damping_nms_per_rad / 3.0 - 1.0).abs() < 0.10,
            "{stem}: c_sheave {}",
            b.sheave_damping_nms_per_rad
        );
        // Eqn 4 and 13: the machine supplies the out-of-balance torque and
        // the losses, which oppose the motion.
        let drive_power = (b.mean_torque_nm - b.out_of_balance_torque_nm) * b.mean_speed_radps;
        assert!(drive_power > 0.0, "{stem}: the torque beyond Eqn 4 does not oppose the losses");
    }
}

#[test]
fn the_diagnosis_measures_every_foreign_recording_without_assuming_the_projects_drive() {
    let rig = rig();
    let data = sample();
    let report = diagnose(&rig, "rig-sample", &data, &GapOptions::default(), &|_, _, _| {}).expect("a verdict");
    println!("drive: {:?}; verdict {:?}, excess {:.2} dB", report.drive, report.verdict, report.nominal_excess_db);
    for r in &report.recordings {
        println!("  {}: excess {:.2} dB", r.recording, r.nominal_excess_db);
    }
    assert!(report.left_out.is_empty() && report.calibration.skipped.is_empty(), "{:?}", report.left_out);
    assert_eq!(report.recordings.len(), data.len());
    assert_eq!(report.drive.drive, DriveModel::Foreign, "{}", report.drive.reason);
    let c = &report.calibration;
    assert!((c.rope_ea_n / 1.0e6 - 1.0).abs() < 0.02 && (c.sheave_damping_nms_per_rad / 3.0 - 1.0).abs() < 0.1);
    // The sample's README: the rig is the nominal one, no unmodelled effect.
    assert_eq!(report.verdict, Verdict::Nominal, "excess {:.3} dB", report.nominal_excess_db);
}

/// A travel whose phase currents read zero (a probe unplugged): nothing
/// can be made of its torque.
fn broken(data: &[(String, Recording)]) -> (String, Recording) {
    let (stem, travel) = data.iter().find(|(_, r)| matches!(r.meta.kind, RecordingKind::Travel { .. })).unwrap();
    let mut travel = travel.clone();
    for c in travel.columns.iter_mut().filter(|c| [I_A, I_B, I_C].contains(&c.name.as_str())) {
        c.values.iter_mut().for_each(|v| *v = 0.0);
    }
    (format!("{stem}_probes_unplugged"), travel)
}

#[test]
fn one_broken_recording_is_left_out_with_its_reason_and_the_rest_gets_a_result() {
    let rig = rig();
    let mut data = sample();
    let bad = broken(&data);
    let bad_stem = bad.0.clone();
    data.push(bad);
    let id = identify_dataset(&rig, &data, DECAY_MAX_FREQUENCY_HZ);
    println!("identify left out: {:?}", id.left_out);
    assert_eq!(id.left_out.len(), 1);
    assert_eq!(id.left_out[0].recording, bad_stem);
    assert!(id.left_out[0].reason.contains("current"), "{}", id.left_out[0].reason);
    assert!(id.rope_ea_n.is_some() && id.sheave_damping_nms_per_rad.is_some());

    let report = diagnose(&rig, "rig-sample + broken", &data, &GapOptions::default(), &|_, _, _| {})
        .expect("a verdict on the rest");
    println!("gap left out: {:?}", report.left_out);
    assert!(report.left_out.iter().any(|l| l.recording == bad_stem));
    assert_eq!(report.recordings.len(), data.len() - 1);
}
