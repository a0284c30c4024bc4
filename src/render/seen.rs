//! Counting the pixels each patch shows, for the error LOD's next frames
//! of the same view (`lod::seen`).
//!
//! In a frame that counts, glsl/terrain.frag adds one to its patch's word
//! for each fragment that passes the depth test when it is shaded (early
//! fragment tests). The terrain is drawn front to back, so a fragment a
//! nearer one later covers is rare, and counting it only adds pixels: a
//! block is never taken to show less than it does. The slot's buffer is
//! read when the slot next comes round, its frame complete, so the choice
//! never waits on the GPU.
//!
//! Counts hold for one view, one path and one tolerance: a frame whose
//! camera, projection or viewport differs in any way from the last frame
//! of its path at its tolerance reads none, and counts none. Both paths'
//! error LODs count and read: the geomip path draws through the same
//! fragment shader. A still camera counts from its second frame at a
//! path and tolerance on, `COUNTS_PER_VIEW` times, each count merged into
//! each patch's largest, and the choice settles: a hidden patch drawn
//! coarser that then shows through keeps what it showed. A moving camera
//! never counts, and pays nothing.

use std::borrow::Cow;
use std::mem::size_of;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::view::FrameView;
use crate::gpu::descriptors::DescriptorSet;
use crate::gpu::memory::{Buffer, BufferDesc};
use crate::gpu::Device;
use crate::lod::seen::{SeenPixels, NOT_DRAWN};
use crate::render::error::{RenderError, Result};
use crate::render::settings::RenderPath;
use crate::shader_constants::BINDING_SEEN_PIXELS;
use crate::terrain::PatchGrid;

/// Frames a still view counts.
pub const COUNTS_PER_VIEW: u32 = 4;

/// Bytes before the counts: the word that says whether the frame counts.
const HEADER_BYTES: usize = size_of::<u32>();

/// One frame slot's counts.
pub(super) struct SeenBuffer {
    buffer: Buffer,
    /// Patches it has a word for: the grid's, or 0 where it never counts.
    patches: usize,
    /// The view, path and tolerance the slot's last frame counted, if it
    /// counted.
    counted: Option<(FrameView, CountKey)>,
    /// The level each patch was drawn at in the frame that counts
    /// (`FramePlan::patch_levels`), set once its levels are chosen.
    levels: Vec<u8>,
}

impl SeenBuffer {
    /// A buffer for `patches` words, or one that never counts (`None`:
    /// the bindings still need a buffer).
    pub(super) fn new(device: &Device, slot: usize, patches: Option<usize>) -> Result<Self> {
        let patches = patches.unwrap_or(0);
        let size = (HEADER_BYTES + patches.max(1) * size_of::<u32>()) as u64;
        let mut buffer = device.create_buffer(
            BufferDesc {
                size,
                usage: vk::BufferUsageFlags::STORAGE_BUFFER,
                location: MemoryLocation::GpuToCpu,
            },
            &format!("terrain.seen_pixels[{slot}]"),
        )?;
        buffer
            .mapped_mut()
            .ok_or(RenderError::NotMapped("the seen pixels"))?
            .fill(0);
        Ok(SeenBuffer {
            buffer,
            patches,
            counted: None,
            levels: Vec::new(),
        })
    }

    /// Points `set`'s binding at the buffer.
    pub(super) fn bind(&self, device: &Device, set: DescriptorSet) {
        device.write_buffer(
            set,
            BINDING_SEEN_PIXELS,
            vk::DescriptorType::STORAGE_BUFFER,
            &self.buffer,
            self.buffer.desc.size,
        );
    }

    /// Whether the slot's frame counts.
    pub(super) fn counting(&self) -> bool {
        self.counted.is_some()
    }

    /// Where the slot's frame counts, the buffer its patches' levels go in
    /// (`FramePlan::patch_levels`); None where it does not count.
    pub(super) fn levels_mut(&mut self) -> Option<&mut Vec<u8>> {
        self.counting().then_some(&mut self.levels)
    }

    /// Hands `read` the counts of the slot's last frame, the view, path
    /// and tolerance it counted, and the levels its patches were drawn at,
    /// where it counted (the frame must have completed). The counts are
    /// read where the frame wrote them, not copied out first.
    fn take(
        &mut self,
        read: impl FnOnce((FrameView, CountKey), &[u32], &[u8]) -> Result<()>,
    ) -> Result<()> {
        let Some(counted) = self.counted.take() else {
            return Ok(());
        };
        let bytes = self
            .buffer
            .mapped()
            .ok_or(RenderError::NotMapped("the seen pixels"))?;
        let bytes = &bytes[HEADER_BYTES..HEADER_BYTES + self.patches * size_of::<u32>()];
        read(counted, &counts_of(bytes), &self.levels)
    }

    /// Sets the slot's next frame to count `view` for a path and tolerance
    /// (zeroing the counts), or not to count.
    fn arm(&mut self, view: Option<(FrameView, CountKey)>) -> Result<()> {
        let bytes = self
            .buffer
            .mapped_mut()
            .ok_or(RenderError::NotMapped("the seen pixels"))?;
        let counting = view.is_some() && self.patches > 0;
        bytes[..HEADER_BYTES].copy_from_slice(&u32::from(counting).to_ne_bytes());
        if counting {
            bytes[HEADER_BYTES..].fill(0);
            // Set once the frame's levels are chosen; until then, none
            // drawn.
            self.levels.clear();
            self.levels.resize(self.patches, NOT_DRAWN);
        }
        self.counted = view.filter(|_| counting);
        Ok(())
    }
}

