//! Table 2 of Mitra & Chiueh, "Compression-Domain Parallel Rendering"
//! (`shared/papers/bft-compression-domain-sort-first.txt`, section 3.2): the modification rules
//! that rewrite a BFT command for one tile, walked row by row against
//! [`tile_sort::rewrite`](codec::bft::tile_sort::rewrite).
//!
//! Every command kind is tried with every combination of which of its left, right and third
//! vertices and its triangle are unclipped for the tile (the tile is in their boxes). The one
//! row of the table that matches gives the expected rewrite; a combination that no row matches
//! must give nothing (the table's "other combinations: ϕ"), which covers the commands the
//! table has no row for (`SEED`, which the tile sort handles itself, and the tile-only `ADD`
//! and `CLEAR`). Combinations that cannot occur are skipped: a triangle unclipped for a tile
//! has its three vertices unclipped there, as `[t] ⊆ [v_l] ∩ [v_r] ∩ [v_x]`.

use codec::bft::tile_sort::{rewrite, Rewrite};
use codec::bft::Command;

/// An entry of the columns `v_l`, `v_r`, `v_x`, `t` of Table 2.
#[derive(Clone, Copy, Debug)]
enum Status {
    /// NC: unclipped.
    Nc,
    /// C: clipped.
    C,
    /// X: don't care.
    X,
    /// -: undefined (a command without a third vertex or a triangle).
    Undef,
}

use Status::{Nc, Undef, C, X};

impl Status {
    fn admits(self, unclipped: bool) -> bool {
        match self {
            Nc => unclipped,
            C => !unclipped,
            X | Undef => true,
        }
    }
}

const NEW_RF_LF: &[Command] = &[Command::New, Command::Rf, Command::Lf];

/// Table 2 as printed, one entry per row: the commands of column `c`, the columns `v_l`, `v_r`,
/// `v_x`, `t`, and `c'` (`Same`: the input command itself, `New/RF/LF`, `RF0` or `LF0`, with
/// its offset rewritten). The comment is the row's tile column.
const TABLE_2: [(&[Command], [Status; 4], Rewrite); 13] = [
    (NEW_RF_LF, [Nc, Nc, Nc, Nc], Rewrite::Same),             // [t]
    (NEW_RF_LF, [Nc, X, Nc, C], Rewrite::NullAdd),            // ([v_l] ∩ [v_x]) − [t]
    (NEW_RF_LF, [Nc, X, C, C], Rewrite::Null),                // ([v_l] − [v_x]) − [t]
    (NEW_RF_LF, [C, X, Nc, C], Rewrite::Add),                 // ([v_x] − [v_l]) − [t]
    (&[Command::Rf0], [Nc, Nc, Nc, Nc], Rewrite::Same),       // [t]
    (&[Command::Rf0], [Nc, Nc, X, C], Rewrite::Dr),           // ([v_r] ∩ [v_l]) − [t]
    (&[Command::Rf0], [C, Nc, X, C], Rewrite::Dl),            // ([v_r] − [v_l]) − [t]
    (&[Command::Dr], [Nc, Nc, Undef, Undef], Rewrite::Dr),    // [v_r] ∩ [v_l]
    (&[Command::Dr], [C, Nc, Undef, Undef], Rewrite::Dl),     // [v_r] − [v_l]
    (&[Command::Lf0], [Nc, Nc, Nc, Nc], Rewrite::Same),       // [t]
    (&[Command::Lf0], [Nc, X, X, C], Rewrite::Dl),            // [v_l] − [t]
    (&[Command::Dl], [Nc, X, Undef, Undef], Rewrite::Dl),     // [v_l]
    (&[Command::Null], [Nc, X, Undef, Undef], Rewrite::Null), // [v_l]
];

/// Which of `v_l`, `v_r`, `v_x`, `t` are unclipped, for all 16 combinations.
fn combinations() -> impl Iterator<Item = [bool; 4]> {
    (0..16u8).map(|bits| std::array::from_fn(|i| bits & (1 << i) != 0))
}

/// Whether `c` codes the triangle `(v_l, v_r, v_x)`, so that an unclipped triangle has its
/// three vertices unclipped.
fn codes_the_triangle(c: Command) -> bool {
    matches!(c, Command::New | Command::Rf | Command::Lf | Command::Rf0 | Command::Lf0)
}

#[test]
fn every_row_of_table_2() {
    let mut failures = vec![];
    let mut used = [0usize; TABLE_2.len()];
    for c in Command::ALL {
        for s @ [l, r, x, t] in combinations() {
            if codes_the_triangle(c) && t && !(l && r && x) {
                continue;
            }
            let rows: Vec<usize> = (0..TABLE_2.len())
                .filter(|&i| {
                    let (cs, status, _) = TABLE_2[i];
                    cs.contains(&c) && status.iter().zip(s).all(|(st, u)| st.admits(u))
                })
                .collect();
            // "For a particular input command c, the different rules cover mutually exclusive
            // tiles."
            assert!(rows.len() <= 1, "{c:?} {s:?} matches rows {rows:?}");
            let expected = rows.first().map_or(Rewrite::Nothing, |&i| TABLE_2[i].2);
            if let Some(&i) = rows.first() {
                used[i] += 1;
            }
            let got = rewrite(c, l, r, x, t);
            if got != expected {
                failures.push(format!(
                    "{c:?}, unclipped v_l {l}, v_r {r}, v_x {x}, t {t}: {got:?}, Table 2 says {expected:?}"
                ));
            }
        }
    }
    assert!(failures.is_empty(), "rewrite disagrees with Table 2:\n{}", failures.join("\n"));
    assert!(used.iter().all(|&n| n > 0), "rows that no combination reaches: {used:?}");
}

/// The tile sort's pass 2 has no box for the third vertex of `RF0`, `LF0`, `DR`, `DL` and
/// `NULL`, nor a triangle for the last three, and passes `false` for them: Table 2 never reads
/// them there (`X` or `-`, and `RF0`/`LF0` in `[t]` have `v_x` unclipped with the triangle).
#[test]
fn the_arguments_table_2_does_not_read_change_nothing() {
    for c in [Command::Rf0, Command::Lf0, Command::Dr, Command::Dl, Command::Null] {
        for [l, r, x, t] in combinations() {
            assert_eq!(rewrite(c, l, r, x, t), rewrite(c, l, r, !x, t), "{c:?}: v_x read");
            if !codes_the_triangle(c) {
                assert_eq!(rewrite(c, l, r, x, t), rewrite(c, l, r, x, !t), "{c:?}: t read");
            }
        }
    }
}
