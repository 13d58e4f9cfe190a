//! Categorical heat maps on a diverging colour scale: one panel per item
//! (e.g. per measured channel), named columns (e.g. travel phases) across,
//! named rows (e.g. band centre frequencies) up, a value per cell coloured
//! blue below zero, white at zero and red above, and one colour bar.
//!
//! Used for the gap maps of the sim-to-real diagnosis: the excess gap in dB
//! of each (phase, band) cell, where zero means the model meets the data.

use std::path::Path;

use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::{check_png_path, draw_err, render_sized, PlotError, FONT_FAMILY};

/// One panel of a [`heat_map_plot`]: a title and the value of each cell,
/// `values[column][row]` in the unit of the colour bar; `None` is a cell
/// without data (drawn grey).
#[derive(Debug, Clone, PartialEq)]
pub struct HeatPanel {
    /// Title of the panel (e.g. the channel's name).
    pub title: String,
    /// Cell values, `values[column][row]`, colour-bar units; `None` for no
    /// data.
    pub values: Vec<Vec<Option<f64>>>,
}

/// A figure of [`HeatPanel`]s sharing their columns, rows and colour scale.
#[derive(Debug, Clone, PartialEq)]
pub struct HeatMap {
    /// Figure title (put the dataset's name in it).
    pub title: String,
    /// Column names, left to right (e.g. the travel phases).
    pub columns: Vec<String>,
    /// Row names, bottom to top (e.g. band centre frequencies).
    pub rows: Vec<String>,
    /// Description of the columns, drawn under the panels.
    pub x_label: String,
    /// Description of the rows, with the unit, drawn left of the panels.
    pub y_label: String,
    /// Description of the colour bar, with the unit (e.g. `excess gap [dB]`).
    pub colour_label: String,
    /// The colour scale spans `-limit..limit` (colour-bar units, > 0);
    /// values beyond are drawn in the end colours. `None` takes the largest
    /// magnitude of the cells, so that the map is read at its own size (1
    /// when every cell is zero).
    pub limit: Option<f64>,
    /// The panels (at least one), laid out left to right, at most
    /// [`HEAT_PANELS_PER_ROW`] to a row (four as two by two).
    pub panels: Vec<HeatPanel>,
}

/// Panels per row of a [`heat_map_plot`].
pub const HEAT_PANELS_PER_ROW: usize = 3;
/// Width in pixels of one panel's cell area and labels.
const PANEL_W_PX: u32 = 430;
/// Height in pixels of one row of panels.
const PANEL_H_PX: u32 = 560;
/// Width in pixels of the colour bar column.
const BAR_W_PX: u32 = 170;
/// Grey of cells without data.
const NO_DATA: RGBColor = RGBColor(200, 200, 200);

/// Diverging colour map (blue - white - red, after ColorBrewer "RdBu"
/// reversed), `t` in [-1, 1] (clamped; NaN gives white): -1 dark blue, 0
/// white, 1 dark red, linearly interpolated between 11 samples.
pub fn diverging(t: f64) -> RGBColor {
    const TABLE: [(u8, u8, u8); 11] = [
        (0x05, 0x30, 0x61),
        (0x21, 0x66, 0xac),
        (0x43, 0x93, 0xc3),
        (0x92, 0xc5, 0xde),
        (0xd1, 0xe5, 0xf0),
        (0xff, 0xff, 0xff),
        (0xfd, 0xdb, 0xc7),
        (0xf4, 0xa5, 0x82),
        (0xd6, 0x60, 0x4d),
        (0xb2, 0x18, 0x2b),
        (0x67, 0x00, 0x1f),
    ];
    let t = if t.is_nan() { 0.0 } else { t.clamp(-1.0, 1.0) };
    let pos = (t + 1.0) * 0.5 * (TABLE.len() - 1) as f64;
    let i = (pos.floor() as usize).min(TABLE.len() - 2);
    let frac = pos - i as f64;
    let lerp = |a: u8, b: u8| (a as f64 + (b as f64 - a as f64) * frac).round() as u8;
    let (a, b) = (TABLE[i], TABLE[i + 1]);
    RGBColor(lerp(a.0, b.0), lerp(a.1, b.1), lerp(a.2, b.2))
}

