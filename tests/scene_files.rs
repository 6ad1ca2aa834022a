//! Scene files: every kind of bad file is rejected with a `SceneError` that names the
//! field (or line), the value and what is allowed; good files and dumped built-ins parse.

use soda::scene::builtin::{builtin, BUILTINS};
use soda::scene::{load_scene_file, parse_scene, SceneFormat};
use soda::SceneError;
use std::path::Path;

/// A valid scene: a cube resting on the ground and a ball beside it.
const BASE: &str = r#"
name = "base"

[domain]
min = [-5.0, -1.0, -5.0]
max = [5.0, 10.0, 5.0]

[[bodies]]
id = 0
shape = { type = "cuboid", half_extents = [0.5, 0.5, 0.5] }
position = [0.0, 0.5, 0.0]

[[bodies]]
id = 1
shape = { type = "ball", radius = 0.5 }
position = [2.0, 0.5, 0.0]
"#;

fn parse(text: &str) -> Result<soda::Scene, SceneError> {
    parse_scene(text, SceneFormat::Toml, "test.toml")
}

/// `BASE` with `from` replaced by `to` (which must occur exactly once).
fn variant(from: &str, to: &str) -> String {
    assert_eq!(BASE.matches(from).count(), 1, "fixture `{from}` not unique");
    BASE.replace(from, to)
}

/// Parses `text`, expects an `Invalid` error and checks that its field and message name
/// `field`, and that the message contains every one of `mentions`.
fn expect_invalid(text: &str, field: &str, mentions: &[&str]) -> String {
    let err = parse(text).expect_err("the scene must be rejected");
    let msg = err.to_string();
    match &err {
        SceneError::Invalid { field: f, .. } => {
            assert_eq!(f, field, "wrong field in: {msg}")
        }
        other => panic!("expected SceneError::Invalid naming `{field}`, got {other:?}"),
    }
    assert!(
        msg.contains("test.toml"),
        "message does not name the file: {msg}"
    );
    assert!(
        msg.contains(&format!("`{field}`")),
        "message does not name the field: {msg}"
    );
    for m in mentions {
        assert!(msg.contains(m), "message lacks `{m}`: {msg}");
    }
    println!("{msg}");
    msg
}

/// Parses `text`, expects a `Parse` error whose message contains every one of `mentions`.
fn expect_parse_error(text: &str, mentions: &[&str]) -> String {
    let err = parse(text).expect_err("the scene must be rejected");
    let msg = err.to_string();
    assert!(
        matches!(err, SceneError::Parse { .. }),
        "expected SceneError::Parse, got {err:?}"
    );
    assert!(
        msg.contains("test.toml"),
        "message does not name the file: {msg}"
    );
    for m in mentions {
        assert!(msg.contains(m), "message lacks `{m}`: {msg}");
    }
    msg
}

#[test]
fn the_base_fixture_is_valid() {
    let scene = parse(BASE).unwrap();
    assert_eq!(scene.bodies.len(), 2);
}

#[test]
fn malformed_syntax_is_rejected_naming_the_line() {
    let text = variant("id = 1", "id = = 1");
    let msg = expect_parse_error(&text, &["line 14"]);
    println!("{msg}");
}

#[test]
fn missing_field_is_rejected_naming_the_field() {
    let text = variant("position = [2.0, 0.5, 0.0]", "");
    let msg = expect_parse_error(&text, &["missing field", "`position`"]);
    println!("{msg}");
}

#[test]
fn missing_domain_is_rejected_naming_the_field() {
    let text = variant(
        "[domain]\nmin = [-5.0, -1.0, -5.0]\nmax = [5.0, 10.0, 5.0]\n",
        "",
    );
    let msg = expect_parse_error(&text, &["missing field", "`domain`"]);
    println!("{msg}");
}

#[test]
fn misspelt_table_is_rejected_naming_it_and_the_allowed_ones() {
    let text = variant("[domain]", "[domian]");
    let msg = expect_parse_error(&text, &["unknown field", "`domian`", "`domain`"]);
    println!("{msg}");
}

#[test]
fn unknown_field_is_rejected_naming_the_field_and_the_allowed_ones() {
    let text = variant("id = 1", "id = 1\nmass = 3.0");
    let msg = expect_parse_error(&text, &["unknown field", "`mass`", "position"]);
    println!("{msg}");
}

