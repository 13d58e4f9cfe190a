//! Build script of the PIL target: its own memory map (QEMU mps2-an386, not
//! the STM32's), the cortex-m-rt and defmt linker scripts, and the drive
//! parameters of `configs/rig.toml` as a `drive_core::DriveConfig` constant
//! (the same `rig-config` code the firmware and the host use), the chain
//! model, and the landings and car mass of the DCP slave.

use std::env;
use std::fs;
use std::path::PathBuf;

fn main() {
    let manifest_dir = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let out_dir = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    println!("cargo:rerun-if-changed=build.rs");

    let memory_x = manifest_dir.join("memory.x");
    fs::copy(&memory_x, out_dir.join("memory.x")).unwrap_or_else(|e| panic!("cannot copy {}: {e}", memory_x.display()));
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rustc-link-search={}", out_dir.display());
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");

    let rig_toml = manifest_dir.join("../configs/rig.toml");
    println!("cargo:rerun-if-changed={}", rig_toml.display());
    let rig = rig_config::RigConfig::embedded_default().unwrap_or_else(|e| panic!("{e}"));
    let path = out_dir.join("drive_config.rs");
    fs::write(&path, rig.drive_config_source("configs/rig.toml"))
        .unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
    let path = out_dir.join("chain_model.rs");
    fs::write(&path, rig.chain_model_source("configs/rig.toml"))
        .unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
    // The landings and the load weighing of the DCP slave, as the firmware's
    // build script and the host tests derive them.
    let shaft_travel_mm = ((rig.travel.lw_high_m - rig.travel.lw_low_m) * 1000.0).round();
    assert!(shaft_travel_mm >= 1.0 && shaft_travel_mm <= u16::MAX as f64, "[travel]: {shaft_travel_mm} mm");
    let heaviest = rig.mechanics.m_car_kg.iter().cloned().fold(f64::MIN, f64::max) as f32;
    // The rig's ripple, as the firmware's build script writes it: the
    // offline compensation table is made from it.
    let path = out_dir.join("ripple.rs");
    fs::write(&path, rig.ripple_source()).unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
    let path = out_dir.join("lift.rs");
    fs::write(
        &path,
        format!(
            "/// The landings: `[travel].lw_low_m` (lowest landing) to `lw_high_m` (highest).\n\
             pub const LIFT_GEOMETRY: drive_core::lift_drive::LiftGeometry = drive_core::lift_drive::LiftGeometry {{ \
             lw_lowest_landing_m: {:?}, shaft_travel_mm: {} }};\n\
             /// Car mass of the load weighing: the heaviest car of `[mechanics].m_car_kg`, kg.\n\
             pub const DEFAULT_CAR_MASS_KG: f32 = {heaviest:?};\n",
            rig.travel.lw_low_m as f32, shaft_travel_mm as u32
        ),
    )
    .unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
}
