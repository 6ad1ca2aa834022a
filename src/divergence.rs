//! First-divergence reports: given the committed states of one step from the reference and
//! from another executor, name the first body (in id order) and the first field that
//! differ, and the cell that computed it. "hash mismatch" alone helps nobody.

use crate::grid::Grid;
use crate::model::{BodyId, CellModel, Step};
use serde::Serialize;
use std::cmp::Ordering;
use std::fmt;

/// The first difference between two committed states of the same step.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Divergence {
    /// The step whose committed state differs.
    pub step: Step,
    /// The first body (ascending id) that differs.
    pub body: BodyId,
    /// The body's home cell in the reference state (`None` if the reference lacks it).
    pub cell: Option<[i32; 3]>,
    /// What differs: a field name, or `presence` when one side lacks the body.
    pub field: String,
    /// The reference's value.
    pub expected: String,
    /// The other executor's value.
    pub got: String,
}

impl fmt::Display for Divergence {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let cell = match self.cell {
            Some([x, y, z]) => format!("cell ({x}, {y}, {z})"),
            None => "no cell in the reference".to_string(),
        };
        write!(
            f,
            "step {}, body {} ({cell}), field {}: reference {}, got {}",
            self.step, self.body, self.field, self.expected, self.got
        )
    }
}

/// The first difference between `expected` and `got` (both sorted by id), or `None` if
/// every field of every body is equal.
pub fn first_difference<M: CellModel>(
    step: Step,
    grid: &Grid,
    expected: &[&M::State],
    got: &[&M::State],
) -> Option<Divergence> {
    let cell = |s: &M::State| grid.cell_of(M::position(s)).map(|c| [c.x, c.y, c.z]);
    let (mut i, mut j) = (0, 0);
    loop {
        let order = match (expected.get(i), got.get(j)) {
            (None, None) => return None,
            (Some(_), None) => Ordering::Less,
            (None, Some(_)) => Ordering::Greater,
            (Some(e), Some(g)) => M::id(e).cmp(&M::id(g)),
        };
        match order {
            Ordering::Equal => {
                let (e, g) = (expected[i], got[j]);
                let (fe, fg) = (M::fields(e), M::fields(g));
                let k = (0..fe.len().max(fg.len())).find(|&k| fe.get(k) != fg.get(k));
                if let Some(k) = k {
                    let show = |f: Option<&(String, String)>| {
                        f.map_or_else(|| "absent".to_string(), |f| f.1.clone())
                    };
                    let field = fe.get(k).or(fg.get(k)).map(|f| f.0.clone());
                    return Some(Divergence {
                        step,
                        body: M::id(e),
                        cell: cell(e),
                        field: field.unwrap_or_else(|| "state".into()),
                        expected: show(fe.get(k)),
                        got: show(fg.get(k)),
                    });
                }
                i += 1;
                j += 1;
            }
            Ordering::Less => {
                let e = expected[i];
                return Some(Divergence {
                    step,
                    body: M::id(e),
                    cell: cell(e),
                    field: "presence".into(),
                    expected: "present".into(),
                    got: "absent".into(),
                });
            }
            Ordering::Greater => {
                let g = got[j];
                return Some(Divergence {
                    step,
                    body: M::id(g),
                    cell: None,
                    field: "presence".into(),
                    expected: "absent".into(),
                    got: match cell(g) {
                        Some([x, y, z]) => format!("present in cell ({x}, {y}, {z})"),
                        None => "present outside the grid".to_string(),
                    },
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::synthetic::{Particle, Particles};

    fn grid() -> Grid {
        Grid::covering(
            crate::math::Vec3::zeros(),
            crate::math::Vec3::new(4.0, 4.0, 4.0),
            1.0,
        )
    }

    fn p(id: u64, x: f32) -> Particle {
        Particle {
            id,
            pos: [x, 0.5, 0.5],
            vel: [0.0; 3],
        }
    }

    #[test]
    fn equal_states_have_no_difference() {
        let a = [p(1, 0.5), p(2, 1.5)];
        let refs: Vec<&Particle> = a.iter().collect();
        assert_eq!(
            first_difference::<Particles>(3, &grid(), &refs, &refs),
            None
        );
    }

    #[test]
    fn the_first_differing_body_and_a_missing_body_are_named() {
        let a = [p(1, 0.5), p(2, 1.5), p(3, 2.5)];
        let mut b = a.clone();
        b[1].pos[0] = 1.25;
        b[2].pos[0] = 3.5;
        let (ra, rb): (Vec<&Particle>, Vec<&Particle>) = (a.iter().collect(), b.iter().collect());
        let d = first_difference::<Particles>(7, &grid(), &ra, &rb).unwrap();
        assert_eq!((d.step, d.body, d.cell), (7, 2, Some([1, 0, 0])));
        let text = d.to_string();
        assert!(text.contains("step 7") && text.contains("body 2"), "{text}");
        let d = first_difference::<Particles>(7, &grid(), &ra, &ra[..2]).unwrap();
        assert_eq!(
            (d.body, d.field.as_str(), d.got.as_str()),
            (3, "presence", "absent")
        );
        let d = first_difference::<Particles>(7, &grid(), &ra[..2], &ra).unwrap();
        assert_eq!((d.body, d.expected.as_str()), (3, "absent"));
        assert!(d.got.contains("cell (2, 0, 0)"), "{d}");
    }
}
