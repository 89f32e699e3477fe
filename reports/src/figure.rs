//! A small figure description (panels of marker/line series on linear or log
//! axes, one legend) and its renderer to SVG and PNG through plotters.
//!
//! Log axes are drawn by plotting `log10(v)` on a linear axis whose ticks are
//! chosen here (decades, then 2x/5x, then every integer multiple when the range
//! is narrow) and labelled with the original value (`1e-3`, `2e-3`), so labels
//! never lie about the tick position and every plot shares one code path.

use std::path::{Path, PathBuf};
use std::sync::Once;

use std::ops::Range;

use plotters::coord::Shift;
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};
use plotters::element::DynElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::ReportError;
use crate::format::{fmt_linear_tick, fmt_plain, fmt_tick};

/// Font family name the embedded DejaVu Sans is registered under.
const FONT: &str = "sans-serif";

/// Registers the embedded DejaVu Sans (regular and bold) with plotters, once.
pub(crate) fn register_fonts() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The bytes are a valid TTF shipped by the `dejavu` crate; if plotters
        // ever refused them, text would fail to draw and `render` reports a
        // plot error naming the file, so the result can be ignored here.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
        let _ = plotters::style::register_font(FONT, FontStyle::Bold, dejavu::sans::bold());
    });
}

/// Marker shapes, cycled per model so plots stay readable in grey scale.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Marker {
    Circle,
    Square,
    TriangleUp,
    Diamond,
    TriangleDown,
    Cross,
    Plus,
}

impl Marker {
    pub(crate) const ALL: [Marker; 7] = [
        Marker::Circle,
        Marker::Square,
        Marker::TriangleUp,
        Marker::Diamond,
        Marker::TriangleDown,
        Marker::Cross,
        Marker::Plus,
    ];
}

/// Okabe & Ito colour-blind safe palette (blue, vermillion, green, purple,
/// orange, sky blue, black).
pub(crate) const PALETTE: [RGBColor; 7] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(0, 0, 0),
];

/// Status colours of the stability map.
pub(crate) const OK_GREEN: RGBColor = RGBColor(0, 150, 60);
/// Unstable runs.
pub(crate) const BAD_RED: RGBColor = RGBColor(215, 25, 28);
/// Failed / timed-out runs.
pub(crate) const FAIL_GREY: RGBColor = RGBColor(130, 130, 130);

/// Line drawing style of a series.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Line {
    None,
    Solid,
    Dashed,
}

/// How a series looks (shared by the plot and its legend entry).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Look {
    pub color: RGBColor,
    pub marker: Option<Marker>,
    pub line: Line,
}

/// One series: markers at `points`, and a line through `line_points` (if any).
#[derive(Debug, Clone)]
pub(crate) struct SeriesSpec {
    pub look: Look,
    /// Points drawn as markers.
    pub points: Vec<(f64, f64)>,
    /// Points joined by a line (may differ from `points`, e.g. a Pareto front).
    pub line_points: Vec<(f64, f64)>,
}

/// An axis: its label (with unit), linear or log, and integer labels for counts.
#[derive(Debug, Clone)]
pub(crate) struct Axis {
    pub label: String,
    pub log: bool,
    /// Label ticks as plain numbers (`10`, `20`) rather than `1e1`.
    pub plain: bool,
    /// Fixed tick positions (data units); `None` = automatic.
    pub ticks: Option<Vec<f64>>,
}

impl Axis {
    pub(crate) fn log(label: impl Into<String>) -> Self {
        Axis {
            label: label.into(),
            log: true,
            plain: false,
            ticks: None,
        }
    }
    pub(crate) fn linear(label: impl Into<String>) -> Self {
        Axis {
            label: label.into(),
            log: false,
            plain: true,
            ticks: None,
        }
    }
    fn tr(&self, v: f64) -> f64 {
        if self.log { v.log10() } else { v }
    }
    fn usable(&self, v: f64) -> bool {
        v.is_finite() && (!self.log || v > 0.0)
    }
}

/// One chart: title, axes, series.
#[derive(Debug, Clone)]
pub(crate) struct Panel {
    pub title: String,
    pub x: Axis,
    pub y: Axis,
    pub series: Vec<SeriesSpec>,
}

