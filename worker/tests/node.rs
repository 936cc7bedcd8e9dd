//! The worker's loop over in-process channels: a frame of a kind whose model has not come
//! is refused with the reason rank 0 prints, and the worker stops.

use std::time::Duration;

use protocol::{NspFrameJob, PmFrameJob, ToMaster, ToWorker};
use worker::transport::{local_ranks, Transport};

/// Starts a worker, waits for its handshake, sends `msg`, and returns the reason it fails with.
fn failure_for(msg: ToWorker) -> String {
    let mut ranks = local_ranks(2);
    let worker_end = ranks.pop().unwrap();
    let master = ranks.pop().unwrap();
    let worker = std::thread::spawn(move || worker::node::run(&worker_end));
    let mut failed = None;
    let mut sent = false;
    while failed.is_none() {
        let (_, bytes) = master.recv(Duration::from_secs(120)).expect("the worker answers");
        match ToMaster::decode(&bytes).unwrap() {
            ToMaster::Ready(_) if !sent => {
                master.send(1, &msg.encode());
                sent = true;
            }
            ToMaster::Failed(f) => failed = Some(f.reason),
            _ => {}
        }
    }
    let stopped = worker.join().unwrap().expect_err("the worker stops");
    let reason = failed.unwrap();
    assert_eq!(stopped.reason.to_string(), reason);
    reason
}

#[test]
fn a_frame_before_its_model_is_refused() {
    let tiles = vec![(0, [0, 0, 8, 8])];
    let pm = PmFrameJob {
        frame: 1,
        width: 8,
        height: 8,
        view_proj: glam::Mat4::IDENTITY.to_cols_array(),
        eye: [0.0; 3],
        pixels_per_unit: 1.0,
        error_px: 1.0,
        c_lod: 0.0,
        attribute_scale: 0.0,
        max_passes: 1,
        occlusion: false,
        tiles: tiles.clone(),
    };
    assert_eq!(failure_for(ToWorker::PmFrame(pm)), "a progressive-mesh frame arrived before its model");
    let nsp = NspFrameJob {
        frame: 1,
        width: 8,
        height: 8,
        view_proj: glam::Mat4::IDENTITY.to_cols_array(),
        selection: Vec::new(),
        draw: Vec::new(),
        cells: Vec::new(),
        tiles,
    };
    assert_eq!(failure_for(ToWorker::NspFrame(nsp)), "an .nsp frame arrived before its model");
}
