//! The texel arrays the LUT file writers take ([`super::ktx2`],
//! [`super::dds`]): one format per array, and one order.
//!
//! Order: layers one after another, each layer its rows one after another
//! (row y = 0 first), each row its texels left to right, so texel (x, y) of
//! layer l is number (l · height + y) · width + x ([`texel_index`]). This
//! is the order of the data in both KTX2 and DDS, and every graphics API
//! uploads the first row at texture coordinate t = 0 (Vulkan, Direct3D,
//! Metal and OpenGL alike). So a slice stored in the order the `lut` camera
//! renders it (pixel (x, y) is (u, v) = ((x + ½) / width, (y + ½) / height),
//! rows top down) is sampled at texture coordinates (s, t) = (u, v): u = 0,
//! v = 0 is the outer corner of texel (0, 0), the first texel of each
//! layer, and layer l is slice l.

/// The texels of a texture, in the order of [`texel_index`].
#[derive(Debug, Clone, Copy)]
pub enum Texels<'a> {
    /// R11G11B10 words ([`super::r11g11b10::pack`]).
    B10G11R11(&'a [u32]),
    /// RGBA halves ([`super::rgba16f::pack`]).
    Rgba16f(&'a [[u16; 4]]),
}

impl Texels<'_> {
    /// Number of texels.
    pub fn len(&self) -> usize {
        match self {
            Texels::B10G11R11(t) => t.len(),
            Texels::Rgba16f(t) => t.len(),
        }
    }

    /// Whether there are no texels.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes per texel: 4 or 8.
    pub fn texel_bytes(&self) -> usize {
        match self {
            Texels::B10G11R11(_) => 4,
            Texels::Rgba16f(_) => 8,
        }
    }

    /// Appends the texels as little-endian bytes (the words, or the four
    /// halves R, G, B, A of each texel).
    pub fn write_le(&self, out: &mut Vec<u8>) {
        match self {
            Texels::B10G11R11(t) => t.iter().for_each(|w| out.extend_from_slice(&w.to_le_bytes())),
            Texels::Rgba16f(t) => t.iter().flatten().for_each(|h| out.extend_from_slice(&h.to_le_bytes())),
        }
    }
}

/// The position of texel (x, y) of layer `layer` in a texel array of
/// `width` × `height` layers.
pub fn texel_index(width: u32, height: u32, layer: u32, x: u32, y: u32) -> usize {
    ((layer as usize * height as usize) + y as usize) * width as usize + x as usize
}

/// The inverse of [`texel_index`]: (layer, x, y) of texel number `index`,
/// e.g. to name the slice and texel of a value that cannot be packed.
pub fn texel_position(width: u32, height: u32, index: usize) -> (u32, u32, u32) {
    let (w, h) = (width as usize, height as usize);
    ((index / (w * h)) as u32, (index % w) as u32, ((index / w) % h) as u32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_is_layer_row_column() {
        assert_eq!(texel_index(32, 128, 0, 0, 0), 0);
        assert_eq!(texel_index(32, 128, 0, 1, 0), 1);
        assert_eq!(texel_index(32, 128, 0, 0, 1), 32);
        assert_eq!(texel_index(32, 128, 1, 0, 0), 32 * 128);
        assert_eq!(texel_index(32, 128, 63, 31, 127), 32 * 128 * 64 - 1);
        for (l, x, y) in [(0, 0, 0), (0, 31, 0), (1, 0, 0), (5, 7, 99), (63, 31, 127)] {
            assert_eq!(texel_position(32, 128, texel_index(32, 128, l, x, y)), (l, x, y));
        }
        let mut b = Vec::new();
        Texels::B10G11R11(&[0x0403_0201]).write_le(&mut b);
        Texels::Rgba16f(&[[0x0201, 0x0403, 0x0605, 0x0807]]).write_le(&mut b);
        assert_eq!(b, [1, 2, 3, 4, 1, 2, 3, 4, 5, 6, 7, 8]);
    }
}
