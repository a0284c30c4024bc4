//! CPU terrain model on a 4097x4097 heightmap: Y bounds and the error table
//! (all cores), height_at (one core), and a memcpy of the heightmap's bytes
//! in the same run so the figures read as ratios to memory bandwidth. Then
//! the error LOD's frame plan on the bench views of the default scene and,
//! once `scripts/bench` has generated it, of the 4097^2 terrain, with the
//! view model (warm, and with the caches flushed first) and with the bound
//! alone (one core, 1280x720, tau 1 px), and the geomip path's refining
//! and balancing of the default scene's plan's blocks, from beyond the
//! blocks' sides beside from every side patch's neighbours. Last, the
//! geomip path's whole error choice (`ChosenPatches::by_error`: its plan,
//! levels, stitching, balancing and drawn list) on both terrains, warm
//! and cold, at tau 0.25 and 1 px.

use std::ffi::OsStr;
use std::hint::black_box;
use std::path::Path;

use clap::Parser;

use criterion::measurement::WallTime;
use criterion::{
    criterion_group, criterion_main, BatchSize, BenchmarkGroup, Criterion, Throughput,
};
use glam::DVec2;
use vkterrain::bench::cameras::named_views;
use vkterrain::cli::args::TerrainArgs;
use vkterrain::lod::geomip;
use vkterrain::lod::geomip_choice::ChosenPatches;
use vkterrain::lod::hierarchy::Hierarchy;
use vkterrain::lod::plan::{plan, PlanInputs, Planner, SightReading};
use vkterrain::lod::view::Tau;
use vkterrain::render::{FrameView, LoadedScene, Loading};
use vkterrain::scene::Scene;
use vkterrain::terrain::grid::patch_y_bounds;
use vkterrain::terrain::lod_params::DistanceLod;
use vkterrain::terrain::{ErrorTable, Heightmap, PatchId, Terrain, TerrainInfo};

const SIZE: usize = 4097;

fn heightmap() -> Heightmap {
    // Rolling hills plus hashed noise: realistic spread, no constant runs.
    Heightmap::from_fn(SIZE, SIZE, |r, c| {
        let (x, z) = (c as f32 * 0.01, r as f32 * 0.013);
        let mut h = (r as u64 * 0x9E37_79B9 + c as u64 * 0x85EB_CA6B) as u32;
        h ^= h >> 15;
        100.0 * x.sin() * z.cos() + (h % 1000) as f32 * 0.01
    })
    .expect("valid size")
}

/// xorshift points spread over the whole terrain.
fn random_points(info: &TerrainInfo, n: usize) -> Vec<DVec2> {
    let mut s = 0x2545_F491_4F6C_DD1Du64;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n)
        .map(|_| {
            DVec2::new(
                (next() - 0.5) * info.world_width(),
                (next() - 0.5) * info.world_depth(),
            )
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let map = heightmap();
    let bytes = (map.heights().len() * 4) as u64;
    let info = TerrainInfo::new(map, DVec2::new(1.0, 1.0), 32, DVec2::ZERO).unwrap();
    let grid = info.patch_grid();

    let mut group = c.benchmark_group("4097x4097");
    group.sample_size(10);

    group.throughput(Throughput::Bytes(bytes));
    let mut dst = vec![0.0f32; info.whole().heights().len()];
    group.bench_function("memcpy_heightmap_bytes", |b| {
        b.iter(|| {
            dst.copy_from_slice(black_box(info.whole().heights()));
            black_box(&dst);
        })
    });
    group.bench_function("y_bounds", |b| {
        b.iter(|| black_box(patch_y_bounds(black_box(info.whole()), &grid, 0.0)))
    });

    group.throughput(Throughput::Elements(grid.patch_count() as u64));
    group.bench_function("error_table", |b| {
        b.iter(|| black_box(ErrorTable::compute(black_box(info.whole()), &grid)))
    });

    const QUERIES: usize = 1 << 20;
    group.throughput(Throughput::Elements(QUERIES as u64));
    let scattered = random_points(&info, QUERIES);
    group.bench_function("height_at_random_points", |b| {
        b.iter(|| {
            let mut sum = 0.0f32;
            for p in &scattered {
                sum += info.height_at(p.x, p.y).unwrap_or(0.0);
            }
            black_box(sum)
        })
    });
    // A walk: consecutive queries a fraction of a cell apart, as a camera or
    // object placement produces.
    let mut walk: Vec<DVec2> = Vec::with_capacity(QUERIES);
    let start = DVec2::new(-0.45 * info.world_width(), 0.45 * info.world_depth());
    for i in 0..QUERIES {
        let t = i as f64 * 0.37;
        walk.push(start + DVec2::new(t % 3600.0, -(t / 3600.0).floor() * 3.0 - (t * 0.01).sin()));
    }
    group.bench_function("height_at_walk", |b| {
        b.iter_batched(
            || (),
            |_| {
                let mut sum = 0.0f32;
                for p in &walk {
                    sum += info.height_at(p.x, p.y).unwrap_or(0.0);
                }
                black_box(sum)
            },
            BatchSize::SmallInput,
        )
    });
    group.finish();
}

/// The default scene's terrain, held whole.
fn default_scene_terrain() -> Terrain {
    LoadedScene::load(&Scene::default_scene(), Loading::WHOLE_TERRAIN)
        .expect("the default scene loads")
        .terrain
}

/// The terrain `scripts/bench` generates and measures as `large-4097`,
/// where it has generated it: 4097^2 samples 4 m apart, 16,384 patches.
fn large_terrain() -> Option<Terrain> {
    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: TerrainArgs,
    }
    let target = std::env::var_os("CARGO_TARGET_DIR").unwrap_or_else(|| "target".into());
    let path = Path::new(&target).join("bench-data/large-4097.png");
    if !path.exists() {
        return None;
    }
    let scene = Cli::parse_from([
        OsStr::new("large-4097"),
        OsStr::new("--heightmap"),
        path.as_os_str(),
        OsStr::new("--cell-spacing"),
        OsStr::new("4"),
        OsStr::new("--height-scale"),
        OsStr::new("1400"),
    ])
    .args
    .scene()
    .expect("the large terrain's scene");
    let loaded =
        LoadedScene::load(&scene, Loading::WHOLE_TERRAIN).expect("the large terrain loads");
    Some(loaded.terrain)
}

