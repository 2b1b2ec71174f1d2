//! Animated GIF encoding, frame by frame, into any writer.

use std::io::Write;

use crate::RasterError;

/// Colour quantisation speed of each frame, 1 (best, slowest) to 30: 10
/// keeps gradients in hair smooth at a tenth of the best setting's cost.
const QUANTIZE_SPEED: i32 = 10;

/// An animated GIF being encoded into `W`: frames are quantised to 256
/// colours and encoded as they come; [`Self::finish`] writes the trailer
/// and hands the writer back (a file that appears whole is the writer's
/// business).
pub struct GifWriter<W: Write> {
    encoder: gif::Encoder<W>,
    width: u16,
    height: u16,
    /// Seconds per frame.
    frame_s: f64,
    /// Frames written.
    frames: u64,
}

impl<W: Write> std::fmt::Debug for GifWriter<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GifWriter")
            .field("width", &self.width)
            .field("height", &self.height)
            .field("frame_s", &self.frame_s)
            .field("frames", &self.frames)
            .finish()
    }
}

fn encode_err(message: impl ToString) -> RasterError {
    RasterError::Encode {
        format: "GIF",
        message: message.to_string(),
    }
}

impl<W: Write> GifWriter<W> {
    /// A looping GIF of `width` x `height` frames shown at `fps` frames per
    /// second, encoded into `out`. GIF delays are whole hundredths of a
    /// second: frame `i` waits `round(100 (i + 1) / fps) - round(100 i /
    /// fps)` of them (at least 2, what viewers show), so that the delays
    /// add up to the animation's time (30 fps: 3, 4, 3, 3, 4, 3, ...).
    pub fn new(out: W, width: u32, height: u32, fps: f32) -> Result<GifWriter<W>, RasterError> {
        let (Ok(w), Ok(h)) = (u16::try_from(width), u16::try_from(height)) else {
            return Err(encode_err(format!(
                "{width}x{height} is larger than GIF's 65535 pixels a side"
            )));
        };
        if !(fps.is_finite() && fps > 0.0) {
            return Err(encode_err(format!("{fps} frames per second")));
        }
        let mut encoder = gif::Encoder::new(out, w, h, &[]).map_err(encode_err)?;
        encoder
            .set_repeat(gif::Repeat::Infinite)
            .map_err(encode_err)?;
        Ok(GifWriter {
            encoder,
            width: w,
            height: h,
            frame_s: 1.0 / f64::from(fps),
            frames: 0,
        })
    }

    /// Appends a frame of the size given to [`Self::new`].
    pub fn add(&mut self, img: &image::RgbImage) -> Result<(), RasterError> {
        if img.dimensions() != (u32::from(self.width), u32::from(self.height)) {
            return Err(encode_err(format!(
                "frame of {}x{} in a {}x{} GIF",
                img.width(),
                img.height(),
                self.width,
                self.height
            )));
        }
        let mut frame =
            gif::Frame::from_rgb_speed(self.width, self.height, img.as_raw(), QUANTIZE_SPEED);
        let at = |i: u64| (100.0 * i as f64 * self.frame_s).round();
        let delay = at(self.frames + 1) - at(self.frames);
        frame.delay = delay.clamp(2.0, 65535.0) as u16;
        self.frames += 1;
        self.encoder.write_frame(&frame).map_err(encode_err)
    }

    /// Ends the GIF and hands back the writer.
    pub fn finish(self) -> Result<W, RasterError> {
        self.encoder.into_inner().map_err(encode_err)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decode(bytes: &[u8]) -> Vec<gif::Frame<'static>> {
        let mut opts = gif::DecodeOptions::new();
        opts.set_color_output(gif::ColorOutput::RGBA);
        let mut d = opts.read_info(bytes).unwrap();
        let mut frames = Vec::new();
        while let Some(f) = d.read_next_frame().unwrap() {
            frames.push(f.clone());
        }
        frames
    }

    #[test]
    fn encodes_a_looping_gif_that_decodes_to_its_frames() {
        let frames: Vec<image::RgbImage> = (0..3)
            .map(|k| {
                image::RgbImage::from_fn(8, 6, |x, _| image::Rgb([x as u8 * 30, 200, k * 100]))
            })
            .collect();
        let mut g = GifWriter::new(Vec::new(), 8, 6, 25.0).unwrap();
        for f in &frames {
            g.add(f).unwrap();
        }
        let e = g.add(&image::RgbImage::new(4, 4)).unwrap_err();
        assert!(e.to_string().contains("frame of 4x4 in a 8x6 GIF"), "{e}");
        let bytes = g.finish().unwrap();
        assert_eq!(&bytes[..6], b"GIF89a");
        let got = decode(&bytes);
        assert_eq!(got.len(), 3);
        for (f, want) in got.iter().zip(&frames) {
            assert_eq!(f.delay, 4, "25 fps is 4 hundredths");
            // Few colours: quantisation keeps them.
            assert_eq!(&f.buffer[..3], &want.as_raw()[..3]);
        }
    }

    #[test]
    fn frame_delays_add_up_to_the_animations_time() {
        for (fps, frames, want_cs) in [(30.0, 45, 150), (24.0, 48, 200), (60.0, 6, 12)] {
            let mut g = GifWriter::new(Vec::new(), 4, 4, fps).unwrap();
            for _ in 0..frames {
                g.add(&image::RgbImage::new(4, 4)).unwrap();
            }
            let delays: Vec<u32> = decode(&g.finish().unwrap())
                .iter()
                .map(|f| u32::from(f.delay))
                .collect();
            assert_eq!(delays.len(), frames, "{fps} fps");
            // 60 fps: every delay is the 2 hundredths viewers show at least.
            assert_eq!(delays.iter().sum::<u32>(), want_cs, "{fps} fps: {delays:?}");
        }
    }

    #[test]
    fn sizes_past_gifs_and_unphysical_rates_are_refused() {
        let e = GifWriter::new(Vec::new(), 70000, 4, 30.0).unwrap_err();
        assert!(e.to_string().contains("65535"), "{e}");
        assert!(GifWriter::new(Vec::new(), 4, 4, 0.0).is_err());
        assert!(GifWriter::new(Vec::new(), 4, 4, f32::NAN).is_err());
    }
}
