//! `work_precision.png` (log-log error against wall time, one line per scheme),
//! `stability.png` (heat maps of the fraction of the run completed, one panel per scheme)
//! `from_rest.png` (the from-rest map: each cell coloured by its outcome) and
//! `damping.png` (modal damping ratio per dissipation parameter). Same embedded font as
//! the run charts; a path ending in `.svg` is drawn as SVG with the same layout.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::{
    Damping, FromRest, ModeKind, OrderFit, Outcome, SchemeKind, SchemeSpec, Stability,
    WorkPrecision, ORDER_AGREEMENT, PARAMETERS,
};
use crate::observe::record::RunStatus;
use crate::output::{ensure_font, num, OutputError, FONT};

const PALETTE: [RGBColor; 8] = [
    RGBColor(20, 20, 20),
    RGBColor(214, 39, 40),
    RGBColor(31, 119, 180),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(23, 190, 207),
];

fn plot_err(path: &Path) -> impl Fn(String) -> OutputError + '_ {
    move |message| OutputError::Plot {
        path: path.to_path_buf(),
        message,
    }
}

/// Whether a chart path asks for SVG (by extension); anything else is a bitmap whose
/// format follows the extension (normally PNG).
fn is_svg(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("svg"))
}

/// Draws `$draw(&root, args…)` on an SVG or bitmap backend of `$size`, chosen by the
/// extension of `$path`, and writes the file.
macro_rules! render {
    ($path:expr, $size:expr, $draw:ident ( $($arg:expr),* )) => {{
        ensure_font();
        let path: &Path = $path;
        let r = if is_svg(path) {
            let root = SVGBackend::new(path, $size).into_drawing_area();
            $draw(&root, $($arg),*).and_then(|()| root.present().map_err(|e| e.to_string()))
        } else {
            let root = BitMapBackend::new(path, $size).into_drawing_area();
            $draw(&root, $($arg),*).and_then(|()| root.present().map_err(|e| e.to_string()))
        };
        r.map_err(plot_err(path))
    }};
}

/// Decade range `[10^floor(log lo), 10^ceil(log hi)]` around positive data.
fn decades(lo: f64, hi: f64) -> (f64, f64) {
    let (lo, hi) = if lo.is_finite() && hi.is_finite() && lo > 0.0 {
        (lo, hi.max(lo))
    } else {
        (1e-3, 1.0)
    };
    // Keep 10^k a normal f64: below 1e-300 (subnormals) it underflows to 0 and a log axis
    // from 0 never ends its tick loop.
    let (lo, hi) = (lo.clamp(1e-300, 1e300), hi.clamp(1e-300, 1e300));
    let a = 10f64.powf(lo.log10().floor());
    let mut b = 10f64.powf(hi.log10().ceil());
    if b <= a {
        b = a * 10.0;
    }
    // A hair wider, so that round-off in 10^k keeps the end decades' tick labels.
    (a * 0.999, b * 1.001)
}

fn sci(v: f64) -> String {
    let s = format!("{v:.0e}");
    s.strip_suffix("e0").map_or(s.clone(), str::to_string)
}

/// [`sci`] at 1, 2 and 5 × 10^k only (the other ticks of a log axis that spans about one
/// decade crowd each other): empty elsewhere.
fn sci_125(v: f64) -> String {
    let s = sci(v);
    if ["1", "2", "5"].iter().any(|m| s.starts_with(m)) {
        s
    } else {
        String::new()
    }
}

/// Left-aligned, vertically centred text style.
fn left(px: u32, color: &RGBColor) -> TextStyle<'static> {
    (FONT, px)
        .into_font()
        .color(color)
        .pos(Pos::new(HPos::Left, VPos::Center))
}

/// Marker shapes, one per Δt of a work–precision chart (coarsest first), cycled.
const MARKER_SHAPES: usize = 6;

/// Vertices (pixel offsets) of marker `shape`; `None` for the circle.
fn marker_vertices(shape: usize) -> Option<Vec<(i32, i32)>> {
    match shape % MARKER_SHAPES {
        0 => None,
        1 => Some(vec![(-6, -6), (6, -6), (6, 6), (-6, 6)]),
        2 => Some(vec![(0, -8), (7, 5), (-7, 5)]),
        3 => Some(vec![(0, -8), (8, 0), (0, 8), (-8, 0)]),
        4 => Some(vec![(0, 8), (7, -5), (-7, -5)]),
        _ => Some(vec![(-4, -7), (4, -7), (8, 0), (4, 7), (-4, 7), (-8, 0)]),
    }
}

