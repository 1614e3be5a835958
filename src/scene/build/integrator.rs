//! The `[integrator]` table: scheme and its parameters, step and end time, strategy,
//! fallback, cutback, Newton variant, tolerances and iteration caps.

use super::check::{Ctx, Result};
use crate::integrator::params::{IntegratorParams, NewtonVariant, Scheme, Strategy};
use crate::scene::fmt_num;
use crate::scene::limits;
use crate::scene::raw::RawIntegrator;
use crate::scene::span::KeyPath;

pub(super) fn integrator(
    cx: &Ctx,
    ip: &KeyPath,
    r: &RawIntegrator,
) -> Result<(IntegratorParams, usize)> {
    let k = |name: &str| ip.key(name);
    let scheme_name = cx.required(&k("scheme"), r.scheme.as_deref())?;
    let all_params: [(&str, Option<f64>, &str); 10] = [
        ("alpha", r.alpha, "edmc2"),
        ("alpha_gv", r.alpha_gv, "edmc2"),
        ("alpha_gn", r.alpha_gn, "edmc2"),
        ("alpha_ov", r.alpha_ov, "edmc2"),
        ("alpha_on", r.alpha_on, "edmc2"),
        ("chi_gamma", r.chi_gamma, "edmc1"),
        ("chi_omega", r.chi_omega, "edmc1"),
        ("chi_v", r.chi_v, "edmc1"),
        ("chi_nu", r.chi_nu, "edmc1"),
        ("rho_inf", r.rho_inf, "gen-alpha"),
    ];
    if !matches!(
        scheme_name,
        "em" | "edmc1" | "edmc2" | "midpoint" | "gen-alpha"
    ) {
        return Err(cx.err(
            &k("scheme"),
            format!(
                "unknown scheme `{scheme_name}` (expected \"em\", \"edmc1\", \"edmc2\", \"midpoint\" or \"gen-alpha\")"
            ),
        ));
    }
    for (name, value, owner) in all_params {
        if value.is_some() && owner != scheme_name {
            return Err(cx.err(
                &k(name),
                format!("not a parameter of scheme {scheme_name} (it belongs to {owner})"),
            ));
        }
    }
    let scheme = match scheme_name {
        "em" => Scheme::Em,
        "midpoint" => Scheme::Midpoint,
        "gen-alpha" => {
            let rho_inf = r
                .rho_inf
                .unwrap_or(crate::integrator::gen_alpha::DEFAULT_RHO_INF);
            if !(0.0..=1.0).contains(&rho_inf) {
                return Err(cx.err(&k("rho_inf"), format!("must be in [0, 1] (got {rho_inf})")));
            }
            Scheme::GenAlpha { rho_inf }
        }
        "edmc1" => Scheme::Edmc1 {
            chi_gamma: cx.opt_non_negative(&k("chi_gamma"), r.chi_gamma)?,
            chi_omega: cx.opt_non_negative(&k("chi_omega"), r.chi_omega)?,
            chi_v: cx.opt_non_negative(&k("chi_v"), r.chi_v)?,
            chi_nu: cx.opt_non_negative(&k("chi_nu"), r.chi_nu)?,
        },
        _ => {
            if r.alpha.is_some() && r.alpha_gv.is_some() {
                return Err(cx.err(
                    &k("alpha_gv"),
                    "give `alpha` (shorthand for alpha_gv) or `alpha_gv`, not both",
                ));
            }
            let alpha_gv = match r.alpha {
                Some(a) => cx.non_negative(&k("alpha"), a)?,
                None => cx.opt_non_negative(&k("alpha_gv"), r.alpha_gv)?,
            };
            Scheme::Edmc2 {
                alpha_gv,
                alpha_gn: cx.opt_non_negative(&k("alpha_gn"), r.alpha_gn)?,
                alpha_ov: cx.opt_non_negative(&k("alpha_ov"), r.alpha_ov)?,
                alpha_on: cx.opt_non_negative(&k("alpha_on"), r.alpha_on)?,
            }
        }
    };
    let dt = cx.req_positive(&k("dt"), r.dt)?;
    let t_end = cx.req_positive(&k("t_end"), r.t_end)?;
    if dt > t_end {
        return Err(cx.err(
            &k("dt"),
            format!(
                "must not exceed t_end = {} (got {}): the run would take no step",
                fmt_num(t_end),
                fmt_num(dt)
            ),
        ));
    }
    if t_end / dt > limits::MAX_STEPS {
        return Err(cx.err(
            &k("dt"),
            format!(
                "t_end / dt = {:e} steps, above the limit of {:e} steps per run",
                t_end / dt,
                limits::MAX_STEPS
            ),
        ));
    }
    let mut p = IntegratorParams::new(scheme, dt, t_end);
    if let Some(s) = r.strategy.as_deref() {
        p.strategy = match s {
            "monolithic" => Strategy::Monolithic,
            "staggered" => Strategy::Staggered,
            "inexact" => Strategy::Inexact,
            "auto" => Strategy::Auto,
            other => {
                return Err(cx.err(
                    &k("strategy"),
                    format!(
                        "unknown strategy `{other}` (expected \"auto\", \"staggered\", \"monolithic\" or \"inexact\")"
                    ),
                ))
            }
        };
    }
    if let Some(f) = r.fallback {
        p.fallback = f;
    }
    if let Some(n) = r.cutback {
        p.cutback = match n {
            0..=20 => n as usize,
            _ => {
                return Err(cx.err(
                    &k("cutback"),
                    format!("must be between 0 and 20 halvings (got {n})"),
                ))
            }
        };
    }
    if let Some(s) = r.newton.as_deref() {
        p.newton = match s {
            "full" => NewtonVariant::Full,
            "fresh" => NewtonVariant::Fresh,
            "modified" => NewtonVariant::Modified,
            other => {
                return Err(cx.err(
                    &k("newton"),
                    format!(
                        "unknown Newton variant `{other}` (expected \"full\", \"fresh\" or \"modified\")"
                    ),
                ))
            }
        };
    }
    if let Some(x) = r.newton_tol {
        p.newton_tol = cx.tolerance(&k("newton_tol"), x)?;
    }
    if let Some(x) = r.outer_tol {
        p.outer_tol = cx.tolerance(&k("outer_tol"), x)?;
    }
    if let Some(x) = r.energy_tol {
        p.energy_tol = cx.tolerance(&k("energy_tol"), x)?;
    }
    p.max_iter = cx.iteration_cap(&k("max_iter"), r.max_iter, p.max_iter)?;
    p.max_outer = cx.iteration_cap(&k("max_outer"), r.max_outer, p.max_outer)?;
    p.max_link_rounds =
        cx.iteration_cap(&k("max_link_rounds"), r.max_link_rounds, p.max_link_rounds)?;
    let output_every = cx.count(&k("output_every"), r.output_every, 1)?;
    Ok((p, output_every))
}
