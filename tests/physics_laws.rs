//! Physical laws the rigid-body model must keep on any scene, not only on cube piles
//! (issue 23): momentum in isolated collisions, energy in closed systems, restitution,
//! rolling, resting contacts, no NaN, and removal only at the declared domain's edge.
//! Property tests draw sizes, masses, velocities, spins and contact geometries.

mod physics_support;

use physics_support::{ball_box, ball_pile, mixed_pile};
use proptest::prelude::*;
use soda::math::Vec3;
use soda::physics::{Material, Shape};
use soda::scene::BodySpec;
use soda::sim::Simulation;
use soda::{Body, RigidBodyModel, Scene, SceneBuilder};

/// The state sorted by id, cloned.
fn bodies(sim: &Simulation) -> Vec<Body> {
    sim.state()
        .sorted::<RigidBodyModel>()
        .into_iter()
        .cloned()
        .collect()
}

/// Total linear momentum, kg·m/s, summed in f64 in id order.
fn momentum(bs: &[Body]) -> [f64; 3] {
    let mut p = [0.0f64; 3];
    for b in bs {
        for (k, pk) in p.iter_mut().enumerate() {
            *pk += b.mass() as f64 * b.linvel[k] as f64;
        }
    }
    p
}

/// Σ m·|v|: the scale momentum errors are measured against.
fn momentum_scale(bs: &[Body]) -> f64 {
    bs.iter()
        .map(|b| b.mass() as f64 * b.linvel.norm() as f64)
        .sum()
}

