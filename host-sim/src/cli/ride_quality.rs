//! `host-sim ride-quality FILE`: lift ride quality after ISO 18738-1 of one
//! run: the project's format (`<stem>.toml`: vertical = `acc_car_mps2`,
//! regions from `speed_radps`) or the text export of lift ride-quality
//! analyzers (`EVIMP1`: x, y, z and, when recorded, the sound level; no
//! speed, so the regions come from the integrated vertical acceleration).
//! One report per run: a table on the terminal, `ride_quality.json`,
//! `ride_quality.csv` and `ride_quality.png`.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Args, ValueEnum};
use serde::Serialize;

use super::output_dir;
use dsp::ride_quality::MPS2_PER_MG;
use dsp::{
    regions_from_acceleration, regions_from_speed, ride_report, RegionFigures, RideInput, RideRegions, RideReport,
};
use plots::{stacked_plot, Band, Level, Mark, Panel, Series};
use recording::{read_evimp, read_recording, RecordingKind, ACC_CAR, SPEED};
use rig_config::RigConfig;

/// Where the regions of the run come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum RegionsFrom {
    /// The recorded speed when the file has one (a travel of the project's format), else the acceleration.
    Auto,
    /// The recorded speed (`speed_radps`); an error for a file without one.
    Speed,
    /// The vertical acceleration, integrated, with the standstill before and after found.
    Acceleration,
}

/// Options of `ride-quality`.
#[derive(Debug, Args)]
pub struct RideQualityArgs {
    /// A recording (`<stem>.toml`, with its `<stem>.csv` beside it) or an `EVIMP1` text export.
    pub file: PathBuf,
    /// Output directory.
    #[arg(long, value_name = "DIR", default_value = "out/ride-quality")]
    pub out: PathBuf,
    /// Where the acceleration, constant-speed and deceleration regions come from.
    #[arg(long, value_enum, value_name = "FROM", default_value_t = RegionsFrom::Auto)]
    pub regions_from: RegionsFrom,
    /// Replace the outputs of an earlier run (default: refuse to overwrite).
    #[arg(long)]
    pub force: bool,
}

/// Files `ride-quality` writes.
const OUTPUTS: [&str; 3] = ["ride_quality.json", "ride_quality.csv", "ride_quality.png"];

/// The signals of one run, as read.
struct Run {
    /// What the file is, for the report.
    source: &'static str,
    /// Sample rate, Hz.
    fs: f64,
    /// Vertical acceleration, m/s^2.
    z: Vec<f64>,
    /// Horizontal accelerations, m/s^2, when recorded.
    x: Option<Vec<f64>>,
    /// See `x`.
    y: Option<Vec<f64>>,
    /// Sound level, dB(A), when recorded.
    sound: Option<Vec<f64>>,
    /// Shaft speed, rad/s, of a travel of the measurement format.
    speed: Option<Vec<f64>>,
    /// The car's vertical speed from it (shaft speed times sheave radius,
    /// 1:1 roping), m/s, positive up.
    car_speed_mps: Option<Vec<f64>>,
    /// Travel direction, when the file records one.
    direction: Option<&'static str>,
}

/// The start of the first line of `path` (at most 64 bytes, lossy UTF-8,
/// trimmed): `EVIMP1` for an EVIMP export.
fn first_line(path: &Path) -> anyhow::Result<String> {
    recording::read::refuse_special_file(path)?;
    let file = std::fs::File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    let mut head = Vec::new();
    file.take(64).read_to_end(&mut head).with_context(|| format!("cannot read {}", path.display()))?;
    let head = head.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&head);
    let line = head.split(|&b| b == b'\n').next().unwrap_or_default();
    Ok(String::from_utf8_lossy(line).trim().to_string())
}

