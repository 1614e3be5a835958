//! Chart content (issue 20): what a broken chart would change, not only that a file exists.
//!
//! The charts are drawn once as SVG (same layout code as the PNG, vector output) and the
//! data lines are read back from the `<polyline>`s: one line per series in its colour,
//! every sample where an affine map of (t, value) puts it (one map for all series of a
//! panel, y growing downwards), and the axes fitted to the data (the data fill most of the
//! plot area). The PNG drawn from the same records must then carry each series' colour
//! at the pixels the SVG puts its samples at.

mod common;

use cosserat::model::Vec3;
use cosserat::observe::record::StepRecord;
use cosserat::output::{plot_energy, plot_momenta};

const BLACK_ISH: &str = "#141414";
const RED: &str = "#D62728";
const BLUE: &str = "#1F77B4";
const ORANGE: &str = "#FF7F0E";
const GREEN: &str = "#2CA02C";

/// What a series charts of a record.
type Value<'a> = &'a dyn Fn(&StepRecord) -> f64;

/// 201 records over t ∈ [0, 10]: K = 2 + sin t, V = 5 − sin t, H = 7 (constant), L and J
/// with distinct ranges per component.
fn records() -> Vec<StepRecord> {
    (0..=200)
        .map(|i| {
            let t = 0.05 * i as f64;
            StepRecord {
                step: i,
                t,
                kinetic: 2.0 + t.sin(),
                potential: 5.0 - t.sin(),
                total: 7.0,
                l: Vec3::new(t.cos(), 0.5 * t, -1.0),
                j: Vec3::new(10.0, 10.0 + 5.0 * t.sin(), 12.0 - 0.2 * t),
                ..Default::default()
            }
        })
        .collect()
}

/// `(stroke colour, points)` of every `<polyline>` in an SVG document.
fn polylines(svg: &str) -> Vec<(String, Vec<(f64, f64)>)> {
    let attr = |tag: &str, name: &str| -> Option<String> {
        let key = format!(" {name}=\"");
        let i = tag.find(&key)? + key.len();
        Some(tag[i..i + tag[i..].find('"')?].to_string())
    };
    svg.split("<polyline")
        .skip(1)
        .map(|rest| {
            let tag = &rest[..rest.find("/>").unwrap()];
            let stroke = attr(tag, "stroke").unwrap_or_default();
            let pts = attr(tag, "points")
                .unwrap_or_default()
                .split_whitespace()
                .map(|p| {
                    let (x, y) = p.split_once(',').unwrap();
                    (x.parse().unwrap(), y.parse().unwrap())
                })
                .collect();
            (stroke, pts)
        })
        .collect()
}

/// The data lines of colour `c`: its polylines with more than 10 points (legend samples
/// have two), longest first.
fn data_lines(lines: &[(String, Vec<(f64, f64)>)], c: &str) -> Vec<Vec<(f64, f64)>> {
    let mut v: Vec<_> = lines
        .iter()
        .filter(|(s, p)| s == c && p.len() > 10)
        .map(|(_, p)| p.clone())
        .collect();
    v.sort_by_key(|p| std::cmp::Reverse(p.len()));
    v
}

