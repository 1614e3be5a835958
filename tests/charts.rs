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