#[test]
fn unknown_shape_type_is_rejected_naming_the_allowed_types() {
    let text = variant(r#"type = "ball""#, r#"type = "cone""#);
    let msg = expect_parse_error(&text, &["cone", "ball", "cuboid"]);
    println!("{msg}");
}

#[test]
fn wrong_type_is_rejected_naming_the_field() {
    let text = variant("id = 1", r#"id = "one""#);
    let msg = expect_parse_error(&text, &["line", "at `bodies[1].id`"]);
    println!("{msg}");
}

#[test]
fn nan_position_is_rejected_naming_the_field() {
    let text = variant("[2.0, 0.5, 0.0]", "[nan, 0.5, 0.0]");
    let msg = expect_invalid(&text, "bodies[1].position", &["NaN", "finite"]);
    println!("{msg}");
}

#[test]
fn infinite_gravity_is_rejected_naming_the_field() {
    let text = variant(
        r#"name = "base""#,
        "name = \"base\"\ngravity = [0.0, -inf, 0.0]",
    );
    expect_invalid(&text, "gravity", &["inf", "finite"]);
}

#[test]
fn nan_time_step_is_rejected_naming_the_field() {
    let text = variant(r#"name = "base""#, "name = \"base\"\ndt = nan");
    expect_invalid(&text, "dt", &["`dt` = nan is invalid"]);
}

#[test]
fn an_extreme_density_is_blamed_for_a_mass_f32_cannot_hold() {
    let text = variant(
        "radius = 0.5 }",
        "radius = 0.5 }\nmaterial = { density = 1e-40 }",
    );
    expect_invalid(&text, "bodies[1].material.density", &["1e-40", "mass"]);
}

#[test]
fn negative_radius_is_rejected_naming_the_field() {
    let text = variant("radius = 0.5", "radius = -0.5");
    expect_invalid(&text, "bodies[1].shape.radius", &["-0.5", "greater than 0"]);
}

#[test]
fn negative_half_extent_is_rejected_naming_the_field() {
    let text = variant("[0.5, 0.5, 0.5]", "[0.5, -0.5, 0.5]");
    expect_invalid(
        &text,
        "bodies[0].shape.half_extents[1]",
        &["-0.5", "greater than 0"],
    );
}

#[test]
fn zero_density_is_rejected_naming_the_field() {
    let text = variant("id = 1", "id = 1\nmaterial = { density = 0.0 }");
    expect_invalid(&text, "bodies[1].material.density", &["greater than 0"]);
}

#[test]
fn body_too_large_for_the_domain_is_rejected_naming_the_field() {
    let text = variant("radius = 0.5", "radius = 6.0");
    expect_invalid(
        &text,
        "bodies[1].shape.radius",
        &["= 6 is invalid", "smaller than the domain"],
    );
}

#[test]
fn overlapping_bodies_are_rejected_naming_both() {
    let text = variant("[2.0, 0.5, 0.0]", "[0.8, 0.5, 0.0]");
    expect_invalid(&text, "bodies[1].position", &["body 1 overlaps body 0"]);
}

#[test]
fn body_sunk_into_the_ground_is_rejected_naming_the_field() {
    let text = variant("[2.0, 0.5, 0.0]", "[2.0, 0.2, 0.0]");
    expect_invalid(&text, "bodies[1].position", &["static environment"]);
}

#[test]
fn duplicate_ids_are_rejected_naming_the_field() {
    let text = variant("id = 1", "id = 0");
    expect_invalid(&text, "bodies[1].id", &["unique", "bodies[0]"]);
}

#[test]
fn body_outside_the_domain_is_rejected_naming_the_field() {
    let text = variant("[2.0, 0.5, 0.0]", "[2.0, 0.5, 7.0]");
    expect_invalid(
        &text,
        "bodies[1].position",
        &["= [2, 0.5, 7] is invalid", "inside the domain"],
    );
}

#[test]
fn inverted_domain_is_rejected_naming_the_field() {
    let text = variant("min = [-5.0, -1.0, -5.0]", "min = [-5.0, -1.0, 6.0]");
    expect_invalid(&text, "domain.max[2]", &["greater than domain.min[2]"]);
}

#[test]
fn huge_domain_is_rejected_without_overflow() {
    let text = variant("max = [5.0, 10.0, 5.0]", "max = [3.0e38, 3.0e38, 3.0e38]");
    expect_invalid(&text, "domain", &["cells"]);
}

#[test]
fn negative_id_is_rejected_naming_the_value() {
    let text = variant("id = 1", "id = -1");
    expect_parse_error(&text, &["-1"]);
}

#[test]
fn json_scene_errors_name_the_line_and_field() {
    let err = parse_scene(
        r#"{"domain": {"min": [0,0,0], "max": [1,1,1]}, "bodies": [{"id": 0}]}"#,
        SceneFormat::Json,
        "test.json",
    )
    .unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, SceneError::Parse { .. }), "{err:?}");
    assert!(
        msg.contains("test.json") && msg.contains("shape") && msg.contains("line 1"),
        "{msg}"
    );
    let err = parse_scene("{\"domain\": ", SceneFormat::Json, "test.json").unwrap_err();
    assert!(err.to_string().contains("end of file"), "{err}");
    // A wrong type deep inside names the field's path.
    let err = parse_scene(
        r#"{"domain": {"min": [0,0,0], "max": [4,4,4]}, "bodies": [{"id": 0,
            "shape": {"type": "ball", "radius": 0.5}, "position": [2,1,2],
            "material": {"density": "heavy"}}]}"#,
        SceneFormat::Json,
        "test.json",
    )
    .unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("at `bodies[0].material.density`") && msg.contains("line 3"),
        "{msg}"
    );
    // A JSON array is not a scene (serde would read a struct from one, by position).
    let err = parse_scene("[]", SceneFormat::Json, "test.json").unwrap_err();
    assert!(err.to_string().contains("one JSON object"), "{err}");
}

