//! Build script of the firmware.
//!
//! 1. Puts the workspace's `memory.x` on the linker search path and passes
//!    cortex-m-rt's `link.x` and defmt's `defmt.x` linker scripts to the binary.
//! 2. Generates `$OUT_DIR/drive_config.rs`: the drive parameters of
//!    `configs/rig.toml` as a `drive_core::DriveConfig` constant, through the same
//!    `rig-config` code the host simulator uses, so firmware and host run the
//!    controller with identical values; the inverter's dead time
//!    (`[inverter].dead_time_s`) as `DEAD_TIME_S`; and the operator's travel
//!    command of the environment variable `FW_TRAVEL` as `OPERATOR_TRAVEL`.
//!
//! `FW_TRAVEL=<up|down>:<distance m>:<car mass kg>:<lw at start m>`, e.g.
//! `FW_TRAVEL=up:1.0:70.5:2.0 cargo flash`, builds a firmware that starts
//! exactly that one travel once the drive is calibrated and idle. The board
//! has no load weighing and no car-position sensor, so the operator states
//! both; without `FW_TRAVEL` the drive stays idle.

use std::env;
use std::fs;
use std::path::PathBuf;

fn main() {
    let manifest_dir = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("CARGO_MANIFEST_DIR"));
    let out_dir = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR"));
    let workspace_root = manifest_dir.parent().expect("firmware/ lies inside the workspace").to_path_buf();

    println!("cargo:rerun-if-changed=build.rs");
    link_scripts(&workspace_root, &out_dir);
    let mut source = drive_config(&workspace_root);
    source.push_str(&operator_travel());
    let path = out_dir.join("drive_config.rs");
    fs::write(&path, source).unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
}

/// Copies `memory.x` into OUT_DIR and adds the linker scripts.
fn link_scripts(workspace_root: &std::path::Path, out_dir: &std::path::Path) {
    let memory_x = workspace_root.join("memory.x");
    fs::copy(&memory_x, out_dir.join("memory.x")).unwrap_or_else(|e| panic!("cannot copy {}: {e}", memory_x.display()));
    println!("cargo:rustc-link-search={}", out_dir.display());
    println!("cargo:rerun-if-changed={}", memory_x.display());

    // cortex-m-rt's link.x INCLUDEs memory.x; defmt.x places the log strings.
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}

/// Source of `pub const DRIVE_CONFIG: drive_core::DriveConfig = ...;` and
/// `pub const DEAD_TIME_S: f32 = ...;`.
fn drive_config(workspace_root: &std::path::Path) -> String {
    let rig_toml = workspace_root.join("configs").join("rig.toml");
    println!("cargo:rerun-if-changed={}", rig_toml.display());

    let rig = match rig_config::RigConfig::embedded_default() {
        Ok(rig) => rig,
        Err(e) => panic!("{} is not a valid rig file: {e:?}", rig_toml.display()),
    };
    let dead_time_s = rig.inverter.dead_time_s as f32;
    assert!(
        dead_time_s.is_finite() && dead_time_s > 0.0,
        "{}: [inverter].dead_time_s must be a positive number of seconds, is {dead_time_s}",
        rig_toml.display()
    );
    // The same generator the PIL target uses, so both run identical values.
    format!(
        "{}/// Inverter dead time between the switches of one leg, s (`[inverter].dead_time_s`).\n\
         pub const DEAD_TIME_S: f32 = {dead_time_s:?};\n",
        rig.drive_config_source("configs/rig.toml")
    )
}

/// Source of `pub const OPERATOR_TRAVEL: Option<drive_core::TravelCommand> = ...;`
/// from the environment variable `FW_TRAVEL` (see the module doc).
fn operator_travel() -> String {
    println!("cargo:rerun-if-env-changed=FW_TRAVEL");
    let doc = "/// The travel the operator asked for at build time (`FW_TRAVEL`), if any.\n";
    let value = match env::var("FW_TRAVEL") {
        Err(env::VarError::NotPresent) => "None".to_string(),
        Err(e) => panic!("FW_TRAVEL: {e}"),
        Ok(text) if text.trim().is_empty() => "None".to_string(),
        Ok(text) => {
            let fields: Vec<&str> = text.trim().split(':').collect();
            let usage = "FW_TRAVEL=<up|down>:<distance m>:<car mass kg>:<lw at start m>, e.g. up:1.0:70.5:2.0";
            let [direction, distance, mass, lw_start] = fields[..] else {
                panic!("FW_TRAVEL={text:?}: expected {usage}");
            };
            let direction = match direction {
                "up" => "Up",
                "down" => "Down",
                other => panic!("FW_TRAVEL: direction {other:?} is neither `up` nor `down` ({usage})"),
            };
            let number = |name: &str, field: &str| -> f32 {
                match field.parse::<f32>() {
                    Ok(v) if v.is_finite() && v > 0.0 => v,
                    _ => panic!("FW_TRAVEL: {name} {field:?} is not a positive number ({usage})"),
                }
            };
            let (distance, mass, lw_start) =
                (number("distance", distance), number("car mass", mass), number("lw at start", lw_start));
            format!(
                "Some(drive_core::TravelCommand {{ direction: drive_core::config::Direction::{direction}, \
                 distance_m: {distance:?}, m_car_kg: {mass:?}, lw_start_m: {lw_start:?} }})"
            )
        }
    };
    format!("{doc}pub const OPERATOR_TRAVEL: Option<drive_core::TravelCommand> = {value};\n")
}
