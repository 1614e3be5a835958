//! Charts of a run's history: `energy.png` and `momenta.png` (or `.svg`).
//!
//! The charts are robust against the data a failed or degenerate run produces: a single
//! record (drawn as markers), constant data and tiny variations around a large value (the
//! axis range is widened to at least [`REL_MIN_SPAN`] of the magnitude), values of very
//! small or very large magnitude (the axis is scaled by a power of ten that the axis label
//! names), and NaN/infinite values (skipped; lines are broken there).

use std::path::Path;
use std::sync::Once;

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::FontStyle;

use super::OutputError;
use crate::observe::record::StepRecord;

/// Size of `energy.png`.
const ENERGY_SIZE: (u32, u32) = (1000, 700);
/// Size of `momenta.png` (two stacked panels).
const MOMENTA_SIZE: (u32, u32) = (1000, 900);
/// The smallest y range drawn, relative to the largest magnitude on the axis.
pub const REL_MIN_SPAN: f64 = 1e-6;

/// Data of magnitude below this are charted as zero (see `Axis::new`).
const TINY_MAGNITUDE: f64 = 1e-290;

/// Family name of the embedded chart font (registered by [`ensure_font`]).
pub(crate) const FONT: &str = "sans-serif";
const TITLE_PX: u32 = 28;
const DESC_PX: u32 = 21;
const LABEL_PX: u32 = 18;
const LEGEND_PX: u32 = 18;
const N_LABELS: usize = 8;
/// Height of the legend row above each panel.
const LEGEND_ROW_PX: u32 = 34;

static FONT_ONCE: Once = Once::new();
static FONT_BYTES: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

/// Registers the embedded DejaVu Sans as the "sans-serif" family (once per process).
pub(crate) fn ensure_font() {
    FONT_ONCE.call_once(|| {
        if plotters::style::register_font(FONT, FontStyle::Normal, FONT_BYTES).is_err() {
            // The font is embedded at compile time; this cannot fail for a valid file.
            panic!("embedded DejaVuSans.ttf is not a valid font");
        }
    });
}

pub(super) const BLACK_ISH: RGBColor = RGBColor(20, 20, 20);
pub(super) const RED: RGBColor = RGBColor(214, 39, 40);
pub(super) const BLUE: RGBColor = RGBColor(31, 119, 180);
pub(super) const ORANGE: RGBColor = RGBColor(255, 127, 14);
pub(super) const GREEN: RGBColor = RGBColor(44, 160, 44);

/// One line of a chart: its legend label, colour and (t, value) samples, which may hold
/// non-finite values.
struct Series {
    label: String,
    color: RGBColor,
    width: u32,
    points: Vec<(f64, f64)>,
}

impl Series {
    fn new(
        label: &str,
        color: RGBColor,
        width: u32,
        records: &[StepRecord],
        f: impl Fn(&StepRecord) -> f64,
    ) -> Self {
        Self {
            label: label.to_string(),
            color,
            width,
            points: records.iter().map(|r| (r.t, f(r))).collect(),
        }
    }

    /// Maximal runs of consecutive finite samples.
    fn segments(&self) -> Vec<Vec<(f64, f64)>> {
        let mut out = Vec::new();
        let mut cur = Vec::new();
        for &(t, v) in &self.points {
            if t.is_finite() && v.is_finite() {
                cur.push((t, v));
            } else if !cur.is_empty() {
                out.push(std::mem::take(&mut cur));
            }
        }
        if !cur.is_empty() {
            out.push(cur);
        }
        out
    }
}

/// One chart panel: the quantity on the y axis and its lines.
struct Panel {
    /// Quantity name for the y-axis label, e.g. "energy".
    quantity: &'static str,
    /// Unit for the y-axis label, e.g. "J".
    unit: &'static str,
    series: Vec<Series>,
}

/// A chart axis: the drawn range (in scaled units), the power of ten the data are divided
/// by, and the decimals of the tick labels.
#[derive(Clone, Copy, Debug)]
struct Axis {
    lo: f64,
    hi: f64,
    exp: i32,
    decimals: usize,
}

