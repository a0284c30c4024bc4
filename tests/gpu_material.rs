//! Material layers on the GPU, validation on: golden images of blend-map
//! mode, rules mode, one layer and eight; rules against the blend map baked
//! from them (the GLSL weights against the Rust ones); displacement that
//! culling must not lose; and only the resources a scene uses.

mod common;

use std::path::{Path, PathBuf};

use common::gpu::*;
use common::*;
use glam::DVec2;
use vkterrain::appearance::generate::blend_maps_from_rules;
use vkterrain::appearance::Appearance;
use vkterrain::bench::error::differing_pixels;
use vkterrain::gpu::Capabilities;
use vkterrain::render::{LodMetric, RenderPath, RenderSettings};
use vkterrain::scene::{Asset, AssetSource, Scene, WeightSource};
use vkterrain::terrain::camera::Camera;
use vkterrain::terrain::shading::Rules;
use vkterrain::terrain::{Heightmap, Terrain, TerrainInfo};

const W: u32 = 320;
const H: u32 = 180;

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

/// The scene's terrain (Y bounds grown for its displacement), look and
/// settings.
fn prepare(scene: &Scene) -> (Terrain, Appearance, RenderSettings) {
    let info = scene.terrain_info().unwrap();
    let appearance = Appearance::load(scene, &info).unwrap();
    let terrain = Terrain::new(info, appearance.y_margin()).unwrap();
    let settings = RenderSettings::for_scene(scene, terrain.info());
    (terrain, appearance, settings)
}

/// Renders `scene` from its camera (or overview) with each path in
/// `paths`, on the device the goldens were made on; checks validation.
fn render(scene: &Scene, paths: &[RenderPath]) -> Vec<image::RgbaImage> {
    let (terrain, appearance, settings) = prepare(scene);
    let camera = scene.camera_for(terrain.info());
    let mut gpu = GpuScene::for_golden(terrain, &appearance, W, H);
    let images = paths
        .iter()
        .map(|&path| {
            gpu.render(&camera, &RenderSettings { path, ..settings })
                .rgba_image()
        })
        .collect();
    gpu.finish();
    images
}

/// A scene file over the DEM with `look` appended; TEX stands for the
/// repository's textures directory. The distance LOD is named, so the
/// images are about the material, not the level choice.
fn dem_scene(dir: &tempfile::TempDir, look: &str) -> Scene {
    let text = format!(
        "[heightmap]\npath = \"{}\"\nheight_scale = 65535.0\ncell_spacing = [74.48, 92.15]\n\
         [terrain]\ncells_per_patch = 32\n[lod]\nmin_distance = 20.0\nmax_distance = 500.0\n\
         [camera]\neye = [-9000.0, 2600.0, -19000.0]\n\
         target = [1500.0, 300.0, 2000.0]\nfov = 55.0\n{}",
        data_path("jacksboro_fault_dem.png").display(),
        look.replace("TEX", &repo("assets/textures").display().to_string())
    );
    Scene::load(&temp_file(dir, "scene.toml", text.as_bytes())).unwrap()
}

#[test]
fn blend_map_mode_matches_its_golden_image_on_every_path() {
    if skip_gpu() {
        return;
    }
    let scene = Scene::default_scene();
    let images = render(
        &scene,
        &[RenderPath::Tess, RenderPath::Geomip, RenderPath::Brute],
    );
    assert_golden("material-blend-map", &images[0], 12, 0.005);
    // The other paths draw the same surface and look, up to the
    // triangulation: most pixels agree closely.
    for (i, name) in [(1, "geomip"), (2, "brute")] {
        assert_images_match(
            &format!("material-blend-map-{name}"),
            &images[i],
            &images[0],
            40,
            0.03,
        );
    }
}