/// Reads `path`: an EVIMP1 export or the `<stem>.toml` of a recording.
fn load(rig: &RigConfig, path: &Path) -> anyhow::Result<Run> {
    let first = first_line(path)?;
    if first == "EVIMP1" {
        let e = read_evimp(path)?;
        recording::consistency::check_live(&e.z_mg, "z_mg", path)?;
        let mps2 = |v: &[f64]| v.iter().map(|a| a * MPS2_PER_MG).collect::<Vec<f64>>();
        let source = if e.sound_dba.is_some() {
            "EVIMP1 export: x, y, z in mg, sound in dB(A)"
        } else {
            "EVIMP1 export: x, y, z in mg"
        };
        return Ok(Run {
            source,
            fs: e.sample_rate_hz,
            z: mps2(&e.z_mg),
            x: Some(mps2(&e.x_mg)),
            y: Some(mps2(&e.y_mg)),
            sound: e.sound_dba,
            speed: None,
            car_speed_mps: None,
            direction: None,
        });
    }
    if path.extension().is_some_and(|e| e == "toml") {
        let recording = read_recording(path, rig.mechanics.rope_total_length_m)?;
        let acc = recording.column(ACC_CAR).map(|c| c.values.clone()).context("no acc_car_mps2 column")?;
        let (speed, direction) = match &recording.meta.kind {
            RecordingKind::Travel { direction, .. } => {
                (recording.column(SPEED).map(|c| c.values.clone()), Some(direction.as_str()))
            }
            RecordingKind::FreeDecay { .. } => (None, None),
        };
        let source = "measurement format: vertical acc_car_mps2 (no horizontal axes, no sound)";
        let fs = recording.meta.sample_rate_hz;
        let radius_m = rig.mechanics.sheave_radius_m;
        let car_speed_mps = speed.as_ref().map(|w| w.iter().map(|w| w * radius_m).collect());
        return Ok(Run { source, fs, z: acc, x: None, y: None, sound: None, speed, car_speed_mps, direction });
    }
    let sibling = path.with_extension("toml");
    let hint = if path.extension().is_some_and(|e| e == "csv") && sibling.is_file() {
        format!(" (it is the samples file of a recording: give its metadata file `{}`)", sibling.display())
    } else {
        String::new()
    };
    anyhow::bail!(
        "`{}` is neither an `EVIMP1` export (its first line is {first:?}, not `EVIMP1`) nor a recording of the \
         measurement format{hint}; expected an EVIMP1 text export or the `<stem>.toml` of a recording, with its \
         `<stem>.csv` beside it",
        path.display()
    )
}

/// The regions of `run` as `--regions-from` asks; `None` with a note when the
/// run has none (no motion found).
fn find_regions(run: &Run, from: RegionsFrom, file: &Path) -> anyhow::Result<Option<RideRegions>> {
    let use_speed = match (from, &run.speed) {
        (RegionsFrom::Speed, None) => anyhow::bail!(
            "--regions-from speed: `{}` has no speed signal (an EVIMP1 export or a free decay); expected a travel \
             recording with a `speed_radps` column, or --regions-from auto|acceleration",
            file.display()
        ),
        (RegionsFrom::Acceleration, _) | (_, None) => false,
        (_, Some(_)) => true,
    };
    let found = match (&run.speed, use_speed) {
        (Some(speed), true) => regions_from_speed(speed, run.fs),
        _ => regions_from_acceleration(&run.z, run.fs).map(|(r, _)| r),
    };
    match found {
        Ok(r) => Ok(Some(r)),
        Err(e) => {
            eprintln!("note: `{}`: no motion found, the whole record only: {e}", file.display());
            Ok(None)
        }
    }
}

