//! The smooth contact model (`model = "smooth"`): line contact along a cubic B-spline of
//! each rod's nodes instead of its polyline.
//!
//! A point load on two-node elements is split `(1 − ξ) P`, `ξ P` onto the element's end
//! nodes, so a rod under a load that slides along it is stiffest where the load sits at
//! an element's mid-point and softest at a node. A frictionless rope resting on another
//! then slides to a node of the one below (half an element off-centre on the
//! cosseratbench crossing). Along the B-spline each quadrature point is a fixed
//! combination of four nodes (`x(u) = Σ Bₖ(u) Pₖ`, control points `Pₖ` the nodes, the
//! rod's ends extended by linear extrapolation so the curve starts and ends at the end
//! nodes; a closed rod wraps round): a load spreads over four nodes with weights that
//! vary smoothly as it moves, and the compliance it sees varies along an element by a
//! few percent of what the polyline's does (the tests measure it).
//!
//! Everything else is the line model's: the pair energy `c wᵢ wⱼ (R² − |d|²)²₊` of
//! fixed-weight quadrature points and its discrete gradient in `s = |d|²`. The positions
//! are still fixed linear combinations of the nodes with weights summing to one, so the
//! nodal forces `wₐ F` do the work `F·Δd`, sum to zero, and have no moment about the
//! origin at the mid-point positions (`Σ wₐ r_a,½ = x_½`): the energy law and both
//! momenta hold exactly as for the other models.

use super::{RodContact, SamplePoint, Stencil, V3};

/// The weights of the `p + 1` control points `e − (p−1)/2 … e + (p+1)/2` of the uniform
/// B-spline of odd degree `p` at `u = e + t`, `t ∈ [0, 1]` (the cardinal B-spline
/// centred on each control point, `Mₚ₊₁(x) = Σₖ (−1)ᵏ C(p+1, k) (x + (p+1)/2 − k)₊ᵖ / p!`).
fn bspline(p: usize, t: f64) -> Vec<f64> {
    let half = (p as f64 + 1.0) / 2.0;
    let fact: f64 = (1..=p).map(|k| k as f64).product();
    let lo = (p as i64 - 1) / 2;
    (0..=p as i64)
        .map(|j| {
            // Distance from control point e − lo + j to u.
            let x = t + lo as f64 - j as f64;
            let mut binom = 1.0;
            let mut sum = 0.0;
            for k in 0..=p + 1 {
                let y = x + half - k as f64;
                if y > 0.0 {
                    let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
                    sum += sign * binom * y.powi(p as i32);
                }
                binom = binom * (p + 1 - k) as f64 / (k + 1) as f64;
            }
            sum / fact
        })
        .collect()
}

/// The chain's node `k` (any integer) as `(chain index, weight)` pairs: the node itself
/// inside, a linear extrapolation of the two end nodes beyond an open rod's ends, the
/// node `k mod N` round a closed rod (`chain` repeats its first node at the end).
fn extended(n: usize, closed: bool, k: i64) -> [(usize, f64); 2] {
    let ni = n as i64;
    if closed {
        return [(k.rem_euclid(ni) as usize, 1.0), (0, 0.0)];
    }
    if k < 0 {
        // x₀ + k (x₁ − x₀)
        [(0, 1.0 - k as f64), (1, k as f64)]
    } else if k > ni {
        let e = (k - ni) as f64;
        [(n, 1.0 + e), (n - 1, -e)]
    } else {
        [(k as usize, 1.0), (0, 0.0)]
    }
}

/// The stencil of the point at parameter `u` (element `e = ⌊u⌋`, `t = u − e`) of the
/// B-spline of odd degree `p` over `chain` (node ids; `N + 1` entries for `N` elements,
/// the first repeated at the end for a closed rod). With `corrected` the control points
/// are `Pₖ = xₖ − c Δ²xₖ`, `c = (p+1)/24` (half the B-spline's variance), which removes
/// the curve's `O(h²κ)` offset from the nodes: it then passes through them to `O(h⁴)`.
pub(crate) fn spline_stencil(
    chain: &[usize],
    e: usize,
    t: f64,
    p: usize,
    corrected: bool,
) -> Stencil {
    let n = chain.len() - 1;
    let closed = n >= 3 && chain[0] == chain[n];
    let b = bspline(p, t);
    let c = if corrected {
        (p as f64 + 1.0) / 24.0
    } else {
        0.0
    };
    let mut acc: Vec<(usize, f64)> = Vec::with_capacity(8);
    let mut add = |idx: usize, w: f64| {
        if w == 0.0 {
            return;
        }
        let node = chain[idx];
        match acc.iter_mut().find(|x| x.0 == node) {
            Some(x) => x.1 += w,
            None => acc.push((node, w)),
        }
    };
    let lo = (p as i64 - 1) / 2;
    for (j, &bj) in b.iter().enumerate() {
        let k = e as i64 - lo + j as i64;
        for (dk, cw) in [(-1, -c), (0, 1.0 + 2.0 * c), (1, -c)] {
            if cw == 0.0 {
                continue;
            }
            for (idx, w) in extended(n, closed, k + dk) {
                add(idx, bj * cw * w);
            }
        }
    }
    // Σ w = 1 to round-off: the last weight takes the rest.
    let rest: f64 = acc[..acc.len() - 1].iter().map(|x| x.1).sum();
    if let Some(last) = acc.last_mut() {
        last.1 = 1.0 - rest;
    }
    Stencil::from_pairs(&acc)
}

