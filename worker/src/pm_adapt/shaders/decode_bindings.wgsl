// The operation decoder's buffers (decode.wgsl says what each holds): bind group 1 of every
// shader that decodes, declared here once and bound by name (`decoder_buffers` in pass.rs,
// `GpuOpDecoder::decode` in decoder.rs). `errors` is used only by the stages that report
// failures (vertex_op.wgsl): the first failure's status, then its address.
@group(1) @binding(0) var<storage, read> D: DecodeParams;
@group(1) @binding(1) var<storage, read> ops: array<u32>;
@group(1) @binding(2) var<storage, read> tables: array<u32>;
@group(1) @binding(3) var<storage, read_write> dec_faces: array<u32>;
@group(1) @binding(4) var<storage, read_write> errors: array<atomic<u32>, 2>;
