//! `--solve whole`: a step run entirely on the device (docs/gpu.md, "Whole step on the
//! device"). The member posts one request per step (with the step's nodal terms where its
//! dead loads differ from those the device holds); the device advances its state by the
//! step accepted last, runs Newton from its own iterate (the last increment: the CPU's
//! first predictor), and sends back the iterations' residuals, the residual work and the
//! records at the iterate it stopped at, keeping the state at `n`. The host replays its
//! own Newton test and the EM energy check on those numbers (the same tests, the same
//! tolerances), and either takes the step from the record alone — no state, no increment
//! on the host: they stay on the device — or, where any test would go another way than
//! "accepted at the device's last iterate", takes the state at `n` and that step's
//! predictor back from the device and runs the step as every other path does.

use super::newton::{at_floor, rose_from_start, stagnated, STAGNATION_ITERS};
use super::{node_local, Backend, Mode, Simulation};
use crate::integrator::dofs::NONE;
use crate::integrator::evaluate::{
    AssembledSystem, DeviceStep, DeviceStepAnswer, EvalRequest, Prescribed, Pull, Pulled,
};
use crate::integrator::invariants::Invariants;
use crate::integrator::report::{StepFailure, StepReport};
use crate::integrator::scaling;
use crate::integrator::state::State;

impl Simulation {
    /// `--solve whole` (set by the batch evaluator for the members its device step
    /// covers: [`crate::batch::gpu::device_step_refusal`]): steps whose start the device
    /// holds run entirely there.
    pub fn set_device_steps(&mut self, on: bool) {
        self.device_steps = on;
    }