/// Draws marker `shape` centred at the pixel `at` of `area`: filled in `color`, or hollow
/// (white inside, outlined in `color`).
fn draw_marker<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    at: (i32, i32),
    shape: usize,
    color: RGBColor,
    filled: bool,
) -> Result<(), String> {
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
    let (x, y) = at;
    match marker_vertices(shape) {
        None => {
            if filled {
                area.draw(&Circle::new(at, 7, color.filled())).map_err(e)?;
            } else {
                area.draw(&Circle::new(at, 6, WHITE.filled())).map_err(e)?;
                area.draw(&Circle::new(at, 6, color.stroke_width(2)))
                    .map_err(e)?;
            }
        }
        Some(v) => {
            let pts: Vec<(i32, i32)> = v.iter().map(|(dx, dy)| (x + dx, y + dy)).collect();
            if filled {
                area.draw(&Polygon::new(pts, color.filled())).map_err(e)?;
            } else {
                area.draw(&Polygon::new(pts.clone(), WHITE.filled()))
                    .map_err(e)?;
                let mut ring = pts.clone();
                ring.push(pts[0]);
                area.draw(&PathElement::new(ring, color.stroke_width(2)))
                    .map_err(e)?;
            }
        }
    }
    Ok(())
}

/// Size of `work_precision.png`: the plot on the left, the legend column on the right.
const WP_SIZE: (u32, u32) = (1500, 900);
/// Width of the legend column.
const WP_LEGEND_W: u32 = 560;
/// A fitted order this far below the nominal one is "below nominal" (the chart then
/// explains what that means).
const BELOW_NOMINAL: f64 = 0.3;

/// The legend text of a scheme: its observed order and the Δt range it was fitted over,
/// or that it has no asymptotic range.
fn order_label(spec: &SchemeSpec, fit: Option<OrderFit>) -> String {
    match fit {
        Some(f) => format!(
            "{}: order {:.2} (fit over Δt {}–{})",
            spec.label(),
            f.order,
            num(f.dt_min),
            num(f.dt_max)
        ),
        None => format!("{}: no asymptotic range", spec.label()),
    }
}

/// Draws `work_precision.png`: error against wall time on log-log axes, one line per
/// scheme/parameter (colour) through its runs ordered by Δt, one marker shape per Δt (a
/// legend of them instead of text at the points). The legend gives each scheme's observed
/// order and the Δt range it was fitted over ([`super::asymptotic_fit`]); markers of runs
/// outside that range are hollow (all of a scheme's with no asymptotic range). The fit is
/// the rows' `observed_order`, `fit_dt_min` and `fit_dt_max`, as in the CSV. Failed runs
/// are crosses on the bottom edge at their wall time.
pub fn plot_work_precision(path: &Path, wp: &WorkPrecision) -> Result<(), OutputError> {
    render!(path, WP_SIZE, draw_wp(wp))
}