#[test]
fn rules_mode_matches_its_golden_image_and_the_blend_map_baked_from_it() {
    if skip_gpu() {
        return;
    }
    let rules_scene = Scene::load(&repo("assets/scenes/rules.toml")).unwrap();
    let rules = render(&rules_scene, &[RenderPath::Tess]).remove(0);
    assert_golden("material-rules", &rules, 12, 0.005);

    // The same rules baked into a full-resolution blend map by the CPU
    // (terrain::shading::Rules) must look the same as the GPU's rules
    // (rule_weights in glsl/material.glsl): this holds the two equal.
    let dir = tempfile::tempdir().unwrap();
    let material = rules_scene.material.as_ref().unwrap();
    let WeightSource::Rules { cliff } = material.weights else {
        panic!("rules.toml is in rules mode")
    };
    let info = rules_scene.terrain_info().unwrap();
    let cpu_rules = Rules {
        bands: material.layers.iter().map(|l| l.band).collect(),
        cliff,
    };
    let maps = blend_maps_from_rules(&info, &cpu_rules, material.layers.len(), 1);
    let path = dir.path().join("blend.png");
    maps[0].save(&path).unwrap();
    let mut baked = rules_scene.clone();
    let m = baked.material.as_mut().unwrap();
    m.weights = WeightSource::BlendMaps(vec![Asset {
        source: AssetSource::File(path),
        scene: PathBuf::from("test"),
        line: 1,
        key: "blend".into(),
    }]);
    let from_map = render(&baked, &[RenderPath::Tess]).remove(0);
    assert_images_match("material-rules-baked", &from_map, &rules, 24, 0.02);
}

#[test]
fn one_layer_matches_its_golden_image() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let scene = dem_scene(
        &dir,
        "[material]\n[[material.layer]]\ndiffuse = \"TEX/rock.png\"\n\
         normal = \"TEX/rock-normal.png\"\ntile_size = 400.0\n",
    );
    let image = render(&scene, &[RenderPath::Tess]).remove(0);
    assert_golden("material-one-layer", &image, 12, 0.005);
}

/// Eight height bands over the DEM, every texture at least once.
const EIGHT_LAYERS: [(&str, f32, f32); 8] = [
    ("sand", 0.0, 0.1),
    ("grass", 0.15, 0.1),
    ("dirt", 0.3, 0.1),
    ("grass", 0.45, 0.1),
    ("rock", 0.6, 0.1),
    ("dirt", 0.72, 0.1),
    ("rock", 0.85, 0.1),
    ("snow", 1.0, 0.12),
];

#[test]
fn eight_layers_over_two_blend_maps_match_their_golden_image() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // Bake eight bands into two blend maps, then draw from the maps.
    let mut rules_look = String::from("[material]\n");
    for (i, (name, centre, width)) in EIGHT_LAYERS.iter().enumerate() {
        rules_look.push_str(&format!(
            "[[material.layer]]\ndiffuse = \"TEX/{name}.png\"\ntile_size = {}\nheight_band = [{centre}, {width}]\n",
            300.0 + 50.0 * i as f32
        ));
    }
    let rules_scene = dem_scene(&dir, &rules_look);
    let info = rules_scene.terrain_info().unwrap();
    let m = rules_scene.material.as_ref().unwrap();
    let rules = Rules {
        bands: m.layers.iter().map(|l| l.band).collect(),
        cliff: None,
    };
    let maps = blend_maps_from_rules(&info, &rules, 8, 1);
    assert_eq!(maps.len(), 2, "layers 1..4 and 5..7");
    for (i, map) in maps.iter().enumerate() {
        map.save(dir.path().join(format!("blend{i}.png"))).unwrap();
    }
    let mut look = format!(
        "[material]\nblend_maps = [\"{0}/blend0.png\", \"{0}/blend1.png\"]\n",
        dir.path().display()
    );
    for (i, (name, _, _)) in EIGHT_LAYERS.iter().enumerate() {
        look.push_str(&format!(
            "[[material.layer]]\ndiffuse = \"TEX/{name}.png\"\nnormal = \"TEX/{name}-normal.png\"\ntile_size = {}\n",
            300.0 + 50.0 * i as f32
        ));
    }
    look.push_str("[fog]\nstart = 10000.0\nrange = 40000.0\ncolor = [0.52, 0.68, 0.86]\n");
    let scene = dem_scene(&dir, &look);
    let image = render(&scene, &[RenderPath::Tess]).remove(0);
    assert_golden("material-eight-layers", &image, 12, 0.005);
}

