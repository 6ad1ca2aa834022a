//! The built-in scenes, seeded and sized by parameters.

use super::{BodySpec, Scene, SceneBuilder, SceneError};
use crate::physics::{Material, Shape, SolverParams};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A built-in scene: its name, default body count and what it exercises.
pub struct Builtin {
    /// Name used on the command line.
    pub name: &'static str,
    /// Default number of bodies.
    pub default_objects: usize,
    /// One line for `soda scenes`.
    pub about: &'static str,
}

/// Every built-in scene.
pub const BUILTINS: &[Builtin] = &[
    Builtin { name: "falling-cubes", default_objects: 1000, about: "unit cubes on a jittered lattice fall onto the ground and settle in columns (the thesis's sample; the benchmark scene)" },
    Builtin { name: "sparse-gas", default_objects: 200, about: "balls bouncing elastically in a closed box without gravity, at low density" },
    Builtin { name: "dense-pile", default_objects: 500, about: "cubes and balls dropped into a narrow walled bin, forming a dense pile" },
    Builtin { name: "skewed", default_objects: 300, about: "a lattice of falling cubes in one corner of a large domain (load imbalance)" },
    Builtin { name: "chain", default_objects: 60, about: "a row of touching balls spanning the domain, pushed at one end (a chain across every territory)" },
    Builtin { name: "peak", default_objects: 1000, about: "a floor of balls spinning in place (a steady load) and a block of twice as many cubes landing at 1.5 s on one quadrant (a computational peak)" },
];