fn draw_wp<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    wp: &WorkPrecision,
) -> Result<(), String> {
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
    root.fill(&WHITE).map_err(e)?;
    let ok: Vec<_> = wp
        .rows
        .iter()
        .filter(|r| r.status == RunStatus::Completed && r.error > 0.0 && r.error.is_finite())
        .collect();
    let wall = |w: f64| w.max(1e-5);
    let (xl, xh) = decades(
        wp.rows
            .iter()
            .map(|r| wall(r.wall_s))
            .fold(f64::INFINITY, f64::min),
        wp.rows.iter().map(|r| wall(r.wall_s)).fold(0.0, f64::max),
    );
    let (yl, yh) = decades(
        ok.iter().map(|r| r.error).fold(f64::INFINITY, f64::min),
        ok.iter().map(|r| r.error).fold(0.0, f64::max),
    );
    let mut specs: Vec<SchemeSpec> = Vec::new();
    for r in &wp.rows {
        if !specs.contains(&r.spec) {
            specs.push(r.spec);
        }
    }
    // Δt, coarsest first: one marker shape each.
    let mut dts: Vec<f64> = Vec::new();
    for r in &wp.rows {
        if !dts.contains(&r.dt) {
            dts.push(r.dt);
        }
    }
    dts.sort_by(|a, b| b.total_cmp(a));
    let shape_of = |dt: f64| dts.iter().position(|&d| d == dt).unwrap_or(0);
    // Each scheme's fit, as its rows (and the CSV) give it.
    let fits: Vec<Option<OrderFit>> = specs
        .iter()
        .map(|s| {
            wp.rows
                .iter()
                .find(|r| r.spec == *s)
                .filter(|r| {
                    r.observed_order.is_finite()
                        && r.fit_dt_min.is_finite()
                        && r.fit_dt_max.is_finite()
                })
                .map(|r| OrderFit {
                    order: r.observed_order,
                    dt_min: r.fit_dt_min,
                    dt_max: r.fit_dt_max,
                })
        })
        .collect();

    let (w, h) = root.dim_in_pixel();
    let (head, rest) = root.split_vertically(50);
    let (body, foot) = rest.split_vertically(h - 50 - 90);
    let (plot, side) = body.split_horizontally(w - WP_LEGEND_W);
    head.draw(&Text::new(
        format!(
            "{}: work–precision (t_end = {}, reference EM Δt = {})",
            wp.scene,
            num(wp.t_end),
            num(wp.reference_dt)
        ),
        (w as i32 / 2, 28),
        (FONT, 26)
            .into_font()
            .color(&BLACK)
            .pos(Pos::new(HPos::Center, VPos::Center)),
    ))
    .map_err(e)?;

    let mut chart = ChartBuilder::on(&plot)
        .margin(20)
        .x_label_area_size(70)
        .y_label_area_size(100)
        .build_cartesian_2d((xl..xh).log_scale(), (yl..yh).log_scale())
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("wall time of the run [s]")
        .y_desc("L2-in-time error of nodal positions [m]")
        .axis_desc_style((FONT, 21))
        .label_style((FONT, 17))
        .x_label_formatter(&|v| sci(*v))
        .y_label_formatter(&|v| sci(*v))
        .draw()
        .map_err(e)?;
    for (i, (spec, fit)) in specs.iter().zip(&fits).enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        let mut rows: Vec<_> = ok.iter().filter(|r| r.spec == *spec).collect();
        rows.sort_by(|a, b| b.dt.total_cmp(&a.dt));
        let pts: Vec<(f64, f64)> = rows.iter().map(|r| (wall(r.wall_s), r.error)).collect();
        // A scheme with no asymptotic range: a thin dashed line.
        if fit.is_some() {
            chart
                .draw_series(LineSeries::new(pts, color.stroke_width(2)))
                .map_err(e)?;
        } else {
            chart
                .draw_series(DashedLineSeries::new(pts, 8, 5, color.stroke_width(1)))
                .map_err(e)?;
        }
        for r in &rows {
            let at = chart.backend_coord(&(wall(r.wall_s), r.error));
            let inside = fit.is_some_and(|f| f.contains(r.dt));
            draw_marker(root, at, shape_of(r.dt), color, inside)?;
        }
        chart
            .draw_series(
                wp.rows
                    .iter()
                    .filter(|r| r.spec == *spec && r.status == RunStatus::Failed)
                    .map(|r| Cross::new((wall(r.wall_s), yl * 1.15), 8, color.stroke_width(3))),
            )
            .map_err(e)?;
    }

    // The legend column: schemes (colour, order, fitted range), then Δt (marker shape).
    let (sx, _) = side.get_base_pixel();
    let (_, sy) = body.get_base_pixel();
    let x0 = sx + 4;
    let mut y = sy + 30;
    let head_style = left(18, &BLACK);
    root.draw(&Text::new(
        "scheme (colour): observed order, Δt range fitted",
        (x0, y),
        head_style.clone(),
    ))
    .map_err(e)?;
    y += 30;
    for (i, (spec, fit)) in specs.iter().zip(&fits).enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        let failed = wp
            .rows
            .iter()
            .filter(|r| r.spec == *spec && r.status == RunStatus::Failed)
            .count();
        if fit.is_some() {
            root.draw(&PathElement::new(
                vec![(x0, y), (x0 + 30, y)],
                color.stroke_width(3),
            ))
            .map_err(e)?;
        } else {
            for k in 0..3 {
                root.draw(&PathElement::new(
                    vec![(x0 + 11 * k, y), (x0 + 11 * k + 7, y)],
                    color.stroke_width(1),
                ))
                .map_err(e)?;
            }
        }
        root.draw(&Text::new(
            order_label(spec, *fit),
            (x0 + 40, y),
            left(16, &color),
        ))
        .map_err(e)?;
        let nominal = spec.kind.nominal_order();
        let mut note = format!("nominal order {nominal}");
        if fit.is_some_and(|f| f.order < nominal as f64 - BELOW_NOMINAL) {
            note += " (observed below it, see below)";
        }
        if failed > 0 {
            note += &format!("; {failed} failed");
        }
        root.draw(&Text::new(
            note,
            (x0 + 40, y + 19),
            left(14, &RGBColor(90, 90, 90)),
        ))
        .map_err(e)?;
        y += 46;
    }
    y += 14;
    root.draw(&Text::new(
        "time step (marker shape)",
        (x0, y),
        head_style.clone(),
    ))
    .map_err(e)?;
    y += 28;
    for (k, dt) in dts.iter().enumerate() {
        draw_marker(root, (x0 + 15, y), k, BLACK, true)?;
        root.draw(&Text::new(
            format!("Δt = {}", num(*dt)),
            (x0 + 40, y),
            left(16, &BLACK),
        ))
        .map_err(e)?;
        y += 26;
    }
    y += 14;
    draw_marker(root, (x0 + 15, y), 0, BLACK, true)?;
    root.draw(&Text::new(
        "filled: Δt in the fitted (asymptotic) range",
        (x0 + 40, y),
        left(16, &BLACK),
    ))
    .map_err(e)?;
    y += 26;
    draw_marker(root, (x0 + 15, y), 0, BLACK, false)?;
    root.draw(&Text::new(
        "hollow: outside it, not in the order fit",
        (x0 + 40, y),
        left(16, &BLACK),
    ))
    .map_err(e)?;
    y += 26;
    for k in 0..3 {
        root.draw(&PathElement::new(
            vec![(x0 + 11 * k, y), (x0 + 11 * k + 7, y)],
            BLACK.stroke_width(1),
        ))
        .map_err(e)?;
    }
    root.draw(&Text::new(
        "thin dashed line: no asymptotic range",
        (x0 + 40, y),
        left(16, &BLACK),
    ))
    .map_err(e)?;
    y += 26;
    root.draw(&Cross::new((x0 + 15, y), 7, BLACK.stroke_width(3)))
        .map_err(e)?;
    root.draw(&Text::new(
        "on the bottom edge: failed run (at its wall time)",
        (x0 + 40, y),
        left(16, &BLACK),
    ))
    .map_err(e)?;

    // The rule, and what an order below the nominal one means.
    let (_, fy) = foot.get_base_pixel();
    let mut notes = vec![format!(
        "order = least-squares slope of log error vs log Δt over the asymptotic range (longest run of the finest Δt, ≥ 3, whose local orders agree within {:.0} %); lower-left is better.",
        100.0 * ORDER_AGREEMENT
    )];
    let below = specs.iter().zip(&fits).any(|(s, f)| match f {
        Some(f) => f.order < s.kind.nominal_order() as f64 - BELOW_NOMINAL,
        None => true,
    });
    if below {
        notes.push(
            "An order below the nominal one, or no asymptotic range, means the error at these Δt is dominated by motion none of them resolves".into(),
        );
        notes.push(
            "(e.g. modes excited by a sudden load or a point-velocity start), not by the scheme's truncation error.".into(),
        );
    }
    for (k, n) in notes.iter().enumerate() {
        root.draw(&Text::new(
            n.as_str(),
            (20, fy + 18 + 24 * k as i32),
            left(15, &BLACK),
        ))
        .map_err(e)?;
    }
    Ok(())
}

