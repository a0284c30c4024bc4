//! Scenes with material layers, lights and fog, on the CPU: parsing and its
//! errors (file, key, line), texture loading with mipmaps, blend-map sizes,
//! the rules' weights, displacement bounds and the baked lightmap.

mod common;

use std::path::{Path, PathBuf};

use common::*;
use glam::{DVec2, DVec3};
use vkterrain::appearance::generate::blend_maps_from_rules;
use vkterrain::appearance::{blend_map_sizes, Appearance, MaterialError, TexelFormat};
use vkterrain::scene::{AssetSource, Scene, SceneFileError, WeightSource};
use vkterrain::terrain::shading::{
    bake_lightmap, blend_map_weights, blend_values, max_displacement, Cliff, HeightBand, Rules,
};
use vkterrain::terrain::{Heightmap, Terrain, TerrainInfo};

fn textures_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/textures")
}

/// A scene over a 33x33 cliff map in `dir`, with `look` appended.
fn scene_in(dir: &tempfile::TempDir, look: &str) -> PathBuf {
    let map: Vec<u8> = (0..33 * 33).map(|i| ((i % 33) * 7) as u8).collect();
    temp_file(dir, "map.r8", &map);
    let textures = textures_dir().display().to_string();
    let text = format!(
        "[heightmap]\npath = \"map.r8\"\nformat = \"raw8\"\nsize = [33, 33]\n\n{}",
        look.replace("TEX", &textures)
    );
    temp_file(dir, "scene.toml", text.as_bytes())
}

fn refused(look: &str) -> SceneFileError {
    let dir = tempfile::tempdir().unwrap();
    let err = Scene::load(&scene_in(&dir, look)).expect_err("must be refused");
    assert!(
        err.to_string().contains("scene.toml"),
        "names the file: {err}"
    );
    err
}

fn assert_refused(look: &str, key: &str, line: usize, words: &str) {
    let err = refused(look);
    let text = err.to_string();
    match &err {
        SceneFileError::Invalid {
            key: k, line: l, ..
        } => {
            assert_eq!((k.as_str(), *l), (key, line), "{text}")
        }
        SceneFileError::Parse { message, .. } => {
            assert!(message.contains(key), "{text}");
            assert!(message.contains(&format!("line {line}")), "{text}");
        }
        other => panic!("expected an error at {key}, line {line}; got {other}"),
    }
    assert!(text.contains(words), "{text}");
}

const ONE_LAYER: &str = "[material]\n[[material.layer]]\ndiffuse = \"TEX/grass.png\"\n";

#[test]
fn a_scene_without_a_look_has_the_default_light_and_nothing_else() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::load(&scene_in(&dir, "")).unwrap();
    assert!(scene.material.is_none() && scene.fog.is_none() && !scene.lightmap);
    assert_eq!(scene.lighting.light_count, 1);
    let appearance = Appearance::load(&scene, &scene.terrain_info().unwrap()).unwrap();
    assert_eq!(appearance, Appearance::default());
    assert_eq!(appearance.y_margin(), 0.0);
}

