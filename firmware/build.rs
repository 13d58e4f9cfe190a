//! Build script of the firmware.
//!
//! 1. Puts the workspace's `memory.x` on the linker search path and passes
//!    cortex-m-rt's `link.x` and defmt's `defmt.x` linker scripts to the binary.
//! 2. Generates `$OUT_DIR/board_generated.rs` (pin types, alternate
//!    functions, active levels, current-sense sign) from the board
//!    description `configs/boards/$DRIVE_BOARD.toml` (default
//!    `nucleo-g474re-ihm08m1`), and
//!    `$OUT_DIR/drive_config.rs` from `configs/rig.toml` and that board
//!    (the board's sensing scales, bus voltage and trip levels), through
//!    the same `rig-config` code the host simulator uses, so firmware and host
//!    run the controller with identical values: the drive parameters as a
//!    `drive_core::DriveConfig` constant, the drive's chain model
//!    (`CHAIN_MODEL`, for the ripple compensation and the observer), the
//!    inverter's dead time (`DEAD_TIME_S`), the landings (`LIFT_GEOMETRY`:
//!    `[travel].lw_low_m` is the lowest landing, `lw_high_m` the highest) and
//!    the rig's ripple components (`RIPPLE`, from which the offline
//!    compensation table is built), and the default car mass of the load
//!    weighing (`DEFAULT_CAR_MASS_KG`, the heaviest car).
//!
//! Travels are commanded at run time by a lift controller over DCP
//! (`src/dcp.rs`); nothing about a travel is fixed at build time.

use std::env;
use std::fs;
use std::path::PathBuf;

fn main() {
    let manifest_dir = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("CARGO_MANIFEST_DIR"));
    let out_dir = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR"));
    let workspace_root = manifest_dir.parent().expect("firmware/ lies inside the workspace").to_path_buf();

    println!("cargo:rerun-if-changed=build.rs");
    link_scripts(&workspace_root, &out_dir);
    let board = board(&workspace_root);
    let source = drive_config(&workspace_root, &board);
    let path = out_dir.join("drive_config.rs");
    fs::write(&path, source).unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
    let path = out_dir.join("board_generated.rs");
    fs::write(&path, board.firmware_source(&format!("configs/boards/{}.toml", board.name)))
        .unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
}

/// The board description: `configs/boards/$DRIVE_BOARD.toml`, by default
/// `rig_config::board::DEFAULT_BOARD` (NUCLEO-G474RE with X-NUCLEO-IHM08M1).
fn board(workspace_root: &std::path::Path) -> rig_config::board::Board {
    println!("cargo:rerun-if-env-changed=DRIVE_BOARD");
    let name = env::var("DRIVE_BOARD").unwrap_or_else(|_| rig_config::board::DEFAULT_BOARD.to_string());
    let path = workspace_root.join("configs").join("boards").join(format!("{name}.toml"));
    println!("cargo:rerun-if-changed={}", path.display());
    let text = fs::read_to_string(&path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    rig_config::board::Board::from_toml_str(&text, &path.display().to_string())
        .unwrap_or_else(|e| panic!("{} is not a valid board description: {e}", path.display()))
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
fn drive_config(workspace_root: &std::path::Path, board: &rig_config::board::Board) -> String {
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
    let lw_low = rig.travel.lw_low_m;
    let lw_high = rig.travel.lw_high_m;
    let shaft_travel_mm = ((lw_high - lw_low) * 1000.0).round();
    assert!(
        shaft_travel_mm >= 1.0 && shaft_travel_mm <= u16::MAX as f64,
        "{}: [travel].lw_high_m - lw_low_m = {shaft_travel_mm} mm is not a DCP distance (1..=65535 mm)",
        rig_toml.display()
    );
    // The rig generators the PIL target uses; the DRIVE_CONFIG is the rig on this board.
    format!(
        "{}{}/// Inverter dead time between the switches of one leg, s (`[inverter].dead_time_s`).\n\
         pub const DEAD_TIME_S: f32 = {dead_time_s:?};\n\
         /// The landings: `[travel].lw_low_m` (lowest landing) to `lw_high_m` (highest).\n\
         pub const LIFT_GEOMETRY: drive_core::lift_drive::LiftGeometry = drive_core::lift_drive::LiftGeometry {{ \
         lw_lowest_landing_m: {:?}, shaft_travel_mm: {} }};\n\
         /// Car mass of the load weighing until one is stored: the heaviest car of `[mechanics].m_car_kg`, kg.\n\
         pub const DEFAULT_CAR_MASS_KG: f32 = {:?};\n{}",
        board
            .drive_config_source(&rig, "configs/rig.toml")
            .unwrap_or_else(|e| panic!("the rig does not fit the board: {e}")),
        rig.chain_model_source("configs/rig.toml"),
        lw_low as f32,
        shaft_travel_mm as u32,
        rig.mechanics.m_car_kg.iter().cloned().fold(f64::MIN, f64::max) as f32,
        rig.ripple_source()
    )
}
