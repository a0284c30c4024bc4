//! `generate-textures` and `generate-blend-map`: the default scene's layer
//! textures and blend map, rebuilt bit for bit.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use super::args::TerrainArgs;
use crate::appearance::blend_map_sizes;
use crate::appearance::generate::{blend_maps_from_rules, layer_textures};
use crate::output::write_atomically;
use crate::scene::WeightSource;
use crate::terrain::shading::Rules;

#[derive(clap::Args, Debug)]
pub struct GenerateTexturesCmd {
    /// Texels per side of each texture (a power of two from 16 to 512).
    #[arg(long, default_value_t = 256)]
    pub size: u32,
    /// Directory to write NAME.png, NAME-normal.png and NAME-height.png
    /// into, for sand, grass, dirt, rock and snow.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

fn save(image: &image::DynamicImage, path: &std::path::Path) -> Result<()> {
    write_atomically(path, |tmp| {
        image
            .save_with_format(tmp, image::ImageFormat::Png)
            .with_context(|| format!("{}: cannot write PNG", path.display()))
    })
}

pub fn generate_textures(cmd: GenerateTexturesCmd, out: &mut dyn Write) -> Result<()> {
    if !(16..=512).contains(&cmd.size) || !cmd.size.is_power_of_two() {
        bail!("--size {} must be a power of two from 16 to 512", cmd.size);
    }
    std::fs::create_dir_all(&cmd.out)
        .with_context(|| format!("{}: cannot create the directory", cmd.out.display()))?;
    for layer in layer_textures(cmd.size) {
        for (suffix, image) in [
            ("", image::DynamicImage::ImageRgb8(layer.diffuse)),
            ("-normal", image::DynamicImage::ImageRgb8(layer.normal)),
            ("-height", image::DynamicImage::ImageLuma8(layer.height)),
        ] {
            let path = cmd.out.join(format!("{}{suffix}.png", layer.name));
            save(&image, &path)?;
            writeln!(out, "wrote {}", path.display())?;
        }
    }
    Ok(())
}

#[derive(clap::Args, Debug)]
pub struct GenerateBlendMapCmd {
    /// A rules-mode scene: its heightmap, layers, height bands and cliff.
    #[command(flatten)]
    pub terrain: TerrainArgs,
    /// One texel every STEP samples (a power of two that divides the cells).
    #[arg(long, default_value_t = 1)]
    pub step: usize,
    /// Where to write the first blend map; a second (layers 5..7) gets
    /// "-2" before the extension.
    #[arg(long, value_name = "PATH")]
    pub out: PathBuf,
}

pub fn generate_blend_map(cmd: GenerateBlendMapCmd, out: &mut dyn Write) -> Result<()> {
    let scene = cmd.terrain.scene()?;
    let Some(material) = &scene.material else {
        bail!("the scene has no [material] to bake into a blend map");
    };
    let WeightSource::Rules { cliff } = material.weights else {
        bail!("the scene already weighs its layers with blend maps; give a rules-mode scene");
    };
    let info = scene.terrain_info()?;
    let sizes = blend_map_sizes(info.cols(), info.rows());
    let k = cmd.step.trailing_zeros() as usize;
    if !cmd.step.is_power_of_two() || k >= sizes.len() {
        bail!(
            "--step {} does not divide the {}x{} heightmap's cells into a power-of-two grid (sizes: {:?})",
            cmd.step,
            info.cols(),
            info.rows(),
            sizes
        );
    }
    let rules = Rules {
        bands: material.layers.iter().map(|l| l.band).collect(),
        cliff,
    };
    let maps = blend_maps_from_rules(&info, &rules, material.layers.len(), cmd.step);
    for (i, map) in maps.into_iter().enumerate() {
        let path = if i == 0 {
            cmd.out.clone()
        } else {
            let stem = cmd.out.file_stem().unwrap_or_default().to_string_lossy();
            cmd.out.with_file_name(format!("{stem}-{}.png", i + 1))
        };
        let (w, h) = map.dimensions();
        save(&image::DynamicImage::ImageRgba8(map), &path)?;
        writeln!(out, "wrote {} ({w}x{h})", path.display())?;
    }
    Ok(())
}