#[test]
fn lights_fog_and_layers_are_read() {
    let dir = tempfile::tempdir().unwrap();
    let look = "[lighting]\nambient = [0.1, 0.2, 0.3]\n\
        [[lighting.light]]\ndirection = [0.0, 2.0, 0.0]\ncolor = [1.0, 0.5, 0.25]\nintensity = 2.0\n\
        [[lighting.light]]\ndirection = [1.0, 0.0, 0.0]\n\
        [fog]\nstart = 100.0\nrange = 400.0\ncolor = [0.5, 0.6, 0.7]\n\
        [material]\ncliff_layer = 1\ncliff_slope = [20.0, 40.0]\ntriplanar = true\n\
        [[material.layer]]\ndiffuse = \"TEX/grass.png\"\nheight_band = [0.2, 0.3]\n\
        [[material.layer]]\ndiffuse = \"TEX/rock.png\"\nnormal = \"TEX/rock-normal.png\"\n\
        height = \"TEX/rock-height.png\"\ntile_size = [10.0, 20.0]\ntile_rotation = 90.0\n\
        displacement = 8.0\n";
    let scene = Scene::load(&scene_in(&dir, look)).unwrap();
    let l = scene.lighting;
    assert_eq!(l.light_count, 2);
    assert_eq!(l.ambient.to_array(), [0.1, 0.2, 0.3]);
    assert_eq!(l.lights[0].direction.to_array(), [0.0, 1.0, 0.0]);
    assert_eq!(l.lights[0].radiance.to_array(), [2.0, 1.0, 0.5]);
    let fog = scene.fog.unwrap();
    assert_eq!((fog.start, fog.range), (100.0, 400.0));
    let m = scene.material.as_ref().unwrap();
    assert_eq!(m.layers.len(), 2);
    assert_eq!(
        m.weights,
        WeightSource::Rules {
            cliff: Some(Cliff {
                layer: 1,
                slope_deg: [20.0, 40.0]
            })
        }
    );
    assert_eq!(
        m.layers[0].band,
        Some(HeightBand {
            centre: 0.2,
            half_width: 0.3
        })
    );
    assert!(m.triplanar);
    assert_eq!(m.layers[1].diffuse.line, 26);
    assert_eq!(m.layers[1].diffuse.key, "material.layer[1].diffuse");

    let info = scene.terrain_info().unwrap();
    let a = Appearance::load(&scene, &info).unwrap();
    let mat = a.material.as_ref().unwrap();
    assert_eq!(a.y_margin(), 4.0, "half the displacement scale");
    assert_eq!(mat.diffuse.layers, 2);
    assert_eq!(mat.diffuse.format, TexelFormat::Srgba8);
    assert_eq!(mat.diffuse.levels.len(), 9, "256x256 down to 1x1");
    assert_eq!(mat.normals.as_ref().unwrap().layers, 1);
    assert_eq!(mat.heights.as_ref().unwrap().format, TexelFormat::R8);
    assert!(mat.triplanar, "carried to the loaded material");
    assert_eq!(mat.layers[1].normal_index, Some(0));
    assert_eq!(mat.layers[0].normal_index, None);
    // 90 degrees: world x runs along -v, z along u, at 1/10 and 1/20 repeats a metre.
    let t = mat.layers[1].tile;
    let uv = t * glam::Vec2::new(10.0, 0.0);
    assert!((uv - glam::Vec2::new(0.0, -0.5)).length() < 1e-6, "{uv}");
}

#[test]
fn scene_errors_name_the_key_and_line() {
    assert_refused("[material]\nlayers = 3\n", "layers", 7, "unknown field");
    assert_refused(
        "[material]\ntriplanar = \"yes\"\n[[material.layer]]\ndiffuse = \"x.png\"\n",
        "triplanar",
        7,
        "invalid type",
    );
    let nine = "[[material.layer]]\ndiffuse = \"TEX/grass.png\"\n".repeat(9);
    assert_refused(
        &format!("[material]\n{nine}"),
        "material.layer",
        7,
        "9 layers; a material has 1 to 8",
    );
    assert_refused(
        &format!(
            "[lighting]\n{}",
            "[[lighting.light]]\ndirection = [0.0, 1.0, 0.0]\n".repeat(4)
        ),
        "lighting.light",
        7,
        "4 lights, at most 3",
    );
    assert_refused(
        "[[lighting.light]]\ndirection = [0.0, 0.0, 0.0]\n",
        "lighting.light[0].direction",
        7,
        "must be finite and not zero",
    );
    assert_refused(
        "[fog]\nstart = 1.0\nrange = 0.0\ncolor = [1.0, 1.0, 1.0]\n",
        "fog.range",
        8,
        "must be positive",
    );
    assert_refused(
        &format!("{ONE_LAYER}tile_size = -2.0\n"),
        "material.layer[0].tile_size",
        9,
        "must be positive",
    );
    assert_refused(
        &format!("{ONE_LAYER}displacement = 3.0\n"),
        "material.layer[0].displacement",
        9,
        "needs a height map",
    );
    assert_refused(
        "[material]\ncliff_layer = 4\n[[material.layer]]\ndiffuse = \"x.png\"\n",
        "material.cliff_layer",
        7,
        "layer 4 does not exist",
    );
    assert_refused(
        "[material]\nblend_maps = [\"b.png\"]\ncliff_layer = 0\n[[material.layer]]\ndiffuse = \"x.png\"\n",
        "material.cliff_layer",
        8,
        "rules-mode key",
    );
    let six = "[[material.layer]]\ndiffuse = \"x.png\"\n".repeat(6);
    assert_refused(
        &format!("[material]\nblend_maps = [\"b.png\"]\n{six}"),
        "material.blend_maps",
        7,
        "weigh at most 5 layers, but there are 6",
    );
}

fn load_error(look: &str) -> MaterialError {
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::load(&scene_in(&dir, look)).unwrap();
    let info = scene.terrain_info().unwrap();
    Appearance::load(&scene, &info).expect_err("must be refused")
}