/// The smooth model's quadrature points along one rod: `chain` its nodes in order, `h`
/// its element lengths (reference), `rho` its contact radius, `per_radius` points per
/// contact radius (the midpoint rule in the curve parameter, `m = ⌈n h/ρ⌉` per element,
/// weight `h/m` each).
pub fn smooth_points(chain: &[usize], h: &[f64], rho: f64, per_radius: f64) -> Vec<SamplePoint> {
    assert_eq!(
        chain.len(),
        h.len() + 1,
        "a chain of N + 1 nodes for N elements"
    );
    let mut out = Vec::new();
    let mut arc = 0.0;
    let (p, corrected) = match std::env::var("COSSERAT_SMOOTH").as_deref() {
        Ok("3c") => (3, true),
        Ok("5") => (5, false),
        Ok("5c") => (5, true),
        _ => (3, false),
    };
    for (e, &he) in h.iter().enumerate() {
        let m = (per_radius * he / rho).ceil().max(1.0) as usize;
        let m = m + m % 2;
        for s in 0..m {
            let t = (s as f64 + 0.5) / m as f64;
            out.push(SamplePoint {
                nodes: [chain[e], chain[e + 1]],
                xi: t,
                stencil: spline_stencil(chain, e, t, p, corrected),
                radius: rho,
                spacing: he / m as f64,
                arc: arc + he * t,
            });
        }
        arc += he;
    }
    out
}

impl RodContact {
    /// The smooth model's pair search: each element's points are bounded by a sphere
    /// (their centroid and largest distance from it), elements whose spheres come within
    /// `2 ρ_max + reach` are found on a uniform grid, then the points of each within that
    /// distance of the other's sphere, then the pairs of those that are allowed and closer
    /// than `ρᵢ + ρⱼ + reach`. Two points that close lie each within that distance of the
    /// other's sphere, so the search misses none.
    pub fn candidates_by_bounds(&self, r: &[V3], reach: f64) -> Vec<(usize, usize)> {
        let els = self.elements();
        let lim = 2.0 * self.max_radius() + reach;
        let x: Vec<V3> = self.points.iter().map(|p| p.at(r)).collect();
        let bound: Vec<(V3, f64)> = els
            .iter()
            .map(|&(a, b)| {
                let c = x[a..b].iter().sum::<V3>() / (b - a) as f64;
                let rad = x[a..b].iter().fold(0.0f64, |m, p| m.max((p - c).norm()));
                (c, rad)
            })
            .collect();
        let rad_max = bound.iter().fold(0.0f64, |m, b| m.max(b.1));
        let cell = 2.0 * rad_max + lim;
        let key = |v: &V3| -> [i64; 3] { std::array::from_fn(|c| (v[c] / cell).floor() as i64) };
        let mut grid: std::collections::HashMap<[i64; 3], Vec<usize>> =
            std::collections::HashMap::new();
        for (e, b) in bound.iter().enumerate() {
            grid.entry(key(&b.0)).or_default().push(e);
        }
        let near = |e: usize, f: usize| -> Vec<usize> {
            let (c, rad) = bound[f];
            let l = rad + lim;
            (els[e].0..els[e].1)
                .filter(|&i| (x[i] - c).norm_squared() < l * l)
                .collect()
        };
        let mut out = Vec::new();
        for (e, be) in bound.iter().enumerate() {
            let k = key(&be.0);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let Some(list) = grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) else {
                            continue;
                        };
                        for &f in list {
                            if f < e {
                                continue;
                            }
                            if !self.is_self() && (els[e].0 < self.split) == (els[f].0 < self.split)
                            {
                                continue;
                            }
                            let bf = &bound[f];
                            if (be.0 - bf.0).norm() >= be.1 + bf.1 + lim {
                                continue;
                            }
                            let (a, b) = (near(e, f), near(f, e));
                            for &i in &a {
                                for &j in &b {
                                    let (i, j) = (i.min(j), i.max(j));
                                    if i == j || !self.allowed(i, j) {
                                        continue;
                                    }
                                    let l = self.points[i].radius + self.points[j].radius + reach;
                                    if (x[i] - x[j]).norm_squared() < l * l {
                                        out.push((i, j));
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        out.sort_unstable();
        out.dedup();
        out
    }
}
