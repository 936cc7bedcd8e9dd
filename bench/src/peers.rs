//! The peers Tessera is measured against, set up once for every benchmark: Draco
//! (`draco-core`, Draco in pure Rust) and meshopt (its index and vertex codecs).
//!
//! Both take positions quantized as Tessera's `.bft` files are, so that the comparison is at
//! equal precision:
//! - Draco: compression level 7 (the `draco_encoder` CLI default, speed 3), positions
//!   quantized by Draco itself to the same number of bits.
//! - meshopt: the model's own quantized positions (u16 x, y, z plus a pad up to 16 bits,
//!   since the vertex codec wants a multiple of 4 bytes; u32 x, y, z above), vertex-cache
//!   then vertex-fetch optimised (which also drops unused vertices, as a real pipeline
//!   would), then the index and vertex codecs. No general-purpose compressor on top.

use anyhow::{Context, Result};
use draco_core::{
    DataType, DecoderBuffer, EncoderBuffer, EncoderOptions, GeometryAttributeType, MeshDecoder, MeshEncoder,
    PointAttribute,
};

/// Draco's `draco_encoder` default (speed 3).
pub const DRACO_COMPRESSION_LEVEL: i32 = 7;

/// Draco at [`DRACO_COMPRESSION_LEVEL`] with positions quantized to `quant_bits`.
pub fn draco_encode(positions: &[[f32; 3]], triangles: &[[u32; 3]], quant_bits: u8) -> Result<Vec<u8>> {
    draco_encode_attributes(positions, triangles, quant_bits, &DracoAttributes::default())
}