/// Builds the built-in scene `name` with `objects` bodies (or its default) and `seed`.
pub fn builtin(name: &str, objects: Option<usize>, seed: u64) -> Result<Scene, SceneError> {
    let info = BUILTINS
        .iter()
        .find(|b| b.name == name)
        .ok_or_else(|| SceneError::UnknownBuiltin(name.to_string()))?;
    let n = objects.unwrap_or(info.default_objects);
    if n == 0 || n > 1_000_000 {
        return Err(SceneError::Invalid {
            origin: format!("built-in scene {name}"),
            field: "objects".into(),
            value: n.to_string(),
            allowed: "must be between 1 and 1000000".into(),
        });
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let scene = match name {
        "falling-cubes" => falling_cubes(n, &mut rng, 10.0, [0.0, 0.0]),
        "skewed" => falling_cubes(n, &mut rng, 0.0, [1.0, 1.0]),
        "sparse-gas" => sparse_gas(n, &mut rng),
        "dense-pile" => dense_pile(n, &mut rng),
        "peak" => peak(n, &mut rng),
        _ => chain(n),
    };
    scene.name(name).seed(seed).build()
}

fn unit_cube() -> Shape {
    Shape::Cuboid {
        half_extents: [0.5; 3],
    }
}

/// The falling-cubes lattice: side = ceil(cbrt(n)) columns; x, z = (i − side/2)·1.2,
/// y = 1 + layer·1.2, jittered ±0.05 m and ±0.04 rad. `pad` metres of free domain around the
/// footprint; `corner` shifts the lattice into the domain's (+x, +z) corner of a domain
/// four times wider (the skewed scene) when non-zero.
fn falling_cubes(n: usize, rng: &mut ChaCha8Rng, pad: f32, corner: [f32; 2]) -> SceneBuilder {
    let side = (n as f64).cbrt().ceil() as usize;
    let layers = n.div_ceil(side * side);
    let half = side as f32 / 2.0;
    let lo = -half * 1.2 - 0.5;
    let hi = (side as f32 - 1.0 - half) * 1.2 + 0.5;
    let top = 1.0 + (layers as f32 - 1.0) * 1.2 + 0.5;
    let (min, max) = if corner == [0.0, 0.0] {
        ([lo - pad, -1.0, lo - pad], [hi + pad, top + 5.0, hi + pad])
    } else {
        let width = hi - lo;
        (
            [hi - 4.0 * width - 2.0, -1.0, hi - 4.0 * width - 2.0],
            [hi + 2.0, top + 5.0, hi + 2.0],
        )
    };
    let mut b = SceneBuilder::new(min, max);
    b.reserve(n);
    let mat = Material {
        density: 1.0,
        friction: 0.5,
        restitution: 0.0,
    };
    for k in 0..n {
        let layer = k / (side * side);
        let i = (k % (side * side)) % side;
        let j = (k % (side * side)) / side;
        let mut jit = || rng.random_range(-0.05f32..=0.05);
        let pos = [
            (i as f32 - half) * 1.2 + jit(),
            1.0 + layer as f32 * 1.2 + jit(),
            (j as f32 - half) * 1.2 + jit(),
        ];
        let mut rot = || rng.random_range(-0.04f32..=0.04);
        let r = [rot(), rot(), rot()];
        b.body(unit_cube(), mat, pos, r);
    }
    b.environment_material(0.5, 0.0)
}

fn sparse_gas(n: usize, rng: &mut ChaCha8Rng) -> SceneBuilder {
    let radius = 0.25;
    let side = (n as f64).cbrt().ceil() as usize;
    let spacing = 2.0;
    let extent = side as f32 * spacing;
    let mut b = SceneBuilder::new([0.0; 3], [extent; 3])
        .gravity([0.0; 3])
        .walls(true, true)
        .environment_material(0.0, 1.0);
    b.reserve(n);
    let mat = Material {
        density: 1.0,
        friction: 0.0,
        restitution: 1.0,
    };
    for k in 0..n {
        let c = [k % side, (k / side) % side, k / (side * side)];
        let mut jit = || rng.random_range(-0.3f32..=0.3);
        let pos = c.map(|c| (c as f32 + 0.5) * spacing);
        let pos = [pos[0] + jit(), pos[1] + jit(), pos[2] + jit()];
        let id = b.body(Shape::Ball { radius }, mat, pos, [0.0; 3]);
        let mut v = || rng.random_range(-3.0f32..=3.0);
        let vel = [v(), v(), v()];
        b.velocity(id, vel);
    }
    b
}

fn dense_pile(n: usize, rng: &mut ChaCha8Rng) -> SceneBuilder {
    let side = ((n as f64 / 4.0).sqrt().ceil() as usize).max(2);
    let spacing = 1.0;
    let layers = n.div_ceil(side * side);
    let width = side as f32 * spacing;
    let top = 0.5 + layers as f32 * spacing + 5.0;
    let mut b = SceneBuilder::new([0.0, -1.0, 0.0], [width, top, width])
        .walls(true, false)
        .environment_material(0.5, 0.0);
    b.reserve(n);
    let mat = Material {
        density: 1.0,
        friction: 0.5,
        restitution: 0.1,
    };
    for k in 0..n {
        let c = [k % side, k / (side * side), (k / side) % side];
        let mut jit = || rng.random_range(-0.03f32..=0.03);
        let pos = [
            (c[0] as f32 + 0.5) * spacing + jit(),
            0.5 + c[1] as f32 * spacing + 0.05 + jit().abs(),
            (c[2] as f32 + 0.5) * spacing + jit(),
        ];
        let shape = if k % 2 == 0 {
            Shape::Cuboid {
                half_extents: [0.4, 0.4, 0.4],
            }
        } else {
            Shape::Ball { radius: 0.4 }
        };
        b.body(shape, mat, pos, [0.0; 3]);
    }
    b
}

fn chain(n: usize) -> SceneBuilder {
    let radius = 0.5;
    let length = n as f32 * 2.0 * radius;
    let mut b = SceneBuilder::new([-1.0, -1.0, -2.0], [length + 1.0, 3.0, 2.0])
        .environment_material(0.1, 0.0);
    b.reserve(n);
    let mat = Material {
        density: 1.0,
        friction: 0.1,
        restitution: 0.5,
    };
    for k in 0..n {
        b.body(
            Shape::Ball { radius },
            mat,
            [radius + k as f32 * 2.0 * radius, radius, 0.0],
            [0.0; 3],
        );
    }
    b.velocity(0, [5.0, 0.0, 0.0]);
    b
}

/// Height of the peak scene's lowest burst layer: it lands after sqrt(2·11 m / g) ≈ 1.50 s,
/// step 90 at 60 steps per second.
pub const PEAK_DROP_HEIGHT: f32 = 11.5;

/// The peak scene: `n − ⌈2n/3⌉` balls (radius 0.4 m) resting on a square lattice (1.5 m
/// apart) and spinning about the vertical at 2 rad/s — their contact point does not slip,
/// and the scene turns torsional friction off (`patch_radius` 0, SPEC.md §5.3), so they never
/// slow down or fall asleep: a steady load on every territory — and, above the
/// centre of the (+x, +z) quadrant, a block of `⌈2n/3⌉` unit cubes (the falling-cubes
/// lattice, jittered by `rng`) whose lowest layer starts at [`PEAK_DROP_HEIGHT`]. The floor
/// is left clear 2 m around the block's footprint, so the landing stays in that quadrant;
/// 10 m of free domain surround the floor.
/// The lattice is the smallest square whose sites outside the clearing hold the balls.
fn peak(n: usize, rng: &mut ChaCha8Rng) -> SceneBuilder {
    const SPACING: f32 = 1.5;
    const RADIUS: f32 = 0.4;
    let cubes = (2 * n).div_ceil(3);
    let balls = n - cubes;
    let side = (cubes as f64).cbrt().ceil() as usize;
    let layers = cubes.div_ceil(side * side);
    let clearing = side as f32 * 1.2 + 4.0;
    let inside = |c: f32, x: f32| (x - c).abs() < clearing / 2.0;
    // Lattice sites of an s × s floor outside the clearing of the (+x, +z) quadrant's centre.
    let sites = |s: usize| -> Vec<[f32; 2]> {
        let centre = s as f32 * SPACING / 4.0;
        let coord = |i: usize| (i as f32 - (s as f32 - 1.0) / 2.0) * SPACING;
        (0..s * s)
            .map(|k| [coord(k % s), coord(k / s)])
            .filter(|p| !(inside(centre, p[0]) && inside(centre, p[1])))
            .collect()
    };
    let mut s = ((2.0 * clearing / SPACING).ceil() as usize).max(2);
    while sites(s).len() < balls {
        s += 1;
    }
    let half = s as f32 * SPACING / 2.0 + 10.0;
    let centre = s as f32 * SPACING / 4.0;
    let top = PEAK_DROP_HEIGHT + (layers as f32 - 1.0) * 1.2 + 0.5;
    let mut b = SceneBuilder::new([-half, -1.0, -half], [half, top + 5.0, half])
        .environment_material(0.5, 0.0)
        .solver(SolverParams {
            patch_radius: 0.0,
            ..SolverParams::default()
        });
    b.reserve(n);
    let material = Material::default();
    for (k, p) in sites(s).into_iter().take(balls).enumerate() {
        b = b.body_spec(BodySpec {
            id: k as u64,
            shape: Shape::Ball { radius: RADIUS },
            material,
            position: [p[0], RADIUS, p[1]],
            rotation: [0.0; 3],
            velocity: [0.0; 3],
            angular_velocity: [0.0, 2.0, 0.0],
        });
    }
    let mid = (side as f32 - 1.0) / 2.0;
    for k in 0..cubes {
        let layer = k / (side * side);
        let i = (k % (side * side)) % side;
        let j = (k % (side * side)) / side;
        let mut jit = || rng.random_range(-0.05f32..=0.05);
        let pos = [
            centre + (i as f32 - mid) * 1.2 + jit(),
            PEAK_DROP_HEIGHT + layer as f32 * 1.2 + jit(),
            centre + (j as f32 - mid) * 1.2 + jit(),
        ];
        let mut rot = || rng.random_range(-0.04f32..=0.04);
        let r = [rot(), rot(), rot()];
        b.body(unit_cube(), material, pos, r);
    }
    b
}