/// Runs `ride-quality`.
pub fn run(rig: &RigConfig, args: &RideQualityArgs) -> anyhow::Result<()> {
    let run = load(rig, &args.file)?;
    let regions = find_regions(&run, args.regions_from, &args.file)?;
    let out = output_dir(&args.out, args.force)?;
    out.refuse_existing(OUTPUTS)?;
    let input = RideInput {
        sample_rate_hz: run.fs,
        z_mps2: &run.z,
        x_mps2: run.x.as_deref(),
        y_mps2: run.y.as_deref(),
        sound_dba: run.sound.as_deref(),
        speed_mps: run.car_speed_mps.as_deref(),
    };
    let report = ride_report(&input, regions.as_ref())
        .with_context(|| format!("`{}`: ride quality (ISO 18738-1)", args.file.display()))?;
    let json = JsonReport::new(&args.file, &run, regions.as_ref(), &report);
    std::fs::write(out.path(OUTPUTS[0]), serde_json::to_string_pretty(&json)?)?;
    write_csv(&out.path(OUTPUTS[1]), &json)?;
    draw(&out.path(OUTPUTS[2]), &args.file, &run, regions.as_ref(), &report)?;
    let published: Vec<PathBuf> = out.commit()?;
    print_table(&json);
    outln!("wrote {}", published.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "));
    Ok(())
}

/// Regions of the JSON report, s.
#[derive(Debug, Serialize)]
struct JsonRegions {
    from: &'static str,
    constant_speed_rule: String,
    motion_s: [f64; 2],
    acceleration_s: [f64; 2],
    constant_speed_s: Option<[f64; 2]>,
    deceleration_s: [f64; 2],
}

/// One axis over one region.
#[derive(Debug, Serialize)]
struct JsonAxis {
    axis: &'static str,
    weighting: &'static str,
    max_peak_to_peak_mg: f64,
    max_at_s: f64,
    a95_peak_to_peak_mg: f64,
    peak_to_peak_count: usize,
}

/// Sound over one region.
#[derive(Debug, Serialize)]
struct JsonSound {
    max_dba: f64,
    max_at_s: f64,
    a95_dba: f64,
}

/// The figures of one region.
#[derive(Debug, Serialize)]
struct JsonRegion {
    region: &'static str,
    start_s: f64,
    end_s: f64,
    axes: Vec<JsonAxis>,
    sound: Option<JsonSound>,
}

/// Motion figures.
#[derive(Debug, Serialize)]
struct JsonMotion {
    max_acceleration_mg: f64,
    max_deceleration_mg: f64,
    max_velocity_mps: f64,
    distance_m: f64,
    from: &'static str,
}

/// `ride_quality.json`.
#[derive(Debug, Serialize)]
struct JsonReport {
    file: String,
    source: &'static str,
    sample_rate_hz: f64,
    duration_s: f64,
    direction: Option<&'static str>,
    regions: Option<JsonRegions>,
    max_jerk_mps3: f64,
    motion: Option<JsonMotion>,
    vibration: Vec<JsonRegion>,
}

impl JsonReport {
    fn new(file: &Path, run: &Run, regions: Option<&RideRegions>, report: &RideReport) -> Self {
        let fs = run.fs;
        let s = |i: usize| i as f64 / fs;
        let span = |r: &std::ops::Range<usize>| [s(r.start), s(r.end)];
        let regions = regions.map(|r| JsonRegions {
            from: r.source.describe(),
            constant_speed_rule: format!(
                "speed >= {:.0} % of its maximum, at least {} s",
                100.0 * dsp::ride_regions::CONSTANT_SPEED_FRACTION,
                dsp::ride_regions::MIN_CONSTANT_SPEED_S
            ),
            motion_s: span(&r.motion()),
            acceleration_s: span(&r.acceleration),
            constant_speed_s: r.constant_speed.as_ref().map(span),
            deceleration_s: span(&r.deceleration),
        });
        let region = |name: &'static str, f: &RegionFigures| JsonRegion {
            region: name,
            start_s: s(f.region.start),
            end_s: s(f.region.end),
            axes: f
                .axes
                .iter()
                .map(|a| JsonAxis {
                    axis: a.axis.name(),
                    weighting: a.axis.weighting().name(),
                    max_peak_to_peak_mg: a.max_peak_to_peak_mg,
                    max_at_s: s(a.max_at),
                    a95_peak_to_peak_mg: a.a95_peak_to_peak_mg,
                    peak_to_peak_count: a.peak_to_peak_count,
                })
                .collect(),
            sound: f.sound.as_ref().map(|x| JsonSound {
                max_dba: x.max_dba,
                max_at_s: s(x.max_at),
                a95_dba: x.a95_dba,
            }),
        };
        let mut vibration = vec![region("whole run", &report.whole_run)];
        vibration.extend(report.constant_speed.as_ref().map(|c| region("constant speed", c)));
        JsonReport {
            file: file.display().to_string(),
            source: run.source,
            sample_rate_hz: fs,
            duration_s: s(run.z.len()),
            direction: run.direction,
            regions,
            max_jerk_mps3: report.max_jerk_mps3,
            motion: report.motion.as_ref().map(|m| JsonMotion {
                max_acceleration_mg: m.max_acceleration_mg,
                max_deceleration_mg: m.max_deceleration_mg,
                max_velocity_mps: m.max_velocity_mps,
                distance_m: m.distance_m,
                from: m.source.describe(),
            }),
            vibration,
        }
    }
}