#[test]
fn a_missing_file_is_an_io_error_naming_the_path() {
    let err = load_scene_file(Path::new("no/such/scene.toml")).unwrap_err();
    assert!(matches!(err, SceneError::Io { .. }), "{err:?}");
    assert!(err.to_string().contains("no/such/scene.toml"), "{err}");
}

#[test]
fn a_file_without_a_scene_extension_is_rejected_naming_the_extension() {
    let err = load_scene_file(Path::new("Cargo.lock")).unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("= `.lock` is invalid") && msg.contains(".toml or .json"),
        "{msg}"
    );
}

#[test]
fn unknown_builtin_is_rejected_listing_the_builtins() {
    let err = builtin("no-such-scene", None, 0).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, SceneError::UnknownBuiltin(_)), "{err:?}");
    assert!(
        msg.contains("no-such-scene") && msg.contains("falling-cubes"),
        "{msg}"
    );
}

#[test]
fn every_builtin_round_trips_through_toml_and_json_bit_exactly() {
    for b in BUILTINS {
        let scene = builtin(b.name, Some(10), 7).unwrap();
        for format in [SceneFormat::Toml, SceneFormat::Json] {
            let text = format.render(&scene).unwrap();
            let back = parse_scene(&text, format, b.name)
                .unwrap_or_else(|e| panic!("{} as {format:?}: {e}\n{text}", b.name));
            assert_eq!(back, scene, "{} as {format:?}", b.name);
            assert_eq!(
                soda::Simulation::new(back)
                    .state()
                    .hash::<soda::RigidBodyModel>(),
                soda::Simulation::new(scene.clone())
                    .state()
                    .hash::<soda::RigidBodyModel>(),
            );
        }
    }
}

#[test]
fn a_scene_without_ground_cannot_be_written_as_toml_but_can_as_json() {
    let mut scene = builtin("chain", Some(3), 0).unwrap();
    scene.environment.ground = None;
    let err = SceneFormat::Toml.render(&scene).unwrap_err();
    assert!(err.to_string().contains("environment.ground"), "{err}");
    let text = SceneFormat::Json.render(&scene).unwrap();
    assert_eq!(parse_scene(&text, SceneFormat::Json, "x").unwrap(), scene);
}

#[test]
fn every_example_scene_file_parses() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let mut paths: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| SceneFormat::from_path(p).is_some())
        .collect();
    paths.sort();
    assert!(
        paths.len() >= 2,
        "expected example scenes in {}",
        dir.display()
    );
    for p in paths {
        let scene = load_scene_file(&p).unwrap_or_else(|e| panic!("{e}"));
        assert!(!scene.bodies.is_empty(), "{}", p.display());
    }
}

#[test]
fn the_readme_scene_example_parses() {
    let readme =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md")).unwrap();
    let start = readme
        .find("```toml\n")
        .expect("a TOML example in README.md")
        + 8;
    let len = readme[start..].find("```").unwrap();
    let scene = parse_scene(&readme[start..start + len], SceneFormat::Toml, "README.md")
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(scene.bodies.len(), 2);
    assert_eq!(scene.environment.cuboids.len(), 1);
}