/// A legend line.
#[derive(Debug, Clone)]
pub(crate) struct LegendEntry {
    pub look: Look,
    pub label: String,
}

/// A whole picture: a title, panels laid out in a grid, a legend on the right.
#[derive(Debug, Clone)]
pub(crate) struct Figure {
    pub title: String,
    pub panels: Vec<Panel>,
    pub legend: Vec<LegendEntry>,
    pub size: (u32, u32),
}

/// Pixel sizes chosen for a 1000+ px wide PNG read at 100 %: labels >= 18 px.
const TITLE_PX: f64 = 26.0;
const PANEL_TITLE_PX: f64 = 22.0;
const DESC_PX: f64 = 21.0;
const TICK_PX: f64 = 18.0;
const LEGEND_PX: f64 = 18.0;
const LEGEND_W: u32 = 330;
const MARKER_R: i32 = 7;

/// Writes `fig` to `<dir>/<stem>.svg` and `<dir>/<stem>.png`; returns both paths.
pub(crate) fn save(fig: &Figure, dir: &Path, stem: &str) -> Result<Vec<PathBuf>, ReportError> {
    register_fonts();
    let svg = dir.join(format!("{stem}.svg"));
    let png = dir.join(format!("{stem}.png"));
    let size = fitted_size(fig);
    {
        let root = SVGBackend::new(&svg, size).into_drawing_area();
        draw(fig, &root).map_err(|m| ReportError::plot(&svg, m))?;
        root.present().map_err(|e| ReportError::plot(&svg, e))?;
    }
    {
        let root = BitMapBackend::new(&png, size).into_drawing_area();
        draw(fig, &root).map_err(|m| ReportError::plot(&png, m))?;
        root.present().map_err(|e| ReportError::plot(&png, e))?;
    }
    Ok(vec![svg, png])
}

fn font(px: f64) -> TextStyle<'static> {
    (FONT, px).into_font().color(&BLACK)
}

fn draw<DB: DrawingBackend>(fig: &Figure, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let body = draw_title(root, &fig.title)?;
    let (w, _) = body.dim_in_pixel();
    let (plots, legend) = body.split_horizontally(w.saturating_sub(LEGEND_W));
    draw_legend(&legend, &fig.legend)?;
    let n = fig.panels.len().max(1);
    let cols = if n <= 1 { 1 } else { 2 };
    let rows = n.div_ceil(cols);
    let areas = plots.split_evenly((rows, cols));
    for (panel, area) in fig.panels.iter().zip(areas.iter()) {
        draw_panel(panel, area)?;
    }
    Ok(())
}

/// Draws `title` centred at the top, shrinking the font (down to 18 px) and
/// then wrapping so long scenario names stay inside the picture; returns the
/// area below it.
fn draw_title<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
) -> Result<DrawingArea<DB, Shift>, String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let (w, _) = root.dim_in_pixel();
    let (px, lines, used) = title_layout(w, title);
    let style = (FONT, px, FontStyle::Bold)
        .into_font()
        .color(&BLACK)
        .pos(Pos::new(HPos::Center, VPos::Top));
    let line_h = (px * 1.25) as i32;
    for (k, l) in lines.iter().enumerate() {
        root.draw(&Text::new(
            l.clone(),
            (w as i32 / 2, 10 + k as i32 * line_h),
            style.clone(),
        ))
        .map_err(e)?;
    }
    Ok(root.split_vertically(used).1)
}

/// The title's font size (px), its lines at picture width `w`, and the
/// height it takes (px).
fn title_layout(w: u32, title: &str) -> (f64, Vec<String>, i32) {
    // DejaVu Sans Bold averages about 0.65 em per character.
    let chars = title.chars().count().max(1) as f64;
    let px = (f64::from(w) * 0.95 / (0.65 * chars)).clamp(18.0, TITLE_PX);
    let per_line = ((f64::from(w) * 0.95) / (0.65 * px)).floor().max(10.0) as usize;
    let lines = wrap(title, per_line);
    let used = 10 + (px * 1.25) as i32 * lines.len() as i32 + 14;
    (px, lines, used)
}

/// Characters per legend line (26 at 18 px fit the 330 px legend column).
const LEGEND_CHARS: usize = 26;
const LEGEND_TOP: i32 = 40;
const LEGEND_GAP: i32 = 12;

