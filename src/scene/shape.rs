//! Reading a body's `shape` so that an error names the field inside it.
//!
//! [`Shape`] derives an internally tagged `Deserialize` (`type = "ball"` beside the variant's
//! fields), which serde reads by buffering the whole table first: an error in it came out at
//! `bodies[0].shape` only (`invalid type: string "x", expected f32`, which of its fields?),
//! and a wrong kind of value as `expected internally tagged enum Shape`. This reads the
//! fields one by one from the file's own table, so `serde_path_to_error` follows them into
//! `bodies[0].shape.radius` and `bodies[0].shape.half_extents[2]`. It accepts what the
//! derived one accepts from a table; [`Shape`]'s `Serialize` is unchanged.

use crate::physics::Shape;
use serde::de::{self, DeserializeSeed, Deserializer, MapAccess, Visitor};
use serde::Deserialize;
use std::fmt;

/// A shape's `type`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
enum Kind {
    Ball,
    Cuboid,
}

impl Kind {
    /// The fields a shape of this kind takes besides `type`.
    fn fields(self) -> &'static [&'static str] {
        match self {
            Kind::Ball => &["radius"],
            Kind::Cuboid => &["half_extents"],
        }
    }
}

/// A field of a shape's table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Field {
    Type,
    Radius,
    HalfExtents,
}

const ALL_FIELDS: &[&str] = &["type", "radius", "half_extents"];

/// Reads a field name, refusing one the shape does not take while the key is being read
/// (so the error's path ends in that key): any but the three, or once `type` is known,
/// another kind's size field.
struct FieldSeed(Option<Kind>);

impl<'de> DeserializeSeed<'de> for FieldSeed {
    type Value = Field;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Field, D::Error> {
        d.deserialize_identifier(self)
    }
}

impl Visitor<'_> for FieldSeed {
    type Value = Field;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a shape's field: `type`, `radius` or `half_extents`")
    }

    fn visit_str<E: de::Error>(self, key: &str) -> Result<Field, E> {
        let field = match key {
            "type" => Field::Type,
            "radius" => Field::Radius,
            "half_extents" => Field::HalfExtents,
            _ => {
                let expected = self.0.map_or(ALL_FIELDS, Kind::fields);
                return Err(E::unknown_field(key, expected));
            }
        };
        match (self.0, field) {
            (Some(kind @ Kind::Ball), Field::HalfExtents)
            | (Some(kind @ Kind::Cuboid), Field::Radius) => {
                Err(E::unknown_field(key, kind.fields()))
            }
            _ => Ok(field),
        }
    }
}

struct ShapeVisitor;

impl<'de> Visitor<'de> for ShapeVisitor {
    type Value = Shape;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str(
            "a shape: `type` \"ball\" with a `radius`, or `type` \"cuboid\" with `half_extents`",
        )
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Shape, A::Error> {
        let mut kind: Option<Kind> = None;
        let mut radius: Option<f32> = None;
        let mut half_extents: Option<[f32; 3]> = None;
        while let Some(field) = map.next_key_seed(FieldSeed(kind))? {
            match field {
                Field::Type if kind.is_some() => return Err(de::Error::duplicate_field("type")),
                Field::Type => kind = Some(map.next_value()?),
                Field::Radius if radius.is_some() => {
                    return Err(de::Error::duplicate_field("radius"))
                }
                Field::Radius => radius = Some(map.next_value()?),
                Field::HalfExtents if half_extents.is_some() => {
                    return Err(de::Error::duplicate_field("half_extents"))
                }
                Field::HalfExtents => half_extents = Some(map.next_value()?),
            }
        }
        match kind {
            None => Err(de::Error::missing_field("type")),
            // A size field of the other kind given before `type`.
            Some(Kind::Ball) if half_extents.is_some() => Err(de::Error::custom(
                "a ball's size is its `radius`; `half_extents` is a cuboid's",
            )),
            Some(Kind::Cuboid) if radius.is_some() => Err(de::Error::custom(
                "a cuboid's size is its `half_extents`; `radius` is a ball's",
            )),
            Some(Kind::Ball) => Ok(Shape::Ball {
                radius: radius.ok_or_else(|| de::Error::missing_field("radius"))?,
            }),
            Some(Kind::Cuboid) => Ok(Shape::Cuboid {
                half_extents: half_extents
                    .ok_or_else(|| de::Error::missing_field("half_extents"))?,
            }),
        }
    }
}

/// Reads a body's `shape` (`#[serde(deserialize_with)]` of [`super::BodySpec::shape`]).
pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Shape, D::Error> {
    d.deserialize_map(ShapeVisitor)
}
