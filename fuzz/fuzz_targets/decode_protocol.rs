//! Fuzzes the master-worker protocol: any bytes must decode as a message to the worker and
//! as one to the master, or return an error, never panic, hang or allocate without bound;
//! and a message that decodes encodes back to the same bytes (the layout has no slack).
//! Run: `cd fuzz && cargo fuzz run decode_protocol`
//! (on stable Rust: `RUSTC_BOOTSTRAP=1 cargo fuzz run decode_protocol`).
//!
//! The protocol lives in the worker crate, which depends on wgpu and MPI; building those
//! under the fuzzer's instrumentation would be slow and needs system libraries. The module
//! itself depends only on `thiserror`, so it is compiled here straight from its source
//! file, `worker/src/protocol.rs`, the same code the binary runs (not a copy).
#![no_main]

use libfuzzer_sys::fuzz_target;

#[path = "../../worker/src/protocol.rs"]
#[allow(dead_code)]
mod protocol;

use protocol::{ToMaster, ToWorker};

fuzz_target!(|data: &[u8]| {
    if let Ok(m) = ToWorker::decode(data) {
        assert_eq!(m.encode(), data, "a decoded message to the worker encodes back to its bytes");
    }
    if let Ok(m) = ToMaster::decode(data) {
        assert_eq!(m.encode(), data, "a decoded message to the master encodes back to its bytes");
    }
});
