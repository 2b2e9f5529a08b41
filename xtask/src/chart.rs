//! Pareto charts: error against wall time, one series per solver, drawn with `plotters`.
//!
//! The layout is computed before anything is drawn, from the labels' widths measured in the
//! embedded font (DejaVu Sans, so that a chart comes out the same on every machine):
//!
//! - the plot on the left, 640 px wide and at least 460 px tall (as tall as the legend);
//! - the legend in a column of its own on the right, grouped by family (transport,
//!   diffusion, explicit schemes, GPU twins, `auto`), as wide as its longest label and as
//!   tall as its rows: the canvas grows to hold it, so it is never cut;
//! - each series a distinct (colour, marker) pair: the marker says the family, the colour
//!   the solver (a GPU twin takes its CPU solver's colour where that pair is free);
//! - the error axis capped at 100 %: a run whose error is larger, or not finite, has
//!   diverged and is drawn in a grey band above the cap instead of stretching the axis;
//! - each series joined in order of time.
//!
//! [`Chart::svg`] is what `cargo xtask pareto` writes to `docs/pareto/<scene>.svg`;
//! `Chart::rgb` draws the same chart into pixels for the tests below, which read them back.

use std::collections::BTreeMap;
use std::sync::OnceLock;

use lucent::pareto::{AutoPoint, Point};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;

/// Errors above this (100 %) are divergence: the answer is worth nothing.
pub(crate) const ERROR_CAP: f64 = 1.0;
/// Where a diverged run is drawn: inside the band above the cap.
const DIVERGED_AT: f64 = 1.778_279_410_038_923; // 10^0.25
/// The top of the band.
const BAND_TOP: f64 = 3.162_277_660_168_379_5; // 10^0.5
/// The plot's size, the legend's font size, row heights and padding, in pixels.
const PLOT: (u32, u32) = (640, 460);
const LEGEND_FONT: f64 = 13.0;
const ENTRY_ROW: i32 = 20;
const HEADING_ROW: i32 = 24;
const LEGEND_TOP: i32 = 44;
const PAD: i32 = 14;
const SWATCH: i32 = 34;

/// The ten colours of matplotlib's `tab10`, chosen to be told apart, and black, kept for
/// `auto`.
pub(crate) const PALETTE: [RGBColor; 11] = [
    RGBColor(0x1f, 0x77, 0xb4),
    RGBColor(0xff, 0x7f, 0x0e),
    RGBColor(0x2c, 0xa0, 0x2c),
    RGBColor(0xd6, 0x27, 0x28),
    RGBColor(0x94, 0x67, 0xbd),
    RGBColor(0x8c, 0x56, 0x4b),
    RGBColor(0xe3, 0x77, 0xc2),
    RGBColor(0x7f, 0x7f, 0x7f),
    RGBColor(0xbc, 0xbd, 0x22),
    RGBColor(0x17, 0xbe, 0xcf),
    RGBColor(0x00, 0x00, 0x00),
];
/// The colours given out in turn (black is `auto`'s).
const COLOURS: usize = 10;
const AUTO_COLOUR: usize = 10;

/// A marker shape.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub(crate) enum Marker {
    Circle,
    Square,
    Diamond,
    Triangle,
    Cross,
}

const MARKERS: [Marker; 5] = [
    Marker::Circle,
    Marker::Square,
    Marker::Diamond,
    Marker::Triangle,
    Marker::Cross,
];

/// How a series is drawn: a colour of [`PALETTE`], a marker, filled or hollow.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub(crate) struct Style {
    pub colour: usize,
    pub marker: Marker,
    pub filled: bool,
}

/// The legend's groups, in its order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub(crate) enum Family {
    Transport,
    Diffusion,
    Explicit,
    Gpu,
    Auto,
}

impl Family {
    /// The family of a series named after its solver.
    pub(crate) fn of(name: &str) -> Self {
        let solver = name.split_whitespace().next().unwrap_or(name);
        match solver {
            "auto" => Self::Auto,
            s if s.starts_with("gpu-") => Self::Gpu,
            "direct" | "direct-refractive" | "mc" | "dom" | "hybrid" | "lbm" => Self::Transport,
            s if s.starts_with("diffusion-") || s == "fem-diffusion" => Self::Diffusion,
            _ => Self::Explicit,
        }
    }

