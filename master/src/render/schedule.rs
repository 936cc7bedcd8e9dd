//! Which worker renders which tile.

/// Tiles (by index) to workers (ranks `1..=workers`), one entry per tile in `tiles`' order. By
/// default tile `i` goes to worker `1 + i % workers`, so each worker keeps its tiles from
/// frame to frame. With `costs` (last frame's per-tile time), tiles go longest first to
/// the least loaded worker, in the manner of Equalizer's load equalizer; a tile without a
/// cost yet counts as the mean.
pub fn assign(tiles: &[usize], workers: usize, costs: Option<&[f64]>) -> Vec<usize> {
    let Some(costs) = costs else {
        return tiles.iter().map(|t| 1 + t % workers).collect();
    };
    let known: Vec<f64> = tiles.iter().map(|&t| costs[t]).filter(|&c| c > 0.0).collect();
    let mean = if known.is_empty() { 1.0 } else { known.iter().sum::<f64>() / known.len() as f64 };
    let cost = |&t: &usize| if costs[t] > 0.0 { costs[t] } else { mean };
    let mut order: Vec<usize> = (0..tiles.len()).collect();
    order.sort_by(|&a, &b| cost(&tiles[b]).total_cmp(&cost(&tiles[a])).then(a.cmp(&b)));
    let mut load = vec![0.0f64; workers];
    let mut owner = vec![0; tiles.len()];
    for i in order {
        let w = (0..workers).min_by(|&a, &b| load[a].total_cmp(&load[b])).expect("at least one worker");
        load[w] += cost(&tiles[i]);
        owner[i] = w + 1;
    }
    owner
}

/// Tiles (by index, in the grid's row-major order) to workers in contiguous runs: worker `w`
/// gets the `w`-th of `workers` nearly equal runs, so its tiles are a band of the frame. A
/// progressive mesh's worker adapts one mesh to the bounding rectangle of its tiles, so a
/// band keeps that rectangle to its share of the frame (round robin would make it the whole
/// frame for every worker).
pub fn contiguous(tiles: usize, workers: usize) -> Vec<usize> {
    (0..tiles).map(|k| 1 + k * workers / tiles.max(1)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contiguous_runs() {
        assert_eq!(contiguous(5, 2), vec![1, 1, 1, 2, 2]);
        assert_eq!(contiguous(2, 4), vec![1, 3]);
        assert_eq!(contiguous(8, 3), vec![1, 1, 1, 2, 2, 2, 3, 3]);
        assert!(contiguous(0, 3).is_empty());
    }

    #[test]
    fn round_robin_and_balanced_assignment() {
        let tiles = [0, 1, 2, 5, 6];
        assert_eq!(assign(&tiles, 2, None), vec![1, 2, 1, 2, 1]);
        // More workers than tiles: the extra ones get nothing.
        assert_eq!(assign(&tiles[..2], 4, None), vec![1, 2]);
        let mut costs = vec![0.0; 8];
        costs[0] = 10.0;
        costs[1] = 1.0;
        costs[2] = 1.0;
        costs[5] = 1.0;
        costs[6] = 7.0;
        // LPT: 10 -> w1, 7 -> w2, then the ones fill w2 (7 + 1 + 1 + 1 = 10).
        assert_eq!(assign(&tiles, 2, Some(&costs)), vec![1, 2, 2, 2, 2]);
    }
}