#[test]
fn a_missing_texture_names_the_scene_line_key_and_file() {
    let err = load_error(
        "[material]\n[[material.layer]]\ndiffuse = \"TEX/grass.png\"\n[[material.layer]]\ndiffuse = \"no-such.png\"\n",
    )
    .to_string();
    assert!(
        err.contains("scene.toml:10: material.layer[1].diffuse"),
        "{err}"
    );
    assert!(
        err.contains("no-such.png") && err.contains("No such file"),
        "{err}"
    );

    // Not an image at all.
    let dir = tempfile::tempdir().unwrap();
    let junk = temp_file(&dir, "junk.png", b"not a png");
    let err = load_error(&format!(
        "[material]\n[[material.layer]]\ndiffuse = \"{}\"\n",
        junk.display()
    ))
    .to_string();
    assert!(err.contains("not a readable image"), "{err}");
}

#[test]
fn a_blend_map_of_the_wrong_size_is_refused_with_the_sizes_that_fit() {
    // 33x33 samples take 33x33, 17x17, 9x9, 5x5, 3x3 or 2x2 blend maps.
    assert_eq!(
        blend_map_sizes(33, 33),
        vec![(33, 33), (17, 17), (9, 9), (5, 5), (3, 3), (2, 2)]
    );
    assert_eq!(blend_map_sizes(403, 344), vec![(403, 344)]);
    let err = load_error(
        "[material]\nblend_maps = [\"TEX/grass.png\"]\n[[material.layer]]\ndiffuse = \"TEX/grass.png\"\n",
    );
    assert!(matches!(err, MaterialError::BlendMapSize { .. }));
    let text = err.to_string();
    assert!(
        text.contains("scene.toml:7: material.blend_maps[0]")
            && text.contains("256x256")
            && text.contains("33x33 heightmap")
            && text.contains("17x17"),
        "{text}"
    );
}

#[test]
fn the_default_scene_uses_its_blend_map_and_builds_everything_in() {
    let scene = Scene::default_scene();
    let m = scene
        .material
        .as_ref()
        .expect("the default scene has layers");
    assert_eq!(m.layers.len(), 5);
    let WeightSource::BlendMaps(maps) = &m.weights else {
        panic!("blend-map mode")
    };
    assert_eq!(maps.len(), 1);
    let mut m = m.clone();
    for asset in m.assets_mut() {
        assert!(
            matches!(asset.source, AssetSource::Embedded { .. }),
            "{}",
            asset.origin()
        );
    }
    // Within the size limits of the default assets: each at most 512x512,
    // all together at most 8 MB.
    let mut total = 0;
    for entry in std::fs::read_dir(textures_dir()).unwrap() {
        let path = entry.unwrap().path();
        total += std::fs::metadata(&path).unwrap().len();
        let (w, h) = image::image_dimensions(&path).unwrap();
        let blend = path.ends_with("default-blend.png");
        assert!(blend || (w <= 512 && h <= 512), "{}", path.display());
    }
    assert!(total <= 8 << 20, "{total} bytes of textures");
    let info = scene.terrain_info().unwrap();
    let a = Appearance::load(&scene, &info).unwrap();
    assert!(a.lightmap.is_some());
    let blend = a.material.unwrap().blend_maps.unwrap();
    assert_eq!((blend.width, blend.height, blend.layers), (513, 513, 1));
}

#[test]
fn rules_weights_sum_to_one_and_cliffs_turn_to_the_cliff_layer() {
    let rules = Rules {
        bands: vec![
            Some(HeightBand {
                centre: 0.0,
                half_width: 0.2,
            }),
            Some(HeightBand {
                centre: 0.3,
                half_width: 0.25,
            }),
            None,
            Some(HeightBand {
                centre: 0.9,
                half_width: 0.25,
            }),
        ],
        cliff: Some(Cliff {
            layer: 2,
            slope_deg: [30.0, 45.0],
        }),
    };
    for h in [-0.5f32, 0.0, 0.1, 0.3, 0.5, 0.62, 0.9, 1.0, 2.0] {
        for ny in [1.0f32, 0.9, 0.8, 0.7, 0.5, 0.0] {
            let w = rules.weights(h, ny);
            let sum: f32 = w.iter().sum();
            assert!((sum - 1.0).abs() < 1e-5, "h {h} ny {ny}: {w:?}");
            assert!(w.iter().all(|&x| x >= 0.0));
        }
    }
    // Flat ground at a band's centre is that band's alone.
    assert_eq!(rules.weights(0.0, 1.0)[0], 1.0);
    // Between bands no band reaches (0.62): all on the base layer.
    assert_eq!(rules.weights(0.62, 1.0)[0], 1.0);
    // Steeper than 45 degrees is all rock; 30 degrees none.
    assert_eq!(rules.weights(0.3, 45f32.to_radians().cos() - 1e-4)[2], 1.0);
    assert!(rules.weights(0.3, 30f32.to_radians().cos() + 1e-4)[2] < 1e-6);

    // Blend values reproduce the weights through the blend maps' layering.
    let w = rules.weights(0.2, 0.8);
    let back = blend_map_weights(&blend_values(&w, 4), 4);
    for (a, b) in w.iter().zip(back) {
        assert!((a - b).abs() < 1e-6);
    }
}

