//! PNG plots: line plots of time series, stacked panels, spectrogram heat
//! maps and categorical heat maps on a diverging scale.
//!
//! Plots are drawn with `plotters` into an in-memory RGB bitmap and encoded
//! with the `png` crate. Text uses the DejaVu Sans font embedded in the
//! binary (`assets/DejaVuSans.ttf`), so no system font, fontconfig or
//! font-kit is needed on the machine that draws. Each image is written to
//! `<path>.tmp` first and then renamed to `path`, so a failed plot never
//! leaves a truncated PNG behind.
//!
//! Axis units are whatever the caller puts in the axis labels; the functions
//! take the data in the units it should be shown in.
//!
//! In the data flow config -> plant <-> controller -> recording -> analysis
//! -> diagnosis this crate draws what the analysis ([`dsp::Spectrogram`])
//! and the diagnosis (its gap maps) compute, and what the commands show; it
//! depends only on `dsp`.

#![warn(missing_docs)]

pub mod heat_map;
pub mod panels;

pub use heat_map::{diverging, heat_map_plot, HeatMap, HeatPanel};
pub use panels::{envelope, stacked_plot, Band, Level, Mark, Panel};

use std::fmt::Display;
use std::fs;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::backend::{BitMapBackend, RGBPixel};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::{ReverseCoordTranslate, Shift};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::{register_font, FontStyle};

use dsp::Spectrogram;

/// Width of every plot in pixels.
pub const PLOT_WIDTH_PX: u32 = 1200;
/// Height of every plot in pixels.
pub const PLOT_HEIGHT_PX: u32 = 700;
/// Line plots draw at most about this many points per series; longer
/// series are reduced by keeping the minimum and maximum of each bucket.
pub const MAX_POINTS_PER_SERIES: usize = 4000;
/// Dynamic range (dB) of the automatic spectrogram colour scale.
pub const AUTO_DB_SPAN: f64 = 80.0;

/// Family name the embedded font is registered under.
const FONT_FAMILY: &str = "sans-serif";
/// DejaVu Sans 2.37 (Bitstream Vera license, see `assets/DejaVuSans-LICENSE.txt`).
static FONT_BYTES: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
/// Width in pixels of the colour bar panel of spectrogram plots.
const COLORBAR_PANEL_PX: u32 = 160;

/// Error returned by the plot functions.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The output path does not end in `.png`.
    #[error("plot path `{path}` has no `.png` extension; expected a path like `out/plot.png`")]
    NotPng {
        /// The rejected path.
        path: PathBuf,
    },
    /// `line_plot` was called without any series.
    #[error("no series to plot; expected at least one series")]
    NoSeries,
    /// A series has no points.
    #[error("series `{name}` is empty; expected at least one point")]
    EmptySeries {
        /// Name of the series.
        name: String,
    },
    /// `x` and `y` of a series differ in length.
    #[error("series `{name}` has {x_len} x values but {y_len} y values; expected equal lengths")]
    LengthMismatch {
        /// Name of the series.
        name: String,
        /// Length of `x`.
        x_len: usize,
        /// Length of `y`.
        y_len: usize,
    },
    /// No series has a single point with finite x and y.
    #[error("no series has a point with finite x and y; expected at least one finite point")]
    NoFinitePoints,
    /// The data spans a range too large to map to pixels.
    #[error("{axis} values span [{lo}, {hi}], too wide to draw; expected a finite span")]
    RangeTooLarge {
        /// `"x"`, `"y"`, `"time"` or `"frequency"`.
        axis: &'static str,
        /// Smallest value.
        lo: f64,
        /// Largest value.
        hi: f64,
    },
    /// The spectrogram's vectors do not fit together.
    #[error("spectrogram {what} has length {got}; expected {expected}")]
    SpectrogramShape {
        /// Which vector (e.g. `times_s`, `psd_db`, `psd_db row 3`).
        what: String,
        /// Actual length.
        got: usize,
        /// Required length.
        expected: usize,
    },
    /// A spectrogram axis is not finite and strictly increasing.
    #[error("spectrogram {axis} value {value} at index {index} is not finite and increasing; expected strictly increasing finite values")]
    SpectrogramAxis {
        /// `"times_s"` or `"frequency_hz"`.
        axis: &'static str,
        /// Index of the offending value.
        index: usize,
        /// The offending value.
        value: f64,
    },
    /// A spectrogram PSD value is NaN or infinite.
    #[error("spectrogram psd_db[{time_index}][{frequency_index}] is {value}; expected a finite dB value")]
    SpectrogramValue {
        /// Time index of the value.
        time_index: usize,
        /// Frequency index of the value.
        frequency_index: usize,
        /// The offending value.
        value: f64,
    },
    /// The requested colour scale range is unusable.
    #[error("dB range ({lo}, {hi}) is invalid; expected finite values with lo < hi")]
    InvalidDbRange {
        /// Lower end in dB.
        lo: f64,
        /// Upper end in dB.
        hi: f64,
    },
    /// The embedded font could not be registered with plotters.
    #[error("the embedded DejaVu Sans font could not be registered; expected a valid TrueType file")]
    Font,
    /// plotters reported a drawing error.
    #[error("drawing failed: {message}")]
    Draw {
        /// plotters' message.
        message: String,
    },
    /// The PNG encoder failed.
    #[error("encoding PNG `{path}` failed: {message}")]
    Encode {
        /// Path being written.
        path: PathBuf,
        /// Encoder message.
        message: String,
    },
    /// Creating the directory or writing/renaming the file failed.
    #[error("writing `{path}` failed: {source}")]
    Io {
        /// Path being written.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
}

/// One named curve of a plot. `x` and `y` are in the units of the axis
/// labels and must have equal, non-zero length; points where either value
/// is NaN or infinite are skipped (the line is broken there).
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// Abscissae, in the unit of the x axis.
    pub x: Vec<f64>,
    /// Ordinates, in the unit of the y axis.
    pub y: Vec<f64>,
}

impl Series {
    /// Series from a name and x/y vectors (units of the plot axes).
    pub fn new(name: impl Into<String>, x: Vec<f64>, y: Vec<f64>) -> Self {
        Self { name: name.into(), x, y }
    }
}

