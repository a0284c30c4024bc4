//! Heights streamed from a tiled terrain file (`terrain::tiled`) to the
//! GPU, within a memory budget. The shaders read them through an
//! indirection this module owns (glsl/terrain_common.glsl `fetch_sample`):
//!
//! - a **page pool**: an array image of `tile_cells + 1` square layers,
//!   one page each (`residency`): a block of `2^L x 2^L` tiles at level L
//!   (every `2^L`-th sample). The first layers hold the **base level**'s
//!   pages, uploaded at the start and always resident; the rest take
//!   streamed pages of the finer levels, down to single tiles at full
//!   resolution;
//! - a **page table** per frame in flight: per tile, the finest resident
//!   page over it (its level and layer), the base page where none is.
//!
//! Which pages are resident is `residency`'s policy. Pages are read (a
//! level-L page from its tiles' stored level L) and put together on
//! background threads; each frame takes what has arrived (up to
//! `upload_bytes_per_frame`), copies it into a staging buffer of its own,
//! and records the copies into the pool before its draws. A swap happens
//! within one frame: the new table and the new layer contents arrive
//! together, and a barrier keeps the copy after earlier frames' reads. A
//! frame never waits on disk; a one-shot render calls `settle`, which does.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use ash::vk;
use glam::Vec3;

use super::residency::{entry_level, Load, Residency, StreamShape};
use super::stream_budget::{
    coarsest_base, headroom, plan_stream_memory, StreamMemory, MIN_POOL_LAYERS_PER_LEVEL,
};
use super::view::FrameView;
use crate::gpu::commands::Recorder;
use crate::gpu::descriptors::DescriptorSet;
use crate::gpu::memory::{Buffer, Image};
use crate::gpu::owned::Sampler;
use crate::gpu::transfer::LayerCopy;
use crate::gpu::{Device, VkError};
use crate::render::error::{RenderError, Result};
use crate::shader_constants::{BINDING_PAGES, BINDING_PAGE_TABLE, PAGE_LEVEL_SHIFT};
use crate::terrain::tiled::{TiledError, TiledHeightmap};
use crate::terrain::TerrainInfo;

/// Samples a side of the base level may have at most, by default: 2049^2
/// f32 is 16 MiB.
pub const DEFAULT_BASE_MAX_SIDE: u32 = 2049;
/// Bytes of pages one frame uploads at most, by default.
pub const DEFAULT_UPLOAD_BYTES_PER_FRAME: u64 = 8 << 20;
/// Threads reading pages, by default.
pub const DEFAULT_LOADER_THREADS: usize = 2;
/// Where a streamed terrain comes from and how it streams.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StreamConfig {
    /// The tiled terrain file.
    pub path: PathBuf,
    /// Largest side of the always-resident base level, in samples.
    pub base_max_side: u32,
    /// Bytes of pages one frame uploads at most.
    pub upload_bytes_per_frame: u64,
    pub loader_threads: usize,
    /// Layers of the page pool; by default as many as there are pages (or
    /// the device allows), fewer where the memory budget says so.
    pub layers: Option<u32>,
}

impl StreamConfig {
    pub fn new(path: PathBuf) -> Self {
        StreamConfig {
            path,
            base_max_side: DEFAULT_BASE_MAX_SIDE,
            upload_bytes_per_frame: DEFAULT_UPLOAD_BYTES_PER_FRAME,
            loader_threads: DEFAULT_LOADER_THREADS,
            layers: None,
        }
    }

    /// This configuration with `shape`'s base level, a coarser one than
    /// it chooses itself.
    pub fn with_base(&self, shape: &StreamShape) -> Self {
        let (w, h) = shape.base_size();
        StreamConfig {
            base_max_side: w.max(h),
            ..self.clone()
        }
    }

    /// The smallest layout of `tiled` under this configuration: the base
    /// level (this one's or coarser) whose pages and
    /// `MIN_POOL_LAYERS_PER_LEVEL` pool layers for each finer level are
    /// fewest, and one page of staging a frame.
    pub fn smallest(&self, tiled: &TiledHeightmap, cells_per_patch: u32) -> Self {
        let preferred = self.shape(tiled);
        let layers = |level: u32| MIN_POOL_LAYERS_PER_LEVEL * level;
        let shape = (preferred.base_level..=coarsest_base(&preferred, cells_per_patch))
            .map(|base_level| StreamShape {
                base_level,
                ..preferred
            })
            .min_by_key(|s| s.base_pages() + layers(s.base_level))
            .unwrap_or(preferred);
        StreamConfig {
            layers: Some(layers(shape.base_level)),
            upload_bytes_per_frame: 0,
            ..self.with_base(&shape)
        }
    }