impl Axis {
    /// An axis over the data range `[lo, hi]` (`None`: no finite data). `pad` is the
    /// fraction of the span added on either side.
    fn new(range: Option<(f64, f64)>, pad: f64) -> Self {
        let (mut lo, mut hi) = range.unwrap_or((-1.0, 1.0));
        // Data this small (subnormals included) are zero at any chart resolution, and
        // 10^-k or a relative span of them would overflow or underflow f64 (an axis
        // without extent: plotters' tick loop never ends). Chart them as zero.
        if lo.abs().max(hi.abs()) < TINY_MAGNITUDE {
            (lo, hi) = (0.0, 0.0);
        }
        let mag = lo.abs().max(hi.abs());
        let min_span = if mag > 0.0 { REL_MIN_SPAN * mag } else { 2.0 };
        if hi - lo < min_span {
            let c = 0.5 * (lo + hi);
            lo = c - 0.5 * min_span;
            hi = c + 0.5 * min_span;
        }
        let span = hi - lo;
        lo -= pad * span;
        hi += pad * span;
        if !(hi - lo).is_finite() {
            // Values near ±f64::MAX: drop the padding rather than overflow.
            (lo, hi) = range.unwrap_or((-1.0, 1.0));
        }
        let mag = lo.abs().max(hi.abs());
        let k = mag.log10().floor() as i32;
        let exp = if (-2..4).contains(&k) { 0 } else { k };
        let scale = pow10(-exp);
        let (lo, hi) = (lo * scale, hi * scale);
        if !(lo.is_finite() && hi.is_finite() && hi > lo) {
            // Never hand plotters an empty or non-finite range.
            return Self::new(None, pad);
        }
        let decimals = tick_decimals(lo, hi);
        Self {
            lo,
            hi,
            exp,
            decimals,
        }
    }

    fn scale(&self) -> f64 {
        pow10(-self.exp)
    }

    /// Axis description "quantity [unit]" or "quantity [10ⁿ unit]".
    fn desc(&self, quantity: &str, unit: &str) -> String {
        if self.exp == 0 {
            format!("{quantity} [{unit}]")
        } else {
            format!("{quantity} [10{} {unit}]", superscript(self.exp))
        }
    }

    fn format(&self, v: f64) -> String {
        // Tick positions carry round-off; never print "-0.00".
        let tiny = 0.5 * pow10(-(self.decimals as i32));
        let v = if v.abs() < tiny { 0.0 } else { v };
        format!("{v:.*}", self.decimals)
    }
}

fn pow10(e: i32) -> f64 {
    10f64.powi(e)
}

fn superscript(e: i32) -> String {
    const DIGITS: [char; 10] = ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'];
    let mut s = String::new();
    if e < 0 {
        s.push('⁻');
    }
    for c in e.unsigned_abs().to_string().chars() {
        s.push(DIGITS[c.to_digit(10).unwrap_or(0) as usize]);
    }
    s
}

/// Decimals needed to tell apart the tick labels plotters will put on `[lo, hi]`.
fn tick_decimals(lo: f64, hi: f64) -> usize {
    let ticks = RangedCoordf64::from(lo..hi).key_points(N_LABELS);
    let step = ticks
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|d| *d > 0.0)
        .fold(f64::INFINITY, f64::min);
    if !step.is_finite() {
        return 3;
    }
    // Smallest d with every tick an exact multiple of 10^-d (to round-off).
    (0..=15)
        .find(|&d| {
            let q = pow10(d as i32);
            ticks
                .iter()
                .all(|t| ((t * q).round() - t * q).abs() < 1e-6 * step * q)
        })
        .unwrap_or(15)
}

/// Finite (min, max) of an iterator.
fn finite_range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values
        .filter(|v| v.is_finite())
        .fold(None, |acc, v| match acc {
            None => Some((v, v)),
            Some((lo, hi)) => Some((f64::min(lo, v), f64::max(hi, v))),
        })
}