/// `ride_quality.csv`: one row per region, an empty field where a figure
/// does not apply (an axis or the sound not recorded, the motion figures on
/// the constant-speed row).
fn write_csv(path: &Path, report: &JsonReport) -> anyhow::Result<()> {
    let mut csv = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(
        csv,
        "region,start_s,end_s,x_max_pp_mg,x_a95_pp_mg,y_max_pp_mg,y_a95_pp_mg,z_max_pp_mg,z_a95_pp_mg,\
         sound_max_dba,sound_a95_dba,max_acceleration_mg,max_deceleration_mg,max_jerk_mps3,max_velocity_mps,distance_m"
    )?;
    let opt = |v: Option<f64>| v.map(|v| v.to_string()).unwrap_or_default();
    for (i, r) in report.vibration.iter().enumerate() {
        let axis = |name: &str| r.axes.iter().find(|a| a.axis == name);
        let mut fields = vec![r.region.to_string(), r.start_s.to_string(), r.end_s.to_string()];
        for name in ["X", "Y", "Z"] {
            fields.push(opt(axis(name).map(|a| a.max_peak_to_peak_mg)));
            fields.push(opt(axis(name).map(|a| a.a95_peak_to_peak_mg)));
        }
        fields.push(opt(r.sound.as_ref().map(|s| s.max_dba)));
        fields.push(opt(r.sound.as_ref().map(|s| s.a95_dba)));
        let motion = report.motion.as_ref().filter(|_| i == 0);
        fields.push(opt(motion.map(|m| m.max_acceleration_mg)));
        fields.push(opt(motion.map(|m| m.max_deceleration_mg)));
        fields.push(opt((i == 0).then_some(report.max_jerk_mps3)));
        fields.push(opt(motion.map(|m| m.max_velocity_mps)));
        fields.push(opt(motion.map(|m| m.distance_m)));
        writeln!(csv, "{}", fields.join(","))?;
    }
    csv.flush()?;
    Ok(())
}

/// The report on the terminal.
fn print_table(r: &JsonReport) {
    let direction = r.direction.unwrap_or("not recorded");
    outln!("{} ({}), {} Hz, {:.2} s, direction {direction}", r.file, r.source, r.sample_rate_hz, r.duration_s);
    match &r.regions {
        Some(g) => {
            let cs = g.constant_speed_s.map_or("none".to_string(), |c| format!("{:.2}-{:.2} s", c[0], c[1]));
            outln!(
                "regions from {}: motion {:.2}-{:.2} s, constant speed {cs} ({})",
                g.from,
                g.motion_s[0],
                g.motion_s[1],
                g.constant_speed_rule
            );
        }
        None => outln!("regions: none (no motion found), the whole record only"),
    }
    let header: Vec<String> = r.vibration.iter().map(|v| format!("{:^21}", v.region)).collect();
    outln!("{:<16}{}", "", header.join(" "));
    let sub: Vec<String> = r.vibration.iter().map(|_| format!("{:>10} {:>10}", "max p-p", "A95 p-p")).collect();
    outln!("{:<16}{}", "vibration [mg]", sub.join(" "));
    for (i, a) in r.vibration[0].axes.iter().enumerate() {
        let cells: Vec<String> = r
            .vibration
            .iter()
            .map(|v| format!("{:>10.1} {:>10.1}", v.axes[i].max_peak_to_peak_mg, v.axes[i].a95_peak_to_peak_mg))
            .collect();
        outln!("{:<16}{}", format!("{} ({})", a.axis, a.weighting), cells.join(" "));
    }
    if r.vibration[0].sound.is_some() {
        let cells: Vec<String> = r
            .vibration
            .iter()
            .filter_map(|v| v.sound.as_ref().map(|s| format!("{:>6.1} max {:>6.1} A95", s.max_dba, s.a95_dba)))
            .collect();
        outln!("{:<16}{}", "sound [dB(A)]", cells.join("  "));
    }
    match &r.motion {
        Some(m) => outln!(
            "max acceleration {:.1} mg, max deceleration {:.1} mg, max jerk {:.3} m/s^3, max velocity {:.3} m/s, \
             distance {:.2} m (motion from the {})",
            m.max_acceleration_mg,
            m.max_deceleration_mg,
            r.max_jerk_mps3,
            m.max_velocity_mps,
            m.distance_m,
            m.from
        ),
        None => outln!("max jerk {:.3} m/s^3", r.max_jerk_mps3),
    }
}