/// Line plot of one or more series into a 1200 x 700 PNG at `path`.
///
/// * `path`: output file, must end in `.png`; missing parent directories
///   are created.
/// * `title`, `x_label`, `y_label`: texts; put the units in the labels
///   (e.g. `"time [s]"`, `"acceleration [m/s^2]"`).
/// * `series`: at least one; each with `x.len() == y.len() > 0`.
///
/// Axis ranges cover all finite points (the y range with a 5 % margin).
/// Non-finite points are skipped and break the line. Series longer than
/// [`MAX_POINTS_PER_SERIES`] points are reduced by keeping the minimum and
/// maximum of each bucket of consecutive points, so peaks and the envelope
/// survive while a 300 000-sample signal still draws quickly; such a series
/// is drawn as its min/max envelope (a filled band,
/// [`panels::envelope`]) rather than as a zigzag line. A legend is drawn
/// when there is more than one series.
///
/// # Errors
/// [`PlotError::NotPng`], [`PlotError::NoSeries`],
/// [`PlotError::EmptySeries`], [`PlotError::LengthMismatch`],
/// [`PlotError::NoFinitePoints`], [`PlotError::RangeTooLarge`] for bad
/// input; [`PlotError::Font`], [`PlotError::Draw`], [`PlotError::Encode`],
/// [`PlotError::Io`] when drawing or writing fails.
pub fn line_plot(path: &Path, title: &str, x_label: &str, y_label: &str, series: &[Series]) -> Result<(), PlotError> {
    check_png_path(path)?;
    if series.is_empty() {
        return Err(PlotError::NoSeries);
    }
    let prepared = series.iter().map(prepare_series).collect::<Result<Vec<_>, _>>()?;
    let (x_min, x_max, y_min, y_max) = bounds(prepared.iter().flatten().flatten()).ok_or(PlotError::NoFinitePoints)?;
    let x_range = padded_range("x", x_min, x_max, 0.0)?;
    let y_range = padded_range("y", y_min, y_max, 0.05)?;

    render(path, |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(title, (FONT_FAMILY, 26))
            .margin(15)
            .x_label_area_size(55)
            .y_label_area_size(95)
            .build_cartesian_2d(x_range.clone(), y_range.clone())
            .map_err(draw_err)?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .label_style((FONT_FAMILY, 16))
            .axis_desc_style((FONT_FAMILY, 18))
            .light_line_style(RGBColor(235, 235, 235))
            .bold_line_style(RGBColor(200, 200, 200))
            .draw()
            .map_err(draw_err)?;
        for (i, (s, runs)) in series.iter().zip(&prepared).enumerate() {
            panels::draw_trace(&mut chart, s, runs, palette(i))?;
        }
        if series.len() > 1 {
            chart
                .configure_series_labels()
                .label_font((FONT_FAMILY, 16))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .position(SeriesLabelPosition::UpperRight)
                .draw()
                .map_err(draw_err)?;
        }
        Ok(())
    })
}

/// A second quantity shown along the top of a spectrogram: ticks at given
/// times labelled with its value there (e.g. the rope length over a
/// travel), and a description with the unit.
#[derive(Debug, Clone, PartialEq)]
pub struct TopAxis {
    /// Description with the unit, e.g. `rope length lw [m]`.
    pub label: String,
    /// `(time in s, text)` of each tick; ticks outside the time axis are
    /// not drawn.
    pub ticks: Vec<(f64, String)>,
}

impl TopAxis {
    /// Ticks where `value` (sampled at `time_s`, same length) first reaches
    /// each multiple of `step` between its first and last sample (linearly
    /// interpolated between samples), labelled with the multiple
    /// (`decimals` after the point). A value that does not move gives one
    /// tick at its start; non-finite samples are skipped.
    pub fn at_multiples(label: impl Into<String>, time_s: &[f64], value: &[f64], step: f64, decimals: usize) -> Self {
        let points: Vec<(f64, f64)> =
            time_s.iter().zip(value).filter(|(t, v)| t.is_finite() && v.is_finite()).map(|(t, v)| (*t, *v)).collect();
        let mut ticks = Vec::new();
        if let (Some(&(t0, v0)), true) = (points.first(), step > 0.0 && step.is_finite()) {
            let v_end = points[points.len() - 1].1;
            let (lo, hi) = (v0.min(v_end), v0.max(v_end));
            let mut k = (lo / step).ceil() as i64;
            while (k as f64) * step <= hi && ticks.len() < 1000 {
                let target = k as f64 * step;
                let crossing = points.windows(2).find_map(|w| {
                    let ((ta, va), (tb, vb)) = (w[0], w[1]);
                    let between = (va - target) * (vb - target) <= 0.0 && va != vb;
                    between.then(|| ta + (tb - ta) * (target - va) / (vb - va))
                });
                let t = if (target - v0).abs() < 1e-12 * step.max(1.0) { Some(t0) } else { crossing };
                if let Some(t) = t {
                    ticks.push((t, format!("{target:.decimals$}")));
                }
                k += 1;
            }
            if ticks.is_empty() {
                ticks.push((t0, format!("{v0:.decimals$}")));
            }
        }
        Self { label: label.into(), ticks }
    }
}

/// Spectrogram heat map into a 1200 x 700 PNG at `path`.
///
/// * `path`: output file, must end in `.png`; missing parent directories
///   are created.
/// * `title`: plot title.
/// * `spectrogram`: time on the x axis (s), frequency on the y axis (Hz),
///   PSD in dB as colour (perceptual "viridis" map, dark = low). Every cell
///   is drawn centred on its time and frequency; the axes span the cells.
/// * `overlays`: curves drawn on top (x in s, y in Hz), e.g. the model's
///   natural frequencies over the travel; alternately white and black with
///   a contrasting outline, named in a legend. Non-finite points break the
///   line; points outside the plot are clipped.
/// * `db_range`: colour scale `(lo, hi)` in dB; values outside are clamped.
///   `None` chooses `(max - 80 dB, max)` (or `(min, max)` if that is
///   narrower).
///
/// A colour bar with dB labels is drawn to the right of the heat map.
///
/// # Errors
/// [`PlotError::NotPng`], [`PlotError::SpectrogramShape`],
/// [`PlotError::SpectrogramAxis`], [`PlotError::SpectrogramValue`],
/// [`PlotError::InvalidDbRange`], [`PlotError::EmptySeries`] /
/// [`PlotError::LengthMismatch`] (overlays) for bad input;
/// [`PlotError::Font`], [`PlotError::Draw`], [`PlotError::Encode`],
/// [`PlotError::Io`] when drawing or writing fails.
pub fn spectrogram_plot(
    path: &Path,
    title: &str,
    spectrogram: &Spectrogram,
    overlays: &[Series],
    db_range: Option<(f64, f64)>,
) -> Result<(), PlotError> {
    spectrogram_plot_with_top_axis(path, title, spectrogram, overlays, db_range, None)
}