/// Fraction completed → colour (red 0, yellow ½, green 1).
fn heat(f: f64) -> RGBColor {
    let f = f.clamp(0.0, 1.0);
    let lerp = |a: u8, b: u8, t: f64| (a as f64 + (b as f64 - a as f64) * t).round() as u8;
    let (c0, c1, t) = if f < 0.5 {
        ((215, 48, 39), (254, 224, 139), f / 0.5)
    } else {
        ((254, 224, 139), (26, 152, 80), (f - 0.5) / 0.5)
    };
    RGBColor(
        lerp(c0.0, c1.0, t),
        lerp(c0.1, c1.1, t),
        lerp(c0.2, c1.2, t),
    )
}

/// Draws `stability.png`: per scheme a grid Δt (x) × parameter (y); each cell's colour is
/// the fraction of the run completed (colour bar below the panels), its text the
/// percentage reached and the largest relative energy growth `(H − H_0 − W)/H_0` (`≤0`
/// when no energy was created). The title says that every run takes fixed steps.
pub fn plot_stability(path: &Path, st: &Stability) -> Result<(), OutputError> {
    let kinds = &st.config.kinds;
    let cols = kinds.len().clamp(1, 3);
    let rows = kinds.len().div_ceil(cols).max(1);
    let size = (560 * cols as u32, 440 * rows as u32 + 150);
    render!(path, size, draw_stability(st, rows, cols))
}

/// Relative energy growth below this is round-off (the EM acceptance tolerance
/// `energy_tol` defaults to 1e-9).
const GROWTH_ROUNDOFF: f64 = 1e-9;

fn growth_text(g: f64) -> String {
    if !g.is_finite() {
        "n/a".into()
    } else if g <= GROWTH_ROUNDOFF {
        "ΔH≤0".into()
    } else {
        format!("ΔH+{g:.0e}")
    }
}