    /// How `tiled` (the file at `path`) streams under this configuration.
    pub fn shape(&self, tiled: &TiledHeightmap) -> StreamShape {
        StreamShape::new(
            tiled.width() as u32,
            tiled.depth() as u32,
            tiled.header().tile_cells,
            self.base_max_side,
        )
    }
}

/// What streaming did in one frame, and where it stands.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StreamStats {
    /// Pages uploaded by this frame and their bytes.
    pub uploaded_pages: u32,
    pub upload_bytes: u64,
    /// Pages this frame's uploads evicted.
    pub evicted_pages: u32,
    /// The largest change this frame's uploads and evictions made on
    /// screen, at most, in pixels: over each tile whose drawn level
    /// changed, the two levels' errors added, seen from the view.
    pub pop_px: f32,
    /// Streamed pages resident after this frame, and the pool's layers
    /// for them; the base level's pages, always resident, besides.
    pub resident_pages: u32,
    pub layers: u32,
    pub base_pages: u32,
    /// Reads in flight and pages read but not uploaded yet.
    pub loads_in_flight: u32,
    pub waiting_uploads: u32,
    /// The largest error, in pixels, of a tile in view drawn coarser than
    /// full resolution: its drawn level's error seen from the view (0:
    /// everything in view is drawn exactly).
    pub missing_px: f32,
}

/// A page read from disk: its samples, row-major.
type Loaded = (Load, std::result::Result<Vec<f32>, TiledError>);

/// Background threads reading pages in the order asked.
struct Loader {
    requests: Option<Sender<Load>>,
    results: Receiver<Loaded>,
    threads: Vec<JoinHandle<()>>,
}

impl Loader {
    fn new(reader: &Arc<TiledHeightmap>, shape: StreamShape, threads: usize) -> Result<Self> {
        let (requests, jobs) = mpsc::channel::<Load>();
        let jobs = Arc::new(Mutex::new(jobs));
        let (done, results) = mpsc::channel();
        let mut handles = Vec::new();
        for i in 0..threads.max(1) {
            // The threads share one reader: only its seek and read are
            // locked, checking and decoding are not. Pages go to the GPU,
            // so no tile is kept in the reader's cache.
            let reader = Arc::clone(reader);
            let (jobs, done) = (Arc::clone(&jobs), done.clone());
            let handle = std::thread::Builder::new()
                .name(format!("page-loader-{i}"))
                .spawn(move || loop {
                    let next = jobs.lock().map(|j| j.recv());
                    let Ok(Ok(load)) = next else { break };
                    let page = read_page(&reader, &shape, shape.page_coords(load.page));
                    if done.send((load, page)).is_err() {
                        break;
                    }
                })
                .map_err(|e| RenderError::Stream(format!("starting a page loader: {e}")))?;
            handles.push(handle);
        }
        Ok(Loader {
            requests: Some(requests),
            results,
            threads: handles,
        })
    }

    fn request(&self, load: Load) -> Result<()> {
        self.requests
            .as_ref()
            .and_then(|r| r.send(load).ok())
            .ok_or_else(|| RenderError::Stream("the page loaders stopped".into()))
    }
}