    fn heading(self) -> &'static str {
        match self {
            Self::Transport => "transport",
            Self::Diffusion => "diffusion (implicit)",
            Self::Explicit => "explicit and Jacobi schemes",
            Self::Gpu => "GPU twins",
            Self::Auto => "auto",
        }
    }

    fn marker(self) -> Marker {
        match self {
            Self::Transport => Marker::Circle,
            Self::Diffusion => Marker::Square,
            Self::Explicit => Marker::Diamond,
            Self::Gpu => Marker::Triangle,
            Self::Auto => Marker::Cross,
        }
    }
}

/// One curve: a solver's runs.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Series {
    /// The run label ([`lucent::pareto::Run::label`]): a solver, with its distinguishing
    /// parameter where one solver has two curves.
    pub name: String,
    /// What the legend says.
    pub label: String,
    pub family: Family,
    pub style: Style,
    /// (seconds, relative L2 error), in order of time.
    pub points: Vec<(f64, f64)>,
}

/// A legend row.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Row {
    Heading(Family),
    /// The index of a series.
    Entry(usize),
}

/// Where everything goes, in pixels.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Layout {
    pub width: u32,
    pub height: u32,
    /// The legend column starts here.
    pub legend_x: i32,
    /// Each legend row and its vertical centre.
    pub rows: Vec<(Row, i32)>,
}

/// A chart of error against time.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Chart {
    pub title: String,
    pub series: Vec<Series>,
}

fn fonts() {
    static FONTS: OnceLock<()> = OnceLock::new();
    FONTS.get_or_init(|| {
        // Both are valid TrueType files compiled in: registering cannot fail.
        let regular = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            dejavu::sans::regular(),
        );
        let bold =
            plotters::style::register_font("sans-serif", FontStyle::Bold, dejavu::sans::bold());
        assert!(
            regular.is_ok() && bold.is_ok(),
            "DejaVu Sans is a valid font"
        );
    });
}

fn legend_font() -> TextStyle<'static> {
    // A font description looks its face up when made: register the fonts first.
    fonts();
    TextStyle::from(("sans-serif", LEGEND_FONT).into_font())
}

fn heading_font() -> TextStyle<'static> {
    fonts();
    TextStyle::from(("sans-serif", LEGEND_FONT, FontStyle::Bold).into_font())
}

/// Text anchored at its left end, centred vertically on the row.
fn middle_left() -> plotters::style::text_anchor::Pos {
    use plotters::style::text_anchor::{HPos, Pos, VPos};
    Pos::new(HPos::Left, VPos::Center)
}

fn text_width(text: &str, style: &TextStyle<'_>) -> i32 {
    let (width, _) = style
        .font
        .box_size(text)
        .unwrap_or_else(|e| panic!("the embedded font measures `{text}`: {e}"));
    width as i32
}

impl Chart {
    /// The chart of a sweep's points and `auto`'s runs (those made with the scene's own
    /// rows, or on a scene outside the suite), `auto` against the total fluence.
    pub(crate) fn new(title: &str, points: &[Point], autos: &[AutoPoint]) -> Self {
        let mut curves: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
        let mut add =
            |name: &str, seconds: f64, error: f64| match curves.iter_mut().find(|(n, _)| n == name)
            {
                Some((_, c)) => c.push((seconds, error)),
                None => curves.push((name.to_owned(), vec![(seconds, error)])),
            };
        for p in points {
            add(&p.solver, p.seconds, p.error);
        }
        for a in autos.iter().filter(|a| a.own_rows || a.held_out) {
            add("auto", a.seconds, a.error_total);
        }
        let mut series: Vec<Series> = curves
            .into_iter()
            .map(|(name, mut points)| {
                points.retain(|(s, _)| s.is_finite() && *s > 0.0);
                points.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
                let label = match name.as_str() {
                    "direct" | "direct-refractive" | "gpu-direct" => format!("{name} (uncollided)"),
                    "auto" => "auto (total error)".to_owned(),
                    _ => name.clone(),
                };
                Series {
                    family: Family::of(&name),
                    label,
                    name,
                    // Assigned below, once every series is known.
                    style: Style {
                        colour: 0,
                        marker: Marker::Circle,
                        filled: true,
                    },
                    points,
                }
            })
            .collect();
        series.sort_by_key(|s| s.family);
        assign_styles(&mut series);
        Self {
            title: title.to_owned(),
            series,
        }
    }