mod never_panics {
    use super::*;
    use proptest::prelude::*;

    /// Extreme and invalid values to put in place of the base scene's numbers.
    const EXTREMES: &[&str] = &[
        "nan", "inf", "-inf", "0.0", "-0.0", "-1.0", "1e-38", "3e38", "-3e38", "1e6", "0.5", "2.0",
    ];

    /// The byte ranges of the numbers in `BASE` (not the ids).
    fn number_spans() -> Vec<(usize, usize)> {
        let b = BASE.as_bytes();
        let mut spans = Vec::new();
        let mut i = 0;
        while i < b.len() {
            let starts =
                (b[i] == b'-' || b[i].is_ascii_digit()) && i > 0 && matches!(b[i - 1], b' ' | b'[');
            if starts {
                let j = (i + 1..b.len())
                    .find(|&j| !(b[j].is_ascii_digit() || b[j] == b'.'))
                    .unwrap_or(b.len());
                if BASE[i..j].contains('.') {
                    spans.push((i, j));
                }
                i = j;
            } else {
                i += 1;
            }
        }
        spans
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]

        /// Any mix of extreme values either parses to a scene that runs a step, or is
        /// rejected with an error naming a field — never a panic.
        #[test]
        fn extreme_values_are_rejected_or_run_without_panicking(
            picks in proptest::collection::vec((any::<proptest::sample::Index>(), 0..EXTREMES.len()), 1..4)
        ) {
            let spans = number_spans();
            prop_assert!(spans.len() > 10);
            let mut chosen: Vec<(usize, usize, &str)> = picks
                .iter()
                .map(|(i, e)| {
                    let (a, b) = spans[i.index(spans.len())];
                    (a, b, EXTREMES[*e])
                })
                .collect();
            chosen.sort();
            chosen.dedup_by_key(|c| c.0);
            let mut text = BASE.to_string();
            for (a, b, v) in chosen.iter().rev() {
                text.replace_range(a..b, v);
            }
            match parse(&text) {
                Ok(scene) => {
                    let mut sim = soda::Simulation::new(scene);
                    sim.run(1, |_, _| {});
                }
                Err(SceneError::Invalid { field, .. }) => prop_assert!(!field.is_empty()),
                Err(e) => prop_assert!(false, "unexpected error kind: {e}"),
            }
        }
    }
}

/// A body's spin cap grows as it gets smaller (SPEC.md §3): a 5 cm ball may spin at up to
/// `max_speed / r` = 600 rad/s (rolling at 30 m/s), not only `max_angular_speed` = 60;
/// a faster one is refused naming the field, the cap and where it comes from.
#[test]
fn a_small_ball_may_spin_as_fast_as_it_may_roll() {
    use soda::physics::{Material, Shape};
    use soda::scene::BodySpec;
    let ball = |spin: f32| {
        soda::SceneBuilder::new([-5.0, -1.0, -5.0], [5.0, 5.0, 5.0])
            .body_spec(BodySpec {
                id: 0,
                shape: Shape::Ball { radius: 0.05 },
                material: Material {
                    density: 1.0,
                    friction: 0.5,
                    restitution: 0.0,
                },
                position: [0.0, 1.0, 0.0],
                rotation: [0.0; 3],
                velocity: [0.0; 3],
                angular_velocity: [0.0, 0.0, spin],
            })
            .build()
    };
    assert!(ball(590.0).is_ok());
    let error = ball(610.0).unwrap_err().to_string();
    assert!(
        error.contains("angular_velocity")
            && error.contains("must not exceed 600 rad/s for this body")
            && error.contains("solver.max_speed / bounding radius = 30 / 0.05 m"),
        "{error}"
    );
}

/// A JSON scene saved with a UTF-8 byte-order mark reads as the same scene without it, as
/// a TOML one does (it failed at line 1, column 1).
#[test]
fn a_json_scene_with_a_byte_order_mark_reads_as_without_it() {
    let json = r#"{"domain": {"min": [-4,-1,-4], "max": [4,8,4]},
        "bodies": [{"id": 0, "shape": {"type": "ball", "radius": 0.5}, "position": [0,2,0]}]}"#;
    let plain = parse_scene(json, SceneFormat::Json, "plain.json").unwrap();
    let marked = parse_scene(&format!("\u{feff}{json}"), SceneFormat::Json, "bom.json").unwrap();
    assert_eq!(plain.bodies.len(), 1);
    assert_eq!(format!("{plain:?}"), format!("{marked:?}"));
}
