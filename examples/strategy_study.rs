//! Measures how often the staggered and monolithic dissipation strategies converge on
//! the frame (free flight, elements starting at rest) across α and Δt.
//! `cargo run --release --example strategy_study`
use cosserat::integrator::{IntegratorParams, Scheme, Simulation, Strategy};
use cosserat::scene::load_scene;

fn main() {
    let scene = load_scene("frame").expect("built-in frame");
    println!("alpha,dt,strategy,steps_done,steps,newton_iters,wall_s,reason");
    for alpha in [0.5, 1.0, 2.0, 5.0] {
        for dt in [0.05, 0.2, 0.5] {
            for strategy in [Strategy::Staggered, Strategy::Monolithic] {
                let s = Scheme::Edmc2 {
                    alpha_gv: alpha,
                    alpha_gn: 0.0,
                    alpha_ov: 0.0,
                    alpha_on: 0.0,
                };
                let mut p = IntegratorParams::new(s, dt, 10.0);
                p.strategy = strategy;
                let mut sim = Simulation::new(scene.model.clone(), p).unwrap();
                let n = p.n_steps();
                let t0 = std::time::Instant::now();
                let (mut done, mut iters, mut reason) = (0, 0, String::new());
                for _ in 0..n {
                    match sim.step() {
                        Ok(r) => {
                            done += 1;
                            iters += r.newton_iters;
                        }
                        Err(f) => {
                            reason = f.reason;
                            break;
                        }
                    }
                }
                println!(
                    "{alpha},{dt},{strategy:?},{done},{n},{iters},{:.3},\"{}\"",
                    t0.elapsed().as_secs_f64(),
                    reason.replace('"', "'")
                );
            }
        }
    }
}
