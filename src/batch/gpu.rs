//! The GPU element evaluator shared by the workers of a batch: every live member submits
//! its element inputs; when all live members are waiting, the last one to arrive runs one
//! dispatch for all of them and wakes the others (a dynamic barrier: a member that
//! converged early simply goes on to its next step or its next iteration, a member that
//! finished leaves, and the barrier shrinks).

use std::sync::{Condvar, Mutex, MutexGuard};

use crate::element::{ElementEval, StepConsts};
use crate::gpu::kernel::{KernelMode, KernelTimers};
use crate::gpu::{ElementKernel, GpuContext, GpuError};
use crate::integrator::backend::{ElementBackend, ElementInput};
use crate::integrator::Simulation;

struct Inner {
    kernel: ElementKernel,
    /// Workers that may still submit.
    live: usize,
    /// Slots waiting for the next dispatch.
    pending: Vec<usize>,
    want_tangent: bool,
    generation: u64,
    results: Vec<Option<Result<Vec<ElementEval>, String>>>,
    n_elems: Vec<usize>,
}

/// A batch of `slots` simulations of at most `per_slot` elements each on one GPU kernel.
pub struct GpuBatcher {
    inner: Mutex<Inner>,
    cv: Condvar,
    per_slot: usize,
}

impl GpuBatcher {
    /// Kernel buffers for `slots × per_slot` elements; `slots` workers are counted live
    /// from the start (each must call [`Self::leave`] when it is done).
    pub fn new(ctx: &GpuContext, slots: usize, per_slot: usize) -> Result<Self, GpuError> {
        let kernel = ElementKernel::new(ctx, slots * per_slot)?;
        Ok(Self {
            inner: Mutex::new(Inner {
                kernel,
                live: slots,
                pending: Vec::with_capacity(slots),
                want_tangent: false,
                generation: 0,
                results: (0..slots).map(|_| None).collect(),
                n_elems: vec![0; slots],
            }),
            cv: Condvar::new(),
            per_slot,
        })
    }

    /// Largest number of slots of `per_slot` elements that fits one kernel on `ctx`.
    pub fn max_slots(ctx: &GpuContext, per_slot: usize) -> usize {
        ElementKernel::max_capacity(ctx) / per_slot.max(1)
    }

    fn lock(&self) -> MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Uploads the element constants of `sim` into `slot` (once per member).
    pub fn register(&self, slot: usize, sim: &Simulation) {
        let k = StepConsts {
            dt: sim.params().dt,
            scheme: sim.params().scheme,
        };
        let trans = sim.params().scheme.translational_dissipation();
        let mut g = self.lock();
        for (e, d) in sim.element_data().iter().enumerate() {
            g.kernel.set_element(slot * self.per_slot + e, d, &k, trans);
        }
    }

    /// A worker stops submitting (its members are done).
    pub fn leave(&self) {
        let mut g = self.lock();
        g.live -= 1;
        if g.live > 0 && g.pending.len() == g.live {
            self.dispatch(&mut g);
        }
    }

    /// Stage timers and traffic so far.
    pub fn timers(&self) -> KernelTimers {
        self.lock().kernel.timers
    }

    fn dispatch(&self, g: &mut Inner) {
        let tangent = g.want_tangent;
        let res = g.kernel.run(KernelMode::Frozen, tangent);
        let pending = std::mem::take(&mut g.pending);
        for &slot in &pending {
            let n = g.n_elems[slot];
            let base = slot * self.per_slot;
            let out = match &res {
                Ok(()) => Ok((0..n).map(|e| g.kernel.eval(base + e, tangent)).collect()),
                Err(e) => Err(e.to_string()),
            };
            g.results[slot] = Some(out);
            for e in 0..n {
                g.kernel.set_inactive(base + e);
            }
        }
        g.pending = pending;
        g.pending.clear();
        g.want_tangent = false;
        g.generation += 1;
        self.cv.notify_all();
    }
}

impl ElementBackend for GpuBatcher {
    fn evaluate(
        &self,
        slot: usize,
        inputs: &[ElementInput],
        tangent: bool,
    ) -> Result<Vec<ElementEval>, String> {
        let mut g = self.lock();
        let base = slot * self.per_slot;
        for (e, inp) in inputs.iter().enumerate() {
            g.kernel.set_state(base + e, &inp.st, &inp.eps_n);
            g.kernel.set_iter(base + e, &inp.inc, &inp.s);
        }
        g.n_elems[slot] = inputs.len();
        g.pending.push(slot);
        g.want_tangent |= tangent;
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
