//! Build script of the PIL target: its own memory map (QEMU mps2-an386, not
//! the STM32's), the cortex-m-rt and defmt linker scripts, and the drive
//! parameters of `configs/rig.toml` as a `drive_core::DriveConfig` constant
//! (the same `rig-config` code the firmware and the host use).

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
}