/// [`spectrogram_plot`] with a second quantity along the top edge of the
/// heat map (`top`, e.g. the rope length over a travel): its ticks drawn
/// on the top edge at their times, labelled above it, and its description
/// above the labels.
///
/// # Errors
/// Those of [`spectrogram_plot`].
pub fn spectrogram_plot_with_top_axis(
    path: &Path,
    title: &str,
    spectrogram: &Spectrogram,
    overlays: &[Series],
    db_range: Option<(f64, f64)>,
    top: Option<&TopAxis>,
) -> Result<(), PlotError> {
    check_png_path(path)?;
    check_spectrogram(spectrogram)?;
    let (db_lo, db_hi) = spectrogram_db_range(spectrogram, db_range)?;
    let overlay_runs = overlays.iter().map(prepare_series).collect::<Result<Vec<_>, _>>()?;
    let axes = spectrogram_axes(spectrogram)?;

    render(path, |root| {
        let (main, bar_panel) = root.split_horizontally(PLOT_WIDTH_PX - COLORBAR_PANEL_PX);
        // With a top axis the title goes above it, clear of its labels.
        let (head, body) = main.split_vertically(if top.is_some() { 42 } else { 0 });
        let mut builder = ChartBuilder::on(&body);
        if top.is_some() {
            head.titled(title, (FONT_FAMILY, 24)).map_err(draw_err)?;
            builder.margin(15).margin_top(60);
        } else {
            builder.caption(title, (FONT_FAMILY, 24)).margin(15);
        }
        let mut chart = builder
            .x_label_area_size(55)
            .y_label_area_size(85)
            .build_cartesian_2d(axes.t_range.clone(), axes.f_range.clone())
            .map_err(draw_err)?;
        let py_range = draw_heat_map(root, &chart, spectrogram, &axes, (db_lo, db_hi))?;

        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("time [s]")
            .y_desc("frequency [Hz]")
            .label_style((FONT_FAMILY, 16))
            .axis_desc_style((FONT_FAMILY, 18))
            .draw()
            .map_err(draw_err)?;
        if let Some(top) = top {
            draw_top_axis(root, &chart, &axes, top)?;
        }
        draw_overlays(&mut chart, overlays, &overlay_runs)?;
        draw_colour_bar(&main, &bar_panel, py_range, (db_lo, db_hi), "PSD [dB]")
    })
}

/// The ticks, their labels and the description of `top` along the top edge
/// of `chart`'s plotting area (drawn on `root`).
fn draw_top_axis(
    root: &Area<'_>,
    chart: &Chart<'_, '_>,
    axes: &SpectrogramAxes,
    top: &TopAxis,
) -> Result<(), PlotError> {
    let (px, py) = chart.plotting_area().get_pixel_range();
    let style = ShapeStyle::from(BLACK).stroke_width(1);
    root.draw(&PathElement::new(vec![(px.start, py.start), (px.end, py.start)], style)).map_err(draw_err)?;
    let mut last_right = i32::MIN;
    for (t, text) in &top.ticks {
        if !(*t >= axes.t_range.start && *t <= axes.t_range.end) {
            continue;
        }
        let (x, _) = chart.backend_coord(&(*t, axes.f_range.end));
        root.draw(&PathElement::new(vec![(x, py.start), (x, py.start - 6)], style)).map_err(draw_err)?;
        // Skip a label that would overlap the previous one.
        let half_width = 5 * text.chars().count() as i32;
        if x - half_width > last_right + 4 {
            root.draw(&Text::new(
                text.clone(),
                (x, py.start - 8),
                (FONT_FAMILY, 15).into_font().color(&BLACK).pos(Pos::new(HPos::Center, VPos::Bottom)),
            ))
            .map_err(draw_err)?;
            last_right = x + half_width;
        }
    }
    root.draw(&Text::new(
        top.label.clone(),
        ((px.start + px.end) / 2, py.start - 28),
        (FONT_FAMILY, 17).into_font().color(&BLACK).pos(Pos::new(HPos::Center, VPos::Bottom)),
    ))
    .map_err(draw_err)
}

/// The drawing area of a plot.
type Area<'a> = DrawingArea<BitMapBackend<'a, RGBPixel>, Shift>;
/// A chart with `f64` axes on a plot.
type Chart<'a, 'b> = ChartContext<'a, BitMapBackend<'b, RGBPixel>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// The colour scale `(lo, hi)` in dB of a spectrogram plot: `db_range`
/// checked, or for `None` the automatic one.
fn spectrogram_db_range(spectrogram: &Spectrogram, db_range: Option<(f64, f64)>) -> Result<(f64, f64), PlotError> {
    Ok(match db_range {
        Some((lo, hi)) => {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(PlotError::InvalidDbRange { lo, hi });
            }
            (lo, hi)
        }
        None => auto_db_range(spectrogram),
    })
}

/// The axes of a spectrogram plot: the cells' edges and the ranges they span.
struct SpectrogramAxes {
    /// Edges of the time cells, s.
    t_edges: Vec<f64>,
    /// Edges of the frequency cells, Hz.
    f_edges: Vec<f64>,
    /// Span of the time axis, s.
    t_range: Range<f64>,
    /// Span of the frequency axis, Hz (from 0 when the first cell is at or above 0 Hz).
    f_range: Range<f64>,
}

/// The axes of a checked spectrogram, or [`PlotError::RangeTooLarge`].
fn spectrogram_axes(spectrogram: &Spectrogram) -> Result<SpectrogramAxes, PlotError> {
    let times = &spectrogram.times_s;
    let freqs = &spectrogram.frequency_hz;
    let t_edges = cell_edges(times);
    let f_edges = cell_edges(freqs);
    let t_range = t_edges[0]..t_edges[t_edges.len() - 1];
    let f_lo = if freqs[0] >= 0.0 { f_edges[0].max(0.0) } else { f_edges[0] };
    let f_range = f_lo..f_edges[f_edges.len() - 1];
    for (axis, r) in [("time", &t_range), ("frequency", &f_range)] {
        if !(r.end - r.start).is_finite() {
            return Err(PlotError::RangeTooLarge { axis, lo: r.start, hi: r.end });
        }
    }
    Ok(SpectrogramAxes { t_edges, f_edges, t_range, f_range })
}

/// Heat map: every pixel of the plotting area of `chart` takes the colour
/// of the cell under its centre (drawn on `root`), on the colour scale
/// `(db_lo, db_hi)` dB. Returns the plotting area's pixel rows.
fn draw_heat_map(
    root: &Area<'_>,
    chart: &Chart<'_, '_>,
    spectrogram: &Spectrogram,
    axes: &SpectrogramAxes,
    (db_lo, db_hi): (f64, f64),
) -> Result<Range<i32>, PlotError> {
    let (px_range, py_range) = chart.plotting_area().get_pixel_range();
    let spec = chart.as_coord_spec();
    let columns: Vec<Option<usize>> = px_range
        .clone()
        .map(|px| spec.reverse_translate((px, py_range.start)).and_then(|(t, _)| cell_index(&axes.t_edges, t)))
        .collect();
    let rows: Vec<Option<usize>> = py_range
        .clone()
        .map(|py| spec.reverse_translate((px_range.start, py)).and_then(|(_, f)| cell_index(&axes.f_edges, f)))
        .collect();
    for (py, row) in py_range.clone().zip(&rows) {
        let Some(k) = *row else { continue };
        for (px, col) in px_range.clone().zip(&columns) {
            let Some(i) = *col else { continue };
            let db = spectrogram.psd_db[i][k];
            let color = viridis((db - db_lo) / (db_hi - db_lo));
            root.draw_pixel((px, py), &color).map_err(draw_err)?;
        }
    }
    Ok(py_range)
}

