use vkterrain::scene::Scene;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let scene = if args.len() > 1 {
        Scene::load(std::path::Path::new(&args[1])).unwrap()
    } else {
        Scene::default_scene()
    };
    let info = vkterrain::cli::scene_terrain_info(&scene, false).unwrap().0;
    let terrain = vkterrain::terrain::Terrain::new(info, 0.0).unwrap();
    let t = std::time::Instant::now();
    let _ = terrain.error_tables();
    println!("error tables {:.3} s", t.elapsed().as_secs_f64());
    let t = std::time::Instant::now();
    let s = terrain.sight_table().unwrap();
    println!(
        "sight {:.3} s, patches {}",
        t.elapsed().as_secs_f64(),
        terrain.grid().patch_count()
    );
    let _ = s;
}