/// The counts in `bytes` (native-endian words, as the shader wrote them):
/// read in place, or copied out where the bytes are not aligned for words
/// (no map seen so far).
fn counts_of(bytes: &[u8]) -> Cow<'_, [u32]> {
    match bytemuck::try_cast_slice(bytes) {
        Ok(counts) => Cow::Borrowed(counts),
        Err(_) => Cow::Owned(bytemuck::pod_collect_to_vec(bytes)),
    }
}

/// Paths and tolerances (`CountKey`s) whose counts are kept at once (the
/// bench draws a view at three tolerances; the window at one at a time).
const KEYS_KEPT: usize = 8;

/// Whose counts a frame takes and reads: its path's error LOD at its
/// tolerance. Each is a choice of its own, and draws its patches at levels
/// of its own.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct CountKey {
    pub path: RenderPath,
    pub tau: f32,
}

/// What the renderer knows of the pixels each patch showed, for each path
/// and tolerance its frames drew at: counts are taken and read per path
/// and tolerance, and a view is still for them when their last frame was
/// of the same view.
#[derive(Default)]
pub(super) struct SeenState {
    /// The most recently drawn last.
    entries: Vec<SeenEntry>,
    /// The path and tolerance of the frame last prepared, if it reads
    /// counts.
    current: Option<CountKey>,
}

struct SeenEntry {
    key: CountKey,
    /// The view of the last frame of this path and tolerance.
    last_view: FrameView,
    /// The merged counts and the view they are of.
    pixels: Option<(FrameView, SeenPixels)>,
    /// Counts taken of `last_view` so far, read or not.
    counts: u32,
}

impl SeenState {
    /// The counts that hold for the frame last prepared.
    pub(super) fn pixels(&self) -> Option<&SeenPixels> {
        let key = self.current?;
        let entry = self.entries.iter().find(|e| e.key == key)?;
        entry
            .pixels
            .as_ref()
            .filter(|(held, _)| *held == entry.last_view)
            .map(|(_, p)| p)
    }

    /// Before a frame of `view` is prepared in the slot that owns
    /// `buffer` (its last frame complete): takes in what that frame
    /// counted, and arms the slot to count if the view is still for the
    /// frame's path and tolerance and wants more counts (`count`: the path
    /// and tolerance where the frame reads the counts, None where it does
    /// not).
    pub(super) fn prepare(
        &mut self,
        grid: &PatchGrid,
        buffer: &mut SeenBuffer,
        view: &FrameView,
        count: Option<CountKey>,
    ) -> Result<()> {
        buffer.take(|(counted, key), counts, levels| {
            if let Some(entry) = self.entries.iter_mut().find(|e| e.key == key) {
                match &mut entry.pixels {
                    Some((held, pixels)) if *held == counted => pixels.merge(counts, levels),
                    _ => SeenPixels::new(grid, counts, levels).map(|p| {
                        entry.pixels = Some((counted, p));
                    }),
                }
                .map_err(|e| RenderError::Unsupported(e.to_string()))?;
            }
            Ok(())
        })?;
        self.current = count;
        let Some(key) = count else {
            return buffer.arm(None);
        };
        let Some(at) = self.entries.iter().position(|e| e.key == key) else {
            // A path and tolerance's first frame: the next of the same
            // view counts.
            if self.entries.len() == KEYS_KEPT {
                self.entries.remove(0);
            }
            self.entries.push(SeenEntry {
                key,
                last_view: *view,
                pixels: None,
                counts: 0,
            });
            return buffer.arm(None);
        };
        let mut entry = self.entries.remove(at);
        if entry.last_view != *view {
            entry.last_view = *view;
            entry.counts = 0;
            // Not still: the next frame of this view may count.
            entry.pixels = None;
            buffer.arm(None)?;
        } else if entry.counts < COUNTS_PER_VIEW {
            entry.counts += 1;
            buffer.arm(Some((*view, key)))?;
        } else {
            buffer.arm(None)?;
        }
        self.entries.push(entry);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Counts are the same words whether the bytes lie where words may
    /// start (read in place) or one byte off (copied out).
    #[test]
    fn counts_read_alike_aligned_or_not() {
        let words: Vec<u32> = vec![0, 1, 255, 256, 70_000, u32::MAX];
        let mut bytes = vec![0u8; words.len() * 4 + 4];
        let aligned = (0..4)
            .find(|&o| (bytes.as_ptr() as usize + o) % 4 == 0)
            .expect("an aligned offset among four");
        let unaligned = (aligned + 1) % 4;
        for (offset, in_place) in [(aligned, true), (unaligned, false)] {
            let slice = &mut bytes[offset..offset + words.len() * 4];
            for (chunk, w) in slice.chunks_exact_mut(4).zip(&words) {
                chunk.copy_from_slice(&w.to_ne_bytes());
            }
            let counts = counts_of(slice);
            assert_eq!(
                matches!(counts, Cow::Borrowed(_)),
                in_place,
                "offset {offset}"
            );
            assert_eq!(&*counts, words.as_slice(), "offset {offset}");
        }
    }
}