fn legend_line_h() -> i32 {
    (LEGEND_PX * 1.3) as i32
}

/// The height (px) the legend of `entries` needs, from its first line to
/// below its last.
fn legend_height(entries: &[LegendEntry]) -> i32 {
    LEGEND_TOP
        + entries
            .iter()
            .map(|ent| legend_line_h() * wrap(&ent.label, LEGEND_CHARS).len().max(1) as i32 + LEGEND_GAP)
            .sum::<i32>()
}

/// `fig`'s size, taller when its title and legend need more height than it
/// has: a long legend grows the picture instead of running off its bottom.
pub(crate) fn fitted_size(fig: &Figure) -> (u32, u32) {
    let (w, h) = fig.size;
    let need = title_layout(w, &fig.title).2 + legend_height(&fig.legend);
    (w, h.max(u32::try_from(need).unwrap_or(h)))
}

/// Data range of the transformed values on one axis, padded so markers are not
/// cut at the frame. Log axes pad by a factor, linear by a fraction.
fn range(axis: &Axis, vals: &[f64]) -> (f64, f64) {
    let t: Vec<f64> = vals.iter().filter(|v| axis.usable(**v)).map(|v| axis.tr(*v)).collect();
    let (mut lo, mut hi) = t
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(*v), b.max(*v)));
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-12 {
        // A single value: one third of a decade either side (log), or +-10 % (linear).
        let half = if axis.log { 0.5 } else { (lo.abs() * 0.1).max(1e-12) };
        lo -= half;
        hi += half;
    } else {
        let pad = (hi - lo) * 0.06;
        lo -= pad;
        hi += pad;
    }
    (lo, hi)
}

/// Tick positions (transformed units) for an axis spanning `lo..hi` (transformed).
fn ticks(axis: &Axis, lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    if let Some(t) = &axis.ticks {
        let bold: Vec<f64> = t
            .iter()
            .filter(|v| axis.usable(**v))
            .map(|v| axis.tr(*v))
            .filter(|v| *v >= lo && *v <= hi)
            .collect();
        return (bold, vec![]);
    }
    if axis.log {
        let (bold, light) = crate::format::log_ticks(10f64.powf(lo), 10f64.powf(hi));
        (
            bold.iter().map(|v| v.log10()).collect(),
            light.iter().map(|v| v.log10()).collect(),
        )
    } else {
        (crate::format::linear_ticks(lo, hi), vec![])
    }
}

/// The x and y scales of a panel: ranges and tick lines fitted to its points.
fn scales(p: &Panel) -> (Scale, Scale) {
    let coord = |f: fn(&(f64, f64)) -> f64| -> Vec<f64> {
        p.series
            .iter()
            .flat_map(|s| s.points.iter().chain(s.line_points.iter()).map(f))
            .collect()
    };
    let scale = |axis: &Axis, vs: &[f64]| {
        let (lo, hi) = range(axis, vs);
        let (bold, light) = ticks(axis, lo, hi);
        Scale { lo, hi, bold, light }
    };
    (scale(&p.x, &coord(|q| q.0)), scale(&p.y, &coord(|q| q.1)))
}