#[test]
fn blend_maps_baked_from_rules_hold_the_rules_weights() {
    let dem = dem_info(32);
    let rules = Rules {
        bands: vec![
            Some(HeightBand {
                centre: 0.2,
                half_width: 0.3,
            }),
            Some(HeightBand {
                centre: 0.6,
                half_width: 0.3,
            }),
            Some(HeightBand {
                centre: 1.0,
                half_width: 0.2,
            }),
        ],
        cliff: Some(Cliff {
            layer: 1,
            slope_deg: [10.0, 20.0],
        }),
    };
    let maps = blend_maps_from_rules(&dem, &rules, 3, 1);
    assert_eq!(maps.len(), 1);
    assert_eq!(maps[0].dimensions(), (403, 344));
    let (lo, hi) = dem.min_max();
    for (r, c) in [(0, 0), (343, 402), (100, 200), (200, 37)] {
        let p: DVec2 = dem.sample_position(r, c);
        let n = dem.normal_at(p.x, p.y);
        let h = (dem.whole().get(r, c) - lo) / (hi - lo);
        let want = rules.weights(h, n.y);
        let px = maps[0].get_pixel(c as u32, r as u32).0;
        let blend = [px[0], px[1], px[2], px[3], 0, 0, 0].map(|v| f32::from(v) / 255.0);
        let got = blend_map_weights(&blend, 3);
        for k in 0..3 {
            assert!(
                (got[k] - want[k]).abs() < 0.01,
                "({r}, {c}) layer {k}: {got:?} vs {want:?}"
            );
        }
    }
}

#[test]
fn displacement_widens_the_y_bounds_by_the_largest_half_scale() {
    assert_eq!(max_displacement(&[]), 0.0);
    assert_eq!(max_displacement(&[2.0, -10.0, 4.0]), 5.0);
    let info = dem_info(32);
    let plain = Terrain::new(info.clone(), 0.0).unwrap();
    let widened = Terrain::new(info, 5.0).unwrap();
    for (a, b) in plain.y_bounds().iter().zip(widened.y_bounds()) {
        assert_eq!((b[0], b[1]), (a[0] - 5.0, a[1] + 5.0));
    }
}

/// A 65x65 plane at height 0 with a 100 m wall along column 40.
fn wall() -> TerrainInfo {
    let map = Heightmap::from_fn(65, 65, |_, c| if c == 40 { 100.0 } else { 0.0 }).unwrap();
    TerrainInfo::new(map, DVec2::splat(10.0), 16, DVec2::ZERO).unwrap()
}

#[test]
fn the_lightmap_shadows_the_lee_of_a_wall_and_nothing_else() {
    let info = wall();
    // Sun low in the +x direction at 45 degrees: the wall (column 40) hides
    // it from the ground just west of it, up to its height away (10 cells).
    let lit = bake_lightmap(&info, DVec3::new(1.0, 1.0, 0.0));
    let at = |r: usize, c: usize| lit[r * 65 + c];
    assert_eq!(at(32, 20), 255, "far west of the wall");
    assert_eq!(at(32, 35), 0, "5 cells west, behind the wall");
    assert_eq!(at(32, 45), 255, "east of the wall, facing the sun");
    assert_eq!(at(32, 40), 255, "the wall's top");
    // Overhead: nothing is shadowed.
    assert!(bake_lightmap(&info, DVec3::Y).iter().all(|&v| v == 255));
    // Sun from -x: now the east side is in shadow.
    let other = bake_lightmap(&info, DVec3::new(-1.0, 1.0, 0.0));
    assert_eq!(other[32 * 65 + 45], 0);
    assert_eq!(other[32 * 65 + 35], 255);
}

