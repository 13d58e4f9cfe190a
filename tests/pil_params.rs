//! Power cycles of the emulated chip: the PIL target keeps the drive's
//! parameter record in a `sequential-storage` map over an emulated flash
//! that QEMU keeps in a file of its working directory (`pil/src/flash.rs`);
//! starting QEMU again in the same directory is a power cycle. The service
//! port (UART2) sets the strategy and the car mass and saves the record
//! (the table learned by an adaptive travel, installed as the table
//! strategy's); after the power cycle the chip must run, bit for bit, as a
//! host shadow started from the parameters it saved, and with a corrupted
//! record as a shadow started from the defaults.
//!
//! Needs `qemu-system-arm` and the PIL ELF (`scripts/test.sh` builds both;
//! `PIL_ELF` overrides the path).

use std::path::Path;

use closed_loop::pil::dcp::{default_elf, default_parameters, geometry, Chip, Lift, Master, Phase, Trip};
use drive_core::dcp::command::{Mode, Speed};
use drive_core::param_store::{DriveParameters, RecordError};
use drive_core::ripple::Strategy;
use drive_core::service::ParamsStatus;
use rig_config::RigConfig;

fn rig() -> RigConfig {
    RigConfig::embedded_default().expect("the embedded rig loads")
}

/// QEMU started (again) in `dir`, the car at `position_mm` above the lowest
/// landing, the shadow started from `parameters` (`status`).
fn power_on(dir: &Path, parameters: &DriveParameters, status: ParamsStatus, position_mm: f64) -> Lift {
    let rig = rig();
    let (geometry, m_car) = geometry(&rig);
    let chip = Chip::launch(&default_elf(), Path::new("qemu-system-arm"), dir).expect("the PIL target starts");
    let lw = geometry.lw_lowest_landing_m as f64 + position_mm / 1000.0;
    Lift::new(&rig, Some(chip), parameters, status, m_car as f64, lw).expect("a lift")
}

fn ask(lift: &mut Lift, line: &str) -> String {
    lift.ask(line, 2_000).unwrap_or_else(|e| panic!("{e:#}")).0
}

/// A DCP4 travel to `target_mm`, chip and shadow compared at every step;
/// stops after `max_steps` if not finished. The landing position, if it landed.
fn travel(lift: &mut Lift, target_mm: i32, max_steps: u64) -> Option<f64> {
    let trips = vec![Trip { target_mm, speed: Speed::V4 }];
    let mut master = Master::new(Mode::Dcp4, trips, &rig().drive_config());
    for k in 0..max_steps {
        let out = master.bytes(k, lift.position_mm());
        let step = lift.step(&out, &[]).unwrap_or_else(|e| panic!("{e:#}"));
        master.receive(&step.dcp_replies).unwrap();
        if master.phase() == Phase::Done {
            break;
        }
    }
    master.arrivals.first().map(|a| a.position_mm)
}

/// sequential-storage's item CRC (its `adapted_crc32`: CRC-32C from
/// 0xEEEE_EEEE, never 0, first byte never 0 or 0xFF), to rewrite an item
/// whose data the test changed, so that the store hands the record over.
fn store_crc(data: &[u8]) -> u32 {
    let mut crc = 0xEEEE_EEEEu32;
    for &byte in data {
        crc ^= byte as u32;
        for _ in 0..8 {
            crc = if crc & 1 == 1 { (crc >> 1) ^ 0x82F6_3B78 } else { crc >> 1 };
        }
    }
    let crc = !crc;
    match crc {
        0 => 1,
        c if c.to_le_bytes()[0] == 0 || c.to_le_bytes()[0] == 0xFF => c ^ 1,
        c => c,
    }
}

/// The flash image's newest parameter record: where its store item's data
/// starts (the key byte before the record) and its length.
fn record_item(image: &[u8]) -> (usize, usize) {
    let magic = [b'L', b'D', b'P', drive_core::param_store::VERSION];
    let at = image.windows(4).rposition(|w| w == magic).expect("a record in the flash image");
    let data = at - 1;
    // The item header (data CRC u32, length u16, length CRC u16) is the double word before.
    let length = u16::from_le_bytes([image[data - 4], image[data - 3]]) as usize;
    (data, length)
}

