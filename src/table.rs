//! Time tables: piecewise scalar factors `f(t)` that scale loads and drive supports and
//! obstacles (a leaf module: the model and the obstacles use it).

/// A piecewise-linear scalar table `f(t)`; constant before the first and after the last
/// entry. Equal consecutive times express a jump (the later value holds from that time on).
#[derive(Clone, Debug, PartialEq)]
pub struct TimeTable {
    /// Strictly non-decreasing times.
    pub times: Vec<f64>,
    /// Values at `times`.
    pub values: Vec<f64>,
}

impl TimeTable {
    /// A table that is `1` for all time.
    pub fn constant_one() -> Self {
        Self {
            times: vec![0.0],
            values: vec![1.0],
        }
    }

    /// Evaluates the table at `t` (right-continuous at jumps).
    pub fn eval(&self, t: f64) -> f64 {
        match self.segment(t) {
            Err(held) => held,
            Ok((t0, t1, f0, f1)) => f0 + (f1 - f0) * (t - t0) / (t1 - t0),
        }
    }

    /// The entries `(t0, t1, f0, f1)` around `t`, or the value held there (before the
    /// first entry, after the last, at a jump; 0 for an empty table).
    fn segment(&self, t: f64) -> Result<(f64, f64, f64, f64), f64> {
        let n = self.times.len();
        if n == 0 {
            return Err(0.0);
        }
        if t < self.times[0] {
            return Err(self.values[0]);
        }
        // Last index k with times[k] <= t.
        let k = self.times.partition_point(|&x| x <= t) - 1;
        if k + 1 >= n {
            return Err(self.values[n - 1]);
        }
        let (t0, t1) = (self.times[k], self.times[k + 1]);
        let (f0, f1) = (self.values[k], self.values[k + 1]);
        if t1 <= t0 {
            return Err(f1);
        }
        Ok((t0, t1, f0, f1))
    }
}

/// How a support's motion factor is interpolated between the entries of its table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ramp {
    /// Piecewise linear.
    Linear,
    /// Smoothstep `3τ² − 2τ³` between consecutive entries: the factor's rate is zero at
    /// every entry (no velocity jump at the start or end of a ramp).
    Smooth,
}

impl TimeTable {
    /// Evaluates the table at `t` with `ramp` between its entries: linear (as
    /// [`Self::eval`]) or smoothstep `3τ² − 2τ³` (zero rate at every entry).
    pub fn eval_ramped(&self, ramp: Ramp, t: f64) -> f64 {
        match ramp {
            Ramp::Linear => self.eval(t),
            Ramp::Smooth => match self.segment(t) {
                Err(held) => held,
                Ok((t0, t1, f0, f1)) => {
                    let x = (t - t0) / (t1 - t0);
                    f0 + (f1 - f0) * x * x * (3.0 - 2.0 * x)
                }
            },
        }
    }
}