/// The parameter axis of a stability panel, with what the parameter sets.
fn param_desc(kind: SchemeKind) -> String {
    match kind {
        SchemeKind::Edmc1 => "χ = χ_Γ = χ_Ω [–]".into(),
        SchemeKind::Edmc2 => "α = α_Γv [–]".into(),
        SchemeKind::GenAlpha => "ρ∞ (spectral radius at Δt → ∞) [–]".into(),
        SchemeKind::Em | SchemeKind::Midpoint => "(no parameter)".into(),
    }
}

fn draw_stability<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    st: &Stability,
    rows: usize,
    cols: usize,
) -> Result<(), String> {
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
    root.fill(&WHITE).map_err(e)?;
    let (w, h) = root.dim_in_pixel();
    let (head, rest) = root.split_vertically(60);
    let (body, foot) = rest.split_vertically(h - 60 - 90);
    head.draw(&Text::new(
        format!(
            "{}: stability map, fixed step (no cut-back), t_end = {}",
            st.scene,
            num(st.config.t_end)
        ),
        (w as i32 / 2, 30),
        (FONT, 26)
            .into_font()
            .color(&BLACK)
            .pos(Pos::new(HPos::Center, VPos::Center)),
    ))
    .map_err(e)?;
    // Colour bar: fraction of t_end reached.
    let (_, fy) = foot.get_base_pixel();
    let bar_w = 360;
    let bx = w as i32 / 2 - bar_w / 2;
    let by = fy + 14;
    for k in 0..bar_w {
        let c = heat(k as f64 / (bar_w - 1) as f64);
        root.draw(&Rectangle::new(
            [(bx + k, by), (bx + k + 1, by + 16)],
            c.filled(),
        ))
        .map_err(e)?;
    }
    root.draw(&Rectangle::new(
        [(bx, by), (bx + bar_w, by + 16)],
        BLACK.stroke_width(1),
    ))
    .map_err(e)?;
    let small = (FONT, 14).into_font().color(&BLACK);
    for (f, label) in [(0.0, "0 %"), (0.5, "50 %"), (1.0, "100 %")] {
        root.draw(&Text::new(
            label,
            (bx + (f * bar_w as f64) as i32, by + 20),
            small.pos(Pos::new(HPos::Center, VPos::Top)),
        ))
        .map_err(e)?;
    }
    root.draw(&Text::new(
        "colour: fraction of t_end reached",
        (bx - 14, by + 8),
        small.pos(Pos::new(HPos::Right, VPos::Center)),
    ))
    .map_err(e)?;
    root.draw(&Text::new(
        "cell text: % of t_end reached; ΔH: largest relative energy growth (H − H₀ − W)/H₀ (ΔH≤0: none beyond 1e-9)",
        (w as i32 / 2, by + 58),
        (FONT, 15)
            .into_font()
            .color(&BLACK)
            .pos(Pos::new(HPos::Center, VPos::Center)),
    ))
    .map_err(e)?;
    let panels = body.split_evenly((rows, cols));
    let dts = &st.config.dts;
    for (kind, area) in st.config.kinds.iter().zip(panels.iter()) {
        draw_stability_panel(root, area, st, *kind, dts)?;
    }
    Ok(())
}

fn draw_stability_panel<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    area: &DrawingArea<DB, Shift>,
    st: &Stability,
    kind: SchemeKind,
    dts: &[f64],
) -> Result<(), String> {
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
    let params = st.config.params_of(kind);
    let (nx, ny) = (dts.len(), params.len());
    let name = SchemeSpec { kind, param: 0.0 }.label();
    let mut chart = ChartBuilder::on(area)
        .caption(name.split(' ').next().unwrap_or(""), (FONT, 22))
        .margin(12)
        .x_label_area_size(55)
        .y_label_area_size(70)
        .build_cartesian_2d(0f64..nx as f64, 0f64..ny as f64)
        .map_err(e)?;
    // Cells are categories: no numeric ticks; labels at the cell centres below.
    chart
        .configure_mesh()
        .disable_mesh()
        .x_labels(0)
        .y_labels(0)
        .x_desc("time step Δt [s]")
        .y_desc(param_desc(kind))
        .axis_desc_style((FONT, 17))
        .draw()
        .map_err(e)?;
    let tick = (FONT, 14).into_font().color(&BLACK);
    for (i, dt) in dts.iter().enumerate() {
        let (px, py) = chart.backend_coord(&(i as f64 + 0.5, 0.0));
        root.draw(&Text::new(
            num(*dt),
            (px, py + 8),
            tick.pos(Pos::new(HPos::Center, VPos::Top)),
        ))
        .map_err(e)?;
    }
    if kind.has_param() {
        for (j, p) in params.iter().enumerate() {
            let (px, py) = chart.backend_coord(&(0.0, j as f64 + 0.5));
            root.draw(&Text::new(
                num(*p),
                (px - 8, py),
                tick.pos(Pos::new(HPos::Right, VPos::Center)),
            ))
            .map_err(e)?;
        }
    }
    for (j, &p) in params.iter().enumerate() {
        for (i, &dt) in dts.iter().enumerate() {
            let Some(c) = st
                .cells
                .iter()
                .find(|c| c.kind == kind && c.param == p && c.dt == dt)
            else {
                continue;
            };
            let (x, y) = (i as f64, j as f64);
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(x, y), (x + 1.0, y + 1.0)],
                    heat(c.fraction()).filled(),
                )))
                .map_err(e)?;
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(x, y), (x + 1.0, y + 1.0)],
                    WHITE.stroke_width(1),
                )))
                .map_err(e)?;
            // Two lines: percentage reached, energy growth.
            let style = (FONT, 13)
                .into_font()
                .color(&BLACK)
                .pos(Pos::new(HPos::Center, VPos::Center));
            let lines = [
                format!("{:.0}%", 100.0 * c.fraction()),
                growth_text(c.max_energy_growth),
            ];
            chart
                .draw_series(lines.into_iter().zip([-8, 8]).map(|(t, dy)| {
                    EmptyElement::at((x + 0.5, y + 0.5)) + Text::new(t, (0, dy), style.clone())
                }))
                .map_err(e)?;
        }
    }
    Ok(())
}