/// Min/max decimation of a segment into about `buckets` buckets (samples kept in order).
fn decimate(seg: &[(f64, f64)], buckets: usize) -> Vec<(f64, f64)> {
    let buckets = buckets.max(1);
    if seg.len() <= 2 * buckets {
        return seg.to_vec();
    }
    let chunk = seg.len().div_ceil(buckets);
    let mut out = Vec::with_capacity(2 * buckets + 2);
    for c in seg.chunks(chunk) {
        let (mut imin, mut imax) = (0, 0);
        for (i, p) in c.iter().enumerate() {
            if p.1 < c[imin].1 {
                imin = i;
            }
            if p.1 > c[imax].1 {
                imax = i;
            }
        }
        let (a, b) = (imin.min(imax), imin.max(imax));
        out.push(c[a]);
        if b != a {
            out.push(c[b]);
        }
    }
    if out.last() != seg.last() {
        out.push(seg[seg.len() - 1]);
    }
    if out.first() != seg.first() {
        out.insert(0, seg[0]);
    }
    out
}

/// Draws `energy.png`: total, kinetic and potential energy against time.
pub fn plot_energy(path: &Path, records: &[StepRecord], title: &str) -> Result<(), OutputError> {
    let panel = Panel {
        quantity: "energy",
        unit: "J",
        series: vec![
            Series::new("total H = K + V", BLACK_ISH, 2, records, |r| r.total),
            Series::new("kinetic K", RED, 2, records, |r| r.kinetic),
            Series::new("potential V", BLUE, 2, records, |r| r.potential),
        ],
    };
    render(path, ENERGY_SIZE, title, &[panel])
}

/// Draws `momenta.png`: linear momentum (Lx, Ly, Lz) and angular momentum (Jx, Jy, Jz)
/// against time, in two stacked panels.
pub fn plot_momenta(path: &Path, records: &[StepRecord], title: &str) -> Result<(), OutputError> {
    let linear = Panel {
        quantity: "linear momentum L",
        unit: "kg·m/s",
        series: vec![
            Series::new("Lx", BLUE, 2, records, |r| r.l.x),
            Series::new("Ly", ORANGE, 2, records, |r| r.l.y),
            Series::new("Lz", GREEN, 2, records, |r| r.l.z),
        ],
    };
    let angular = Panel {
        quantity: "angular momentum J",
        unit: "kg·m²/s",
        series: vec![
            Series::new("Jx", BLUE, 2, records, |r| r.j.x),
            Series::new("Jy", ORANGE, 2, records, |r| r.j.y),
            Series::new("Jz", GREEN, 2, records, |r| r.j.z),
        ],
    };
    render(path, MOMENTA_SIZE, title, &[linear, angular])
}

/// Draws `accelerations.png` (paper fig. 11): the L2 norms over the rods of the
/// translational acceleration `(v_{n+1} − v_n)/Δt` and of the director acceleration, in two
/// stacked panels.
pub fn plot_accelerations(
    path: &Path,
    records: &[StepRecord],
    title: &str,
) -> Result<(), OutputError> {
    // Row 0 is the initial state: no step has ended there, so it has no acceleration.
    let steps = records.get(1..).unwrap_or(&[]);
    let trans = Panel {
        quantity: "‖a‖ translational",
        unit: "m/s²",
        series: vec![Series::new(
            "‖(v_n+1 − v_n)/Δt‖ (L2 over the rods)",
            RED,
            2,
            steps,
            |r| r.acc_trans,
        )],
    };
    let rot = Panel {
        quantity: "‖a‖ directors",
        unit: "1/s²",
        series: vec![Series::new(
            "‖(ḋ_n+1 − ḋ_n)/Δt‖ (L2 over the rods)",
            BLUE,
            2,
            steps,
            |r| r.acc_rot,
        )],
    };
    render(path, MOMENTA_SIZE, title, &[trans, rot])
}

/// One run's history for [`plot_comparison`].
pub struct LabelledHistory<'a> {
    /// Legend label (e.g. "EM", "EDMC-2 α = 1").
    pub label: String,
    /// The run's records.
    pub records: &'a [StepRecord],
}