fn kinetic(bs: &[Body]) -> f64 {
    soda::physics::metrics::kinetic_energy(bs.iter())
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// A free-space scene: no gravity, no ground, no walls, an 80 m box.
fn free_space() -> SceneBuilder {
    SceneBuilder::new([-40.0; 3], [40.0; 3])
        .gravity([0.0; 3])
        .ground(None)
}

/// A body as drawn by the strategies.
#[derive(Clone, Debug)]
struct Drawn {
    shape: Shape,
    density: f32,
    rotation: [f32; 3],
    spin: [f32; 3],
}

impl Drawn {
    /// Radius of the largest ball about the centre inside the shape.
    fn inner_radius(&self) -> f32 {
        match self.shape {
            Shape::Ball { radius } => radius,
            Shape::Cuboid { half_extents: h } => h[0].min(h[1]).min(h[2]),
        }
    }
}

fn shape() -> impl Strategy<Value = Shape> {
    prop_oneof![
        (0.15f32..0.8).prop_map(|radius| Shape::Ball { radius }),
        (0.15f32..0.6, 0.15f32..0.6, 0.15f32..0.6).prop_map(|(x, y, z)| Shape::Cuboid {
            half_extents: [x, y, z]
        }),
    ]
}

fn drawn() -> impl Strategy<Value = Drawn> {
    (
        shape(),
        0.3f32..4.0,
        prop::array::uniform3(-3.1f32..3.1),
        prop::array::uniform3(-4.0f32..4.0),
    )
        .prop_map(|(shape, density, rotation, spin)| Drawn {
            shape,
            density,
            rotation,
            spin,
        })
}

fn spec(
    id: u64,
    d: &Drawn,
    material: Material,
    position: [f32; 3],
    velocity: [f32; 3],
) -> BodySpec {
    BodySpec {
        id,
        shape: d.shape,
        material: Material {
            density: d.density,
            ..material
        },
        position,
        rotation: d.rotation,
        velocity,
        angular_velocity: d.spin,
    }
}

/// Runs `scene` for `steps` steps; returns the states after every step (step 0 first).
/// One ball of radius `r` resting on the ground at `(x, z)` in a domain `±half` wide, ball
/// and ground of friction `friction`, restitution 0.
fn ball_on_the_ground(
    half: f32,
    r: f32,
    density: f32,
    friction: f32,
    at: [f32; 2],
    velocity: [f32; 3],
    angular_velocity: [f32; 3],
) -> Scene {
    SceneBuilder::new([-half, -1.0, -half], [half, 5.0, half])
        .environment_material(friction, 0.0)
        .body_spec(BodySpec {
            id: 0,
            shape: Shape::Ball { radius: r },
            material: Material {
                density,
                friction,
                restitution: 0.0,
            },
            position: [at[0], r, at[1]],
            rotation: [0.3, -1.1, 2.0],
            velocity,
            angular_velocity,
        })
        .build()
        .unwrap()
}

fn history(scene: Scene, steps: u32) -> Vec<Vec<Body>> {
    let mut sim = Simulation::new(scene);
    let mut out = vec![bodies(&sim)];
    for _ in 0..steps {
        sim.step();
        out.push(bodies(&sim));
    }
    out
}

/// Body 1's velocity relative to body 0's: a collision changes it by the impulse over the
/// reduced mass, however unequal the masses.
fn relative_velocity(s: &[Body]) -> Vec3 {
    s[1].linvel - s[0].linvel
}

/// Runs `scene` for `steps` steps and checks that its kinetic energy never grows from one
/// step to the next (beyond f32 rounding: a relative 1e-5 and 1e-9 J); returns the states
/// after the last step, or where and how much it grew.
fn never_gains_kinetic_energy(scene: Scene, steps: u32) -> Result<Vec<Body>, String> {
    let mut sim = Simulation::new(scene);
    let mut prev = kinetic(&bodies(&sim));
    for step in 1..=steps {
        sim.step();
        let now = kinetic(&bodies(&sim));
        if now > prev * (1.0 + 1e-5) + 1e-9 {
            return Err(format!(
                "kinetic energy grew at step {step}: {prev} J -> {now} J"
            ));
        }
        prev = now;
    }
    Ok(bodies(&sim))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Two bodies of any shapes, sizes, masses, spins and orientations meet in free space,
    /// head-on or off-centre: total momentum is the same after the collision (1e-4 of
    /// Σ m·|v|), and the collision did happen.
    #[test]
    fn isolated_pair_collision_conserves_momentum(
        a in drawn(),
        b in drawn(),
        speed_a in 0.5f32..8.0,
        speed_b in 0.0f32..8.0,
        lateral in prop::array::uniform2(-0.8f32..0.8),
        friction in 0.0f32..1.0,
        restitution in 0.0f32..1.0,
    ) {
        let material = Material { density: 1.0, friction, restitution };
        let ra = a.shape.bounding_radius();
        let rb = b.shape.bounding_radius();
        // Lateral offset within 80 % of the inner radii: the bodies must hit.
        let reach = a.inner_radius() + b.inner_radius();
        let (y, z) = (lateral[0] * reach * 0.7, lateral[1] * reach * 0.7);
        let mut builder = free_space();
        builder = builder.body_spec(spec(0, &a, material, [-ra - 0.3, 0.0, 0.0], [speed_a, 0.0, 0.0]));
        builder = builder.body_spec(spec(1, &b, material, [rb + 0.3, y, z], [-speed_b, 0.0, 0.0]));
        let scene = builder.build().unwrap();
        // Long enough to close the centres' whole distance (the surfaces may be that far apart
        // less the inner radii, as the tumbling bodies turn), plus half a second.
        let closing = (ra + rb + 0.6) / (speed_a + speed_b) / scene.dt;
        let steps = 90u32.max(closing.ceil() as u32 + 30);
        let h = history(scene, steps);
        let (first, last) = (&h[0], &h[h.len() - 1]);
        prop_assert_eq!(last.len(), 2);
        // The relative velocity changes by the impulse over the reduced mass, however heavy
        // one body is against the other (body 0's own change is the lighter partner's
        // share, and could fall below any fixed threshold).
        let rel = relative_velocity;
        prop_assert!((rel(last) - rel(first)).norm() > 1e-3, "no collision happened: {:?}", rel(last));
        let scale = momentum_scale(first);
        for (step, s) in h.iter().enumerate() {
            let err = distance(momentum(s), momentum(first));
            prop_assert!(
                err <= 1e-4 * scale,
                "step {}: momentum {:?} vs {:?} at step 0 (error {} > 1e-4 × {})",
                step, momentum(s), momentum(first), err, scale
            );
        }
    }

    /// Two bodies of any shapes, sizes, masses and spins collide in any direction — vertical
    /// included — while falling under gravity, far from any ground or wall: the total
    /// momentum is the start's plus gravity's impulse `Σm·g·t` (1e-4 of the largest Σ m·|v|
    /// of the run), and the collision did happen (the run lasts until the centres must have
    /// met: a spinning elongated body can turn its long side away for a while). Before the support depth (SPEC.md §5.2) a
    /// vertical collision in flight was solved as a support (shock propagation): the lower
    /// body kept its velocity and the upper one stopped on it.
    #[test]
    fn collision_in_flight_under_gravity_conserves_momentum(
        a in drawn(),
        b in drawn(),
        direction in prop::array::uniform3(-1.0f32..1.0),
        vertical in any::<bool>(),
        speed_a in 0.5f32..8.0,
        speed_b in 0.0f32..8.0,
        lateral in prop::array::uniform2(-0.8f32..0.8),
        friction in 0.0f32..1.0,
        restitution in 0.0f32..1.0,
    ) {
        use soda::math::Vec3;
        let material = Material { density: 1.0, friction, restitution };
        // Half of the cases straight up or down (the shock-propagation case), the rest any
        // direction.
        let raw = Vec3::from(direction);
        let d = if vertical || raw.norm() < 0.1 {
            Vec3::new(0.0, if direction[0] < 0.0 { -1.0 } else { 1.0 }, 0.0)
        } else {
            raw.normalize()
        };
        // Two unit vectors across `d`, for an off-centre hit within 56 % of the inner radii.
        let helper = if d.x.abs() < 0.9 { Vec3::x() } else { Vec3::y() };
        let (s, t) = {
            let s = d.cross(&helper).normalize();
            (s, d.cross(&s))
        };
        let off = (s * lateral[0] + t * lateral[1]) * ((a.inner_radius() + b.inner_radius()) * 0.7);
        let (ra, rb) = (a.shape.bounding_radius(), b.shape.bounding_radius());
        let pa = -d * (ra + 0.3);
        let pb = d * (rb + 0.3) + off;
        let g = -9.81f32;
        let builder = SceneBuilder::new([-40.0; 3], [40.0; 3])
            .gravity([0.0, g, 0.0])
            .ground(None)
            .body_spec(spec(0, &a, material, pa.into(), (d * speed_a).into()))
            .body_spec(spec(1, &b, material, pb.into(), (-d * speed_b).into()));
        let scene = builder.build().unwrap();
        let dt = scene.dt as f64;
        // Long enough for the centres to close from their start to within the inner radii
        // at the closing speed (gravity moves both alike), whatever the spins turn the
        // shapes to, plus half a second: the collision must happen.
        let closing = ra + rb + 0.6 - a.inner_radius() - b.inner_radius();
        let steps = (closing / ((speed_a + speed_b) * scene.dt)).ceil() as u32 + 30;
        let max_speed = scene.solver.max_speed;
        let h = history(scene, steps.max(90));
        let (first, last) = (&h[0], &h[h.len() - 1]);
        prop_assert_eq!(last.len(), 2);
        // Gravity changes both velocities alike: the collision shows in the relative one.
        let rel = relative_velocity;
        prop_assert!((rel(last) - rel(first)).norm() > 1e-3, "no collision happened: {:?}", rel(last));
        let mass: f64 = first.iter().map(|b| b.mass() as f64).sum();
        let scale = h.iter().map(|s| momentum_scale(s)).fold(0.0f64, f64::max);
        let p0 = momentum(first);
        for (step, s) in h.iter().enumerate() {
            // The speed cap (SPEC.md §3, a `speed-capped` event) takes momentum by design: a
            // body knocked downwards reaches it while falling on after the collision.
            if s.iter().any(|b| b.linvel.norm() >= 0.999 * max_speed) {
                break;
            }
            let expected = [p0[0], p0[1] + mass * g as f64 * dt * step as f64, p0[2]];
            let err = distance(momentum(s), expected);
            prop_assert!(
                err <= 1e-4 * scale,
                "step {}: momentum {:?}, expected {:?} (error {} > 1e-4 × {})",
                step, momentum(s), expected, err, scale
            );
        }
    }

    /// Restitution measured from head-on collisions of two balls or two face-aligned boxes
    /// (any sizes and masses, no friction effects on a head-on hit) is the material's
    /// within ±0.05.
    #[test]
    fn head_on_restitution_matches_the_material(
        cubes in any::<bool>(),
        sa in 0.2f32..0.8,
        sb in 0.2f32..0.8,
        da in 0.3f32..4.0,
        db in 0.3f32..4.0,
        va in 0.5f32..8.0,
        vb in -3.0f32..3.0,
        restitution in 0.0f32..=1.0,
        friction in 0.0f32..1.0,
    ) {
        let shape = |s: f32| if cubes { Shape::Cuboid { half_extents: [s; 3] } } else { Shape::Ball { radius: s } };
        let body = |id, s, d, x: f32, v: f32| BodySpec {
            id,
            shape: shape(s),
            material: Material { density: d, friction, restitution },
            position: [x, 0.0, 0.0],
            rotation: [0.0; 3],
            velocity: [v, 0.0, 0.0],
            angular_velocity: [0.0; 3],
        };
        let builder = free_space()
            .body_spec(body(0, sa, da, -sa - 0.25, va))
            .body_spec(body(1, sb, db, sb + 0.25, vb.min(va - 0.5)));
        let h = history(builder.build().unwrap(), 90);
        let approach = h[0][0].linvel.x - h[0][1].linvel.x;
        let last = &h[h.len() - 1];
        let separation = last[1].linvel.x - last[0].linvel.x;
        let e = separation / approach;
        prop_assert!(
            (e - restitution).abs() <= 0.05,
            "measured e = {} (separation {} / approach {}), material e = {}",
            e, separation, approach, restitution
        );
    }

    /// Two frictionless balls meet obliquely in free space, any radii, densities, speed,
    /// restitution, impact parameter and starting gap: the struck ball, at rest before,
    /// leaves along the line of centres at the moment they touch (1 mrad), at the textbook
    /// speed `(1 + e)·m_a/(m_a + m_b)·v·cos θ` (0.1 %), and momentum is kept. While the
    /// pair's normal was the line of centres at the step's start, up to a step's travel
    /// before the touch, a ball struck at 2 m/s with the impact parameter equal to its
    /// radius left at −28.6° instead of −30° (docs/open-defects, §8).
    #[test]
    fn an_oblique_impact_of_balls_acts_along_the_line_of_centres_at_the_touch(
        ra in 0.1f32..0.5,
        rb in 0.1f32..0.5,
        da in 0.3f32..4.0,
        db in 0.3f32..4.0,
        speed in 0.5f32..8.0,
        aim in 0.0f32..0.9,
        heading in 0.0f32..std::f32::consts::TAU,
        gap in 0.002f32..0.3,
        restitution in 0.0f32..=1.0,
    ) {
        let reach = ra + rb;
        // The offset of b's centre across the line of motion, in the plane at `heading`.
        let across = aim * reach;
        let (y, z) = (across * heading.cos(), across * heading.sin());
        let along = (reach * reach - across * across).sqrt();
        let body = |id, r, d, position, velocity| BodySpec {
            id,
            shape: Shape::Ball { radius: r },
            material: Material { density: d, friction: 0.0, restitution },
            position,
            rotation: [0.0; 3],
            velocity,
            angular_velocity: [0.0; 3],
        };
        let scene = free_space()
            .body_spec(body(0, ra, da, [-along - gap, -y, -z], [speed, 0.0, 0.0]))
            .body_spec(body(1, rb, db, [0.0; 3], [0.0; 3]))
            .build()
            .unwrap();
        let steps = (gap / speed / scene.dt).ceil() as u32 + 3;
        let h = history(scene, steps);
        let (first, last) = (&h[0], &h[h.len() - 1]);
        // At the touch, b's centre lies `(along, y, z)` from a's: the line of centres.
        let normal = Vec3::new(along, y, z) / reach;
        let (ma, mb) = (first[0].mass(), first[1].mass());
        let expected = (1.0 + restitution) * ma / (ma + mb) * speed * normal.x;
        let v = last[1].linvel;
        prop_assert!(
            (v.norm() - expected).abs() <= 1e-3 * expected + 1e-6,
            "the struck ball leaves at {} m/s, not {}", v.norm(), expected
        );
        let off = v.normalize().cross(&normal).norm().asin();
        prop_assert!(
            off <= 1e-3,
            "the struck ball leaves {} rad off the line of centres at the touch ({:?}, not {:?})",
            off, v.normalize(), normal
        );
        let err = distance(momentum(last), momentum(first));
        prop_assert!(err <= 1e-4 * momentum_scale(first), "momentum changed by {}", err);
    }

    /// A ball rolling on flat ground — without slip, or spinning slower than rolling so that
    /// friction acts — any radius, density, speed and friction, never speeds up and never
    /// gains kinetic energy (600 steps).
    #[test]
    fn rolling_ball_never_speeds_up(
        r in 0.1f32..1.0,
        density in 0.3f32..4.0,
        v in 0.05f32..5.0,
        friction in 0.0f32..1.0,
        slip in 0.0f32..1.0,
    ) {
        // Rolling (slip 0) to sliding on a still ball (slip 1).
        let spin = [0.0, 0.0, -(1.0 - slip) * v / r];
        let scene = ball_on_the_ground(60.0, r, density, friction, [-50.0, 0.0], [v, 0.0, 0.0], spin);
        let h = history(scene, 600);
        let v0 = h[0][0].linvel.norm();
        for (step, pair) in h.windows(2).enumerate() {
            let speed = pair[1][0].linvel.norm();
            prop_assert!(speed <= v0 * (1.0 + 1e-4) + 1e-6, "step {}: {} m/s > {} m/s", step + 1, speed, v0);
            let (e0, e1) = (kinetic(&pair[0]), kinetic(&pair[1]));
            prop_assert!(e1 <= e0 * (1.0 + 1e-5) + 1e-9, "step {}: kinetic energy {} J -> {} J", step + 1, e0, e1);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// A ball thrown sliding along the ground without spin — radius 1 cm to 0.5 m, speed up
    /// to 20 m/s, any friction — ends rolling at 5/7 of its speed (a solid ball, `I = ⅖·m·r²`)
    /// with `ω·r` equal to its speed, having slid for `2·v₀/(7·μ·g)`, and no speed cap bites
    /// (SPEC.md §3: a body may spin as fast as moves its bounding sphere's surface at
    /// `max_speed`). Capped at 60 rad/s whatever its size, a 5 cm ball thrown at 5 m/s was
    /// braked to 3 m/s and slid for ever.
    #[test]
    fn a_sliding_ball_ends_rolling_at_five_sevenths_of_its_speed(
        r in 0.01f32..0.5,
        density in 0.3f32..4.0,
        v0 in 1.0f32..20.0,
        friction in 0.2f32..1.0,
    ) {
        let g = 9.81f32;
        // Slides at most 2·20/(7·0.2·g) ≈ 2.9 s (≤ 60 m), then rolls for 30 steps.
        let scene = ball_on_the_ground(120.0, r, density, friction, [-110.0, 0.0], [v0, 0.0, 0.0], [0.0; 3]);
        let sliding = 2.0 * v0 / (7.0 * friction * g);
        let steps = (sliding / scene.dt) as u32 + 30;
        let mut sim = Simulation::new(scene);
        for _ in 0..steps {
            let frame = sim.step();
            prop_assert!(frame.events.is_empty(), "step {}: {:?}", frame.step, frame.events);
        }
        let b = &bodies(&sim)[0];
        let rolling = 5.0 / 7.0 * v0;
        prop_assert!((b.linvel.x - rolling).abs() <= 1e-3 * rolling, "{} m/s, not {}", b.linvel.x, rolling);
        prop_assert!((-b.angvel.z * r - b.linvel.x).abs() <= 1e-3 * rolling, "ω·r = {} against v = {}", -b.angvel.z * r, b.linvel.x);
        prop_assert!(b.linvel.y.abs() <= 1e-4 && b.linvel.z == 0.0, "{:?}", b.linvel);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    /// Torsional friction means what it says (SPEC.md §5.3): a ball spinning about the
    /// vertical while it rests on the ground loses spin at `μ·g·ρ·m/I = μ·g·ρ/(0.4·r²)` rad/s²
    /// (`ρ` the solver's `patch_radius`, `μ` the pair's friction), never speeds up, never
    /// turns the other way, and never moves. Before it, such a ball spun for ever and kept a
    /// pile awake.
    #[test]
    fn a_ball_spinning_on_the_ground_slows_at_the_torsional_friction_rate(
        r in 0.1f32..1.0,
        density in 0.3f32..4.0,
        friction in 0.05f32..1.0,
        spin in 2.0f32..30.0,
        sign in prop::bool::ANY,
    ) {
        spinning_ball_slows_at_the_torsional_rate(r, density, friction, if sign { spin } else { -spin })?;
    }
}

/// A full torsional stop never leaves the spin one ulp on the other side of zero: this ball
/// (drawn by the property test above) went from −9.3e-10 to +9.9e-32 rad/s at step 45 when
/// the stop was computed as `ω·n − k·(ω·n / k)` alone (SPEC.md §5.3).
#[test]
fn a_full_torsional_stop_never_reverses_the_spin_by_rounding() {
    spinning_ball_slows_at_the_torsional_rate(0.19472826, 2.9408813, 0.8967294, -2.1137593)
        .unwrap();
}

/// The torsional-friction law of `a_ball_spinning_on_the_ground_slows_at_the_torsional_friction_rate`
/// for one ball: radius `r`, `density`, `friction`, starting `spin` about the vertical.
fn spinning_ball_slows_at_the_torsional_rate(
    r: f32,
    density: f32,
    friction: f32,
    spin: f32,
) -> Result<(), TestCaseError> {
    let scene = ball_on_the_ground(
        10.0,
        r,
        density,
        friction,
        [0.0, 0.0],
        [0.0; 3],
        [0.0, spin, 0.0],
    );
    let rho = scene.solver.patch_radius;
    let h = history(scene, 60);
    let rate = friction * 9.81 * rho / (0.4 * r * r);
    for (step, pair) in h.windows(2).enumerate() {
        let (w0, w1) = (pair[0][0].angvel.y, pair[1][0].angvel.y);
        prop_assert!(
            w1.abs() <= w0.abs() && w1 * spin >= 0.0,
            "step {}: spin {} -> {} rad/s",
            step + 1,
            w0,
            w1
        );
        let p = pair[1][0].position;
        prop_assert!(
            (p.x.abs() + p.z.abs()) < 1e-4,
            "step {}: the spinning ball moved to {:?}",
            step + 1,
            p
        );
    }
    let expected = (spin.abs() - rate).max(0.0);
    let measured = h[60][0].angvel.y.abs();
    prop_assert!(
        (measured - expected).abs() <= 0.1 * rate + 1e-3,
        "spin after 1 s: {} rad/s, expected {} (from {} at {} rad/s²)",
        measured,
        expected,
        spin,
        rate
    );
    Ok(())
}

/// A dense gas of random-size balls (and boxes if `cubes`) without gravity, in a closed box
/// if `walls`, else in free space (the same lattice, no ground).
fn ball_gas(
    n: usize,
    seed: u64,
    restitution: f32,
    friction: f32,
    cubes: bool,
    walls: bool,
) -> Scene {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let side = (n as f64).cbrt().ceil() as usize;
    let spacing = 1.0f32;
    let extent = side as f32 * spacing;
    let (lo, hi) = if walls {
        (0.0, extent)
    } else {
        (-40.0, 40.0 + extent)
    };
    let mut b = SceneBuilder::new([lo; 3], [hi; 3])
        .gravity([0.0; 3])
        .walls(walls, walls)
        .ground(walls.then_some(0.0))
        .environment_material(friction, restitution);
    for k in 0..n {
        let c = [k % side, (k / side) % side, k / (side * side)];
        let pos = c.map(|c| (c as f32 + 0.5) * spacing + rng.random_range(-0.05f32..0.05));
        let shape = if cubes && k % 3 == 0 {
            let s = rng.random_range(0.12f32..0.22);
            Shape::Cuboid {
                half_extents: [s, rng.random_range(0.12f32..0.22), s],
            }
        } else {
            Shape::Ball {
                radius: rng.random_range(0.2f32..0.35),
            }
        };
        b = b.body_spec(BodySpec {
            id: k as u64,
            shape,
            material: Material {
                density: rng.random_range(0.5f32..2.0),
                friction,
                restitution,
            },
            position: pos,
            rotation: [
                rng.random_range(-3.0f32..3.0),
                0.0,
                rng.random_range(-3.0f32..3.0),
            ],
            velocity: [0, 1, 2].map(|_| rng.random_range(-3.0f32..3.0)),
            angular_velocity: [0.0; 3],
        });
    }
    b.build().unwrap()
}

/// An elastic, frictionless gas of 343 balls of random sizes and masses (≈ 10 % of the box's
/// volume) in a closed box: kinetic energy stays within 1 % of its start over 1,000 steps.
#[test]
fn elastic_ball_gas_keeps_its_energy_within_one_percent() {
    for seed in [1, 2] {
        let mut sim = Simulation::new(ball_gas(343, seed, 1.0, 0.0, false, true));
        let e0 = kinetic(&bodies(&sim));
        let mut worst = 0.0f64;
        for _ in 0..1000 {
            sim.step();
            let e = kinetic(&bodies(&sim));
            worst = worst.max((e - e0).abs() / e0);
        }
        assert_eq!(bodies(&sim).len(), 343, "seed {seed}: bodies lost");
        assert!(
            worst <= 0.01,
            "seed {seed}: kinetic energy drifted by {:.3} % (start {e0:.3} J)",
            worst * 100.0
        );
    }
}

/// With restitution below 1 (and friction), a dense gas of balls and boxes colliding in
/// free space — a closed system of body–body contacts only — never gains kinetic energy from
/// one step to the next (beyond f32 rounding).
#[test]
fn inelastic_collisions_never_increase_kinetic_energy() {
    for (seed, e, mu) in [(3, 0.9, 0.0), (4, 0.5, 0.3), (5, 0.0, 0.8), (6, 0.95, 0.5)] {
        if let Err(grew) = never_gains_kinetic_energy(ball_gas(216, seed, e, mu, true, false), 400)
        {
            panic!("seed {seed} (e {e}, μ {mu}): {grew}");
        }
    }
}

/// The same gas in a closed box (walls, ground and ceiling): neither body–body contacts nor
/// contacts with static surfaces — depenetrations included, which move positions without
/// adding velocity (SPEC.md §5.3) — ever raise the kinetic energy from one step to the next
/// (beyond f32 rounding).
#[test]
fn inelastic_gas_in_a_box_never_gains_kinetic_energy() {
    for (seed, e, mu) in [(3, 0.9, 0.0), (4, 0.5, 0.3), (5, 0.0, 0.8), (6, 0.95, 0.5)] {
        if let Err(grew) = never_gains_kinetic_energy(ball_gas(216, seed, e, mu, true, true), 600) {
            panic!("seed {seed} (e {e}, μ {mu}): {grew}");
        }
    }
}

/// Two clusters of balls and boxes meet head-on in free space with equal and opposite
/// momentum: total momentum stays 0 (1e-4 of Σ m·|v|) through the collision.
#[test]
fn cluster_collision_conserves_momentum() {
    let mut b = free_space();
    let mut id = 0;
    for side in [-1.0f32, 1.0] {
        for k in 0..27 {
            let c = [k % 3, (k / 3) % 3, k / 9].map(|c| c as f32 - 1.0);
            let shape = if k % 2 == 0 {
                Shape::Ball { radius: 0.4 }
            } else {
                Shape::Cuboid {
                    half_extents: [0.35, 0.4, 0.3],
                }
            };
            b = b.body_spec(BodySpec {
                id,
                shape,
                material: Material {
                    density: 1.0,
                    friction: 0.5,
                    restitution: 0.3,
                },
                position: [side * (2.5 + c[0]) + 0.05 * c[1], c[1] + 0.1 * c[2], c[2]],
                rotation: [0.1 * c[0], 0.2 * c[1], 0.3 * c[2]],
                velocity: [-side * 3.0, 0.0, 0.0],
                angular_velocity: [0.0; 3],
            });
            id += 1;
        }
    }
    let h = history(b.build().unwrap(), 300);
    let scale = momentum_scale(&h[0]);
    let mut touched = false;
    for (step, s) in h.iter().enumerate() {
        let p = momentum(s);
        assert!(
            distance(p, [0.0; 3]) <= 1e-4 * scale,
            "step {step}: momentum {p:?} (scale {scale})"
        );
        touched |= s.iter().any(|b| b.linvel.x.abs() < 2.0);
    }
    assert!(touched, "the clusters never met");
}

/// Issue 23's body-deleting NaN: a ball resting on the ground, touching a wall with zero
/// gap, rotated, with a tiny velocity. Any rotation and drift: it stays finite, in the
/// domain and (nearly) still.
#[test]
fn ball_touching_ground_and_wall_with_zero_gap_stays_finite_and_still() {
    for (k, rotation) in [
        [-0.714f32, 0.13, -2.913],
        [0.0, 0.0, 0.0],
        [3.1, -1.5, 0.7],
        [1.0, 2.0, 3.0],
    ]
    .into_iter()
    .enumerate()
    {
        let builder = SceneBuilder::new([-11.0, -1.0, -11.0], [11.0, 16.0, 11.0])
            .walls(true, false)
            .body_spec(BodySpec {
                id: 0,
                shape: Shape::Ball { radius: 0.5 },
                material: Material::default(),
                position: [0.0, 0.5, 10.5],
                rotation,
                velocity: [0.001 * (k as f32 + 1.0), 0.0, 0.0],
                angular_velocity: [0.0; 3],
            });
        let mut sim = Simulation::new(builder.build().unwrap());
        for step in 0..300 {
            let f = sim.step();
            assert!(
                f.events.is_empty(),
                "rotation {rotation:?}, step {step}: {:?}",
                f.events
            );
        }
        let b = &bodies(&sim)[0];
        assert!(b.linvel.norm() < 0.01, "{:?}", b.linvel);
        assert!((b.position.y - 0.5).abs() < 0.005, "{:?}", b.position);
        assert!((b.position.z - 10.5).abs() < 0.005, "{:?}", b.position);
    }
}

/// A row of balls and boxes resting on the ground against a wall and each other (zero
/// gaps), with small random drifts and spins: every state stays finite, nothing is removed,
/// and they come to rest without penetrating.
#[test]
fn resting_contacts_against_ground_wall_and_neighbours_stay_finite_and_still() {
    let mut b = SceneBuilder::new([-6.0, -1.0, -6.0], [6.0, 8.0, 6.0]).walls(true, false);
    for k in 0..10u64 {
        let (shape, half) = if k % 2 == 0 {
            (Shape::Ball { radius: 0.5 }, 0.5)
        } else {
            (
                Shape::Cuboid {
                    half_extents: [0.5; 3],
                },
                0.5,
            )
        };
        b = b.body_spec(BodySpec {
            id: k,
            shape,
            material: Material::default(),
            position: [6.0 - half - k as f32, half, 0.0],
            rotation: if k % 2 == 0 {
                [0.4 * k as f32, 1.0, -0.3]
            } else {
                [0.0; 3]
            },
            velocity: [0.003 * (k as f32 - 5.0), 0.0, 0.002],
            angular_velocity: [0.01 * k as f32, -0.02, 0.0],
        });
    }
    let mut sim = Simulation::new(b.build().unwrap());
    for step in 0..600 {
        let f = sim.step();
        assert!(f.events.is_empty(), "step {step}: {:?}", f.events);
    }
    let r = soda::sim::measure(sim.reference());
    assert_eq!(r.bodies, 10);
    assert!(r.max_speed < 0.01, "max speed {}", r.max_speed);
    assert!(
        r.max_penetration < 0.005,
        "penetration {}",
        r.max_penetration
    );
}

/// A pile of balls carries its own weight: balls resting in the grooves of the layer below
/// are held there (shock propagation through contacts up to 75° from the vertical, SPEC.md
/// §5.2), so after 15 s no two balls overlap by more than half the smallest radius the scene
/// can draw (0.1 m). With a 45° cone these grooves were solved by one Jacobi pass per step
/// and the pile sank into itself: 0.14–0.19 m overlaps on such piles.
#[test]
fn a_ball_pile_carries_its_weight_without_sinking_into_itself() {
    for seed in [11, 12, 13] {
        let mut sim = Simulation::new(ball_pile(seed));
        for step in 1..=900 {
            let f = sim.step();
            assert!(
                f.events.is_empty(),
                "seed {seed}, step {step}: {:?}",
                f.events
            );
        }
        let bs = bodies(&sim);
        assert_eq!(bs.len(), 225, "seed {seed}: bodies lost");
        let mut worst = (0.0f32, 0, 0);
        for (i, a) in bs.iter().enumerate() {
            for c in &bs[i + 1..] {
                let d = soda::physics::metrics::pair_penetration(a, c);
                if d > worst.0 {
                    worst = (d, a.id(), c.id());
                }
            }
        }
        assert!(
            worst.0 <= 0.1,
            "seed {seed}: balls {} and {} overlap by {:.4} m after 15 s",
            worst.1,
            worst.2,
            worst.0
        );
    }
}

/// A pile of balls and boxes comes to rest: after 30 s at least 95 % of its bodies sleep,
/// with less than 10 mJ of kinetic energy left in all, and no two bodies overlap by more
/// than 0.05 m. Before pile contacts (SPEC.md §5.3) the resting contacts of a pile were
/// solved apart from the supports, kept approach velocities that never turned into motion,
/// and the pile crept like a liquid: a ball pile kept 0.6–0.9 J and only 1–3 % of its balls
/// slept.
#[test]
fn a_pile_of_balls_and_boxes_comes_to_rest() {
    for seed in 1..=4u64 {
        let scene = mixed_pile(seed);
        let sleep_steps = scene.solver.sleep_steps;
        let mut sim = Simulation::new(scene);
        for _ in 0..1800 {
            sim.step();
        }
        let bs = bodies(&sim);
        assert_eq!(bs.len(), 150, "seed {seed}: bodies lost");
        let asleep = bs
            .iter()
            .filter(|b| u32::from(b.rest_steps) >= sleep_steps)
            .count();
        let energy = soda::physics::metrics::kinetic_energy(bs.iter());
        assert!(
            asleep * 100 >= 95 * bs.len(),
            "seed {seed}: {asleep} of {} asleep after 30 s ({energy:.5} J left)",
            bs.len()
        );
        assert!(energy < 0.01, "seed {seed}: {energy:.5} J left after 30 s");
        let mut worst = 0.0f32;
        for (i, a) in bs.iter().enumerate() {
            for c in &bs[i + 1..] {
                worst = worst.max(soda::physics::metrics::pair_penetration(a, c));
            }
        }
        assert!(
            worst <= 0.05,
            "seed {seed}: overlap {worst:.4} m after 30 s"
        );
    }
}

/// Runs a settling `scene` (draw `seed`) for 30 s and checks that from 5 s on its kinetic plus
/// potential energy never rises above its lowest value so far by more than `bound` J.
fn rises_at_most_after_landing(scene: Scene, seed: u64, bound: f64) {
    let gravity = Vec3::new(scene.gravity[0], scene.gravity[1], scene.gravity[2]);
    let mut sim = Simulation::new(scene);
    let mut lowest = f64::INFINITY;
    for step in 1..=1800u32 {
        sim.step();
        if step < 300 {
            continue;
        }
        let bs = bodies(&sim);
        let energy = kinetic(&bs) + soda::physics::metrics::potential_energy(bs.iter(), gravity);
        lowest = lowest.min(energy);
        assert!(
            energy - lowest <= bound,
            "seed {seed}, step {step}: {energy:.4} J, {:.4} J above the lowest so far",
            energy - lowest
        );
    }
}

/// A settling pile never gains mechanical energy: from 5 s to 30 s, kinetic plus potential
/// energy never rises above its lowest value so far by more than 20 mJ. Before the lower body
/// of a support stopped its own approach to the body it carries (SPEC.md §5.2), a lower body
/// sliding sideways into it pushed it as if infinitely heavy and wedged it upwards along the
/// steep support normal: these four piles gained 35, 457, 288 and 680 mJ. (The bound was
/// 10 mJ until balls stopped being held back by the static environment; then one of these
/// piles rose 14.7 mJ, as much as one of main's own 48 draws of the settling sweep did
/// before: docs/results/README.md, "Settling over seeds".)
#[test]
fn a_settling_pile_gains_no_mechanical_energy_beyond_20_mj() {
    for seed in 1..=4u64 {
        let scene = mixed_pile(seed);
        rises_at_most_after_landing(scene, seed, 0.02);
    }
}

/// A ball held by two still balls does not follow a box that tumbles away beneath it: the
/// mixed pile of the settling sweep's draw 11, from 5 s to 30 s, never rises above its
/// lowest mechanical energy so far by more than 10 mJ. While the velocity pass removed a
/// contact's whole separation, a separation the partner's motion made included (SPEC.md
/// §5.3), ball 28 was pulled after box 27 every substep while balls 3 and 8 held its
/// position, and the pile rose 92.6 mJ in four steps (docs/open-defects, §10).
#[test]
fn a_ball_held_by_still_balls_does_not_follow_a_box_falling_away_beneath_it() {
    rises_at_most_after_landing(mixed_pile(11), 11, 0.01);
}

/// Piles of balls whose supports lifted the columns they carried no longer do: from 5 s to
/// 30 s, kinetic plus potential energy never rises above its lowest value so far by more
/// than 10 mJ (20 mJ for a while on 2026-11-29: after the load of SPEC.md §5.2, seed 18 rose
/// 14.2 mJ, a ball deep in the pile lifted 4 mm, until the pile contacts were corrected
/// together, SPEC.md §5.3 step 5). While the lower body of a support stopped only its share of its approach to
/// the body it carried (SPEC.md §5.2), a ball rolling off the ball under it slid on under the
/// column it carried and lifted it 0.3–0.5 mm per step: these three draws of the settling
/// sweep rose 288, 78 and 20 mJ. (Over its 24 draws the worst rose 32 mJ after that fix, seed
/// 9, and 5.0 mJ since paired sets, SPEC.md §5.3: docs/results/README.md.)
#[test]
fn ball_piles_whose_supports_lifted_their_columns_gain_no_more_than_10_mj() {
    for seed in [18u64, 4, 8] {
        let scene = ball_pile(seed);
        rises_at_most_after_landing(scene, seed, 0.01);
    }
}

/// A small ball caged by pile neighbours does not climb out of the cage: ball pile 86 of the
/// settling sweep, from 5 s to 30 s, never rises above its lowest mechanical energy so far by
/// more than 10 mJ. While each pile partner's share of its overlap was corrected apart and
/// the corrections summed (SPEC.md §5.3 step 5), the two partners on one side of ball 166,
/// caged by four neighbours 2 cm too close, pushed it 2.4 cm into the one on its other side,
/// which pushed it back in the next substep; each swing lifted it a little, and it climbed
/// 4 mm a step, 13 cm in all with the balls above it: 519.6 mJ (docs/open-defects §4).
#[test]
fn a_ball_caged_by_pile_neighbours_does_not_climb_out() {
    rises_at_most_after_landing(ball_pile(86), 86, 0.01);
}

/// A light ball driven at 2 m/s under a ball five times as dense that leans on a wall and
/// rests on it lifts it with no more energy than the scene has: kinetic plus potential
/// energy never exceeds its start. While the upper body of a support saw the lower body
/// move into it at the lower body's whole speed, as if that body were infinitely heavy
/// (SPEC.md §5.2), the pair gained 26 mJ over the 67 mJ of kinetic energy it started with.
#[test]
fn a_light_ball_driven_under_a_heavy_one_lifts_it_with_no_energy_it_lacks() {
    let (ra, rb, tilt) = (0.2f32, 0.3f32, 0.6f32);
    let material = |density: f32| Material {
        density,
        friction: 0.3,
        restitution: 0.0,
    };
    let ball = |id: u64, r: f32, density: f32, position: [f32; 3], vx: f32| BodySpec {
        id,
        shape: Shape::Ball { radius: r },
        material: material(density),
        position,
        rotation: [0.0; 3],
        velocity: [vx, 0.0, 0.0],
        angular_velocity: [0.0; 3],
    };
    // The heavy ball touches the wall at x = 0 and rests on the light one along a normal
    // `tilt` from the vertical; the light one, on the ground, is driven towards the wall.
    let scene = SceneBuilder::new([0.0, -1.0, -2.0], [4.0, 5.0, 2.0])
        .walls(true, false)
        .environment_material(0.3, 0.0)
        .body_spec(ball(
            0,
            ra,
            1.0,
            [rb + (ra + rb) * tilt.sin(), ra, 0.0],
            -2.0,
        ))
        .body_spec(ball(
            1,
            rb,
            5.0,
            [rb, ra + (ra + rb) * tilt.cos(), 0.0],
            0.0,
        ))
        .build()
        .unwrap();
    let gravity = Vec3::new(scene.gravity[0], scene.gravity[1], scene.gravity[2]);
    let energy =
        |bs: &[Body]| kinetic(bs) + soda::physics::metrics::potential_energy(bs.iter(), gravity);
    let mut sim = Simulation::new(scene);
    let start = energy(&bodies(&sim));
    for step in 1..=120 {
        sim.step();
        let now = energy(&bodies(&sim));
        assert!(
            now <= start + 1e-5,
            "step {step}: {now:.5} J against {start:.5} J at the start"
        );
    }
}

/// A ball resting on the ball under it, thrown into a light box beside it that a wall holds,
/// comes to rest against the box and falls asleep without sinking into it. The ball and the
/// box form a symmetric pair (the box is beside the ball, not under it)
/// whose collision, from step-`t` velocities, gave the light box nearly all of the impulse;
/// while the ball's own solve then rolled it on, unresisted, into the box again (SPEC.md
/// §5.3, `Paired` sets), only the pair's position correction held it there: it kept an
/// approach of about 0.3 m/s, spun at 1.5 rad/s, sank up to 7.5 cm into the box, a new "impact"
/// every step, until it slipped out sideways after 4 s and rolled away. Twelve
/// arrangements: three tilts, a box a tenth and half the ball's density, two speeds.
#[test]
fn a_ball_thrown_into_a_light_box_held_by_a_wall_rests_against_it_without_sinking_in() {
    for tilt in [0.4f32, 0.7, 1.0] {
        for box_density in [0.1f32, 0.5] {
            for speed in [0.5f32, 1.0] {
                ball_into_box_held_by_wall(tilt, box_density, speed);
            }
        }
    }
}

/// The scene of [`a_ball_thrown_into_a_light_box_held_by_a_wall_rests_against_it_without_sinking_in`]: the ball
/// (density 1) rests on the support ball along a normal `tilt` from the vertical and is
/// thrown at `speed` into the box (`box_density`).
fn ball_into_box_held_by_wall(tilt: f32, box_density: f32, speed: f32) {
    let (r_support, r_ball) = (0.3f32, 0.25f32);
    let material = |density: f32| Material {
        density,
        friction: 0.5,
        restitution: 0.3,
    };
    let spec = |id: u64, shape: Shape, density: f32, position: [f32; 3], vx: f32| BodySpec {
        id,
        shape,
        material: material(density),
        position,
        rotation: [0.0; 3],
        velocity: [vx, 0.0, 0.0],
        angular_velocity: [0.0; 3],
    };
    // A tall light box against the wall at x = 0; the ball touches its face and rests on the
    // support ball along a normal `tilt` from the vertical, rolling towards the box.
    let half = [0.2f32, 0.5, 0.3];
    let ball_x = 2.0 * half[0] + r_ball;
    let support_x = ball_x + (r_support + r_ball) * tilt.sin();
    let scene = SceneBuilder::new([0.0, -1.0, -2.0], [4.0, 5.0, 2.0])
        .walls(true, false)
        .environment_material(0.5, 0.3)
        .body_spec(spec(
            0,
            Shape::Cuboid { half_extents: half },
            box_density,
            [half[0], half[1], 0.0],
            0.0,
        ))
        .body_spec(spec(
            1,
            Shape::Ball { radius: r_support },
            1.0,
            [support_x, r_support, 0.0],
            0.0,
        ))
        .body_spec(spec(
            2,
            Shape::Ball { radius: r_ball },
            1.0,
            [ball_x, r_support + (r_support + r_ball) * tilt.cos(), 0.0],
            -speed,
        ))
        .build()
        .unwrap();
    let sleep_steps = scene.solver.sleep_steps;
    let mut sim = Simulation::new(scene);
    // How deep the ball is in the box (the box's face at rest against the wall).
    let overlap = |bs: &[Body]| 2.0 * half[0] - (bs[2].position.x - r_ball);
    let asleep = (1..=600u32).find(|step| {
        sim.step();
        let now = bodies(&sim);
        // The impact's first steps may press the light box into the wall; the ball never
        // sinks into it.
        assert!(
            overlap(&now) < 0.025,
            "tilt {tilt}, box density {box_density}, {speed} m/s: step {step}: the ball is \
             {:.3} m deep in the box",
            overlap(&now)
        );
        now.iter().all(|b| u32::from(b.rest_steps) >= sleep_steps)
    });
    assert!(
        overlap(&bodies(&sim)) < 0.005,
        "tilt {tilt}, box density {box_density}, {speed} m/s: asleep {:.4} m deep in the box",
        overlap(&bodies(&sim))
    );
    assert!(
        overlap(&bodies(&sim)) > -0.01,
        "tilt {tilt}, box density {box_density}, {speed} m/s: asleep {:.4} m away from the box",
        -overlap(&bodies(&sim))
    );
    let ball = bodies(&sim)[2].clone();
    assert!(
        asleep.is_some(),
        "tilt {tilt}, box density {box_density}, {speed} m/s: still awake after 10 s: the ball at {:?} moves at {:?} m/s and spins at {:?} rad/s",
        ball.position,
        ball.linvel,
        ball.angvel
    );
}

/// Ball gases settling under gravity come to rest: every ball asleep within 20 s. These
/// draws of the quality bench's gas (512 balls, restitution 0.5) never did while each body of
/// a pile contact removed the pair's whole approach in its own solve (SPEC.md §5.3): two balls
/// leaning on each other from two grooves rebounded from each other every other step. (They
/// were asleep at steps 481 and 545; since a support moving into the body on it is seen at
/// the speed the two share, SPEC.md §5.2, at 476 and 925: in the second a ball sinks slowly
/// between two steep supports, gaining speed, and the sleep rule keeps it awake until it
/// stops. The bound was 15 s.) Draws 4 and 8 kept three balls awake for good, trading
/// velocities of 0.1–1.4 mm/s that reset their counters as "speeding up", until such noise
/// below the speeding-up floor stopped counting (SPEC.md §5.4, 2026-11-28).
#[test]
fn ball_gases_that_never_came_to_rest_are_asleep_within_20_s() {
    for seed in [4u64, 8, 12, 58] {
        let scene = ball_box(seed, 0.5, 0.5, true);
        let sleep_steps = scene.solver.sleep_steps;
        let mut sim = Simulation::new(scene);
        let asleep = (1..=1200u32).find(|_| {
            sim.step();
            bodies(&sim)
                .iter()
                .all(|b| u32::from(b.rest_steps) >= sleep_steps)
        });
        assert!(
            asleep.is_some(),
            "seed {seed}: balls still awake after 1200 steps: {:?}",
            bodies(&sim)
                .iter()
                .filter(|b| u32::from(b.rest_steps) < sleep_steps)
                .map(|b| b.id())
                .collect::<Vec<_>>()
        );
    }
}

/// A body is removed exactly when its centre leaves the declared domain, not at the grid's
/// edge (which lies beyond the domain's upper faces): moving at 2 m/s along x through
/// `domain.max.x`, it is present while its centre is inside and leaves, with one
/// `left-domain` event, in the step its centre crosses.
#[test]
fn a_body_leaves_exactly_when_its_centre_leaves_the_declared_domain() {
    for (axis, sign) in [(0usize, 1.0f32), (0, -1.0), (2, 1.0), (1, 1.0), (1, -1.0)] {
        leaves_through_the_face(axis, sign);
    }
}

/// A ball moving at 2 m/s along `axis` (towards the upper face if `sign > 0`) in a ±16 m
/// domain without gravity or ground.
fn leaves_through_the_face(axis: usize, sign: f32) {
    let mut v = [0.0; 3];
    v[axis] = 2.0 * sign;
    let builder = SceneBuilder::new([-16.0, -16.0, -16.0], [16.0, 16.0, 16.0])
        .gravity([0.0; 3])
        .ground(None)
        .body_spec(BodySpec {
            id: 0,
            shape: Shape::Ball { radius: 0.3 },
            material: Material::default(),
            position: [0.0; 3],
            rotation: [0.0; 3],
            velocity: v,
            angular_velocity: [0.0; 3],
        });
    let scene = builder.build().unwrap();
    let grid = scene.grid();
    let face = 16.0 * sign;
    // The grid reaches past the upper faces (dims = ceil(extent / edge)).
    assert!(grid.max()[axis] > 16.0, "grid max {}", grid.max()[axis]);
    let mut sim = Simulation::new(scene);
    let mut last_inside = None;
    for step in 1..=600u64 {
        let f = sim.step();
        let all = bodies(&sim);
        match all.first() {
            Some(b) => {
                let c = b.position[axis];
                assert!(
                    (-16.0..16.0).contains(&c),
                    "axis {axis}, step {step}: centre {c} outside the domain"
                );
                last_inside = Some(c);
                assert!(f.events.is_empty());
            }
            None => {
                assert_eq!(f.events.len(), 1, "one left-domain event");
                assert_eq!(f.events[0].kind, soda::EventKind::LeftDomain);
                let prev = last_inside.expect("it was inside before");
                // The last position inside was within one step's travel of the face.
                assert!(
                    (face - prev).abs() <= 2.0 / 60.0 + 1e-4,
                    "axis {axis}: left from {prev}"
                );
                return;
            }
        }
    }
    panic!("axis {axis}: the body never left");
}

/// A NaN or infinity reaching a body's state is a hard error naming the body, the step and
/// the field (a panic inside the model, which executors report as a typed error), never a
/// silent removal.
#[test]
fn a_non_finite_state_is_a_hard_error_naming_body_step_and_field() {
    use soda::model::{CellModel, Neighbourhood};
    let mut b = free_space();
    b.body(
        Shape::Ball { radius: 0.5 },
        Material::default(),
        [0.0; 3],
        [0.0; 3],
    );
    let scene = b.build().unwrap();
    let model = scene.model();
    let grid = scene.grid();
    let mut body = scene.initial_bodies()[0].clone();
    body.linvel.y = f32::NAN;
    let own = [body];
    let centre = grid.cell_of([0.0; 3]).unwrap();
    let mut cells: [&[Body]; 27] = [&[]; 27];
    cells[Neighbourhood::<Body>::CENTRE] = &own;
    let nb = Neighbourhood::new(centre, cells);
    let err = std::panic::catch_unwind(|| {
        let (mut out, mut events) = (Vec::new(), Vec::new());
        model.step_cell(34, &grid, &nb, &mut out, &mut events);
    })
    .expect_err("a NaN velocity must stop the run");
    let msg = err.downcast_ref::<String>().cloned().unwrap_or_default();
    assert!(
        msg.contains("body 0 at step 34") && msg.contains("linear velocity y is NaN"),
        "{msg}"
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    /// A body in free flight keeps its momentum however slowly it moves: slower than the
    /// sleep speed, touching nothing, it never falls asleep (which would freeze it in
    /// mid-air, SPEC.md §5.4), and after 120 steps it still has its velocities. A body that
    /// does not move at all does fall asleep, which changes nothing about it.
    #[test]
    fn a_slow_body_in_free_flight_keeps_its_momentum(
        a in drawn(),
        direction in prop::array::uniform3(-1.0f32..1.0),
        fraction in 1e-3f32..1.0,
    ) {
        use soda::math::Vec3;
        let raw = Vec3::from(direction);
        let d = if raw.norm() < 0.1 { Vec3::x() } else { raw.normalize() };
        let material = Material { density: 1.0, friction: 0.5, restitution: 0.0 };
        let probe = free_space().build().unwrap();
        let speed = fraction * probe.solver.sleep_speed;
        let sleep_steps = probe.solver.sleep_steps;
        let mut moving = spec(0, &a, material, [0.0; 3], (d * speed).into());
        moving.angular_velocity = [0.0; 3];
        let mut still = spec(1, &a, material, [20.0, 0.0, 0.0], [0.0; 3]);
        still.angular_velocity = [0.0; 3];
        let h = history(free_space().body_spec(moving).body_spec(still).build().unwrap(), 120);
        let last = &h[h.len() - 1];
        prop_assert_eq!(last[0].linvel, h[0][0].linvel, "the slow body lost its velocity");
        prop_assert_eq!(last[0].rest_steps, 0);
        let moved = (last[0].position - h[0][0].position).norm();
        let expected = speed * 120.0 * probe.dt;
        prop_assert!((moved - expected).abs() <= 1e-3 + 1e-3 * expected, "moved {} m, expected {} m", moved, expected);
        prop_assert_eq!(u32::from(last[1].rest_steps), sleep_steps, "the still body is asleep");
        prop_assert_eq!(last[1].position, h[0][1].position);
    }

    /// A box tumbling in free flight, whatever its proportions, orientation and spin, keeps
    /// its angular momentum `R·I·Rᵀ·ω` and its kinetic energy over 5 s (SPEC.md §5.3, the
    /// torque-free rotation), within 1e-5 plus the rounding of storing `ω` in `f32` at every
    /// substep: `ε·κ` per substep, `κ` the ratio of the largest to the smallest principal
    /// moment, adding up as a random walk (`ε·κ·√n` after `n` substeps). Keeping `ω` fixed
    /// instead turned `L` with the body (a brick spun at 4 rad/s about a tilted axis: 13° in
    /// 10 s).
    #[test]
    fn a_tumbling_box_in_free_flight_keeps_its_angular_momentum_and_energy(
        half in prop::array::uniform3(0.02f32..0.6),
        density in 0.3f32..4.0,
        rotation in prop::array::uniform3(-3.1f32..3.1),
        spin in prop::array::uniform3(-20.0f32..20.0),
    ) {
        let body = BodySpec {
            id: 0,
            shape: Shape::Cuboid { half_extents: half },
            material: Material { density, friction: 0.5, restitution: 0.0 },
            position: [0.0; 3],
            rotation,
            velocity: [0.0; 3],
            angular_velocity: spin,
        };
        let scene = free_space().body_spec(body).build().unwrap();
        let substeps = scene.solver.substeps as f32;
        let h = history(scene, 300);
        let moments = [0, 1, 2].map(|k| 1.0 / h[0][0].inv_inertia()[k]);
        let kappa = moments.iter().copied().fold(0.0f32, f32::max)
            / moments.iter().copied().fold(f32::INFINITY, f32::min);
        let l0 = h[0][0].angular_momentum();
        let e0 = h[0][0].kinetic_energy();
        for (step, states) in h.iter().enumerate() {
            let b = &states[0];
            let l = b.angular_momentum();
            let e = b.kinetic_energy();
            let tolerance = 1e-5 + f32::EPSILON * kappa * (step as f32 * substeps).sqrt();
            prop_assert!((l - l0).norm() <= tolerance * l0.norm() + 1e-12, "step {}: L {:?} from {:?} (κ {})", step, l, l0, kappa);
            prop_assert!((e - e0).abs() <= tolerance * e0 + 1e-12, "step {}: energy {} from {} (κ {})", step, e, e0, kappa);
        }
    }
}

/// The wall at `x = WALL_X` that [`thrown_at_the_wall`] throws bodies at.
const WALL_X: f32 = 4.0;

/// A plastic, frictionless body of `shape` and `density` at `position`, thrown along +x at
/// `speed` towards the wall at [`WALL_X`] (`substeps` per step), in free space or, if
/// `on_the_ground`, sliding on the ground under gravity: its state after 300 steps.
fn thrown_at_the_wall(
    shape: Shape,
    density: f32,
    speed: f32,
    substeps: u32,
    position: [f32; 3],
    on_the_ground: bool,
) -> Body {
    let wall = WALL_X;
    let (low, gravity) = if on_the_ground {
        (0.0, [0.0, -9.81, 0.0])
    } else {
        (-wall, [0.0; 3])
    };
    let body = BodySpec {
        id: 0,
        shape,
        material: Material {
            density,
            friction: 0.0,
            restitution: 0.0,
        },
        position,
        rotation: [0.0; 3],
        velocity: [speed, 0.0, 0.0],
        angular_velocity: [0.0; 3],
    };
    let solver = soda::physics::SolverParams {
        substeps,
        ..Default::default()
    };
    let scene = SceneBuilder::new([-wall, low, -wall], [wall; 3])
        .gravity(gravity)
        .ground(on_the_ground.then_some(0.0))
        .walls(true, false)
        .environment_material(0.0, 0.0)
        .solver(solver)
        .body_spec(body)
        .build()
        .unwrap();
    let h = history(scene, 300);
    h[h.len() - 1][0].clone()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// A ball thrown at a wall touches it (SPEC.md §5.3, the impact pass's landing limit
    /// against the static environment): whatever its size, speed and the number of
    /// substeps, a plastic, frictionless ball comes to rest against the wall, not short of it
    /// by up to its travel in a substep (it stopped 24 cm short at 30 m/s), and not in it.
    #[test]
    fn a_ball_thrown_at_a_wall_comes_to_rest_touching_it(
        radius in 0.01f32..0.8,
        density in 0.3f32..4.0,
        speed in 1.0f32..29.0,
        substeps in 1u32..9,
        offset in prop::array::uniform2(-1.5f32..1.5),
        on_the_ground in any::<bool>(),
    ) {
        // On the ground the ball slides (no friction) into the wall under gravity: the wall
        // and the ground are one contact set of two points.
        let height = if on_the_ground { radius } else { offset[0] };
        let last = thrown_at_the_wall(
            Shape::Ball { radius },
            density,
            speed,
            substeps,
            [0.0, height, offset[1]],
            on_the_ground,
        );
        let wall = WALL_X;
        let gap = wall - (last.position.x + radius);
        prop_assert!(gap.abs() <= 1e-3, "the ball rests {} m from the wall (negative: in it)", gap);
        prop_assert_eq!(last.linvel.x, 0.0, "still moving along x");
        if on_the_ground {
            prop_assert!((last.position.y - radius).abs() <= 1e-3, "the ball left the ground: y = {}", last.position.y);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// A box thrown face-on at a wall touches it (SPEC.md §5.3: the static environment holds
    /// no box's face back to the landing speed): whatever its size and shape — 1 cm cubes to
    /// rods and plates 1.2 m long — its speed and the number of substeps, a plastic,
    /// frictionless box comes to rest against the wall, square to it, not short of it by up
    /// to its travel in a substep (a 20 cm cube at 29 m/s stopped 17 cm short) and not
    /// rebounding (a rod 0.83 m long, 2 cm thick, at 1 m/s, turned and left the wall at
    /// 2.5 mm/s while the impact pass solved its end face point after point).
    #[test]
    fn a_box_thrown_face_on_at_a_wall_comes_to_rest_touching_it(
        half in prop::array::uniform3(0.005f32..0.6),
        density in 0.3f32..4.0,
        speed in 1.0f32..29.0,
        substeps in 1u32..9,
        offset in prop::array::uniform2(-1.5f32..1.5),
    ) {
        let last = thrown_at_the_wall(
            Shape::Cuboid { half_extents: half },
            density,
            speed,
            substeps,
            [0.0, offset[0], offset[1]],
            false,
        );
        let wall = WALL_X;
        let gap = wall - (last.position.x + half[0]);
        prop_assert!(gap.abs() <= 1e-3, "the box rests {} m from the wall (negative: in it)", gap);
        prop_assert_eq!(last.linvel.x, 0.0, "still moving along x");
        prop_assert!(last.angvel.norm() <= 1e-4, "turning at {} rad/s", last.angvel.norm());
    }
}

/// A box spinning at `spin` about its centre at the origin, struck by a ball moving along −x
/// at `speed` from `[1.5, aim]`, in free space; friction and restitution shared.
#[allow(clippy::too_many_arguments)]
fn spinning_box_and_ball(
    half: [f32; 3],
    rotation: [f32; 3],
    spin: [f32; 3],
    radius: f32,
    density: f32,
    aim: [f32; 2],
    speed: f32,
    restitution: f32,
    friction: f32,
) -> Scene {
    let material = Material {
        density: 1.0,
        friction,
        restitution,
    };
    free_space()
        .body_spec(BodySpec {
            id: 0,
            shape: Shape::Cuboid { half_extents: half },
            material,
            position: [0.0; 3],
            rotation,
            velocity: [0.0; 3],
            angular_velocity: spin,
        })
        .body_spec(BodySpec {
            id: 1,
            shape: Shape::Ball { radius },
            material: Material {
                density,
                ..material
            },
            position: [1.5, aim[0], aim[1]],
            rotation: [0.0; 3],
            velocity: [-speed, 0.0, 0.0],
            angular_velocity: [0.0; 3],
        })
        .build()
        .unwrap()
}

/// The cases that found it: a thin box spinning at 47 rad/s struck by a ball gained 13 % of
/// kinetic energy in one step (restitution 0), and the property test's first failure.
#[test]
fn the_spinning_boxes_that_gained_energy_no_longer_do() {
    let helper = spinning_box_and_ball(
        [0.2749, 0.0545, 0.1002],
        [2.0262, 2.5931, -0.9369],
        [38.964, 22.616, -12.872],
        0.1319,
        5.0,
        [-0.1722, 0.1047],
        3.0,
        0.0,
        0.0,
    );
    let shrunk = spinning_box_and_ball(
        [0.3487761, 0.15118329, 0.03],
        [0.0, 2.0152144, -3.0352204],
        [25.152218, 0.0, 13.489657],
        0.23468198,
        0.3,
        [0.0, 0.0],
        7.3450146,
        0.70109063,
        0.0,
    );
    for (name, scene) in [("47 rad/s", helper), ("shrunk", shrunk)] {
        let last = never_gains_kinetic_energy(scene, 90).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(last[1].linvel.x > -2.9, "{name}: the ball missed the box");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// A fast-spinning box struck by a ball in free space, restitution ≤ 1: the kinetic
    /// energy never grows from one step to the next (beyond f32 rounding). A box spinning at
    /// tens of rad/s turns by most of a radian in a step; the time-of-impact correction of
    /// its orientation used to turn it without turning its angular velocity along, which
    /// changed its rotational energy. The ball is aimed within reach of the sphere inscribed
    /// in the box, so it always strikes it.
    #[test]
    fn a_spinning_box_struck_by_a_ball_never_gains_kinetic_energy(
        half in prop::array::uniform3(0.03f32..0.4),
        rotation in prop::array::uniform3(-3.1f32..3.1),
        spin in prop::array::uniform3(-30.0f32..30.0),
        radius in 0.05f32..0.3,
        density in 0.3f32..6.0,
        aim in prop::array::uniform2(-1.0f32..1.0),
        speed in 2.0f32..8.0,
        restitution in 0.0f32..1.0,
        friction in 0.0f32..1.0,
    ) {
        let reach = 0.9 * (radius + half[0].min(half[1]).min(half[2])) / std::f32::consts::SQRT_2;
        let scene = spinning_box_and_ball(
            half, rotation, spin, radius, density,
            [aim[0] * reach, aim[1] * reach], speed, restitution, friction,
        );
        let last = never_gains_kinetic_energy(scene, 90);
        prop_assert!(last.is_ok(), "{}", last.as_ref().err().cloned().unwrap_or_default());
        let ball = &last.unwrap()[1];
        prop_assert!(ball.linvel != soda::math::Vec3::new(-speed, 0.0, 0.0), "the ball missed the box");
    }
}

/// A box of half extents `half` (rotated by `yaw` about the vertical) resting on the ground
/// with velocity `velocity`, under gravity `gravity` (tilted for an incline: flat ground
/// under tilted gravity is an incline without the slope's edges), box and ground of
/// friction `friction`, restitution 0, `substeps` substeps.
fn box_on_the_ground(
    half: [f32; 3],
    yaw: f32,
    friction: f32,
    velocity: [f32; 3],
    gravity: [f32; 3],
    substeps: u32,
) -> Scene {
    let solver = soda::physics::SolverParams {
        substeps,
        ..Default::default()
    };
    SceneBuilder::new([-60.0, -1.0, -60.0], [60.0, 5.0, 60.0])
        .gravity(gravity)
        .environment_material(friction, 0.0)
        .solver(solver)
        .body_spec(BodySpec {
            id: 0,
            shape: Shape::Cuboid { half_extents: half },
            material: Material {
                density: 1.3,
                friction,
                restitution: 0.0,
            },
            position: [0.0, half[1], 0.0],
            rotation: [0.0, yaw, 0.0],
            velocity,
            angular_velocity: [0.0; 3],
        })
        .build()
        .unwrap()
}

/// The horizontal speed of `b` and the angle of its horizontal velocity, rad.
fn horizontal(b: &Body) -> (f32, f32) {
    (b.linvel.x.hypot(b.linvel.z), b.linvel.z.atan2(b.linvel.x))
}

/// The property of `a_box_sliding_on_the_ground_slows_at_mu_g_and_keeps_its_heading` for
/// one box: half extents `hx`, `hz` and `height · min(hx, hz)`, turned by `yaw`, sliding at
/// `speed` along `heading` on ground of friction `friction`.
#[allow(clippy::too_many_arguments)]
fn sliding_slows_at_mu_g(
    hx: f32,
    hz: f32,
    height: f32,
    yaw: f32,
    heading: f32,
    speed: f32,
    friction: f32,
    substeps: u32,
) -> Result<(), TestCaseError> {
    // Low enough not to tip: friction moves the normal force's centre `μ·h_y` ahead
    // of the centre, which must stay inside the footprint.
    // (`height < 1`, `μ < 1`.)
    let hy = height * hx.min(hz);
    let g = 9.81f32;
    let v = [speed * heading.cos(), 0.0, speed * heading.sin()];
    let scene = box_on_the_ground([hx, hy, hz], yaw, friction, v, [0.0, -g, 0.0], substeps);
    let dt = scene.dt;
    let h = history(scene, 120);
    let expected = friction * g * dt;
    // The step it stops in: it must have slid that long.
    let stops = h
        .iter()
        .position(|s| horizontal(&s[0]).0 < expected)
        .unwrap_or(h.len());
    let sliding = ((speed / expected) as usize).min(h.len()) - 1;
    prop_assert!(
        stops >= sliding,
        "stopped after {} steps, not {}",
        stops,
        sliding
    );
    for (step, pair) in h[..stops].windows(2).enumerate() {
        let (before, after) = (&pair[0][0], &pair[1][0]);
        let (s0, _) = horizontal(before);
        let (s1, angle) = horizontal(after);
        let drop = s0 - s1;
        prop_assert!(
            (drop - expected).abs() <= 0.01 * expected + 1e-4,
            "step {}: speed {} -> {} m/s, a drop of {} where μ·g·dt = {}",
            step,
            s0,
            s1,
            drop,
            expected
        );
        let turned = (angle - heading + std::f32::consts::PI).rem_euclid(std::f32::consts::TAU)
            - std::f32::consts::PI;
        prop_assert!(
            turned.abs() <= 1e-3,
            "step {}: the heading turned by {} rad",
            step,
            turned
        );
        prop_assert!(
            after.angvel.norm() <= 1e-3,
            "step {}: spinning at {:?} rad/s",
            step,
            after.angvel
        );
        prop_assert!(
            (after.position.y - hy).abs() <= 1e-3,
            "step {}: the centre at height {}, not {}",
            step,
            after.position.y,
            hy
        );
    }
    Ok(())
}

/// The case CI drew on 2026-11-27 (proptest draws new cases each run): a tall box
/// (0.54 × 0.28 × 0.30 m) sliding diagonally at 2 m/s with μ = 0.95, one substep. With 8
/// velocity sweeps the pass had not converged and the box rocked at 0.004 rad/s; over 3,000
/// drawn cases 2 did so with 8 sweeps, none with 12 or 16 (worst 0.19 mrad/s).
#[test]
fn a_tall_box_sliding_diagonally_with_high_friction_does_not_rock() {
    sliding_slows_at_mu_g(
        0.268799,
        0.15,
        0.936_774_7,
        -2.926_196,
        -2.022_457_4,
        2.0,
        0.946_564_4,
        1,
    )
    .unwrap();
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Coulomb friction means what it says (SPEC.md §5.3, the velocity pass): a box sliding
    /// on flat ground, whatever its shape, heading, orientation about the vertical, speed
    /// and friction, slows at `μ·g` step after step, keeps its heading and does not start
    /// to spin about the vertical. (The pass once removed the normal impulses that balance
    /// friction's tipping moment after friction was bounded: a 0.6 m cube at 8 m/s with
    /// μ = 0.5 slowed at 4.86 falling to 3.9 m/s², picked up 0.5 rad/s of yaw and drifted
    /// sideways.)
    #[test]
    fn a_box_sliding_on_the_ground_slows_at_mu_g_and_keeps_its_heading(
        hx in 0.15f32..0.6,
        hz in 0.15f32..0.6,
        height in 0.2f32..1.0,
        yaw in -3.1f32..3.1,
        heading in -3.1f32..3.1,
        speed in 2.0f32..12.0,
        friction in 0.1f32..1.0,
        substeps in 1u32..5,
    ) {
        sliding_slows_at_mu_g(hx, hz, height, yaw, heading, speed, friction, substeps)?;
    }

    /// A box on an incline slides down at `g·(sin θ − μ·cos θ)` when `tan θ > μ`, and stays
    /// where it is when `tan θ < μ` (a 35° slope with μ = 0.5 once accelerated the box at
    /// 2.1–2.28 instead of 1.61 m/s², and a box on 3° crept 8.6 mm/s with one substep). The
    /// incline is either flat ground under gravity tilted by `θ` (with the box turned about
    /// the ground's normal) or a static box tilted by `θ` under vertical gravity (its normal
    /// `(sin θ, cos θ, 0)`).
    #[test]
    fn a_box_on_an_incline_slides_at_the_coulomb_rate_or_stays(
        hx in 0.15f32..0.6,
        hz in 0.15f32..0.6,
        height in 0.2f32..1.0,
        yaw in -3.1f32..3.1,
        slope_deg in 3.0f32..40.0,
        friction in 0.05f32..0.9,
        substeps in 1u32..5,
        ramp in any::<bool>(),
    ) {
        let theta = slope_deg.to_radians();
        let (tan, mu) = (theta.tan(), friction);
        prop_assume!((tan - mu).abs() > 0.05 * mu.max(tan));
        // Low enough not to tip at rest (`tan θ`) or sliding (`μ`).
        let hy = height * hx.min(hz) / tan.max(mu).max(1.0);
        let g = 9.81f32;
        // Down the slope, and across it.
        let (down, across) = if ramp {
            (Vec3::new(theta.cos(), -theta.sin(), 0.0), Vec3::z())
        } else {
            (Vec3::x(), Vec3::z())
        };
        let scene = if ramp {
            let normal = Vec3::new(theta.sin(), theta.cos(), 0.0);
            let thickness = 0.2;
            let centre = normal * (thickness + hy) - down * 4.0;
            let solver = soda::physics::SolverParams { substeps, ..Default::default() };
            SceneBuilder::new([-60.0, -30.0, -60.0], [60.0, 30.0, 60.0])
                .ground(None)
                .environment_material(friction, 0.0)
                .static_cuboid([0.0; 3], [12.0, thickness, 3.0], [0.0, 0.0, -theta])
                .solver(solver)
                .body_spec(BodySpec {
                    id: 0,
                    shape: Shape::Cuboid { half_extents: [hx, hy, hz] },
                    material: Material { density: 1.3, friction, restitution: 0.0 },
                    position: [centre.x, centre.y, centre.z],
                    rotation: [0.0, 0.0, -theta],
                    velocity: [0.0; 3],
                    angular_velocity: [0.0; 3],
                })
                .build()
                .unwrap()
        } else {
            let gravity = [g * theta.sin(), -g * theta.cos(), 0.0];
            box_on_the_ground([hx, hy, hz], yaw, friction, [0.0; 3], gravity, substeps)
        };
        let dt = scene.dt;
        let h = history(scene, 90);
        let (first, last) = (&h[30][0], &h[90][0]);
        if tan > mu {
            let expected = g * (theta.sin() - mu * theta.cos());
            let accel = (last.linvel - first.linvel).dot(&down) / (60.0 * dt);
            prop_assert!(
                (accel - expected).abs() <= 0.01 * expected + 0.01,
                "slid down at {} m/s², g·(sin θ − μ·cos θ) = {}", accel, expected
            );
            let sideways = last.linvel.dot(&across);
            prop_assert!(sideways.abs() <= 1e-3, "drifted sideways at {} m/s", sideways);
        } else {
            let moved = (last.position - h[0][0].position).norm();
            prop_assert!(moved <= 1e-3, "moved {} m on a slope that holds it", moved);
        }
    }
}

/// An elastic (restitution 1), frictionless box of any proportions, thrown and spun in a
/// closed box without gravity, with `substeps` substeps per step: its state after every step.
fn elastic_box_in_a_box(
    half: [f32; 3],
    rotation: [f32; 3],
    velocity: [f32; 3],
    spin: [f32; 3],
    substeps: u32,
    steps: u32,
) -> Result<Vec<Body>, String> {
    let body = BodySpec {
        id: 0,
        shape: Shape::Cuboid { half_extents: half },
        material: Material {
            density: 1.0,
            friction: 0.0,
            restitution: 1.0,
        },
        position: [0.0; 3],
        rotation,
        velocity,
        angular_velocity: spin,
    };
    let solver = soda::physics::SolverParams {
        substeps,
        ..Default::default()
    };
    let scene = SceneBuilder::new([-1.2; 3], [1.2; 3])
        .gravity([0.0; 3])
        .ground(Some(-1.2))
        .walls(true, true)
        .environment_material(0.0, 1.0)
        .solver(solver)
        .body_spec(body)
        .build()
        .unwrap();
    never_gains_kinetic_energy(scene, steps)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// An elastic, frictionless box spinning into the walls, floor and ceiling of a closed
    /// box never gains kinetic energy from one step to the next (beyond f32 rounding), with
    /// any proportions, pose, spin and number of substeps (SPEC.md §5.3, restitution with
    /// several points). It gained 5 % in one step when two corners reached a ceiling within
    /// one substep (the impact pass's impulse at the corner the other lifted was kept on top
    /// of its restitution), and 0.5 % when a position correction's velocity was added to a
    /// corner's rebound.
    #[test]
    fn an_elastic_box_never_gains_energy_on_the_walls_of_its_box(
        half in prop::array::uniform3(0.05f32..0.35),
        rotation in prop::array::uniform3(-3.1f32..3.1),
        velocity in prop::array::uniform3(-3.0f32..3.0),
        spin in prop::array::uniform3(-12.0f32..12.0),
        substeps in 1u32..=4,
    ) {
        let result = elastic_box_in_a_box(half, rotation, velocity, spin, substeps, 150);
        prop_assert!(result.is_ok(), "{}", result.unwrap_err());
    }

    /// Two elastic, frictionless boxes of any proportions, spinning, meet in free space:
    /// the pair's kinetic energy never grows from one step to the next (beyond f32
    /// rounding), and momentum is kept. The compression of a face against a face was left
    /// unconverged by the pair's sweeps (its corners' rows are nearly dependent), a corner
    /// kept pushing while it separated, and an elastic pair of cubes gained up to 2 % in
    /// one impact; such a compression is now solved exactly (SPEC.md §5.3).
    #[test]
    fn an_elastic_pair_of_boxes_never_gains_energy(
        half_a in prop::array::uniform3(0.1f32..0.4),
        half_b in prop::array::uniform3(0.1f32..0.4),
        rotation_a in prop::array::uniform3(-3.1f32..3.1),
        rotation_b in prop::array::uniform3(-3.1f32..3.1),
        spin_a in prop::array::uniform3(-10.0f32..10.0),
        spin_b in prop::array::uniform3(-10.0f32..10.0),
        speed in 0.5f32..5.0,
        lateral in prop::array::uniform2(-0.15f32..0.15),
    ) {
        let elastic = Material { density: 1.0, friction: 0.0, restitution: 1.0 };
        let body = |id, half, rotation, position, velocity, spin| BodySpec {
            id,
            shape: Shape::Cuboid { half_extents: half },
            material: elastic,
            position,
            rotation,
            velocity,
            angular_velocity: spin,
        };
        let scene = free_space()
            .body_spec(body(0, half_a, rotation_a, [-0.8, 0.0, 0.0], [speed, 0.0, 0.0], spin_a))
            .body_spec(body(1, half_b, rotation_b, [0.8, lateral[0], lateral[1]], [-speed, 0.0, 0.0], spin_b))
            .build()
            .unwrap();
        let steps = (1.6 / (2.0 * speed) / scene.dt).ceil() as u32 + 30;
        let first = bodies(&Simulation::new(scene.clone()));
        let result = never_gains_kinetic_energy(scene, steps);
        prop_assert!(result.is_ok(), "{}", result.as_ref().unwrap_err());
        let last = result.unwrap();
        let (p0, p) = (momentum(&first), momentum(&last));
        let scale = momentum_scale(&first);
        prop_assert!(distance(p, p0) <= 1e-4 * scale, "momentum {:?} from {:?} (scale {})", p, p0, scale);
        prop_assert!((relative_velocity(&last) - relative_velocity(&first)).norm() > 1e-3, "no collision happened");
    }
}

/// An elastic, frictionless gas of balls and boxes in a closed box never gains kinetic
/// energy from one step to the next (beyond f32 rounding), and loses at most 3 % over 1,000
/// steps (measured 2026-11-28: 0.4 % and 1.2 % for these seeds; 0.4 % and 2.3 % since two
/// balls meeting obliquely act along the line of centres at the touch, which changes the
/// trajectories and so which box contacts happen; an elastic gas of balls alone keeps its
/// energy within 1e-7, so the boxes' contacts still dissipate a little: docs/open-defects). (It gained 3 % in 2,000 steps before the fixes named in
/// [`an_elastic_box_never_gains_energy_on_the_walls_of_its_box`] and
/// [`an_elastic_pair_of_boxes_never_gains_energy`].)
#[test]
fn an_elastic_gas_of_balls_and_boxes_never_gains_energy() {
    for seed in [7, 8] {
        let scene = ball_gas(216, seed, 1.0, 0.0, true, true);
        let e0 = kinetic(&bodies(&Simulation::new(scene.clone())));
        match never_gains_kinetic_energy(scene, 1000) {
            Err(grew) => panic!("seed {seed}: {grew}"),
            Ok(last) => {
                let e = kinetic(&last);
                assert!(
                    (e - e0).abs() <= 0.03 * e0,
                    "seed {seed}: kinetic energy {e} J from {e0} J"
                );
            }
        }
    }
}

/// A body resting on a body lighter than itself, which rests on the ground, stands still and
/// gains no energy, whatever the mass ratio: a cube on a cube 3, 20, 100 and 1,000 times
/// lighter, and a dense ball on a light plate. While the joint solve of such a load system
/// (SPEC.md §5.2, "Load") started from no impulse, its sweeps approached the answer at the
/// pace of the mass ratio, and the upper body followed a lower body that was still falling
/// in the joint solve while its own solve held it on the ground: at 100 times the upper
/// cube's velocity grew by nearly `g·dt` a step while overlap kept its place (energy +21 %
/// in 15 steps), and at 1,000 times the lower cube was thrown out from under it.
#[test]
fn a_heavy_body_on_a_light_one_stands_still_and_gains_no_energy_at_any_mass_ratio() {
    let body = |id: u64, shape: Shape, density: f32, y: f32| BodySpec {
        id,
        shape,
        material: Material {
            density,
            friction: 0.5,
            restitution: 0.0,
        },
        position: [0.0, y, 0.0],
        rotation: [0.0; 3],
        velocity: [0.0; 3],
        angular_velocity: [0.0; 3],
    };
    let cube = Shape::Cuboid {
        half_extents: [0.2; 3],
    };
    let mut cases: Vec<(String, [BodySpec; 2])> = [3.0f32, 20.0, 100.0, 1000.0]
        .iter()
        .map(|&ratio| {
            (
                format!("a cube {ratio} times as dense on a cube"),
                [body(0, cube, 1.0, 0.2), body(1, cube, ratio, 0.6)],
            )
        })
        .collect();
    cases.push((
        "a dense ball on a light plate".to_string(),
        [
            body(
                0,
                Shape::Cuboid {
                    half_extents: [0.3, 0.1, 0.3],
                },
                1.0,
                0.1,
            ),
            body(1, Shape::Ball { radius: 0.2 }, 1000.0, 0.4),
        ],
    ));
    for (name, [lower, upper]) in cases {
        let scene = SceneBuilder::new([-3.0, -1.0, -3.0], [3.0, 4.0, 3.0])
            .body_spec(lower)
            .body_spec(upper)
            .build()
            .unwrap();
        let gravity = Vec3::new(scene.gravity[0], scene.gravity[1], scene.gravity[2]);
        let energy = |bs: &[Body]| {
            kinetic(bs) + soda::physics::metrics::potential_energy(bs.iter(), gravity)
        };
        let mut sim = Simulation::new(scene);
        let start_bodies = bodies(&sim);
        let start = energy(&start_bodies);
        for step in 1..=300 {
            sim.step();
            let now = bodies(&sim);
            let e = energy(&now);
            assert!(
                e <= start * (1.0 + 1e-5),
                "{name}, step {step}: {e:.5} J against {start:.5} J at the start"
            );
            for (b, b0) in now.iter().zip(&start_bodies) {
                let moved = (b.position - b0.position).norm();
                assert!(
                    moved < 1e-3,
                    "{name}, step {step}: body {} moved {moved} m",
                    b.id()
                );
            }
        }
    }
}