/// Least-squares `y ≈ a x + b`; returns `(a, b, largest residual)`.
fn fit(pairs: &[(f64, f64)]) -> (f64, f64, f64) {
    let n = pairs.len() as f64;
    let (mx, my) = (
        pairs.iter().map(|p| p.0).sum::<f64>() / n,
        pairs.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxx: f64 = pairs.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pairs.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let a = sxy / sxx;
    let b = my - a * mx;
    let worst = pairs
        .iter()
        .map(|p| (p.1 - (a * p.0 + b)).abs())
        .fold(0.0, f64::max);
    (a, b, worst)
}

/// Matches each drawn point of `line` with the record whose time maps nearest to its x
/// (x is affine in t), and returns the `(data, pixel)` pairs for x and for y.
#[allow(clippy::type_complexity)]
fn pairs(
    line: &[(f64, f64)],
    recs: &[StepRecord],
    value: impl Fn(&StepRecord) -> f64,
) -> (Vec<(f64, f64)>, Vec<(f64, f64)>) {
    // Points are in time order; the first and last are the first and last records
    // (decimation keeps both ends).
    let (x0, x1) = (line[0].0, line[line.len() - 1].0);
    let (t0, t1) = (recs[0].t, recs[recs.len() - 1].t);
    let mut xs = Vec::new();
    let mut ys = Vec::new();
    for &(x, y) in line {
        let t = t0 + (x - x0) / (x1 - x0) * (t1 - t0);
        let r = recs
            .iter()
            .min_by(|a, b| (a.t - t).abs().total_cmp(&(b.t - t).abs()))
            .unwrap();
        xs.push((r.t, x));
        ys.push((value(r), y));
    }
    (xs, ys)
}

#[test]
fn energy_chart_draws_each_series_where_its_data_are() {
    let recs = records();
    let dir = tempfile::tempdir().unwrap();
    let svg_path = dir.path().join("energy.svg");
    plot_energy(&svg_path, &recs, "energy").unwrap();
    keep(&svg_path);
    let svg = std::fs::read_to_string(&svg_path).unwrap();
    let lines = polylines(&svg);
    let (w, h) = (1000.0, 700.0);

    let series: [(&str, Value); 3] = [
        (BLACK_ISH, &|r| r.total),
        (RED, &|r| r.kinetic),
        (BLUE, &|r| r.potential),
    ];
    let mut maps = Vec::new();
    for (colour, value) in series {
        let found = data_lines(&lines, colour);
        assert_eq!(found.len(), 1, "{colour}: {} data lines", found.len());
        let line = &found[0];
        assert!(line.len() >= 100, "{colour}: {} points", line.len());
        let (xs, ys) = pairs(line, &recs, value);
        let (ax, bx, ex) = fit(&xs);
        assert!(ex <= 1.0, "{colour}: x off the time axis by {ex} px");
        maps.push((ax, bx));
        if colour != BLACK_ISH {
            let (ay, by, ey) = fit(&ys);
            assert!(ey <= 1.0, "{colour}: y off the value axis by {ey} px");
            assert!(ay < 0.0, "{colour}: larger values must be drawn higher");
            maps.push((ay, by));
        } else {
            // H is constant: a flat line.
            let spread = line.iter().map(|p| p.1).fold(f64::NAN, f64::max)
                - line.iter().map(|p| p.1).fold(f64::NAN, f64::min);
            assert!(spread <= 1.0, "total energy line not flat: {spread} px");
        }
    }
    // One coordinate system: K and V share the time map and the value map; H = 7 lies
    // on that value map too.
    let (tx, kv, vv) = (maps[0], maps[2], maps[4]);
    // (Pixel coordinates are whole numbers: slopes agree to 1 %, maps to 2 px.)
    let same = |a: (f64, f64), b: (f64, f64), over: f64| {
        (a.0 - b.0).abs() * over <= 2.0 && (a.1 - b.1 + (a.0 - b.0) * over / 2.0).abs() <= 2.0
    };
    for m in [maps[1], maps[3]] {
        assert!(same(m, tx, 10.0), "time maps {m:?} vs {tx:?}");
    }
    assert!(same(kv, vv, 6.0), "value maps {kv:?} vs {vv:?}");
    let h_line = &data_lines(&lines, BLACK_ISH)[0];
    assert!((h_line[0].1 - (kv.0 * 7.0 + kv.1)).abs() <= 1.0);
    // The axes come from the data: t ∈ [0, 10] spans most of the width, the values
    // [1, 7] most of the height (a fixed or wrongly computed range would squash them).
    let x_span = tx.0 * 10.0;
    let y_span = -kv.0 * 6.0;
    assert!(
        x_span > 0.7 * w && x_span < w,
        "time axis spans {x_span} px of {w}"
    );
    assert!(
        y_span > 0.55 * h && y_span < h,
        "value axis spans {y_span} px of {h}"
    );
    // A legend entry per series.
    for label in ["total H = K + V", "kinetic K", "potential V"] {
        assert!(svg.contains(label), "legend lacks {label}");
    }

    // The PNG from the same records shows each series' colour where the SVG puts it.
    let png_path = dir.path().join("energy.png");
    plot_energy(&png_path, &recs, "energy").unwrap();
    keep(&png_path);
    let img = decode(&png_path);
    for (colour, _) in series {
        let rgb = parse_hex(colour);
        let line = &data_lines(&lines, colour)[0];
        let hits = line
            .iter()
            .filter(|&&(x, y)| img.near(x, y, rgb, 2))
            .count();
        assert!(
            hits * 10 >= line.len() * 9,
            "{colour}: {hits} of {} samples drawn in the PNG",
            line.len()
        );
    }
}

#[test]
fn momenta_chart_has_two_panels_of_three_components() {
    let recs = records();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("momenta.svg");
    plot_momenta(&path, &recs, "momenta").unwrap();
    keep(&path);
    let svg = std::fs::read_to_string(&path).unwrap();
    let lines = polylines(&svg);
    // Per colour: the L line (upper panel) and the J line (lower panel).
    let comps: [(&str, Value, Value); 3] = [
        (BLUE, &|r| r.l.x, &|r| r.j.x),
        (ORANGE, &|r| r.l.y, &|r| r.j.y),
        (GREEN, &|r| r.l.z, &|r| r.j.z),
    ];
    let mut value_maps = [Vec::new(), Vec::new()];
    for (colour, lf, jf) in comps {
        let mut found = data_lines(&lines, colour);
        assert_eq!(found.len(), 2, "{colour}: {} data lines", found.len());
        found.sort_by(|a, b| a[0].1.total_cmp(&b[0].1));
        let mean_y = |p: &Vec<(f64, f64)>| p.iter().map(|q| q.1).sum::<f64>() / p.len() as f64;
        assert!(mean_y(&found[0]) < mean_y(&found[1]));
        for (panel, (line, f)) in found.iter().zip([lf, jf]).enumerate() {
            let (_, ys) = pairs(line, &recs, f);
            let spread = ys.iter().map(|p| p.0).fold(f64::NAN, f64::max)
                - ys.iter().map(|p| p.0).fold(f64::NAN, f64::min);
            if spread > 0.0 {
                let (a, b, e) = fit(&ys);
                assert!(e <= 1.0, "{colour} panel {panel}: off by {e} px");
                value_maps[panel].push((a, b));
            }
        }
    }
    // Each panel has one value map shared by its components, and the two differ.
    for maps in &value_maps {
        assert!(maps.len() >= 2);
        for m in &maps[1..] {
            assert!((m.0 - maps[0].0).abs() <= 1e-3 * maps[0].0.abs());
            assert!((m.1 - maps[0].1).abs() <= 1.0);
        }
    }
    assert!((value_maps[0][0].1 - value_maps[1][0].1).abs() > 100.0);
}

#[test]
fn tiny_values_are_scaled_by_a_power_of_ten_the_axis_names() {
    let mut recs = records();
    for r in &mut recs {
        r.kinetic *= 1e-8;
        r.potential *= 1e-8;
        r.total *= 1e-8;
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("energy.svg");
    plot_energy(&path, &recs, "tiny").unwrap();
    keep(&path);
    let svg = std::fs::read_to_string(&path).unwrap();
    assert!(
        svg.contains("energy [10⁻⁸ J]"),
        "axis description lacks 10⁻⁸"
    );
    // Still drawn across the plot, not collapsed onto zero.
    let line = &data_lines(&polylines(&svg), RED)[0];
    let spread = line.iter().map(|p| p.1).fold(f64::NAN, f64::max)
        - line.iter().map(|p| p.1).fold(f64::NAN, f64::min);
    assert!(spread > 100.0, "kinetic line spans {spread} px");
}

fn parse_hex(c: &str) -> [u8; 3] {
    let v = u32::from_str_radix(&c[1..], 16).unwrap();
    [(v >> 16) as u8, (v >> 8) as u8, v as u8]
}

struct Image {
    w: usize,
    h: usize,
    rgb: Vec<u8>,
}

impl Image {
    /// Whether a pixel within `r` of `(x, y)` has colour `c` (to ±40 per channel:
    /// antialiased edges).
    fn near(&self, x: f64, y: f64, c: [u8; 3], r: i64) -> bool {
        let (x, y) = (x.round() as i64, y.round() as i64);
        (-r..=r).any(|dy| {
            (-r..=r).any(|dx| {
                let (px, py) = (x + dx, y + dy);
                if px < 0 || py < 0 || px >= self.w as i64 || py >= self.h as i64 {
                    return false;
                }
                let i = (py as usize * self.w + px as usize) * 3;
                (0..3).all(|k| (self.rgb[i + k] as i32 - c[k] as i32).abs() <= 40)
            })
        })
    }
}

fn decode(path: &std::path::Path) -> Image {
    let (w, h, rgb) = common::image_rgb(path);
    Image { w, h, rgb }
}

// ---------------------------------------------------------------------------------------
// Every chart kind, drawn as SVG (same layout code as the PNG) and as PNG: the PNG is not
// blank (each series' colour is on it) and the SVG's text lists what was run.

use std::collections::HashMap;

use cosserat::observe::record::RunStatus;
use cosserat::output::{plot_accelerations, plot_snapshots, Snapshot};
use cosserat::study::{
    asymptotic_fit, plot_damping, plot_from_rest, plot_stability, plot_work_precision, Damping,
    DampingConfig, DampingRow, FromRest, FromRestCell, FromRestConfig, FromRestRow, MemberResult,
    ModeKind, Outcome, SchemeKind, SchemeSpec, Stability, StabilityConfig, WorkPrecision,
    WorkPrecisionRow, PARAMETERS,
};

/// One SVG element: tag name, attributes, and the text up to the next tag (unescaped).
struct Element {
    name: String,
    attrs: HashMap<String, String>,
    text: String,
}

fn unescape(s: &str) -> String {
    s.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&apos;", "'")
        .replace("&amp;", "&")
}

fn elements(svg: &str) -> Vec<Element> {
    svg.split('<')
        .skip(1)
        .filter(|c| !c.starts_with('/') && !c.starts_with('?') && !c.starts_with('!'))
        .map(|chunk| {
            let end = chunk.find('>').unwrap_or(chunk.len());
            let (tag, rest) = chunk.split_at(end);
            let name: String = tag
                .chars()
                .take_while(|c| !c.is_whitespace() && *c != '/')
                .collect();
            let mut attrs = HashMap::new();
            let mut s = &tag[name.len()..];
            while let Some(eq) = s.find("=\"") {
                let key = s[..eq].trim().to_string();
                let v0 = eq + 2;
                let v1 = v0 + s[v0..].find('"').unwrap();
                attrs.insert(key, unescape(&s[v0..v1]));
                s = &s[v1 + 1..];
            }
            Element {
                name,
                attrs,
                text: unescape(rest.get(1..).unwrap_or("").trim()),
            }
        })
        .collect()
}

/// The text elements' contents.
fn texts(els: &[Element]) -> Vec<String> {
    els.iter()
        .filter(|e| e.name == "text")
        .map(|e| e.text.clone())
        .collect()
}

fn attr<'a>(e: &'a Element, k: &str) -> &'a str {
    e.attrs.get(k).map_or("", String::as_str)
}