/// Overlays one quantity of several runs (e.g. the total energy of EM and EDMC-2): one
/// panel per entry of `quantities` (`(name, unit, accessor)`), one line per run.
#[allow(clippy::type_complexity)]
pub fn plot_comparison(
    path: &Path,
    title: &str,
    runs: &[LabelledHistory<'_>],
    quantities: &[(&'static str, &'static str, &dyn Fn(&StepRecord) -> f64)],
) -> Result<(), OutputError> {
    const PALETTE: [RGBColor; 5] = [BLACK_ISH, RED, BLUE, ORANGE, GREEN];
    let panels: Vec<Panel> = quantities
        .iter()
        .map(|(q, unit, f)| Panel {
            quantity: q,
            unit,
            series: runs
                .iter()
                .enumerate()
                .map(|(i, r)| Series::new(&r.label, PALETTE[i % PALETTE.len()], 2, r.records, f))
                .collect(),
        })
        .collect();
    let height = 120 + 330 * panels.len() as u32;
    render(path, (1000, height), title, &panels)
}

/// Whether a chart path asks for SVG (by extension); anything else is a bitmap whose
/// format follows the extension.
pub(super) fn is_svg(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("svg"))
}

/// Chooses the backend by the file extension (`.svg` → SVG, anything else → bitmap, whose
/// format follows the extension, normally PNG) and draws the panels stacked vertically.
fn render(path: &Path, size: (u32, u32), title: &str, panels: &[Panel]) -> Result<(), OutputError> {
    ensure_font();
    let result = if is_svg(path) {
        let root = SVGBackend::new(path, size).into_drawing_area();
        let quirks = Quirks {
            text_dy: 0,
            brush_lines: false,
        };
        draw_figure(&root, title, panels, quirks)
            .and_then(|()| root.present().map_err(|e| e.to_string()))
    } else {
        let root = BitMapBackend::new(path, size).into_drawing_area();
        let quirks = Quirks {
            text_dy: LEGEND_PX as i32 / 6,
            brush_lines: true,
        };
        draw_figure(&root, title, panels, quirks)
            .and_then(|()| root.present().map_err(|e| e.to_string()))
    };
    result.map_err(|message| OutputError::Plot {
        path: path.to_path_buf(),
        message,
    })
}

/// Backend-specific drawing adjustments.
#[derive(Clone, Copy, Debug)]
struct Quirks {
    /// Vertical nudge of centred legend text: the rasterized (ab_glyph) text sits a few
    /// pixels above its anchor.
    text_dy: i32,
    /// Draw a line of width w as w×w one-pixel lines offset by whole pixels: the bitmap
    /// backend polygonizes thick polylines with unlimited miter joins, which spike far
    /// outside the plot at sharp turns (noise, min/max decimation), and drawing the pieces
    /// separately leaves gaps. SVG viewers draw thick lines properly.
    brush_lines: bool,
}

