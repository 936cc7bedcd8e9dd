//! Tile pixels coded for the wire (`render --pixel-codec`): a worker codes each tile it
//! sends, rank 0 or a display rank decodes it before compositing. LZ4 is lossless; JPEG
//! codes the colour (lossy, quality 1-100; `jpeg-encoder` encodes, the `image` crate
//! decodes) and keeps the alpha plane exact beside it in LZ4,
//! since coverage is what tells drawn pixels from the transparent background in a PNG, and
//! an all-opaque or all-transparent plane costs a few bytes. A tile whose coding is not
//! smaller than its raw pixels goes raw.
//!
//! A JPEG tile: `jpeg length u32 (little-endian), the JPEG, the alpha plane as an LZ4 block`.

use protocol::{PixelCodec, TilePixels};

/// Why coded pixels cannot be decoded (they come from another rank: never a panic).
#[derive(Debug, thiserror::Error)]
pub enum PixelError {
    #[error("tile {index}: its {what} pixels do not decode: {why}")]
    Corrupt { index: u32, what: &'static str, why: String },
}

/// `rgba` (`width` x `height`, rows top first) coded by `codec`: the codec used (raw where
/// the coding is not smaller) and the bytes.
pub fn encode(codec: PixelCodec, rgba: &[u8], width: u32, height: u32) -> (PixelCodec, Vec<u8>) {
    let coded = match codec {
        PixelCodec::Raw => None,
        PixelCodec::Lz4 => Some(lz4_flex::block::compress(rgba)),
        PixelCodec::Jpeg { quality } => jpeg(rgba, width, height, quality),
    };
    match coded {
        Some(bytes) if bytes.len() < rgba.len() => (codec, bytes),
        _ => (PixelCodec::Raw, rgba.to_vec()),
    }
}

fn jpeg(rgba: &[u8], width: u32, height: u32, quality: u8) -> Option<Vec<u8>> {
    let rgb: Vec<u8> = rgba.chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
    let alpha: Vec<u8> = rgba.chunks_exact(4).map(|p| p[3]).collect();
    let mut out = vec![0u8; 4];
    // jpeg-encoder, not the image crate's encoder: 8.5 ms against 22.3 ms for a 1455x555
    // frame at quality 90 on this machine (65,806 against 65,743 bytes), 4.8 against 28.4 ms
    // at 75 (29,861 against 40,138 bytes); the image crate decodes.
    let (w, h) = (u16::try_from(width).ok()?, u16::try_from(height).ok()?);
    jpeg_encoder::Encoder::new(&mut out, quality).encode(&rgb, w, h, jpeg_encoder::ColorType::Rgb).ok()?;
    let jpeg_len = (out.len() - 4) as u32;
    out[..4].copy_from_slice(&jpeg_len.to_le_bytes());
    out.extend_from_slice(&lz4_flex::block::compress(&alpha));
    Some(out)
}

/// The RGBA pixels of `tile`'s rectangle, decoded.
pub fn decode(tile: &TilePixels) -> Result<Vec<u8>, PixelError> {
    let [x0, y0, x1, y1] = tile.rect;
    let (width, height) = (x1 - x0, y1 - y0);
    // The protocol checked the area times 4 fits 64 bits and the coded size against it.
    let size = width as usize * height as usize * 4;
    let corrupt = |what: &'static str, why: String| PixelError::Corrupt { index: tile.index, what, why };
    match tile.codec {
        PixelCodec::Raw => Ok(tile.pixels.clone()),
        PixelCodec::Lz4 => {
            let mut rgba = vec![0u8; size];
            match lz4_flex::block::decompress_into(&tile.pixels, &mut rgba) {
                Ok(n) if n == size => Ok(rgba),
                Ok(n) => Err(corrupt("LZ4", format!("{n} bytes, the rectangle needs {size}"))),
                Err(e) => Err(corrupt("LZ4", e.to_string())),
            }
        }
        PixelCodec::Jpeg { .. } => {
            let bytes = &tile.pixels;
            let n = bytes.get(..4).map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")) as usize);
            let Some((jpeg, alpha)) = n.and_then(|n| bytes.get(4..).filter(|b| b.len() >= n).map(|b| b.split_at(n)))
            else {
                return Err(corrupt("JPEG", "cut short".into()));
            };
            let rgb = decode_jpeg(jpeg, width, height).map_err(|why| corrupt("JPEG", why))?;
            let mut a = vec![0u8; size / 4];
            match lz4_flex::block::decompress_into(alpha, &mut a) {
                Ok(n) if n == a.len() => {}
                Ok(n) => return Err(corrupt("JPEG", format!("an alpha plane of {n} bytes, not {}", a.len()))),
                Err(e) => return Err(corrupt("JPEG", format!("the alpha plane: {e}"))),
            }
            let mut rgba = Vec::with_capacity(size);
            for (p, a) in rgb.chunks_exact(3).zip(a) {
                rgba.extend_from_slice(&[p[0], p[1], p[2], a]);
            }
            Ok(rgba)
        }
    }
}

/// A JPEG's RGB pixels, refused unless it is `width` x `height` in RGB (checked from its
/// header before anything is allocated for it).
fn decode_jpeg(jpeg: &[u8], width: u32, height: u32) -> Result<Vec<u8>, String> {
    use image::ImageDecoder;
    let decoder = image::codecs::jpeg::JpegDecoder::new(std::io::Cursor::new(jpeg)).map_err(|e| e.to_string())?;
    if decoder.dimensions() != (width, height) || decoder.color_type() != image::ColorType::Rgb8 {
        return Err(format!(
            "a {:?} {:?} image in a {width}x{height} tile",
            decoder.dimensions(),
            decoder.color_type()
        ));
    }
    let mut rgb = vec![0u8; width as usize * height as usize * 3];
    decoder.read_image(&mut rgb).map_err(|e| e.to_string())?;
    Ok(rgb)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tile with a disc drawn on a transparent background, shaded across.
    fn tile(width: u32, height: u32) -> Vec<u8> {
        let mut rgba = Vec::new();
        for y in 0..height {
            for x in 0..width {
                let (dx, dy) = (x as f32 - width as f32 / 2.0, y as f32 - height as f32 / 2.0);
                let inside = dx * dx + dy * dy < (width.min(height) as f32 / 3.0).powi(2);
                let shade = (x * 255 / width) as u8;
                rgba.extend_from_slice(&if inside { [shade, 128, 255 - shade, 255] } else { [0; 4] });
            }
        }
        rgba
    }

    fn coded(codec: PixelCodec, rgba: &[u8], (w, h): (u32, u32)) -> TilePixels {
        let (codec, pixels) = encode(codec, rgba, w, h);
        TilePixels {
            index: 3,
            rect: [10, 20, 10 + w, 20 + h],
            times: Default::default(),
            triangles: 0,
            reused: 0,
            codec,
            coded_bytes: pixels.len() as u32,
            pixels,
        }
    }

    #[test]
    fn lz4_is_lossless_and_jpeg_keeps_the_coverage_exact() {
        let size = (96, 64);
        let rgba = tile(size.0, size.1);
        let lz4 = coded(PixelCodec::Lz4, &rgba, size);
        assert_eq!(lz4.codec, PixelCodec::Lz4);
        assert!(lz4.pixels.len() < rgba.len() / 4, "{} bytes", lz4.pixels.len());
        assert_eq!(decode(&lz4).unwrap(), rgba);

        let jpeg = coded(PixelCodec::Jpeg { quality: 90 }, &rgba, size);
        assert_eq!(jpeg.codec, PixelCodec::Jpeg { quality: 90 });
        let back = decode(&jpeg).unwrap();
        assert_eq!(back.len(), rgba.len());
        // Alpha exact; colour close where drawn.
        for (a, b) in rgba.chunks_exact(4).zip(back.chunks_exact(4)) {
            assert_eq!(a[3], b[3]);
        }
        let worst = rgba
            .chunks_exact(4)
            .zip(back.chunks_exact(4))
            .filter(|(a, _)| a[3] == 255)
            .map(|(a, b)| (0..3).map(|k| (a[k] as i32 - b[k] as i32).abs()).max().unwrap())
            .collect::<Vec<_>>();
        let mean = worst.iter().sum::<i32>() as f64 / worst.len() as f64;
        assert!(mean < 8.0, "mean error {mean}");
        assert_eq!(decode(&coded(PixelCodec::Raw, &rgba, size)).unwrap(), rgba);
    }

    #[test]
    fn a_tile_that_does_not_shrink_goes_raw() {
        // Noise: LZ4 cannot shrink it.
        let mut x = 12345u32;
        let noise: Vec<u8> = (0..16 * 16 * 4)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                x as u8
            })
            .collect();
        let t = coded(PixelCodec::Lz4, &noise, (16, 16));
        assert_eq!((t.codec, &t.pixels), (PixelCodec::Raw, &noise));
    }

    #[test]
    fn corrupt_pixels_are_errors_not_panics() {
        let size = (32, 32);
        let rgba = tile(size.0, size.1);
        for codec in [PixelCodec::Lz4, PixelCodec::Jpeg { quality: 75 }] {
            let good = coded(codec, &rgba, size);
            for cut in [0, 3, 4, 10, good.pixels.len() / 2, good.pixels.len() - 1] {
                let t = TilePixels { pixels: good.pixels[..cut].to_vec(), ..good.clone() };
                assert!(decode(&t).is_err(), "{codec:?} cut at {cut}");
            }
            let mut flipped = good.clone();
            for b in flipped.pixels.iter_mut().skip(2).step_by(7) {
                *b ^= 0x5a;
            }
            // Either an error or pixels of the tile's size: never a panic or another size.
            if let Ok(p) = decode(&flipped) {
                assert_eq!(p.len(), rgba.len());
            }
            // A JPEG of another size is refused from its header.
            let other = coded(codec, &tile(16, 32), (16, 32));
            let t = TilePixels { pixels: other.pixels, ..good.clone() };
            let e = decode(&t).unwrap_err().to_string();
            assert!(e.starts_with("tile 3: its"), "{e}");
        }
    }
}