/// Reads a line of each 64 bytes of `junk` (written, and larger than the
/// last-level cache), so that what runs next finds its data in memory, as
/// a frame's choice does after the frame before it was drawn.
fn flush_caches(junk: &[u8]) {
    black_box(junk.iter().step_by(64).fold(0u8, |a, &x| a ^ x));
}

/// The default scene's terrain and, where `scripts/bench` has generated
/// it, the 4097^2 terrain, by name.
fn plan_terrains() -> Vec<(&'static str, Terrain)> {
    [
        Some(("default", default_scene_terrain())),
        large_terrain().map(|t| ("large-4097", t)),
    ]
    .into_iter()
    .flatten()
    .collect()
}

/// Times `run` warm as `{label}/{view}`, and as `{label}-cold/{view}`
/// after the caches are flushed (`flush_caches`).
fn warm_and_cold(
    group: &mut BenchmarkGroup<'_, WallTime>,
    (label, view): (&str, &str),
    junk: &[u8],
    mut run: impl FnMut(),
) {
    group.bench_function(format!("{label}/{view}"), |b| b.iter(&mut run));
    group.bench_function(format!("{label}-cold/{view}"), |b| {
        b.iter_batched_ref(|| flush_caches(junk), |_| run(), BatchSize::PerIteration)
    });
}

/// The error LOD's plan for each bench view, with the view model and
/// with the bound alone, on the default scene and, where `scripts/bench`
/// has generated it, the 4097^2 terrain; and with the view model again
/// after the caches are flushed (`cold`), which is what a frame's choice
/// costs on lavapipe, whose frame between two choices runs through the
/// same cores and caches.
fn frame_plan(c: &mut Criterion) {
    let junk = vec![1u8; 96 << 20];
    for (name, terrain) in plan_terrains() {
        let (table, _) = terrain.error_tables();
        let sight = terrain.sight_table();
        let hierarchy = Hierarchy::new(&terrain, table);
        let mut group = c.benchmark_group(format!("frame_plan/{name}"));
        for view in named_views(terrain.info()) {
            let lod_view = FrameView::new(&terrain, &view.camera, 1280, 720).lod_view(Tau::DEFAULT);
            for (measure, sight) in [("sight", sight), ("bound", None)] {
                let inputs = PlanInputs {
                    table,
                    sight,
                    merge: true,
                    cull: true,
                    reading: SightReading::Tessellated,
                    seen: None,
                };
                // One planner a view, as a frame slot keeps one: after the
                // first plan its buffers have grown, and a plan allocates
                // nothing.
                let mut planner = Planner::default();
                let mut plan_once = || {
                    black_box(planner.plan(&terrain, &hierarchy, black_box(&lod_view), &inputs));
                };
                match measure {
                    "sight" => warm_and_cold(&mut group, (measure, view.name), &junk, plan_once),
                    _ => {
                        group.bench_function(format!("{measure}/{}", view.name), |b| {
                            b.iter(&mut plan_once)
                        });
                    }
                }
            }
        }
        group.finish();
    }
}

/// The plan's inputs as the geomip path's error choice gives them, with
/// its error table `table`: the view model read by template, culled, no
/// nodes merged, no counts.
fn geomip_inputs<'a>(terrain: &'a Terrain, table: &'a ErrorTable) -> PlanInputs<'a> {
    PlanInputs {
        table,
        sight: terrain.sight_table(),
        merge: false,
        cull: true,
        reading: SightReading::Template,
        seen: None,
    }
}

