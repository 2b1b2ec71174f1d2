//! The finished picture: each band's fragments rasterized into its sums
//! and nearest fragments, then composited over the opaque layer and the
//! background, as 8-bit sRGB or linear RGBA.

use glam::{Vec3, Vec4};
use rayon::prelude::*;

use super::scratch::Scratch;
use super::{Canvas, HairLayer, NO_REACH, front, srgb};

impl Canvas {
    /// The finished picture: hair over the opaque layer over `background`
    /// (linear colours), encoded as 8-bit sRGB. Each band of rows is
    /// rasterized into its own sums, then composited.
    pub fn resolve(&self, background: Vec3) -> image::RgbImage {
        self.resolve_layers(background, &[])
    }

    /// [`Self::resolve`] with the hair of `layers` (drawn on other
    /// canvases of the same size, with the same opaque layer) added to
    /// this canvas's own: the same bytes as drawing all their groups here.
    /// Layers of another size are ignored (the caller checks them).
    pub fn resolve_layers(&self, background: Vec3, layers: &[HairLayer]) -> image::RgbImage {
        let (w, h) = (self.width as u32, self.height as u32);
        let buf = self.resolve_rows(background, layers, 0..h);
        image::RgbImage::from_raw(w, h, buf).expect("one RGB pixel each")
    }

    /// [`Self::resolve_layers`] of rows `rows` alone (starting on a
    /// multiple of [`Self::band_rows`]; clipped to the picture), as 8-bit
    /// sRGB, row after row: the same bytes as those rows of the whole
    /// picture. A cluster worker resolves its own band of the picture so.
    pub fn resolve_rows(
        &self,
        background: Vec3,
        layers: &[HairLayer],
        rows: std::ops::Range<u32>,
    ) -> Vec<u8> {
        self.srgb_rows(background, layers, rows, true)
    }

    /// The finished picture as [`Self::resolve`] composites it, before it
    /// is encoded: linear RGB (not clamped to 1) and alpha, the coverage
    /// of the head (1) or the hair (`1 - prod (1 - a)` over its
    /// fragments; 0 on the background), row after row.
    pub fn resolve_linear(&self, background: Vec3) -> Vec<Vec4> {
        let h = self.height as u32;
        self.resolve_rows_with(background, &[], 0..h, true, true, |c, a, _| c.extend(a))
    }

    /// [`Self::resolve_linear`], and in the same pass the view depth
    /// (scene units) of the nearest surface at each pixel: the head's, or
    /// the hair's nearest fragment kept (with [`Self::set_nearest`] above
    /// 0; with none kept, the head's alone); infinite where nothing is
    /// drawn.
    pub fn resolve_linear_and_depth(&self, background: Vec3) -> (Vec<Vec4>, Vec<f32>) {
        let h = self.height as u32;
        self.resolve_rows_with(background, &[], 0..h, true, true, |c, a, z| {
            (c.extend(a), z)
        })
        .into_iter()
        .unzip()
    }

    /// [`Self::resolve_rows`] of `layers` over this canvas's opaque layer
    /// alone, without this canvas's own hair (already in `layers`, say
    /// from [`Self::layer_rows`]): the same bytes.
    pub fn resolve_layer_rows(
        &self,
        background: Vec3,
        layers: &[HairLayer],
        rows: std::ops::Range<u32>,
    ) -> Vec<u8> {
        self.srgb_rows(background, layers, rows, false)
    }

    /// Rows `rows` as 8-bit sRGB, with or without this canvas's own hair.
    fn srgb_rows(
        &self,
        background: Vec3,
        layers: &[HairLayer],
        rows: std::ops::Range<u32>,
        own_hair: bool,
    ) -> Vec<u8> {
        let lut = srgb::srgb_table();
        self.resolve_rows_with(background, layers, rows, own_hair, false, |c, _, _| {
            srgb::encode(lut, c)
        })
        .into_flattened()
    }