/// Checks the shape and values of `map`; returns the colour-scale limit.
fn check_heat_map(map: &HeatMap) -> Result<f64, PlotError> {
    if map.panels.is_empty() {
        return Err(PlotError::NoSeries);
    }
    if map.columns.is_empty() || map.rows.is_empty() {
        let (what, got) = if map.columns.is_empty() { ("columns", 0) } else { ("rows", 0) };
        return Err(PlotError::SpectrogramShape { what: format!("heat map {what}"), got, expected: 1 });
    }
    let mut largest: f64 = 0.0;
    for panel in &map.panels {
        if panel.values.len() != map.columns.len() {
            return Err(PlotError::SpectrogramShape {
                what: format!("heat map panel `{}` columns", panel.title),
                got: panel.values.len(),
                expected: map.columns.len(),
            });
        }
        for (c, column) in panel.values.iter().enumerate() {
            if column.len() != map.rows.len() {
                return Err(PlotError::SpectrogramShape {
                    what: format!("heat map panel `{}` column {c} rows", panel.title),
                    got: column.len(),
                    expected: map.rows.len(),
                });
            }
            if let Some((r, v)) =
                column.iter().enumerate().find_map(|(r, v)| v.filter(|v| !v.is_finite()).map(|v| (r, v)))
            {
                return Err(PlotError::SpectrogramValue { time_index: c, frequency_index: r, value: v });
            }
            largest = column.iter().flatten().fold(largest, |m, v| m.max(v.abs()));
        }
    }
    match map.limit {
        Some(l) if !(l.is_finite() && l > 0.0) => Err(PlotError::InvalidDbRange { lo: -l, hi: l }),
        Some(l) => Ok(l),
        None if largest > 0.0 => Ok(largest),
        None => Ok(1.0),
    }
}

/// Heat maps of `map` into a PNG at `path`: panels of up to
/// [`HEAT_PANELS_PER_ROW`] to a row (four as two by two), each with the column names under it
/// (written upwards) and the row names left of it, the panel's title above;
/// a colour bar from `-limit` to `limit` labelled `colour_label` on the
/// right, with zero (white) in its middle; cells without data grey.
///
/// # Errors
/// [`PlotError::NotPng`]; [`PlotError::NoSeries`] without panels;
/// [`PlotError::SpectrogramShape`] when a panel's columns or rows do not
/// match the names; [`PlotError::SpectrogramValue`] for a non-finite value
/// (its column and row as time and frequency index);
/// [`PlotError::InvalidDbRange`] for a limit that is not finite and
/// positive; [`PlotError::Font`], [`PlotError::Draw`],
/// [`PlotError::Encode`], [`PlotError::Io`] when drawing or writing fails.
pub fn heat_map_plot(path: &Path, map: &HeatMap) -> Result<(), PlotError> {
    check_png_path(path)?;
    let limit = check_heat_map(map)?;
    let per_row = panels_per_row(map.panels.len());
    let panel_rows = map.panels.len().div_ceil(per_row);
    let width = 40 + per_row as u32 * PANEL_W_PX + BAR_W_PX;
    let title_lines = wrap_words(&map.title, title_chars_per_line(width));
    let x_label_px = 34;
    let title_px = TITLE_MARGIN_PX + title_lines.len() as u32 * TITLE_LINE_PX;
    let height = title_px + panel_rows as u32 * PANEL_H_PX + x_label_px;
    render_sized(path, width, height, |root| {
        let (head, rest) = root.split_vertically(title_px);
        for (i, line) in title_lines.iter().enumerate() {
            head.draw(&Text::new(
                line.clone(),
                (width as i32 / 2, (TITLE_MARGIN_PX / 2 + i as u32 * TITLE_LINE_PX) as i32),
                (FONT_FAMILY, TITLE_FONT_PX).into_font().color(&BLACK).pos(Pos::new(HPos::Center, VPos::Top)),
            ))
            .map_err(draw_err)?;
        }
        let (body, foot) = rest.split_vertically(panel_rows as u32 * PANEL_H_PX);
        foot.draw(&Text::new(
            map.x_label.clone(),
            ((width - BAR_W_PX) as i32 / 2, 6),
            (FONT_FAMILY, 18).into_font().color(&BLACK).pos(Pos::new(HPos::Center, VPos::Top)),
        ))
        .map_err(draw_err)?;
        let (y_desc, grid) = body.split_horizontally(40);
        let (grid, bar_column) = grid.split_horizontally(per_row as u32 * PANEL_W_PX);
        let (_, y_desc_h) = y_desc.dim_in_pixel();
        y_desc
            .draw(&Text::new(
                map.y_label.clone(),
                (12, y_desc_h as i32 / 2),
                (FONT_FAMILY, 18)
                    .into_font()
                    .transform(FontTransform::Rotate270)
                    .color(&BLACK)
                    .pos(Pos::new(HPos::Center, VPos::Center)),
            ))
            .map_err(draw_err)?;
        let cells = grid.split_evenly((panel_rows, per_row));
        let mut cell_rows = 0..0;
        for (panel, area) in map.panels.iter().zip(&cells) {
            cell_rows = draw_heat_panel(area, map, panel, limit)?;
        }
        draw_diverging_bar(&bar_column, cell_rows, limit, &map.colour_label)
    })
}

