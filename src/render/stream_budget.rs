//! How a streamed terrain's GPU memory is laid out under a budget: the
//! base level, the page pool and the staging, planned before any of it
//! is allocated (`Streamer::plan`), and the smallest budget a layout
//! needs. Pure arithmetic over sizes the device reports.

use super::residency::StreamShape;

/// Under a memory budget, what the pool leaves free for what is allocated
/// after it (the occlusion pyramid: 2.6 MiB at 1920x1080, 10.5 MiB at
/// 3840x2160): this fraction of the budget, and at least
/// `MIN_HEADROOM_BYTES`. Render targets made before the renderer are
/// already counted.
pub const HEADROOM_FRACTION: u64 = 32;
pub const MIN_HEADROOM_BYTES: u64 = 4 << 20;
/// Pool layers a stream needs at the least for each level finer than its
/// base: the 3x3 pages around the eye.
pub const MIN_POOL_LAYERS_PER_LEVEL: u32 = 9;

/// What a streamed terrain holds on the GPU: the base level (in `shape`),
/// the pool's layers for streamed pages, and each frame slot's staging.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StreamMemory {
    pub shape: StreamShape,
    /// Pool layers for streamed pages, besides the base level's.
    pub layers: u32,
    /// Bytes of each frame slot's staging buffer.
    pub staging_bytes: u64,
}

/// The coarsest base level a budget may give a stream of `preferred`'s
/// shape: none coarser than a patch of `cells_per_patch` cells (or than
/// `preferred`'s, where that is coarser), since a terrain's Y bounds allow
/// only for its configured base level beyond a patch
/// (`Terrain::widen_y_bounds_to_blocks`), and none coarser than a tile.
pub fn coarsest_base(preferred: &StreamShape, cells_per_patch: u32) -> u32 {
    cells_per_patch
        .trailing_zeros()
        .min(preferred.tile_cells.trailing_zeros())
        .max(preferred.base_level)
}

/// Lays a stream out in `room` bytes (None: no budget), for `frames`
/// frame slots on a device of `device_layers` array layers, where a pool
/// of n layers takes `pool_bytes(n)`, with a base level at most
/// `coarsest` (`coarsest_base`). It keeps `preferred`'s base level
/// where that leaves the pool `MIN_POOL_LAYERS_PER_LEVEL` layers for each
/// finer level, and otherwise takes the finest coarser base that does; the
/// pool takes what the base and staging leave, up to `wanted` layers
/// (default: every streamed page). Staging keeps `upload_bytes` a slot
/// where that is at most an eighth of the room, and shrinks to one page a
/// slot. Where no base level fits, returns the fewest bytes that would
/// (None: no base level fits the device's layers).
pub fn plan_stream_memory(
    preferred: StreamShape,
    (wanted, upload_bytes): (Option<u32>, u64),
    frames: usize,
    (device_layers, pool_bytes): (u32, &dyn Fn(u32) -> u64),
    (room, coarsest): (Option<u64>, u32),
) -> std::result::Result<StreamMemory, Option<u64>> {
    let side = u64::from(preferred.page_side());
    let page = 4 * side * side;
    let frames = frames.max(1) as u64;
    let full_staging = upload_bytes.max(page);
    let mut least_room: Option<u64> = None;
    for base_level in preferred.base_level..=coarsest {
        let shape = StreamShape {
            base_level,
            ..preferred
        };
        let base_pages = shape.base_pages();
        if base_pages >= device_layers {
            continue;
        }
        let streamed = shape.page_total().min(u32::MAX as usize) as u32;
        let most = wanted
            .unwrap_or(streamed)
            .min(streamed)
            .min(device_layers - base_pages);
        let fewest = (MIN_POOL_LAYERS_PER_LEVEL * base_level).min(most);
        let least = pool_bytes(base_pages + fewest) + frames * page;
        least_room = Some(least_room.map_or(least, |r| r.min(least)));
        let Some(room) = room else {
            return Ok(StreamMemory {
                shape,
                layers: most,
                staging_bytes: full_staging,
            });
        };
        if least > room {
            continue;
        }
        let mut staging = full_staging.min((room / 8 / frames / page).max(1) * page);
        if pool_bytes(base_pages + fewest) + frames * staging > room {
            staging = page;
        }
        // The most layers whose pool fits beside the staging.
        let fits = |n: u32| pool_bytes(base_pages + n) + frames * staging <= room;
        let (mut lo, mut hi) = (fewest, most);
        while lo < hi {
            let mid = hi - (hi - lo) / 2;
            if fits(mid) {
                lo = mid;
            } else {
                hi = mid - 1;
            }
        }
        return Ok(StreamMemory {
            shape,
            layers: lo,
            staging_bytes: staging,
        });
    }
    Err(least_room)
}

