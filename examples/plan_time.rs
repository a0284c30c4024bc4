use vkterrain::bench::cameras::named_views;
use vkterrain::lod::hierarchy::Hierarchy;
use vkterrain::lod::plan::{plan, PlanInputs};
use vkterrain::lod::view::Tau;
use vkterrain::render::FrameView;
use vkterrain::scene::Scene;
use vkterrain::terrain::Terrain;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let scene = match args.get(1).map(String::as_str) {
        None | Some("default") => Scene::default_scene(),
        Some(p) if p.ends_with(".toml") => Scene::load(std::path::Path::new(p)).unwrap(),
        Some(p) => {
            let mut s = Scene::default_scene();
            s.heightmap = vkterrain::scene::HeightmapSource::File(p.into());
            s.cell_spacing = glam::DVec2::splat(4.0);
            s.load.height_scale = 1400.0;
            s.load.format = None;
            s
        }
    };
    let info = vkterrain::cli::scene_terrain_info(&scene, false).unwrap().0;
    let terrain = Terrain::new(info, 0.0).unwrap();
    let t = std::time::Instant::now();
    let (table, _) = terrain.error_tables();
    println!("error tables {:.3} s", t.elapsed().as_secs_f64());
    let t = std::time::Instant::now();
    let sight = terrain.sight_table();
    println!("sight {:.3} s, {} patches", t.elapsed().as_secs_f64(), terrain.grid().patch_count());
    let t = std::time::Instant::now();
    let hierarchy = Hierarchy::new(&terrain, table);
    println!("hierarchy {:.3} ms", t.elapsed().as_secs_f64() * 1e3);
    for v in named_views(terrain.info()) {
        let view = FrameView::new(&terrain, &v.camera, 1280, 720);
        for tau in [0.5f32, 1.0, 2.0] {
            let lod_view = view.lod_view(Tau::new(tau).unwrap());
            let inputs = PlanInputs { table, sight, merge: true, cull: true };
            let mut times = Vec::new();
            let mut p = None;
            let reps = std::env::var("REPS").ok().and_then(|r| r.parse().ok()).unwrap_or(20usize);
            let mut junk = vec![0u8; 64 << 20];
            for i in 0..reps {
                if std::env::var("COLD").is_ok() {
                    // Evict the caches, as a frame's rendering does.
                    for b in junk.iter_mut().step_by(64) { *b = b.wrapping_add(i as u8); }
                }
                let t = std::time::Instant::now();
                p = Some(plan(&terrain, &hierarchy, &lod_view, &inputs));
                times.push(t.elapsed().as_secs_f64() * 1e3);
            }
            let first = times[0];
            times.sort_by(f64::total_cmp);
            std::hint::black_box(&junk);
            let p = p.unwrap();
            let mut hist = [0usize; 8];
            for b in &p.blocks { hist[b.level as usize] += 1; }
            let chosen = p.blocks.iter().filter(|b| b.chosen).count();
            let full = p.blocks.iter().filter(|b| b.full_resolution).count();
            println!("   block levels {hist:?}, chosen {chosen}, full {full}");
            let candidates = p.blocks.len();
            println!("{:8} tau {tau}: plan median {:.3} ms max {:.3} ms, first {:.3}; {} blocks ({} patches in view), {} merged, {} visited", v.name, times[reps / 2], times[reps - 1], first, candidates, p.patches_in_view, p.merged.len(), p.nodes_visited);
        }
    }
}
