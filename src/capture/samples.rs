//! An angle's reflectance samples (band-interleaved-by-pixel f32): decoded into memory, or —
//! when the cube on disk already is that layout (float32 BIP in this machine's byte order, no
//! white/dark references) — the file's own bytes, mapped copy-on-write: no decoding pass and
//! no copy; the few masked samples written as NaN copy only their pages, never the file.

use std::ops::{Deref, DerefMut};

/// BIP f32 samples, read and written as a slice.
pub struct Samples(Storage);

enum Storage {
    Owned(Vec<f32>),
    /// `len` f32 at byte `offset` (a multiple of 4) of a private (copy-on-write) mapping.
    Mapped {
        map: memmap2::MmapMut,
        offset: usize,
        len: usize,
    },
}

impl Samples {
    /// `len` f32 at byte `offset` of `map`, or `map` back when they are not aligned f32.
    pub(super) fn mapped(
        map: memmap2::MmapMut,
        offset: usize,
        len: usize,
    ) -> Result<Self, memmap2::MmapMut> {
        let fits = offset % 4 == 0 && offset + len * 4 <= map.len();
        // The mapping starts on a page boundary, so `offset % 4 == 0` makes it f32-aligned.
        if fits && (map.as_ptr() as usize) % std::mem::align_of::<f32>() == 0 {
            Ok(Samples(Storage::Mapped { map, offset, len }))
        } else {
            Err(map)
        }
    }

    /// Whether the samples are the file's mapping (no decoded copy).
    pub fn is_mapped(&self) -> bool {
        matches!(self.0, Storage::Mapped { .. })
    }
}

impl Deref for Samples {
    type Target = [f32];
    fn deref(&self) -> &[f32] {
        match &self.0 {
            Storage::Owned(v) => v,
            Storage::Mapped { map, offset, len } => {
                bytemuck::cast_slice(&map[*offset..*offset + *len * 4])
            }
        }
    }
}

impl DerefMut for Samples {
    fn deref_mut(&mut self) -> &mut [f32] {
        match &mut self.0 {
            Storage::Owned(v) => v,
            Storage::Mapped { map, offset, len } => {
                bytemuck::cast_slice_mut(&mut map[*offset..*offset + *len * 4])
            }
        }
    }
}

impl From<Vec<f32>> for Samples {
    fn from(v: Vec<f32>) -> Self {
        Samples(Storage::Owned(v))
    }
}

impl Clone for Samples {
    /// A copy in memory (a mapped cube is copied out of its mapping).
    fn clone(&self) -> Self {
        Samples(Storage::Owned(self.to_vec()))
    }
}

impl std::fmt::Debug for Samples {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Samples({} f32{})",
            self.len(),
            if self.is_mapped() { ", mapped" } else { "" }
        )
    }
}

impl PartialEq<Vec<f32>> for Samples {
    fn eq(&self, other: &Vec<f32>) -> bool {
        **self == **other
    }
}

impl PartialEq for Samples {
    fn eq(&self, other: &Samples) -> bool {
        **self == **other
    }
}