#[test]
fn a_power_cycle_restores_the_saved_parameters_and_a_corrupt_record_is_refused() {
    let rig = rig();
    let defaults = default_parameters(&rig);
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("pil-flash.bin");

    // First power-up: nothing stored; adaptive compensation and a car mass
    // set on the service port, a travel to learn, then saved.
    let mut lift = power_on(dir.path(), &defaults, ParamsStatus::None, 1000.0);
    assert_eq!(ask(&mut lift, "get params"), "params none");
    assert_eq!(ask(&mut lift, "set strategy adaptive"), "ok strategy adaptive");
    // The firmware installs the strategy in its control interrupt, in the
    // period that takes the request: that period's work must fit the PWM
    // period (10 624 cycles; 255 for the conversions), one cycle counted
    // per instruction.
    let install = lift.last_period_instructions().expect("the chip's cost");
    println!("the period that installs the strategy: {install:.0} instructions");
    assert!(255.0 + install < 2.0 * rig.pwm_period_counts() as f64, "{install} instructions");
    assert_eq!(ask(&mut lift, "set mass 70"), "ok mass 70.0");
    let offline_table = ask(&mut lift, "get table");
    let landed = travel(&mut lift, 1600, 120_000).expect("the learning travel lands");
    assert!((landed - 1600.0).abs() < 3.0, "landed at {landed:.1} mm");
    let learned_table = ask(&mut lift, "get table");
    assert_ne!(learned_table, offline_table, "the travel learned nothing");
    // What it learned becomes the table of Strategy::Table, which is saved.
    assert_eq!(ask(&mut lift, "set strategy table"), "ok strategy table");
    assert_eq!(ask(&mut lift, "get table"), learned_table);
    let (answer, saved) = lift.ask("save", 2_000).unwrap();
    assert_eq!(answer, "ok saved");
    let saved = saved.expect("the parameters saved");
    assert_eq!((saved.strategy, saved.m_car_kg, saved.dcp_mode), (Strategy::Table, 70.0, Mode::Dcp4));
    println!("saved after {} steps: {learned_table}", lift.steps());
    drop(lift);
    assert!(file.is_file(), "no flash file written");

    // Power cycle: the chip installs the record; it must run as a shadow
    // started from what it saved (bit for bit through 20 000 steps of a
    // travel, 0.9 s of it compensated with the learned table), and answer
    // with the same values.
    let mut lift = power_on(dir.path(), &saved, ParamsStatus::Stored, 1600.0);
    assert_eq!(ask(&mut lift, "get params"), "params stored");
    assert_eq!(ask(&mut lift, "get strategy"), "strategy table");
    assert_eq!(ask(&mut lift, "get mass"), "mass 70.0");
    assert_eq!(ask(&mut lift, "get table"), learned_table);
    travel(&mut lift, 1300, 20_000);
    drop(lift);

    // The record corrupted in the flash (one byte of the table), the store's
    // own item CRC rewritten so that the record reaches the drive's checks:
    // refused by its CRC, the drive runs with the defaults.
    let image = std::fs::read(&file).unwrap();
    let (data, length) = record_item(&image);
    let mut corrupt = image.clone();
    corrupt[data + 1 + 8 + 4] ^= 0x40;
    let crc = store_crc(&corrupt[data..data + length]);
    corrupt[data - 8..data - 4].copy_from_slice(&crc.to_le_bytes());
    std::fs::write(&file, &corrupt).unwrap();
    let mut lift = power_on(dir.path(), &defaults, ParamsStatus::Refused(RecordError::Crc), 1000.0);
    assert_eq!(ask(&mut lift, "get params"), "params refused crc");
    assert_eq!(ask(&mut lift, "get strategy"), "strategy off");
    assert_eq!(ask(&mut lift, "get table"), offline_table);
    travel(&mut lift, 1300, 20_000);
    drop(lift);

    // The same byte flipped without the store's CRC rewritten: the store
    // drops the item itself, so the drive finds no record.
    let mut flipped = image;
    flipped[data + 1 + 8 + 4] ^= 0x40;
    std::fs::write(&file, &flipped).unwrap();
    let mut lift = power_on(dir.path(), &defaults, ParamsStatus::None, 1000.0);
    assert_eq!(ask(&mut lift, "get params"), "params none");
    assert_eq!(ask(&mut lift, "get strategy"), "strategy off");
}
