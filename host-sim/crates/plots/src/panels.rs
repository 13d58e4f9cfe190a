//! Stacked panels sharing one time axis: traces drawn as lines, or as
//! min/max envelopes when they are long, with shaded regions common to all
//! panels, labelled markers and labelled horizontal levels.

use std::path::Path;

use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::{
    bounds, check_png_path, draw_err, padded_range, palette, prepare_series, render_sized, Chart, PlotError, Series,
    FONT_FAMILY, PLOT_WIDTH_PX,
};

/// A series longer than [`super::MAX_POINTS_PER_SERIES`] is drawn as the
/// min/max envelope of this many buckets of consecutive samples (about four
/// pixels each across a plot), so that a vibration faster than a bucket
/// shows as a band rather than a block of zigzags.
pub const ENVELOPE_BUCKETS: usize = 300;

/// Height in pixels of one panel of [`stacked_plot`] when there are three or
/// more; fewer panels share [`PANELS_MIN_HEIGHT_PX`].
pub const PANEL_HEIGHT_PX: u32 = 260;
/// Height in pixels that one or two panels share.
pub const PANELS_MIN_HEIGHT_PX: u32 = 620;

/// A region shaded across every panel, from `x0` to `x1` (x-axis units),
/// named in the top panel.
#[derive(Debug, Clone, PartialEq)]
pub struct Band {
    /// Start, x-axis units.
    pub x0: f64,
    /// End, x-axis units.
    pub x1: f64,
    /// Legend text.
    pub label: String,
}

/// A labelled point of a panel (a filled circle with its text beside it),
/// with an error bar when `y_error` is given.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Mark {
    /// Abscissa, x-axis units.
    pub x: f64,
    /// Ordinate, the panel's y-axis units.
    pub y: f64,
    /// Text drawn beside the point.
    pub label: String,
    /// Half-width of a vertical error bar, the panel's y-axis units (`y -
    /// e` to `y + e`, with caps); `None` for no bar. The axis spans the bar.
    pub y_error: Option<f64>,
}

/// A labelled horizontal dashed segment of a panel at `y` from `x0` to `x1`.
#[derive(Debug, Clone, PartialEq)]
pub struct Level {
    /// Ordinate, the panel's y-axis units.
    pub y: f64,
    /// Start, x-axis units.
    pub x0: f64,
    /// End, x-axis units.
    pub x1: f64,
    /// Text drawn at the segment's start.
    pub label: String,
}

/// One panel of a [`stacked_plot`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Panel {
    /// Y-axis label, with the unit.
    pub y_label: String,
    /// The traces (at least one).
    pub series: Vec<Series>,
    /// Labelled points.
    pub marks: Vec<Mark>,
    /// Labelled horizontal levels.
    pub levels: Vec<Level>,
}

/// Shade colours of the bands, in order.
const BAND_COLOURS: [RGBColor; 4] =
    [RGBColor(255, 236, 179), RGBColor(200, 230, 201), RGBColor(187, 222, 251), RGBColor(225, 190, 231)];