/// `ride_quality.png`: the weighted axes, the sound and the velocity over
/// time, the regions shaded, the largest peak-to-peak of the whole run
/// marked and the A95 drawn as +-A95/2 over the constant-speed region.
fn draw(path: &Path, file: &Path, run: &Run, regions: Option<&RideRegions>, report: &RideReport) -> anyhow::Result<()> {
    let fs = run.fs;
    let time: Vec<f64> = (0..run.z.len()).map(|i| i as f64 / fs).collect();
    let mut panels = Vec::new();
    for (i, (axis, w)) in report.weighted_mps2.iter().enumerate() {
        let mg: Vec<f64> = w.iter().map(|a| a / MPS2_PER_MG).collect();
        let whole = &report.whole_run.axes[i];
        let mut panel = Panel {
            y_label: format!("{} {} [mg]", axis.name(), axis.weighting().name()),
            series: vec![Series::new(format!("{} weighted", axis.name()), time.clone(), mg.clone())],
            marks: vec![],
            levels: vec![],
        };
        if whole.peak_to_peak_count > 0 {
            let label = format!("max p-p {:.1} mg", whole.max_peak_to_peak_mg);
            panel.marks.push(Mark { x: time[whole.max_at], y: mg[whole.max_at], label, y_error: None });
        }
        if let Some(c) = &report.constant_speed {
            let half = c.axes[i].a95_peak_to_peak_mg / 2.0;
            let (x0, x1) = (c.region.start as f64 / fs, c.region.end as f64 / fs);
            let label = format!("A95 p-p {:.1} mg (constant speed)", c.axes[i].a95_peak_to_peak_mg);
            panel.levels.push(Level { y: half, x0, x1, label });
            panel.levels.push(Level { y: -half, x0, x1, label: String::new() });
        }
        panels.push(panel);
    }
    if let Some(sound) = &run.sound {
        let mut panel = Panel {
            y_label: "sound [dB(A)]".to_string(),
            series: vec![Series::new("sound level", time.clone(), sound.clone())],
            ..Panel::default()
        };
        let s = report.whole_run.sound.as_ref().expect("sound figures of a run with sound");
        panel.marks.push(Mark {
            x: time[s.max_at],
            y: s.max_dba,
            label: format!("max {:.1} dB(A)", s.max_dba),
            y_error: None,
        });
        if let Some(c) = report.constant_speed.as_ref().and_then(|c| c.sound.as_ref().map(|s| (c, s))) {
            let (x0, x1) = (c.0.region.start as f64 / fs, c.0.region.end as f64 / fs);
            panel.levels.push(Level { y: c.1.a95_dba, x0, x1, label: format!("A95 {:.1} dB(A)", c.1.a95_dba) });
        }
        panels.push(panel);
    }
    if let Some(v) = &report.velocity_mps {
        let source = regions.map_or("", |r| r.source.describe());
        panels.push(Panel {
            y_label: "velocity [m/s]".to_string(),
            series: vec![Series::new(format!("from {source}"), time.clone(), v.clone())],
            ..Panel::default()
        });
    }
    let bands = regions.map(|r| region_bands(r, fs)).unwrap_or_default();
    let name = file.file_name().map_or_else(|| file.display().to_string(), |n| n.to_string_lossy().into_owned());
    let title =
        format!("{name}: ride quality (ISO 18738-1), regions from {}", regions.map_or("none", |r| r.source.describe()));
    stacked_plot(path, &title, "time [s]", &panels, &bands)?;
    Ok(())
}

/// The shaded regions: acceleration, constant speed, deceleration.
fn region_bands(r: &RideRegions, fs: f64) -> Vec<Band> {
    let band = |range: &std::ops::Range<usize>, label: &str| Band {
        x0: range.start as f64 / fs,
        x1: range.end as f64 / fs,
        label: label.to_string(),
    };
    let mut bands = vec![band(&r.acceleration, "acceleration")];
    bands.extend(r.constant_speed.as_ref().map(|c| band(c, "constant speed")));
    bands.push(band(&r.deceleration, "deceleration"));
    bands
}
