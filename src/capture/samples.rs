//! An angle's reflectance samples, read pixel by pixel in band-interleaved-by-pixel (BIP)
//! order whatever their storage:
//! - decoded into memory as BIP f32;
//! - the file's own bytes when the cube on disk is float32 BIP in this machine's byte order
//!   (mapped copy-on-write: no decoding pass, no copy; the few masked samples written as NaN
//!   copy only their pages, never the file);
//! - the file's own bytes when it is float32 band-sequential (BSQ) or band-interleaved-by-
//!   line (BIL): pixels are transposed a tile at a time as they are read, into a small
//!   per-thread cache, instead of a full BIP copy made before the fit. A full copy of a
//!   1-megapixel, 5-angle, 81-band capture is 1.6 GB of fresh memory, and the kernel's
//!   page faults to provide it (one per 4 KB page, each clearing, charging and mapping it)
//!   cost more than the transposition itself.

use std::cell::RefCell;
use std::sync::atomic::{AtomicU64, Ordering};

/// Reflectance samples of one angle; `at(i)` and `pixel` read them in BIP order
/// (`i = p * bands + b`).
pub struct Samples(Storage);

enum Storage {
    Owned(Vec<f32>),
    /// `len` f32 at byte `offset` (a multiple of 4) of a private (copy-on-write) mapping.
    Mapped {
        map: memmap2::MmapMut,
        offset: usize,
        len: usize,
    },
    Planar(Planar),
}

/// A planar (BSQ or BIL) float32 cube in its file's private mapping: sample (y, x, b) is
/// the f32 at `base + y * line_stride + b * band_stride + x`.
struct Planar {
    map: memmap2::MmapMut,
    base: usize,
    width: usize,
    lines: usize,
    bands: usize,
    line_stride: usize,
    band_stride: usize,
    /// Identifies this cube in the per-thread tile caches (never reused).
    id: u64,
}

/// Pixels per transposed tile (also the decoding of BSQ/BIL cubes): 256 px × 81 bands of f32 is ~80 KB (a 5-angle pixel's
/// tiles stay in L2), and each band's run is 1 KB, long enough for the prefetcher.
pub(super) const TILE_PX: usize = 256;
/// Tiles a thread keeps: every angle of a pixel (captures rarely have more than 8).
const TILE_SLOTS: usize = 8;

/// One thread's recently transposed tiles, (cube id, tile index, BIP samples), and the
/// last pixel it read of each recent cube, (cube id, pixel).
struct TileCache {
    slots: Vec<(u64, usize, Vec<f32>)>,
    next: usize,
    last: [(u64, usize); TILE_SLOTS],
}

thread_local! {
    static TILES: RefCell<TileCache> = const {
        RefCell::new(TileCache {
            slots: Vec::new(),
            next: 0,
            last: [(0, 0); TILE_SLOTS],
        })
    };
}

static NEXT_ID: AtomicU64 = AtomicU64::new(1);

impl Planar {
    fn data(&self) -> &[f32] {
        bytemuck::cast_slice(&self.map[..])
    }

    /// The `width` samples of band `b` on line `y`, in file order.
    fn run(&self, y: usize, b: usize) -> &[f32] {
        let start = self.base + y * self.line_stride + b * self.band_stride;
        &self.data()[start..start + self.width]
    }

    /// Pixels `[x0, x0 + n)` of line `y` (n ≤ [`TILE_PX`]) as BIP into `out` (`n * bands`
    /// long), read band run by band run ([`transpose_runs`]).
    fn transpose(&self, y: usize, x0: usize, n: usize, out: &mut [f32]) {
        transpose_runs(self.bands, n, out, |b, run| {
            run.copy_from_slice(&self.run(y, b)[x0..x0 + n]);
        });
    }