/// Draw one panel: axes, grid, lines and markers.
fn draw_panel<DB: DrawingBackend>(p: &Panel, area: &DrawingArea<DB, Shift>) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let (xs, ys) = scales(p);
    let (x_step, y_step) = (xs.tick_step(), ys.tick_step());
    let mut builder = ChartBuilder::on(area);
    if !p.title.is_empty() {
        builder.caption(&p.title, font(PANEL_TITLE_PX));
    }
    let mut chart = builder
        .margin(12)
        .x_label_area_size(60)
        .y_label_area_size(90)
        .build_cartesian_2d(xs, ys)
        .map_err(e)?;
    let xa = p.x.clone();
    let ya = p.y.clone();
    let xf = move |v: &f64| label(&xa, *v, x_step);
    let yf = move |v: &f64| label(&ya, *v, y_step);
    chart
        .configure_mesh()
        .x_desc(p.x.label.as_str())
        .y_desc(p.y.label.as_str())
        .axis_desc_style(font(DESC_PX))
        .label_style(font(TICK_PX))
        .x_label_formatter(&xf)
        .y_label_formatter(&yf)
        .bold_line_style(RGBColor(200, 200, 200))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(e)?;
    for s in &p.series {
        let line: Vec<(f64, f64)> = s
            .line_points
            .iter()
            .filter(|q| p.x.usable(q.0) && p.y.usable(q.1))
            .map(|q| (p.x.tr(q.0), p.y.tr(q.1)))
            .collect();
        let style = ShapeStyle::from(&s.look.color).stroke_width(2);
        match s.look.line {
            Line::Solid if line.len() > 1 => {
                chart.draw_series(LineSeries::new(line, style)).map_err(e)?;
            }
            Line::Dashed if line.len() > 1 => {
                chart
                    .draw_series(DashedLineSeries::new(line, 10, 6, style))
                    .map_err(e)?;
            }
            _ => {}
        }
        if let Some(m) = s.look.marker {
            let pts: Vec<(f64, f64)> = s
                .points
                .iter()
                .filter(|q| p.x.usable(q.0) && p.y.usable(q.1))
                .map(|q| (p.x.tr(q.0), p.y.tr(q.1)))
                .collect();
            // Markers are drawn in pixel coordinates on the panel's area.
            let (bx, by) = area.get_base_pixel();
            for c in pts {
                let (px, py) = chart.backend_coord(&c);
                area.draw(&marker(m, (px - bx, py - by), s.look.color)).map_err(e)?;
            }
        }
    }
    Ok(())
}

/// A linear axis over `lo..hi` (already log10-transformed for log axes) whose
/// tick positions are given: plotters' own log ticks are unreadable on narrow ranges.
struct Scale {
    lo: f64,
    hi: f64,
    bold: Vec<f64>,
    light: Vec<f64>,
}

impl Scale {
    /// Spacing of the bold ticks (transformed units), when there are two.
    fn tick_step(&self) -> Option<f64> {
        match self.bold.as_slice() {
            [a, b, ..] => Some(b - a),
            _ => None,
        }
    }
}

impl Ranged for Scale {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, v: &f64, limit: (i32, i32)) -> i32 {
        let f = (v - self.lo) / (self.hi - self.lo);
        limit.0 + (f * f64::from(limit.1 - limit.0)).round() as i32
    }

    fn key_points<H: KeyPointHint>(&self, hint: H) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            self.light.clone()
        } else {
            self.bold.clone()
        }
    }

    fn range(&self) -> Range<f64> {
        self.lo..self.hi
    }
}

fn label(axis: &Axis, v: f64, step: Option<f64>) -> String {
    let raw = if axis.log { 10f64.powf(v) } else { v };
    match (axis.plain, axis.log, step) {
        (true, false, Some(step)) => fmt_linear_tick(raw, step),
        (true, _, _) => fmt_plain(raw),
        _ => fmt_tick(raw),
    }
}

/// A marker of shape `m` centred on `c` (any coordinate type), radius [`MARKER_R`] px.
fn marker<'a, DB: DrawingBackend + 'a, C: Clone + 'a>(m: Marker, c: C, color: RGBColor) -> DynElement<'a, DB, C> {
    let r = MARKER_R;
    let fill = ShapeStyle::from(&color).filled();
    let outline = ShapeStyle::from(&WHITE).stroke_width(1);
    let stroke = ShapeStyle::from(&color).stroke_width(3);
    // A filled polygon with a thin white outline, so overlapping markers stay apart.
    let poly = |pts: Vec<(i32, i32)>| {
        let mut closed = pts.clone();
        closed.push(pts[0]);
        (EmptyElement::at(c.clone()) + Polygon::new(pts, fill) + PathElement::new(closed, outline)).into_dyn()
    };
    match m {
        Marker::Circle => {
            (EmptyElement::at(c.clone()) + Circle::new((0, 0), r, fill) + Circle::new((0, 0), r, outline)).into_dyn()
        }
        Marker::Square => {
            let s = r - 1;
            poly(vec![(-s, -s), (s, -s), (s, s), (-s, s)])
        }
        Marker::TriangleUp => poly(vec![(0, -r - 1), (r + 1, r), (-r - 1, r)]),
        Marker::TriangleDown => poly(vec![(0, r + 1), (r + 1, -r), (-r - 1, -r)]),
        Marker::Diamond => {
            let s = r + 1;
            poly(vec![(0, -s), (s, 0), (0, s), (-s, 0)])
        }
        Marker::Cross => (EmptyElement::at(c.clone())
            + PathElement::new(vec![(-r, -r), (r, r)], stroke)
            + PathElement::new(vec![(-r, r), (r, -r)], stroke))
        .into_dyn(),
        Marker::Plus => (EmptyElement::at(c)
            + PathElement::new(vec![(-r, 0), (r, 0)], stroke)
            + PathElement::new(vec![(0, -r), (0, r)], stroke))
        .into_dyn(),
    }
}