fn points(e: &Element) -> Vec<(f64, f64)> {
    attr(e, "points")
        .split_whitespace()
        .map(|p| {
            let (x, y) = p.split_once(',').unwrap();
            (x.parse().unwrap(), y.parse().unwrap())
        })
        .collect()
}

/// Pixels of colour `c` (±40 per channel) in a PNG, and the share of non-white pixels.
fn coverage(path: &std::path::Path, colours: &[&str]) -> (Vec<usize>, f64) {
    let img = decode(path);
    let px = |i: usize| [img.rgb[3 * i], img.rgb[3 * i + 1], img.rgb[3 * i + 2]];
    let n = img.w * img.h;
    let inked = (0..n).filter(|&i| px(i).iter().any(|&v| v < 235)).count();
    let counts = colours
        .iter()
        .map(|c| {
            let rgb = parse_hex(c);
            (0..n)
                .filter(|&i| (0..3).all(|k| (px(i)[k] as i32 - rgb[k] as i32).abs() <= 40))
                .count()
        })
        .collect();
    (counts, inked as f64 / n as f64)
}

/// Approximate boxes of the horizontal text elements (0.6 em per character; from 0.75 em
/// above to 0.2 em below the baseline, which plotters' SVG places at `y + dy`): no two may
/// overlap.
fn assert_no_text_overlaps(els: &[Element]) {
    let boxes: Vec<(String, [f64; 4])> = els
        .iter()
        .filter(|e| e.name == "text" && !e.attrs.contains_key("transform") && !e.text.is_empty())
        .map(|e| {
            let num = |k: &str| attr(e, k).parse::<f64>().unwrap_or(0.0);
            let (x, y, size) = (num("x"), num("y"), num("font-size"));
            let dy = attr(e, "dy");
            let shift = if let Some(v) = dy.strip_suffix("ex") {
                0.5 * v.parse::<f64>().unwrap() * size
            } else if let Some(v) = dy.strip_suffix("em") {
                v.parse::<f64>().unwrap() * size
            } else {
                0.0
            };
            let w = 0.6 * size * e.text.chars().count() as f64;
            let x0 = match attr(e, "text-anchor") {
                "middle" => x - w / 2.0,
                "end" => x - w,
                _ => x,
            };
            let base = y + shift;
            (
                e.text.clone(),
                [x0, base - 0.75 * size, x0 + w, base + 0.2 * size],
            )
        })
        .collect();
    for (i, (ta, a)) in boxes.iter().enumerate() {
        for (tb, b) in &boxes[i + 1..] {
            // (The same text drawn twice at one place reads as one: a log axis's end tick.)
            let same = ta == tb && a == b;
            let overlap = !same && a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3];
            assert!(!overlap, "texts overlap: {ta:?} {a:?} and {tb:?} {b:?}");
        }
    }
}