/// Draws `damping.png`: the modal damping ratio ζ against the parameter value on log-log
/// axes, one panel per mode (axial, bending), one line per dissipation parameter (legend
/// column on the right); EM's ζ (round-off) is given in each panel's caption. Failed runs
/// are left out of the lines and drawn as crosses on the bottom edge (their count in the
/// panel's caption).
pub fn plot_damping(path: &Path, d: &Damping) -> Result<(), OutputError> {
    render!(path, (1600, 740), draw_damping(d))
}

/// Smallest ζ drawn (smaller values, e.g. EDMC-2 at small amplitude, sit on the floor).
const ZETA_FLOOR: f64 = 1e-8;
/// Width of the damping chart's legend column.
const DAMPING_LEGEND_W: u32 = 210;

/// Line style and marker (circle: EDMC-1, triangle: EDMC-2) of damping parameter `i`.
fn damping_style(i: usize) -> (RGBColor, ShapeStyle, bool) {
    let color = PALETTE[i % PALETTE.len()];
    let edmc1 = i < 4;
    let width = if edmc1 { 2 } else { 1 };
    (color, ShapeStyle::from(&color).stroke_width(width), edmc1)
}

fn draw_damping<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    d: &Damping,
) -> Result<(), String> {
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
    root.fill(&WHITE).map_err(e)?;
    let c = &d.config;
    let title = format!(
        "{}: modal damping ratio per dissipation parameter ({} steps per period, tip amplitude {} L, {} periods)",
        d.scene,
        c.steps_per_period,
        num(c.amplitude),
        num(c.periods)
    );
    let (w, h) = root.dim_in_pixel();
    let (top, rest) = root.split_vertically(40);
    let (body, foot) = rest.split_vertically(h - 40 - 34);
    let (plots, side) = body.split_horizontally(w - DAMPING_LEGEND_W);
    top.draw(&Text::new(
        title,
        (20, 10),
        (FONT, 22).into_font().color(&BLACK),
    ))
    .map_err(e)?;
    foot.draw(&Text::new(
        format!(
            "ζ = r/2ω (r: fitted decay rate of H); ζ < {} drawn on the bottom line; × on the bottom edge: failed run (left out of the line).",
            sci(ZETA_FLOOR)
        ),
        (20, 14),
        left(15, &BLACK),
    ))
    .map_err(e)?;
    // Legend column: one entry per parameter run.
    let (sx, sy) = side.get_base_pixel();
    let mut y = sy + 60;
    side.draw(&Text::new("parameter", (sx + 4, y), left(16, &BLACK)))
        .map_err(e)?;
    for (i, p) in PARAMETERS.iter().enumerate() {
        if !d.rows.iter().any(|r| r.param == p.key) {
            continue;
        }
        y += 26;
        let (color, style, edmc1) = damping_style(i);
        root.draw(&PathElement::new(vec![(sx + 4, y), (sx + 34, y)], style))
            .map_err(e)?;
        if edmc1 {
            root.draw(&Circle::new((sx + 19, y), 4, color.filled()))
                .map_err(e)?;
        } else {
            root.draw(&TriangleMarker::new((sx + 19, y), 5, color.filled()))
                .map_err(e)?;
        }
        root.draw(&Text::new(p.symbol, (sx + 42, y), left(15, &BLACK)))
            .map_err(e)?;
    }
    let panels = plots.split_evenly((1, 2));
    let ok = |r: &&super::DampingRow| r.status == RunStatus::Completed && r.zeta.is_finite();
    let (xl, xh) = decades(
        c.values.iter().copied().fold(f64::INFINITY, f64::min),
        c.values.iter().copied().fold(0.0, f64::max),
    );
    let zmax = d
        .rows
        .iter()
        .filter(ok)
        .map(|r| r.zeta)
        .fold(ZETA_FLOOR, f64::max);
    let (yl, yh) = decades(ZETA_FLOOR, zmax);
    for (panel, mode) in panels.iter().zip([ModeKind::Axial, ModeKind::Bending]) {
        let rows: Vec<_> = d.rows.iter().filter(|r| r.mode == mode).collect();
        let em = rows.iter().find(|r| r.param == "em");
        let failed = rows
            .iter()
            .filter(|r| r.status == RunStatus::Failed)
            .count();
        let caption = format!(
            "first {} mode, ωΔt = {:.3}; EM ζ = {}{}",
            mode.name(),
            rows.first().map_or(f64::NAN, |r| r.omega * r.dt),
            em.map_or("—".to_string(), |r| format!("{:.1e}", r.zeta)),
            if failed > 0 {
                format!("; {failed} failed (×)")
            } else {
                String::new()
            }
        );
        let mut chart = ChartBuilder::on(panel)
            .caption(caption, (FONT, 20))
            .margin(15)
            .margin_right(25)
            .x_label_area_size(55)
            .y_label_area_size(80)
            .build_cartesian_2d((xl..xh).log_scale(), (yl..yh).log_scale())
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("parameter value (χ or α) [–]")
            .y_desc("modal damping ratio ζ [–]")
            .axis_desc_style((FONT, 18))
            .label_style((FONT, 15))
            .x_label_formatter(&|v| sci_125(*v))
            .y_label_formatter(&|v| sci(*v))
            .draw()
            .map_err(e)?;
        for (i, p) in PARAMETERS.iter().enumerate() {
            let (color, style, edmc1) = damping_style(i);
            let mine: Vec<_> = rows.iter().filter(|r| r.param == p.key).collect();
            let pts: Vec<(f64, f64)> = mine
                .iter()
                .filter(|r| ok(r))
                .map(|r| (r.value, r.zeta.max(ZETA_FLOOR)))
                .collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), style))
                .map_err(e)?;
            if edmc1 {
                chart
                    .draw_series(pts.iter().map(|&q| Circle::new(q, 4, color.filled())))
                    .map_err(e)?;
            } else {
                chart
                    .draw_series(
                        pts.iter()
                            .map(|&q| TriangleMarker::new(q, 5, color.filled())),
                    )
                    .map_err(e)?;
            }
            chart
                .draw_series(
                    mine.iter()
                        .filter(|r| r.status == RunStatus::Failed)
                        .map(|r| Cross::new((r.value, yl * 1.25), 7, color.stroke_width(3))),
                )
                .map_err(e)?;
        }
    }
    Ok(())
}