/// A flat 129x129 plane, 10 m between samples, in 4-cell patches, with
/// one rock layer displaced by up to ±`scale / 2`.
fn displaced_plane(dir: &tempfile::TempDir, scale: f32) -> Scene {
    let map = vec![0u8; 129 * 129];
    let map_path = temp_file(dir, "flat.r8", &map);
    let text = format!(
        "[heightmap]\npath = \"{}\"\nformat = \"raw8\"\nsize = [129, 129]\ncell_spacing = 10.0\n\
         [terrain]\ncells_per_patch = 4\n\
         [material]\n[[material.layer]]\ndiffuse = \"{tex}/rock.png\"\nheight = \"{tex}/rock-height.png\"\n\
         tile_size = 120.0\ndisplacement = {scale}\n",
        map_path.display(),
        tex = repo("assets/textures").display()
    );
    Scene::load(&temp_file(dir, "displaced.toml", text.as_bytes())).unwrap()
}

#[test]
fn culling_keeps_what_displacement_lifts_into_view() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let scene = displaced_plane(&dir, 240.0);
    // Low over the plane, looking up a little: near patches lie wholly
    // below the frustum's bottom plane until displacement lifts them.
    let camera = camera([0.0, 20.0, -600.0], [0.0, 120.0, 600.0], 50.0);
    let (terrain, appearance, settings) = prepare(&scene);
    assert_eq!(appearance.y_margin(), 120.0);
    let flat = terrain.info().clone();
    let mut gpu = GpuScene::with_appearance(terrain, &appearance, W, H, false);
    // Geomip's levels are balanced between the patches in view only (a
    // culled patch constrains nothing), so culling may change where its
    // distance levels step; on this flat plane its error LOD draws every
    // patch at the coarsest level, whatever is culled.
    let geomip = RenderSettings {
        path: RenderPath::Geomip,
        lod_metric: LodMetric::Error(1.0),
        ..settings
    };
    for settings in [
        RenderSettings {
            path: RenderPath::Tess,
            ..settings
        },
        geomip,
    ] {
        let path = settings.path;
        let culled = gpu.render(&camera, &settings);
        let all = gpu.render(
            &camera,
            &RenderSettings {
                cull: false,
                ..settings
            },
        );
        assert!(
            culled.patches_in_frustum < gpu.terrain.grid().patch_count(),
            "{path:?}: culling must have something to cull"
        );
        assert_eq!(
            culled.readback.rgba, all.readback.rgba,
            "{path:?}: culling changed the image"
        );
    }
    gpu.finish();

    // Without the grown bounds, the same culling loses visible ground:
    // the check above can fail.
    let bare = Terrain::new(flat, 0.0).unwrap();
    let mut gpu = GpuScene::with_appearance(bare, &appearance, W, H, false);
    let culled = gpu.render(&camera, &settings);
    let all = gpu.render(
        &camera,
        &RenderSettings {
            cull: false,
            ..settings
        },
    );
    let differing = differing_pixels(&culled.readback.rgba, &all.readback.rgba);
    assert!(
        differing > 100,
        "ungrown bounds should lose ground: {differing} pixels differ"
    );
    gpu.finish();
}

#[test]
fn only_the_resources_a_scene_uses_are_created() {
    if skip_gpu() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let names = |scene: &Scene| -> Vec<String> {
        let (terrain, appearance, _) = prepare(scene);
        let gpu = GpuScene::with_appearance(terrain, &appearance, 8, 8, false);
        let names = gpu
            .gpu()
            .device
            .memory_report()
            .into_iter()
            .map(|(n, _)| n)
            .filter(|n| n.starts_with("material.") || n.starts_with("lighting."))
            .collect();
        gpu.finish();
        names
    };
    // No layers: nothing.
    assert!(names(&dem_scene(&dir, "")).is_empty());
    // One layer, no maps: its uniforms and colour only.
    assert_eq!(
        names(&dem_scene(
            &dir,
            "[material]\n[[material.layer]]\ndiffuse = \"TEX/rock.png\"\n"
        )),
        vec!["material.diffuse_maps", "material.uniforms"]
    );
    // A height map whose displacement is 0 is not uploaded.
    let look = "[material]\n[[material.layer]]\ndiffuse = \"TEX/rock.png\"\nheight = \"TEX/rock-height.png\"\n";
    assert_eq!(
        names(&dem_scene(&dir, look)),
        vec!["material.diffuse_maps", "material.uniforms"]
    );
    // The default scene: blend map, normal maps and lightmap, no height maps.
    assert_eq!(
        names(&Scene::default_scene()),
        vec![
            "lighting.lightmap",
            "material.blend_maps",
            "material.diffuse_maps",
            "material.normal_maps",
            "material.uniforms"
        ]
    );
}