const DTS: [f64; 4] = [0.02, 0.01, 0.005, 0.0025];

/// Rows of a scheme whose errors have the given local orders over [`DTS`], all completed,
/// fitted as `work_precision` fits them.
fn wp_rows(spec: &str, e0: f64, local: [f64; 3], cost: f64) -> Vec<WorkPrecisionRow> {
    let spec = SchemeSpec::parse(spec).unwrap();
    let mut e = e0;
    let mut rows: Vec<WorkPrecisionRow> = DTS
        .iter()
        .enumerate()
        .map(|(i, &dt)| {
            if i > 0 {
                e *= (DTS[i] / DTS[i - 1]).powf(local[i - 1]);
            }
            WorkPrecisionRow {
                spec,
                dt,
                error: e,
                wall_s: cost * DTS[0] / dt,
                status: RunStatus::Completed,
                newton_iters_total: 10,
                observed_order: f64::NAN,
                fit_dt_min: f64::NAN,
                fit_dt_max: f64::NAN,
                reason: None,
            }
        })
        .collect();
    refit(&mut rows);
    rows
}

/// Sets the rows' order and fitted range as `work_precision` does.
fn refit(rows: &mut [WorkPrecisionRow]) {
    let pts: Vec<(f64, f64)> = rows.iter().map(|r| (r.dt, r.error)).collect();
    let fit = asymptotic_fit(&pts);
    for r in rows {
        r.observed_order = fit.map_or(f64::NAN, |f| f.order);
        r.fit_dt_min = fit.map_or(f64::NAN, |f| f.dt_min);
        r.fit_dt_max = fit.map_or(f64::NAN, |f| f.dt_max);
    }
}

