//! The compact binary form a committed frame travels in to the page (little-endian, every
//! field 4-byte aligned so the page reads it through typed-array views without copying).
//! docs/formats.md "Viewer frames" is the contract; `web/app.js` is the reader.
//!
//! | offset | field |
//! |---|---|
//! | 0 | magic `SODF` |
//! | 4 | format version (u16, 1), flags (u16, 0) |
//! | 8 | step (f64) |
//! | 16 | state hash, low and high 32 bits (2 × u32) |
//! | 24 | GVT when the frame was committed (f64; 0 on the reference executor) |
//! | 32 | frames buffered ahead of the display (u32), display starvations so far (u32) |
//! | 40 | display rate measured, frames/s (f32); playback speed (f32) |
//! | 48 | bodies (u32), worlds (u32), cells (u32), paused (u32) |
//! | 64 | per world: LVT, rollbacks so far, cells recomputed so far (3 × f64) |
//! | … | owner world of every cell (u16, `0xFFFF`: none), padded to 4 bytes |
//! | … | computations of every cell re-executed so far by its owner (u32, saturating; a cell that changes owner starts again from 0): the page flashes a cell whose count grew |
//! | … | per body (52 bytes): id low, id high (2 × u32), world (u16), shape (u8: 0 ball, 1 box), asleep (u8), position (3 × f32), rotation x, y, z, w (4 × f32), size (3 × f32: radius 3 times, or half extents) |
//!
//! The display stage fills in the fields of offsets 32–63 when it shows the frame.

use soda::exec::live::LiveStatus;
use soda::grid::Grid;
use soda::physics::{Body, Shape};

/// First four bytes of every frame.
pub const MAGIC: &[u8; 4] = b"SODF";
/// The format's version.
pub const VERSION: u16 = 2;
/// Bytes before the per-world records.
pub const HEADER_BYTES: usize = 64;
/// Bytes per world record.
pub const WORLD_BYTES: usize = 24;
/// Bytes per body record.
pub const BODY_BYTES: usize = 52;
/// Offset of the fields the display stage fills in.
pub const DISPLAY_FIELDS: usize = 32;

/// A committed frame ready for the page.
#[derive(Debug)]
pub struct EncodedFrame {
    /// Its step.
    pub step: u64,
    /// The state hash at that step.
    pub hash: u64,
    /// The bytes sent.
    pub bytes: Vec<u8>,
}

/// What the display stage writes into a frame when it shows it.
#[derive(Clone, Copy, Debug, Default)]
pub struct DisplayFields {
    /// Frames buffered ahead of it.
    pub buffered: u32,
    /// Times the display found the buffer empty.
    pub starved: u32,
    /// Frames shown per second, measured.
    pub rate: f32,
    /// Playback speed (1 = real time).
    pub speed: f32,
    /// Whether playback is paused.
    pub paused: bool,
}

/// Writes `fields` into an encoded frame's bytes.
pub fn fill_display_fields(bytes: &mut [u8], fields: DisplayFields) {
    let at = DISPLAY_FIELDS;
    bytes[at..at + 4].copy_from_slice(&fields.buffered.to_le_bytes());
    bytes[at + 4..at + 8].copy_from_slice(&fields.starved.to_le_bytes());
    bytes[at + 8..at + 12].copy_from_slice(&fields.rate.to_le_bytes());
    bytes[at + 12..at + 16].copy_from_slice(&fields.speed.to_le_bytes());
    bytes[60..64].copy_from_slice(&u32::from(fields.paused).to_le_bytes());
}

/// The run's status as frames carry it: the last [`LiveStatus`] looked at (`None` on the
/// reference executor: one world owning every cell) and the owner of every cell, worked out
/// once per look rather than once per frame.
#[derive(Debug)]
pub struct Look {
    live: Option<LiveStatus>,
    owners: Vec<u16>,
    recomputes: Vec<u32>,
}