/// Panels stacked vertically over one x axis into a PNG of width
/// [`PLOT_WIDTH_PX`] and height `title + max(panels x PANEL_HEIGHT_PX,
/// PANELS_MIN_HEIGHT_PX)`.
///
/// * `path`: output file, must end in `.png`.
/// * `title`: drawn at the top (put the recording's name in it).
/// * `x_label`: the shared x axis, drawn under the last panel.
/// * `panels`: at least one; each with at least one series.
/// * `bands`: regions shaded across every panel and named in a legend of
///   the first panel.
///
/// Every panel spans the x range of all the panels' finite points. Series
/// longer than [`super::MAX_POINTS_PER_SERIES`] are drawn as their min/max
/// envelope (a filled band between the smallest and the largest value of
/// each bucket of consecutive samples), so that a long vibration record
/// shows its envelope instead of a solid block of zigzags.
///
/// # Errors
/// Those of [`super::line_plot`].
pub fn stacked_plot(
    path: &Path,
    title: &str,
    x_label: &str,
    panels: &[Panel],
    bands: &[Band],
) -> Result<(), PlotError> {
    check_png_path(path)?;
    if panels.is_empty() || panels.iter().any(|p| p.series.is_empty()) {
        return Err(PlotError::NoSeries);
    }
    let prepared = panels
        .iter()
        .map(|p| p.series.iter().map(prepare_series).collect::<Result<Vec<_>, _>>())
        .collect::<Result<Vec<_>, _>>()?;
    let (x_min, x_max, _, _) =
        bounds(prepared.iter().flatten().flatten().flatten()).ok_or(PlotError::NoFinitePoints)?;
    let x_range = padded_range("x", x_min, x_max, 0.0)?;
    let title_px = 50;
    let height = title_px + (PANEL_HEIGHT_PX * panels.len() as u32).max(PANELS_MIN_HEIGHT_PX) + 30;
    render_sized(path, PLOT_WIDTH_PX, height, |root| {
        let (head, body) = root.split_vertically(title_px);
        head.titled(title, (FONT_FAMILY, 24)).map_err(draw_err)?;
        let areas = body.split_evenly((panels.len(), 1));
        for (i, ((panel, runs), area)) in panels.iter().zip(&prepared).zip(&areas).enumerate() {
            let last = i + 1 == panels.len();
            draw_panel(area, panel, runs, x_range.clone(), if last { Some(x_label) } else { None }, bands, i == 0)?;
        }
        Ok(())
    })
}

/// One panel of [`stacked_plot`] on `area`.
fn draw_panel(
    area: &super::Area<'_>,
    panel: &Panel,
    runs: &[Vec<Vec<(f64, f64)>>],
    x_range: std::ops::Range<f64>,
    x_label: Option<&str>,
    bands: &[Band],
    legend_bands: bool,
) -> Result<(), PlotError> {
    let extra = panel
        .marks
        .iter()
        .flat_map(|m| {
            let e = m.y_error.filter(|e| e.is_finite()).unwrap_or(0.0).abs();
            [m.y - e, m.y + e]
        })
        .chain(panel.levels.iter().map(|l| l.y));
    let ys: Vec<(f64, f64)> =
        runs.iter().flatten().flatten().copied().chain(extra.map(|y| (x_range.start, y))).collect();
    let (_, _, y_min, y_max) = bounds(ys.iter()).ok_or(PlotError::NoFinitePoints)?;
    let y_range = padded_range("y", y_min, y_max, 0.08)?;
    let mut chart = ChartBuilder::on(area)
        .margin_left(15)
        .margin_right(20)
        .margin_top(8)
        .x_label_area_size(if x_label.is_some() { 45 } else { 22 })
        .y_label_area_size(95)
        .build_cartesian_2d(x_range, y_range.clone())
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .x_desc(x_label.unwrap_or(""))
        .y_desc(panel.y_label.as_str())
        .label_style((FONT_FAMILY, 14))
        .axis_desc_style((FONT_FAMILY, 16))
        .light_line_style(RGBColor(240, 240, 240))
        .bold_line_style(RGBColor(210, 210, 210))
        .draw()
        .map_err(draw_err)?;
    for (i, band) in bands.iter().enumerate() {
        let colour = BAND_COLOURS[i % BAND_COLOURS.len()];
        let rect = Rectangle::new([(band.x0, y_range.start), (band.x1, y_range.end)], colour.mix(0.55).filled());
        let drawn = chart.draw_series(std::iter::once(rect)).map_err(draw_err)?;
        if legend_bands {
            drawn
                .label(band.label.as_str())
                .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 20, y + 6)], colour.filled()));
        }
    }
    for (i, (s, r)) in panel.series.iter().zip(runs).enumerate() {
        draw_trace(&mut chart, s, r, palette(i))?;
    }
    draw_levels_and_marks(&mut chart, panel)?;
    if legend_bands && !bands.is_empty() {
        chart
            .configure_series_labels()
            .label_font((FONT_FAMILY, 14))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(draw_err)?;
    }
    Ok(())
}