    /// The factors of the dead loads' time tables at the middle of the coming step: the
    /// nodal loads (in [`crate::model::Model::loads`] order), then the dead line loads
    /// (gravity is constant; follower line loads are not dead).
    pub(super) fn load_factors(&self) -> impl Iterator<Item = f64> + '_ {
        let t_mid = self.state.t + 0.5 * self.params.dt;
        let nodal = self.model.loads.iter().map(|l| &l.table);
        let line = self
            .model
            .line_loads
            .iter()
            .filter(|l| !l.follower)
            .map(|l| &l.table);
        nodal.chain(line).map(move |t| t.eval(t_mid))
    }

    /// Whether commands move driven supports (the device step covers none).
    pub fn has_commands(&self) -> bool {
        !self.commands.is_empty()
    }

    /// A step on the device, when it covers this one: the device holds the state at `n`
    /// once advanced by the step accepted last and that step's increment (the predictor).
    /// `None`: the step runs as on every path (after the state was taken back, where the
    /// device's attempt would not have been accepted as it stands).
    pub(super) async fn device_step(&mut self) -> Option<Result<StepReport, StepFailure>> {
        let advance = self.sent_version.is_some()
            && self.sent_version != Some(self.state_version)
            && self.advanced_version == Some(self.state_version);
        if !(self.device_steps && advance && self.gen_alpha.is_none()) {
            return None;
        }
        let Backend::Lockstep(port) = &self.backend else {
            return None;
        };
        let port = port.clone();
        // The device forms the step's nodal terms from the loads it holds. Where this
        // step's loads differ (a tabled load whose factor changed), the request carries the
        // step's nodal terms: dead loads only, which depend on time alone (follower loads
        // go up as element constants; drag and point masses are the element kernel's).
        let same_loads = self
            .device_loads
            .as_ref()
            .is_some_and(|f| self.load_factors().eq(f.iter().copied()));
        // The step's loads and prescribed support motion, where it sends either (the
        // step's support work takes the loads at the driven nodes).
        if !same_loads || !self.model.drives.is_empty() {
            self.mid_step_loads();
        }
        let extra = (!same_loads).then(|| self.step_nodal_terms());
        // Driven supports: the step's prescribed increments of their removed unknowns.
        let prescribed: Vec<Prescribed> = self.prescribed_rows().collect();
        self.sent_version = Some(self.state_version);
        // A dissipative scheme (the inexact strategy) after a step the host ran: the
        // scalars it starts from (those the device's advance forms too) go up once, with
        // the consistent flag; after a device step the device holds them.
        let inexact = self.params.scheme.is_dissipative();
        let scalars = if inexact && !self.host_stale {
            self.frozen.clone()
        } else {
            Vec::new()
        };
        let req = EvalRequest {
            advance: true,
            scalars,
            consistent: inexact,
            device_step: Some(DeviceStep {
                scale: self.resident_scale,
            }),
            follower: self.follower_update(),
            device_extra: extra,
            prescribed,
            ..EvalRequest::default()
        };
        let answer = port.evaluate(req).await;
        let taken = match answer {
            Ok(AssembledSystem { step: Some(a), .. }) => self.take_device_step(&a),
            Ok(_) => None,
            Err(_) => None,
        };
        if let Some(rep) = taken {
            return Some(Ok(rep));
        }
        // The host's step from the device's state at `n` and the step's predictor.
        match self.pull(&port, true).await {
            Ok(p) => {
                self.set_pulled(&p);
                None
            }
            Err(e) => {
                self.sent_version = None;
                self.advanced_version = None;
                self.follower_sent = None;
                Some(Err(StepFailure {
                    reason: format!("the device did not hand the state back: {e}"),
                    residuals: vec![],
                }))
            }
        }
    }

    /// The driven supports' increments over this step (`mid_step_loads`), one per removed
    /// translation or rotation unknown of a driven node, in node-local row order (so that
    /// consecutive rows go up together).
    fn prescribed_rows(&self) -> impl Iterator<Item = Prescribed> + '_ {
        self.model.drives.iter().flat_map(move |d| {
            let nd = &self.dofs.nodes[d.node];
            let [u, th] = self.prescribed[d.node];
            let values: [f64; 6] = std::array::from_fn(|k| if k < 3 { u[k] } else { th[k - 3] });
            nd.u.into_iter()
                .chain(nd.th)
                .zip(values)
                .enumerate()
                .filter(|(_, (i, _))| *i == NONE)
                .map(move |(row, (_, value))| Prescribed {
                    node: d.node,
                    row,
                    value,
                })
        })
    }

    /// The driven supports' work over a step on the device (the part of
    /// [`Self::support_work`]'s sum the host holds): the reactions' work from the element
    /// passes (`reaction_work`, the device's) less that of the loads at the driven nodes on
    /// their prescribed motion.
    fn device_support_work(&self, reaction_work: f64) -> f64 {
        self.prescribed_rows().fold(reaction_work, |w, p| {
            let load = if p.row < 3 {
                self.force[p.node][p.row]
            } else {
                self.moment[p.node][p.row - 3]
            };
            w - load * p.value
        })
    }

    /// This step's nodal terms (the dead loads at its middle, `mid_step_loads`) per node in
    /// node-local order, for the device; their row scales become the device step's, and the loads the ones
    /// the device holds.
    fn step_nodal_terms(&mut self) -> Vec<[f64; 9]> {
        let q = vec![0.0; self.prev.len()];
        let mut r = vec![0.0; self.prev.len()];
        let mut scale = [0.0f64; 3];
        self.nodal_terms(&q, false, false, &mut r, &mut scale);
        self.resident_scale = scale;
        self.device_loads = Some(self.load_factors().collect());
        self.node_rows(&r)
    }

    /// The step from the device's answer, if every test of the host's step accepts it at
    /// the device's last iterate (`None`: the host runs the step). A dissipative scheme's
    /// device step is the inexact strategy's (`strategy.rs`, `solve_first`): its
    /// consistent-scalar iterations (linear contraction), accepted within the tolerance,
    /// then the polish round's frozen-scalar iterations from that iterate.
    fn take_device_step(&mut self, a: &DeviceStepAnswer) -> Option<StepReport> {
        let tol = self.params.newton_tol;
        let polish = self.params.scheme.is_dissipative();
        let (it0, res0) = replay_newton(&a.iterations, tol, !polish, self.params.max_iter)?;
        // Accepted within the tolerance, the polish round's iterations follow; on its
        // round-off floor above it, the step is checked there with the consistent scalars
        // (the device's records too).
        let rounds = usize::from(polish && res0 <= tol);
        let on_floor = polish && rounds == 0;
        let (it, res) = if rounds == 1 {
            let (it1, res1) =
                replay_newton(&a.iterations[it0 + 1..], tol, true, self.params.max_iter)?;
            (it0 + it1, res1)
        } else {
            (it0, res0)
        };
        // The device stopped where the host's test accepts.
        if it + 1 + rounds != a.iterations.len() {
            return None;
        }
        let r = &a.record;
        let fields = [
            a.support_reaction_work,
            r.kinetic,
            r.potential,
            r.dissipation,
            r.acc_sums[0],
            r.acc_sums[1],
            r.turn,
            r.follower_work,
            a.residual_work,
            a.external_work,
        ];
        if fields.iter().any(|x| !x.is_finite())
            || !(r.l.iter().chain(r.j.iter()).all(|x| x.is_finite()))
            || r.turn > 0.0
        {
            return None;
        }
        // The host's energy checks (`accept.rs`, `check_energy`) on the device's numbers: W
        // the dead loads' work and D the dissipation (Kelvin–Voigt damping, drag) it summed
        // at the iterate.
        let inv = Invariants {
            kinetic: r.kinetic,
            potential: r.potential,
            l: r.l,
            j: r.j,
        };
        // (The follower loads' work from the records, summed per element; the driven
        // supports' from the device's sum over the removed rows, which holds the loads at
        // their nodes on their prescribed motion: `accept.rs`, `external_work`.)
        let support_work = self.device_support_work(a.support_reaction_work);
        let w = a.external_work + r.follower_work + a.support_reaction_work;
        self.check_energy(
            self.inv.total(),
            inv.total(),
            w,
            r.dissipation,
            a.residual_work,
        )
        .ok()?;
        self.state.t += self.params.dt;
        self.state_version += 1;
        self.advanced_version = Some(self.state_version);
        self.host_stale = true;
        self.device_step_consistent = on_floor;
        self.inv = inv;
        self.fell_back = false;
        Some(StepReport {
            newton_iters: it,
            outer_iters: 1,
            residual: res,
            dissipation: r.dissipation,
            external_work: w,
            support_work,
            friction: 0.0,
            acc_trans: r.acc_sums[0].max(0.0).sqrt(),
            acc_rot: r.acc_sums[1].max(0.0).sqrt(),
            max_link_g: 0.0,
            link_rounds: 1,
            fallback: false,
            substeps: 1,
        })
    }

    /// Takes the member's state and increments back from the device.
    async fn pull(
        &mut self,
        port: &crate::integrator::evaluate::EvalPort,
        saved: bool,
    ) -> Result<Pulled, String> {
        let req = EvalRequest {
            pull: Some(Pull { saved }),
            ..EvalRequest::default()
        };
        match port.evaluate(req).await? {
            AssembledSystem {
                pulled: Some(p), ..
            } => {
                if p.states.len() != self.model.elements.len()
                    || p.increments.len() != self.dofs.nodes.len()
                {
                    return Err("the device handed back a state of another size".into());
                }
                Ok(p)
            }
            _ => Err("the evaluator did not hand the state back".into()),
        }
    }

    /// The host's state from the device's element states (the time stays the host's) and
    /// its predictor from the device's increments.
    fn set_pulled(&mut self, p: &Pulled) {
        let mut state = State {
            t: self.state.t,
            r: self.state.r.clone(),
            v: self.state.v.clone(),
            d: Vec::with_capacity(p.states.len()),
            vd: Vec::with_capacity(p.states.len()),
            eps: Vec::with_capacity(p.states.len()),
            lambda: self.state.lambda.clone(),
            anchors: self.state.anchors.clone(),
        };
        for (e, (st, eps)) in p.states.iter().enumerate() {
            for l in 0..2 {
                let a = self.model.elements[e].nodes[l];
                state.r[a] = st.cfg.r[l];
                state.v[a] = st.v[l];
            }
            state.d.push(st.cfg.d);
            state.vd.push(st.vd);
            state.eps.push(*eps);
        }
        self.state = state;
        if !p.scalars.is_empty() {
            self.frozen.clone_from(&p.scalars);
        }
        self.prev.iter_mut().for_each(|x| *x = 0.0);
        for (nd, x) in self.dofs.nodes.iter().zip(&p.increments) {
            for (&i, &v) in node_local(nd).iter().zip(x) {
                if i != NONE {
                    self.prev[i] = v;
                }
            }
        }
        self.host_stale = false;
    }

    /// `--solve whole`: after steps run on the device, the host's copy of the state is
    /// behind; this takes the device's back (the state before the last step and that
    /// step's increment, advanced here as the host's step does). A no-op otherwise.
    pub async fn sync_device_state(&mut self) -> Result<(), String> {
        if !self.host_stale {
            return Ok(());
        }
        let Backend::Lockstep(port) = &self.backend else {
            return Err("no device holds the state".into());
        };
        let port = port.clone();
        let p = self.pull(&port, false).await?;
        let t = self.state.t;
        self.set_pulled(&p);
        let q = self.prev.clone();
        // (With the consistent scalars where the step was accepted on its round-off floor,
        // as the host's step and the device's advance take it.)
        let mode = if self.device_step_consistent {
            Mode::Consistent
        } else {
            Mode::Frozen
        };
        let (mut next, _, consistent) = self.advance(&q, mode);
        next.t = t;
        self.state = next;
        // (As the host's step leaves them: the next step's scalars.)
        if self.params.scheme.is_dissipative() {
            self.frozen = consistent;
        }
        Ok(())
    }
}

/// The host's Newton loop (`newton.rs`) replayed on a device step's iterations `reports`
/// (relative residual, solve succeeded): the index of the iteration its test accepts and
/// that residual, with `quadratic` convergence or linear contraction (the inexact
/// strategy's). `None` where the host would decide otherwise than "accepted there": a
/// non-finite residual, one of its early stops (which depend on the predictor it is on),
/// its cap, a failed solve, or no accepted iteration among those recorded.
fn replay_newton(
    reports: &[(f64, bool)],
    tol: f64,
    quadratic: bool,
    max_iter: usize,
) -> Option<(usize, f64)> {
    let mut history: Vec<f64> = Vec::with_capacity(reports.len());
    for (it, &(res, solved)) in reports.iter().enumerate() {
        let accepted =
            (res <= tol && scaling::may_accept(it)) || at_floor(&history, res, tol, quadratic);
        history.push(res);
        if !res.is_finite() {
            return None;
        }
        if accepted {
            return Some((it, res));
        }
        if rose_from_start(&history)
            || stagnated(&history, STAGNATION_ITERS)
            || it == max_iter
            || !solved
        {
            return None;
        }
    }
    None
}
