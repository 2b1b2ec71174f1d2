//! Animated GIF output, frame by frame, that appears whole or not at all.

use std::io::Write;
use std::path::Path;

use crate::RasterError;
use crate::png::AtomicFile;

/// Colour quantisation speed of each frame, 1 (best, slowest) to 30: 10
/// keeps gradients in hair smooth at a tenth of the best setting's cost.
const QUANTIZE_SPEED: i32 = 10;

/// An animated GIF being written: frames are quantised to 256 colours and
/// encoded as they come, into a temporary file renamed into place by
/// [`Self::finish`]. Dropped unfinished, it leaves nothing behind.
pub struct GifWriter {
    encoder: gif::Encoder<AtomicFile>,
    width: u16,
    height: u16,
    /// Seconds per frame.
    frame_s: f64,
    /// Frames written.
    frames: u64,
}

impl std::fmt::Debug for GifWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GifWriter")
            .field("width", &self.width)
            .field("height", &self.height)
            .field("frame_s", &self.frame_s)
            .finish()
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.writer().write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.writer().flush()
    }
}

impl GifWriter {
    /// A looping GIF of `width` x `height` frames shown at `fps` frames per
    /// second. GIF delays are whole hundredths of a second: frame `i` waits
    /// `round(100 (i + 1) / fps) - round(100 i / fps)` of them (at least 2,
    /// what viewers show), so that the delays add up to the animation's
    /// time (30 fps: 3, 4, 3, 3, 4, 3, ...).
    pub fn create(
        path: &Path,
        width: u32,
        height: u32,
        fps: f32,
    ) -> Result<GifWriter, RasterError> {
        let (Ok(w), Ok(h)) = (u16::try_from(width), u16::try_from(height)) else {
            return Err(RasterError::Encode {
                path: path.to_owned(),
                message: format!("{width}x{height} is larger than GIF's 65535 pixels a side"),
            });
        };
        let encode_err = |e: gif::EncodingError| RasterError::Encode {
            path: path.to_owned(),
            message: e.to_string(),
        };
        let file = AtomicFile::create(path)?;
        let mut encoder = gif::Encoder::new(file, w, h, &[]).map_err(encode_err)?;
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

    /// Appends a frame of the size given to [`Self::create`].
    pub fn add(&mut self, img: &image::RgbImage) -> Result<(), RasterError> {
        let path = self.encoder.get_ref().path().to_owned();
        if img.dimensions() != (u32::from(self.width), u32::from(self.height)) {
            return Err(RasterError::Encode {
                path,
                message: format!(
                    "frame of {}x{} in a {}x{} GIF",
                    img.width(),
                    img.height(),
                    self.width,
                    self.height
                ),
            });
        }
        let mut frame =
            gif::Frame::from_rgb_speed(self.width, self.height, img.as_raw(), QUANTIZE_SPEED);
        let at = |i: u64| (100.0 * i as f64 * self.frame_s).round();
        let delay = at(self.frames + 1) - at(self.frames);
        frame.delay = delay.clamp(2.0, 65535.0) as u16;
        self.frames += 1;
        self.encoder
            .write_frame(&frame)
            .map_err(|e| RasterError::Encode {
                path,
                message: e.to_string(),
            })
    }

    /// Ends the GIF and moves it into place.
    pub fn finish(self) -> Result<(), RasterError> {
        let path = self.encoder.get_ref().path().to_owned();
        let file = self.encoder.into_inner().map_err(|e| RasterError::Encode {
            path,
            message: e.to_string(),
        })?;
        file.commit()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_a_looping_gif_that_decodes_to_its_frames() {
        let dir = std::env::temp_dir().join(format!("wisplight-gif-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.gif");
        let frames: Vec<image::RgbImage> = (0..3)
            .map(|k| {
                image::RgbImage::from_fn(8, 6, |x, _| image::Rgb([x as u8 * 30, 200, k * 100]))
            })
            .collect();
        let mut g = GifWriter::create(&path, 8, 6, 25.0).unwrap();
        for f in &frames {
            g.add(f).unwrap();
        }
        assert!(g.add(&image::RgbImage::new(4, 4)).is_err(), "wrong size");
        assert!(!path.exists(), "nothing at the path before finish");
        g.finish().unwrap();
        let mut opts = gif::DecodeOptions::new();
        opts.set_color_output(gif::ColorOutput::RGBA);
        let mut d = opts.read_info(std::fs::File::open(&path).unwrap()).unwrap();
        let mut n = 0;
        while let Some(f) = d.read_next_frame().unwrap() {
            assert_eq!(f.delay, 4, "25 fps is 4 hundredths");
            // Few colours: quantisation keeps them.
            let want = &frames[n];
            assert_eq!(&f.buffer[..3], &want.as_raw()[..3]);
            n += 1;
        }
        assert_eq!(n, 3);
        let names: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
        assert_eq!(names.len(), 1, "no temporary file left");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn frame_delays_add_up_to_the_animations_time() {
        let dir = std::env::temp_dir().join(format!("wisplight-gif-t-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for (fps, frames, want_cs) in [(30.0, 45, 150), (24.0, 48, 200), (60.0, 6, 12)] {
            let path = dir.join(format!("{fps}.gif"));
            let mut g = GifWriter::create(&path, 4, 4, fps).unwrap();
            for _ in 0..frames {
                g.add(&image::RgbImage::new(4, 4)).unwrap();
            }
            g.finish().unwrap();
            let mut d = gif::DecodeOptions::new()
                .read_info(std::fs::File::open(&path).unwrap())
                .unwrap();
            let mut delays = Vec::new();
            while let Some(f) = d.read_next_frame().unwrap() {
                delays.push(u32::from(f.delay));
            }
            assert_eq!(delays.len(), frames, "{fps} fps");
            // 60 fps: every delay is the 2 hundredths viewers show at least.
            assert_eq!(delays.iter().sum::<u32>(), want_cs, "{fps} fps: {delays:?}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn an_unfinished_gif_leaves_nothing() {
        let dir = std::env::temp_dir().join(format!("wisplight-gif-drop-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("b.gif");
        let mut g = GifWriter::create(&path, 4, 4, 30.0).unwrap();
        g.add(&image::RgbImage::new(4, 4)).unwrap();
        drop(g);
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
    }
}