/// Per-vertex attributes for [`draco_encode_attributes`].
#[derive(Default)]
pub struct DracoAttributes<'a> {
    /// 8-bit colours, RGB or RGBA (`alpha`), as Draco's `COLOR` attribute (normalized
    /// `uint8`, not quantized further: it is exact, as Tessera's).
    pub colors: Option<(&'a [[u8; 4]], bool)>,
    /// Normals, as Draco's `NORMAL` attribute quantized to the given bits (octahedral).
    pub normals: Option<(&'a [[f32; 3]], u8)>,
}

/// [`draco_encode`] with colours and normals too.
pub fn draco_encode_attributes(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    quant_bits: u8,
    extra: &DracoAttributes,
) -> Result<Vec<u8>> {
    let mut position = PointAttribute::new();
    position.init(GeometryAttributeType::Position, 3, DataType::Float32, false, positions.len());
    let bytes: Vec<u8> = positions.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
    position.buffer_mut().write(0, &bytes);

    let mut mesh = draco_core::Mesh::new();
    let position_id = mesh.add_attribute(position);
    if let Some((colors, alpha)) = extra.colors {
        let n = if alpha { 4 } else { 3 };
        let mut color = PointAttribute::new();
        color.init(GeometryAttributeType::Color, n as u8, DataType::Uint8, true, colors.len());
        let bytes: Vec<u8> = colors.iter().flat_map(|c| c[..n].to_vec()).collect();
        color.buffer_mut().write(0, &bytes);
        mesh.add_attribute(color);
    }
    let mut normal_id = None;
    if let Some((normals, _)) = extra.normals {
        let mut normal = PointAttribute::new();
        normal.init(GeometryAttributeType::Normal, 3, DataType::Float32, false, normals.len());
        // Draco expects unit normals.
        let unit = |n: &[f32; 3]| {
            let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            if l > 0.0 {
                n.map(|c| c / l)
            } else {
                [0.0, 0.0, 1.0]
            }
        };
        let bytes: Vec<u8> = normals.iter().flat_map(unit).flat_map(|v| v.to_le_bytes()).collect();
        normal.buffer_mut().write(0, &bytes);
        normal_id = Some(mesh.add_attribute(normal));
    }
    mesh.set_num_faces(triangles.len());
    mesh.set_faces_from_flat_indices(triangles.as_flattened());

    let mut options = EncoderOptions::new();
    options.set_compression_level(DRACO_COMPRESSION_LEVEL);
    options.set_attribute_quantization(position_id, quant_bits.into());
    if let (Some(id), Some((_, bits))) = (normal_id, extra.normals) {
        options.set_attribute_quantization(id, bits.into());
    }
    let mut encoder = MeshEncoder::new();
    encoder.set_mesh(mesh);
    let mut out = EncoderBuffer::new();
    encoder.encode(&options, &mut out)?;
    Ok(out.data().to_vec())
}

/// Decodes a Draco stream into Draco's own mesh (what its users get; the decoder also
/// dequantizes positions back to `f32` and has no switch to skip that).
pub fn draco_decode(bytes: &[u8]) -> Result<draco_core::Mesh> {
    let mut mesh = draco_core::Mesh::new();
    MeshDecoder::new().decode(&mut DecoderBuffer::new(bytes), &mut mesh)?;
    Ok(mesh)
}

/// A decoded Draco mesh as float positions and triangles.
pub fn draco_to_mesh(mesh: &draco_core::Mesh) -> Result<codec::Mesh> {
    let position =
        mesh.named_attribute(GeometryAttributeType::Position).context("the Draco stream has no positions")?;
    let flat = position.read_f32s(mesh.num_points(), 3);
    let positions = flat.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    let triangles = mesh.faces().iter().map(|f| f.map(|p| p.0)).collect();
    Ok(codec::Mesh::new(positions, triangles))
}

/// meshopt's encoded streams, with the counts its decoder has to be told.
pub struct Meshopt {
    pub indices: Vec<u8>,
    pub vertices: Vec<u8>,
    pub index_count: usize,
    pub vertex_count: usize,
}

impl Meshopt {
    /// Vertex-cache then vertex-fetch optimised, then the index and vertex codecs.
    pub fn encode<V: Clone + Default>(triangles: &[[u32; 3]], vertices: &[V]) -> Result<Meshopt> {
        let mut indices = meshopt::optimize_vertex_cache(triangles.as_flattened(), vertices.len());
        let vertices = meshopt::optimize_vertex_fetch(&mut indices, vertices);
        Ok(Meshopt {
            indices: meshopt::encode_index_buffer(&indices, vertices.len())?,
            vertices: meshopt::encode_vertex_buffer(&vertices)?,
            index_count: indices.len(),
            vertex_count: vertices.len(),
        })
    }

    /// [`Meshopt::encode`] of quantized positions, narrowed as the module docs say.
    pub fn encode_quantized(triangles: &[[u32; 3]], quantized: &[[u32; 3]], quant_bits: u8) -> Result<Meshopt> {
        if quant_bits <= 16 {
            Meshopt::encode(triangles, &narrow(quantized))
        } else {
            Meshopt::encode(triangles, quantized)
        }
    }

    /// The encoded size in bytes.
    pub fn bytes(&self) -> usize {
        self.indices.len() + self.vertices.len()
    }

    /// Decodes the index buffer and the vertices, as `V` (what they were encoded from).
    pub fn decode<V: Clone + Default>(&self) -> Result<(Vec<u32>, Vec<V>)> {
        let indices = meshopt::decode_index_buffer::<u32>(&self.indices, self.index_count)?;
        let vertices = meshopt::decode_vertex_buffer::<V>(&self.vertices, self.vertex_count)?;
        Ok((indices, vertices))
    }
}

/// Quantized positions of at most 16 bits as meshopt's vertex codec takes them.
pub fn narrow(quantized: &[[u32; 3]]) -> Vec<[u16; 4]> {
    quantized.iter().map(|&[x, y, z]| [x as u16, y as u16, z as u16, 0]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `n x n` square of quads, two triangles each.
    pub(crate) fn square(n: u32) -> codec::Mesh {
        let positions = (0..=n).flat_map(|y| (0..=n).map(move |x| [x as f32, y as f32, 0.0])).collect();
        let v = |x: u32, y: u32| y * (n + 1) + x;
        let triangles = (0..n)
            .flat_map(|y| {
                (0..n).flat_map(move |x| {
                    [[v(x, y), v(x + 1, y), v(x, y + 1)], [v(x + 1, y), v(x + 1, y + 1), v(x, y + 1)]]
                })
            })
            .collect();
        codec::Mesh::new(positions, triangles)
    }

    #[test]
    fn draco_round_trip_keeps_the_mesh() {
        let mesh = square(10);
        let back = draco_to_mesh(&draco_decode(&draco_encode(&mesh.positions, &mesh.triangles, 14).unwrap()).unwrap())
            .unwrap();
        assert_eq!(back.triangles.len(), 200);
        assert_eq!(back.positions.len(), 121);
        let mut a: Vec<_> = back.positions.iter().map(|p| p.map(|c| c.round() as i32)).collect();
        let mut b: Vec<_> = mesh.positions.iter().map(|p| p.map(|c| c as i32)).collect();
        a.sort_unstable();
        b.sort_unstable();
        assert_eq!(a, b);
    }

    /// Issue 17's target, measured against Draco in the same run: each attribute's bytes in
    /// a `.bft` stream at most Draco's for the same attribute and quantization (the bundled
    /// coloured Spot's RGB; the horse's own normals at 8, 10 and 12 bits).
    #[test]
    fn attribute_bytes_are_at_most_dracos() {
        let spot =
            codec::load_path(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/spot_colored.ply.gz"))
                .unwrap();
        let horse = codec::load_path(&testkit::mesh_path("classic/horse.ply.gz")).unwrap();
        let base = |m: &codec::Mesh| draco_encode(&m.positions, &m.triangles, 16).unwrap().len();
        let ours = |m: &codec::Mesh, bits: u8| {
            let o = codec::bft::EncodeOptions { quant_bits: 16, normal_bits: bits, ..Default::default() };
            codec::bft::Stats::of(&codec::bft::encode(m, o).unwrap().bytes).unwrap()
        };
        let colours = DracoAttributes { colors: Some((&spot.colors, false)), normals: None };
        let draco =
            draco_encode_attributes(&spot.positions, &spot.triangles, 16, &colours).unwrap().len() - base(&spot);
        let tessera = ours(&spot, 10).color_bytes;
        assert!(tessera > 0 && tessera <= draco, "colours: {tessera} bytes against Draco's {draco}");
        for bits in [8u8, 10, 12] {
            let normals = DracoAttributes { colors: None, normals: Some((&horse.normals, bits)) };
            let draco =
                draco_encode_attributes(&horse.positions, &horse.triangles, 16, &normals).unwrap().len() - base(&horse);
            let tessera = ours(&horse, bits).normal_bytes;
            assert!(tessera > 0 && tessera <= draco, "normals at {bits} bits: {tessera} bytes against Draco's {draco}");
        }
    }

    #[test]
    fn meshopt_round_trip_keeps_the_triangles() {
        let mesh = square(6);
        let q = codec::Quantization::fit(&mesh.positions, None, 14).unwrap();
        let quantized: Vec<[u32; 3]> = mesh.positions.iter().map(|&p| q.quantize(p)).collect();
        let m = Meshopt::encode_quantized(&mesh.triangles, &quantized, 14).unwrap();
        let (indices, vertices) = m.decode::<[u16; 4]>().unwrap();
        let mut back: Vec<[u16; 4]> = indices.iter().map(|&i| vertices[i as usize]).collect();
        let mut want: Vec<[u16; 4]> =
            mesh.triangles.iter().flatten().map(|&v| narrow(&quantized)[v as usize]).collect();
        // The vertex-cache optimisation reorders triangles; compare the corner multisets.
        back.sort_unstable();
        want.sort_unstable();
        assert_eq!(back, want);
        assert_eq!(m.bytes(), m.indices.len() + m.vertices.len());
    }
}