#[test]
fn a_textured_scene_draws_on_a_terrain_that_is_not_2n_plus_1() {
    if skip_gpu() {
        return;
    }
    // 100x70 samples with uneven spacing: texel-centre addressing of the
    // lightmap and displacement on every path, validation-clean, projected
    // from above and triplanar (the sawtooth's slopes take the sides).
    for triplanar in [false, true] {
        let map = Heightmap::from_fn(100, 70, |r, c| ((r * 7 + c * 13) % 50) as f32).unwrap();
        let info = TerrainInfo::new(map, DVec2::new(3.0, 5.0), 8, DVec2::ZERO).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let mut scene = displaced_plane(&dir, 10.0);
        scene.lightmap = true;
        scene.material.as_mut().unwrap().triplanar = triplanar;
        let appearance = Appearance::load(&scene, &info).unwrap();
        let terrain = Terrain::new(info, appearance.y_margin()).unwrap();
        let camera: Camera = scene.camera_for(terrain.info());
        let mut gpu = GpuScene::with_appearance(terrain, &appearance, 64, 64, false);
        let images: Vec<_> = [RenderPath::Tess, RenderPath::Geomip, RenderPath::Brute]
            .into_iter()
            .map(|path| {
                // Near full resolution everywhere, so the paths draw the
                // same surface of this sawtooth map.
                let settings = RenderSettings {
                    path,
                    lod_metric: LodMetric::Error(0.25),
                    ..RenderSettings::default()
                };
                gpu.render(&camera, &settings).rgba_image()
            })
            .collect();
        gpu.finish();
        // The terrain fills most of the view, and every path draws the
        // same displaced, lit surface up to its triangulation.
        let background = *images[2].get_pixel(0, 0);
        let drawn = images[2].pixels().filter(|&&p| p != background).count();
        assert!(drawn * 2 > 64 * 64, "brute drew {drawn} pixels of 4096");
        let name = if triplanar { "-triplanar" } else { "" };
        assert_images_match(
            &format!("uneven-textured{name}-tess"),
            &images[0],
            &images[2],
            24,
            0.05,
        );
        assert_images_match(
            &format!("uneven-textured{name}-geomip"),
            &images[1],
            &images[2],
            24,
            0.05,
        );
    }
}

#[test]
fn anisotropy_follows_the_scene_within_the_device() {
    let caps = |kind: &str, has: bool| Capabilities {
        device_type: kind.into(),
        sampler_anisotropy: has,
        ..test_capabilities()
    };
    use vkterrain::render::appearance::anisotropy_for;
    let gpu = caps("discrete GPU", true);
    assert_eq!(anisotropy_for(None, &gpu), Some(16.0));
    assert_eq!(anisotropy_for(Some(4.0), &gpu), Some(4.0));
    assert_eq!(anisotropy_for(Some(64.0), &gpu), Some(16.0));
    assert_eq!(anisotropy_for(Some(1.0), &gpu), None);
    // CPU rasterisers leave it off unless the scene asks.
    let cpu = caps("CPU", true);
    assert_eq!(anisotropy_for(None, &cpu), None);
    assert_eq!(anisotropy_for(Some(4.0), &cpu), Some(4.0));
    // Without the feature it is always off.
    assert_eq!(
        anisotropy_for(Some(4.0), &caps("discrete GPU", false)),
        None
    );
}

#[test]
fn anisotropic_filtering_when_the_scene_asks_for_it() {
    if skip_gpu() {
        return;
    }
    // Tiny, because on lavapipe it costs over 1000x. The same grazing view
    // with 4 samples and with 1 differs where the texture is seen at a
    // slant, when the device filters anisotropically at all.
    let dir = tempfile::tempdir().unwrap();
    let render = |anisotropy: f32| {
        let scene = dem_scene(
            &dir,
            &format!(
                "[material]\nanisotropy = {anisotropy:.1}\n[[material.layer]]\n\
                 diffuse = \"TEX/rock.png\"\ntile_size = 400.0\n"
            ),
        );
        let (terrain, appearance, settings) = prepare(&scene);
        assert_eq!(
            appearance.material.as_ref().unwrap().anisotropy,
            Some(anisotropy)
        );
        let camera = scene.camera_for(terrain.info());
        let mut gpu = GpuScene::with_appearance(terrain, &appearance, 48, 27, false);
        let has = gpu.gpu().device.caps.sampler_anisotropy;
        let image = gpu.render(&camera, &settings).rgba_image();
        gpu.finish();
        (image, has)
    };
    let (four, has) = render(4.0);
    let (one, _) = render(1.0);
    let differing = four
        .pixels()
        .zip(one.pixels())
        .filter(|(a, b)| a != b)
        .count();
    if has {
        assert!(differing > 0, "anisotropic filtering changed nothing");
    } else {
        assert_eq!(differing, 0);
    }
}

