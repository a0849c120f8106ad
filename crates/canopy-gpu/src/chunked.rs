//! Arrays larger than one storage binding: uploaded as up to [`CHUNKS`] buffers of a
//! power-of-two number of elements each, bound side by side, and read in WGSL through an
//! accessor that picks the chunk by the index's high bits.
//!
//! Adapters cap a storage binding (lavapipe at 128 MiB, 1.4 million 96-byte primitives),
//! so a large mesh's primitives, nodes or vertex normals may not fit in one. The chunk
//! size is a pipeline-overridable constant (`<NAME>_BITS`) and so is the chunk count
//! (`<NAME>_CHUNKS`): a scene that fits in one binding compiles to the plain array read.

use crate::{Gpu, GpuError};

/// Bindings a chunked array may take: a scene's primitives, nodes or vertex normals may
/// be up to this many times the adapter's largest storage binding.
pub const CHUNKS: usize = 4;

/// An array uploaded as `1..=CHUNKS` buffers of `1 << bits` elements (the last one
/// shorter).
pub(crate) struct ChunkedBuffer {
    name: &'static str,
    buffers: Vec<wgpu::Buffer>,
    bits: u32,
}

impl ChunkedBuffer {
    /// Uploads `items`; `name` is the prefix of the shader's constants (`NODE` for
    /// `NODE_BITS` and `NODE_CHUNKS`), `label` names the array in errors.
    pub fn new<T: bytemuck::Pod>(
        gpu: &Gpu,
        name: &'static str,
        label: &'static str,
        items: &[T],
    ) -> Result<Self, GpuError> {
        let item = std::mem::size_of::<T>() as u64;
        let bits = chunk_bits(gpu.max_binding_bytes(), item);
        let per_chunk = 1usize << bits;
        let chunks = items.len().div_ceil(per_chunk).max(1);
        if chunks > CHUNKS {
            return Err(GpuError::TooLargeToSplit {
                what: label,
                bytes: items.len() as u64 * item,
                chunks: CHUNKS,
                binding: gpu.max_binding_bytes(),
            });
        }
        let buffers = (0..chunks)
            .map(|c| {
                let part = &items[(c * per_chunk).min(items.len())..];
                let part = &part[..part.len().min(per_chunk)];
                gpu.storage(
                    label,
                    bytemuck::cast_slice(part),
                    wgpu::BufferUsages::empty(),
                )
            })
            .collect::<Result<_, _>>()?;
        Ok(Self {
            name,
            buffers,
            bits,
        })
    }

    /// Bind group entries for the chunks at `bindings` (the shader's order); bindings
    /// past the last chunk repeat the first buffer, which the shader never reads there.
    pub fn entries(&self, bindings: [u32; CHUNKS]) -> [(u32, &wgpu::Buffer); CHUNKS] {
        std::array::from_fn(|c| (bindings[c], self.buffers.get(c).unwrap_or(&self.buffers[0])))
    }

    /// The pipeline constants that tell the shader this array's chunking.
    pub fn constants(&self) -> [(String, f64); 2] {
        [
            (format!("{}_BITS", self.name), self.bits as f64),
            (format!("{}_CHUNKS", self.name), self.buffers.len() as f64),
        ]
    }

    /// Number of buffers the array was split into.
    #[cfg(test)]
    pub fn chunks(&self) -> usize {
        self.buffers.len()
    }
}

/// The largest `b` (at most 31, as WGSL indices are `u32`) with `2^b` items of `item`
/// bytes in `binding` bytes; at least 0.
fn chunk_bits(binding: u64, item: u64) -> u32 {
    let items = (binding / item).max(1);
    (63 - items.leading_zeros()).min(31)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunks_are_the_largest_power_of_two_that_fits_a_binding() {
        // lavapipe: 128 MiB bindings; 96-byte primitives come 2^20 to a chunk.
        assert_eq!(chunk_bits(128 << 20, 96), 20);
        assert_eq!(chunk_bits(128 << 20, 64), 21);
        assert_eq!(chunk_bits(u32::MAX as u64, 4), 29);
        assert_eq!(chunk_bits(u64::MAX, 1), 31);
        assert_eq!(chunk_bits(10, 96), 0);
    }

    #[test]
    fn an_array_too_large_for_every_chunk_is_an_error_naming_the_limit() {
        let Ok(mut gpu) = Gpu::new() else {
            return eprintln!("SKIPPED: no GPU adapter");
        };
        gpu.cap_binding_bytes(1024);
        let fits = ChunkedBuffer::new(&gpu, "T", "test items", &vec![0u32; 4 * 256]).unwrap();
        assert_eq!(fits.chunks(), 4);
        let err = ChunkedBuffer::new(&gpu, "T", "test items", &vec![0u32; 4 * 256 + 1])
            .err()
            .expect("five chunks' worth was accepted");
        let message = err.to_string();
        assert!(message.contains("test items"), "{message}");
        assert!(
            message.contains("max_storage_buffer_binding_size"),
            "{message}"
        );
    }
}