fn draw_figure<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    panels: &[Panel],
    quirks: Quirks,
) -> Result<(), String> {
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let body = root
        .titled(title, (FONT, TITLE_PX).into_font().color(&BLACK))
        .map_err(|e| e.to_string())?;

    // One time axis shared by all panels: where any line has a finite value.
    let t_range = finite_range(panels.iter().flat_map(|p| {
        p.series.iter().flat_map(|s| {
            s.points
                .iter()
                .filter(|(_, v)| v.is_finite())
                .map(|(t, _)| *t)
        })
    }));
    // A single time level: start the axis (almost) there rather than centring it, so a
    // run stopped at t = 0 does not get a negative time axis.
    let t_range = t_range.map(|(lo, hi)| {
        if hi > lo {
            (lo, hi)
        } else {
            let w = if lo == 0.0 { 1.0 } else { 0.1 * lo.abs() };
            (lo - 0.05 * w, lo + w)
        }
    });
    let x_axis = Axis::new(t_range, 0.0);

    let y_axes: Vec<Axis> = panels
        .iter()
        .map(|panel| {
            let y_range = finite_range(
                panel
                    .series
                    .iter()
                    .flat_map(|s| s.points.iter().filter(|(t, _)| t.is_finite()).map(|p| p.1)),
            );
            Axis::new(y_range, 0.06)
        })
        .collect();

    // One y label area width for all panels, so that their plots line up: the widest
    // tick label, the gap, the rotated axis label.
    let label_style: TextStyle = (FONT, LABEL_PX).into_font().into();
    let mut label_w = 0;
    for y_axis in &y_axes {
        for v in RangedCoordf64::from(y_axis.lo..y_axis.hi).key_points(N_LABELS) {
            let (w, _) = root
                .estimate_text_size(&y_axis.format(v), &label_style)
                .map_err(|e| e.to_string())?;
            label_w = label_w.max(w);
        }
    }
    let y_label_area = label_w + 22 + DESC_PX + 14;

    let areas = body.split_evenly((panels.len(), 1));
    for (i, ((panel, area), y_axis)) in panels.iter().zip(&areas).zip(&y_axes).enumerate() {
        let last = i + 1 == panels.len();
        draw_panel(area, panel, &x_axis, y_axis, y_label_area, last, quirks)?;
    }
    Ok(())
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panel: &Panel,
    x_axis: &Axis,
    y_axis: &Axis,
    y_label_area: u32,
    x_desc: bool,
    quirks: Quirks,
) -> Result<(), String> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let (xs, ys) = (x_axis.scale(), y_axis.scale());
    let label_font = (FONT, LABEL_PX).into_font();
    let (margin_left, margin_right): (u32, u32) = (10, 35);

    // The legend: one row above the plot, centred over the plotting area.
    let (legend_area, chart_area) = area.split_vertically(LEGEND_ROW_PX);
    let (area_w, _) = area.dim_in_pixel();
    let plot_x0 = (margin_left + y_label_area) as i32;
    let plot_x1 = area_w as i32 - margin_right as i32;
    draw_legend(
        &legend_area,
        &panel.series,
        (plot_x0, plot_x1),
        quirks.text_dy,
    )
    .map_err(err)?;

    let mut chart = ChartBuilder::on(&chart_area)
        .margin_top(6)
        .margin_left(margin_left)
        .margin_right(margin_right)
        .margin_bottom(if x_desc { 10 } else { 4 })
        .x_label_area_size(if x_desc { 62 } else { 34 })
        .y_label_area_size(y_label_area)
        .build_cartesian_2d(x_axis.lo..x_axis.hi, y_axis.lo..y_axis.hi)
        .map_err(err)?;

    let x_fmt = |v: &f64| x_axis.format(*v);
    let y_fmt = |v: &f64| y_axis.format(*v);
    let x_desc_text = x_axis.desc("time t", "s");
    let y_desc_text = y_axis.desc(panel.quantity, panel.unit);
    let mut mesh = chart.configure_mesh();
    mesh.x_labels(N_LABELS)
        .y_labels(N_LABELS)
        .x_label_formatter(&x_fmt)
        .y_label_formatter(&y_fmt)
        .label_style(label_font.clone())
        .axis_desc_style((FONT, DESC_PX))
        .y_desc(y_desc_text)
        .light_line_style(RGBColor(238, 238, 238))
        .bold_line_style(RGBColor(208, 208, 208));
    if x_desc {
        mesh.x_desc(x_desc_text);
    }
    mesh.draw().map_err(err)?;

    let (plot_w, plot_h) = chart.plotting_area().dim_in_pixel();
    let buckets = (plot_w as usize).max(100);

    let mut any_finite = false;
    // Drawn in reverse so that the first series (the total energy) lies on top.
    for s in panel.series.iter().rev() {
        let style = ShapeStyle::from(&s.color).stroke_width(s.width);
        let segments: Vec<Vec<(f64, f64)>> = s
            .segments()
            .iter()
            .map(|seg| {
                decimate(seg, buckets)
                    .into_iter()
                    .map(|(t, v)| (t * xs, v * ys))
                    .collect()
            })
            .collect();
        any_finite |= !segments.is_empty();
        if quirks.brush_lines {
            // A w×w brush of one-pixel lines, offset by whole pixels.
            let (px, py) = (
                (x_axis.hi - x_axis.lo) / plot_w.max(1) as f64,
                (y_axis.hi - y_axis.lo) / plot_h.max(1) as f64,
            );
            let thin = ShapeStyle::from(&s.color).stroke_width(1);
            let w = s.width.max(1) as i32;
            let offsets: Vec<(f64, f64)> = (0..w * w)
                .map(|k| {
                    let (i, j) = (k % w - (w - 1) / 2, k / w - (w - 1) / 2);
                    (i as f64 * px, j as f64 * py)
                })
                .collect();
            chart
                .draw_series(
                    offsets
                        .iter()
                        .flat_map(|&(dx, dy)| {
                            segments.iter().filter(|seg| seg.len() > 1).map(move |seg| {
                                seg.iter()
                                    .map(|&(x, y)| (x + dx, y + dy))
                                    .collect::<Vec<_>>()
                            })
                        })
                        .map(|seg| PathElement::new(seg, thin)),
                )
                .map_err(err)?;
        } else {
            chart
                .draw_series(
                    segments
                        .iter()
                        .filter(|seg| seg.len() > 1)
                        .map(|seg| PathElement::new(seg.clone(), style)),
                )
                .map_err(err)?;
        }
        // Isolated samples (a single record, or a value between two gaps) as markers.
        chart
            .draw_series(
                segments
                    .iter()
                    .filter(|seg| seg.len() == 1)
                    .map(|seg| Circle::new(seg[0], 3 + s.width, style.filled())),
            )
            .map_err(err)?;
    }

    if !any_finite {
        let style = (FONT, DESC_PX)
            .into_font()
            .color(&RGBColor(120, 120, 120))
            .pos(Pos::new(HPos::Center, VPos::Center));
        chart
            .plotting_area()
            .draw(&Text::new(
                "no finite data",
                (0.5 * (x_axis.lo + x_axis.hi), 0.5 * (y_axis.lo + y_axis.hi)),
                style,
            ))
            .map_err(err)?;
    }
    Ok(())
}