    /// The canvas and legend layout: the legend column as wide as its widest row, the
    /// canvas as tall as the plot or the legend, whichever is taller.
    pub(crate) fn layout(&self) -> Layout {
        let entry = legend_font();
        let heading = heading_font();
        let mut rows = Vec::new();
        let mut y = LEGEND_TOP;
        let mut widest = 0;
        let mut family = None;
        for (i, s) in self.series.iter().enumerate() {
            if family != Some(s.family) {
                family = Some(s.family);
                y += if rows.is_empty() { 0 } else { 6 };
                rows.push((Row::Heading(s.family), y + HEADING_ROW / 2));
                widest = widest.max(text_width(s.family.heading(), &heading) - SWATCH - 6);
                y += HEADING_ROW;
            }
            rows.push((Row::Entry(i), y + ENTRY_ROW / 2));
            widest = widest.max(text_width(&s.label, &entry));
            y += ENTRY_ROW;
        }
        let legend_x = PLOT.0 as i32;
        Layout {
            width: (legend_x + PAD + SWATCH + 6 + widest + PAD) as u32,
            height: PLOT.1.max((y + PAD) as u32),
            legend_x,
            rows,
        }
    }

    /// The error axis: from the decade below the least error to the decade above the
    /// largest one at most 100 %, and the diverged band above it when a run diverged.
    fn error_range(&self) -> (f64, f64) {
        let errors = self
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.1));
        let kept: Vec<f64> = errors
            .clone()
            .filter(|e| *e > 0.0 && *e <= ERROR_CAP)
            .collect();
        let low = kept.iter().copied().fold(f64::INFINITY, f64::min);
        let high = kept.iter().copied().fold(0.0, f64::max);
        let low = if low.is_finite() {
            decade_below(low).max(1e-8)
        } else {
            1e-3
        };
        let top = if errors.clone().any(diverged) {
            BAND_TOP
        } else {
            decade_above(high).max(low * 10.0)
        };
        (low, top)
    }

    fn time_range(&self) -> (f64, f64) {
        let times = self
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.0));
        let low = times.clone().fold(f64::INFINITY, f64::min);
        let high = times.fold(0.0, f64::max);
        if !low.is_finite() {
            return (1e-3, 1.0);
        }
        let low = decade_below(low);
        (low, decade_above(high).max(low * 10.0))
    }

    /// Draws the chart onto `root`, which must be [`Chart::layout`]'s size.
    pub(crate) fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), String> {
        fonts();
        let layout = self.layout();
        let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
        root.fill(&WHITE).map_err(err)?;
        // The plot takes the canvas's height: as tall as the legend where that is taller.
        let (plot, _) = root.split_horizontally(layout.legend_x);
        let (t0, t1) = self.time_range();
        let (e0, e1) = self.error_range();
        let mut chart = ChartBuilder::on(&plot)
            .caption(&self.title, ("sans-serif", 16.0))
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(64)
            .build_cartesian_2d((t0..t1).log_scale(), (e0..e1).log_scale())
            .map_err(err)?;
        let seconds = |v: &f64| decimal(*v, "");
        let percent = |v: &f64| {
            if *v > ERROR_CAP * 1.0001 {
                String::new()
            } else {
                decimal(100.0 * v, " %")
            }
        };
        chart
            .configure_mesh()
            .x_desc("wall time (s)")
            .y_desc("relative L2 error")
            .x_label_formatter(&seconds)
            .y_label_formatter(&percent)
            .label_style(("sans-serif", 12.0))
            .axis_desc_style(("sans-serif", 13.0))
            .draw()
            .map_err(err)?;
        if e1 > ERROR_CAP {
            chart
                .draw_series([Rectangle::new(
                    [(t0, ERROR_CAP), (t1, e1)],
                    RGBColor(0xee, 0xee, 0xee).filled(),
                )])
                .map_err(err)?;
            let (x, y) = chart.backend_coord(&(t0, e1));
            root.draw(&Text::new(
                "diverged (error > 100 % or not finite)",
                (x + 6, y + 4),
                ("sans-serif", 12.0).into_font().color(&BLACK.mix(0.7)),
            ))
            .map_err(err)?;
        }
        let at = |p: &(f64, f64)| (p.0, if diverged(p.1) { DIVERGED_AT } else { p.1 });
        for s in &self.series {
            let colour = PALETTE[s.style.colour];
            chart
                .draw_series(LineSeries::new(
                    s.points.iter().map(at),
                    colour.mix(0.8).stroke_width(2),
                ))
                .map_err(err)?;
            for p in &s.points {
                draw_marker(root, chart.backend_coord(&at(p)), s.style).map_err(err)?;
            }
        }
        // The legend, in its own column.
        for (row, y) in &layout.rows {
            let x = layout.legend_x + PAD;
            match row {
                Row::Heading(family) => root
                    .draw(&Text::new(
                        family.heading(),
                        (x, *y),
                        heading_font().color(&BLACK).pos(middle_left()),
                    ))
                    .map_err(err)?,
                Row::Entry(i) => {
                    let s = &self.series[*i];
                    let colour = PALETTE[s.style.colour];
                    root.draw(&PathElement::new(
                        [(x, *y), (x + SWATCH, *y)],
                        colour.mix(0.8).stroke_width(2),
                    ))
                    .map_err(err)?;
                    draw_marker(root, (x + SWATCH / 2, *y), s.style).map_err(err)?;
                    root.draw(&Text::new(
                        s.label.as_str(),
                        (x + SWATCH + 6, *y),
                        legend_font().color(&BLACK).pos(middle_left()),
                    ))
                    .map_err(err)?;
                }
            }
        }
        root.present().map_err(err)
    }

    /// The chart as SVG.
    pub(crate) fn svg(&self) -> Result<String, String> {
        let layout = self.layout();
        let mut out = String::new();
        {
            let root = SVGBackend::with_string(&mut out, (layout.width, layout.height))
                .into_drawing_area();
            self.draw(&root)?;
        }
        Ok(out)
    }

    /// The chart as RGB pixels, row by row: (width, height, pixels).
    #[cfg(test)]
    pub(crate) fn rgb(&self) -> Result<(u32, u32, Vec<u8>), String> {
        let layout = self.layout();
        let mut pixels = vec![0u8; (layout.width * layout.height * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut pixels, (layout.width, layout.height))
                .into_drawing_area();
            self.draw(&root)?;
        }
        Ok((layout.width, layout.height, pixels))
    }
}

