//! The graphics driver's share of the host thread: every submission and every wait of the
//! GPU path goes through `submit` and `wait`, which add the calling thread's CPU time
//! inside them to a per-thread account ([`driver_thread_s`]).
//!
//! On a real GPU these calls hand work to the device and sleep while it runs; on a
//! software adapter (lavapipe) the driver executes the command buffers' commands on the
//! submitting thread, so its CPU time is the device's own work, not the host's. `bench`
//! reports the two apart (docs/gpu.md, "Host time and driver time").

use std::cell::Cell;

use super::GpuError;

thread_local! {
    static DRIVER_S: Cell<f64> = const { Cell::new(0.0) };
    static DRIVER_WALL_S: Cell<f64> = const { Cell::new(0.0) };
}

/// CPU time of the calling thread, in seconds (wall time since the first call where the
/// platform has no per-thread clock).
pub fn thread_cpu_s() -> f64 {
    #[cfg(unix)]
    {
        let mut ts = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: `ts` is a valid, writable timespec; the clock id is a constant.
        if unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) } == 0 {
            return ts.tv_sec as f64 + 1e-9 * ts.tv_nsec as f64;
        }
    }
    use std::sync::OnceLock;
    use std::time::Instant;
    static START: OnceLock<Instant> = OnceLock::new();
    START.get_or_init(Instant::now).elapsed().as_secs_f64()
}

/// The calling thread's CPU seconds spent inside `submit` and `wait` so far.
pub fn driver_thread_s() -> f64 {
    DRIVER_S.with(Cell::get)
}

/// The calling thread's wall seconds spent inside `submit` and `wait` so far (on a GPU,
/// mostly the waits for the device).
pub fn driver_wall_s() -> f64 {
    DRIVER_WALL_S.with(Cell::get)
}

/// Runs `f`, adding the calling thread's CPU time and wall time inside it to its driver
/// accounts.
fn account<T>(f: impl FnOnce() -> T) -> T {
    let t0 = thread_cpu_s();
    let w0 = std::time::Instant::now();
    let out = f();
    let dt = thread_cpu_s() - t0;
    DRIVER_S.with(|c| c.set(c.get() + dt));
    DRIVER_WALL_S.with(|c| c.set(c.get() + w0.elapsed().as_secs_f64()));
    out
}

/// `queue.submit` of one command buffer, accounted.
pub(crate) fn submit(queue: &wgpu::Queue, commands: wgpu::CommandBuffer) {
    account(|| {
        queue.submit(Some(commands));
    });
}

/// Waits until the device has finished all submitted work (and mapping callbacks ran),
/// accounted.
pub(crate) fn wait(device: &wgpu::Device) -> Result<(), GpuError> {
    account(|| device.poll(wgpu::PollType::wait_indefinitely()))
        .map(|_| ())
        .map_err(|e| GpuError::Kernel(e.to_string()))
}