#[test]
fn odd_sized_and_odd_format_textures_load_and_draw() {
    if skip_gpu() {
        return;
    }
    // 37x5 16-bit RGB and a 1x1 grayscale colour, and a 3x7 RGBA normal
    // map: each array takes its largest width and height and mips down to
    // 1x1.
    let dir = tempfile::tempdir().unwrap();
    let wide = image::ImageBuffer::<image::Rgb<u16>, _>::from_fn(37, 5, |x, y| {
        image::Rgb([(x * 1700) as u16, (y * 9000) as u16, 40000])
    });
    wide.save(dir.path().join("wide.png")).unwrap();
    image::GrayImage::from_pixel(1, 1, image::Luma([200]))
        .save(dir.path().join("dot.png"))
        .unwrap();
    image::RgbaImage::from_pixel(3, 7, image::Rgba([128, 128, 255, 255]))
        .save(dir.path().join("flat-normal.png"))
        .unwrap();
    let d = dir.path().display();
    let scene = dem_scene(
        &dir,
        &format!(
            "[material]\ncliff_layer = 1\n\
             [[material.layer]]\ndiffuse = \"{d}/wide.png\"\nnormal = \"{d}/flat-normal.png\"\n\
             tile_size = 500.0\ntile_rotation = 1000.0\ntile_offset = [123456.0, -0.5]\n\
             height_band = [0.3, 0.5]\n\
             [[material.layer]]\ndiffuse = \"{d}/dot.png\"\n"
        ),
    );
    let (terrain, appearance, settings) = prepare(&scene);
    let m = appearance.material.as_ref().unwrap();
    assert_eq!(
        (m.diffuse.width, m.diffuse.height, m.diffuse.layers),
        (37, 5, 2)
    );
    // 37x5 -> 18x2 -> 9x1 -> 4x1 -> 2x1 -> 1x1
    assert_eq!(m.diffuse.levels.len(), 6);
    assert_eq!(m.diffuse.level_extent(5), (1, 1));
    assert_eq!(m.diffuse.levels[1].len(), 2 * 18 * 2 * 4);
    let normals = m.normals.as_ref().unwrap();
    assert_eq!(
        (normals.width, normals.height, normals.levels.len()),
        (3, 7, 3)
    );
    let camera = scene.camera_for(terrain.info());
    let mut gpu = GpuScene::with_appearance(terrain, &appearance, 64, 36, false);
    let images: Vec<_> = [RenderPath::Tess, RenderPath::Geomip, RenderPath::Brute]
        .into_iter()
        .map(|path| {
            // Near full resolution, so the paths draw the same surface.
            let lod_metric = LodMetric::Error(0.25);
            let settings = RenderSettings {
                path,
                lod_metric,
                ..settings
            };
            gpu.render(&camera, &settings).rgba_image()
        })
        .collect();
    gpu.finish();
    // The wide 16-bit texture shows: more blue than green throughout (its
    // blue channel is constant, green under it in most rows), with its red
    // gradient across each tile.
    let background = *images[2].get_pixel(0, 0);
    let drawn: Vec<_> = images[2].pixels().filter(|&&p| p != background).collect();
    let bluish = drawn
        .iter()
        .filter(|p| p[2] > p[1].saturating_add(20))
        .count();
    let reds = drawn.iter().map(|p| p[0]);
    let red_range = reds.clone().max().unwrap_or(0) - reds.min().unwrap_or(0);
    assert!(
        drawn.len() * 3 > 64 * 36 && bluish * 2 > drawn.len() && red_range >= 40,
        "{} drawn, {bluish} blue, red range {red_range}",
        drawn.len()
    );
    assert_images_match("odd-format-tess", &images[0], &images[2], 24, 0.05);
    assert_images_match("odd-format-geomip", &images[1], &images[2], 24, 0.05);
}