fn diverged(error: f64) -> bool {
    error.is_nan() || error > ERROR_CAP
}

fn decade_below(v: f64) -> f64 {
    10f64.powf(v.log10().floor())
}

fn decade_above(v: f64) -> f64 {
    10f64.powf(v.log10().ceil())
}

/// `v` with as many decimals as its leading digit needs, and `unit`.
fn decimal(v: f64, unit: &str) -> String {
    let decimals = (-v.log10().floor()).max(0.0) as usize;
    format!("{v:.decimals$}{unit}")
}

/// Gives every series its family's marker and the first colour that no series of the
/// same marker has; a GPU twin asks first for its CPU solver's colour, `auto` for black. When a marker runs
/// out of colours the next marker is used, then the hollow ones: no two series ever share
/// colour and marker.
fn assign_styles(series: &mut [Series]) {
    let mut taken: Vec<Style> = Vec::new();
    let mut colour_of: BTreeMap<String, usize> = BTreeMap::new();
    for s in series.iter_mut() {
        let preferred = if s.family == Family::Auto {
            Some(AUTO_COLOUR)
        } else {
            s.name
                .strip_prefix("gpu-")
                .and_then(|cpu| colour_of.get(cpu).copied())
        };
        let first = MARKERS
            .iter()
            .position(|m| *m == s.family.marker())
            .unwrap_or(0);
        let candidates = [true, false].into_iter().flat_map(|filled| {
            (0..MARKERS.len()).flat_map(move |k| {
                let marker = MARKERS[(first + k) % MARKERS.len()];
                preferred
                    .into_iter()
                    .chain(0..COLOURS)
                    .map(move |colour| Style {
                        colour,
                        marker,
                        filled,
                    })
            })
        });
        let style = candidates
            .into_iter()
            .find(|c| !taken.contains(c))
            .expect("5 markers × 10 colours × 2 fills hold every solver");
        taken.push(style);
        colour_of.insert(s.name.clone(), style.colour);
        s.style = style;
    }
}