#[test]
fn work_precision_chart_states_orders_ranges_and_marks_points_outside_the_fit() {
    let mut rows = Vec::new();
    // EM: pre-asymptotic at the coarsest step, then order 2.
    rows.extend(wp_rows("em", 1e-2, [0.5, 2.0, 2.0], 0.01));
    // EDMC-1: order 1 throughout.
    rows.extend(wp_rows("edmc1:0.2", 8e-3, [1.0, 1.0, 1.0], 0.012));
    // Mid-point: the frame's orders, no asymptotic range.
    rows.extend(wp_rows("midpoint", 1.1e-2, [0.3, 1.2, 1.0], 0.009));
    // Generalized-α: the coarsest run failed, the rest order 2.
    let mut ga = wp_rows("gen-alpha:0.8", 1e-2, [2.0, 2.0, 2.0], 0.02);
    ga[0].error = f64::NAN;
    ga[0].status = RunStatus::Failed;
    refit(&mut ga);
    rows.extend(ga);
    let wp = WorkPrecision {
        scene: "synthetic".into(),
        rows,
        reference_dt: 3.125e-4,
        sample_dt: 0.02,
        t_end: 1.0,
    };
    let dir = tempfile::tempdir().unwrap();
    let svg_path = dir.path().join("wp.svg");
    plot_work_precision(&svg_path, &wp).unwrap();
    keep(&svg_path);
    let els = elements(&std::fs::read_to_string(&svg_path).unwrap());
    let text = texts(&els);
    // The legend: each scheme with its order and fitted range, or no range.
    for label in [
        "EM: order 2.00 (fit over Δt 0.0025–0.01)",
        "EDMC-1 χ=0.2: order 1.00 (fit over Δt 0.0025–0.02)",
        "mid-point: no asymptotic range",
        "gen-α ρ∞=0.8: order 2.00 (fit over Δt 0.0025–0.01)",
    ] {
        assert!(
            text.iter().any(|t| t == label),
            "legend lacks {label:?}: {text:?}"
        );
    }
    assert!(text.iter().any(|t| t.contains("1 failed")), "{text:?}");
    // What hollow means, and why an order can be below the nominal one.
    assert!(text.iter().any(|t| t.starts_with("hollow")), "{text:?}");
    assert!(text.iter().any(|t| t.contains("sudden load")), "{text:?}");
    // Δt in a legend of marker shapes, once each; no Δt text at the points.
    for dt in DTS {
        let label = format!("Δt = {dt}");
        assert_eq!(text.iter().filter(|t| **t == label).count(), 1, "{label}");
    }
    assert!(!text.iter().any(|t| t.starts_with("Δt=")), "{text:?}");
    assert_no_text_overlaps(&els);
    // Markers per scheme colour: filled inside the fitted range, hollow outside.
    let filled = |c: &str| {
        els.iter()
            .filter(|e| {
                (e.name == "polygon" && attr(e, "fill") == c)
                    || (e.name == "circle" && attr(e, "fill") == c)
            })
            .count()
    };
    let hollow = |c: &str| {
        els.iter()
            .filter(|e| {
                (e.name == "circle" && attr(e, "fill") == "none" && attr(e, "stroke") == c)
                    || (e.name == "polyline" && attr(e, "stroke") == c && {
                        let p = points(e);
                        p.len() >= 4 && p.first() == p.last()
                    })
            })
            .count()
    };
    // (colour, filled, hollow): EM 3 + 1, EDMC-1 4 + 0, mid-point 0 + 4, gen-α 3 + 0
    // (its failed run is a cross).
    for (c, f, h) in [(BLACK_ISH, 3, 1), (RED, 4, 0), (BLUE, 0, 4), (GREEN, 3, 0)] {
        assert_eq!((filled(c), hollow(c)), (f, h), "markers of {c}");
    }

    let png = dir.path().join("wp.png");
    plot_work_precision(&png, &wp).unwrap();
    keep(&png);
    let (counts, inked) = coverage(&png, &[BLACK_ISH, RED, BLUE, GREEN]);
    assert!(inked > 0.02, "{inked}");
    assert!(counts.iter().all(|&n| n > 100), "{counts:?}");
}