/// Title font size, pixels.
const TITLE_FONT_PX: u32 = 22;
/// Height of one title line, pixels.
const TITLE_LINE_PX: u32 = 28;
/// Space above and below the title, pixels together.
const TITLE_MARGIN_PX: u32 = 24;

/// Characters of the title font that fit on one line of a figure `width`
/// pixels wide, with a margin: a glyph of the sans-serif font is at most
/// about 0.6 of the font size wide on average over a line of text.
fn title_chars_per_line(width: u32) -> usize {
    ((width.saturating_sub(40)) as f64 / (0.6 * TITLE_FONT_PX as f64)).floor().max(10.0) as usize
}

/// `text` broken into lines of at most `max` characters, at spaces where
/// it can be, inside a word (a long path) where it cannot.
pub fn wrap_words(text: &str, max: usize) -> Vec<String> {
    let max = max.max(1);
    let mut lines: Vec<String> = Vec::new();
    let mut line = String::new();
    for word in text.split_whitespace() {
        let mut word: Vec<char> = word.chars().collect();
        loop {
            let used = line.chars().count();
            let room = if used == 0 { max } else { max.saturating_sub(used + 1) };
            if word.len() <= room {
                if used > 0 {
                    line.push(' ');
                }
                line.extend(word.iter());
                break;
            }
            if used > 0 && word.len() <= max {
                lines.push(std::mem::take(&mut line));
                continue;
            }
            // A word longer than the room: as much as fits, the rest on.
            let take = if room == 0 {
                lines.push(std::mem::take(&mut line));
                max
            } else {
                room
            };
            if !line.is_empty() {
                line.push(' ');
            }
            line.extend(word.drain(..take.min(word.len())));
            lines.push(std::mem::take(&mut line));
            if word.is_empty() {
                break;
            }
        }
    }
    if !line.is_empty() || lines.is_empty() {
        lines.push(line);
    }
    lines
}

/// Panels in a row for `n` panels: all of up to [`HEAT_PANELS_PER_ROW`] in
/// one row, four as two rows of two, more [`HEAT_PANELS_PER_ROW`] to a row.
fn panels_per_row(n: usize) -> usize {
    match n {
        4 => 2,
        n => n.clamp(1, HEAT_PANELS_PER_ROW),
    }
}