fn draw_marker<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    (x, y): (i32, i32),
    style: Style,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let colour = PALETTE[style.colour];
    let paint = if style.filled {
        colour.filled()
    } else {
        colour.stroke_width(2)
    };
    let outline = |points: Vec<(i32, i32)>| -> Vec<(i32, i32)> {
        points.iter().map(|(dx, dy)| (x + dx, y + dy)).collect()
    };
    let closed = |points: Vec<(i32, i32)>| {
        let mut p = outline(points);
        p.push(p[0]);
        p
    };
    match (style.marker, style.filled) {
        (Marker::Circle, _) => area.draw(&Circle::new((x, y), 5, paint)),
        (Marker::Square, _) => area.draw(&Rectangle::new([(x - 4, y - 4), (x + 4, y + 4)], paint)),
        (Marker::Diamond, true) => area.draw(&Polygon::new(
            outline(vec![(0, -6), (6, 0), (0, 6), (-6, 0)]),
            paint,
        )),
        (Marker::Diamond, false) => area.draw(&PathElement::new(
            closed(vec![(0, -6), (6, 0), (0, 6), (-6, 0)]),
            paint,
        )),
        (Marker::Triangle, true) => area.draw(&Polygon::new(
            outline(vec![(0, -6), (6, 5), (-6, 5)]),
            paint,
        )),
        (Marker::Triangle, false) => area.draw(&PathElement::new(
            closed(vec![(0, -6), (6, 5), (-6, 5)]),
            paint,
        )),
        (Marker::Cross, _) => {
            let stroke = colour.stroke_width(if style.filled { 3 } else { 1 });
            area.draw(&PathElement::new(outline(vec![(-5, -5), (5, 5)]), stroke))?;
            area.draw(&PathElement::new(outline(vec![(-5, 5), (5, -5)]), stroke))
        }
    }
}

