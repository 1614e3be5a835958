//! Snapshot charts (paper figs. 3 and 8): the deformed rods at several times, overlaid in
//! one picture, coloured from blue (first) to red (last).
//!
//! A planar model is drawn in its plane; a 3D model in an oblique parallel projection
//! (azimuth −35°, elevation 25°, e3 up), which keeps the staircase frame's three rods apart. Lengths are true (equal scales on both axes) unless the picture would be
//! more than [`MAX_ASPECT`] times wider than tall (the shallow arch: span 200, rise 3.15);
//! then the vertical axis is exaggerated and its label says by how much.

use std::path::Path;

use plotters::prelude::*;

use super::plot::{ensure_font, is_svg, BLACK_ISH, FONT};
use super::OutputError;
use crate::integrator::Simulation;
use crate::model::{Plane, Vec3};

/// Width / height beyond which the vertical axis is exaggerated.
const MAX_ASPECT: f64 = 4.0;
const SIZE: (u32, u32) = (1100, 800);

/// The rods (as polylines of node positions), the rigid links (pivot, node) and the time
/// of one level.
#[derive(Clone, Debug)]
pub struct Snapshot {
    /// Time.
    pub t: f64,
    /// One polyline per rod, in element order.
    pub rods: Vec<Vec<Vec3>>,
    /// Rigid links as (pivot, node position).
    pub links: Vec<(Vec3, Vec3)>,
}

impl Snapshot {
    /// The current level of `sim`.
    pub fn of(sim: &Simulation) -> Self {
        let (model, state) = (sim.model(), sim.state());
        let rods = model
            .rods
            .iter()
            .map(|rod| {
                let els = &model.elements[rod.elements.clone()];
                let mut line: Vec<Vec3> = Vec::with_capacity(els.len() + 1);
                for el in els {
                    let (a, b) = (state.r[el.nodes[0]], state.r[el.nodes[1]]);
                    if line.last() != Some(&a) {
                        line.push(a);
                    }
                    line.push(b);
                }
                line
            })
            .collect();
        let links = model
            .links
            .iter()
            .map(|l| (l.pivot, state.r[l.node]))
            .collect();
        Self {
            t: state.t,
            rods,
            links,
        }
    }
}

/// How 3D points map to the page, and the axis names.
#[derive(Clone, Copy)]
enum Projection {
    Planar(Plane),
    Oblique,
}

impl Projection {
    fn apply(&self, x: &Vec3) -> (f64, f64) {
        match self {
            Self::Planar(p) => {
                let (i, j) = match p.normal {
                    0 => (1, 2),
                    1 => (0, 2),
                    _ => (0, 1),
                };
                (x[i], x[j])
            }
            Self::Oblique => {
                let (right, up) = oblique_axes();
                (x.dot(&right), x.dot(&up))
            }
        }
    }

    fn axis_names(&self) -> (&'static str, &'static str) {
        match self {
            Self::Planar(p) => match p.normal {
                0 => ("e2", "e3"),
                1 => ("e1", "e3"),
                _ => ("e1", "e2"),
            },
            Self::Oblique => ("oblique view, horizontal", "oblique view, vertical"),
        }
    }
}

/// Viewing direction of the 3D projection: azimuth −35° (from e1 toward −e2), elevation
/// 25°. Not the isometric (1, 1, 1) direction, along which the staircase frame's free end
/// would fall onto its first corner.
const AZIMUTH_DEG: f64 = -35.0;
const ELEVATION_DEG: f64 = 25.0;

/// Page axes (right, up) of the oblique projection: e3 stays vertical on the page.
fn oblique_axes() -> (Vec3, Vec3) {
    let (az, el) = (AZIMUTH_DEG.to_radians(), ELEVATION_DEG.to_radians());
    let view = Vec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
    let right = Vec3::z().cross(&view).normalize();
    let up = view.cross(&right);
    (right, up)
}

fn lerp_color(f: f64) -> RGBColor {
    let (a, b) = ((31.0, 119.0, 180.0), (214.0, 39.0, 40.0));
    let m = |x: f64, y: f64| (x + (y - x) * f.clamp(0.0, 1.0)).round() as u8;
    RGBColor(m(a.0, b.0), m(a.1, b.1), m(a.2, b.2))
}

/// Draws `snapshots` into `path` (PNG, or SVG by extension). `planar` picks the
/// projection (`None`: oblique 3D view); `unit` names the length unit on the axes.
pub fn plot_snapshots(
    path: &Path,
    title: &str,
    snapshots: &[Snapshot],
    planar: Option<Plane>,
    unit: &str,
) -> Result<(), OutputError> {
    ensure_font();
    let proj = planar.map_or(Projection::Oblique, Projection::Planar);
    let to_err = |message: String| OutputError::Plot {
        path: path.to_path_buf(),
        message,
    };
    let r = if is_svg(path) {
        let root = SVGBackend::new(path, SIZE).into_drawing_area();
        draw(&root, SIZE, title, snapshots, snapshots, proj, unit)
            .and_then(|()| root.present().map_err(|e| e.to_string()))
    } else {
        let root = BitMapBackend::new(path, SIZE).into_drawing_area();
        draw(&root, SIZE, title, snapshots, snapshots, proj, unit)
            .and_then(|()| root.present().map_err(|e| e.to_string()))
    };
    r.map_err(to_err)
}

/// Frames of the animated GIF: this size, this many milliseconds each.
const GIF_SIZE: (u32, u32) = (800, 600);
const GIF_DELAY_MS: u32 = 60;