/// Colour of a from-rest outcome: green completed, the scheme's limits orange, purple and
/// grey, Newton's divergence blue, a solver stall red.
pub fn outcome_colour(o: Outcome) -> RGBColor {
    match o {
        Outcome::Completed => RGBColor(26, 152, 80),
        Outcome::ElementTurn => RGBColor(253, 174, 97),
        Outcome::EnergyGrowth => RGBColor(148, 103, 189),
        Outcome::NonFinite => RGBColor(120, 120, 120),
        Outcome::SolverStall => RGBColor(215, 48, 39),
        Outcome::NewtonDivergence => RGBColor(69, 117, 180),
    }
}

/// Width of the row-label column of the from-rest chart.
const FR_LABEL_W: u32 = 230;

/// Draws `from_rest.png`: one row per scheme (EM, each dissipation parameter alone), one
/// column per Δt (log grid); each cell coloured by its [`Outcome`] (legend with the counts
/// below), the percentage of the end time reached written in failed cells when the
/// columns are wide enough. The title says whether the steps were fixed.
pub fn plot_from_rest(path: &Path, fr: &FromRest) -> Result<(), OutputError> {
    let ny = fr.config.rows.len().max(1) as u32;
    let size = (1500, 60 + 44 * ny + 90 + 110);
    render!(path, size, draw_from_rest(fr))
}