    /// The pixels of `rows`, each `pixel(colour, alpha, depth)`: its
    /// linear colour over the background, and with `alpha` its coverage
    /// and the depth of its nearest surface (otherwise 1 and the head's
    /// depth alone).
    fn resolve_rows_with<P: Copy + Send + Sync>(
        &self,
        background: Vec3,
        layers: &[HairLayer],
        rows: std::ops::Range<u32>,
        own_hair: bool,
        alpha: bool,
        pixel: impl Fn(Vec3, f32, f32) -> P + Sync,
    ) -> Vec<P> {
        let (w, h, band_rows) = (self.width, self.height, self.band);
        let (r0, r1) = ((rows.start as usize).min(h), (rows.end as usize).min(h));
        debug_assert!(r0.is_multiple_of(band_rows), "rows start on a band");
        let bg = pixel(background, 0.0, f32::INFINITY);
        let mut buf = vec![bg; r1.saturating_sub(r0) * w];
        let layers: Vec<&HairLayer> = layers
            .iter()
            .filter(|l| l.width() as usize == w && l.height() as usize == h)
            .collect();
        buf.par_chunks_mut(w * band_rows).enumerate().for_each_init(
            Scratch::default,
            |scratch, (k, out)| {
                let band = r0 / band_rows + k;
                let y0 = band * band_rows;
                let rows = out.len() / w;
                // The last group stays in floats, folded as it is composited.
                let last = if own_hair {
                    self.band_sums(band, rows, scratch, false)
                } else {
                    scratch.ready(rows, w, self.nearest);
                    NO_REACH
                };
                let first = (y0 * w) as u32;
                for l in &layers {
                    let (a, b) = l.range(first, first + (rows * w) as u32);
                    for i in a..b {
                        let px = (l.pixels()[i] - first) as usize;
                        scratch.add(px, px / w, px % w, &l.sums()[i], l.front(i));
                    }
                }
                let depth = &self.depth[y0 * w..(y0 + rows) * w];
                let opaque = &self.opaque[y0 * w..(y0 + rows) * w];
                for (r, row) in out.chunks_exact_mut(w).enumerate() {
                    // 64 pixels a word of `marked`: a run with no exact
                    // sums, no float sums and no head is background.
                    for (k, run) in row.chunks_mut(64).enumerate() {
                        let (x0, x1) = (k * 64, k * 64 + run.len());
                        let (p0, p1) = (r * w + x0, r * w + x1);
                        let word = &mut scratch.marked[r * scratch.words + k];
                        let floats = x1 as u32 > last[0] && (x0 as u32) < last[1];
                        if *word == 0 && !floats && depth[p0..p1].iter().all(|d| d.is_infinite()) {
                            run.fill(bg);
                            continue;
                        }
                        *word = 0;
                        for (p, px) in (p0..p1).zip(run.iter_mut()) {
                            let covered = depth[p].is_finite();
                            let hair = scratch.take(p);
                            if hair.is_none() && !covered {
                                *px = bg;
                                continue;
                            }
                            let base = if covered { opaque[p] } else { background };
                            let c = hair.map_or(base, |s| {
                                front::composite(scratch.front(s), Some(&scratch.sums[s]), base)
                            });
                            if !alpha {
                                *px = pixel(c, 1.0, depth[p]);
                                continue;
                            }
                            let a = match hair {
                                _ if covered => 1.0,
                                Some(s) => {
                                    1.0 - front::reveal(scratch.front(s), Some(&scratch.sums[s]))
                                }
                                None => 0.0,
                            };
                            // The nearest surface: the head's, or the
                            // hair's nearest fragment kept.
                            let near = hair
                                .and_then(|s| scratch.front(s).first())
                                .map_or(f32::INFINITY, |f| f.z);
                            *px = pixel(c, a, near.min(depth[p]));
                        }
                    }
                }
            },
        );
        buf
    }
}