fn cell(kind: SchemeKind, param: f64, dt: f64, fraction: f64, growth: f64) -> MemberResult {
    MemberResult {
        kind,
        param,
        dt,
        t_end: 10.0,
        status: if fraction < 1.0 {
            RunStatus::Failed
        } else {
            RunStatus::Completed
        },
        t_reached: 10.0 * fraction,
        reason: None,
        wall_s: 0.1,
        newton_iters_total: 10,
        max_energy_growth: growth,
        energy_initial: 1.0,
        energy_final: 1.0,
        max_rel_dl: 0.0,
        max_rel_dj: 0.0,
        samples: Vec::new(),
    }
}

#[test]
fn stability_chart_shows_each_scheme_panel_and_the_fixed_step_title() {
    let config = StabilityConfig {
        kinds: vec![SchemeKind::Em, SchemeKind::Edmc2, SchemeKind::Midpoint],
        params: vec![0.0, 1.0],
        rho_infs: vec![0.8],
        dts: vec![0.1, 0.4],
        t_end: 10.0,
        jobs: 1,
    };
    let cells = vec![
        cell(SchemeKind::Em, 0.0, 0.1, 1.0, -1e-12),
        cell(SchemeKind::Em, 0.0, 0.4, 0.44, -1e-12),
        cell(SchemeKind::Edmc2, 0.0, 0.1, 1.0, 0.0),
        cell(SchemeKind::Edmc2, 0.0, 0.4, 0.5, 0.0),
        cell(SchemeKind::Edmc2, 1.0, 0.1, 1.0, 0.0),
        cell(SchemeKind::Edmc2, 1.0, 0.4, 1.0, 0.0),
        cell(SchemeKind::Midpoint, 0.0, 0.1, 1.0, 2e-3),
        cell(SchemeKind::Midpoint, 0.0, 0.4, 0.08, 2.0),
    ];
    let st = Stability {
        scene: "synthetic".into(),
        config,
        cells,
    };
    let dir = tempfile::tempdir().unwrap();
    let svg_path = dir.path().join("st.svg");
    plot_stability(&svg_path, &st).unwrap();
    keep(&svg_path);
    let els = elements(&std::fs::read_to_string(&svg_path).unwrap());
    let text = texts(&els);
    assert!(
        text.iter()
            .any(|t| t.contains("stability map, fixed step (no cut-back), t_end = 10")),
        "{text:?}"
    );
    for panel in ["EM", "EDMC-2", "mid-point"] {
        assert!(
            text.iter().any(|t| t == panel),
            "no panel {panel}: {text:?}"
        );
    }
    // Axes and colour say what they show.
    assert!(text.iter().any(|t| t == "time step Δt [s]"));
    assert!(text.iter().any(|t| t == "α = α_Γv [–]"), "{text:?}");
    assert!(text.iter().any(|t| t.contains("fraction of t_end reached")));
    for cell_text in ["100%", "44%", "8%", "ΔH≤0", "ΔH+2e-3", "ΔH+2e0"] {
        assert!(text.iter().any(|t| t == cell_text), "no cell {cell_text}");
    }
    assert_no_text_overlaps(&els);

    let png = dir.path().join("st.png");
    plot_stability(&png, &st).unwrap();
    keep(&png);
    // Completed cells are green, the 8 % cell red.
    let (counts, inked) = coverage(&png, &["#1A9850", "#D73027"]);
    assert!(inked > 0.2, "{inked}");
    assert!(counts.iter().all(|&n| n > 1000), "{counts:?}");
}

