//! The smooth contact model (`model = "smooth"`): line contact along a quadratic
//! B-spline of each rod's nodes instead of its polyline.
//!
//! A point load on two-node elements is split `(1 − ξ) P`, `ξ P` onto the element's end
//! nodes, so a rod under a load that slides along it is stiffest where the load sits at
//! an element's mid-point and softest at a node. A frictionless rope resting on another
//! then slides to a node of the one below (half an element off-centre on the
//! cosseratbench crossing). Along the B-spline each quadrature point is a fixed
//! combination of three nodes (`x(u) = Σ Bₖ(u) Pₖ`, control points `Pₖ` the nodes, the
//! rod's ends extended by point reflection so the curve starts and ends at the end
//! nodes; a closed rod wraps round): a load spreads over three nodes with weights that
//! vary smoothly (C¹) as it moves, and the compliance it sees varies along an element far
//! less than on the polyline (the tests measure it). The curve lies `h²κ/8` inside a
//! curved node chain, as the polyline does at an element's mid-point.
//!
//! Everything else is the line model's: the pair energy `c wᵢ wⱼ (R² − |d|²)²₊` of
//! fixed-weight quadrature points and its discrete gradient in `s = |d|²`. The positions
//! are still fixed linear combinations of the nodes with weights summing to one, so the
//! nodal forces `wₐ F` do the work `F·Δd`, sum to zero, and have no moment about the
//! origin at the mid-point positions (`Σ wₐ r_a,½ = x_½`): the energy law and both
//! momenta hold exactly as for the other models.

use super::{RodContact, SamplePoint, Stencil, V3};