impl Drop for Loader {
    fn drop(&mut self) {
        // Closing the queue ends each thread after its current read.
        self.requests = None;
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

/// The streamed heights on the GPU and the residency behind them.
pub struct Streamer {
    shape: StreamShape,
    residency: Residency,
    /// Per tile, per level from full resolution to the base: the level's
    /// error against full resolution (`tiled::Entry::error`).
    tile_errors: Vec<f32>,
    /// Per page: the error of drawing its area one level coarser (the
    /// largest over its tiles), and its box in terrain-local coordinates
    /// (centre, half extents).
    coarser_errors: Vec<f32>,
    boxes: Vec<(Vec3, Vec3)>,
    /// The pool: the base pages, then the layers `residency` fills.
    pool: Image,
    /// Per frame slot: the page table it draws with, the staging buffer
    /// its uploads come from, and the copies `record` makes.
    tables: Vec<Buffer>,
    staging: Vec<Buffer>,
    copies: Vec<Vec<LayerCopy>>,
    loader: Loader,
    /// Pages read and waiting for a frame to upload them.
    arrived: VecDeque<(Load, Vec<f32>)>,
    /// Loads a frame's `prepare` asked for, not yet handed to the loaders
    /// (`dispatch`).
    unsent: Vec<Load>,
    /// The page table the last prepared frame draws with: per tile, the
    /// page it is drawn from (`StreamShape::page_table`).
    table: Vec<u32>,
    stats: StreamStats,
    device: Device,
}

impl Streamer {
    /// How `tiled` (`config.path`) fits on `device` beside what is already
    /// allocated, for `frames` frames in flight: its base level, pool and
    /// staging (`plan_stream_memory`) under the memory budget. Where
    /// nothing fits the budget, an `OverBudget` error for the stream's
    /// smallest layout.
    pub fn plan(
        device: &Device,
        (config, cells_per_patch): (&StreamConfig, u32),
        tiled: &TiledHeightmap,
        frames: usize,
    ) -> Result<StreamMemory> {
        let device_layers = device
            .caps
            .max_image_array_layers
            .min(1 << PAGE_LEVEL_SHIFT);
        let in_use = device.memory_in_use();
        let budget = device.memory_budget();
        let room = budget.map(|b| b.saturating_sub(in_use + headroom(b)));
        let preferred = config.shape(tiled);
        let side = preferred.page_side();
        plan_stream_memory(
            preferred,
            (config.layers, config.upload_bytes_per_frame),
            frames,
            (device_layers, &|n| device.layer_pool_bytes(side, n)),
            (room, coarsest_base(&preferred, cells_per_patch)),
        )
        .map_err(|least| match (budget, least) {
            (Some(budget), Some(least)) => RenderError::Vk(VkError::OverBudget {
                name: "terrain.stream (its smallest layout)".into(),
                requested: least + headroom(budget),
                in_use,
                budget,
            }),
            _ => RenderError::Stream(format!(
                "{}: its coarsest base level takes {} pages of {side}x{side} samples, and the \
                 device allows {device_layers} layers in all; import it with larger tiles (--tile)",
                config.path.display(),
                StreamShape {
                    base_level: coarsest_base(&preferred, cells_per_patch),
                    ..preferred
                }
                .base_pages(),
            )),
        })
    }

    /// Streams `tiled` (`config.path`, opened) for a terrain whose CPU
    /// model is `info`, laid out as `memory` (`Streamer::plan`): makes the
    /// pool and uploads the base level into it, for `frames` frames in
    /// flight.
    pub fn new(
        device: &Device,
        info: &TerrainInfo,
        (config, memory): (&StreamConfig, StreamMemory),
        tiled: Arc<TiledHeightmap>,
        frames: usize,
    ) -> Result<Self> {
        if (tiled.width(), tiled.depth()) != (info.cols(), info.rows()) {
            return Err(RenderError::Stream(format!(
                "{} holds {}x{} samples, the terrain drawn {}x{}",
                config.path.display(),
                tiled.width(),
                tiled.depth(),
                info.cols(),
                info.rows()
            )));
        }
        let shape = memory.shape;
        let levels = shape.base_level + 1;
        let mut tile_errors = Vec::with_capacity(shape.tile_total() * levels as usize);
        let mut tile_boxes = Vec::with_capacity(shape.tile_total());
        for tz in 0..shape.tiles_z {
            for tx in 0..shape.tiles_x {
                tile_errors.extend((0..levels).map(|l| tiled.entry(tx, tz, l).error));
                let full = tiled.entry(tx, tz, 0);
                let ((c0, r0), (w, d)) = shape.tile_rect(tx, tz);
                let lo = Vec3::new(
                    info.local_x(c0 as usize) as f32,
                    full.min,
                    info.local_z((r0 + d) as usize) as f32,
                );
                let hi = Vec3::new(
                    info.local_x((c0 + w) as usize) as f32,
                    full.max,
                    info.local_z(r0 as usize) as f32,
                );
                tile_boxes.push((lo, hi));
            }
        }
        // A page's box holds its tiles' boxes: every level's surface lies
        // within its full-resolution samples' range.
        let (mut coarser_errors, mut boxes) = (Vec::new(), Vec::new());
        for page in 0..shape.page_total() {
            let (level, px, pz) = shape.page_coords(page);
            let coarser = (level + 1).min(shape.base_level);
            let (xs, zs) = shape.page_tiles(level, px, pz);
            let (mut error, mut lo, mut hi) = (0f32, Vec3::MAX, Vec3::MIN);
            for tz in zs {
                for tx in xs.clone() {
                    let t = shape.tile_index(tx, tz);
                    error = error.max(tile_errors[t * levels as usize + coarser as usize]);
                    lo = lo.min(tile_boxes[t].0);
                    hi = hi.max(tile_boxes[t].1);
                }
            }
            coarser_errors.push(error);
            boxes.push((0.5 * (lo + hi), 0.5 * (hi - lo)));
        }
        let side = shape.page_side();
        let staging_bytes = memory.staging_bytes;
        let pages = shape.page_total();
        let mut staging = Vec::new();
        let mut tables = Vec::new();
        for i in 0..frames {
            staging.push(device.create_host_buffer(
                &format!("terrain.stream.staging[{i}]"),
                vk::BufferUsageFlags::TRANSFER_SRC,
                &vec![0u8; staging_bytes as usize],
            )?);
            tables.push(device.create_host_buffer(
                &format!("terrain.stream.page_table[{i}]"),
                vk::BufferUsageFlags::STORAGE_BUFFER,
                // Written by each frame's `prepare` before it draws.
                bytemuck::cast_slice(&vec![0u32; shape.tile_total()]),
            )?);
        }
        let (base_pages, layers) = (shape.base_pages(), memory.layers);
        let pool = device.create_layer_pool("terrain.stream.pages", side, base_pages + layers)?;
        upload_base(device, &tiled, &shape, &pool, &mut staging[0])?;
        let residency = Residency::new(pages, layers);
        // Nothing streamed is resident yet: every tile draws its base page.
        let mut table = vec![0; shape.tile_total()];
        shape.page_table(residency.page_layers(), &mut table);
        Ok(Streamer {
            shape,
            residency,
            tile_errors,
            coarser_errors,
            boxes,
            pool,
            tables,
            staging,
            copies: vec![Vec::new(); frames],
            unsent: Vec::new(),
            loader: Loader::new(&tiled, shape, config.loader_threads)?,
            arrived: VecDeque::new(),
            table,
            stats: StreamStats::default(),
            device: device.clone(),
        })
    }

    /// How the terrain streams: its tiles, pages and base level.
    pub fn shape(&self) -> StreamShape {
        self.shape
    }

    /// Points slot `slot`'s set at the pool and its page table.
    pub fn write_bindings(&self, set: DescriptorSet, slot: usize, sampler: &Sampler) {
        let table = &self.tables[slot];
        self.device
            .write_sampled_image(set, BINDING_PAGES, &self.pool, sampler);
        self.device.write_buffer(
            set,
            BINDING_PAGE_TABLE,
            vk::DescriptorType::STORAGE_BUFFER,
            table,
            table.desc.size,
        );
    }

    /// What the last prepared frame did.
    pub fn stats(&self) -> StreamStats {
        self.stats
    }

    /// Per page, what a metre of height error is seen as from `view`, in
    /// pixels: over its box's distance (at least the near plane's); 0
    /// outside the frustum. Level 0's entries are the tiles'.
    fn scales(&self, view: &FrameView) -> Vec<f32> {
        self.boxes
            .iter()
            .map(|&(centre, extents)| {
                let rel = centre - view.eye_local;
                if view.frustum.aabb_outside(rel, extents) {
                    return 0.0;
                }
                // Nothing nearer than the near plane is drawn: from inside
                // a page's box the error is seen from there at the nearest.
                let d = (rel.abs() - extents).max(Vec3::ZERO).length();
                view.pixels_per_radian / d.max(view.near)
            })
            .collect()
    }

    /// Each page's priority at `scales`: the error, in pixels, of drawing
    /// its area one level coarser.
    fn priorities(&self, scales: &[f32]) -> Vec<f32> {
        scales
            .iter()
            .zip(&self.coarser_errors)
            .map(|(&scale, &error)| scale * error)
            .collect()
    }

    /// Tile `tile`'s error at `level` against full resolution, in metres.
    fn tile_error(&self, tile: usize, level: u32) -> f32 {
        self.tile_errors[tile * (self.shape.base_level as usize + 1) + level as usize]
    }

    /// The level tile `tile` is drawn at now.
    fn drawn_level(&self, tile: usize) -> u32 {
        self.shape.drawn_level(
            |p| self.residency.is_resident(p),
            self.shape.tile_coords(tile),
        )
    }

    /// The largest error, in pixels, a tile in view is drawn with, at the
    /// level the page table (`self.table`, up to date) draws it.
    fn missing_px(&self, scales: &[f32]) -> f32 {
        if self.shape.page_levels() == 0 {
            // The base level is full resolution: nothing streams, and
            // `scales` (one a streamed page) is empty.
            return 0.0;
        }
        self.table
            .iter()
            .enumerate()
            .filter(|&(t, _)| scales[t] > 0.0)
            .map(|(t, &entry)| self.tile_error(t, entry_level(entry)) * scales[t])
            .fold(0.0, f32::max)
    }

    /// Takes what the loaders finished, without waiting (with `wait`,
    /// waits up to that long for the first).
    fn collect(&mut self, wait: Option<Duration>) -> Result<()> {
        let mut next = match wait {
            Some(timeout) => match self.loader.results.recv_timeout(timeout) {
                Ok(r) => Some(r),
                Err(RecvTimeoutError::Timeout) => None,
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(RenderError::Stream("the page loaders stopped".into()))
                }
            },
            None => self.loader.results.try_recv().ok(),
        };
        while let Some((load, page)) = next {
            match page {
                Ok(heights) => self.arrived.push_back((load, heights)),
                Err(e) => {
                    self.residency.cancelled(load);
                    return Err(RenderError::Stream(e.to_string()));
                }
            }
            next = self.loader.results.try_recv().ok();
        }
        Ok(())
    }

    /// Makes `load` resident, and returns the largest change it makes on
    /// screen at `scales`, at most, in pixels: over the tiles of the page
    /// it brings and of the page it evicts, where a tile's drawn level
    /// changes, the two levels' errors added.
    fn make_resident(&mut self, load: Load, scales: &[f32]) -> (Option<usize>, f32) {
        let mut tiles = Vec::new();
        let evicting = self.residency.page_in_layer(load.layer);
        for page in std::iter::once(load.page).chain(evicting) {
            let (level, px, pz) = self.shape.page_coords(page);
            let (xs, zs) = self.shape.page_tiles(level, px, pz);
            for tz in zs {
                tiles.extend(xs.clone().map(|tx| self.shape.tile_index(tx, tz)));
            }
        }
        let before: Vec<u32> = tiles.iter().map(|&t| self.drawn_level(t)).collect();
        let evicted = self.residency.arrived(load);
        let pop = tiles
            .iter()
            .zip(before)
            .filter(|&(&t, was)| self.drawn_level(t) != was)
            .map(|(&t, was)| {
                (self.tile_error(t, was) + self.tile_error(t, self.drawn_level(t))) * scales[t]
            })
            .fold(0.0, f32::max);
        (evicted, pop)
    }

    /// Places arrived pages into slot `slot`'s staging buffer while they
    /// fit, updating the residency, and returns the copies to record.
    fn stage(&mut self, slot: usize, scales: &[f32]) -> Result<Vec<LayerCopy>> {
        let mut copies = Vec::new();
        let capacity = self.staging[slot].desc.size;
        let mut offset = 0u64;
        while let Some((load, heights)) = self.arrived.pop_front() {
            let bytes = 4 * heights.len() as u64;
            if offset + bytes > capacity {
                self.arrived.push_front((load, heights));
                break;
            }
            let staging = self.staging[slot]
                .mapped_mut()
                .ok_or(RenderError::NotMapped("staging memory"))?;
            let (level, px, pz) = self.shape.page_coords(load.page);
            copies.push(stage_page(
                staging,
                offset,
                &heights,
                self.shape.base_pages() + load.layer,
                self.shape.page_size(level, px, pz),
            ));
            let (evicted, pop) = self.make_resident(load, scales);
            self.stats.uploaded_pages += 1;
            self.stats.upload_bytes += bytes;
            self.stats.evicted_pages += u32::from(evicted.is_some());
            self.stats.pop_px = self.stats.pop_px.max(pop);
            offset += bytes;
        }
        Ok(copies)
    }

    /// Asks for the loads this view needs most, keeping at most two
    /// frames' uploads read or in flight; `dispatch` starts them.
    fn request(&mut self, priorities: &[f32], frame_pages: usize) {
        let busy = self.residency.loads_in_flight();
        let room = (2 * frame_pages).saturating_sub(busy);
        let planned = self.residency.plan(priorities, room);
        self.unsent.extend(planned);
    }

    /// Hands the loads asked for to the loaders. A loader woken takes a
    /// core at once, the frame thread's if it must: on two cores, the
    /// 32769^2 stream's level choice, 0.015 ms of its thread's CPU time,
    /// waited up to 4 ms behind two loaders woken by its own `prepare`
    /// (notes section 70). So a frame wakes them once it has recorded,
    /// and they read while it waits on the GPU.
    pub fn dispatch(&mut self) -> Result<()> {
        for load in self.unsent.drain(..) {
            self.loader.request(load)?;
        }
        Ok(())
    }

    /// Pages one frame's staging buffer holds.
    fn frame_pages(&self, slot: usize) -> usize {
        pages_fitting(&self.staging[slot], &self.shape)
    }

    /// Sets slot `slot` (whose last frame has completed) up for a frame
    /// seen as `view`: uploads what has arrived, asks for what the view
    /// needs (started by `dispatch`), and writes the slot's page table.
    /// Never waits on disk.
    pub fn prepare(&mut self, slot: usize, view: &FrameView) -> Result<()> {
        self.stats = StreamStats::default();
        self.collect(None)?;
        let scales = self.scales(view);
        self.copies[slot] = self.stage(slot, &scales)?;
        self.request(&self.priorities(&scales), self.frame_pages(slot));
        self.finish_frame(slot, &scales)
    }

    /// Loads and uploads (with its own submissions) until everything
    /// `view` needs is resident, or the pool holds what helps it most:
    /// what a one-shot render does before its frame. Slot `slot` must be
    /// idle. Returns the pages uploaded.
    pub fn settle(&mut self, slot: usize, view: &FrameView) -> Result<u32> {
        let scales = self.scales(view);
        let priorities = self.priorities(&scales);
        let frame_pages = self.frame_pages(slot);
        let mut uploaded = 0;
        loop {
            self.request(&priorities, frame_pages);
            self.dispatch()?;
            if self.residency.loads_in_flight() == 0 && self.arrived.is_empty() {
                return Ok(uploaded);
            }
            self.collect(Some(Duration::from_millis(100)))?;
            let copies = self.stage(slot, &scales)?;
            if copies.is_empty() {
                continue;
            }
            uploaded += copies.len() as u32;
            let (staging, pool) = (&self.staging[slot], &self.pool);
            self.device.one_shot("terrain.stream.settle", |rec| {
                rec.copy_to_layers(staging, pool, &copies)
            })?;
        }
    }

    fn finish_frame(&mut self, slot: usize, scales: &[f32]) -> Result<()> {
        self.shape
            .page_table(self.residency.page_layers(), &mut self.table);
        self.stats.missing_px = self.missing_px(scales);
        let table = self.tables[slot]
            .mapped_mut()
            .ok_or(RenderError::NotMapped("page table memory"))?;
        table.copy_from_slice(bytemuck::cast_slice(&self.table));
        self.stats.resident_pages = self.residency.resident_pages() as u32;
        self.stats.layers = self.residency.layers();
        self.stats.base_pages = self.shape.base_pages();
        self.stats.loads_in_flight = self.residency.loads_in_flight() as u32;
        self.stats.waiting_uploads = self.arrived.len() as u32;
        Ok(())
    }

    /// Records slot `slot`'s uploads (outside rendering, before its draws).
    pub fn record(&self, rec: &Recorder, slot: usize) {
        rec.copy_to_layers(&self.staging[slot], &self.pool, &self.copies[slot]);
    }

    /// The page table the last prepared frame draws with: per tile, the
    /// page it is drawn from (`residency::page_entry`).
    pub fn page_table(&self) -> &[u32] {
        &self.table
    }

    /// Evictions since the start.
    pub fn evictions(&self) -> u64 {
        self.residency.evictions()
    }
}

/// What the pool and page-table bindings hold where heights are not
/// streamed: a one-texel pool and an empty table. Every pipeline that
/// includes glsl/terrain_common.glsl declares them, and lavapipe wants
/// them bound even where the specialisation constants leave them unread.
pub struct NoStream {
    pool: Image,
    table: Buffer,
}

impl NoStream {
    pub fn new(device: &Device, name: &str) -> Result<Self> {
        Ok(NoStream {
            pool: device.create_layer_pool(&format!("{name}.pages.unused"), 1, 1)?,
            table: device.create_host_buffer(
                &format!("{name}.page_table.unused"),
                vk::BufferUsageFlags::STORAGE_BUFFER,
                &[0u8; 16],
            )?,
        })
    }

