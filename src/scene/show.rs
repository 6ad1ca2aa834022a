//! Values in messages written as a user writes them in a scene file: numbers as TOML and
//! JSON numbers (`0.5`, `2`, `1e30`), vectors as arrays (`[2, 1, 50]`), a shape by its size field
//! (`shape.radius` or `shape.half_extents`) — never Rust's `Debug` forms such as
//! `Ball { radius: 1e30 }` or `NaN`.

use crate::physics::Shape;

/// `x` as a number in a scene file: `0.5`, `2`, `-9.81`, the shortest text that reads back
/// to the same `f32`; with an exponent from 1e7 up and below 1e-4 (`1e30`, `-1e7`, `1e-20`);
/// `nan`, `inf` and `-inf` as TOML spells them.
pub(crate) fn number(x: f32) -> String {
    if x.is_nan() {
        "nan".into()
    } else if x.is_infinite() {
        if x > 0.0 { "inf" } else { "-inf" }.into()
    } else if x != 0.0 && !(1e-4..1e7).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// `v` as an array in a scene file: `[2, 1, 50]`.
pub(crate) fn vector(v: [f32; 3]) -> String {
    format!("[{}, {}, {}]", number(v[0]), number(v[1]), number(v[2]))
}

/// The field of a shape that sets its size (`shape.radius` of a ball, `shape.half_extents`
/// of a cuboid), its value as written, and what the shape is called in messages.
pub(crate) fn shape_size(shape: &Shape) -> (&'static str, String, &'static str) {
    match *shape {
        Shape::Ball { radius } => ("shape.radius", number(radius), "ball"),
        Shape::Cuboid { half_extents } => ("shape.half_extents", vector(half_extents), "cuboid"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_written_as_in_a_scene_file() {
        assert_eq!(number(0.5), "0.5");
        assert_eq!(number(2.0), "2");
        assert_eq!(number(0.0), "0");
        assert_eq!(number(0.016666668), "0.016666668");
        assert_eq!(number(-9.81), "-9.81");
        assert_eq!(number(1e30), "1e30");
        assert_eq!(number(-1e7), "-1e7");
        assert_eq!(number(1e-20), "1e-20");
        assert_eq!(number(f32::NAN), "nan");
        assert_eq!(number(f32::NEG_INFINITY), "-inf");
        assert_eq!(vector([2.0, 1.0, 50.0]), "[2, 1, 50]");
        assert_eq!(
            shape_size(&Shape::Ball { radius: 1e30 }),
            ("shape.radius", "1e30".to_string(), "ball")
        );
        assert_eq!(
            shape_size(&Shape::Cuboid {
                half_extents: [0.5, 30.0, 0.5]
            }),
            ("shape.half_extents", "[0.5, 30, 0.5]".to_string(), "cuboid")
        );
    }
}
