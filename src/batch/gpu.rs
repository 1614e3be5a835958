//! The GPU element evaluator shared by the workers of a batch: every live member submits
//! its element inputs; when all live members are waiting, the last one to arrive runs one
//! dispatch for all of them and wakes the others (a dynamic barrier: a member that
//! converged early simply goes on to its next step or its next iteration, a member that
//! finished leaves, and the barrier shrinks). The dispatch runs the element pass and the
//! assembly pass ([`Assembler`]); each member gets its assembled block system back.

use std::sync::{Condvar, Mutex, MutexGuard};

use crate::element::StepConsts;
use crate::gpu::kernel::KernelTimers;
use crate::gpu::layout::AsmLayout;
use crate::gpu::{Assembler, ElementKernel, GpuContext, GpuError};
use crate::integrator::backend::{AssembledSystem, ElementBackend, ElementInput};
use crate::integrator::dofs::NONE;
use crate::integrator::Simulation;

struct Inner {
    kernel: ElementKernel,
    assembler: Assembler,
    /// Workers that may still submit.
    live: usize,
    /// Slots waiting for the next dispatch, and whether each wants the tangent.
    pending: Vec<(usize, bool)>,
    generation: u64,
    results: Vec<Option<Result<AssembledSystem, String>>>,
    /// Per slot: elements and nodes of the registered member.
    sizes: Vec<(usize, usize)>,
}

/// A batch of `slots` simulations of at most `per_slot` elements and `nodes_per_slot`
/// nodes each on one GPU kernel.
pub struct GpuBatcher {
    inner: Mutex<Inner>,
    cv: Condvar,
    per_slot: usize,
    /// `gpu: ADAPTER, PRECISION`.
    adapter: String,
}

impl GpuBatcher {
    /// Kernel and assembly buffers for `slots` members of at most `per_slot` elements and
    /// `nodes_per_slot` nodes; `slots` workers are counted live from the start (each must
    /// call [`Self::leave`] when it is done).
    pub fn new(
        ctx: &GpuContext,
        slots: usize,
        per_slot: usize,
        nodes_per_slot: usize,
    ) -> Result<Self, GpuError> {
        let mut kernel = ElementKernel::new(ctx, slots * per_slot)?;
        let assembler = Assembler::new(ctx, &mut kernel, slots, per_slot, nodes_per_slot)?;
        Ok(Self {
            inner: Mutex::new(Inner {
                kernel,
                assembler,
                live: slots,
                pending: Vec::with_capacity(slots),
                generation: 0,
                results: (0..slots).map(|_| None).collect(),
                sizes: vec![(0, 0); slots],
            }),
            cv: Condvar::new(),
            per_slot,
            adapter: format!("gpu: {}", ctx.describe()),
        })
    }

    /// Largest number of slots of `per_slot` elements and `nodes_per_slot` nodes that fits
    /// one kernel and its assembled buffer on `ctx`.
    pub fn max_slots(ctx: &GpuContext, per_slot: usize, nodes_per_slot: usize) -> usize {
        (ElementKernel::max_capacity(ctx) / per_slot.max(1)).min(Assembler::max_members(
            ctx,
            per_slot,
            nodes_per_slot,
        ))
    }

    fn lock(&self) -> MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Uploads the element constants and the node incidence of `sim` into `slot` (once per
    /// member).
    pub fn register(&self, slot: usize, sim: &Simulation) -> Result<(), GpuError> {
        let k = StepConsts {
            dt: sim.params().dt,
            scheme: sim.params().scheme,
        };
        let trans = sim.params().scheme.translational_dissipation();
        let ends: Vec<[usize; 2]> = sim.model().elements.iter().map(|e| e.nodes).collect();
        let masks: Vec<u32> = sim
            .dof_map()
            .elements
            .iter()
            .map(|m| {
                m.iter()
                    .enumerate()
                    .filter(|(_, &i)| i != NONE)
                    .fold(0u32, |acc, (r, _)| acc | (1 << r))
            })
            .collect();
        let n_nodes = sim.model().n_nodes();
        let mut g = self.lock();
        g.assembler.set_member(slot, n_nodes, &ends, &masks)?;
        for (e, d) in sim.element_data().iter().enumerate() {
            g.kernel.set_element(slot * self.per_slot + e, d, &k, trans);
        }
        g.sizes[slot] = (ends.len(), n_nodes);
        Ok(())
    }

    /// A worker stops submitting (its members are done).
    pub fn leave(&self) {
        let mut g = self.lock();
        g.live -= 1;
        if g.live > 0 && g.pending.len() == g.live {
            self.dispatch(&mut g);
        }
    }

    /// Layout of the assembled buffer (what a dispatch reads back: its residual range
    /// without the tangent, all of it with).
    pub fn layout(&self) -> AsmLayout {
        self.lock().assembler.layout()
    }

    /// Stage timers and traffic so far.
    pub fn timers(&self) -> KernelTimers {
        self.lock().kernel.timers
    }

    fn dispatch(&self, g: &mut Inner) {
        let pending = std::mem::take(&mut g.pending);
        let res = g.assembler.run(&mut g.kernel, &pending);
        let t0 = std::time::Instant::now();
        for &(slot, tangent) in &pending {
            let (n_elems, n_nodes) = g.sizes[slot];
            let out = match &res {
                Ok(()) => Ok(g.assembler.system(slot, n_nodes, n_elems, tangent)),
                Err(e) => Err(e.to_string()),
            };
            g.results[slot] = Some(out);
            let base = slot * self.per_slot;
            for e in 0..n_elems {
                g.kernel.set_inactive(base + e);
            }
        }
        g.kernel.timers.unpack_s += t0.elapsed().as_secs_f64();
        g.pending = pending;
        g.pending.clear();
        g.generation += 1;
        self.cv.notify_all();
    }
}

impl ElementBackend for GpuBatcher {
    fn describe(&self) -> String {
        self.adapter.clone()
    }

    fn evaluate_assembled(
        &self,
        slot: usize,
        inputs: &[ElementInput],
        increments: &[[f64; 9]],
        tangent: bool,
    ) -> Result<AssembledSystem, String> {
        let mut g = self.lock();
        if (inputs.len(), increments.len()) != g.sizes[slot] {
            return Err(format!(
                "GPU slot {slot} holds (elements, nodes) {:?}, ({}, {}) submitted",
                g.sizes[slot],
                inputs.len(),
                increments.len()
            ));
        }
        let base = slot * self.per_slot;
        for (e, inp) in inputs.iter().enumerate() {
            g.kernel.set_state(base + e, &inp.st, &inp.eps_n);
            g.kernel.set_scalars(base + e, &inp.s);
        }
        g.assembler.set_increments(slot, increments);
        g.pending.push((slot, tangent));
        if g.pending.len() == g.live {
            self.dispatch(&mut g);
        } else {
            let gen = g.generation;
            while g.generation == gen {
                g = self.cv.wait(g).unwrap_or_else(|p| p.into_inner());
            }
        }
        g.results[slot]
            .take()
            .unwrap_or_else(|| Err("GPU batch lost this member's result".into()))
    }
}