/// One panel on `area`; returns the pixel rows (root coordinates) of its cells.
fn draw_heat_panel(
    area: &super::Area<'_>,
    map: &HeatMap,
    panel: &HeatPanel,
    limit: f64,
) -> Result<std::ops::Range<i32>, PlotError> {
    let (n_cols, n_rows) = (map.columns.len(), map.rows.len());
    let longest_column = map.columns.iter().map(|c| c.chars().count()).max().unwrap_or(1) as u32;
    let mut chart = ChartBuilder::on(area)
        .caption(&panel.title, (FONT_FAMILY, 19))
        .margin(8)
        .x_label_area_size(16 + 8 * longest_column)
        .y_label_area_size(62)
        .build_cartesian_2d(0.0..n_cols as f64, 0.0..n_rows as f64)
        .map_err(draw_err)?;
    chart.configure_mesh().disable_mesh().x_labels(0).y_labels(0).draw().map_err(draw_err)?;
    let cells = panel.values.iter().enumerate().flat_map(|(c, column)| {
        column.iter().enumerate().map(move |(r, v)| {
            let colour = v.map_or(NO_DATA, |v| diverging(v / limit));
            Rectangle::new([(c as f64, r as f64), (c as f64 + 1.0, r as f64 + 1.0)], colour.filled())
        })
    });
    chart.draw_series(cells).map_err(draw_err)?;
    let grid = ShapeStyle::from(RGBColor(120, 120, 120)).stroke_width(1);
    chart
        .draw_series((0..=n_cols).map(|c| PathElement::new(vec![(c as f64, 0.0), (c as f64, n_rows as f64)], grid)))
        .map_err(draw_err)?;
    chart
        .draw_series(std::iter::once(Rectangle::new([(0.0, 0.0), (n_cols as f64, n_rows as f64)], BLACK)))
        .map_err(draw_err)?;
    // Names: the columns under the cells written upwards, every row's name
    // left of it (every other one when the rows are tight).
    let (px, py) = chart.plotting_area().get_pixel_range();
    let (area_x, area_y) = area.get_base_pixel();
    let row_px = (py.end - py.start) as f64 / n_rows as f64;
    let row_step = if row_px < 15.0 { 2 } else { 1 };
    for (c, name) in map.columns.iter().enumerate() {
        let (x, _) = chart.backend_coord(&(c as f64 + 0.5, 0.0));
        area.draw(&Text::new(
            name.clone(),
            (x - area_x, py.end - area_y + 6),
            (FONT_FAMILY, 15)
                .into_font()
                .transform(FontTransform::Rotate270)
                .color(&BLACK)
                .pos(Pos::new(HPos::Right, VPos::Center)),
        ))
        .map_err(draw_err)?;
    }
    for (r, name) in map.rows.iter().enumerate().filter(|(r, _)| r % row_step == 0) {
        let (_, y) = chart.backend_coord(&(0.0, r as f64 + 0.5));
        area.draw(&Text::new(
            name.clone(),
            (px.start - area_x - 6, y - area_y),
            (FONT_FAMILY, 14).into_font().color(&BLACK).pos(Pos::new(HPos::Right, VPos::Center)),
        ))
        .map_err(draw_err)?;
    }
    Ok(py)
}