/// A scene over a 33x33 map with a 64 m step between columns 15 and 16 (a
/// vertical cliff facing -x), one layer of a checker of 4 m squares
/// (32 m per repeat), projected triplanar or from above.
fn cliff_scene(dir: &tempfile::TempDir, triplanar: bool) -> Scene {
    let heights = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(33, 33, |x, _| {
        image::Luma([if x >= 16 { 65535 } else { 0 }])
    });
    heights.save(dir.path().join("cliff.png")).unwrap();
    let checker = image::RgbImage::from_fn(64, 64, |x, y| {
        if (x / 8 + y / 8) % 2 == 0 {
            image::Rgb([200, 200, 200])
        } else {
            image::Rgb([40, 40, 40])
        }
    });
    checker.save(dir.path().join("checker.png")).unwrap();
    let text = format!(
        "[heightmap]\npath = \"cliff.png\"\nheight_scale = 64.0\ncell_spacing = 1.0\n\
         [terrain]\ncells_per_patch = 16\n\
         [material]\ntriplanar = {triplanar}\n\
         [[material.layer]]\ndiffuse = \"checker.png\"\ntile_size = 32.0\n"
    );
    Scene::load(&temp_file(dir, "scene.toml", text.as_bytes())).unwrap()
}

/// Texture frequency down the cliff face over frequency across it: the
/// sign changes of luminance about its mean per pixel, down the columns
/// over along the rows, in the middle half of a face-on view. 1 for a
/// texture at its own scale; near 0 for one smeared into vertical streaks.
fn cliff_stretch(triplanar: bool) -> f64 {
    let dir = tempfile::tempdir().unwrap();
    let scene = cliff_scene(&dir, triplanar);
    let (terrain, appearance, settings) = prepare(&scene);
    let info = terrain.info();
    let origin = info.origin();
    let face_x = origin.x + 0.5 * (info.local_x(15) + info.local_x(16));
    let mid_z = origin.y + info.local_z(16);
    let cam = camera([face_x - 40.0, 32.0, mid_z], [face_x, 32.0, mid_z], 55.0);
    let (w, h) = (128u32, 128u32);
    let mut gpu = GpuScene::with_appearance(terrain, &appearance, w, h, false);
    let frame = gpu.render(
        &cam,
        &RenderSettings {
            path: RenderPath::Brute,
            ..settings
        },
    );
    gpu.finish();
    let image = frame.rgba_image();
    let luma = |x: u32, y: u32| {
        let p = image.get_pixel(x, y);
        0.2126 * f64::from(p[0]) + 0.7152 * f64::from(p[1]) + 0.0722 * f64::from(p[2])
    };
    let (lo, hi) = (w / 4, 3 * w / 4);
    for y in lo..hi {
        for x in lo..hi {
            assert!(
                frame.readback.depth[(y * w + x) as usize] > 0.0,
                "pixel {x},{y} of the middle shows the cliff"
            );
        }
    }
    let mean = (lo..hi)
        .flat_map(|y| (lo..hi).map(move |x| (x, y)))
        .map(|(x, y)| luma(x, y))
        .sum::<f64>()
        / f64::from((hi - lo) * (hi - lo));
    let changes = |a: (u32, u32), b: (u32, u32)| {
        usize::from((luma(a.0, a.1) > mean) != (luma(b.0, b.1) > mean))
    };
    let (mut across, mut down) = (0, 0);
    for y in lo..hi {
        for x in lo..hi - 1 {
            across += changes((x, y), (x + 1, y));
        }
    }
    for x in lo..hi {
        for y in lo..hi - 1 {
            down += changes((x, y), (x, y + 1));
        }
    }
    assert!(
        across > 10,
        "the checker shows across the face: {across} changes"
    );
    down as f64 / across as f64
}

#[test]
fn triplanar_projection_keeps_the_texture_scale_on_a_vertical_cliff() {
    if skip_gpu() {
        return;
    }
    let triplanar = cliff_stretch(true);
    assert!(
        (0.75..=1.33).contains(&triplanar),
        "triplanar: vertical over horizontal frequency {triplanar:.3}, not about 1"
    );
    // Projected from above, the face smears into vertical streaks: the
    // measure sees it.
    let planar = cliff_stretch(false);
    eprintln!("cliff stretch (vertical / horizontal frequency): triplanar {triplanar:.3}, from above {planar:.3}");
    assert!(
        planar < 0.2,
        "from above: vertical over horizontal frequency {planar:.3}, expected streaks"
    );
}
