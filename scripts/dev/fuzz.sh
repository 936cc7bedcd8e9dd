#!/usr/bin/env bash
# Fuzzes every decoder: each target in fuzz/fuzz_targets runs for SECONDS_PER_TARGET
# (default 60), one after the other, each a single libFuzzer process on one core, built with
# optimisations, debug assertions (overflow checks) and AddressSanitizer (cargo fuzz's
# defaults). Prints per target the executions done (libFuzzer's final
# stat::number_of_executed_units) and the rate; exits non-zero if any target crashed (the
# input is under fuzz/artifacts/TARGET/). Inputs that once crashed a target are kept in
# fuzz/regressions/TARGET/ and run first; one that still crashes fails the target too.
#
#   scripts/dev/fuzz.sh [SECONDS_PER_TARGET]
#
# Environment: FUZZ_RUNS=N also stops a target after N executions (whichever comes first);
# FUZZ_TARGETS="a b" runs only those targets; FUZZ_ARGS adds libFuzzer flags; FUZZ_CARGO_ARGS
# adds cargo fuzz flags (e.g. -O: without debug assertions, so overflows wrap). The corpus of
# each target grows in fuzz/corpus/TARGET/ (not committed) and is reused by later runs; logs
# go to fuzz/logs/TARGET.log. cargo-fuzz is installed if missing; a nightly toolchain is
# used when rustup has one, stable with RUSTC_BOOTSTRAP=1 otherwise.
set -euo pipefail
cd "$(dirname "$0")/../../fuzz"

secs="${1:-60}"
if ! [[ "$secs" =~ ^[0-9]+$ ]] || [ "$secs" -lt 1 ]; then
    echo "usage: scripts/dev/fuzz.sh [SECONDS_PER_TARGET]" >&2
    exit 2
fi

if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "installing cargo-fuzz" >&2
    cargo install cargo-fuzz --locked
fi
if rustup toolchain list 2>/dev/null | grep -q '^nightly'; then
    fuzz=(cargo +nightly fuzz)
else
    export RUSTC_BOOTSTRAP=1
    fuzz=(cargo fuzz)
fi

if [ -n "${FUZZ_TARGETS:-}" ]; then
    read -r -a targets <<<"$FUZZ_TARGETS"
else
    targets=()
    for f in fuzz_targets/*.rs; do
        targets+=("$(basename "$f" .rs)")
    done
fi

# shellcheck disable=SC2206 # FUZZ_CARGO_ARGS is split on purpose
cargo_args=(${FUZZ_CARGO_ARGS:-})
"${fuzz[@]}" build "${cargo_args[@]}" >&2
mkdir -p logs
failed=()
printf '%-18s %14s %10s %8s  %s\n' target executions exec/s seconds result
for t in "${targets[@]}"; do
    mkdir -p "corpus/$t"
    args=(-max_total_time="$secs" -print_final_stats=1)
    [ -n "${FUZZ_RUNS:-}" ] && args+=(-runs="$FUZZ_RUNS")
    # shellcheck disable=SC2206 # FUZZ_ARGS is split on purpose
    [ -n "${FUZZ_ARGS:-}" ] && args+=($FUZZ_ARGS)
    regression=""
    if compgen -G "regressions/$t/*" >/dev/null; then
        if ! "${fuzz[@]}" run "${cargo_args[@]}" "$t" regressions/"$t"/* -- -runs=1 >"logs/$t.regressions.log" 2>&1; then
            regression=", a regression input crashes (fuzz/logs/$t.regressions.log)"
            failed+=("$t")
        fi
    fi
    start=$(date +%s)
    rc=0
    "${fuzz[@]}" run "${cargo_args[@]}" "$t" "corpus/$t" -- "${args[@]}" >"logs/$t.log" 2>&1 || rc=$?
    took=$(($(date +%s) - start))
    execs=$(grep -o 'stat::number_of_executed_units: [0-9]*' "logs/$t.log" | tail -1 | grep -o '[0-9]*$' || true)
    execs="${execs:-0}"
    if [ "$rc" -eq 0 ]; then
        result="ok$regression"
    else
        result="FAILED (exit $rc, see fuzz/logs/$t.log and fuzz/artifacts/$t/)$regression"
        failed+=("$t")
    fi
    printf '%-18s %14s %10s %8s  %s\n' "$t" "$execs" "$((execs / (took > 0 ? took : 1)))" "$took" "$result"
done
if [ "${#failed[@]}" -gt 0 ]; then
    echo "crashed: $(printf '%s\n' "${failed[@]}" | sort -u | tr '\n' ' ')" >&2
    exit 1
fi