/// The overlay curves on `chart` (their finite runs `overlay_runs`),
/// alternately white and black with a contrasting outline, and their legend.
fn draw_overlays<'a, 'b: 'a>(
    chart: &mut Chart<'a, 'b>,
    overlays: &[Series],
    overlay_runs: &[Vec<Vec<(f64, f64)>>],
) -> Result<(), PlotError> {
    for (i, (s, runs)) in overlays.iter().zip(overlay_runs).enumerate() {
        let (core, halo) = if i % 2 == 0 { (WHITE, BLACK) } else { (BLACK, WHITE) };
        let halo_style = ShapeStyle::from(halo).stroke_width(4);
        let core_style = ShapeStyle::from(core).stroke_width(2);
        for (j, run) in runs.iter().enumerate() {
            chart.draw_series(LineSeries::new(run.iter().copied(), halo_style)).map_err(draw_err)?;
            let drawn = chart.draw_series(LineSeries::new(run.iter().copied(), core_style)).map_err(draw_err)?;
            if j == 0 {
                drawn.label(s.name.as_str()).legend(move |(x, y)| {
                    EmptyElement::at((x, y))
                        + PathElement::new(vec![(0, 0), (24, 0)], halo_style)
                        + PathElement::new(vec![(0, 0), (24, 0)], core_style)
                });
            }
        }
    }
    if !overlays.is_empty() {
        chart
            .configure_series_labels()
            .label_font((FONT_FAMILY, 16))
            .background_style(RGBColor(128, 128, 128).mix(0.6))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(draw_err)?;
    }
    Ok(())
}

/// The colour bar of the scale `(db_lo, db_hi)` dB in `bar_panel`, aligned
/// with the plotting area's pixel rows `py_range` of `main`, labelled `label`.
fn draw_colour_bar(
    main: &Area<'_>,
    bar_panel: &Area<'_>,
    py_range: Range<i32>,
    (db_lo, db_hi): (f64, f64),
    label: &str,
) -> Result<(), PlotError> {
    let (_, main_h) = main.dim_in_pixel();
    let top = py_range.start.max(0) as u32;
    let bottom = main_h.saturating_sub(py_range.end.max(0) as u32);
    let bar_area = bar_panel.margin(top, bottom, 10, 12);
    let mut bar = ChartBuilder::on(&bar_area)
        .y_label_area_size(0)
        .right_y_label_area_size(88)
        .build_cartesian_2d(0.0..1.0, db_lo..db_hi)
        .map_err(draw_err)?;
    const STEPS: usize = 256;
    bar.draw_series((0..STEPS).map(|s| {
        let v0 = db_lo + (db_hi - db_lo) * s as f64 / STEPS as f64;
        let v1 = db_lo + (db_hi - db_lo) * (s + 1) as f64 / STEPS as f64;
        let color = viridis((s as f64 + 0.5) / STEPS as f64);
        Rectangle::new([(0.0, v0), (1.0, v1)], color.filled())
    }))
    .map_err(draw_err)?;
    bar.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_desc(label)
        .label_style((FONT_FAMILY, 15))
        .axis_desc_style((FONT_FAMILY, 17))
        .draw()
        .map_err(draw_err)?;
    Ok(())
}

/// Viridis colour map (matplotlib), `t` in [0, 1] (clamped; NaN gives the
/// low end), linearly interpolated between 9 samples of the map.
pub fn viridis(t: f64) -> RGBColor {
    const TABLE: [(u8, u8, u8); 9] = [
        (0x44, 0x01, 0x54),
        (0x47, 0x2d, 0x7b),
        (0x3b, 0x52, 0x8b),
        (0x2c, 0x72, 0x8e),
        (0x21, 0x91, 0x8c),
        (0x28, 0xae, 0x80),
        (0x5e, 0xc9, 0x62),
        (0xad, 0xdc, 0x30),
        (0xfd, 0xe7, 0x25),
    ];
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let pos = t * (TABLE.len() - 1) as f64;
    let i = (pos.floor() as usize).min(TABLE.len() - 2);
    let frac = pos - i as f64;
    let lerp = |a: u8, b: u8| (a as f64 + (b as f64 - a as f64) * frac).round() as u8;
    let (a, b) = (TABLE[i], TABLE[i + 1]);
    RGBColor(lerp(a.0, b.0), lerp(a.1, b.1), lerp(a.2, b.2))
}

/// Line colours (matplotlib "tab10").
fn palette(i: usize) -> RGBColor {
    const COLORS: [RGBColor; 10] = [
        RGBColor(0x1f, 0x77, 0xb4),
        RGBColor(0xd6, 0x27, 0x28),
        RGBColor(0x2c, 0xa0, 0x2c),
        RGBColor(0xff, 0x7f, 0x0e),
        RGBColor(0x94, 0x67, 0xbd),
        RGBColor(0x8c, 0x56, 0x4b),
        RGBColor(0xe3, 0x77, 0xc2),
        RGBColor(0x7f, 0x7f, 0x7f),
        RGBColor(0xbc, 0xbd, 0x22),
        RGBColor(0x17, 0xbe, 0xcf),
    ];
    COLORS[i % COLORS.len()]
}

fn draw_err(e: impl Display) -> PlotError {
    PlotError::Draw { message: e.to_string() }
}

fn check_png_path(path: &Path) -> Result<(), PlotError> {
    let is_png = path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if is_png && path.file_stem().is_some() {
        Ok(())
    } else {
        Err(PlotError::NotPng { path: path.to_path_buf() })
    }
}

/// Registers the embedded font once per process.
fn ensure_font() -> Result<(), PlotError> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| register_font(FONT_FAMILY, FontStyle::Normal, FONT_BYTES).is_ok());
    if ok {
        Ok(())
    } else {
        Err(PlotError::Font)
    }
}