/// What a memory budget keeps free for allocations made after the pool.
pub fn headroom(budget: u64) -> u64 {
    (budget / HEADROOM_FRACTION).max(MIN_HEADROOM_BYTES)
}

/// The smallest budget that leaves `room` bytes past `in_use` and the
/// headroom it keeps.
pub fn smallest_budget(in_use: u64, room: u64) -> u64 {
    let need = in_use + room;
    let fits = |b: u64| b >= need + headroom(b);
    let small = need + MIN_HEADROOM_BYTES;
    if headroom(small) == MIN_HEADROOM_BYTES {
        return small;
    }
    // b - floor(b / F) >= need: from the real solution, down while the
    // floor still lets a smaller budget through.
    let mut b = (need * HEADROOM_FRACTION).div_ceil(HEADROOM_FRACTION - 1);
    while fits(b - 1) {
        b -= 1;
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 16385^2 terrain in 256-cell tiles with a base of at most 2049
    /// samples a side (level 3: 8x8 pages), 64-cell patches, pools of
    /// 257^2 f32 layers.
    fn preferred() -> StreamShape {
        StreamShape::new(16385, 16385, 256, 2049)
    }

    const PAGE: u64 = 4 * 257 * 257;

    fn plan(
        room: Option<u64>,
        device_layers: u32,
    ) -> std::result::Result<StreamMemory, Option<u64>> {
        let coarsest = coarsest_base(&preferred(), 64);
        plan_stream_memory(
            preferred(),
            (None, 8 << 20),
            1,
            (device_layers, &|n| u64::from(n) * PAGE),
            (room, coarsest),
        )
    }

    #[test]
    fn the_pool_takes_what_the_budget_leaves_and_the_base_coarsens_last() {
        assert_eq!(preferred().base_level, 3);
        assert_eq!(coarsest_base(&preferred(), 64), 6);
        // No budget: the configured base, a layer for every streamed page
        // the device allows.
        let free = plan(None, 2048).unwrap();
        assert_eq!((free.shape.base_level, free.layers), (3, 2048 - 64));
        assert_eq!(free.staging_bytes, 8 << 20);
        // Room to spare: the same base, the pool filling what staging leaves.
        let roomy = plan(Some(300 << 20), 2048).unwrap();
        assert_eq!(roomy.shape.base_level, 3);
        assert_eq!(roomy.staging_bytes, 8 << 20);
        assert_eq!(
            u64::from(roomy.layers),
            ((300 << 20) - (8 << 20)) / PAGE - 64
        );
        // 14 MiB, 55 pages: level 3 needs 64 base pages, 27 pool layers
        // and a staging page; level 4 needs 16, 36 and 1, and takes the
        // rest for its pool.
        let tight = plan(Some(14 << 20), 2048).unwrap();
        assert_eq!(tight.shape.base_level, 4);
        assert_eq!(tight.staging_bytes, PAGE);
        assert_eq!(u64::from(tight.layers), (14 << 20) / PAGE - 16 - 1);
        assert!(u64::from(16 + tight.layers + 1) * PAGE <= 14 << 20);
        // Too little for any base: the fewest bytes, at level 5 (4 base
        // pages, 45 pool layers, a staging page).
        assert_eq!(plan(Some(1 << 20), 2048), Err(Some(50 * PAGE)));
        // A device of few layers takes the first base it can hold.
        let few = plan(None, 10).unwrap();
        assert_eq!((few.shape.base_level, few.layers), (5, 6));
        assert_eq!(plan(None, 1), Err(None));
    }

    #[test]
    fn the_smallest_budget_leaves_the_room_and_its_headroom() {
        for (in_use, room) in [(0, 0), (95 << 20, 24 << 20), (400 << 20, 300 << 20)] {
            let b = smallest_budget(in_use, room);
            assert!(b >= in_use + room + headroom(b), "{in_use} {room}: {b}");
            let less = b - 1;
            assert!(
                less < in_use + room + headroom(less),
                "{in_use} {room}: {b}"
            );
        }
    }
}
