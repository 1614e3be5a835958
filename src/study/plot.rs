//! `work_precision.png` (log-log error against wall time, one line per scheme) and
//! `stability.png` (heat maps of the fraction of the run completed, one panel per scheme).
//! Same embedded font as the run charts.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::{Damping, ModeKind, SchemeKind, SchemeSpec, Stability, WorkPrecision, PARAMETERS};
use crate::observe::record::RunStatus;
use crate::output::{ensure_font, OutputError, FONT};

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

/// Draws `work_precision.png`: error against wall time on log-log axes, one line per
/// scheme/parameter (points ordered by Δt, labelled in the legend with the observed
/// order), failed runs as crosses on the bottom edge at their wall time.
pub fn plot_work_precision(path: &Path, wp: &WorkPrecision) -> Result<(), OutputError> {
    ensure_font();
    let root = BitMapBackend::new(path, (1100, 800)).into_drawing_area();
    draw_wp(&root, wp).map_err(plot_err(path))?;
    root.present().map_err(|e| plot_err(path)(e.to_string()))
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
    let title = format!(
        "{}: work–precision (t_end = {}, reference EM Δt = {:e})",
        wp.scene, wp.t_end, wp.reference_dt
    );
    let h_px = root.dim_in_pixel().1;
    let (main, foot) = root.split_vertically(h_px - 28);
    let mut chart = ChartBuilder::on(&main)
        .caption(title, (FONT, 26))
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
    let mut specs: Vec<SchemeSpec> = Vec::new();
    for r in &wp.rows {
        if !specs.contains(&r.spec) {
            specs.push(r.spec);
        }
    }
    for (i, spec) in specs.iter().enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        let mut rows: Vec<_> = ok.iter().filter(|r| r.spec == *spec).collect();
        rows.sort_by(|a, b| b.dt.total_cmp(&a.dt));
        let order = wp
            .rows
            .iter()
            .find(|r| r.spec == *spec)
            .map_or(f64::NAN, |r| r.observed_order);
        let failed = wp
            .rows
            .iter()
            .filter(|r| r.spec == *spec && r.status == RunStatus::Failed)
            .count();
        let label = format!(
            "{} (order {}){}",
            spec.label(),
            if order.is_finite() {
                format!("{order:.2}")
            } else {
                "n/a".into()
            },
            if failed > 0 {
                format!(", {failed} failed")
            } else {
                String::new()
            }
        );
        let pts: Vec<(f64, f64)> = rows.iter().map(|r| (wall(r.wall_s), r.error)).collect();
        let style = ShapeStyle::from(color).stroke_width(2);
        chart
            .draw_series(LineSeries::new(pts.clone(), style))
            .map_err(e)?
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], style));
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 5, color.filled())))
            .map_err(e)?;
        // Δt next to each point.
        chart
            .draw_series(rows.iter().map(|r| {
                EmptyElement::at((wall(r.wall_s), r.error))
                    + Text::new(
                        format!("Δt={}", r.dt),
                        (9, -4),
                        (FONT, 13).into_font().color(&color),
                    )
            }))
            .map_err(e)?;
        chart
            .draw_series(
                wp.rows
                    .iter()
                    .filter(|r| r.spec == *spec && r.status == RunStatus::Failed)
                    .map(|r| Cross::new((wall(r.wall_s), yl * 1.15), 8, color.stroke_width(3))),
            )
            .map_err(e)?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FONT, 17))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(e)?;
    let (w, _) = foot.dim_in_pixel();
    foot.draw(&Text::new(
        "× on the bottom edge: failed run (at its wall time); lower-left is better",
        (w as i32 - 30, 22),
        (FONT, 15)
            .into_font()
            .color(&BLACK)
            .pos(Pos::new(HPos::Right, VPos::Bottom)),
    ))
    .map_err(e)?;
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
/// the fraction of the run completed, its text the percentage reached and the largest
/// relative energy growth `(H − H_0 − W)/H_0` (`≤0` when no energy was created).
pub fn plot_stability(path: &Path, st: &Stability) -> Result<(), OutputError> {
    ensure_font();
    let kinds = &st.config.kinds;
    let cols = kinds.len().clamp(1, 3);
    let rows = kinds.len().div_ceil(cols).max(1);
    let size = (560 * cols as u32, 440 * rows as u32 + 110);
    let root = BitMapBackend::new(path, size).into_drawing_area();
    draw_stability(&root, st, rows, cols).map_err(plot_err(path))?;
    root.present().map_err(|e| plot_err(path)(e.to_string()))
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
    let (body, foot) = rest.split_vertically(h - 60 - 50);
    head.draw(&Text::new(
        format!("{}: stability map (t_end = {})", st.scene, st.config.t_end),
        (w as i32 / 2, 30),
        (FONT, 26)
            .into_font()
            .color(&BLACK)
            .pos(Pos::new(HPos::Center, VPos::Center)),
    ))
    .map_err(e)?;
    foot.draw(&Text::new(
        "colour: fraction of t_end reached (red 0 → yellow ½ → green 1); cell: % reached and largest relative energy growth (H − H₀ − W)/H₀ (ΔH≤0: no growth beyond 1e-9)",
        (w as i32 / 2, 22),
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
    let y_desc = if kind.has_param() {
        format!("{} [–]", kind.param_symbol())
    } else {
        "(no parameter)".into()
    };
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
        .y_desc(y_desc)
        .axis_desc_style((FONT, 17))
        .draw()
        .map_err(e)?;
    let tick = (FONT, 14).into_font().color(&BLACK);
    for (i, dt) in dts.iter().enumerate() {
        let (px, py) = chart.backend_coord(&(i as f64 + 0.5, 0.0));
        root.draw(&Text::new(
            dt.to_string(),
            (px, py + 8),
            tick.pos(Pos::new(HPos::Center, VPos::Top)),
        ))
        .map_err(e)?;
    }
    if kind.has_param() {
        for (j, p) in params.iter().enumerate() {
            let (px, py) = chart.backend_coord(&(0.0, j as f64 + 0.5));
            root.draw(&Text::new(
                p.to_string(),
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
/// axes, one panel per mode (axial, bending), one line per dissipation parameter; EM's
/// ζ (round-off) is given in each panel's caption. Failed runs are left out of the lines.
pub fn plot_damping(path: &Path, d: &Damping) -> Result<(), OutputError> {
    ensure_font();
    let root = BitMapBackend::new(path, (1400, 700)).into_drawing_area();
    draw_damping(&root, d).map_err(plot_err(path))?;
    root.present().map_err(|e| plot_err(path)(e.to_string()))
}

/// Smallest ζ drawn (smaller values, e.g. EDMC-2 at small amplitude, sit on the floor).
const ZETA_FLOOR: f64 = 1e-8;

fn draw_damping<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    d: &Damping,
) -> Result<(), String> {
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| x.to_string();
    root.fill(&WHITE).map_err(e)?;
    let c = &d.config;
    let title = format!(
        "{}: modal damping ratio per dissipation parameter ({} steps per period, tip amplitude {:e} L, {} periods)",
        d.scene, c.steps_per_period, c.amplitude, c.periods
    );
    let (top, body) = root.split_vertically(40);
    top.draw(&Text::new(
        title,
        (20, 10),
        (FONT, 22).into_font().color(&BLACK),
    ))
    .map_err(e)?;
    let panels = body.split_evenly((1, 2));
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
        let caption = format!(
            "first {} mode, ωΔt = {:.3}; EM ζ = {}",
            mode.name(),
            rows.first().map_or(f64::NAN, |r| r.omega * r.dt),
            em.map_or("—".to_string(), |r| format!("{:.1e}", r.zeta))
        );
        let mut chart = ChartBuilder::on(panel)
            .caption(caption, (FONT, 20))
            .margin(15)
            .x_label_area_size(55)
            .y_label_area_size(80)
            .build_cartesian_2d((xl..xh).log_scale(), (yl..yh).log_scale())
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("parameter value (χ or α)")
            .y_desc("modal damping ratio ζ")
            .axis_desc_style((FONT, 18))
            .label_style((FONT, 15))
            .x_label_formatter(&|v| sci(*v))
            .y_label_formatter(&|v| sci(*v))
            .draw()
            .map_err(e)?;
        for (i, p) in PARAMETERS.iter().enumerate() {
            let color = PALETTE[i % PALETTE.len()];
            let style = if i < 4 {
                ShapeStyle::from(&color).stroke_width(2)
            } else {
                ShapeStyle::from(&color).stroke_width(1)
            };
            let pts: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| r.param == p.key && ok(r))
                .map(|r| (r.value, r.zeta.max(ZETA_FLOOR)))
                .collect();
            if pts.is_empty() {
                continue;
            }
            chart
                .draw_series(LineSeries::new(pts.clone(), style))
                .map_err(e)?
                .label(p.symbol)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
            if i < 4 {
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
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .label_font((FONT, 15))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(e)?;
    }
    Ok(())
}