/// Splits `text` into lines of at most `width` characters, breaking at
/// spaces and after `;` (fidelity strings), and hard-breaking longer words.
pub(crate) fn wrap(text: &str, width: usize) -> Vec<String> {
    let width = width.max(1);
    // Tokens with "a space goes before me" flags.
    let mut tokens: Vec<(Vec<char>, bool)> = Vec::new();
    for (wi, word) in text.split_whitespace().enumerate() {
        for (pi, part) in word.split_inclusive(';').enumerate() {
            let chars: Vec<char> = part.chars().collect();
            for (ci, chunk) in chars.chunks(width).enumerate() {
                tokens.push((chunk.to_vec(), wi > 0 && pi == 0 && ci == 0));
            }
        }
    }
    let mut lines = Vec::new();
    let mut line: Vec<char> = Vec::new();
    for (tok, space) in tokens {
        let sep = usize::from(space && !line.is_empty());
        if !line.is_empty() && line.len() + sep + tok.len() > width {
            lines.push(line.drain(..).collect());
        } else if sep == 1 {
            line.push(' ');
        }
        line.extend(tok);
    }
    if !line.is_empty() {
        lines.push(line.into_iter().collect());
    }
    lines
}

fn draw_legend<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, entries: &[LegendEntry]) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let style = font(LEGEND_PX).pos(Pos::new(HPos::Left, VPos::Center));
    let line_h = legend_line_h();
    let mut y = LEGEND_TOP;
    let x_sym = 28;
    let x_text = 62;
    for ent in entries {
        let lines = wrap(&ent.label, LEGEND_CHARS);
        let ls = ShapeStyle::from(&ent.look.color).stroke_width(2);
        // Solid: one 44 px stroke; dashed: two 8 px dashes each side of the marker.
        match ent.look.line {
            Line::Solid => area
                .draw(&PathElement::new(vec![(x_sym - 22, y), (x_sym + 22, y)], ls))
                .map_err(e)?,
            Line::Dashed => {
                for (a, b) in [(-22, -16), (-12, -6), (6, 12), (16, 22)] {
                    area.draw(&PathElement::new(vec![(x_sym + a, y), (x_sym + b, y)], ls))
                        .map_err(e)?;
                }
            }
            Line::None => {}
        }
        if let Some(m) = ent.look.marker {
            area.draw(&marker::<DB, (i32, i32)>(m, (x_sym, y), ent.look.color))
                .map_err(e)?;
        }
        for (k, l) in lines.iter().enumerate() {
            area.draw(&Text::new(l.clone(), (x_text, y + k as i32 * line_h), style.clone()))
                .map_err(e)?;
        }
        y += line_h * lines.len().max(1) as i32 + LEGEND_GAP;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::wrap;

    #[test]
    fn wrap_breaks_at_spaces_semicolons_and_long_words() {
        assert_eq!(wrap("der (7 runs, 4 on front)", 12), ["der (7 runs,", "4 on front)"]);
        assert_eq!(
            wrap("der segments=80;dt=0.0005;iterations=10", 26),
            ["der segments=80;dt=0.0005;", "iterations=10"]
        );
        assert_eq!(wrap("abcdefghij", 4), ["abcd", "efgh", "ij"]);
        assert_eq!(wrap("a b", 10), ["a b"]);
        assert!(wrap("", 5).is_empty());
        for l in wrap("pbd-rod segments=80;dt=0.001 (p = 1.00, 4 points)", 10) {
            assert!(l.chars().count() <= 10, "line {l:?} longer than 10");
        }
    }
}