/// The colour bar `-limit..limit` in `column`, spanning the pixel rows
/// `cell_rows` (figure coordinates) of the last panel, labelled `label`.
fn draw_diverging_bar(
    column: &super::Area<'_>,
    cell_rows: std::ops::Range<i32>,
    limit: f64,
    label: &str,
) -> Result<(), PlotError> {
    let (_, h) = column.dim_in_pixel();
    let (_, base_y) = column.get_base_pixel();
    let top = (cell_rows.start - base_y).max(0) as u32;
    let bottom = (h as i32 - (cell_rows.end - base_y)).max(0) as u32;
    let bar_area = column.margin(top, bottom, 14, 10);
    let mut bar = ChartBuilder::on(&bar_area)
        .y_label_area_size(0)
        .right_y_label_area_size(100)
        .build_cartesian_2d(0.0..1.0, -limit..limit)
        .map_err(draw_err)?;
    const STEPS: usize = 256;
    bar.draw_series((0..STEPS).map(|s| {
        let v0 = -limit + 2.0 * limit * s as f64 / STEPS as f64;
        let v1 = -limit + 2.0 * limit * (s + 1) as f64 / STEPS as f64;
        Rectangle::new([(0.0, v0), (1.0, v1)], diverging(0.5 * (v0 + v1) / limit).filled())
    }))
    .map_err(draw_err)?;
    bar.draw_series(std::iter::once(Rectangle::new([(0.0, -limit), (1.0, limit)], BLACK))).map_err(draw_err)?;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diverging_is_white_at_zero_and_symmetric_in_shade() {
        assert_eq!(diverging(0.0), RGBColor(255, 255, 255));
        assert_eq!(diverging(f64::NAN), RGBColor(255, 255, 255));
        assert_eq!(diverging(-1.0), RGBColor(0x05, 0x30, 0x61));
        assert_eq!(diverging(1.0), RGBColor(0x67, 0x00, 0x1f));
        assert_eq!(diverging(5.0), diverging(1.0));
        // Positive values are red-dominated, negative blue-dominated.
        for t in [0.2, 0.5, 0.9] {
            let (p, n) = (diverging(t), diverging(-t));
            assert!(p.0 > p.2 && n.2 > n.0, "{t}: {p:?} {n:?}");
        }
    }

    fn read_rgb(path: &Path) -> (u32, u32, Vec<u8>) {
        let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        buf.truncate(info.buffer_size());
        (info.width, info.height, buf)
    }

    fn map(panels: usize) -> HeatMap {
        // Column 0 strongly positive, column 1 strongly negative, column 2
        // without data.
        let values = vec![vec![Some(10.0); 4], vec![Some(-10.0); 4], vec![None; 4]];
        HeatMap {
            title: "test".to_string(),
            columns: vec!["a".to_string(), "b".to_string(), "c".to_string()],
            rows: (0..4).map(|r| format!("{r} Hz")).collect(),
            x_label: "phase".to_string(),
            y_label: "band centre [Hz]".to_string(),
            colour_label: "excess gap [dB]".to_string(),
            limit: Some(10.0),
            panels: (0..panels).map(|p| HeatPanel { title: format!("panel {p}"), values: values.clone() }).collect(),
        }
    }

    #[test]
    fn heat_map_draws_each_cell_in_its_colour() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("heat.png");
        heat_map_plot(&path, &map(4)).unwrap();
        let (w, h, rgb) = read_rgb(&path);
        assert_eq!(w, 40 + 2 * PANEL_W_PX + BAR_W_PX);
        assert_eq!(h, TITLE_MARGIN_PX + TITLE_LINE_PX + 2 * PANEL_H_PX + 34);
        assert_eq!((panels_per_row(1), panels_per_row(3), panels_per_row(5)), (1, 3, 3));
        let count = |c: RGBColor| rgb.chunks(3).filter(|p| p == &[c.0, c.1, c.2]).count();
        // Four panels of one red, one blue and one grey column, each a
        // sizeable area (the bar holds the end colours only in a sliver).
        let (red, blue, grey) = (count(diverging(1.0)), count(diverging(-1.0)), count(NO_DATA));
        assert!(red > 4 * 5000 && blue > 4 * 5000 && grey > 4 * 5000, "{red} {blue} {grey}");
        assert!((red as f64 / blue as f64 - 1.0).abs() < 0.1, "{red} {blue}");
    }

    #[test]
    fn long_titles_wrap_to_the_figure_and_every_character_stays() {
        let title = "/work/shared/rig-dev/a_rather_long_dataset_name_that_goes_on_and_on: excess gap of the \
                     calibrated nominal model (d beyond noise and tolerance; white: none)";
        for max in [12, 30, 64] {
            let lines = wrap_words(title, max);
            assert!(lines.len() > 1);
            assert!(lines.iter().all(|l| l.chars().count() <= max), "{max}: {lines:?}");
            let joined: String = lines.concat().chars().filter(|c| !c.is_whitespace()).collect();
            let expected: String = title.chars().filter(|c| !c.is_whitespace()).collect();
            assert_eq!(joined, expected);
        }
        assert_eq!(wrap_words("short title", 64), ["short title"]);
        assert_eq!(wrap_words("", 64), [""]);
        // One panel's figure holds the report's title on a few lines.
        let w = 40 + PANEL_W_PX + BAR_W_PX;
        assert!(wrap_words(title, title_chars_per_line(w)).len() <= 4);
    }

    #[test]
    fn the_automatic_scale_is_the_largest_magnitude() {
        let mut m = map(1);
        m.limit = None;
        m.panels[0].values = vec![vec![Some(0.2); 4], vec![Some(-0.05); 4], vec![None; 4]];
        assert_eq!(check_heat_map(&m).unwrap(), 0.2);
        m.panels[0].values = vec![vec![Some(0.0); 4], vec![Some(0.0); 4], vec![None; 4]];
        assert_eq!(check_heat_map(&m).unwrap(), 1.0);
    }

    #[test]
    fn bad_heat_maps_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("heat.png");
        let mut m = map(1);
        m.panels[0].values[1].pop();
        assert!(matches!(heat_map_plot(&path, &m), Err(PlotError::SpectrogramShape { .. })));
        let mut m = map(1);
        m.panels[0].values[0][2] = Some(f64::NAN);
        assert!(matches!(
            heat_map_plot(&path, &m),
            Err(PlotError::SpectrogramValue { time_index: 0, frequency_index: 2, .. })
        ));
        let mut m = map(1);
        m.limit = Some(0.0);
        assert!(matches!(heat_map_plot(&path, &m), Err(PlotError::InvalidDbRange { .. })));
        assert!(matches!(heat_map_plot(&path, &map(0)), Err(PlotError::NoSeries)));
        assert!(!path.exists());
    }
}