#[test]
fn from_rest_chart_colours_each_outcome_and_counts_them() {
    let rows = vec![
        FromRestRow::parse("em", 0.0).unwrap(),
        FromRestRow::parse("chi_nu", 0.5).unwrap(),
    ];
    let dts = vec![0.02, 0.05, 0.1];
    let cell = |row: FromRestRow, dt: f64, outcome: Outcome, reached: f64| FromRestCell {
        row,
        dt,
        t_end: 2.0,
        t_reached: reached,
        outcome,
        reason: (outcome != Outcome::Completed).then(|| "why".to_string()),
        newton_iters_total: 10,
        cutback_steps: 0,
        max_energy_growth: -1e-12,
    };
    let cells = vec![
        cell(rows[0], 0.02, Outcome::Completed, 2.0),
        cell(rows[0], 0.05, Outcome::Completed, 2.0),
        cell(rows[0], 0.1, Outcome::ElementTurn, 1.5),
        cell(rows[1], 0.02, Outcome::Completed, 2.0),
        cell(rows[1], 0.05, Outcome::SolverStall, 0.2),
        cell(rows[1], 0.1, Outcome::NewtonDivergence, 1.0),
    ];
    let fr = FromRest {
        scene: "synthetic".into(),
        config: FromRestConfig {
            rows,
            dts,
            t_end: 2.0,
            jobs: 1,
        },
        cutback: 0,
        cells,
    };
    let dir = tempfile::tempdir().unwrap();
    let svg_path = dir.path().join("fr.svg");
    plot_from_rest(&svg_path, &fr).unwrap();
    keep(&svg_path);
    let els = elements(&std::fs::read_to_string(&svg_path).unwrap());
    let text = texts(&els);
    assert!(
        text.iter().any(|t| t
            == "synthetic: from-rest stability map, fixed step (no cut-back), t_end = 2"),
        "{text:?}"
    );
    for want in [
        "EM",
        "EDMC-1 χ_ν = 0.5",
        "completed: 3 of 6",
        "scheme: element end triads turned past the limit: 1 of 6",
        "scheme: energy growth refused: 0 of 6",
        "solver stall (came close, did not converge): 1 of 6",
        "Newton diverged (Δt beyond its reach): 1 of 6",
        "75%",
        "10%",
        "50%",
        "0.050",
    ] {
        assert!(text.iter().any(|t| t == want), "no text {want:?}: {text:?}");
    }
    assert_no_text_overlaps(&els);

    let png = dir.path().join("fr.png");
    plot_from_rest(&png, &fr).unwrap();
    keep(&png);
    // Completed green, the stall red, the turn orange, the divergence blue: each drawn.
    let (counts, inked) = coverage(&png, &["#1A9850", "#D73027", "#FDAE61", "#4575B4"]);
    assert!(inked > 0.2, "{inked}");
    assert!(counts.iter().all(|&n| n > 1000), "{counts:?}");
}

#[test]
fn damping_chart_lists_every_parameter_run_and_its_failures() {
    let config = DampingConfig {
        values: vec![0.1, 1.0],
        periods: 2.0,
        steps_per_period: 16,
        amplitude: 0.01,
        jobs: 1,
    };
    let mut rows = Vec::new();
    for mode in [ModeKind::Axial, ModeKind::Bending] {
        let row = |param: &'static str, value: f64, zeta: f64| DampingRow {
            mode,
            param,
            value,
            omega: 10.0,
            dt: 0.039,
            energy_decay_rate: 20.0 * zeta,
            zeta,
            loss_per_period: 1.0 - (-4.0 * std::f64::consts::PI * zeta).exp(),
            status: if zeta.is_nan() {
                RunStatus::Failed
            } else {
                RunStatus::Completed
            },
            reason: None,
        };
        rows.push(row("em", 0.0, 1e-15));
        for (i, p) in PARAMETERS.iter().enumerate() {
            for v in [0.1, 1.0] {
                // One failed run: EDMC-1 χ_v (bending) at 1.
                let zeta = if i == 2 && v == 1.0 && mode == ModeKind::Bending {
                    f64::NAN
                } else {
                    1e-3 * v * (i + 1) as f64
                };
                rows.push(row(p.key, v, zeta));
            }
        }
    }
    let d = Damping {
        scene: "cantilever".into(),
        config,
        rows,
    };
    let dir = tempfile::tempdir().unwrap();
    let svg_path = dir.path().join("damping.svg");
    plot_damping(&svg_path, &d).unwrap();
    keep(&svg_path);
    let els = elements(&std::fs::read_to_string(&svg_path).unwrap());
    let text = texts(&els);
    for p in PARAMETERS {
        // Once in the legend.
        assert_eq!(
            text.iter().filter(|t| *t == p.symbol).count(),
            1,
            "{}: {text:?}",
            p.symbol
        );
    }
    assert!(
        text.iter()
            .any(|t| t.starts_with("first bending mode") && t.ends_with("; 1 failed (×)")),
        "{text:?}"
    );
    assert!(text.iter().any(|t| t == "modal damping ratio ζ [–]"));
    assert_no_text_overlaps(&els);
    assert!(text.iter().any(|t| t.starts_with("first axial mode")));
    assert!(text.iter().any(|t| t.starts_with("first bending mode")));

    let png = dir.path().join("damping.png");
    plot_damping(&png, &d).unwrap();
    keep(&png);
    let (counts, inked) = coverage(&png, &[BLACK_ISH, RED, BLUE, GREEN]);
    assert!(inked > 0.02, "{inked}");
    assert!(counts.iter().all(|&n| n > 100), "{counts:?}");
}