/// Writes `frames` as an animated GIF (one frame per snapshot, fixed axes fitted to all
/// frames, the time in each frame's caption).
pub fn animate_snapshots(
    path: &Path,
    title: &str,
    frames: &[Snapshot],
    planar: Option<Plane>,
    unit: &str,
) -> Result<(), OutputError> {
    ensure_font();
    let proj = planar.map_or(Projection::Oblique, Projection::Planar);
    let r = (|| -> Result<(), String> {
        let root = BitMapBackend::gif(path, GIF_SIZE, GIF_DELAY_MS)
            .map_err(|e| e.to_string())?
            .into_drawing_area();
        for f in frames {
            draw(
                &root,
                GIF_SIZE,
                title,
                std::slice::from_ref(f),
                frames,
                proj,
                unit,
            )?;
            root.present().map_err(|e| e.to_string())?;
        }
        Ok(())
    })();
    r.map_err(|message| OutputError::Plot {
        path: path.to_path_buf(),
        message,
    })
}

/// Draws `snapshots` on axes fitted to `fit` (the same snapshots for a still picture, all
/// frames for an animation).
fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    size: (u32, u32),
    title: &str,
    snapshots: &[Snapshot],
    fit: &[Snapshot],
    proj: Projection,
    unit: &str,
) -> Result<(), String> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(err)?;
    let pts = fit.iter().flat_map(|s| {
        s.rods
            .iter()
            .flatten()
            .chain(s.links.iter().flat_map(|(p, x)| [p, x]))
            .map(|x| proj.apply(x))
    });
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for (x, y) in pts.filter(|(x, y)| x.is_finite() && y.is_finite()) {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    if !x0.is_finite() {
        (x0, x1, y0, y1) = (-1.0, 1.0, -1.0, 1.0);
    }
    let span = (x1 - x0).max(y1 - y0).max(1e-12);
    let (mut w, mut h) = ((x1 - x0).max(1e-3 * span), (y1 - y0).max(1e-3 * span));
    // Equal scales: widen the shorter side to the page's aspect, unless that would
    // flatten the picture beyond recognition.
    let page = (size.0 as f64 - 160.0) / (size.1 as f64 - 200.0);
    let mut exaggeration = 1.0;
    if w / h > MAX_ASPECT {
        exaggeration = (w / h) / page;
    } else if w / h > page {
        h = w / page;
    } else {
        w = h * page;
    }
    let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let (w, h) = (1.08 * w, 1.12 * h);
    let (xr, yr) = (
        (cx - 0.5 * w)..(cx + 0.5 * w),
        (cy - 0.5 * h)..(cy + 0.5 * h),
    );

    let t_first = snapshots.first().map_or(0.0, |s| s.t);
    let t_last = snapshots.last().map_or(0.0, |s| s.t);
    let caption = if snapshots.len() > 1 {
        format!(
            "{} snapshots, t = {} (blue) … {} (red)",
            snapshots.len(),
            fmt_t(t_first),
            fmt_t(t_last)
        )
    } else {
        format!("t = {}", fmt_t(t_first))
    };
    let body = root
        .titled(title, (FONT, 28).into_font().color(&BLACK))
        .map_err(err)?;
    let (names_x, names_y) = proj.axis_names();
    let y_desc = if exaggeration > 1.0 {
        format!("{names_y} [{unit}] (vertical scale ×{exaggeration:.0})")
    } else {
        format!("{names_y} [{unit}]")
    };
    let mut chart = ChartBuilder::on(&body)
        .caption(caption, (FONT, 20))
        .margin(12)
        .margin_right(30)
        .x_label_area_size(60)
        .y_label_area_size(90)
        .build_cartesian_2d(xr, yr)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(format!("{names_x} [{unit}]"))
        .y_desc(y_desc)
        .label_style((FONT, 17))
        .axis_desc_style((FONT, 20))
        .light_line_style(RGBColor(238, 238, 238))
        .bold_line_style(RGBColor(208, 208, 208))
        .draw()
        .map_err(err)?;
    let n = snapshots.len().max(2) - 1;
    for (k, s) in snapshots.iter().enumerate() {
        let color = lerp_color(k as f64 / n as f64);
        for (p, x) in &s.links {
            let line = vec![proj.apply(p), proj.apply(x)];
            chart
                .draw_series(std::iter::once(PathElement::new(
                    line,
                    ShapeStyle::from(&color.mix(0.45)).stroke_width(1),
                )))
                .map_err(err)?;
        }
        for rod in &s.rods {
            let line: Vec<(f64, f64)> = rod.iter().map(|x| proj.apply(x)).collect();
            chart
                .draw_series(std::iter::once(PathElement::new(
                    line.clone(),
                    ShapeStyle::from(&color).stroke_width(2),
                )))
                .map_err(err)?;
            chart
                .draw_series(line.iter().map(|&p| Circle::new(p, 2, color.filled())))
                .map_err(err)?;
        }
    }
    // Pivots of rigid links: fixed, drawn once.
    if let Some(s) = snapshots.first() {
        chart
            .draw_series(
                s.links
                    .iter()
                    .map(|(p, _)| TriangleMarker::new(proj.apply(p), 7, BLACK_ISH.filled())),
            )
            .map_err(err)?;
    }
    Ok(())
}

fn fmt_t(t: f64) -> String {
    let s = format!("{t:.4}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}
