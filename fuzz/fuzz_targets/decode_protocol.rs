//! Fuzzes the master-worker protocol: any bytes must decode as a message to the worker and
//! as one to the master, or return an error, never panic, hang or allocate without bound;
//! and a message that decodes encodes back to the same bytes (the layout has no slack).
//! Run: `cd fuzz && cargo fuzz run decode_protocol`
//! (on stable Rust: `RUSTC_BOOTSTRAP=1 cargo fuzz run decode_protocol`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use protocol::{ToMaster, ToWorker};

fuzz_target!(|data: &[u8]| {
    if let Ok(m) = ToWorker::decode(data) {
        assert_eq!(m.encode(), data, "a decoded message to the worker encodes back to its bytes");
    }
    if let Ok(m) = ToMaster::decode(data) {
        assert_eq!(m.encode(), data, "a decoded message to the master encodes back to its bytes");
    }
});
