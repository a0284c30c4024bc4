//! `vkterrain import`: a heightmap, or a mosaic of SRTM tiles, to a tiled
//! terrain that every `--heightmap` opens.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result};

use super::args::SampleArgs;
use crate::output::write_atomically;
use crate::terrain::grid::validate_cells_per_patch;
use crate::terrain::heightmap::{LoadOptions, DEFAULT_MAX_SAMPLES};
use crate::terrain::info::stored_cells_per_patch;
use crate::terrain::tiled::{self, SourceKind, DEFAULT_TILE_CELLS};

#[derive(clap::Args, Debug)]
pub struct ImportCmd {
    /// A heightmap file (any format `--heightmap` reads), or SRTM .hgt
    /// tiles named by their south-west corner (N37W119.hgt) and
    /// directories of them, mosaicked into one terrain.
    #[arg(value_name = "INPUT", required = true, num_args = 1..)]
    pub inputs: Vec<PathBuf>,

    /// Where to write the tiled terrain.
    #[arg(long, value_name = "PATH")]
    pub out: PathBuf,

    /// Cells per tile side: a power of two from 2 to 4096.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_TILE_CELLS)]
    pub tile: u32,

    /// Store the error tables of patches this size, so that a terrain
    /// loaded with it starts without rebuilding them (when tiles hold a
    /// whole number of such patches) [default: 32, or 64 past 8193
    /// samples a side].
    #[arg(long, value_name = "N")]
    pub cells_per_patch: Option<u32>,

    #[command(flatten)]
    pub samples: SampleArgs,

    /// Accept colour PNGs by converting them to luminance (loaded whole).
    #[arg(long)]
    pub luminance: bool,

    /// Largest input, in samples, loaded whole (colour or interlaced PNGs,
    /// a single .hgt); streamed inputs have no limit.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_SAMPLES)]
    pub max_samples: u64,
}

pub fn import(cmd: ImportCmd, out: &mut dyn Write) -> Result<()> {
    tiled::validate_tile_cells(cmd.tile)?;
    if let Some(n) = cmd.cells_per_patch {
        validate_cells_per_patch(n)?;
    }
    let mut opts = LoadOptions {
        luminance: cmd.luminance,
        max_samples: cmd.max_samples,
        ..LoadOptions::default()
    };
    cmd.samples.apply(&mut opts);
    let (mut source, kind) = tiled::open_source(&cmd.inputs, &opts)?;
    let cells_per_patch = cmd
        .cells_per_patch
        .unwrap_or_else(|| stored_cells_per_patch(source.width(), source.depth()));
    let bar = super::progress::progress_bar(source.depth() as u64, "rows");
    let mut report = None;
    write_atomically(&cmd.out, |tmp| {
        let written = tiled::import(
            source.as_mut(),
            cmd.tile,
            Some(cells_per_patch),
            tmp,
            &mut |done, _| bar.set_position(done),
        )
        .with_context(|| format!("{}: import failed", cmd.out.display()))?;
        report = Some(written);
        Ok(())
    })?;
    bar.finish_and_clear();
    let report = report.expect("written");
    #[derive(serde::Serialize)]
    struct Output<'a> {
        out: &'a std::path::Path,
        read: &'static str,
        #[serde(flatten)]
        report: tiled::ImportReport,
    }
    serde_json::to_writer_pretty(
        &mut *out,
        &Output {
            out: &cmd.out,
            read: match kind {
                SourceKind::Streamed => "streamed by rows",
                SourceKind::Whole => "loaded whole",
                SourceKind::SrtmMosaic => "SRTM mosaic, one row of tiles at a time",
            },
            report,
        },
    )?;
    writeln!(out)?;
    Ok(())
}