/// The weights of the control points `e − lo(p) … e − lo(p) + p + 1` (`lo = ⌈p/2⌉`) of
/// the uniform B-spline of degree `p` at `u = e + t`, `t ∈ [0, 1]`: the cardinal B-spline
/// centred on each control point, `Mₚ₊₁(x) = Σₖ (−1)ᵏ C(p+1, k) (x + (p+1)/2 − k)₊ᵖ / p!`,
/// zero outside its support `|x| < (p+1)/2`.
fn bspline(p: usize, t: f64) -> Vec<f64> {
    let half = (p as f64 + 1.0) / 2.0;
    let fact: f64 = (1..=p).map(|k| k as f64).product();
    let lo = p.div_ceil(2) as i64;
    (0..=p as i64 + 1)
        .map(|j| {
            // Distance from control point e − lo + j to u.
            let x = t + lo as f64 - j as f64;
            if x.abs() >= half {
                return 0.0;
            }
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
/// inside; beyond an open rod's ends its point reflection through the end node
/// (`x₋ₖ = 2x₀ − xₖ`, so an odd-degree B-spline passes through the end nodes; a linear
/// extrapolation of the end element where the rod is too short to reflect); the node
/// `k mod N` round a closed rod (`chain` repeats its first node at the end).
fn extended(n: usize, closed: bool, k: i64) -> [(usize, f64); 2] {
    let ni = n as i64;
    if closed {
        return [(k.rem_euclid(ni) as usize, 1.0), (0, 0.0)];
    }
    if k < 0 {
        if -k <= ni {
            [(0, 2.0), ((-k) as usize, -1.0)]
        } else {
            [(0, 1.0 - k as f64), (1, k as f64)]
        }
    } else if k > ni {
        if k - ni <= ni {
            [(n, 2.0), ((2 * ni - k) as usize, -1.0)]
        } else {
            let e = (k - ni) as f64;
            [(n, 1.0 + e), (n - 1, -e)]
        }
    } else {
        [(k as usize, 1.0), (0, 0.0)]
    }
}

/// The stencil of the point at parameter `u` (element `e = ⌊u⌋`, `t = u − e`) of the
/// B-spline of degree `p` over `chain` (node ids; `N + 1` entries for `N` elements,
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
    let lo = p.div_ceil(2) as i64;
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
    for (e, &he) in h.iter().enumerate() {
        let m = (per_radius * he / rho).ceil().max(1.0) as usize;
        let m = m + m % 2;
        for s in 0..m {
            let t = (s as f64 + 0.5) / m as f64;
            out.push(SamplePoint {
                nodes: [chain[e], chain[e + 1]],
                xi: t,
                stencil: spline_stencil(chain, e, t, 2, false),
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

#[cfg(test)]
mod tests {
    use super::super::{ContactModel, M3};
    use super::*;

    #[test]
    fn stencils_are_partitions_of_unity_that_keep_straight_lines_and_ends() {
        // An open chain of 6 nodes on a line (uneven ids), and a closed one.
        let chain = [7, 3, 9, 0, 4, 12];
        let mut r = vec![V3::zeros(); 13];
        for (k, &a) in chain.iter().enumerate() {
            r[a] = V3::new(0.3, -0.1, 0.2) + k as f64 * V3::new(0.02, 0.01, -0.005);
        }
        for (p, corrected) in [(2, false), (3, false), (2, true), (3, true)] {
            for e in 0..5 {
                for t in [0.0, 0.1, 0.5, 0.93, 1.0] {
                    let st = spline_stencil(&chain, e, t, p, corrected);
                    let tol = 1e-15;
                    let sum: f64 = st.iter().map(|x| x.1).sum();
                    assert!((sum - 1.0).abs() <= 1e-15, "Σw − 1 = {:e}", sum - 1.0);
                    assert!(st.len() <= p + 1 + 2 * usize::from(corrected));
                    let want = r[chain[0]] + (e as f64 + t) * V3::new(0.02, 0.01, -0.005);
                    assert!(
                        (st.at(&r) - want).norm() <= tol,
                        "degree {p}: a straight chain not reproduced at {e} + {t}"
                    );
                }
            }
            // The curve starts and ends at the end nodes (whatever their places).
            let mut bent = r.clone();
            bent[chain[1]] += V3::new(0.0, 0.03, 0.01);
            bent[chain[4]] += V3::new(0.01, -0.02, 0.0);
            let s0 = spline_stencil(&chain, 0, 0.0, p, corrected).at(&bent);
            let s1 = spline_stencil(&chain, 4, 1.0, p, corrected).at(&bent);
            assert!((s0 - bent[chain[0]]).norm() <= 1e-15);
            assert!((s1 - bent[chain[5]]).norm() <= 1e-15);
        }
        // Plain B-spline weights are positive: the curve stays in the nodes' convex hull.
        assert!(spline_stencil(&chain, 2, 0.3, 2, false)
            .iter()
            .all(|x| x.1 > 0.0));
        // A closed chain wraps round: on a regular 12-gon every element's curve is the
        // same, at the same distance from the centre (the chord's mid-point at t = ½).
        let ring: Vec<usize> = (0..12).chain([0]).collect();
        let pos: Vec<V3> = (0..12)
            .map(|k| {
                let a = k as f64 * std::f64::consts::TAU / 12.0;
                V3::new(a.cos(), a.sin(), 0.0)
            })
            .collect();
        let chord = (std::f64::consts::TAU / 24.0).cos();
        for e in [0, 5, 11] {
            for t in [0.2, 0.5] {
                let x = spline_stencil(&ring, e, t, 2, false).at(&pos);
                let y = spline_stencil(&ring, 3, t, 2, false).at(&pos);
                assert!(
                    (x.norm() - y.norm()).abs() <= 1e-15,
                    "{} vs {}",
                    x.norm(),
                    y.norm()
                );
                if t == 0.5 {
                    assert!((x.norm() - chord).abs() <= 1e-15, "{}", x.norm());
                }
            }
        }
    }

    /// Two rods of `n` elements crossing at 60°, rod B pressed into rod A.
    fn crossing(rho: f64, per_radius: f64) -> (RodContact, Vec<V3>) {
        let n = 5;
        let mut r: Vec<V3> = (0..=n)
            .map(|a| V3::new(-0.05 + 0.02 * a as f64, 0.0, 0.0))
            .collect();
        let (c60, s60) = (0.5, 0.75f64.sqrt());
        r.extend((0..=n).map(|a| {
            let s = -0.05 + 0.02 * a as f64 + 0.003;
            V3::new(
                c60 * s,
                s60 * s,
                1.6 * rho + 0.001 * (a as f64 - 2.5).powi(2),
            )
        }));
        let h = vec![0.02; n];
        let mut points = smooth_points(&(0..=n).collect::<Vec<_>>(), &h, rho, per_radius);
        let split = points.len();
        points.extend(smooth_points(
            &(n + 1..=2 * n + 1).collect::<Vec<_>>(),
            &h,
            rho,
            per_radius,
        ));
        let c = RodContact {
            rods: vec!["a".into(), "b".into()],
            stiffness: 1e5,
            friction: 0.0,
            slip: 1e-3,
            model: ContactModel::Smooth,
            points,
            split,
        };
        (c, r)
    }

    #[test]
    fn smooth_contact_work_equals_energy_change_and_keeps_momenta() {
        let rho = 0.01;
        let (c, r0) = crossing(rho, 8.0);
        // Three nodes inside, two next to the rods' ends.
        assert!(c.points.iter().all(|p| (2..=3).contains(&p.stencil.len())));
        assert!(c.points.iter().any(|p| p.stencil.len() == 3));
        let (touching, worst_e, worst_l, worst_j) =
            super::super::tests::random_steps(&c, &r0, rho, 0x2545f4914f6cdd1d);
        eprintln!(
            "smooth contact over {touching} random steps: |W + ΔV| {worst_e:.1e} of V, force sum {worst_l:.1e}, moment {worst_j:.1e} (relative)"
        );
        assert!(touching > 100, "only {touching} steps in contact");
        assert!(worst_e <= 3e-14, "work vs ΔV {worst_e:e}");
        assert!(worst_l <= 1e-15, "force sum {worst_l:e}");
        assert!(worst_j <= 1e-15, "moment {worst_j:e}");
    }

    #[test]
    fn smooth_pair_jacobian_matches_finite_differences() {
        let rho = 0.01;
        let (c, r0) = crossing(rho, 4.0);
        let mut r1 = r0.clone();
        r1[8] += V3::new(0.001, 0.002, -0.004);
        r1[9] += V3::new(-0.001, 0.001, -0.003);
        let (mut checked, mut worst) = (0, 0.0f64);
        for &(i, j) in &c.candidates(&r0, 0.01) {
            let f = c.pair_force(i, j, &r0, &r1, true);
            if f.jacobian == M3::zeros() {
                continue;
            }
            // Node 8 carries weight w of point j (rod B), which feels −F.
            let w = c.points[j]
                .weights()
                .iter()
                .find(|(n, _)| *n == 8)
                .map_or(0.0, |x| x.1);
            if w == 0.0 {
                continue;
            }
            checked += 1;
            let h = 1e-8;
            for col in 0..3 {
                let (mut rp, mut rm) = (r1.clone(), r1.clone());
                rp[8][col] += h;
                rm[8][col] -= h;
                let fd = (c.pair_force(i, j, &r0, &rp, false).force
                    - c.pair_force(i, j, &r0, &rm, false).force)
                    / (2.0 * h);
                let an = -w * f.jacobian.column(col);
                worst = worst.max((fd - an).amax() / f.jacobian.amax());
            }
        }
        eprintln!("smooth pair jacobian vs FD over {checked} pairs: {worst:.1e}");
        assert!(checked > 10, "only {checked} pairs in contact");
        assert!(worst <= 3e-9, "jacobian vs FD {worst:e}");
    }

    #[test]
    fn pair_search_finds_every_pair_in_reach() {
        // A rod coiled on itself (self-contact), against brute force over all pairs.
        let r: Vec<V3> = (0..24)
            .map(|a| {
                let t = a as f64 * 0.3;
                V3::new(0.05 * t.cos(), 0.05 * t.sin(), 0.0015 * t)
            })
            .collect();
        let h: Vec<f64> = r.windows(2).map(|w| (w[1] - w[0]).norm()).collect();
        let points = smooth_points(&(0..24).collect::<Vec<_>>(), &h, 0.006, 4.0);
        let c = RodContact {
            rods: vec!["a".into()],
            stiffness: 1e5,
            friction: 0.0,
            slip: 1e-3,
            model: ContactModel::Smooth,
            split: points.len(),
            points,
        };
        for reach in [0.0, 0.003] {
            let found = c.candidates(&r, reach);
            let mut brute = Vec::new();
            for i in 0..c.points.len() {
                for j in i + 1..c.points.len() {
                    let l = c.points[i].radius + c.points[j].radius + reach;
                    if c.allowed(i, j) && (c.points[i].at(&r) - c.points[j].at(&r)).norm() < l {
                        brute.push((i, j));
                    }
                }
            }
            assert!(!brute.is_empty());
            assert_eq!(found, brute, "reach {reach}");
        }
    }

    /// The compliance `C(u) = w(u)ᵀ G w(u)` of a taut string (tension 1, length 1, `n`
    /// elements, pinned ends) under a unit load carried by a point at parameter `u`
    /// through the stencil `w`: `G` is the string's Green's function at the nodes, which
    /// the two-node elements reproduce exactly.
    fn string_compliance(
        n: usize,
        u: f64,
        stencil: impl Fn(&[usize], usize, f64) -> Stencil,
    ) -> f64 {
        let chain: Vec<usize> = (0..=n).collect();
        let e = (u.floor() as usize).min(n - 1);
        let st = stencil(&chain, e, u - e as f64);
        let x = |a: usize| a as f64 / n as f64;
        let g = |a: usize, b: usize| x(a.min(b)) * (1.0 - x(a.max(b)));
        st.iter()
            .flat_map(|&(a, wa)| st.iter().map(move |&(b, wb)| wa * wb * g(a, b)))
            .sum()
    }

    #[test]
    fn a_sliding_load_sees_a_compliance_ripple_of_a_few_percent_of_the_polylines() {
        // The ripple of C over the middle element against the continuum's own change
        // over half an element there (h²/4 for the unit string), at 51 elements (the
        // cosseratbench crossing: the middle of the span is an element's mid-point).
        let n = 51;
        let ripple = |f: &dyn Fn(&[usize], usize, f64) -> Stencil| {
            let c: Vec<f64> = (0..=40)
                .map(|k| string_compliance(n, 25.0 + k as f64 / 40.0, f))
                .collect();
            // Take out the continuum's parabola u(1 − u) (in span units).
            let (lo, hi) = c
                .iter()
                .enumerate()
                .map(|(k, v)| {
                    let s = (25.0 + k as f64 / 40.0) / n as f64;
                    v - s * (1.0 - s)
                })
                .fold((f64::MAX, f64::MIN), |m, v| (m.0.min(v), m.1.max(v)));
            hi - lo
        };
        let linear =
            ripple(&|ch: &[usize], e: usize, t: f64| Stencil::linear([ch[e], ch[e + 1]], t));
        let h = 1.0 / n as f64;
        let continuum = h * h / 4.0;
        let mut out = Vec::new();
        for (p, corrected) in [(2, false), (3, false), (2, true), (3, true)] {
            let r =
                ripple(&|ch: &[usize], e: usize, t: f64| spline_stencil(ch, e, t, p, corrected));
            out.push(r);
            eprintln!(
                "degree {p}{}: ripple {:.2e} of the polyline's, {:.2} of the continuum's change over half an element",
                if corrected { " corrected" } else { "" },
                r / linear,
                r / continuum
            );
        }
        eprintln!(
            "polyline: ripple {:.2} of the continuum's change",
            linear / continuum
        );
        // The polyline's ripple is h/4 (the string's kink, L/h = 51 times the continuum's
        // change); the quadratic's 12.5 %, the cubic's 5.2 % of it.
        assert!((linear / (h / 4.0) - 1.0).abs() < 0.01, "{linear:e}");
        assert!(
            out[0] <= 0.13 * linear,
            "quadratic ripple {:e}",
            out[0] / linear
        );
        assert!(
            out[1] <= 0.06 * linear,
            "cubic ripple {:e}",
            out[1] / linear
        );
    }
}