    /// Points `set`'s pool and page-table bindings at the stand-ins.
    pub fn write_bindings(&self, device: &Device, set: DescriptorSet, sampler: &Sampler) {
        device.write_sampled_image(set, BINDING_PAGES, &self.pool, sampler);
        device.write_buffer(
            set,
            BINDING_PAGE_TABLE,
            vk::DescriptorType::STORAGE_BUFFER,
            &self.table,
            self.table.desc.size,
        );
    }
}

/// Page (px, pz) at `level` of `tiled`, row-major: its level's samples
/// of its tiles. Every tile's level samples are the whole terrain's
/// lattice: tiles start on multiples of `2^level`, and a tile's last
/// sample is a multiple too or the terrain's last. Neighbours share their
/// border samples, which are equal.
fn read_page(
    tiled: &TiledHeightmap,
    shape: &StreamShape,
    (level, px, pz): (u32, u32, u32),
) -> std::result::Result<Vec<f32>, TiledError> {
    if level == 0 {
        return tiled.read_uncached(px, pz, 0).map(|t| t.heights);
    }
    let (xs, zs) = shape.page_tiles(level, px, pz);
    let (width, height) = shape.page_size(level, px, pz);
    let mut samples = vec![0f32; width as usize * height as usize];
    let step = shape.tile_cells >> level;
    for tz in zs.clone() {
        for tx in xs.clone() {
            let tile = tiled.read_uncached(tx, tz, level)?;
            let (x0, z0) = ((tx - xs.start) * step, (tz - zs.start) * step);
            for r in 0..tile.rows {
                let start = (z0 + r) as usize * width as usize + x0 as usize;
                samples[start..start + tile.cols as usize].copy_from_slice(
                    &tile.heights[(r * tile.cols) as usize..][..tile.cols as usize],
                );
            }
        }
    }
    Ok(samples)
}

/// Full pages `staging` holds (at least one: it is made that large).
fn pages_fitting(staging: &Buffer, shape: &StreamShape) -> usize {
    let side = u64::from(shape.page_side());
    (staging.desc.size / (4 * side * side)).max(1) as usize
}

/// Writes `heights`, the samples of a page `size` samples across and down,
/// into `staging` at byte `offset`, and returns the copy that puts them
/// into pool layer `layer`.
fn stage_page(
    staging: &mut [u8],
    offset: u64,
    heights: &[f32],
    layer: u32,
    (width, height): (u32, u32),
) -> LayerCopy {
    let bytes: &[u8] = bytemuck::cast_slice(heights);
    staging[offset as usize..][..bytes.len()].copy_from_slice(bytes);
    LayerCopy {
        offset,
        layer,
        width,
        height,
    }
}

/// Reads the base level's pages of `tiled` and copies them into the
/// pool's first layers, as many at a time as `staging` holds.
fn upload_base(
    device: &Device,
    tiled: &TiledHeightmap,
    shape: &StreamShape,
    pool: &Image,
    staging: &mut Buffer,
) -> Result<()> {
    let (across, _) = shape.pages_across(shape.base_level);
    let at_once = pages_fitting(staging, shape) as u32;
    let mut first = 0;
    while first < shape.base_pages() {
        let last = (first + at_once).min(shape.base_pages());
        let mapped = staging
            .mapped_mut()
            .ok_or(RenderError::NotMapped("staging memory"))?;
        let mut copies = Vec::new();
        let mut offset = 0u64;
        for layer in first..last {
            let (px, pz) = (layer % across, layer / across);
            let page = read_page(tiled, shape, (shape.base_level, px, pz))
                .map_err(|e| RenderError::Stream(e.to_string()))?;
            let size = shape.page_size(shape.base_level, px, pz);
            copies.push(stage_page(mapped, offset, &page, layer, size));
            offset += 4 * page.len() as u64;
        }
        let staging = &*staging;
        device.one_shot("terrain.stream.base", |rec| {
            rec.copy_to_layers(staging, pool, &copies)
        })?;
        first = last;
    }
    Ok(())
}
