//! End-to-end tests of `.nsp` models under `mpirun`: tiled frames against the single-process
//! frame, with and without the geometry advance, and the cells sent along an orbit.

mod common;

use common::{alone, covered, mpirun, ok, pixels};
use testkit::mesh_arg as mesh;

/// An `.nsp` model under mpirun equals the single-process frame of the same model as one
/// tile, pixel for pixel: rank 0 chooses the cells from the cell table and sends each worker
/// only the streams it lacks; every worker draws the cells reaching its tiles with the border
/// rule against the whole selection. Along an orbit, later frames send only new cells.
#[test]
fn nsp_frames_under_mpirun_equal_the_single_process_frame() {
    // Without and with the geometry advance (whose positions depend on each cell's prologue).
    for (advance, runs) in [("0", &[(2, "4x3"), (3, "5x4")][..]), ("2", &[(3, "5x4")][..])] {
        nsp_cluster_frames(advance, runs);
    }
}

fn nsp_cluster_frames(advance: &str, runs: &[(usize, &str)]) {
    let dir = tempfile::tempdir().unwrap();
    let nsp = dir.path().join("d.nsp");
    let nsp = nsp.to_str().unwrap();
    let build = ["nsp", "build", &mesh("stanford/dragon_vrip_res2.ply.gz"), "-o", nsp, "--min-simplices", "2000"];
    ok(&alone(&[&build[..], &["--advance", advance]].concat()));
    let view = ["--size", "480x360", "--error-px", "1", "--frames", "3", "--orbit", "--orbit-degrees", "20"];
    let single = dir.path().join("single.png");
    let mut args = vec!["render", nsp, "--tiles", "1x1", "--out", single.to_str().unwrap()];
    args.extend(view);
    ok(&alone(&args));
    for &(np, tiles) in runs {
        let out = dir.path().join(format!("np{np}.png"));
        let stats = dir.path().join(format!("np{np}.jsonl"));
        let mut args =
            vec!["render", nsp, "--tiles", tiles, "--out", out.to_str().unwrap(), "--stats", stats.to_str().unwrap()];
        args.extend(view);
        ok(&mpirun(np, &[], &args));
        for k in 1..=3 {
            let (a, b) = (dir.path().join(format!("single-{k:04}.png")), dir.path().join(format!("np{np}-{k:04}.png")));
            assert!(covered(&a) > 5_000, "the model is in view");
            assert_eq!(
                pixels(&a),
                pixels(&b),
                "--advance {advance} -np {np} --tiles {tiles}, frame {k}: differs from the single process"
            );
        }
        let lines: Vec<serde_json::Value> = std::fs::read_to_string(&stats)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
            .filter(|l| l["rank"] == 0)
            .collect();
        let sent: Vec<u64> = lines.iter().map(|l| l["nsp"]["bytes_sent"].as_u64().unwrap()).collect();
        let file = std::fs::metadata(nsp).unwrap().len();
        eprintln!("--advance {advance} -np {np}: bytes sent per frame {sent:?} of a {file}-byte file");
        assert!(sent[0] > 0 && sent[1] < sent[0] && sent[2] < sent[0], "{sent:?}");
        assert!(lines.iter().all(|l| l["nsp"]["selected"].as_u64().unwrap() > 0));
    }
}
