//! Development probe: runs a built-in scene and prints measurements every second.
use soda::scene::builtin::builtin;
use soda::sim::{measure, Simulation};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let name = args.get(1).map(String::as_str).unwrap_or("falling-cubes");
    let n: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1000);
    let steps: u64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(600);
    let mut scene = builtin(name, Some(n), 0).expect("scene");
    let env = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f32>().ok());
    let params = &mut scene.solver;
    if let Some(v) = env("SUB") {
        params.substeps = v as u32;
    }
    if let Some(v) = env("SWEEPS") {
        params.sweeps = v as u32;
    }
    if let Some(v) = env("RELAX") {
        params.relaxation = v;
    }
    if let Some(v) = env("SEP") {
        params.max_separation_speed = v;
    }
    if let Some(v) = env("SLEEP_STEPS") {
        params.sleep_steps = v as u32;
    }
    if let Some(v) = env("SLEEP_SPEED") {
        params.sleep_speed = v;
    }
    let sleep_steps = params.sleep_steps;
    let mut sim = Simulation::new(scene);
    let t = std::time::Instant::now();
    for s in 0..steps {
        sim.step();
        if (s + 1)
            % std::env::var("EVERY")
                .ok()
                .and_then(|v| v.parse().ok())
                .unwrap_or(60)
            == 0
        {
            let r = measure(sim.reference());
            let all = sim.state().sorted::<soda::RigidBodyModel>();
            let f = all
                .iter()
                .max_by(|a, b| a.linvel.norm().total_cmp(&b.linvel.norm()))
                .unwrap();
            eprintln!(
                "   fastest id={} p={:?} v={:?} w={:?}",
                f.id(),
                f.position.as_slice(),
                f.linvel.as_slice(),
                f.angvel.as_slice()
            );
            let asleep = all
                .iter()
                .filter(|b| sleep_steps > 0 && u32::from(b.rest_steps) >= sleep_steps)
                .count();
            println!("t={:5.1}s asleep={asleep} bodies={} ke={:.3} vmax={:.3} pen={:.4} ymin={:.3} ymax={:.3} wall={:.2}s", (s + 1) as f32 / 60.0, r.bodies, r.kinetic_energy, r.max_speed, r.max_penetration, r.min_height, r.max_height, t.elapsed().as_secs_f32());
        }
    }
}