fn draw_from_rest<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    fr: &FromRest,
) -> Result<(), String> {
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
    root.fill(&WHITE).map_err(e)?;
    let (w, h) = root.dim_in_pixel();
    let (head, rest) = root.split_vertically(60);
    let (body, foot) = rest.split_vertically(h - 60 - 110);
    let steps = if fr.cutback == 0 {
        "fixed step (no cut-back)".to_string()
    } else {
        format!("cut-back up to {} sub-steps", 1u64 << fr.cutback.min(20))
    };
    head.draw(&Text::new(
        format!(
            "{}: from-rest stability map, {steps}, t_end = {}",
            fr.scene,
            num(fr.config.t_end)
        ),
        (w as i32 / 2, 30),
        (FONT, 26)
            .into_font()
            .color(&BLACK)
            .pos(Pos::new(HPos::Center, VPos::Center)),
    ))
    .map_err(e)?;
    let rows = &fr.config.rows;
    let dts = &fr.config.dts;
    let (nx, ny) = (dts.len(), rows.len());
    let mut chart = ChartBuilder::on(&body)
        .margin(12)
        .margin_right(30)
        .x_label_area_size(60)
        .y_label_area_size(FR_LABEL_W)
        .build_cartesian_2d(0f64..nx as f64, 0f64..ny as f64)
        .map_err(e)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_labels(0)
        .y_labels(0)
        .x_desc("time step Δt [s] (log grid)")
        .axis_desc_style((FONT, 17))
        .draw()
        .map_err(e)?;
    let tick = (FONT, 14).into_font().color(&BLACK);
    // At most about 12 Δt labels: every k-th column.
    let every = nx.div_ceil(12).max(1);
    for (i, dt) in dts.iter().enumerate() {
        if i % every != 0 && i + 1 != nx {
            continue;
        }
        let (px, py) = chart.backend_coord(&(i as f64 + 0.5, 0.0));
        root.draw(&Text::new(
            format!("{dt:.3}"),
            (px, py + 8),
            tick.pos(Pos::new(HPos::Center, VPos::Top)),
        ))
        .map_err(e)?;
    }
    for (j, r) in rows.iter().enumerate() {
        let (px, py) = chart.backend_coord(&(0.0, j as f64 + 0.5));
        root.draw(&Text::new(
            r.label(),
            (px - 8, py),
            (FONT, 15)
                .into_font()
                .color(&BLACK)
                .pos(Pos::new(HPos::Right, VPos::Center)),
        ))
        .map_err(e)?;
    }
    // Percentages in failed cells where a column is wide enough for "100%".
    let wide = nx <= 20;
    for c in &fr.cells {
        let (Some(i), Some(j)) = (
            dts.iter().position(|&d| d == c.dt),
            rows.iter().position(|r| *r == c.row),
        ) else {
            continue;
        };
        let (x, y) = (i as f64, j as f64);
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(x, y), (x + 1.0, y + 1.0)],
                outcome_colour(c.outcome).filled(),
            )))
            .map_err(e)?;
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(x, y), (x + 1.0, y + 1.0)],
                WHITE.stroke_width(1),
            )))
            .map_err(e)?;
        if wide && c.outcome != Outcome::Completed {
            let style = (FONT, 13)
                .into_font()
                .color(&BLACK)
                .pos(Pos::new(HPos::Center, VPos::Center));
            let pct = 100.0 * (c.t_reached / c.t_end).clamp(0.0, 1.0);
            chart
                .draw_series(std::iter::once(
                    EmptyElement::at((x + 0.5, y + 0.5))
                        + Text::new(format!("{pct:.0}%"), (0, 0), style),
                ))
                .map_err(e)?;
        }
    }
    // Legend: one swatch per outcome with its count, in two columns.
    let (_, fy) = foot.get_base_pixel();
    let counts = fr.counts();
    let total = fr.cells.len();
    for (k, (o, n)) in counts.iter().enumerate() {
        let (col, line) = ((k % 3) as i32, (k / 3) as i32);
        let x0 = 40 + col * 480;
        let y0 = fy + 16 + 28 * line;
        root.draw(&Rectangle::new(
            [(x0, y0 - 9), (x0 + 18, y0 + 9)],
            outcome_colour(*o).filled(),
        ))
        .map_err(e)?;
        root.draw(&Text::new(
            format!("{}: {n} of {total}", o.label()),
            (x0 + 26, y0),
            left(16, &BLACK),
        ))
        .map_err(e)?;
    }
    root.draw(&Text::new(
        "scheme: a step its checks refuse (a solution exists). Newton diverged: residual ≥ 1e-3 in every attempt. Stall: an attempt came close. Failed cells: % of t_end reached.",
        (40, fy + 16 + 28 * 2 + 6),
        left(15, &BLACK),
    ))
    .map_err(e)?;
    Ok(())
}