/// The geomip path's levels after its plan: each block's patches at its
/// level, then culled patches beside drawn ones refined and the levels
/// balanced, by `refine_and_balance_blocks` and, in the same run, by
/// `refine_and_balance` from every patch on a block's side.
fn geomip_levels(c: &mut Criterion) {
    let terrain = default_scene_terrain();
    let (table, _) = terrain.error_tables();
    let hierarchy = Hierarchy::new(&terrain, table);
    let grid = terrain.grid();
    let count = geomip::level_count(grid.cells_per_patch());
    let mut group = c.benchmark_group("geomip_levels");
    for view in named_views(terrain.info()) {
        let lod_view = FrameView::new(&terrain, &view.camera, 1280, 720).lod_view(Tau::DEFAULT);
        let inputs = geomip_inputs(&terrain, table);
        let frame_plan = plan(&terrain, &hierarchy, &lod_view, &inputs);
        let mut levels = vec![(count - 1) as u8; grid.patch_count()];
        let mut drawn = vec![false; grid.patch_count()];
        let mut rects = Vec::new();
        let mut sides = Vec::new();
        for block in &frame_plan.blocks {
            let k = usize::from(block.patch_level).min(count - 1);
            let ([c0, c1], [r0, r1]) = block.patch_range(grid);
            for row in r0..r1 {
                for col in c0..c1 {
                    let p = grid.patch_index(PatchId { row, col });
                    levels[p] = (count - 1 - k) as u8;
                    drawn[p] = true;
                    if row == r0 || row + 1 == r1 || col == c0 || col + 1 == c1 {
                        sides.push(PatchId { row, col });
                    }
                }
            }
            rects.push(([c0, c1], [r0, r1]));
        }
        let stitched = vec![[true; 4]; rects.len()];
        group.bench_function(format!("blocks/{}", view.name), |b| {
            b.iter_batched_ref(
                || levels.clone(),
                |l| geomip::refine_and_balance_blocks(l, grid, &drawn, &rects, |i| stitched[i]),
                BatchSize::SmallInput,
            )
        });
        group.bench_function(format!("side_patches/{}", view.name), |b| {
            b.iter_batched_ref(
                || levels.clone(),
                |l| geomip::refine_and_balance(l, grid, &drawn, &sides),
                BatchSize::SmallInput,
            )
        });
    }
    group.finish();
}

/// The geomip path's error choice as a frame makes it, with a frame
/// slot's kept buffers (`ChosenPatches`, `Planner`): the time its
/// `lod_ms` reads less what the renderer adds around it.
fn geomip_choice(c: &mut Criterion) {
    let junk = vec![1u8; 96 << 20];
    for (name, terrain) in plan_terrains() {
        let (tess_table, table) = terrain.error_tables();
        let hierarchy = Hierarchy::new(&terrain, tess_table);
        let grid = terrain.grid();
        let map = terrain.info().heightmap().expect("a whole terrain");
        let stitch = geomip::StitchErrors::compute(map, grid, table);
        let inputs = geomip_inputs(&terrain, table);
        let mut group = c.benchmark_group(format!("geomip_choice/{name}"));
        for view in named_views(terrain.info()) {
            for tau in [0.25, 1.0] {
                let lod_view = FrameView::new(&terrain, &view.camera, 1280, 720)
                    .lod_view(Tau::new(tau).expect("a valid tau"));
                let mut planner = Planner::default();
                let mut chosen = ChosenPatches::default();
                let choose = || {
                    black_box(chosen.by_error(
                        &terrain,
                        &hierarchy,
                        black_box(&lod_view),
                        (&mut planner, &inputs),
                        Some(&stitch),
                    ));
                };
                warm_and_cold(&mut group, (&format!("{tau}px"), view.name), &junk, choose);
            }
            // The distance LOD at the bench's nearest and farthest reach
            // of the finest level (half and four times the scene's).
            let lod = DistanceLod::for_extent(terrain.info().world_width());
            let lod_view = FrameView::new(&terrain, &view.camera, 1280, 720).lod_view(Tau::DEFAULT);
            for scale in [0.5, 4.0] {
                let mut chosen = ChosenPatches::default();
                let choose = || {
                    chosen.by_distance(
                        &terrain,
                        &hierarchy,
                        black_box(&lod_view),
                        (true, lod.min_dist * scale),
                    );
                    black_box(&chosen);
                };
                warm_and_cold(
                    &mut group,
                    (&format!("distance-x{scale}"), view.name),
                    &junk,
                    choose,
                );
            }
        }
        group.finish();
    }
}

criterion_group!(benches, bench, frame_plan, geomip_levels, geomip_choice);
criterion_main!(benches);