/// The dashed levels and the marked points of `panel`.
fn draw_levels_and_marks(chart: &mut Chart<'_, '_>, panel: &Panel) -> Result<(), PlotError> {
    let dark = RGBColor(40, 40, 40);
    for level in &panel.levels {
        let style = ShapeStyle::from(dark).stroke_width(2);
        chart
            .draw_series(DashedLineSeries::new([(level.x0, level.y), (level.x1, level.y)], 8, 5, style))
            .map_err(draw_err)?;
        chart
            .draw_series(std::iter::once(Text::new(
                level.label.clone(),
                (level.x0, level.y),
                (FONT_FAMILY, 14).into_font().color(&dark).pos(Pos::new(HPos::Left, VPos::Bottom)),
            )))
            .map_err(draw_err)?;
    }
    let red = RGBColor(200, 0, 0);
    for mark in &panel.marks {
        if let Some(e) = mark.y_error.filter(|e| e.is_finite() && *e > 0.0) {
            let bar = ShapeStyle::from(red).stroke_width(2);
            let (lo, hi) = (mark.y - e, mark.y + e);
            chart
                .draw_series(std::iter::once(PathElement::new(vec![(mark.x, lo), (mark.x, hi)], bar)))
                .map_err(draw_err)?;
            let caps = [lo, hi].map(|y| EmptyElement::at((mark.x, y)) + PathElement::new(vec![(-7, 0), (7, 0)], bar));
            chart.draw_series(caps).map_err(draw_err)?;
        }
        chart.draw_series(std::iter::once(Circle::new((mark.x, mark.y), 5, red.filled()))).map_err(draw_err)?;
        chart
            .draw_series(std::iter::once(Text::new(
                format!("  {}", mark.label),
                (mark.x, mark.y),
                (FONT_FAMILY, 14).into_font().color(&red).pos(Pos::new(HPos::Left, VPos::Center)),
            )))
            .map_err(draw_err)?;
    }
    Ok(())
}

/// Draws one prepared series: as a line when it has at most
/// [`super::MAX_POINTS_PER_SERIES`] samples, otherwise as its min/max
/// envelope of [`ENVELOPE_BUCKETS`] buckets (see [`envelope`]): a band
/// filled in a light shade of `colour`, edged in `colour`.
pub(crate) fn draw_trace(
    chart: &mut Chart<'_, '_>,
    series: &Series,
    runs: &[Vec<(f64, f64)>],
    colour: RGBColor,
) -> Result<(), PlotError> {
    let line = ShapeStyle::from(colour).stroke_width(2);
    if series.x.len() <= super::MAX_POINTS_PER_SERIES {
        for (j, run) in runs.iter().enumerate() {
            let drawn = chart.draw_series(LineSeries::new(run.iter().copied(), line)).map_err(draw_err)?;
            if j == 0 {
                drawn
                    .label(series.name.as_str())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], line));
            }
        }
        return Ok(());
    }
    let bucket = series.x.len().div_ceil(ENVELOPE_BUCKETS);
    let fill = colour.mix(0.35).filled();
    for (j, band) in envelope(series, bucket).into_iter().enumerate() {
        // One filled column per bucket, then the upper and lower edges.
        let columns = band.windows(2).map(|w| Rectangle::new([(w[0].0, w[0].1), (w[1].0, w[0].2)], fill));
        chart.draw_series(columns).map_err(draw_err)?;
        let upper: Vec<(f64, f64)> = band.iter().map(|&(x, _, hi)| (x, hi)).collect();
        let lower: Vec<(f64, f64)> = band.iter().map(|&(x, lo, _)| (x, lo)).collect();
        chart.draw_series(LineSeries::new(lower, line)).map_err(draw_err)?;
        let drawn = chart.draw_series(LineSeries::new(upper, line)).map_err(draw_err)?;
        if j == 0 {
            drawn
                .label(format!("{} (min/max envelope)", series.name))
                .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 24, y + 5)], colour.mix(0.35).filled()));
        }
    }
    Ok(())
}