    /// Pixel `p`'s bands into `out`: through this thread's tile cache when the thread reads
    /// this cube pixel after pixel (a row's fit), else gathered alone (the estimator's
    /// spread subsets: a tile per isolated pixel would transpose 256 pixels for one).
    fn pixel(&self, p: usize, out: &mut [f32]) {
        let nb = self.bands;
        let (y, x) = (p / self.width, p % self.width);
        let tiles_per_line = self.width.div_ceil(TILE_PX);
        let tile = y * tiles_per_line + x / TILE_PX;
        let x0 = x / TILE_PX * TILE_PX;
        TILES.with_borrow_mut(|cache| {
            let hit = cache
                .slots
                .iter()
                .position(|s| s.0 == self.id && s.1 == tile);
            let last = &mut cache.last[(self.id as usize) % TILE_SLOTS];
            let sequential = *last == (self.id, p.wrapping_sub(1));
            *last = (self.id, p);
            let slot = match hit {
                Some(i) => i,
                None if !sequential => {
                    for (b, o) in out.iter_mut().enumerate() {
                        *o = self.run(y, b)[x];
                    }
                    return;
                }
                None => {
                    if cache.slots.len() < TILE_SLOTS {
                        cache.slots.push((0, 0, Vec::new()));
                        cache.next = cache.slots.len() - 1;
                    }
                    let i = cache.next;
                    cache.next = (i + 1) % TILE_SLOTS;
                    let n = TILE_PX.min(self.width - x0);
                    let s = &mut cache.slots[i];
                    s.2.resize(n * nb, 0.0);
                    self.transpose(y, x0, n, &mut s.2);
                    (s.0, s.1) = (self.id, tile);
                    i
                }
            };
            let k = (x - x0) * nb;
            out.copy_from_slice(&cache.slots[slot].2[k..k + nb]);
        });
    }
}

/// Transposes `n ≤ TILE_PX` pixels of `bands` bands into BIP `out` (`n * bands` long), from
/// band runs that `fill(b, run)` writes (`run.len() == n`: band `b` of those pixels, as
/// stored in a BSQ or BIL file), eight bands at a time: each run is read front to back once
/// (the band planes of a power-of-two image map to the same cache sets, so gathering a
/// pixel's bands one by one thrashes), into a stack buffer that stays in L1, and each
/// pixel's eight values are written side by side — a line of `out` touched once per eight
/// bands instead of once per band.
pub(super) fn transpose_runs(
    bands: usize,
    n: usize,
    out: &mut [f32],
    mut fill: impl FnMut(usize, &mut [f32]),
) {
    const BLOCK: usize = 8;
    let mut buf = [[0f32; TILE_PX]; BLOCK];
    for b0 in (0..bands).step_by(BLOCK) {
        let k = (bands - b0).min(BLOCK);
        for (j, run) in buf.iter_mut().enumerate().take(k) {
            fill(b0 + j, &mut run[..n]);
        }
        let pixels = out.chunks_exact_mut(bands).enumerate();
        if k == BLOCK {
            for (x, px) in pixels {
                let o: &mut [f32; BLOCK] = (&mut px[b0..b0 + BLOCK]).try_into().unwrap();
                *o = std::array::from_fn(|j| buf[j][x]);
            }
        } else {
            for (x, px) in pixels {
                for (j, o) in px[b0..b0 + k].iter_mut().enumerate() {
                    *o = buf[j][x];
                }
            }
        }
    }
}

impl Samples {
    /// `len` f32 at byte `offset` of `map`, or `map` back when they are not aligned f32.
    pub(super) fn mapped(
        map: memmap2::MmapMut,
        offset: usize,
        len: usize,
    ) -> Result<Self, memmap2::MmapMut> {
        if fits_f32(&map, offset, len) {
            Ok(Samples(Storage::Mapped { map, offset, len }))
        } else {
            Err(map)
        }
    }

    /// A planar cube of `width × lines × bands` f32 at byte `offset` of `map`, sample
    /// (y, x, b) at f32 `y * line_stride + b * band_stride + x` from there; `map` back when
    /// the samples are not aligned f32 inside it.
    pub(super) fn planar(
        map: memmap2::MmapMut,
        offset: usize,
        (width, lines, bands): (usize, usize, usize),
        (line_stride, band_stride): (usize, usize),
    ) -> Result<Self, memmap2::MmapMut> {
        let len = width * lines * bands;
        if !fits_f32(&map, offset, len) || width == 0 {
            return Err(map);
        }
        Ok(Samples(Storage::Planar(Planar {
            map,
            base: offset / 4,
            width,
            lines,
            bands,
            line_stride,
            band_stride,
            id: NEXT_ID.fetch_add(1, Ordering::Relaxed),
        })))
    }