/// Draws with `draw` into a fresh white RGB bitmap and writes it as PNG to
/// `path` (via `<path>.tmp` and a rename).
fn render<F>(path: &Path, draw: F) -> Result<(), PlotError>
where
    F: FnOnce(&DrawingArea<BitMapBackend<'_, RGBPixel>, Shift>) -> Result<(), PlotError>,
{
    render_sized(path, PLOT_WIDTH_PX, PLOT_HEIGHT_PX, draw)
}

/// [`render`] into a `w` x `h` pixel bitmap.
fn render_sized<F>(path: &Path, w: u32, h: u32, draw: F) -> Result<(), PlotError>
where
    F: FnOnce(&DrawingArea<BitMapBackend<'_, RGBPixel>, Shift>) -> Result<(), PlotError>,
{
    ensure_font()?;
    let mut pixels = vec![0u8; w as usize * h as usize * 3];
    {
        let backend = BitMapBackend::<RGBPixel>::with_buffer_and_format(&mut pixels, (w, h)).map_err(draw_err)?;
        let root = backend.into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;
        draw(&root)?;
        root.present().map_err(draw_err)?;
    }
    write_png(path, w, h, &pixels)
}

fn write_png(path: &Path, w: u32, h: u32, rgb: &[u8]) -> Result<(), PlotError> {
    let io_err = |source| PlotError::Io { path: path.to_path_buf(), source };
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        fs::create_dir_all(dir).map_err(io_err)?;
    }
    let mut tmp_name = path.as_os_str().to_os_string();
    tmp_name.push(".tmp");
    let tmp = PathBuf::from(tmp_name);
    let mut encoded = Vec::with_capacity(rgb.len() / 4);
    {
        let mut encoder = png::Encoder::new(&mut encoded, w, h);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let enc_err = |e: png::EncodingError| PlotError::Encode { path: path.to_path_buf(), message: e.to_string() };
        let mut writer = encoder.write_header().map_err(enc_err)?;
        writer.write_image_data(rgb).map_err(enc_err)?;
        writer.finish().map_err(enc_err)?;
    }
    let result = fs::write(&tmp, &encoded).and_then(|()| fs::rename(&tmp, path)).map_err(io_err);
    if result.is_err() {
        // Best effort: do not leave the partial temporary file behind.
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// Checks a series and splits it into runs of finite points, decimated so
/// that the whole series has at most about [`MAX_POINTS_PER_SERIES`] points.
fn prepare_series(s: &Series) -> Result<Vec<Vec<(f64, f64)>>, PlotError> {
    if s.x.len() != s.y.len() {
        return Err(PlotError::LengthMismatch { name: s.name.clone(), x_len: s.x.len(), y_len: s.y.len() });
    }
    if s.x.is_empty() {
        return Err(PlotError::EmptySeries { name: s.name.clone() });
    }
    let mut runs: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut current = Vec::new();
    for (&x, &y) in s.x.iter().zip(&s.y) {
        if x.is_finite() && y.is_finite() {
            current.push((x, y));
        } else if !current.is_empty() {
            runs.push(std::mem::take(&mut current));
        }
    }
    if !current.is_empty() {
        runs.push(current);
    }
    let total: usize = runs.iter().map(Vec::len).sum();
    if total <= MAX_POINTS_PER_SERIES {
        return Ok(runs);
    }
    let bucket = total.div_ceil(MAX_POINTS_PER_SERIES / 2);
    Ok(runs.iter().map(|r| decimate_min_max(r, bucket)).collect())
}

/// Keeps, for each bucket of `bucket` consecutive points, the point with
/// the smallest and the one with the largest y, in their original order.
fn decimate_min_max(points: &[(f64, f64)], bucket: usize) -> Vec<(f64, f64)> {
    if bucket <= 1 {
        return points.to_vec();
    }
    let mut out = Vec::with_capacity(2 * points.len().div_ceil(bucket));
    for chunk in points.chunks(bucket) {
        let (mut i_min, mut i_max) = (0, 0);
        for (i, p) in chunk.iter().enumerate() {
            if p.1 < chunk[i_min].1 {
                i_min = i;
            }
            if p.1 > chunk[i_max].1 {
                i_max = i;
            }
        }
        let (first, second) = (i_min.min(i_max), i_min.max(i_max));
        out.push(chunk[first]);
        if second != first {
            out.push(chunk[second]);
        }
    }
    out
}

/// (x_min, x_max, y_min, y_max) of the points, `None` if there are none.
fn bounds<'a>(points: impl Iterator<Item = &'a (f64, f64)>) -> Option<(f64, f64, f64, f64)> {
    points.fold(None, |acc, &(x, y)| match acc {
        None => Some((x, x, y, y)),
        Some((a, b, c, d)) => Some((a.min(x), b.max(x), c.min(y), d.max(y))),
    })
}

/// Axis range covering `[lo, hi]` plus `margin` of the span on each side;
/// a degenerate span is widened so the axis has a non-zero length.
fn padded_range(axis: &'static str, lo: f64, hi: f64, margin: f64) -> Result<Range<f64>, PlotError> {
    let span = hi - lo;
    if !span.is_finite() {
        return Err(PlotError::RangeTooLarge { axis, lo, hi });
    }
    let (lo, hi) = if span > 0.0 {
        (lo - margin * span, hi + margin * span)
    } else {
        let d = if lo != 0.0 { 0.05 * lo.abs() } else { 1.0 };
        (lo - d, hi + d)
    };
    if !(lo.is_finite() && hi.is_finite() && (hi - lo).is_finite()) {
        return Err(PlotError::RangeTooLarge { axis, lo, hi });
    }
    Ok(lo..hi)
}

fn check_spectrogram(s: &Spectrogram) -> Result<(), PlotError> {
    for (axis, values) in [("times_s", &s.times_s), ("frequency_hz", &s.frequency_hz)] {
        if values.is_empty() {
            return Err(PlotError::SpectrogramShape { what: axis.to_string(), got: 0, expected: 1 });
        }
        for (index, &value) in values.iter().enumerate() {
            let increasing = index == 0 || value > values[index - 1];
            if !value.is_finite() || !increasing {
                return Err(PlotError::SpectrogramAxis { axis, index, value });
            }
        }
    }
    if s.psd_db.len() != s.times_s.len() {
        return Err(PlotError::SpectrogramShape {
            what: "psd_db (rows, one per time)".to_string(),
            got: s.psd_db.len(),
            expected: s.times_s.len(),
        });
    }
    for (time_index, row) in s.psd_db.iter().enumerate() {
        if row.len() != s.frequency_hz.len() {
            return Err(PlotError::SpectrogramShape {
                what: format!("psd_db row {time_index}"),
                got: row.len(),
                expected: s.frequency_hz.len(),
            });
        }
        if let Some((frequency_index, &value)) = row.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(PlotError::SpectrogramValue { time_index, frequency_index, value });
        }
    }
    Ok(())
}

/// Automatic colour range in dB: `(max - AUTO_DB_SPAN, max)`, narrowed to
/// `(min, max)` if the data span less; 1 dB wide for a constant map.
fn auto_db_range(s: &Spectrogram) -> (f64, f64) {
    let (min, max) =
        s.psd_db.iter().flatten().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    let lo = min.max(max - AUTO_DB_SPAN);
    if lo < max {
        (lo, max)
    } else {
        (max - 1.0, max)
    }
}

/// Cell edges for cell centres `c` (ascending, at least one): midpoints
/// between neighbours, and half a neighbour spacing beyond the ends (±0.5
/// for a single centre).
fn cell_edges(c: &[f64]) -> Vec<f64> {
    let n = c.len();
    if n == 1 {
        return vec![c[0] - 0.5, c[0] + 0.5];
    }
    let mut edges = Vec::with_capacity(n + 1);
    edges.push(c[0] - 0.5 * (c[1] - c[0]));
    edges.extend(c.windows(2).map(|w| 0.5 * (w[0] + w[1])));
    edges.push(c[n - 1] + 0.5 * (c[n - 1] - c[n - 2]));
    edges
}

/// Index of the cell whose edges enclose `v`, `None` outside all cells.
fn cell_index(edges: &[f64], v: f64) -> Option<usize> {
    if !(v >= edges[0] && v <= edges[edges.len() - 1]) {
        return None;
    }
    let i = edges.partition_point(|&e| e <= v);
    Some(i.saturating_sub(1).min(edges.len() - 2))
}

#[cfg(test)]
mod tests {
    use super::*;
    use dsp::stft_spectrogram;
    use std::f64::consts::PI;

    /// Checks the PNG signature and IHDR and decodes the image fully;
    /// returns (width, height, RGB bytes).
    fn read_png(path: &Path) -> (u32, u32, Vec<u8>) {
        let bytes = fs::read(path).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "PNG signature");
        assert_eq!(&bytes[8..12], &13u32.to_be_bytes(), "IHDR length");
        assert_eq!(&bytes[12..16], b"IHDR");
        let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
        let h = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
        let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (w, h));
        assert_eq!(info.color_type, png::ColorType::Rgb);
        buf.truncate(info.buffer_size());
        (w, h, buf)
    }

    fn pixel(rgb: &[u8], w: u32, x: u32, y: u32) -> (u8, u8, u8) {
        let i = 3 * (y as usize * w as usize + x as usize);
        (rgb[i], rgb[i + 1], rgb[i + 2])
    }

    fn distinct_colors(rgb: &[u8]) -> usize {
        let mut set = std::collections::HashSet::new();
        for p in rgb.chunks(3) {
            set.insert((p[0], p[1], p[2]));
        }
        set.len()
    }

    #[test]
    fn line_plot_writes_valid_png_of_expected_size() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub/dir/line.png");
        let n = 300_000;
        let t: Vec<f64> = (0..n).map(|k| k as f64 / 16384.0).collect();
        let a: Vec<f64> = t.iter().map(|t| (2.0 * PI * 3.0 * t).sin() * (-t / 5.0).exp()).collect();
        let mut b: Vec<f64> = t.iter().map(|t| 0.5 * (2.0 * PI * 0.5 * t).cos()).collect();
        b[1000] = f64::NAN;
        b[2000] = f64::INFINITY;
        let series = [Series::new("car acceleration", t.clone(), a), Series::new("reference", t, b)];
        line_plot(&path, "Travel up, m_car = 70.5 kg", "time [s]", "acceleration [m/s²]", &series).unwrap();
        let (w, h, rgb) = read_png(&path);
        assert_eq!((w, h), (PLOT_WIDTH_PX, PLOT_HEIGHT_PX));
        // Two line colours, text and grid: more than a handful of colours.
        assert!(distinct_colors(&rgb) > 20);
        let blue = palette(0);
        assert!(rgb.chunks(3).any(|p| (p[0], p[1], p[2]) == (blue.0, blue.1, blue.2)));
        assert!(!path.with_extension("png.tmp").exists());
        if let Ok(dir) = std::env::var("HOST_SIM_KEEP_PLOTS") {
            fs::copy(&path, Path::new(&dir).join("line_plot.png")).unwrap();
        }
    }

    #[test]
    fn spectrogram_plot_writes_valid_png_with_colours_in_place() {
        let dir = tempfile::tempdir().unwrap();
        // Hand-made map: left half of the time axis at 0 dB, right half at
        // -60 dB; with db_range (-60, 0) the left is yellow, the right purple.
        let times: Vec<f64> = (0..40).map(|i| 0.25 * i as f64).collect();
        let freqs: Vec<f64> = (0..100).map(|k| 2.0 * k as f64).collect();
        let psd_db = (0..40).map(|i| vec![if i < 20 { 0.0 } else { -60.0 }; 100]).collect();
        let s = Spectrogram { times_s: times, frequency_hz: freqs, psd_db };
        let path = dir.path().join("halves.png");
        spectrogram_plot(&path, "halves", &s, &[], Some((-60.0, 0.0))).unwrap();
        let (w, h, rgb) = read_png(&path);
        assert_eq!((w, h), (PLOT_WIDTH_PX, PLOT_HEIGHT_PX));
        // The plotting area spans roughly x 100..1035, y 60..630 px.
        let main_w = PLOT_WIDTH_PX - COLORBAR_PANEL_PX;
        let left = pixel(&rgb, w, main_w * 3 / 10, h / 2);
        let right = pixel(&rgb, w, main_w * 8 / 10, h / 2);
        let top = viridis(1.0);
        let bottom = viridis(0.0);
        assert_eq!(left, (top.0, top.1, top.2));
        assert_eq!(right, (bottom.0, bottom.1, bottom.2));
    }

    #[test]
    fn spectrogram_plot_of_chirp_with_overlay() {
        let dir = tempfile::tempdir().unwrap();
        let fs = 2048.0;
        let n = (10.0 * fs) as usize;
        let x: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 / fs;
                (2.0 * PI * (10.0 * t + 4.0 * t * t)).sin() + 0.3 * (2.0 * PI * 120.0 * t).sin()
            })
            .collect();
        let s = stft_spectrogram(&x, fs, 0.5, 0.75, 150.0).unwrap();
        let track_t: Vec<f64> = (0..=100).map(|i| 0.1 * i as f64).collect();
        let track_f: Vec<f64> = track_t.iter().map(|t| 10.0 + 8.0 * t).collect();
        let track2: Vec<f64> = track_t.iter().map(|_| 120.0).collect();
        let overlays =
            [Series::new("mode 1 (model)", track_t.clone(), track_f), Series::new("mode 2 (model)", track_t, track2)];
        let path = dir.path().join("chirp.PNG");
        spectrogram_plot(&path, "Chirp 10 Hz + 8 Hz/s", &s, &overlays, None).unwrap();
        let (w, h, rgb) = read_png(&path);
        assert_eq!((w, h), (PLOT_WIDTH_PX, PLOT_HEIGHT_PX));
        assert!(distinct_colors(&rgb) > 100);
        if let Ok(dir) = std::env::var("HOST_SIM_KEEP_PLOTS") {
            fs::copy(&path, Path::new(&dir).join("chirp_spectrogram.png")).unwrap();
        }
    }

    #[test]
    fn bad_input_gives_errors_not_panics() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.png");
        assert!(matches!(line_plot(&p, "t", "x", "y", &[]), Err(PlotError::NoSeries)));
        let empty = Series::new("empty", vec![], vec![]);
        match line_plot(&p, "t", "x", "y", &[empty]) {
            Err(e @ PlotError::EmptySeries { .. }) => assert!(e.to_string().contains("empty")),
            other => panic!("{other:?}"),
        }
        let bad = Series::new("speed", vec![0.0, 1.0, 2.0], vec![1.0, 2.0]);
        match line_plot(&p, "t", "x", "y", &[bad]) {
            Err(e @ PlotError::LengthMismatch { .. }) => {
                let msg = e.to_string();
                assert!(msg.contains("speed") && msg.contains('3') && msg.contains('2'), "{msg}");
            }
            other => panic!("{other:?}"),
        }
        let nan = Series::new("nan", vec![0.0, 1.0], vec![f64::NAN, f64::NAN]);
        assert!(matches!(line_plot(&p, "t", "x", "y", &[nan]), Err(PlotError::NoFinitePoints)));
        let huge = Series::new("huge", vec![0.0, 1.0], vec![-f64::MAX, f64::MAX]);
        assert!(matches!(line_plot(&p, "t", "x", "y", &[huge]), Err(PlotError::RangeTooLarge { axis: "y", .. })));
        let ok = Series::new("ok", vec![0.0, 1.0], vec![0.0, 1.0]);
        assert!(matches!(line_plot(&dir.path().join("x.svg"), "t", "x", "y", &[ok]), Err(PlotError::NotPng { .. })));
        assert!(!p.exists());

        let good = Spectrogram {
            times_s: vec![0.0, 1.0],
            frequency_hz: vec![0.0, 1.0, 2.0],
            psd_db: vec![vec![0.0; 3], vec![0.0; 3]],
        };
        let mut s = good.clone();
        s.psd_db[1].pop();
        assert!(matches!(spectrogram_plot(&p, "t", &s, &[], None), Err(PlotError::SpectrogramShape { .. })));
        let mut s = good.clone();
        s.psd_db.pop();
        assert!(matches!(spectrogram_plot(&p, "t", &s, &[], None), Err(PlotError::SpectrogramShape { .. })));
        let mut s = good.clone();
        s.times_s = vec![1.0, 0.0];
        assert!(matches!(
            spectrogram_plot(&p, "t", &s, &[], None),
            Err(PlotError::SpectrogramAxis { axis: "times_s", index: 1, .. })
        ));
        let mut s = good.clone();
        s.psd_db[0][2] = f64::NAN;
        assert!(matches!(
            spectrogram_plot(&p, "t", &s, &[], None),
            Err(PlotError::SpectrogramValue { time_index: 0, frequency_index: 2, .. })
        ));
        let empty = Spectrogram { times_s: vec![], frequency_hz: vec![], psd_db: vec![] };
        assert!(matches!(spectrogram_plot(&p, "t", &empty, &[], None), Err(PlotError::SpectrogramShape { .. })));
        assert!(matches!(
            spectrogram_plot(&p, "t", &good, &[], Some((0.0, 0.0))),
            Err(PlotError::InvalidDbRange { .. })
        ));
        let bad_overlay = Series::new("mode", vec![0.0], vec![1.0, 2.0]);
        assert!(matches!(
            spectrogram_plot(&p, "t", &good, &[bad_overlay], None),
            Err(PlotError::LengthMismatch { .. })
        ));
        assert!(!p.exists());
        // A single-cell spectrogram still draws.
        let one = Spectrogram { times_s: vec![0.5], frequency_hz: vec![10.0], psd_db: vec![vec![-20.0]] };
        spectrogram_plot(&p, "one cell", &one, &[], None).unwrap();
        assert_eq!(read_png(&p).0, PLOT_WIDTH_PX);
    }

    #[test]
    fn extreme_but_finite_ranges_draw() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("extreme.png");
        let cases = [
            (vec![0.0, 1.0], vec![0.0, 1e-300]),
            (vec![0.0, 1.0], vec![1e300, 1e300 * (1.0 + 1e-15)]),
            (vec![5.0, 5.0], vec![-2.0, -2.0]),
            (vec![0.0], vec![0.0]),
            (vec![-1e150, 1e150], vec![1e-150, -1e-150]),
        ];
        for (x, y) in cases {
            let label = format!("{x:?} {y:?}");
            line_plot(&p, "extreme", "x", "y", &[Series::new("s", x, y)]).unwrap_or_else(|e| panic!("{label}: {e}"));
            assert_eq!(read_png(&p).0, PLOT_WIDTH_PX, "{label}");
        }
    }

    #[test]
    fn decimation_keeps_bucket_extremes_in_order() {
        let pts: Vec<(f64, f64)> =
            (0..10).map(|i| (i as f64, [3.0, 1.0, 4.0, 1.5, 9.0, 2.0, 6.0, 5.0, 3.5, 8.0][i])).collect();
        let d = decimate_min_max(&pts, 4);
        // Buckets [3,1,4,1.5] -> (1:1),(2:4); [9,2,6,5] -> (4:9),(5:2); [3.5,8] -> (8:3.5),(9:8)
        assert_eq!(d, vec![(1.0, 1.0), (2.0, 4.0), (4.0, 9.0), (5.0, 2.0), (8.0, 3.5), (9.0, 8.0)]);
        // A long series is reduced below the limit but keeps its extremes.
        let n: usize = 300_000;
        let y: Vec<f64> = (0..n).map(|k| ((k * 7919) % 1000) as f64).collect();
        let mut y = y;
        y[123_457] = 5000.0;
        y[200_001] = -5000.0;
        let s = Series::new("s", (0..n).map(|k| k as f64).collect(), y);
        let runs = prepare_series(&s).unwrap();
        let pts: Vec<&(f64, f64)> = runs.iter().flatten().collect();
        assert!(pts.len() <= MAX_POINTS_PER_SERIES, "{}", pts.len());
        assert!(pts.len() >= MAX_POINTS_PER_SERIES - 10);
        assert!(pts.iter().any(|p| p.0 == 123_457.0 && p.1 == 5000.0));
        assert!(pts.iter().any(|p| p.0 == 200_001.0 && p.1 == -5000.0));
        assert!(pts.windows(2).all(|w| w[0].0 < w[1].0));
    }

    #[test]
    fn non_finite_points_split_runs() {
        let s = Series::new("gappy", vec![0.0, 1.0, 2.0, 3.0, f64::NAN, 5.0], vec![1.0, f64::NAN, 3.0, 4.0, 5.0, 6.0]);
        let runs = prepare_series(&s).unwrap();
        assert_eq!(runs, vec![vec![(0.0, 1.0)], vec![(2.0, 3.0), (3.0, 4.0)], vec![(5.0, 6.0)]]);
    }

    #[test]
    fn viridis_endpoints_and_midpoint() {
        assert_eq!(viridis(0.0), RGBColor(0x44, 0x01, 0x54));
        assert_eq!(viridis(1.0), RGBColor(0xfd, 0xe7, 0x25));
        assert_eq!(viridis(0.5), RGBColor(0x21, 0x91, 0x8c));
        assert_eq!(viridis(-3.0), viridis(0.0));
        assert_eq!(viridis(f64::NAN), viridis(0.0));
        // Half-way between the first two samples.
        assert_eq!(viridis(1.0 / 16.0), RGBColor(70, 23, 104));
        // Lightness increases monotonically (sum of channels as a proxy).
        let l: Vec<u32> = (0..=64)
            .map(|i| {
                let c = viridis(i as f64 / 64.0);
                2 * c.0 as u32 + 7 * c.1 as u32 + c.2 as u32
            })
            .collect();
        assert!(l.windows(2).all(|w| w[1] >= w[0]), "{l:?}");
    }

    #[test]
    fn cell_lookup_uses_midpoint_edges() {
        let e = cell_edges(&[0.0, 1.0, 3.0]);
        assert_eq!(e, vec![-0.5, 0.5, 2.0, 4.0]);
        assert_eq!(cell_index(&e, -0.6), None);
        assert_eq!(cell_index(&e, -0.5), Some(0));
        assert_eq!(cell_index(&e, 0.49), Some(0));
        assert_eq!(cell_index(&e, 0.5), Some(1));
        assert_eq!(cell_index(&e, 2.5), Some(2));
        assert_eq!(cell_index(&e, 4.0), Some(2));
        assert_eq!(cell_index(&e, f64::NAN), None);
        assert_eq!(cell_edges(&[2.0]), vec![1.5, 2.5]);
    }

    #[test]
    fn top_axis_ticks_where_the_value_crosses_its_multiples() {
        // A rope length at rest at 1.0 m for 1 s, then rising 0.5 m/s to
        // 2.2 m, then at rest: ticks at 1.0 (its start), 1.5 and 2.0 m.
        let t: Vec<f64> = (0..=50).map(|k| k as f64 * 0.1).collect();
        let lw: Vec<f64> = t.iter().map(|&t| (1.0 + 0.5 * (t - 1.0).max(0.0)).min(2.2)).collect();
        let axis = TopAxis::at_multiples("lw [m]", &t, &lw, 0.5, 1);
        let want = [(0.0, "1.0"), (2.0, "1.5"), (3.0, "2.0")];
        assert_eq!(axis.ticks.len(), want.len(), "{:?}", axis.ticks);
        for ((t, text), (wt, wtext)) in axis.ticks.iter().zip(want) {
            assert!((t - wt).abs() < 1e-9 && text == wtext, "{t} {text}");
        }
        // Falling values tick too; a constant one gets one tick at its start.
        let down: Vec<f64> = lw.iter().map(|v| 3.0 - v).collect();
        assert_eq!(TopAxis::at_multiples("x", &t, &down, 0.5, 1).ticks.len(), 3);
        let flat = TopAxis::at_multiples("x", &t, &vec![1.23; t.len()], 0.5, 2);
        assert_eq!(flat.ticks, vec![(0.0, "1.23".to_string())]);
    }

    #[test]
    fn spectrogram_with_top_axis_draws_its_ticks_above_the_map() {
        let dir = tempfile::tempdir().unwrap();
        let (with, without) = (dir.path().join("top.png"), dir.path().join("plain.png"));
        let s = Spectrogram {
            times_s: (0..20).map(f64::from).collect(),
            frequency_hz: (0..10).map(f64::from).collect(),
            psd_db: vec![vec![-30.0; 10]; 20],
        };
        let top =
            TopAxis { label: "lw [m]".to_string(), ticks: vec![(5.0, "2.0".to_string()), (15.0, "4.0".to_string())] };
        spectrogram_plot_with_top_axis(&with, "t", &s, &[], None, Some(&top)).unwrap();
        spectrogram_plot(&without, "t", &s, &[], None).unwrap();
        let (w, _, a) = read_png(&with);
        let (_, _, b) = read_png(&without);
        // The heat map starts lower with the axis: its top row of colour is
        // further down, and dark tick text sits above it.
        let first_coloured_row = |rgb: &[u8]| {
            (0..PLOT_HEIGHT_PX).find(|&y| {
                pixel(rgb, w, 600, y) == {
                    let c = viridis(1.0);
                    (c.0, c.1, c.2)
                }
            })
        };
        let (ya, yb) = (first_coloured_row(&a).unwrap(), first_coloured_row(&b).unwrap());
        assert!(ya > yb + 40, "{ya} {yb}");
        let dark_above = (yb..ya).flat_map(|y| (100..1000).map(move |x| (x, y))).filter(|&(x, y)| {
            let p = pixel(&a, w, x, y);
            p.0 < 80 && p.1 < 80 && p.2 < 80
        });
        assert!(dark_above.count() > 30);
    }

    #[test]
    fn auto_db_range_limits_span() {
        let s = Spectrogram {
            times_s: vec![0.0],
            frequency_hz: vec![0.0, 1.0, 2.0],
            psd_db: vec![vec![-3000.0, -50.0, 10.0]],
        };
        assert_eq!(auto_db_range(&s), (10.0 - AUTO_DB_SPAN, 10.0));
        let s = Spectrogram { times_s: vec![0.0], frequency_hz: vec![0.0, 1.0], psd_db: vec![vec![-20.0, -5.0]] };
        assert_eq!(auto_db_range(&s), (-20.0, -5.0));
        let s = Spectrogram { times_s: vec![0.0], frequency_hz: vec![0.0], psd_db: vec![vec![-7.0]] };
        assert_eq!(auto_db_range(&s), (-8.0, -7.0));
    }
}
