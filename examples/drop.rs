//! Development probe: one or two bodies dropped on the ground.
use soda::physics::{Material, Shape};
use soda::sim::Simulation;
use soda::SceneBuilder;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let stack: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(1);
    let ball = args.get(2).map(|s| s == "ball").unwrap_or(false);
    let mut b = SceneBuilder::new([-5.0, -1.0, -5.0], [5.0, 30.0, 5.0]);
    for k in 0..stack {
        let shape = if ball {
            Shape::Ball { radius: 0.5 }
        } else {
            Shape::Cuboid {
                half_extents: [0.5; 3],
            }
        };
        let j = std::env::var("JIT").is_ok();
        let r = |s: u64| {
            if j {
                ((k as u64 * 2654435761 + s * 40503) % 1000) as f32 / 500.0 - 1.0
            } else {
                0.0
            }
        };
        b.body(
            shape,
            Material {
                restitution: if ball { 0.5 } else { 0.0 },
                ..Material::default()
            },
            [0.05 * r(1), 1.0 + 1.2 * k as f32 + 0.05 * r(2), 0.05 * r(3)],
            [0.03 + 0.04 * r(4), 0.04 * r(5), 0.02 + 0.04 * r(6)],
        );
    }
    let mut params = soda::physics::SolverParams::default();
    let env = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f32>().ok());
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
    if let Some(v) = env("VX") {
        b.velocity(stack as u64 - 1, [v, 0.0, 0.0]);
    }
    let b = b.solver(params);
    let mut sim = Simulation::new(b.build().unwrap());
    for s in 0..600 {
        sim.step();
        if s % 20 == 0 || s < 5 || std::env::var("ALL").is_ok() {
            let bodies = sim.state().sorted::<soda::RigidBodyModel>();
            let line: Vec<String> = bodies
                .iter()
                .filter(|b| {
                    std::env::var("ONLY")
                        .map(|o| o.split(',').any(|x| x.parse::<u64>().ok() == Some(b.id())))
                        .unwrap_or(true)
                })
                .map(|b| {
                    format!(
                        "x={:.3} y={:.4} vx={:.3} vy={:.3} w={:.3}",
                        b.position.x,
                        b.position.y,
                        b.linvel.x,
                        b.linvel.y,
                        b.angvel.norm()
                    )
                })
                .collect();
            println!("{s}: {}", line.join(" | "));
        }
    }
}