    /// Number of samples (pixels × bands).
    pub fn len(&self) -> usize {
        match &self.0 {
            Storage::Owned(v) => v.len(),
            Storage::Mapped { len, .. } => *len,
            Storage::Planar(p) => p.width * p.lines * p.bands,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whether the samples are the file's mapping (no decoded copy).
    pub fn is_mapped(&self) -> bool {
        !matches!(self.0, Storage::Owned(_))
    }

    /// The samples as one BIP slice, or the planar cube they are read from.
    fn layout(&self) -> Result<&[f32], &Planar> {
        match &self.0 {
            Storage::Owned(v) => Ok(v),
            Storage::Mapped { map, offset, len } => {
                Ok(bytemuck::cast_slice(&map[*offset..*offset + *len * 4]))
            }
            Storage::Planar(p) => Err(p),
        }
    }

    /// The samples as one BIP slice, unless they are a planar file's mapping.
    pub fn as_bip(&self) -> Option<&[f32]> {
        self.layout().ok()
    }

    /// As [`Samples::as_bip`], writable (a mapped page written is copied, never the file).
    pub fn as_bip_mut(&mut self) -> Option<&mut [f32]> {
        match &mut self.0 {
            Storage::Owned(v) => Some(v),
            Storage::Mapped { map, offset, len } => Some(bytemuck::cast_slice_mut(
                &mut map[*offset..*offset + *len * 4],
            )),
            Storage::Planar(_) => None,
        }
    }

    /// Copies the `out.len()` bands of pixel `p` into `out`.
    #[inline]
    pub fn pixel(&self, p: usize, out: &mut [f32]) {
        let nb = out.len();
        match self.layout() {
            Ok(bip) => out.copy_from_slice(&bip[p * nb..(p + 1) * nb]),
            Err(planar) => planar.pixel(p, out),
        }
    }

    /// Sample `i` in BIP order.
    pub fn at(&self, i: usize) -> f32 {
        match self.layout() {
            Ok(bip) => bip[i],
            Err(pl) => {
                let (p, b) = (i / pl.bands, i % pl.bands);
                pl.run(p / pl.width, b)[p % pl.width]
            }
        }
    }

    /// Pixels `px` (row-major pixel indices) of `bands` bands as BIP samples in memory.
    pub fn pixels_to_vec(&self, px: std::ops::Range<usize>, bands: usize) -> Vec<f32> {
        match self.layout() {
            Ok(bip) => bip[px.start * bands..px.end * bands].to_vec(),
            Err(_) => {
                let mut out = vec![0f32; px.len() * bands];
                for (p, o) in px.zip(out.chunks_exact_mut(bands.max(1))) {
                    self.pixel(p, o);
                }
                out
            }
        }
    }

    /// The `width` samples of band `b` on line `y` of a planar cube, in file order.
    pub(super) fn planar_run(&self, y: usize, b: usize) -> Option<&[f32]> {
        match &self.0 {
            Storage::Planar(p) => Some(p.run(y, b)),
            _ => None,
        }
    }

    /// Writes sample (y, x, b) of a planar cube (its page is copied, never the file).
    pub(super) fn set_planar(&mut self, y: usize, x: usize, b: usize, v: f32) {
        if let Storage::Planar(p) = &mut self.0 {
            let i = p.base + y * p.line_stride + b * p.band_stride + x;
            bytemuck::cast_slice_mut::<u8, f32>(&mut p.map[..])[i] = v;
        }
    }

    /// All samples in BIP order, in memory.
    pub fn to_vec(&self) -> Vec<f32> {
        match self.layout() {
            Ok(bip) => bip.to_vec(),
            Err(pl) => self.pixels_to_vec(0..pl.width * pl.lines, pl.bands),
        }
    }
}

/// Whether `len` f32 at byte `offset` lie inside `map`, f32-aligned.
fn fits_f32(map: &memmap2::MmapMut, offset: usize, len: usize) -> bool {
    // The mapping starts on a page boundary, so `offset % 4 == 0` makes it f32-aligned.
    offset % 4 == 0
        && offset + len * 4 <= map.len()
        && (map.as_ptr() as usize) % std::mem::align_of::<f32>() == 0
}

impl From<Vec<f32>> for Samples {
    fn from(v: Vec<f32>) -> Self {
        Samples(Storage::Owned(v))
    }
}

impl Clone for Samples {
    /// A copy in memory (a mapped cube is copied out of its mapping, as BIP).
    fn clone(&self) -> Self {
        Samples(Storage::Owned(self.to_vec()))
    }
}

impl std::fmt::Debug for Samples {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let how = match &self.0 {
            Storage::Owned(_) => "",
            Storage::Mapped { .. } => ", mapped",
            Storage::Planar(_) => ", mapped planar",
        };
        write!(f, "Samples({} f32{how})", self.len())
    }
}

impl PartialEq<Vec<f32>> for Samples {
    fn eq(&self, other: &Vec<f32>) -> bool {
        self.to_vec() == *other
    }
}

impl PartialEq for Samples {
    fn eq(&self, other: &Samples) -> bool {
        self.to_vec() == other.to_vec()
    }
}