impl Look {
    /// The status `live` of a run on `grid`.
    pub fn new(live: Option<LiveStatus>, grid: &Grid) -> Look {
        let cells = grid.cell_count();
        let owners = match &live {
            Some(l) => l
                .owners(cells)
                .iter()
                .map(|&o| o.min(0xFFFF) as u16)
                .collect(),
            None => vec![0; cells],
        };
        let recomputes = match &live {
            Some(l) => l
                .recomputes(cells)
                .iter()
                .map(|&n| n.min(u64::from(u32::MAX)) as u32)
                .collect(),
            None => vec![0; cells],
        };
        Look {
            live,
            owners,
            recomputes,
        }
    }
}

/// Encodes the committed bodies of `step` (sorted by id) with the run's status `look`.
pub fn encode(step: u64, hash: u64, bodies: &[&Body], grid: &Grid, look: &Look) -> EncodedFrame {
    let live = look.live.as_ref();
    let owners = &look.owners;
    let cells = owners.len();
    let worlds = live.map_or(1, |l| l.worlds.len());
    let owner_bytes = (cells * 2).div_ceil(4) * 4;
    let mut b = Vec::with_capacity(
        HEADER_BYTES + worlds * WORLD_BYTES + owner_bytes + cells * 4 + bodies.len() * BODY_BYTES,
    );
    b.extend_from_slice(MAGIC);
    b.extend_from_slice(&VERSION.to_le_bytes());
    b.extend_from_slice(&0u16.to_le_bytes());
    b.extend_from_slice(&(step as f64).to_le_bytes());
    b.extend_from_slice(&(hash as u32).to_le_bytes());
    b.extend_from_slice(&((hash >> 32) as u32).to_le_bytes());
    b.extend_from_slice(&(live.map_or(0, |l| l.gvt) as f64).to_le_bytes());
    b.extend_from_slice(&[0u8; 16]);
    b.extend_from_slice(&(bodies.len() as u32).to_le_bytes());
    b.extend_from_slice(&(worlds as u32).to_le_bytes());
    b.extend_from_slice(&(cells as u32).to_le_bytes());
    b.extend_from_slice(&0u32.to_le_bytes());
    match live {
        Some(l) => {
            for w in &l.worlds {
                b.extend_from_slice(&(w.lvt as f64).to_le_bytes());
                b.extend_from_slice(&(w.rollbacks as f64).to_le_bytes());
                b.extend_from_slice(&(w.cells_recomputed as f64).to_le_bytes());
            }
        }
        None => {
            b.extend_from_slice(&((step + 1) as f64).to_le_bytes());
            b.extend_from_slice(&[0u8; 16]);
        }
    }
    for &o in owners {
        b.extend_from_slice(&o.to_le_bytes());
    }
    b.resize(b.len() + owner_bytes - cells * 2, 0);
    for &n in &look.recomputes {
        b.extend_from_slice(&n.to_le_bytes());
    }
    for body in bodies {
        let world = grid
            .cell_of(body.position.into())
            .map_or(0xFFFF, |c| owners[grid.index(c)]);
        b.extend_from_slice(&(body.id() as u32).to_le_bytes());
        b.extend_from_slice(&((body.id() >> 32) as u32).to_le_bytes());
        b.extend_from_slice(&world.to_le_bytes());
        let (kind, size) = match body.shape() {
            Shape::Ball { radius } => (0u8, [radius; 3]),
            Shape::Cuboid { half_extents } => (1u8, half_extents),
        };
        b.push(kind);
        b.push(u8::from(body.rest_steps > 0 && body.linvel.norm() == 0.0));
        for v in body.position.iter() {
            b.extend_from_slice(&v.to_le_bytes());
        }
        let q = body.rotation.quaternion().coords;
        for v in [q.x, q.y, q.z, q.w] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        for v in size {
            b.extend_from_slice(&v.to_le_bytes());
        }
    }
    EncodedFrame {
        step,
        hash,
        bytes: b,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use soda::exec::live::WorldStatus;
    use soda::math::{Quat, Vec3};
    use soda::physics::Material;

    fn f32_at(b: &[u8], at: usize) -> f32 {
        f32::from_le_bytes(b[at..at + 4].try_into().unwrap())
    }

    #[test]
    fn a_frame_holds_every_field_at_its_documented_offset() {
        let grid = Grid::covering(Vec3::new(0.0, 0.0, 0.0), Vec3::new(4.0, 2.0, 2.0), 2.0);
        let body = Body::new(
            (7u64 << 32) | 5,
            Shape::Cuboid {
                half_extents: [0.5, 0.25, 0.125],
            },
            Material::default(),
            Vec3::new(3.0, 1.0, 1.0),
            Quat::identity(),
        );
        let live = LiveStatus {
            gvt: 9,
            worlds: vec![
                WorldStatus {
                    lvt: 12,
                    cells: vec![0],
                    rollbacks: 3,
                    cells_recomputed: 40,
                    cell_recomputes: vec![40],
                },
                WorldStatus {
                    lvt: 10,
                    cells: vec![1],
                    rollbacks: 0,
                    cells_recomputed: 0,
                    cell_recomputes: vec![0],
                },
            ],
        };
        let look = Look::new(Some(live), &grid);
        let mut f = encode(8, 0x1122_3344_5566_7788, &[&body], &grid, &look);
        fill_display_fields(
            &mut f.bytes,
            DisplayFields {
                buffered: 4,
                starved: 1,
                rate: 60.0,
                speed: 2.0,
                paused: true,
            },
        );
        let b = &f.bytes;
        assert_eq!(&b[0..4], MAGIC);
        assert_eq!(f64::from_le_bytes(b[8..16].try_into().unwrap()), 8.0);
        assert_eq!(
            u32::from_le_bytes(b[16..20].try_into().unwrap()),
            0x5566_7788
        );
        assert_eq!(
            u32::from_le_bytes(b[20..24].try_into().unwrap()),
            0x1122_3344
        );
        assert_eq!(f64::from_le_bytes(b[24..32].try_into().unwrap()), 9.0);
        assert_eq!(u32::from_le_bytes(b[32..36].try_into().unwrap()), 4);
        assert_eq!(f32_at(b, 44), 2.0);
        assert_eq!(u32::from_le_bytes(b[48..52].try_into().unwrap()), 1);
        assert_eq!(u32::from_le_bytes(b[52..56].try_into().unwrap()), 2);
        let cells = grid.cell_count();
        assert_eq!(
            u32::from_le_bytes(b[56..60].try_into().unwrap()),
            cells as u32
        );
        assert_eq!(u32::from_le_bytes(b[60..64].try_into().unwrap()), 1);
        assert_eq!(f64::from_le_bytes(b[64..72].try_into().unwrap()), 12.0);
        assert_eq!(f64::from_le_bytes(b[72..80].try_into().unwrap()), 3.0);
        let owners_at = HEADER_BYTES + 2 * WORLD_BYTES;
        assert_eq!(
            u16::from_le_bytes(b[owners_at..owners_at + 2].try_into().unwrap()),
            0
        );
        let recomputes_at = owners_at + (cells * 2).div_ceil(4) * 4;
        assert_eq!(
            u32::from_le_bytes(b[recomputes_at..recomputes_at + 4].try_into().unwrap()),
            40
        );
        assert_eq!(
            u32::from_le_bytes(b[recomputes_at + 4..recomputes_at + 8].try_into().unwrap()),
            0
        );
        let body_at = recomputes_at + cells * 4;
        assert_eq!(b.len(), body_at + BODY_BYTES);
        assert_eq!(
            u32::from_le_bytes(b[body_at..body_at + 4].try_into().unwrap()),
            5
        );
        assert_eq!(
            u32::from_le_bytes(b[body_at + 4..body_at + 8].try_into().unwrap()),
            7
        );
        // The body at x = 3 lies in cell 1, which world 1 owns.
        assert_eq!(
            u16::from_le_bytes(b[body_at + 8..body_at + 10].try_into().unwrap()),
            1
        );
        assert_eq!(b[body_at + 10], 1);
        assert_eq!(f32_at(b, body_at + 12), 3.0);
        assert_eq!(f32_at(b, body_at + 36), 1.0, "w of the identity rotation");
        assert_eq!(f32_at(b, body_at + 44), 0.25);
    }
}