/// Draws the legend as one centred row of "line sample + label" entries.
fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    series: &[Series],
    (x0, x1): (i32, i32),
    text_dy: i32,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    const SAMPLE: i32 = 30;
    const GAP: i32 = 8;
    const SPACING: i32 = 34;
    let font: TextStyle = (FONT, LEGEND_PX)
        .into_font()
        .color(&BLACK)
        .pos(Pos::new(HPos::Left, VPos::Center));
    let mut widths = Vec::with_capacity(series.len());
    for s in series {
        widths.push(area.estimate_text_size(&s.label, &font)?.0 as i32);
    }
    let total: i32 = widths.iter().map(|w| SAMPLE + GAP + w).sum::<i32>()
        + SPACING * (series.len() as i32 - 1).max(0);
    let (_, h) = area.dim_in_pixel();
    let y = h as i32 / 2;
    let mut x = ((x0 + x1) - total) / 2;
    for (s, w) in series.iter().zip(widths) {
        let style = ShapeStyle::from(&s.color).stroke_width(s.width + 1);
        area.draw(&PathElement::new(vec![(x, y), (x + SAMPLE, y)], style))?;
        area.draw(&Text::new(
            s.label.as_str(),
            (x + SAMPLE + GAP, y + text_dy),
            font.clone(),
        ))?;
        x += SAMPLE + GAP + w + SPACING;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Vec3;

    /// A decaying exchange between kinetic and potential energy, momenta constant.
    fn synthetic(n: usize, t_end: f64) -> Vec<StepRecord> {
        (0..n)
            .map(|i| {
                let t = t_end * i as f64 / (n.max(2) - 1) as f64;
                let h = 9.16667 * (0.6 + 0.4 * (-t / 3.0).exp());
                let kinetic = h * (2.0 * t).sin().powi(2);
                StepRecord {
                    step: i,
                    t,
                    kinetic,
                    potential: h - kinetic,
                    total: h,
                    l: Vec3::new(0.5, -1.25, 2.0e-16 * (t * 7.0).sin()),
                    j: Vec3::new(0.03, 0.31, -0.12),
                    ..Default::default()
                }
            })
            .collect()
    }

    fn assert_png(path: &Path) {
        let bytes = std::fs::read(path).unwrap();
        assert!(bytes.len() > 1000, "{} is too small", path.display());
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    }

    fn both(dir: &Path, name: &str, recs: &[StepRecord]) {
        let e = dir.join(format!("{name}_energy.png"));
        let m = dir.join(format!("{name}_momenta.png"));
        plot_energy(&e, recs, &format!("{name}: energy")).unwrap();
        plot_momenta(&m, recs, &format!("{name}: momenta")).unwrap();
        assert_png(&e);
        assert_png(&m);
    }

    #[test]
    fn plots_normal_data() {
        let dir = tempfile::tempdir().unwrap();
        both(dir.path(), "normal", &synthetic(2001, 10.0));
    }

    #[test]
    fn plots_constant_data() {
        let dir = tempfile::tempdir().unwrap();
        let recs: Vec<StepRecord> = (0..50)
            .map(|i| StepRecord {
                step: i,
                t: 0.01 * i as f64,
                kinetic: 0.0,
                potential: 9.16667,
                total: 9.16667 + if i % 2 == 0 { 1e-15 } else { 0.0 },
                ..Default::default()
            })
            .collect();
        both(dir.path(), "constant", &recs);
    }

    #[test]
    fn plots_single_record() {
        let dir = tempfile::tempdir().unwrap();
        both(dir.path(), "single", &synthetic(1, 0.0));
    }

    #[test]
    fn plots_no_records() {
        let dir = tempfile::tempdir().unwrap();
        both(dir.path(), "empty", &[]);
    }

    #[test]
    fn plots_non_finite_values() {
        let dir = tempfile::tempdir().unwrap();
        let mut recs = synthetic(200, 2.0);
        recs[50].kinetic = f64::NAN;
        recs[51].kinetic = f64::NAN;
        recs[120].total = f64::INFINITY;
        recs[121].total = f64::NEG_INFINITY;
        recs[122].potential = f64::NAN;
        recs[123].potential = f64::NAN;
        recs[199].l = Vec3::new(f64::NAN, f64::NAN, f64::NAN);
        recs[3].t = f64::NAN;
        both(dir.path(), "nonfinite", &recs);
        let all_nan: Vec<StepRecord> = (0..5)
            .map(|i| StepRecord {
                step: i,
                t: i as f64,
                kinetic: f64::NAN,
                potential: f64::NAN,
                total: f64::NAN,
                l: Vec3::new(f64::NAN, f64::NAN, f64::NAN),
                j: Vec3::new(f64::INFINITY, f64::NAN, f64::NAN),
                ..Default::default()
            })
            .collect();
        both(dir.path(), "allnan", &all_nan);
    }

    #[test]
    fn plots_extreme_magnitudes() {
        let dir = tempfile::tempdir().unwrap();
        let mut recs = synthetic(100, 1e-4);
        for r in &mut recs {
            r.kinetic *= 1e-18;
            r.potential *= 1e-18;
            r.total *= 1e-18;
            r.l *= 1e12;
            r.j = Vec3::new(f64::MAX, -f64::MAX, 0.0);
        }
        both(dir.path(), "extreme", &recs);
    }

    #[test]
    fn svg_by_extension() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("energy.svg");
        plot_energy(&path, &synthetic(100, 1.0), "svg").unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.starts_with("<svg"), "{}", &text[..50.min(text.len())]);
        assert!(text.contains("kinetic K"));
    }

    #[test]
    fn unwritable_path_is_an_error_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("missing_dir").join("energy.png");
        let msg = plot_energy(&path, &synthetic(10, 1.0), "x")
            .unwrap_err()
            .to_string();
        assert!(msg.contains("missing_dir"), "{msg}");
    }

    #[test]
    fn axis_never_collapses() {
        let a = Axis::new(Some((9.16667, 9.16667 + 1e-15)), 0.06);
        assert!((a.hi - a.lo) >= REL_MIN_SPAN * 9.16667 * 0.999);
        assert_eq!(a.exp, 0);
        let z = Axis::new(Some((0.0, 0.0)), 0.0);
        assert!(z.hi > z.lo);
        let tiny = Axis::new(Some((-3e-16, 2e-16)), 0.06);
        assert_eq!(tiny.exp, -16);
        assert!(tiny.hi - tiny.lo > 1.0);
        let none = Axis::new(None, 0.06);
        assert!(none.hi > none.lo);
    }

    #[test]
    fn decimation_keeps_envelope_and_ends() {
        let seg: Vec<(f64, f64)> = (0..100_000)
            .map(|i| (i as f64, ((i as f64) * 0.37).sin()))
            .collect();
        let d = decimate(&seg, 1000);
        assert!(d.len() <= 2 * 1000 + 2);
        assert_eq!(d.first(), seg.first());
        assert_eq!(d.last(), seg.last());
        let max = d.iter().map(|p| p.1).fold(f64::MIN, f64::max);
        assert!(max > 0.9999);
        assert!(d.windows(2).all(|w| w[0].0 < w[1].0));
    }

    /// Renders demo charts into `$CHARTS_DEMO_DIR` for visual inspection:
    /// `CHARTS_DEMO_DIR=/tmp/charts_demo cargo test --lib output::plot -- --ignored`.
    #[test]
    #[ignore]
    fn render_demo_charts() {
        let Some(dir) = std::env::var_os("CHARTS_DEMO_DIR") else {
            return;
        };
        let dir = std::path::PathBuf::from(dir);
        std::fs::create_dir_all(&dir).unwrap();
        let normal = synthetic(2001, 10.0);
        plot_energy(&dir.join("energy.png"), &normal, "demo · edmc1 · energy").unwrap();
        plot_momenta(&dir.join("momenta.png"), &normal, "demo · edmc1 · momenta").unwrap();
        plot_energy(&dir.join("energy.svg"), &normal, "demo · edmc1 · energy").unwrap();
        let failed = &normal[..700];
        plot_energy(&dir.join("failed_energy.png"), failed, "failed run").unwrap();
        plot_energy(&dir.join("single_energy.png"), &normal[..1], "single").unwrap();
        plot_momenta(&dir.join("single_momenta.png"), &normal[..1], "single").unwrap();
        let constant: Vec<StepRecord> = (0..50)
            .map(|i| StepRecord {
                step: i,
                t: 0.01 * i as f64,
                kinetic: 0.0,
                potential: 9.16667,
                total: 9.16667 + if i % 2 == 0 { 1e-15 } else { 0.0 },
                ..Default::default()
            })
            .collect();
        plot_energy(&dir.join("constant_energy.png"), &constant, "constant").unwrap();
        plot_momenta(&dir.join("constant_momenta.png"), &constant, "constant").unwrap();
        let mut gaps = synthetic(400, 4.0);
        for r in &mut gaps[100..110] {
            r.kinetic = f64::NAN;
        }
        gaps[250].potential = f64::INFINITY;
        gaps[251].total = f64::NAN;
        plot_energy(&dir.join("gaps_energy.png"), &gaps, "NaN gaps").unwrap();
        let mut tiny = synthetic(300, 3e-4);
        for r in &mut tiny {
            r.total *= 1e-9;
            r.kinetic *= 1e-9;
            r.potential *= 1e-9;
        }
        plot_energy(&dir.join("tiny_energy.png"), &tiny, "tiny magnitudes").unwrap();
        let only_total: Vec<StepRecord> = (0..200)
            .map(|i| StepRecord {
                step: i,
                t: 0.05 * i as f64,
                kinetic: f64::NAN,
                potential: f64::NAN,
                total: 9.16667 + 1e-12 * (i as f64 * 0.3).sin(),
                ..Default::default()
            })
            .collect();
        plot_energy(
            &dir.join("flat_total_energy.png"),
            &only_total,
            "H only, flat",
        )
        .unwrap();
        let mut noise = synthetic(1_000_001, 100.0);
        for (i, r) in noise.iter_mut().enumerate() {
            let x = i as f64;
            r.l = Vec3::new(1e-16 * (x * 0.7).sin(), -2e-16 * (x * 1.3).cos(), 0.0);
            r.j = Vec3::new(4.0e5 + 1e-10 * (x * 0.01).sin(), 3.9e5, 0.0);
        }
        let t0 = std::time::Instant::now();
        plot_momenta(
            &dir.join("noise_momenta.png"),
            &noise,
            "roundoff noise, 10⁶ steps",
        )
        .unwrap();
        plot_energy(&dir.join("long_energy.png"), &noise, "10⁶ steps").unwrap();
        eprintln!("two charts of 10^6 records: {:?}", t0.elapsed());
    }
}