#[test]
fn the_committed_textures_and_blend_map_are_what_the_generators_make() {
    let pixels = |path: &Path| image::open(path).unwrap().to_rgba8();
    for layer in vkterrain::appearance::generate::layer_textures(256) {
        for (suffix, made) in [
            ("", image::DynamicImage::ImageRgb8(layer.diffuse)),
            ("-normal", image::DynamicImage::ImageRgb8(layer.normal)),
            ("-height", image::DynamicImage::ImageLuma8(layer.height)),
        ] {
            let path = textures_dir().join(format!("{}{suffix}.png", layer.name));
            assert!(
                pixels(&path) == made.to_rgba8(),
                "{} differs from the generator's",
                path.display()
            );
        }
    }
    let rules =
        Scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes/rules.toml"))
            .unwrap();
    let m = rules.material.as_ref().unwrap();
    let WeightSource::Rules { cliff } = m.weights else {
        panic!("rules mode")
    };
    let cpu = Rules {
        bands: m.layers.iter().map(|l| l.band).collect(),
        cliff,
    };
    let made = blend_maps_from_rules(&rules.terrain_info().unwrap(), &cpu, m.layers.len(), 2);
    assert!(pixels(&textures_dir().join("default-blend.png")) == made[0]);
}

#[test]
fn maps_without_the_channels_they_need_are_refused() {
    // A grayscale image as a normal map.
    let err = load_error(
        "[material]\n[[material.layer]]\ndiffuse = \"TEX/grass.png\"\nnormal = \"TEX/grass-height.png\"\n",
    )
    .to_string();
    assert!(
        err.contains("material.layer[0].normal") && err.contains("has no colour channels"),
        "{err}"
    );
    // An RGB blend map for five layers: layer 4 would read alpha as 1.
    let dir = tempfile::tempdir().unwrap();
    let rgb = image::RgbImage::from_pixel(33, 33, image::Rgb([0, 0, 0]));
    let path = dir.path().join("rgb.png");
    rgb.save(&path).unwrap();
    let five = "[[material.layer]]\ndiffuse = \"TEX/grass.png\"\n".repeat(5);
    let err = load_error(&format!(
        "[material]\nblend_maps = [\"{}\"]\n{five}",
        path.display()
    ))
    .to_string();
    assert!(
        err.contains("has no alpha channel, which weighs layer 4"),
        "{err}"
    );
    // With four layers alpha is unused and RGB is fine.
    let four = "[[material.layer]]\ndiffuse = \"TEX/grass.png\"\n".repeat(4);
    let scene_dir = tempfile::tempdir().unwrap();
    let scene = Scene::load(&scene_in(
        &scene_dir,
        &format!("[material]\nblend_maps = [\"{}\"]\n{four}", path.display()),
    ))
    .unwrap();
    Appearance::load(&scene, &scene.terrain_info().unwrap()).unwrap();
}

/// The lightmap cache gives back exactly what the bake gives, and a
/// missing, truncated or foreign entry is baked again, never trusted.
#[test]
fn the_lightmap_cache_returns_the_bake_and_survives_bad_entries() {
    let info =
        TerrainInfo::new(noise_map(65, 49, 3), DVec2::new(4.0, 3.0), 16, DVec2::ZERO).unwrap();
    let sun = glam::DVec3::new(0.6, 0.5, -0.3);
    let baked = vkterrain::terrain::shading::bake_lightmap(&info, sun);
    let dir = tempfile::tempdir().unwrap();
    let cached =
        |d: Option<&std::path::Path>| vkterrain::appearance::cached_lightmap(d, &info, sun);
    assert_eq!(cached(None), baked, "without a cache directory");
    assert_eq!(cached(Some(dir.path())), baked, "first launch: baked");
    let entries: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(entries.len(), 1, "{entries:?}");
    let entry = &entries[0];
    assert_eq!(
        std::fs::metadata(entry).unwrap().len(),
        24 + baked.len() as u64
    );
    assert_eq!(cached(Some(dir.path())), baked, "second launch: cached");
    // Truncated, then another format's bytes: baked again and rewritten.
    let full = std::fs::read(entry).unwrap();
    for bad in [
        full[..full.len() / 2].to_vec(),
        [b"NOTOURS!".to_vec(), full[8..].to_vec()].concat(),
    ] {
        std::fs::write(entry, &bad).unwrap();
        assert_eq!(cached(Some(dir.path())), baked);
        assert_eq!(
            std::fs::read(entry).unwrap(),
            full,
            "the entry is rewritten"
        );
    }
    // Another sun is another entry.
    let other = glam::DVec3::new(-0.6, 0.5, 0.3);
    assert_eq!(
        vkterrain::appearance::cached_lightmap(Some(dir.path()), &info, other),
        vkterrain::terrain::shading::bake_lightmap(&info, other)
    );
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
}