/// Min/max envelope of `series`: for each run of finite points, one
/// `(x, min y, max y)` per bucket of `bucket` consecutive samples (x of the
/// bucket's first sample; the last bucket also gets its last x, so the band
/// spans the run).
pub fn envelope(series: &Series, bucket: usize) -> Vec<Vec<(f64, f64, f64)>> {
    let bucket = bucket.max(1);
    let mut bands = Vec::new();
    let mut current: Vec<(f64, f64)> = Vec::new();
    let flush = |run: &mut Vec<(f64, f64)>, bands: &mut Vec<Vec<(f64, f64, f64)>>| {
        if run.is_empty() {
            return;
        }
        let mut band: Vec<(f64, f64, f64)> = run
            .chunks(bucket)
            .map(|c| {
                let (lo, hi) = c.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.1), b.max(p.1)));
                (c[0].0, lo, hi)
            })
            .collect();
        let last = *band.last().expect("a non-empty run has a bucket");
        let x_end = run[run.len() - 1].0;
        if x_end > last.0 {
            band.push((x_end, last.1, last.2));
        }
        bands.push(band);
        run.clear();
    };
    for (&x, &y) in series.x.iter().zip(&series.y) {
        if x.is_finite() && y.is_finite() {
            current.push((x, y));
        } else {
            flush(&mut current, &mut bands);
        }
    }
    flush(&mut current, &mut bands);
    bands
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn envelope_holds_each_buckets_extremes() {
        let x: Vec<f64> = (0..10).map(f64::from).collect();
        let y = vec![1.0, -2.0, 3.0, 0.0, 5.0, -1.0, f64::NAN, 2.0, 4.0, -3.0];
        let bands = envelope(&Series::new("s", x, y), 3);
        assert_eq!(bands.len(), 2);
        assert_eq!(bands[0], vec![(0.0, -2.0, 3.0), (3.0, -1.0, 5.0), (5.0, -1.0, 5.0)]);
        assert_eq!(bands[1], vec![(7.0, -3.0, 4.0), (9.0, -3.0, 4.0)]);
    }

    #[test]
    fn stacked_plot_draws_panels_bands_and_marks() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("stacked.png");
        let n = 300_000;
        let t: Vec<f64> = (0..n).map(|k| k as f64 / 16384.0).collect();
        let y: Vec<f64> = t.iter().map(|t| (2.0 * std::f64::consts::PI * 40.0 * t).sin()).collect();
        let panel = |label: &str| Panel {
            y_label: label.to_string(),
            series: vec![Series::new("trace", t.clone(), y.clone())],
            marks: vec![Mark { x: 5.0, y: 1.0, label: "max 2.0".to_string(), y_error: Some(0.2) }],
            levels: vec![Level { y: 0.5, x0: 4.0, x1: 12.0, label: "A95/2".to_string() }],
        };
        let bands = [Band { x0: 4.0, x1: 12.0, label: "constant speed".to_string() }];
        stacked_plot(&path, "test", "time [s]", &[panel("a [mg]"), panel("b [mg]")], &bands).unwrap();
        let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&path).unwrap()));
        let reader = decoder.read_info().unwrap();
        assert_eq!(reader.info().width, PLOT_WIDTH_PX);
        assert_eq!(reader.info().height, 50 + PANELS_MIN_HEIGHT_PX + 30);
        assert!(matches!(stacked_plot(&path, "t", "x", &[], &[]), Err(PlotError::NoSeries)));
    }
}