/// The chart of `docs/pareto/<scene>.csv` with `auto`'s runs on it, as `cargo xtask
/// pareto` draws it.
pub(crate) fn title(scene: &str) -> String {
    format!("{scene}: error against time (dev machine)")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn pareto_dir() -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/pareto")
    }

    /// Every chart of `docs/pareto/`, rebuilt from its CSV and `auto`'s runs.
    fn charts() -> Vec<(String, Chart)> {
        let dir = pareto_dir();
        let runs = std::fs::read_to_string(dir.join("auto_runs.csv")).unwrap();
        let autos = lucent::pareto::parse_auto_csv(&runs).unwrap();
        let mut charts = Vec::new();
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            let stem = path.file_stem().unwrap().to_string_lossy().into_owned();
            if path.extension().is_none_or(|e| e != "csv") || stem.starts_with("auto") {
                continue;
            }
            let points = lucent::pareto::parse_csv(&std::fs::read_to_string(&path).unwrap())
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let scene_autos: Vec<AutoPoint> =
                autos.iter().filter(|a| a.scene == stem).cloned().collect();
            charts.push((
                stem.clone(),
                Chart::new(&title(&stem), &points, &scene_autos),
            ));
        }
        charts.sort_by(|a, b| a.0.cmp(&b.0));
        assert!(charts.len() >= 10, "{} charts in docs/pareto", charts.len());
        charts
    }

    /// Every chart in `docs/pareto/`, drawn to pixels (and to PNGs in `target/pareto-png/`,
    /// for a person to look at): the legend column holds exactly one band
    /// of ink per row, none touching the canvas's edges (a legend running off the canvas
    /// loses its last rows, or touches the edge); no two series share colour and marker;
    /// each series is drawn in its colour; and the SVG in `docs/pareto/` is the one the
    /// CSV gives (a chart is never edited by hand or left stale).
    #[test]
    fn every_pareto_chart_fits_its_legend_and_tells_its_series_apart() {
        let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/pareto-png");
        std::fs::create_dir_all(&out).unwrap();
        for (scene, chart) in charts() {
            let layout = chart.layout();
            let (w, h, pixels) = chart.rgb().unwrap();
            image::RgbImage::from_raw(w, h, pixels.clone())
                .unwrap()
                .save(out.join(format!("{scene}.png")))
                .unwrap();
            let ink = |x: u32, y: u32| {
                let i = ((y * w + x) * 3) as usize;
                pixels[i..i + 3].iter().any(|&c| c < 200)
            };
            // Bands of rows with ink in the legend column.
            let row_has_ink = |y: u32| (layout.legend_x as u32..w).any(|x| ink(x, y));
            let mut bands = Vec::new();
            let mut start = None;
            for y in 0..h {
                match (row_has_ink(y), start) {
                    (true, None) => start = Some(y),
                    (false, Some(s)) => {
                        bands.push((s, y));
                        start = None;
                    }
                    _ => {}
                }
            }
            assert!(
                start.is_none(),
                "{scene}: legend ink touches the bottom edge"
            );
            assert_eq!(
                bands.len(),
                layout.rows.len(),
                "{scene}: {} legend rows drawn, {} laid out",
                bands.len(),
                layout.rows.len()
            );
            for (band, (_, centre)) in bands.iter().zip(&layout.rows) {
                assert!(
                    band.0 as i32 <= *centre && *centre < band.1 as i32,
                    "{scene}: legend band {band:?} misses its row at {centre}"
                );
            }
            for edge in [0, 1, w - 2, w - 1] {
                assert!(
                    !(0..h).any(|y| ink(edge, y)),
                    "{scene}: ink at column {edge}"
                );
            }
            // Distinct styles, each series visible in its own colour in the plot.
            let styles: std::collections::BTreeSet<Style> =
                chart.series.iter().map(|s| s.style).collect();
            assert_eq!(styles.len(), chart.series.len(), "{scene}: shared styles");
            for (i, s) in chart.series.iter().enumerate() {
                let (_, y) = layout
                    .rows
                    .iter()
                    .find(|(r, _)| *r == Row::Entry(i))
                    .unwrap();
                let c = PALETTE[s.style.colour];
                let x = (layout.legend_x + PAD + SWATCH / 2) as u32;
                let near = (x - 6..x + 7).any(|x| {
                    (*y as u32 - 6..*y as u32 + 7).any(|y| {
                        let i = ((y * w + x) * 3) as usize;
                        pixels[i..i + 3] == [c.0, c.1, c.2]
                    })
                });
                assert!(near, "{scene}: {} has no marker of its colour", s.name);
            }
            let svg = std::fs::read_to_string(pareto_dir().join(format!("{scene}.svg")))
                .unwrap_or_default();
            let drawn = chart.svg().unwrap();
            if svg != drawn {
                std::fs::write(out.join(format!("{scene}.svg")), &drawn).unwrap();
            }
            assert!(
                svg == drawn,
                "{scene}.svg is not the chart of {scene}.csv (drawn: target/pareto-png/{scene}.svg): `cargo xtask pareto --redraw`"
            );
        }
    }

    /// The error axis stops at 100 %: a diverged run (larger, or not finite) is drawn in
    /// the band above it, however far it diverged; a chart without one has no band.
    #[test]
    fn divergence_is_a_band_not_a_stretched_axis() {
        let point = |solver: &str, seconds: f64, error: f64| Point {
            solver: solver.into(),
            setting: String::new(),
            seconds,
            error,
            error_total: error,
        };
        let calm = Chart::new(
            "calm",
            &[point("dom", 0.1, 0.02), point("dom", 1.0, 0.004)],
            &[],
        );
        assert_eq!(calm.error_range(), (1e-3, 0.1));
        let wild = Chart::new(
            "wild",
            &[
                point("dom", 0.1, 0.02),
                point("fem-p1-jacobi", 0.2, 1e7),
                point("fem-p1-jacobi", 0.3, f64::NAN),
            ],
            &[],
        );
        assert_eq!(wild.error_range(), (1e-2, BAND_TOP));
        assert!(wild.svg().unwrap().contains("diverged"));
        assert!(!calm.svg().unwrap().contains("diverged"));
        // Joined in order of time, whatever the order of the sweep.
        let swept = Chart::new(
            "swept",
            &[
                point("mc", 1.0, 0.01),
                point("mc", 0.1, 0.03),
                point("mc", 0.5, 0.02),
            ],
            &[],
        );
        let times: Vec<f64> = swept.series[0].points.iter().map(|p| p.0).collect();
        assert_eq!(times, [0.1, 0.5, 1.0]);
    }

    /// Styles stay distinct beyond the palette: 60 solvers of one family.
    #[test]
    fn styles_are_distinct_for_any_number_of_series() {
        let points: Vec<Point> = (0..60)
            .map(|i| Point {
                solver: if i % 3 == 0 {
                    format!("gpu-s{i}")
                } else {
                    format!("s{i}")
                },
                setting: String::new(),
                seconds: 1.0,
                error: 0.1,
                error_total: 0.1,
            })
            .collect();
        let chart = Chart::new("many", &points, &[]);
        let styles: std::collections::BTreeSet<Style> =
            chart.series.iter().map(|s| s.style).collect();
        assert_eq!(styles.len(), 60);
    }
}