#[test]
fn accelerations_chart_has_both_panels_with_their_legends() {
    let mut recs = records();
    for r in &mut recs {
        r.acc_trans = 1.0 + r.t.sin().abs();
        r.acc_rot = 3.0 + r.t.cos();
    }
    let dir = tempfile::tempdir().unwrap();
    let svg_path = dir.path().join("acc.svg");
    plot_accelerations(&svg_path, &recs, "accelerations").unwrap();
    keep(&svg_path);
    let svg = std::fs::read_to_string(&svg_path).unwrap();
    let text = texts(&elements(&svg));
    for label in [
        "‖(v_n+1 − v_n)/Δt‖ (L2 over the rods)",
        "‖(ḋ_n+1 − ḋ_n)/Δt‖ (L2 over the rods)",
    ] {
        assert!(text.iter().any(|t| t == label), "legend lacks {label}");
    }
    // One data line per panel: red above, blue below; row 0 (no step yet) left out.
    let lines = polylines(&svg);
    let (red, blue) = (data_lines(&lines, RED), data_lines(&lines, BLUE));
    assert_eq!((red.len(), blue.len()), (1, 1));
    assert!(red[0][0].1 < blue[0][0].1 - 100.0 || red[0].iter().all(|p| p.1 < blue[0][0].1));
    let png = dir.path().join("acc.png");
    plot_accelerations(&png, &recs, "accelerations").unwrap();
    keep(&png);
    let (counts, inked) = coverage(&png, &[RED, BLUE]);
    assert!(inked > 0.02, "{inked}");
    assert!(counts.iter().all(|&n| n > 200), "{counts:?}");
}

#[test]
fn snapshots_chart_draws_every_rod_from_blue_to_red() {
    // A rod swinging about the origin in the e1e2 plane, 3 snapshots.
    let snaps: Vec<Snapshot> = (0..3)
        .map(|k| {
            let a = 0.4 * k as f64;
            Snapshot {
                t: k as f64,
                rods: vec![(0..=4)
                    .map(|i| {
                        let s = 0.25 * i as f64;
                        Vec3::new(s * a.cos(), s * a.sin(), 0.0)
                    })
                    .collect()],
                links: Vec::new(),
            }
        })
        .collect();
    let plane = Some(cosserat::model::Plane { normal: 2 });
    let dir = tempfile::tempdir().unwrap();
    let svg_path = dir.path().join("snap.svg");
    plot_snapshots(&svg_path, "snapshots", &snaps, plane, "m").unwrap();
    keep(&svg_path);
    let els = elements(&std::fs::read_to_string(&svg_path).unwrap());
    let text = texts(&els);
    assert!(
        text.iter()
            .any(|t| t == "3 snapshots, t = 0 (blue) … 2 (red)"),
        "{text:?}"
    );
    assert!(text.iter().any(|t| t == "e1 [m]") && text.iter().any(|t| t == "e2 [m]"));
    // One 5-node polyline per snapshot, first blue, last red.
    let rods: Vec<&Element> = els
        .iter()
        .filter(|e| e.name == "polyline" && points(e).len() == 5)
        .collect();
    assert_eq!(rods.len(), 3);
    assert_eq!(attr(rods[0], "stroke"), BLUE);
    assert_eq!(attr(rods[2], "stroke"), RED);
    let png = dir.path().join("snap.png");
    plot_snapshots(&png, "snapshots", &snaps, plane, "m").unwrap();
    keep(&png);
    let (counts, _) = coverage(&png, &[RED, BLUE]);
    assert!(counts.iter().all(|&n| n > 100), "{counts:?}");
}

/// With `CHARTS_KEEP=DIR`, copies a drawn chart to `DIR` (to look at what the tests draw).
fn keep(p: &std::path::Path) {
    if let Ok(d) = std::env::var("CHARTS_KEEP") {
        std::fs::create_dir_all(&d).unwrap();
        std::fs::copy(p, std::path::Path::new(&d).join(p.file_name().unwrap())).unwrap();
    }
}
